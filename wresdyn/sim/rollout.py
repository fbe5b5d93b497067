"""Open-loop rollouts of recorded commands with a residual in the loop: the one driver every replay goes through.

:func:`rollout` advances a :class:`~wresdyn.sim.simulator.Simulator` through a :class:`~wresdyn.sim.bank.Window`:
at each step the residual policy observes [q, q̇, q̈, q_cmd] of the simulated state and the recorded command,
its output is applied (:func:`~wresdyn.sim.residual_kinds.apply_residual`) to the step's PD target (the command after
the command path's delay), and the solver advances one sample period. Evaluation runs it without gradients
(diverged worlds are frozen at their last sane state and reported), the gradient fit with ``grad=True``
(each step differentiable, truncated backpropagation), and :func:`replay` is the numpy form for PD-only checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from ..errors import SimulationDiverged
from .bank import TrajectoryBank, Window, servo_goal_accel
from .physics import PhysicalParams
from .residual_kinds import apply_residual, observation
from .rollout_graph import capture_blocker, rollout_key, run_captured
from .simulator import DivergenceLimits, Simulator
from .tape_chain import chained_rollout, chains
from .tape_step import stage_targets, step_forces

__all__ = ["Rollout", "Replays", "rollout", "replay", "replay_trajectories", "replay_setup", "run_replay",
           "ReplaySetup", "policy_device"]


@dataclass
class Rollout:
    """Simulated trajectories of a window batch."""

    q: torch.Tensor
    """Joint positions [rad], (B, L + 1, n): the start state, then the state after each step."""
    qd: torch.Tensor
    """Joint velocities [rad/s], (B, L + 1, n)."""
    actions: torch.Tensor | None
    """Normalised residual (residual / scale) of the policy's worlds, (B_policy, L, n); ``None`` without one."""
    diverged_at: torch.Tensor
    """First step whose state diverged, (B,) long, −1 if never. From there a world holds its last state
    before divergence with zero velocity (the error to the recording keeps counting)."""


def policy_device(policy) -> torch.device | None:
    """Device of a torch module's parameters or buffers (``None`` for a plain callable or an empty module)."""
    if isinstance(policy, torch.nn.Module):
        for t in list(policy.parameters()) + list(policy.buffers()):
            return t.device
    return None


def _policy_kind(policy, kind: str | None) -> str:
    if kind is not None:
        return kind
    k = getattr(policy, "kind", None)
    if k is None and hasattr(policy, "residual_kind"):
        k = policy.residual_kind()  # an exported residual (wresdyn.learn.network_file)
    if k is None:
        raise ValueError("the residual kind is unknown: pass kind='torque' or 'delta_action'")
    return k


