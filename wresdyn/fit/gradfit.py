"""Gradient fit: train a residual by backpropagating through the differentiable Warp simulation.

Multiple shooting: each iteration samples B windows of H steps from the training recordings, starts each
window (one Newton world each) at the recorded state, rolls the simulation forward with the residual policy in
the loop, and minimises the joint position and velocity mismatch against the recording

    L = mean_k [ w_q |q_k − q_r,k|² + w_qd |q̇_k − q̇_r,k|² ] + w_τ |τ_res|² + w_rate |a_k − a_{k−1}|²,

the regularisers mirroring Table I's torque and action-rate penalties. Gradients come from a ``wp.Tape`` per
solver step, bridged into torch by :meth:`wresdyn.sim.Simulator.step_diff` (a ``torch.autograd.Function``):
torch's autograd walks the steps backwards and each step's tape turns the incoming state gradient into gradients
of the previous state and of the residual, all on the device (through torch views of each step's Warp buffers,
:mod:`wresdyn.sim.tape_step`).
Windows come from the simulation layer's :class:`~wresdyn.sim.TrajectoryBank` and run through its rollout driver
(:func:`wresdyn.sim.rollout`, ``grad=True``), the same code that evaluation replays with.

Model selection is made on the validation split: every ``select_every`` iterations the current residual replays
the validation trajectories open loop (whole trajectories, the evaluation's metric), and the fit returns the
residual with the lowest validation error. Held-out and OOD data are never read here. The loop itself (schedule,
resume, checkpoints, selection) is :func:`~wresdyn.learn.window_fit.run_window_fit`, shared with identification.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch

from ..learn.adam import Adam
from ..learn.fused_mlp import FusedMLPRollout, fusable
from ..learn.graph_step import StepGraphs, adopt_optimiser, set_lr
from ..learn.parametric import ParametricResidual
from ..learn.residual import EluMLP, GRUResidualPolicy, MLPResidualPolicy, ResidualConfig, export_run_files, obs_stats
from ..learn.runs import RunFolder
from ..learn.selection import ValidationScore
from ..learn.window_fit import joint_weights, run_window_fit, squared_error, start_window_fit
from ..sim import Simulator, TrajectoryBank, rollout
from ..sim.bank import servo_goal_accel
from ..sim.physics import PhysicalParams
from ..sim.residual_kinds import residual_scale
from .gradfit_config import GradFitConfig

__all__ = ["GradFitConfig", "build_policy", "window_loss", "fit", "export_run", "RESUME_MAY_CHANGE"]


def build_policy(robot, cfg: ResidualConfig, obs_mean, obs_std, model: str = "network"):
    """A fresh residual: a network (MLP with ELU, or GRU + MLP) as a :class:`~wresdyn.learn.residual.ResidualPolicy`,
    or the ``"parametric"`` baseline."""
    n = robot.n_dof
    if model == "parametric":
        return ParametricResidual(robot, residual_scale(robot, "torque", cfg.fraction))
    if model != "network":
        raise ValueError(f"unknown residual model {model!r}; choose 'network' or 'parametric'")
    scale = residual_scale(robot, cfg.kind, cfg.fraction)
    if cfg.arch == "gru":
        gru = torch.nn.GRU(4 * n, cfg.gru_hidden_dim, cfg.gru_layers)
        mlp = EluMLP(cfg.gru_hidden_dim, n, list(cfg.hidden_dims))
        policy = GRUResidualPolicy(gru, mlp, obs_mean, obs_std, scale, cfg.kind)
    else:
        mlp = EluMLP(4 * n, n, list(cfg.hidden_dims))
        policy = MLPResidualPolicy(mlp, obs_mean, obs_std, scale, cfg.kind)
    last = [m for m in mlp.modules() if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():  # start at PD-only
        last.weight.mul_(cfg.output_gain)
        last.bias.zero_()
    return policy


def window_loss(cfg: GradFitConfig, q, qd, actions, q_ref, qd_ref, scale,
                weights: torch.Tensor | None = None) -> tuple[torch.Tensor, dict]:
    """Multiple-shooting loss of one batch of windows (see module docstring); returns (loss, parts), the parts
    (``pos``, ``vel``, ``torque``, ``rate``) as detached scalar tensors (read them when needed: no host sync here).

    ``actions`` are normalised (B, H, n); ``scale`` turns them into residual torque [N·m] for the torque
    penalty (``None`` for a delta action, which applies no residual torque). ``weights`` (n,) weigh each joint's
    position and velocity error (0 for a joint the dataset excludes from fitting; ``None``: all 1).
    """
    pos, vel = squared_error(q, q_ref, weights), squared_error(qd, qd_ref, weights)
    tau = torch.zeros((), device=q.device)
    if scale is not None:
        tau = ((actions * scale) ** 2).sum(-1).mean()
    rate = ((actions[:, 1:] - actions[:, :-1]) ** 2).sum(-1).mean() if actions.shape[1] > 1 else tau * 0.0
    loss = cfg.w_q * pos + cfg.w_qd * vel + cfg.w_torque * tau + cfg.w_action_rate * rate
    parts = {"pos": pos, "vel": vel, "torque": tau, "rate": rate}
    return loss, {k: v.detach() for k, v in parts.items()}


RESUME_MAY_CHANGE = ("device", "torch_threads", "sim_threads", "cuda_graph", "fused_network", "network_tiles",
                     "max_iterations", "max_seconds", "beat_start_within")
""":class:`GradFitConfig` fields a resumed fit may change: where and how it runs (``fused_network`` and
``network_tiles`` change only the rounding) and the ceilings and early stop of a run until convergence, not what it
learns (``iterations`` shapes the learning-rate and horizon schedule, so it is part of what it learns)."""


def fit(robot, dataset, cfg: GradFitConfig, out: str | Path | None = None, log=print, until: int | None = None,
        stop_below: float | None = None, physics: PhysicalParams | None = None):
    """Fit a residual to ``dataset``'s training split by gradient descent through the simulation.

    Args:
        robot: The nominal robot (the simulator side).
        dataset: A :class:`wresdyn.data.dataset.Dataset` (only ``q``, ``qd``, ``qdd``, ``q_cmd`` are read; recorded
            torques never). Its ``validation`` split, when present, selects the returned residual.
        cfg: Settings.
        out: Optional run folder (:class:`~wresdyn.learn.runs.RunFolder`): ``config.json``, ``checkpoint.pt``
            (resumed if present; a changed config is refused), ``curve.json``.
        log: Progress printer.
        until: Stop (and checkpoint) after this many iterations of the schedule (horizon curriculum and learning
            rate), to resume later; ``None`` runs the whole schedule.
        stop_below: End the fit at the first validation check whose error is at or below this [rad] (time to
            fidelity, ``benchmarks/speed/time_to_fidelity.py``), returning the residual selected so far.
        physics: Physical parameters of the simulator (identified: the hybrid), with their command delay; ``None``
            = the robot file's. ``cfg.physics`` records where they came from.

    Returns:
        ``(policy, curve)``: the trained :class:`~wresdyn.learn.residual.ResidualPolicy` (the one with the lowest
        validation error when the dataset has a validation split, else the last) and the learning curve rows
        (iteration, wall-clock [s], simulated env-steps, loss parts, validation error where evaluated).
    """
    if cfg.physics and physics is None:
        raise ValueError(f"the config records physics from {cfg.physics} but none were given: pass "
                         "physics=PhysicalParams.load(...)")
    rng, train, dt = start_window_fit(cfg, dataset)
    learner = _FitLearner(robot, dataset, cfg, physics, rng, train, dt, log)
    run = RunFolder(out, dataclasses.asdict(cfg), RESUME_MAY_CHANGE, key="gradfit", record=run_record(cfg))
    curve = run_window_fit(cfg, learner, run, rng, log, until=until, stop_below=stop_below)
    return learner.policy.eval(), curve


class _FitLearner:
    """The gradient fit as a :class:`~wresdyn.learn.window_fit.WindowLearner`: the residual, Adam, the training
    windows and their observation noise, one :class:`GradFitIteration` per step."""

    name, what, parts, checkpoint_keys = "fit", "gradient fit", ("loss", "pos", "vel", "torque", "rate"), \
        ("policy", "optim", "noise_rng")

    def __init__(self, robot, dataset, cfg: GradFitConfig, physics, rng, train, dt: float, log) -> None:
        self.cfg, self.rng, self.log, self.physics = cfg, rng, log, physics
        self.n_obs = 4 * robot.n_dof
        self.policy = self.module = build_policy(robot, cfg.residual, *obs_stats(train), cfg.model).to(cfg.device)
        self.horizons = cfg.horizon_curriculum or (cfg.horizon,)
        self.sim = Simulator(robot, cfg.windows, dt, solver=cfg.solver, device=cfg.device, requires_grad=True,
                             friction_kappa=cfg.friction_kappa, solver_threads=cfg.sim_threads)
        self.deferred = cfg.cuda_graph and self.sim.device.type == "cuda"
        fused = cfg.network_paths(fusable(self.policy) is None)[0]
        self.optim = Adam(self.policy.parameters(), lr=cfg.lr, capturable=self.deferred, fused=fused or None)
        self.map_location = cfg.device
        delay = 0.0
        if physics is not None:
            self.sim.set_physics(physics)
            delay = torch.as_tensor(physics.delay / dt, dtype=torch.float32, device=self.sim.device)
        self.bank = TrajectoryBank(train, self.sim.device, delay, servo_goal_accel(robot, physics, dt, self.sim.device))
        validation = dataset.split("validation")
        self._score = ValidationScore(robot, validation, dataset.rate_hz, cfg.solver, cfg.device, physics=physics,
                                      weights=dataset.fit_weights(), friction_kappa=cfg.friction_kappa
                                      ) if validation else None
        weights = joint_weights(dataset, self.sim.device)
        self.obs_noise = cfg.obs_noise if cfg.model == "network" else 0.0  # the physical model has no normaliser
        self.noise_gen = torch.Generator(device=cfg.device)
        self.noise_gen.manual_seed(cfg.seed)
        self.sim_steps = 0
        self._iteration = GradFitIteration(cfg, self.sim, self.bank, self.policy, self.optim, self.obs_noise, self.deferred,
                                     weights)

    def begin(self, run: RunFolder) -> None:
        if self._score is None:
            self.log("no validation split: the fit returns its last iteration (`wresdyn migrate` adds one)")
        elif self.physics is not None:
            # on identified physics (the hybrid) the zero-residual start is a candidate too: the hybrid is never
            # selected worse than the identified model alone
            run.best.take(self._score(self.policy), 0, self.policy)
            self.log(f"validation at the start: {run.best.value:.4f} rad")

    def step(self, it: int, h: int, lr: float):
        cfg = self.cfg
        traj, start = self.bank.draw(self.rng, cfg.windows, h)
        noise = torch.stack([torch.randn((cfg.windows, self.n_obs), generator=self.noise_gen, device=self.sim.device)
                             for _ in range(h)]) if self.obs_noise > 0.0 else None
        parts = self._iteration(traj, start, h, noise, lr)
        self.sim_steps += cfg.windows * h * 2  # forward + backward through each step
        return {"sim_steps": self.sim_steps}, parts

    def score(self) -> float | None:
        return None if self._score is None else self._score(self.policy)

    def state(self) -> dict:
        return {"policy": self.policy.state_dict(), "optim": self.optim.state_dict(),
                "noise_rng": self.noise_gen.get_state()}

    def meta(self) -> dict:
        return {"sim_steps": self.sim_steps}

    def restore(self, data: dict) -> None:
        self.policy.load_state_dict(data["policy"])
        self.optim.load_state_dict(data["optim"])
        self.noise_gen.set_state(data["noise_rng"].cpu())
        self.sim_steps = data["meta"]["sim_steps"]
        self._iteration.adopt_optimiser()


class GradFitIteration:
    """One optimiser step of the fit: windows of ``h`` steps at (trajectory, start) (B,) each, the rollout with the
    residual in the loop, the loss, the backward pass (torch's autograd through each step's Warp tape), gradient
    clipping and Adam. A call returns the loss and its parts (:attr:`_FitLearner.parts`) as one tensor (5,) on the
    device, without waiting for it.

    With ``graph`` (CUDA) every call runs on the simulator's own stream and, from the second call at a window
    length on, is replayed from a CUDA graph captured for that length: torch's capture, which the Warp launches
    of the solver steps and of their tapes join as an external capture (forward and backward on the same stream,
    :meth:`~wresdyn.sim.Simulator._tape_stream`), Adam ``capturable`` with the learning rate a device tensor. The
    first call at each length runs eagerly on that stream (it loads kernels and creates Adam's state and
    torch's workspaces, which a capture must not). The window indices and the observation noise enter through
    fixed buffers; the gradients live in each graph's memory pool (:class:`~wresdyn.learn.graph_step.StepGraphs`,
    shared with identification). Without ``graph`` the same code runs eagerly.
    Where ``cfg.fused_network`` resolves on (:meth:`GradFitConfig.network_paths`: on CUDA by default) the rollout runs
    the MLP as :class:`~wresdyn.learn.fused_mlp.FusedMLPRollout`, whose
    :meth:`~wresdyn.learn.fused_mlp.FusedMLPRollout.finish` forms the parameters' gradients after the backward pass.
    """

    def __init__(self, cfg: GradFitConfig, sim, bank, policy, optim, obs_noise: float, graph: bool,
                 weights: torch.Tensor | None = None) -> None:
        self.cfg, self.sim, self.bank, self.policy, self.optim = cfg, sim, bank, policy, optim
        self.obs_noise, self.graph, self.weights = obs_noise, graph, weights
        self.torque_scale = policy.scale if policy.kind == "torque" else None
        fused, tiles = cfg.network_paths(fusable(policy) is None)
        self.fused = FusedMLPRollout(policy, tiles=tiles) if fused else None
        self._graphs = StepGraphs(sim)
        self.adopt_optimiser()

    def adopt_optimiser(self) -> None:
        """Put Adam's learning rate and step count where this mode wants them (a device tensor with ``graph``, a
        float and a CPU tensor without); again after a resumed optimiser state is loaded."""
        adopt_optimiser(self.optim, self.sim.device, self.graph, self.fused is not None)

    def gradients(self, traj, start, h: int, noise) -> tuple[torch.Tensor, dict]:
        """The rollout of the windows at (``traj``, ``start``) (B,) of ``h`` steps, its loss and the backward pass: the
        parameters' ``.grad`` hold the loss's gradient (added to what they held), before the clip. Returns ``(loss,
        parts)`` as :func:`window_loss`."""
        window = self.bank.window(traj, start, h)
        if self.fused is not None:
            self.fused.begin(h, window.cmd.shape[0])
        run = rollout(self.sim, window, self.policy if self.fused is None else self.fused, grad=True,
                      truncation=self.cfg.grad_truncation or 0, obs_noise=self.obs_noise, noise=noise)
        loss, parts = window_loss(self.cfg, run.q[:, 1:], run.qd[:, 1:], run.actions, window.q[:, 1:],
                                  window.qd[:, 1:], self.torque_scale, self.weights)
        loss.backward()
        if self.fused is not None:
            self.fused.finish()
        return loss, parts

    def _run(self, traj, start, h: int, noise) -> torch.Tensor:
        loss, parts = self.gradients(traj, start, h, noise)
        torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.cfg.grad_clip)
        self.optim.step()
        return torch.stack([loss.detach(), *(parts[k] for k in _FitLearner.parts[1:])])

    def __call__(self, traj, start, h: int, noise, lr: float) -> torch.Tensor:
        for group in self.optim.param_groups:
            set_lr(group, lr)
        if not self.graph:
            self.optim.zero_grad()
            return self._run(traj, start, h, noise)

        def run(traj, start, noise):
            self.optim.zero_grad()  # to None: the captured backward allocates the gradients in the graph's pool
            return self._run(traj, start, h, noise)
        return self._graphs(h, run, traj, start, noise)


def run_record(cfg: GradFitConfig) -> dict:
    """What ``config.json`` of a gradient-fit run holds beside the config itself (under ``gradfit``): the learner and
    the replay settings in the layout of a PPO run (``config.env``, ``config.residual``), which ``wresdyn eval``
    reads."""
    kind = "torque" if cfg.model == "parametric" else cfg.residual.kind  # the parametric model is a torque residual
    residual = {**dataclasses.asdict(cfg.residual), "kind": kind}
    if cfg.model == "parametric":
        residual["arch"] = "mlp"  # no network; keeps the PPO config layout valid
    return {"learner": "parametric" if cfg.model == "parametric" else "gradient",
            "config": {"env": {"solver": cfg.solver, "substeps": 1, "friction_kappa": cfg.friction_kappa},
                       "residual": residual}}


def export_run(policy, out: str | Path, cfg: GradFitConfig, dataset, data_path: str | Path | None = None,
               physics: PhysicalParams | None = None, onnx_later: bool = False, archive_later: bool = False):
    """Write the run files ``wresdyn eval`` reads: ``config.json`` (:func:`run_record`, the gradient-fit config
    under ``gradfit``, ``data_path``), ``policy.pt``, ``policy.onnx``, ``residual.json``, and ``physics.json`` when
    the residual was fitted on ``physics`` (evaluation replays with them). With ``onnx_later`` every file but
    ``policy.onnx`` is written and the function that writes it is returned (``export_run_files``'s), with
    ``archive_later`` neither ``policy.pt`` nor ``policy.onnx`` (the picklable call that writes both is returned),
    else ``None``."""
    out = Path(out)
    policy = policy.cpu().eval()
    record = {**run_record(cfg), "data_path": str(data_path) if data_path else None}
    RunFolder(out, dataclasses.asdict(cfg), key="gradfit", record=record).write_config()
    arch = "parametric" if cfg.model == "parametric" else cfg.residual.arch
    write_onnx = export_run_files(policy, out, dataset, onnx_later=onnx_later, archive_later=archive_later, arch=arch,
                                  learner=record["learner"])
    if physics is not None:
        physics.save(out / "physics.json")
    return write_onnx
