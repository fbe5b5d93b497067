"""Gradient fit: train a residual by backpropagating through the differentiable Warp simulation.

Multiple shooting: each iteration samples B windows of H steps from the training recordings, starts each
window (one Newton world each) at the recorded state, rolls the simulation forward with the residual policy in
the loop, and minimises the joint position and velocity mismatch against the recording

    L = mean_k [ w_q |q_k − q_r,k|² + w_qd |q̇_k − q̇_r,k|² ] + w_τ |τ_res|² + w_rate |a_k − a_{k−1}|²,

the regularisers mirroring Table I's torque and action-rate penalties. Gradients come from a ``wp.Tape`` per
solver step, bridged into torch by :meth:`wresdyn.sim.Simulator.step_diff` (a ``torch.autograd.Function``):
torch's autograd walks the steps backwards and each step's tape turns the incoming state gradient into gradients
of the previous state and of the residual, all on the device (``wp.from_torch`` / ``wp.to_torch`` are zero-copy).
Windows come from the simulation layer's :class:`~wresdyn.sim.TrajectoryBank` and run through its rollout driver
(:func:`wresdyn.sim.rollout`, ``grad=True``), the same code that evaluation replays with.

Model selection is made on the validation split: every ``select_every`` iterations the current residual replays
the validation trajectories open loop (whole trajectories, the evaluation's metric), and the fit returns the
residual with the lowest validation error. Held-out and OOD data are never read here.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..choices import ModelKind, SolverKind, check_choice, check_number
from ..progress import bar
from ..sim.residual_kinds import residual_scale
from .residual import ResidualConfig, obs_stats

__all__ = ["GradFitConfig", "build_policy", "window_loss", "fit", "export_run", "RESUME_MAY_CHANGE"]


@dataclass(frozen=True)
class GradFitConfig:
    """Gradient fit settings (defaults: a small CPU run on the shipped data)."""

    residual: ResidualConfig = ResidualConfig(fraction=0.25)
    """Residual kind (torque / delta action), network (MLP / GRU) and authority: 0.25 of each effort limit,
    chosen on validation (0.0282 rad against 0.0294 at 0.5, both with ``obs_noise`` 0.1;
    ``benchmarks/results/validation_protocol/fit_sweep_summary.md``)."""
    model: ModelKind = "network"
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
    network otherwise fits the training windows' states too closely. Chosen on validation among 0, 0.03, 0.1
    and 0.3 (0.0316, 0.0301, 0.0294, 0.0302 rad at authority 0.5); 0 = off. Not applied to the parametric
    model."""
    solver: SolverKind = "auto"
    """Newton solver (:data:`wresdyn.sim.solvers.SOLVERS`); must be differentiable."""
    device: str = "cpu"
    """Warp / torch device."""
    torch_threads: int = 1
    """CPU threads for torch (0: torch's default). One is fastest for these small networks, and an unpinned fit
    ran 12x slower on a loaded 2-core machine (threads contending with the simulation and each other)."""
    seed: int = 0
    """Seed of the window sampler and network initialisation."""
    select_every: int = 0
    """Evaluate on the validation split every this many iterations and return the best residual (model
    selection on validation); 0 = ten times per run."""
    cuda_graph: bool = True
    """On CUDA, replay each iteration (the rollout with the residual in the loop, the loss, the backward pass
    through torch and each step's Warp tape, gradient clipping, Adam) from a CUDA graph captured once per window
    length, with no host synchronisation inside (:class:`_Iteration`). The CPU runs the same code eagerly; off,
    CUDA does too. May change on resume."""
    physics: str = ""
    """Physical parameters of the simulator (``physics.json`` of ``wresdyn identify``): the residual is learned
    on top of the identified model (the hybrid), with its command delay; "" = the robot file's."""

    def __post_init__(self) -> None:
        from .runs import check_window_fit_config

        check_choice(self.model, ModelKind, "model")
        check_window_fit_config(self)
        check_number(self.horizon, "horizon", integer=True, ge=1)
        for name in ("w_torque", "w_action_rate", "obs_noise"):
            check_number(getattr(self, name), name, ge=0)