def rollout(sim: Simulator, window: Window, policy=None, *, kind: str | None = None,
            policy_worlds: slice | None = None, residual: torch.Tensor | None = None, grad: bool = False,
            truncation: int = 0, obs_noise: float = 0.0, generator: torch.Generator | None = None,
            noise: torch.Tensor | None = None, limits: DivergenceLimits = DivergenceLimits(),
            on_diverge: str = "freeze", graph: bool | None = None, branch_free: bool | None = None) -> Rollout:
    """Replay ``window`` open loop from its recorded start state, with an optional residual in the loop.

    Args:
        sim: The simulator, ``sim.num_worlds`` equal to the window batch B.
        window: Start states, commands and PD targets (:meth:`~wresdyn.sim.bank.TrajectoryBank.window`).
        policy: Residual ``policy(obs (N, 4n)) -> residual (N, n)`` [N*m or rad] (attributes ``kind`` or a
            ``residual_kind()`` of an exported one, optional ``reset()``, ``scale``, ``obs_std``, and
            ``residual_and_action(obs) -> (residual, residual / scale)``), or ``None``.
        kind: Residual kind; default the policy's.
        policy_worlds: Worlds the policy acts on (default all); the others run PD only in the same batch.
        residual: Instead of a policy, a precomputed open-loop residual of ``kind`` (B, L, n).
        grad: Differentiable rollout (``sim.requires_grad``): no divergence handling; a diverged state
            shows up as a non-finite result.
        truncation: With ``grad``, detach the state (and a GRU's hidden state) every this many steps; 0 = never.
        obs_noise: Std of Gaussian noise on the policy's observation, in units of ``policy.obs_std``.
        generator: Torch generator of that noise.
        noise: The standard normal draws of that noise given up front, (L, B_policy, 4n), instead of drawing from
            ``generator`` at each step (a captured CUDA graph reads them from a fixed buffer).
        limits: When a world counts as diverged (``max_error`` against the window's recording).
        on_diverge: ``"freeze"`` (hold the last sane state, report in ``diverged_at``) or ``"raise"``
            (:class:`~wresdyn.errors.SimulationDiverged`, for the first world to diverge).
        graph: Without ``grad`` on CUDA, capture the whole loop as one CUDA graph and replay it on later calls
            (:mod:`wresdyn.sim.rollout_graph`, where it applies); default ``sim.rollout_graph``.
        branch_free: Without ``grad``, track divergence with masks on every world at every step instead of reading
            the host (the same results, bit for bit); a raise then comes after the whole window. A captured loop is
            branch-free whatever this says; elsewhere the host-read loop is the default (the faster on the CPU).
    """
    b = window.cmd.shape[0]
    if b != sim.num_worlds:
        raise ValueError(f"window batch {b} != simulator worlds {sim.num_worlds}")
    if on_diverge not in ("freeze", "raise"):
        raise ValueError(f"on_diverge must be 'freeze' or 'raise', not {on_diverge!r}")
    kind = _policy_kind(policy, kind) if policy is not None else (kind or "torque")
    pdev = policy_device(policy)
    if noise is not None and obs_noise > 0.0:
        noise = obs_noise * policy.obs_std * noise  # scaled once for the window, not per step

    captured = capture_blocker(sim.device, grad=grad, enabled=sim.rollout_graph if graph is None else graph,
                               policy=policy, policy_device=pdev, obs_noise=obs_noise, noise=noise) is None

    def body(win: Window, noise: torch.Tensor | None, residual: torch.Tensor | None,
             masked: bool = bool(branch_free) and not grad) -> Rollout:
        return _loop(sim, win, policy, kind, policy_worlds, residual, grad, truncation, obs_noise, generator, noise,
                     limits, pdev, masked, on_diverge)

    if captured:
        key = rollout_key(sim, window, policy, kind, policy_worlds, residual, obs_noise, noise, limits)
        out = run_captured(sim, key, window, noise, residual, body, keep=policy)
    else:
        out = body(window, noise, residual)
    if on_diverge == "raise" and (captured or (branch_free and not grad)):  # a branch-free loop raises here: the
        # host-read one raised at its step already, and a read of every world here would be one more wait
        hit = out.diverged_at >= 0
        if hit.any():  # the first step any world diverged at, and the first world diverging then
            k = int(out.diverged_at[hit].min())
            _raise(sim, int((out.diverged_at == k).nonzero()[0]), k)
    return out


def _raise(sim: Simulator, world: int, step: int) -> None:
    raise SimulationDiverged(f"{sim.robot.source.name}: Newton replay diverged in world {world} at step {step} "
                             f"(t = {step * sim.dt:.3f} s)")


