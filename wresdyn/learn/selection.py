"""Model selection on the validation split: the open-loop replay error every learner is chosen by.

The score is the evaluation's headline metric, mean |q_sim − q_real| over all joints and samples of whole
validation trajectories replayed open loop from their first recorded state (:mod:`wresdyn.evaluation.open_loop`),
computed through the same simulation layer; joints the dataset excludes from fitting (``weights`` 0, from
:meth:`~wresdyn.data.dataset.Dataset.fit_weights`) are left out of it, as from the evaluation. A diverged replay holds its last sane state, so it counts with its
growing error instead of being left out. Held-out and OOD data never reach a learner.
"""

from __future__ import annotations

import numpy as np

from ..data.dataset import fitted_mask
from ..sim import Simulator
from ..sim.rollout import replay_setup, run_replay

__all__ = ["ValidationScore"]


class ValidationScore:
    """``score(policy) -> mean |Δq| [rad]`` on fixed validation trajectories; reuses one simulator, so on CUDA
    its replay is captured as one CUDA graph at the second call with a policy and replayed after
    (:mod:`wresdyn.sim.rollout_graph`).

    Args:
        robot: The robot (simulator side).
        trajectories: Validation trajectories.
        rate_hz: Their sample rate [Hz].
        solver, device, friction_kappa: Simulation settings (as the learner's; ``friction_kappa``: the replay
            solver's dry-friction law, :class:`~wresdyn.sim.Simulator`).
        delay: Command-path delay of the simulator [steps].
        physics: Physical parameters of the model (the hybrid's identified physics, with its delay), or ``None``.
        weights: Per-joint weights (n_dof,): joints with 0 (excluded from fitting) are left out of the score;
            ``None``: every joint counts.
    """

    def __init__(self, robot, trajectories, rate_hz: float, solver: str = "auto", device: str = "cpu",
                 delay=0.0, physics=None, weights=None, friction_kappa: float | None = None) -> None:

        self.robot, self.trajectories, self.rate_hz, self.delay = robot, list(trajectories), float(rate_hz), delay
        self.physics = physics
        self.mask = fitted_mask(weights, robot.n_dof)
        """Joints the score averages over, bool (n_dof,)."""
        if not self.trajectories:
            raise ValueError("no validation trajectories")
        self.sim = Simulator(robot, len(self.trajectories), 1.0 / self.rate_hz, solver=solver, device=device,
                             friction_kappa=friction_kappa)
        self.last_diverged = 0
        """Validation replays that diverged in the last call."""
        self.last_errors = np.zeros(robot.n_dof)
        """Mean |Δq| of each joint in the last call [rad], shape (n_dof,), excluded joints too."""
        self._fixed_physics = physics
        self._setup = None  # (with a policy, the replay's set-up): kept while the physics are the ones given here
        self._loose = None  # the last set-up for other physics, whose trajectory banks the next one reuses

    def __call__(self, policy=None, kind: str | None = None) -> float:
        import torch

        was_training = isinstance(policy, torch.nn.Module) and policy.training
        if was_training:
            policy.eval()
        try:
            runs = run_replay(self._replay_setup(policy is not None), policy, kind=kind)
        finally:
            if was_training:
                policy.train()
        rep = runs["residual"] if "residual" in runs else runs["pd"]
        self.last_diverged = sum(a >= 0 for a in rep.diverged_at)
        errors = np.concatenate([np.abs(q - t.q) for t, q in zip(self.trajectories, rep.q)])
        self.last_errors = errors.mean(0)
        return float(errors[:, self.mask].mean())

    def _replay_setup(self, with_policy: bool):
        """The replay's set-up (the simulator's physics, the trajectories on its device), made once for the physics
        given at construction and reused at every later check: the same physics give the same set-up, so only the
        rollout is repeated. Physics set later (a subclass scoring other parameters each call) are set up anew."""
        if self.physics is not self._fixed_physics:  # the recordings stay on the device, the command paths change
            self._loose = replay_setup(self.robot, self.trajectories, self.rate_hz, with_policy, sim=self.sim,
                                       delay=self.delay, physics=self.physics, reuse=self._loose)
            return self._loose
        if self._setup is None or self._setup[0] != with_policy:
            self._setup = (with_policy, replay_setup(self.robot, self.trajectories, self.rate_hz, with_policy,
                                                     sim=self.sim, delay=self.delay, physics=self.physics))
        return self._setup[1]
