"""Gradient fit: train a residual by backpropagating through the differentiable Warp simulation.

Multiple shooting: each iteration samples B windows of H steps from the training recordings, starts each
window (one Newton world each) at the recorded state, rolls the simulation forward with the residual policy in
the loop, and minimises the joint position and velocity mismatch against the recording

    L = mean_k [ w_q |q_k − q_r,k|² + w_qd |q̇_k − q̇_r,k|² ] + w_τ |τ_res|² + w_rate |a_k − a_{k−1}|²,

the regularisers mirroring Table I's torque and action-rate penalties. Gradients come from a ``wp.Tape`` per
solver step, bridged into torch by :class:`SimStep` (a ``torch.autograd.Function``): torch's autograd walks the
steps backwards and each step's tape turns the incoming state gradient into gradients of the previous state and
of the residual, all on the device (``wp.from_torch`` / ``wp.to_torch`` are zero-copy).
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from .residual import ResidualConfig, obs_stats, observation, residual_scale

__all__ = ["GradFitConfig", "DiffReplay", "SimStep", "build_policy", "rollout", "window_loss", "fit", "export_run"]


@dataclass(frozen=True)
class GradFitConfig:
    """Gradient fit settings (defaults: a small CPU run on the shipped data)."""

    residual: ResidualConfig = ResidualConfig()
    """Residual kind (torque / delta action), network (MLP / GRU) and authority (0.5 of each effort limit, as
    for PPO: held-out 3.09x vs 2.97x at 0.25, both with ``obs_noise`` 0.1)."""
    model: str = "network"
    """``"network"`` (``residual``'s MLP or GRU) or ``"parametric"`` (per-joint gain scales, damping, friction,
    armature: :class:`wresdyn.learn.parametric.ParametricResidual`, a torque residual)."""
    horizon: int = 64
    """Window length H [steps] (at 500 Hz, 64 steps = 128 ms) when there is no curriculum."""
    horizon_curriculum: tuple[int, ...] = (2, 4, 8, 16, 32, 64)
    """Window lengths stepped through in equal parts of training; empty = always ``horizon``. Doubling
    matters: a residual fitted on 4-step windows can make the 16-step closed loop unstable, and training
    does not recover from there."""
    grad_truncation: int = 16
    """Truncated backpropagation: gradients flow through at most this many steps [steps] (the state is
    detached every ``grad_truncation`` steps; the rollout and its loss still span the whole window). Through
    stiff PD dynamics, longer gradient paths explode; 0 = never truncate."""
    windows: int = 32
    """Parallel windows B (Newton worlds) per iteration."""
    iterations: int = 2000
    """Optimiser steps."""
    lr: float = 1e-3
    """Adam learning rate at the start."""
    lr_final: float = 1e-4
    """Learning rate at the last iteration (cosine decay from ``lr``)."""
    w_q: float = 1.0
    """Weight of the joint position error [1/rad²]."""
    w_qd: float = 0.01
    """Weight of the joint velocity error [s²/rad²]."""
    w_torque: float = 0.5e-5
    """Weight of |τ_res|² [1/(N·m)²] (Table I joint torque)."""
    w_action_rate: float = 0.5e-4
    """Weight of |a_k − a_{k−1}|² in normalised action units (Table I action rate)."""
    grad_clip: float = 1.0
    """Global gradient-norm clip."""
    obs_noise: float = 0.1
    """Gaussian noise added to the policy's observation during training, in units of each channel's
    normalising std (the simulation itself is not perturbed). A regulariser: with 16 training recordings the
    network otherwise fits the training windows' states too closely (open-loop error 4x below PD-only on the
    training trajectories against 2.9x held-out); 0 = off. Not applied to the parametric model."""
    solver: str = "auto"
    """Newton solver (:data:`wresdyn.sim.solvers.SOLVERS`); must be differentiable."""
    device: str = "cpu"
    """Warp / torch device."""
    seed: int = 0
    """Seed of the window sampler and network initialisation."""


def build_policy(robot, cfg: ResidualConfig, obs_mean, obs_std, model: str = "network"):
    """A fresh residual: a network (MLP with ELU, or GRU + MLP) as a :class:`~wresdyn.learn.residual.ResidualPolicy`,
    or the ``"parametric"`` baseline."""
    from rsl_rl.modules.mlp import MLP

    from .residual import GRUResidualPolicy, MLPResidualPolicy

    n = robot.n_dof
    if model == "parametric":
        from .parametric import ParametricResidual

        return ParametricResidual(robot, residual_scale(robot, dataclasses.replace(cfg, kind="torque")))
    if model != "network":
        raise ValueError(f"unknown residual model {model!r}; choose 'network' or 'parametric'")
    scale = residual_scale(robot, cfg)
    if cfg.arch == "gru":
        gru = torch.nn.GRU(4 * n, cfg.gru_hidden_dim, cfg.gru_layers)
        mlp = MLP(cfg.gru_hidden_dim, n, list(cfg.hidden_dims), "elu")
        policy = GRUResidualPolicy(gru, mlp, obs_mean, obs_std, scale, cfg.kind)
    else:
        mlp = MLP(4 * n, n, list(cfg.hidden_dims), "elu")
        policy = MLPResidualPolicy(mlp, obs_mean, obs_std, scale, cfg.kind)
    last = [m for m in mlp.modules() if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():  # start at PD-only
        last.weight.mul_(cfg.output_gain)
        last.bias.zero_()
    return policy


class DiffReplay:
    """B Newton worlds of one fixed-base robot with per-step states kept for the backward pass.

    Step k reads ``states_in[k]`` and writes ``states_out[k]``; separate buffers keep each step's tape valid.
    """

    def __init__(self, robot, worlds: int, horizon: int, dt: float, solver: str = "auto", device: str = "cpu") -> None:
        import warp as wp

        from ..sim.solvers import make_solver, resolve_solver

        if robot.base != "fixed":
            raise ValueError("the gradient fit replays fixed-base recordings")
        kind = resolve_solver(robot, dt, solver)
        if kind == "mujoco":
            raise ValueError(f"{robot.source.name}: SolverMuJoCo is not differentiable; the gradient fit needs "
                             "a differentiable solver (add armature so Featherstone is stable)")
        self.robot, self.worlds, self.dt, self.device = robot, worlds, dt, device
        self.model = robot.build_model(worlds, device, requires_grad=True)
        self.solver = make_solver(self.model, robot, dt, kind)
        self.nq = self.model.joint_coord_count // worlds
        self.nqd = self.model.joint_dof_count // worlds
        self.q_index = torch.as_tensor(robot.q_index, device=device)
        self.qd_index = torch.as_tensor(robot.qd_index, device=device)
        self.states_in, self.states_out, self.controls = [], [], []
        self.ensure_horizon(horizon)
        self._wp = wp

    def ensure_horizon(self, horizon: int) -> None:
        while len(self.states_in) < horizon:
            self.states_in.append(self.model.state(requires_grad=True))
            self.states_out.append(self.model.state(requires_grad=True))
            self.controls.append(self.model.control(requires_grad=True))

    def scatter(self, x: torch.Tensor, index: torch.Tensor, width: int) -> torch.Tensor:
        """Actuated-joint values (B, n) -> a flat per-world array (B*width,) with zeros elsewhere."""
        full = torch.zeros(self.worlds, width, dtype=torch.float32, device=x.device)
        full[:, index] = x.to(torch.float32)
        return full.reshape(-1)


class SimStep(torch.autograd.Function):
    """One differentiable solver step: (q, q̇, PD target, joint torque) -> (q', q̇'), each (B, n_dof)."""

    @staticmethod
    def forward(ctx, q, qd, target, tau, sim: DiffReplay, k: int):
        wp = sim._wp
        s_in, s_out, ctrl = sim.states_in[k], sim.states_out[k], sim.controls[k]
        wp.copy(s_in.joint_q, wp.from_torch(sim.scatter(q, sim.q_index, sim.nq)))
        wp.copy(s_in.joint_qd, wp.from_torch(sim.scatter(qd, sim.qd_index, sim.nqd)))
        wp.copy(ctrl.joint_target_q, wp.from_torch(sim.scatter(target, sim.qd_index, sim.nqd)))
        wp.copy(ctrl.joint_f, wp.from_torch(sim.scatter(tau, sim.qd_index, sim.nqd)))
        tape = wp.Tape()
        with tape:
            sim.solver.step(s_in, s_out, ctrl, None, sim.dt)
        ctx.tape, ctx.sim, ctx.k = tape, sim, k
        q_out = wp.to_torch(s_out.joint_q).view(sim.worlds, sim.nq)[:, sim.q_index].clone()
        qd_out = wp.to_torch(s_out.joint_qd).view(sim.worlds, sim.nqd)[:, sim.qd_index].clone()
        return q_out, qd_out

    @staticmethod
    def backward(ctx, g_q, g_qd):
        sim, k, tape = ctx.sim, ctx.k, ctx.tape
        wp = sim._wp
        s_in, s_out, ctrl = sim.states_in[k], sim.states_out[k], sim.controls[k]
        tape.backward(grads={
            s_out.joint_q: wp.from_torch(sim.scatter(g_q, sim.q_index, sim.nq)),
            s_out.joint_qd: wp.from_torch(sim.scatter(g_qd, sim.qd_index, sim.nqd)),
        })

        def grad(a, idx, width):
            return wp.to_torch(a.grad).view(sim.worlds, width)[:, idx].clone()

        out = (grad(s_in.joint_q, sim.q_index, sim.nq), grad(s_in.joint_qd, sim.qd_index, sim.nqd),
               grad(ctrl.joint_target_q, sim.qd_index, sim.nqd), grad(ctrl.joint_f, sim.qd_index, sim.nqd))
        tape.zero()
        ctx.tape = None
        return (*out, None, None)


def rollout(sim: DiffReplay, policy, q0, qd0, qdd0, q_cmd, truncation: int = 0, obs_noise: float = 0.0,
            generator: torch.Generator | None = None):
    """Differentiable open-loop replay of H steps with the residual in the loop.

    Args:
        q0, qd0, qdd0: Recorded start state [rad, rad/s, rad/s²], (B, n).
        q_cmd: Commands [rad], (B, H, n).
        truncation: Detach the simulated state (and a GRU's hidden state) every this many steps; 0 = never.
        obs_noise: Std of Gaussian noise on the policy's observation, in units of ``policy.obs_std``.
        generator: Torch generator of that noise.

    Returns:
        q, qd of the simulated steps 1..H, (B, H, n), and the normalised actions (B, H, n).
    """
    if hasattr(policy, "reset"):
        policy.reset()
    q, qd, qdd = q0, qd0, qdd0
    qs, qds, actions = [], [], []
    scale = policy.scale
    for k in range(q_cmd.shape[1]):
        obs = observation(q, qd, qdd, q_cmd[:, k])
        if obs_noise > 0.0:
            obs = obs + obs_noise * policy.obs_std * torch.randn(obs.shape, generator=generator, device=obs.device)
        res = policy(obs)
        actions.append(res / scale)
        if policy.kind == "torque":
            target, tau = q_cmd[:, k], res
        else:
            target, tau = q_cmd[:, k] + res, torch.zeros_like(res)
        q_next, qd_next = SimStep.apply(q, qd, target, tau, sim, k)
        qdd = (qd_next - qd) / sim.dt
        q, qd = q_next, qd_next
        qs.append(q)
        qds.append(qd)
        if truncation and (k + 1) % truncation == 0:
            q, qd, qdd = q.detach(), qd.detach(), qdd.detach()
            if isinstance(getattr(policy, "hidden", None), torch.Tensor):
                policy.hidden = policy.hidden.detach()
    return torch.stack(qs, 1), torch.stack(qds, 1), torch.stack(actions, 1)


def window_loss(cfg: GradFitConfig, q, qd, actions, q_ref, qd_ref, scale) -> tuple[torch.Tensor, dict]:
    """Multiple-shooting loss of one batch of windows (see module docstring); returns (loss, parts).

    ``actions`` are normalised (B, H, n); ``scale`` turns them into residual torque [N·m] for the torque
    penalty (``None`` for a delta action, which applies no residual torque).
    """
    pos = ((q - q_ref) ** 2).sum(-1).mean()
    vel = ((qd - qd_ref) ** 2).sum(-1).mean()
    tau = torch.zeros((), device=q.device)
    if scale is not None:
        tau = ((actions * scale) ** 2).sum(-1).mean()
    rate = ((actions[:, 1:] - actions[:, :-1]) ** 2).sum(-1).mean() if actions.shape[1] > 1 else tau * 0.0
    loss = cfg.w_q * pos + cfg.w_qd * vel + cfg.w_torque * tau + cfg.w_action_rate * rate
    parts = {"pos": pos, "vel": vel, "torque": tau, "rate": rate}
    return loss, {k: float(v.detach()) for k, v in parts.items()}


class _Windows:
    """Uniform sampler of (trajectory, start) windows over the training split, as device tensors.

    Trajectories may differ in length (imported logs do); the recordings live in the replay environment's
    :class:`~wresdyn.learn.replay_env.TrajectoryBank`.
    """

    def __init__(self, trajectories, device: str) -> None:
        from .replay_env import TrajectoryBank

        self.bank = TrajectoryBank(trajectories, device)
        self.lengths = np.array([len(t.q) for t in trajectories])
        self.starts = np.concatenate([[0], np.cumsum(self.lengths)[:-1]])

    def sample(self, rng: np.random.Generator, b: int, h: int):
        eligible = np.flatnonzero(self.lengths > h)
        if len(eligible) == 0:
            raise ValueError(f"every training trajectory is shorter than the {h + 1} samples a window needs")
        traj = eligible[rng.integers(0, len(eligible), b)]
        start = rng.integers(0, self.lengths[traj] - h, b)
        dev = self.bank.q.device
        rows = torch.as_tensor(self.starts[traj] + start, device=dev)[:, None] + torch.arange(h + 1, device=dev)[None]
        q, qd, qdd, cmd = self.bank.q[rows], self.bank.qd[rows], self.bank.qdd[rows], self.bank.q_cmd[rows]  # (B, H+1, n)
        return q[:, 0], qd[:, 0], qdd[:, 0], cmd[:, :h], q[:, 1:], qd[:, 1:]


def fit(robot, dataset, cfg: GradFitConfig, out: str | Path | None = None, log=print, eval_fn=None,
        eval_every: int = 0, until: int | None = None):
    """Fit a residual policy to ``dataset``'s training split by gradient descent through the simulation.

    Args:
        robot: The nominal robot (the simulator side).
        dataset: A :class:`wresdyn.data.dataset.Dataset` recorded on the "real" robot.
        cfg: Settings.
        out: Optional run folder: ``checkpoint.pt`` (resumed if present), ``curve.json``.
        log: Progress printer.
        eval_fn: Optional ``eval_fn(policy) -> float`` (held-out error), called every ``eval_every`` iterations.
        until: Stop (and checkpoint) after this many iterations of the ``cfg.iterations`` schedule (horizon
            curriculum and learning rate), to resume later; ``None`` runs the whole schedule.

    Returns:
        ``(policy, curve)``: the trained :class:`~wresdyn.learn.residual.ResidualPolicy` and the learning curve rows
        (iteration, wall-clock [s], simulated env-steps, loss parts, optional held-out error).
    """
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    train = dataset.split("train")
    if not train:
        raise ValueError("the dataset has no training trajectories")
    dt = 1.0 / dataset.rate_hz
    mean, std = obs_stats(train)
    policy = build_policy(robot, cfg.residual, mean, std, cfg.model).to(cfg.device)
    optim = torch.optim.Adam(policy.parameters(), lr=cfg.lr)
    horizons = cfg.horizon_curriculum or (cfg.horizon,)
    sim = DiffReplay(robot, cfg.windows, max(horizons), dt, cfg.solver, cfg.device)
    windows = _Windows(train, cfg.device)
    obs_noise = cfg.obs_noise if cfg.model == "network" else 0.0  # the physical model has no normaliser
    noise_gen = torch.Generator(device=cfg.device)
    noise_gen.manual_seed(cfg.seed)
    curve, start_it, sim_steps, wall0 = [], 0, 0, 0.0
    ckpt = Path(out) / "checkpoint.pt" if out else None
    if ckpt and ckpt.exists():
        state = torch.load(ckpt, map_location=cfg.device, weights_only=False)
        policy.load_state_dict(state["policy"])
        optim.load_state_dict(state["optim"])
        rng.bit_generator.state = state["rng"]
        if "noise_rng" in state:
            noise_gen.set_state(state["noise_rng"].cpu())
        curve, start_it, sim_steps, wall0 = state["curve"], state["iteration"], state["sim_steps"], state["wall"]
        log(f"resumed from {ckpt} at iteration {start_it}")
    t0 = time.perf_counter() - wall0
    stop = cfg.iterations if until is None else min(until, cfg.iterations)
    for it in range(start_it, stop):
        h = horizons[min(it * len(horizons) // cfg.iterations, len(horizons) - 1)]
        for group in optim.param_groups:
            group["lr"] = cfg.lr_final + 0.5 * (cfg.lr - cfg.lr_final) * (1.0 + np.cos(np.pi * it / cfg.iterations))
        q0, qd0, qdd0, cmd, q_ref, qd_ref = windows.sample(rng, cfg.windows, h)
        q, qd, actions = rollout(sim, policy, q0, qd0, qdd0, cmd, cfg.grad_truncation, obs_noise, noise_gen)
        loss, parts = window_loss(cfg, q, qd, actions, q_ref, qd_ref, policy.scale if policy.kind == "torque" else None)
        if not torch.isfinite(loss):
            raise FloatingPointError(f"gradient fit: non-finite loss at iteration {it} (simulation diverged)")
        optim.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), cfg.grad_clip)
        optim.step()
        sim_steps += cfg.windows * h * 2  # forward + backward through each step
        row = {"iteration": it + 1, "wall": time.perf_counter() - t0, "sim_steps": sim_steps, "loss": float(loss.detach()), **parts}
        if eval_fn is not None and eval_every and ((it + 1) % eval_every == 0 or it + 1 == cfg.iterations):
            row["heldout"] = float(eval_fn(policy))
        curve.append(row)
        if (it + 1) % max(1, cfg.iterations // 20) == 0 or it + 1 == stop:
            msg = f"iter {it + 1:5d}/{cfg.iterations}  H={h:3d}  loss {row['loss']:.3e}  |dq|² {parts['pos']:.3e}"
            log(msg + (f"  held-out {row['heldout']:.4f} rad" if "heldout" in row else "") + f"  {row['wall']:.0f}s")
            if ckpt:
                _save_atomic(ckpt, {"policy": policy.state_dict(), "optim": optim.state_dict(),
                                    "rng": rng.bit_generator.state, "noise_rng": noise_gen.get_state(), "curve": curve,
                                    "iteration": it + 1, "sim_steps": sim_steps, "wall": row["wall"],
                                    "config": dataclasses.asdict(cfg)})
    if out:
        Path(out, "curve.json").write_text(json.dumps(curve, indent=1))
    return policy.eval(), curve


def _save_atomic(path: Path, obj) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(obj, tmp)
    tmp.replace(path)


def export_run(policy, out: str | Path, cfg: GradFitConfig, dataset, data_path: str | Path | None = None) -> None:
    """Write the run files ``wresdyn eval`` reads: ``config.json``, ``policy.pt``, ``policy.onnx``, ``residual.json``.

    ``config.json`` carries the replay settings in the layout of a PPO run (``config.env``, ``config.residual``)
    plus the full gradient-fit config under ``gradfit``.
    """
    from .residual import export_run_files

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    policy = policy.cpu().eval()
    kind = policy.kind
    arch = "parametric" if cfg.model == "parametric" else cfg.residual.arch
    residual = {**dataclasses.asdict(cfg.residual), "kind": kind}
    if cfg.model == "parametric":
        residual["arch"] = "mlp"  # no network; keeps the PPO config layout valid
    config = {"learner": "parametric" if cfg.model == "parametric" else "gradient",
              "config": {"env": {"solver": cfg.solver, "substeps": 1}, "residual": residual},
              "gradfit": dataclasses.asdict(cfg), "data_path": str(data_path) if data_path else None}
    (out / "config.json").write_text(json.dumps(config, indent=2))
    export_run_files(policy, out, dataset, arch=arch, learner=config["learner"])