def _loop(sim: Simulator, window: Window, policy, kind: str, policy_worlds: slice | None,
          residual: torch.Tensor | None, grad: bool, truncation: int, obs_noise: float,
          generator: torch.Generator | None, noise: torch.Tensor | None, limits: DivergenceLimits,
          pdev: torch.device | None, masked: bool, on_diverge: str) -> Rollout:
    """The step loop of :func:`rollout`. ``masked``: branch-free (no host read; every world's divergence bookkeeping
    runs through masks at every step), so it runs inside a CUDA graph; the raise is then the caller's."""
    b, steps = window.cmd.shape[0], window.steps
    pw = slice(None) if policy_worlds is None else policy_worlds
    active = policy is not None or residual is not None
    if policy is not None and hasattr(policy, "reset"):
        policy.reset()
    scale = getattr(policy, "scale", None)
    q, qd, qdd = window.q[:, 0], window.qd[:, 0], window.qdd[:, 0]
    qs, qds, actions = [q], [qd], []
    dead = torch.zeros(b, dtype=torch.bool, device=sim.device)
    diverged_at = torch.full((b,), -1, dtype=torch.long, device=sim.device)
    if not grad:
        sim.set_state(None, q, qd)
        bounds = (sim.lower - limits.limit_margin, sim.upper + limits.limit_margin)  # once, not at every step
    # a differentiable step reads targets staged in its buffers without a copy of its own (one copy, not one a step),
    # and a torque residual its policy wrote straight into them (residual_and_action's out)
    targets = stage_targets(sim, window.target) if grad and (not active or kind == "torque") else None
    both = getattr(policy, "residual_and_action", None) if scale is not None else None
    forces = step_forces(sim, steps) if grad and both is not None and kind == "torque" and policy_worlds is None \
        and pdev in (None, sim.device) else None
    # a policy that forms its observation from the state itself (the tile kernels), where its torque goes in place
    state = forces is not None and getattr(policy, "takes_state", False) and (obs_noise == 0.0 or noise is not None)
    before = None  # q̇ of the step before, for such a policy's q̈
    if state and targets is not None and chains(sim, policy):  # one autograd node for the whole window
        q_all, qd_all, act = chained_rollout(sim, window, policy, targets, forces, noise if obs_noise > 0.0 else None,
                                             truncation)
        return Rollout(q_all, qd_all, act, diverged_at)
    for k in range(steps):
        res = None
        if state:
            r, a = policy.residual_and_action_from_state(q, qd, before, qdd, window.cmd[:, k],
                                                         noise if obs_noise > 0.0 else None, sim.dt, forces[k])
            actions.append(a)
            res = r
        elif policy is not None:
            # all worlds: the tensors themselves, not a full slice of each, whose backward would allocate and fill a
            # copy of every step's gradient (three per step)
            obs = (observation(q, qd, qdd, window.cmd[:, k]) if policy_worlds is None
                   else observation(q[pw], qd[pw], qdd[pw], window.cmd[pw, k]))
            if obs_noise > 0.0:
                obs = obs + (noise[k] if noise is not None else obs_noise * policy.obs_std * torch.randn(
                    obs.shape, generator=generator, device=obs.device))
            x = obs if pdev is None else obs.to(pdev)
            with torch.set_grad_enabled(grad and torch.is_grad_enabled()):  # both: (r, r / scale) in one node
                r, a = (policy(x), None) if both is None else both(x, None if forces is None else forces[k])
            r = r.to(sim.device)
            if scale is not None:
                actions.append(r / scale.to(r.device) if a is None else a.to(sim.device))
            res = r if policy_worlds is None else torch.zeros_like(q).index_put_(
                (torch.arange(b, device=sim.device)[pw],), r)
        elif residual is not None:
            res = residual[:, k]
        target = window.target[:, k] if targets is None else targets[k]
        target, tau = apply_residual(target, res, kind) if active else (target, None)
        if grad:
            q_new, qd_new = sim.step_diff(k, q, qd, target, tau)
        else:
            q_new, qd_new = sim.step(target, tau)
            # on bools a > b is a and not b, in one kernel
            bad = sim.diverged(q_new, qd_new, limits, window.q[:, k + 1], bounds) > dead
            if masked:  # frozen worlds hold their last sane state at rest; keeps NaN out of the solver and the policy
                dead = dead | bad
                diverged_at = torch.where(bad, k + 1, diverged_at)
                q_new = torch.where(dead[:, None], q, q_new)
                qd_new.masked_fill_(dead[:, None], 0.0)  # the step's own copy: one kernel, not a zeros and a where
                sim.set_state_where(dead, q_new, qd_new)
            else:  # the same, read on the host: the faster on the CPU, where a read costs nothing
                if bad.any():
                    if on_diverge == "raise":
                        _raise(sim, int(bad.nonzero()[0]), k + 1)
                    dead |= bad
                    diverged_at[bad] = k + 1
                if dead.any():
                    q_new = torch.where(dead[:, None], q, q_new)
                    qd_new = torch.where(dead[:, None], torch.zeros_like(qd_new), qd_new)
                    sim.set_state(dead.nonzero().squeeze(-1), q_new[dead], qd_new[dead])
        if policy is not None and not state:  # the policy's observation is what reads it
            qdd = (qd_new - qd) / sim.dt
        q, qd, before = q_new, qd_new, qd
        qs.append(q)
        qds.append(qd)
        if grad and truncation and (k + 1) % truncation == 0:
            q, qd, qdd, before = q.detach(), qd.detach(), qdd.detach(), before.detach()
            if isinstance(getattr(policy, "hidden", None), torch.Tensor):
                policy.hidden = policy.hidden.detach()
    return Rollout(torch.stack(qs, 1), torch.stack(qds, 1), torch.stack(actions, 1) if actions else None, diverged_at)