def build_policy(robot, cfg: ResidualConfig, obs_mean, obs_std, model: str = "network"):
    """A fresh residual: a network (MLP with ELU, or GRU + MLP) as a :class:`~wresdyn.learn.residual.ResidualPolicy`,
    or the ``"parametric"`` baseline."""
    from rsl_rl.modules.mlp import MLP

    from .residual import GRUResidualPolicy, MLPResidualPolicy

    n = robot.n_dof
    if model == "parametric":
        from .parametric import ParametricResidual

        return ParametricResidual(robot, residual_scale(robot, "torque", cfg.fraction))
    if model != "network":
        raise ValueError(f"unknown residual model {model!r}; choose 'network' or 'parametric'")
    scale = residual_scale(robot, cfg.kind, cfg.fraction)
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


def window_loss(cfg: GradFitConfig, q, qd, actions, q_ref, qd_ref, scale,
                weights: torch.Tensor | None = None) -> tuple[torch.Tensor, dict]:
    """Multiple-shooting loss of one batch of windows (see module docstring); returns (loss, parts), the parts
    (``pos``, ``vel``, ``torque``, ``rate``) as detached scalar tensors (read them when needed: no host sync here).

    ``actions`` are normalised (B, H, n); ``scale`` turns them into residual torque [N·m] for the torque
    penalty (``None`` for a delta action, which applies no residual torque). ``weights`` (n,) weigh each joint's
    position and velocity error (0 for a joint the dataset excludes from fitting; ``None``: all 1).
    """
    from .runs import squared_error

    pos, vel = squared_error(q, q_ref, weights), squared_error(qd, qd_ref, weights)
    tau = torch.zeros((), device=q.device)
    if scale is not None:
        tau = ((actions * scale) ** 2).sum(-1).mean()
    rate = ((actions[:, 1:] - actions[:, :-1]) ** 2).sum(-1).mean() if actions.shape[1] > 1 else tau * 0.0
    loss = cfg.w_q * pos + cfg.w_qd * vel + cfg.w_torque * tau + cfg.w_action_rate * rate
    parts = {"pos": pos, "vel": vel, "torque": tau, "rate": rate}
    return loss, {k: v.detach() for k, v in parts.items()}


RESUME_MAY_CHANGE = ("device", "torch_threads", "cuda_graph")
""":class:`GradFitConfig` fields a resumed fit may change: where it runs, not what it learns (``iterations``
shapes the learning-rate and horizon schedule, so it is part of what it learns)."""