def replay(robot, q_cmd: np.ndarray, q0: np.ndarray, qd0: np.ndarray | None = None, dt: float = 0.002,
           solver: str = "auto", tau_res: np.ndarray | None = None, device: str | None = "cpu",
           ) -> tuple[np.ndarray, np.ndarray]:
    """Open-loop PD replay of joint commands in Newton, one world per trajectory (numpy in and out).

    Args:
        robot: The robot.
        q_cmd: Commanded joint positions [rad], shape (T, n_dof) or (W, T, n_dof); command k is held during step k.
        q0: Initial joint positions [rad], shape (n_dof,) or (W, n_dof).
        qd0: Initial joint velocities [rad/s], same shape as ``q0`` (default zero).
        dt: Time step [s].
        solver: Solver kind (:data:`wresdyn.sim.solvers.SOLVERS`).
        tau_res: Optional residual joint torque [N*m] added each step, shape like ``q_cmd``.
        device: Warp device.

    Returns:
        ``(q, qd)``, each shape (T + 1, n_dof) or (W, T + 1, n_dof): the initial state, then the state after
        each step.

    Raises:
        SimulationDiverged: the state became non-finite.
    """
    single = np.ndim(q_cmd) == 2
    q_cmd = np.asarray(q_cmd)[None] if single else np.asarray(q_cmd)
    w, _, n = q_cmd.shape
    q0 = np.broadcast_to(q0, (w, n))
    qd0 = np.zeros((w, n)) if qd0 is None else np.broadcast_to(qd0, (w, n))
    sim = Simulator(robot, w, dt, solver=solver, device=device)
    window = Window.from_arrays(q0, qd0, q_cmd, sim.device)
    res = None if tau_res is None else torch.as_tensor(np.asarray(tau_res).reshape(q_cmd.shape), dtype=torch.float32,
                                                         device=sim.device)
    only_nan = DivergenceLimits(max_qd=math.inf, limit_margin=math.inf)
    out = rollout(sim, window, residual=res, kind="torque", limits=only_nan, on_diverge="raise")
    q, qd = out.q.cpu().double().numpy(), out.qd.cpu().double().numpy()
    q[:, 0], qd[:, 0] = q0, qd0  # exact initial state (float64), as given
    return (q[0], qd[0]) if single else (q, qd)


@dataclass
class Replays:
    """Simulated trajectories of one split, one entry per recorded trajectory."""

    q: list[np.ndarray]
    """Joint positions [rad], each (T_i, n_dof); sample 0 is the recorded start state."""
    qd: list[np.ndarray]
    """Joint velocities [rad/s], each (T_i, n_dof)."""
    diverged_at: list[int]
    """Sample at which each replay diverged, −1 if it did not."""


def replay_trajectories(robot, trajectories, rate_hz: float, policy=None, *, kind: str | None = None,
                        solver: str = "auto", substeps: int = 1, device: str | None = "cpu", with_baseline: bool = False,
                        delay=0.0, sim: Simulator | None = None, physics=None, friction_kappa: float | None = None
                        ) -> dict[str, Replays]:
    """Replay every trajectory open loop from its first recorded state, PD only and/or with ``policy``.

    Args:
        robot: The robot (the simulator side).
        trajectories: Recorded trajectories (``q``, ``qd``, ``qdd``, ``q_cmd``; ``tau`` is never read).
        rate_hz: Sample rate of the recordings [Hz]; command k is held for one sample period.
        policy: Residual ``policy(obs) -> residual`` or ``None`` for PD only.
        kind: ``"torque"`` or ``"delta_action"``; default the policy's.
        solver, substeps, device, friction_kappa: Simulation settings (``friction_kappa``: the replay solver's dry
            friction law, :class:`~wresdyn.sim.Simulator`), for a new simulator.
        with_baseline: Also run PD only, in extra worlds of the same batch.
        delay: Command-path delay of the simulator [steps] (see :mod:`wresdyn.sim.bank`).
        sim: A simulator to reuse (its world count must match), e.g. for repeated validation.
        physics: Physical parameters of the model (:class:`~wresdyn.sim.physics.PhysicalParams`, e.g. identified
            by ``wresdyn identify``) for the ``"residual"`` worlds, whose command delay then is ``physics.delay``;
            the ``"pd"`` baseline keeps the robot file's. With ``physics`` and no policy, ``"residual"`` is the
            calibrated model under PD alone.

    Returns:
        ``{"pd": Replays, "residual": Replays}`` (``"residual"`` absent without a policy or physics, ``"pd"``
        without the baseline).
    """
    setup = replay_setup(robot, trajectories, rate_hz, policy is not None, solver=solver, substeps=substeps,
                         device=device, with_baseline=with_baseline, delay=delay, sim=sim, physics=physics,
                         friction_kappa=friction_kappa)
    return run_replay(setup, policy, kind=kind)


@dataclass
class ReplaySetup:
    """What :func:`replay_trajectories` prepares before its rollout: the simulator (its physics set), the whole
    trajectories as one window on its device and where the model's worlds are. A caller that replays the same
    trajectories with the same physics again (validation at every check) keeps it and calls :func:`run_replay`."""

    sim: Simulator
    window: Window
    """The worlds' trajectories, ``len(groups)`` copies of the recordings side by side."""
    policy_worlds: slice | None
    """The worlds the policy drives (the model's), ``None``: all."""
    groups: list
    """``"pd"`` and/or ``"residual"``, in world order."""
    lengths: list
    """Each trajectory's sample count."""
    banks: tuple = ()
    """The trajectory banks the window was cut from (the nominal's, the model's): :func:`replay_setup`'s ``reuse``
    sets their command paths anew instead of uploading the recordings again."""


def replay_setup(robot, trajectories, rate_hz: float, with_policy: bool, *, solver: str = "auto", substeps: int = 1,
                 device: str | None = "cpu", with_baseline: bool = False, delay=0.0, sim: Simulator | None = None,
                 physics=None, friction_kappa: float | None = None, reuse: ReplaySetup | None = None) -> ReplaySetup:
    """The set-up of :func:`replay_trajectories` (same arguments, ``with_policy``: whether a policy will drive the
    model's worlds): the simulator, its physics and the trajectories' window on the device. ``reuse``: an earlier
    set-up of the same trajectories on ``sim`` whose banks take the new command paths (the recordings are on the
    device already); the same window as a fresh set-up."""
    trajectories = list(trajectories)
    model = with_policy or physics is not None
    groups = (["pd"] if with_baseline or not model else []) + (["residual"] if model else [])
    w = len(trajectories)
    if sim is None or sim.num_worlds != w * len(groups):
        sim = Simulator(robot, w * len(groups), 1.0 / rate_hz, solver=solver, substeps=substeps, device=device,
                        friction_kappa=friction_kappa)
    pw = slice(groups.index("residual") * w, (groups.index("residual") + 1) * w) if len(groups) == 2 else None
    old = reuse.banks if reuse is not None and reuse.sim is sim and reuse.groups == groups else ()

    def bank(i: int, delay, accel) -> TrajectoryBank:
        if i < len(old):
            old[i].set_command_path(delay, accel)
            return old[i]
        return TrajectoryBank(trajectories, sim.device, delay, accel)

    if physics is None:
        banks = (bank(0, delay, servo_goal_accel(robot, None, 1.0 / rate_hz, sim.device)),)
        window = banks[0].whole().repeat(len(groups))
    else:
        mw = slice(None) if pw is None else pw
        if pw is not None:
            sim.set_physics(PhysicalParams.nominal(robot), worlds=slice(0, w))
        sim.set_physics(physics, worlds=mw)
        model_delay = torch.as_tensor(np.asarray(physics.delay) * rate_hz, dtype=torch.float32, device=sim.device)
        nominal_accel, model_accel = (servo_goal_accel(robot, p, 1.0 / rate_hz, sim.device) for p in (None, physics))
        banks = ((bank(0, delay, nominal_accel),) if pw is not None else ()) \
            + (bank(1 if pw is not None else 0, model_delay, model_accel),)
        parts = [b.whole() for b in banks]
        window = Window(*(torch.cat([getattr(p, f) for p in parts]) for f in ("q", "qd", "qdd", "cmd", "target",
                                                                               "length")))
    return ReplaySetup(sim, window, pw, groups, [len(t.q) for t in trajectories], banks)


def run_replay(setup: ReplaySetup, policy=None, *, kind: str | None = None) -> dict[str, Replays]:
    """The rollout of :func:`replay_trajectories` on a :func:`replay_setup` (made with ``with_policy`` as
    ``policy is not None``); the same result."""
    sim, window, pw, groups, lengths = setup.sim, setup.window, setup.policy_worlds, setup.groups, setup.lengths
    w = len(lengths)
    with torch.no_grad():
        out = rollout(sim, window, policy, kind=kind, policy_worlds=pw)
    q, qd = out.q.cpu().double().numpy(), out.qd.cpu().double().numpy()
    at = out.diverged_at.cpu().numpy()
    return {g: Replays([q[i * w + j, :lengths[j]] for j in range(w)], [qd[i * w + j, :lengths[j]] for j in range(w)],
                       [int(a) if 0 <= a < lengths[j] else -1 for j, a in enumerate(at[i * w:(i + 1) * w])])
            for i, g in enumerate(groups)}