def fit(robot, dataset, cfg: GradFitConfig, out: str | Path | None = None, log=print, until: int | None = None,
        stop_below: float | None = None):
    """Fit a residual to ``dataset``'s training split by gradient descent through the simulation.

    Args:
        robot: The nominal robot (the simulator side).
        dataset: A :class:`wresdyn.data.dataset.Dataset` (only ``q``, ``qd``, ``qdd``, ``q_cmd`` are read; recorded
            torques never). Its ``validation`` split, when present, selects the returned residual.
        cfg: Settings.
        out: Optional run folder: ``checkpoint.pt`` (resumed if present; a changed config is refused),
            ``curve.json``.
        log: Progress printer.
        until: Stop (and checkpoint) after this many iterations of the ``cfg.iterations`` schedule (horizon
            curriculum and learning rate), to resume later; ``None`` runs the whole schedule.
        stop_below: End the fit at the first validation check whose error is at or below this [rad] (time to
            fidelity, ``benchmarks/time_to_fidelity.py``), returning the residual selected so far.

    Returns:
        ``(policy, curve)``: the trained :class:`~wresdyn.learn.residual.ResidualPolicy` (the one with the lowest
        validation error when the dataset has a validation split, else the last) and the learning curve rows
        (iteration, wall-clock [s], simulated env-steps, loss parts, validation error where evaluated).
    """
    from ..sim import Simulator, TrajectoryBank
    from .runs import check_resume, joint_weights, load_checkpoint, save_checkpoint, start_window_fit
    from .selection import ValidationScore

    rng, train, dt = start_window_fit(cfg, dataset)
    mean, std = obs_stats(train)
    policy = build_policy(robot, cfg.residual, mean, std, cfg.model).to(cfg.device)
    horizons = cfg.horizon_curriculum or (cfg.horizon,)
    sim = Simulator(robot, cfg.windows, dt, solver=cfg.solver, device=cfg.device, requires_grad=True)
    graph = cfg.cuda_graph and sim.device.type == "cuda"
    optim = torch.optim.Adam(policy.parameters(), lr=cfg.lr, capturable=graph)
    physics = load_physics(cfg.physics, robot)
    delay = 0.0
    if physics is not None:
        sim.set_physics(physics)
        delay = torch.as_tensor(physics.delay / dt, dtype=torch.float32, device=sim.device)
    bank = TrajectoryBank(train, sim.device, delay)
    validation = dataset.split("validation")
    score = ValidationScore(robot, validation, dataset.rate_hz, cfg.solver, cfg.device, physics=physics,
                            weights=dataset.fit_weights()) if validation else None
    weights = joint_weights(dataset, sim.device)
    select_every = max(1, cfg.select_every or cfg.iterations // 10)
    log_every = max(1, cfg.iterations // 20)
    obs_noise = cfg.obs_noise if cfg.model == "network" else 0.0  # the physical model has no normaliser
    noise_gen = torch.Generator(device=cfg.device)
    noise_gen.manual_seed(cfg.seed)
    curve, start_it, sim_steps, wall0 = [], 0, 0, 0.0
    best = {"validation": float("inf"), "iteration": 0, "state": None}
    config = dataclasses.asdict(cfg)
    ckpt = Path(out) / "checkpoint.pt" if out else None
    if ckpt and ckpt.exists():
        state = load_checkpoint(ckpt, map_location=cfg.device, keys=("policy", "optim", "noise_rng", "best", "meta"))
        meta = state["meta"]
        check_resume(ckpt.parent, meta["config"], config, RESUME_MAY_CHANGE)
        policy.load_state_dict(state["policy"])
        optim.load_state_dict(state["optim"])
        rng.bit_generator.state = meta["rng"]
        noise_gen.set_state(state["noise_rng"].cpu())
        curve, start_it, sim_steps, wall0 = meta["curve"], meta["iteration"], meta["sim_steps"], meta["wall"]
        best = {"validation": meta["best_validation"], "iteration": meta["best_iteration"],
                "state": state["best"] or None}
        log(f"resumed from {ckpt} at iteration {start_it}")
    step = _Iteration(cfg, sim, bank, policy, optim, obs_noise, graph, weights)
    if score is None and start_it == 0:
        log("no validation split: the fit returns its last iteration (`wresdyn migrate` adds one)")
    if score is not None and start_it == 0 and physics is not None:
        # on identified physics (the hybrid) the zero-residual start is a candidate too: the hybrid is never
        # selected worse than the identified model alone
        value = score(policy)
        best = {"validation": value, "iteration": 0,
                "state": {k: v.detach().clone() for k, v in policy.state_dict().items()}}
        log(f"validation at the start: {value:.4f} rad")
    t0 = time.perf_counter() - wall0
    stop = cfg.iterations if until is None else min(until, cfg.iterations)
    reached = False
    pending: list[tuple[dict, torch.Tensor]] = []  # rows whose loss parts are still on the device

    def settle() -> None:
        """Read the pending rows' loss parts from the device (one sync) and fail at the first non-finite loss."""
        if not pending:
            return
        values = torch.stack([p for _, p in pending]).tolist()
        for (row, _), v in zip(pending, values):
            row.update(zip(_PARTS, v))
            if not np.isfinite(row["loss"]):
                raise FloatingPointError(f"gradient fit: non-finite loss at iteration {row['iteration']} "
                                         "(simulation diverged)")
        pending.clear()

    with bar(log, stop, "fit", start_it) as progress:
        for it in range(start_it, stop):
            h = horizons[min(it * len(horizons) // cfg.iterations, len(horizons) - 1)]
            lr = float(cfg.lr_final + 0.5 * (cfg.lr - cfg.lr_final) * (1.0 + np.cos(np.pi * it / cfg.iterations)))
            traj, start = bank.draw(rng, cfg.windows, h)
            noise = torch.stack([torch.randn((cfg.windows, 4 * robot.n_dof), generator=noise_gen, device=sim.device)
                                 for _ in range(h)]) if obs_noise > 0.0 else None
            parts = step(traj, start, h, noise, lr)
            sim_steps += cfg.windows * h * 2  # forward + backward through each step
            row = {"iteration": it + 1, "wall": time.perf_counter() - t0, "sim_steps": sim_steps}
            pending.append((row, parts))
            if not graph or it < start_it + 2:
                # eager: each iteration is checked before the next; with graphs, the first two of a session (warm-up and
                # capture) wait for the device, so their rows' wall-clock is exact (a reference for throughput)
                settle()
                row["wall"] = time.perf_counter() - t0
            validate = score is not None and ((it + 1) % select_every == 0 or it + 1 == cfg.iterations)
            report = (it + 1) % log_every == 0 or it + 1 == stop
            if validate or report:
                settle()
                row["wall"] = time.perf_counter() - t0  # the device has caught up: the row's true wall-clock
            if validate:
                t_eval = time.perf_counter()
                row["validation"] = score(policy)
                t0 += time.perf_counter() - t_eval  # wall-clock counts training only
                if row["validation"] < best["validation"]:
                    best = {"validation": row["validation"], "iteration": it + 1,
                            "state": {k: v.detach().clone() for k, v in policy.state_dict().items()}}
                reached = stop_below is not None and row["validation"] <= stop_below
            curve.append(row)
            progress.update(1, f"H={h}" + (f"  loss {row['loss']:.2e}" if "loss" in row else ""))
            if report or reached:
                msg = f"iter {it + 1:5d}/{cfg.iterations}  H={h:3d}  loss {row['loss']:.3e}  |dq|² {row['pos']:.3e}"
                log(msg + (f"  validation {row['validation']:.4f} rad" if "validation" in row else "")
                    + f"  {row['wall']:.0f}s")
                if ckpt:
                    meta = {"config": config, "rng": rng.bit_generator.state, "curve": curve, "iteration": it + 1,
                            "sim_steps": sim_steps, "wall": row["wall"], "best_validation": best["validation"],
                            "best_iteration": best["iteration"]}
                    save_checkpoint({"policy": policy.state_dict(), "optim": optim.state_dict(), "meta": meta,
                                     "noise_rng": noise_gen.get_state(), "best": best["state"] or {}}, ckpt)
            if reached:
                log(f"validation {row['validation']:.4f} rad <= {stop_below:.4f} rad at iteration {it + 1}: stopping")
                break
    settle()
    if out:
        Path(out, "curve.json").write_text(json.dumps(curve, indent=1))
    if best["state"] is not None and (stop == cfg.iterations or reached):
        policy.load_state_dict(best["state"])
        log(f"selected iteration {best['iteration']} by validation ({best['validation']:.4f} rad)")
    return policy.eval(), curve


_PARTS = ("loss", "pos", "vel", "torque", "rate")
"""The loss and its parts, in the order :class:`_Iteration` returns them."""


class _Iteration:
    """One optimiser step of the fit: windows of ``h`` steps at (trajectory, start) (B,) each, the rollout with the
    residual in the loop, the loss, the backward pass (torch's autograd through each step's Warp tape), gradient
    clipping and Adam. A call returns :data:`_PARTS` as one tensor (5,) on the device, without waiting for it.

    With ``graph`` (CUDA) every call runs on the simulator's own stream and, from the second call at a window
    length on, is replayed from a CUDA graph captured for that length: torch's capture, which the Warp launches
    of the solver steps and of their tapes join as an external capture (forward and backward on the same stream,
    :meth:`~wresdyn.sim.Simulator._tape_stream`), Adam ``capturable`` with the learning rate a device tensor. The
    first call at each length runs eagerly on that stream (it loads kernels and creates Adam's state and
    torch's workspaces, which a capture must not). The window indices and the observation noise enter through
    fixed buffers; the gradients live in each graph's memory pool. Without ``graph`` the same code runs eagerly.
    """

    def __init__(self, cfg: GradFitConfig, sim, bank, policy, optim, obs_noise: float, graph: bool,
                 weights: torch.Tensor | None = None) -> None:
        self.cfg, self.sim, self.bank, self.policy, self.optim = cfg, sim, bank, policy, optim
        self.obs_noise, self.graph, self.weights = obs_noise, graph, weights
        self.torque_scale = policy.scale if policy.kind == "torque" else None
        self._warm: set[int] = set()
        self._graphs: dict[int, tuple] = {}  # window length -> (graph, (traj, start, noise) buffers, output)
        for group in optim.param_groups:  # a resumed optimiser takes its flag from the checkpoint: set it here
            group["capturable"] = graph
            lr = float(group["lr"])
            group["lr"] = torch.tensor(lr, device=sim.device) if graph else lr
        for state in optim.state.values():  # Adam's step count lives where capturable wants it
            if "step" in state:
                state["step"] = state["step"].to(sim.device if graph else "cpu", torch.float32)

    def _run(self, traj, start, h: int, noise) -> torch.Tensor:
        from ..sim import rollout

        window = self.bank.window(traj, start, h)
        run = rollout(self.sim, window, self.policy, grad=True, truncation=self.cfg.grad_truncation,
                      obs_noise=self.obs_noise, noise=noise)
        loss, parts = window_loss(self.cfg, run.q[:, 1:], run.qd[:, 1:], run.actions, window.q[:, 1:],
                                  window.qd[:, 1:], self.torque_scale, self.weights)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.cfg.grad_clip)
        self.optim.step()
        return torch.stack([loss.detach(), *(parts[k] for k in _PARTS[1:])])

    def __call__(self, traj, start, h: int, noise, lr: float) -> torch.Tensor:
        if not self.graph:
            for group in self.optim.param_groups:
                group["lr"] = lr
            self.optim.zero_grad()
            return self._run(traj, start, h, noise)
        import warp as wp

        for group in self.optim.param_groups:
            group["lr"].fill_(lr)
        sim, cur = self.sim, torch.cuda.current_stream(self.sim.device)
        side = sim.side_stream()
        side.wait_stream(cur)
        if h not in self._warm:
            self._warm.add(h)
            with torch.cuda.stream(side):
                self.optim.zero_grad()
                out = self._run(traj, start, h, noise)
            cur.wait_stream(side)
            return out
        entry = self._graphs.get(h)
        if entry is None:
            inputs = (traj.clone(), start.clone(), None if noise is None else noise.clone())
            self.optim.zero_grad(set_to_none=True)  # backward allocates the gradients in the graph's pool
            graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(graph, stream=side, capture_error_mode="thread_local"):
                wp.capture_begin(stream=sim._wp_side, external=True, capture_mode=wp.CaptureMode.THREAD_LOCAL)
                try:
                    out = self._run(inputs[0], inputs[1], h, inputs[2])
                finally:
                    wp.capture_end(stream=sim._wp_side)
            entry = self._graphs[h] = (graph, inputs, out)
        graph, inputs, out = entry
        inputs[0].copy_(traj)
        inputs[1].copy_(start)
        if noise is not None:
            inputs[2].copy_(noise)
        graph.replay()
        return out.clone()


def load_physics(path: str, robot):
    """The :class:`~wresdyn.sim.physics.PhysicalParams` at ``path`` (checked against ``robot``), ``None`` for ""."""
    if not path:
        return None
    from ..sim.physics import PhysicalParams

    return PhysicalParams.load(path, robot)


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
    if cfg.physics:  # the run carries the model it was fitted on: evaluation replays with it
        from ..sim.physics import PhysicalParams

        PhysicalParams.load(cfg.physics).save(out / "physics.json")
