"""Grey-box system identification: fit the simulator's own physical parameters through the differentiable solver.

The fitted quantities are the model arrays SolverReplay reads (per joint: PD gains, armature, viscous damping,
dry friction with stiction, effort limit, command delay; per link: mass, centre of mass and inertia through the
log-Cholesky pseudo-inertia), produced by :class:`~wresdyn.sim.physics.PhysicsModel`. As in the gradient fit of a
residual (:mod:`.gradfit`), each iteration replays B windows of recorded commands open loop from their recorded
start state and minimises

    L = mean_k [ w_q |q_k − q_r,k|² + w_qd |q̇_k − q̇_r,k|² ] + w_prior |u − u_0|²,

but the gradient goes to the parameters: the Warp tape of every step returns ``∂L/∂(model arrays)``
(:meth:`wresdyn.sim.Simulator.step_diff`), the command delay's through the interpolated PD target
(:func:`wresdyn.sim.bank.delay_commands`). The prior is weak; it only settles what the data cannot tell apart.

A saturating drive has no gradient while the simulated drive does not saturate, so the effort limit starts
from a coarse search: the training loss of a few windows at a geometric grid of fractions of the robot file's
limit (forward only); the gradient refines from the best. Model selection on the validation split, as for
every learner: every ``select_every`` iterations the current parameters replay the validation trajectories and
the best are returned. An optional L-BFGS refinement (``SysIdConfig.refine``) follows on fixed training windows,
each step validated the same way. Held-out and OOD data are never read.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..choices import SolverKind, check_number
from ..progress import bar
from ..sim.physics import JOINT_FIELDS, PhysicalParams, PhysicsModel
from .selection import ValidationScore

__all__ = ["SysIdConfig", "identify", "PhysicsScore", "GridChoice", "RESUME_MAY_CHANGE"]

FIT_FIELDS = (*JOINT_FIELDS, "bodies")
"""What can be identified: the per-joint fields and ``"bodies"`` (every moving link's mass, com, inertia)."""


@dataclass(frozen=True)
class SysIdConfig:
    """Identification settings (defaults: a CPU run of a few minutes on the shipped data)."""

    fit: tuple[str, ...] = FIT_FIELDS
    """Fields to identify (:data:`FIT_FIELDS`); the others keep the robot file's values."""
    iterations: int = 800
    """Optimiser steps."""
    windows: int = 32
    """Windows B (Newton worlds) per iteration."""
    horizon_curriculum: tuple[int, ...] = (16, 32, 64, 128)
    """Window lengths [steps] in equal parts of training: short windows first (a far-off start diverges over
    long ones), long windows last (delay, friction and saturation act over tens of steps)."""
    grad_truncation: int = 0
    """Detach the state every this many steps; 0 = full backpropagation (the parameters are few and the
    identified model is stable, unlike a residual network early in training)."""
    lr: float = 0.01
    """Adam learning rate in the coordinates of :class:`~wresdyn.sim.physics.PhysicsModel` (log scales and
    reference units, all O(0.1-1))."""
    lr_final: float = 0.001
    """Learning rate at the last iteration (cosine decay)."""
    w_q: float = 1.0
    """Weight of the joint position error [1/rad²]."""
    w_qd: float = 0.01
    """Weight of the joint velocity error [s²/rad²]."""
    w_prior: float = 1e-5
    """Weight of the squared distance of the coordinates from the start."""
    effort_grid: tuple[float, ...] = tuple(round(float(x), 4) for x in np.geomspace(0.05, 1.0, 9))
    """Fractions of the robot file's effort limits tried when the effort limit joins the fit (forward only, on
    training windows); empty = continue from the file's limits."""
    delay_grid: tuple[float, ...] = ()
    """Command delays [steps] tried (one for every joint) when the effort limit joins the fit, before it. Off by
    default: on the shipped data (true delay 3 steps) the grid 0-8 picked 0 there, the gains, damping and
    friction having already absorbed the delay, and the final error did not change (0.0057 vs 0.0055 rad
    held-out)."""
    gain_grid: tuple[float, ...] = ()
    """Factors on the start's position gain kp tried before the first step, each joint taking the factor of its own
    least training error (forward only, every joint at one factor per rollout); empty = start from the file's kp.
    Off by default. Where the file's kp is so stiff that the drive saturates on every move (the SO-101's servo
    model: kp 998 N·m/rad against 3.35 N·m), the loss barely depends on kp and Adam cannot walk down to a soft
    servo's: ``benchmarks/so101_real.sh`` uses it."""
    effort_after: float = 0.4
    """Fraction of the iterations after which the effort limit joins the fit. Before, the drives keep the
    file's limits: a low limit started from the file's other values mimics the friction and delay not yet
    identified (a local minimum where saturation stands in for friction)."""
    lr_scale: tuple[float, float, float] = (1.0, 5.0, 0.5)
    """Learning-rate factors of the gain/armature log scales, the linear fields (damping, friction, effort,
    delay: their coordinates run to a few units) and the link pseudo-inertia factors."""
    grad_clip: float = 1.0
    """Global gradient-norm clip."""
    solver: SolverKind = "auto"
    """Newton solver; must be differentiable (SolverReplay)."""
    device: str = "cpu"
    """Warp / torch device."""
    torch_threads: int = 1
    """CPU threads for torch (0: torch's default); see :class:`wresdyn.learn.gradfit.GradFitConfig`."""
    seed: int = 0
    """Seed of the window sampler."""
    select_every: int = 0
    """Validate every this many iterations (0: ten times per run)."""
    refine: int = 0
    """L-BFGS steps after Adam (0: off), each up to 20 evaluations with a strong-Wolfe line search, on
    ``refine_windows`` fixed training windows of the longest horizon, from the parameters selected so far; every
    step is validated and the best kept. The fields of ``fit`` except the effort limit and the delay (both kept)."""
    refine_windows: int = 64
    """Fixed training windows of the refinement."""
    share_effort_ratio: bool = True
    """After the selection, give the effort limits the training data never reaches the ratio to the file's limit that
    the saturating joints share, bounded below by the torque the data demands
    (:func:`~wresdyn.learn.unexcited_limits.limit_unexcited_efforts`); kept only if validation is not worse. Only
    when the effort limit is fitted."""
    saturated_min: float = 0.01
    """Fraction of training samples on which a drive must saturate for its effort limit to count as identified."""

    def __post_init__(self) -> None:
        from .runs import check_window_fit_config

        check_window_fit_config(self)
        bad = sorted(set(self.fit) - set(FIT_FIELDS))
        if bad:
            raise ValueError(f"fit: unknown field(s) {bad}; choose from {list(FIT_FIELDS)}")
        check_number(self.w_prior, "w_prior", ge=0)
        for i, f in enumerate(self.effort_grid):
            check_number(f, f"effort_grid[{i}]", gt=0)
        for i, f in enumerate(self.gain_grid):
            check_number(f, f"gain_grid[{i}]", gt=0)
        if self.gain_grid and "kp" not in self.fit:
            raise ValueError("gain_grid searches kp, which is not among the fitted fields (fit)")
        check_number(self.effort_after, "effort_after", ge=0)
        for i, f in enumerate(self.lr_scale):
            check_number(f, f"lr_scale[{i}]", gt=0)
        check_number(self.refine, "refine", integer=True, ge=0)
        check_number(self.refine_windows, "refine_windows", integer=True, ge=1)
        check_number(self.saturated_min, "saturated_min", gt=0, le=1)


RESUME_MAY_CHANGE = ("device", "torch_threads", "refine", "refine_windows")
""":class:`SysIdConfig` fields a resumed identification may change: where it runs and the L-BFGS refinement, which
runs after the checkpointed Adam steps."""


class PhysicsScore(ValidationScore):
    """``score(params) -> mean |Δq| [rad]``: :class:`~wresdyn.learn.selection.ValidationScore` of whole trajectories
    replayed PD-only with the physical parameters ``params`` (and their delay), through one reused simulator."""

    def __call__(self, params: PhysicalParams) -> float:
        self.physics = params
        return super().__call__()


def _share_effort_ratio(cfg, robot, dataset, train, dt, params, score, validation, log):
    """The selected parameters with the effort limits the training data never reaches set from the saturating
    joints' ratio (:mod:`.unexcited_limits`), unless that is worse on validation."""
    from .unexcited_limits import limit_unexcited_efforts

    shared, found = limit_unexcited_efforts(params, robot.effort, train, dt, fitted=dataset.fit_weights() > 0,
                                            saturated_min=cfg.saturated_min)
    log(found.describe())
    if not found.changed or score is None:
        return shared
    v = score(shared)
    if v > validation:
        log(f"  not kept: validation {v:.4f} rad against {validation:.4f} rad")
        return params
    log(f"  validation {v:.4f} rad (was {validation:.4f} rad)")
    return shared


def _window_loss(cfg, model, sim, window, weights=None):
    """Identification loss of one batch of windows: w_q |q − q_r|² + w_qd |q̇ − q̇_r|², summed over joints with
    per-joint ``weights`` (n,) tensor (0: a joint excluded from fitting; ``None``: all 1), mean over steps."""
    from ..sim import rollout
    from .runs import squared_error

    sim.set_physics(model())
    run = rollout(sim, window, grad=True, truncation=cfg.grad_truncation)
    pos = squared_error(run.q[:, 1:], window.q[:, 1:], weights)
    vel = squared_error(run.qd[:, 1:], window.qd[:, 1:], weights)
    return cfg.w_q * pos + cfg.w_qd * vel, {"pos": float(pos.detach()), "vel": float(vel.detach())}


@dataclass(frozen=True)
class GridChoice:
    """What one grid search of :func:`identify` chose (its ``on_search`` receives one per search)."""

    field: str
    """The field searched: ``"kp"`` (``gain_grid``, per joint), ``"delay"`` or ``"effort"`` (all joints at once)."""
    choice: dict[str, float | None]
    """Grid point each joint took, by joint name; ``None`` for a joint excluded from fitting (it keeps its value)."""
    losses: np.ndarray
    """Training loss of each grid point, shape (len(grid),), or per joint (len(grid), n_dof) for a per-joint
    search (mean squared position error [rad²])."""
    validation: float | None = None
    """Validation score of the parameters right after the search [rad] (the kp search, with a validation split)."""


def _grid_search(cfg, model, sim, train, rng, field: str, grid, values, log, weights=None,
                 per_joint: bool = False) -> GridChoice | None:
    """Set ``field`` to the grid point of least training loss on a few windows (forward only); return what was
    chosen (``None`` for an empty grid).

    ``values(g)`` maps a grid point to the field's values (n,) [SI]; every other field keeps its current value.
    ``weights``: per-joint weights (n,) tensor of the position error (0: excluded from fitting), ``None``: all 1.
    ``per_joint``: each joint takes the grid point of its own least position error (the joints are tried together,
    one rollout per grid point, so their coupling is ignored: a start for the gradient steps, not a fit).
    """
    from ..sim import TrajectoryBank, rollout
    from .runs import squared_error

    if not len(grid):
        return None
    h = max(cfg.horizon_curriculum or (64,))
    bank = TrajectoryBank(train, sim.device)
    traj, start = bank.draw(rng, cfg.windows, h)  # the same windows for every grid point
    base = model.values()
    losses = []
    for g in grid:
        p = base.copy()
        setattr(p, field, values(g))
        sim.set_physics(p)
        bank.set_delay(torch.as_tensor(p.delay / model.dt, dtype=torch.float32, device=sim.device))
        window = bank.window(traj, start, h)
        with torch.no_grad():
            run = rollout(sim, window)
        if per_joint:  # (n,) mean squared position error of each joint
            losses.append(((run.q[:, 1:] - window.q[:, 1:]) ** 2).reshape(-1, run.q.shape[-1]).mean(0).cpu().numpy())
        else:
            losses.append(float(squared_error(run.q[:, 1:], window.q[:, 1:], weights)))
    losses = np.nan_to_num(np.asarray(losses, dtype=np.float64), nan=np.inf)  # a diverged rollout never wins
    if per_joint:
        pick = np.argmin(losses, axis=0)  # (n,) grid index of each joint
        fitted = np.ones(len(pick), bool) if weights is None else weights.detach().cpu().numpy() > 0
        # a joint excluded from fitting keeps its value: its error is no one's to fit
        model.assign(field, np.stack([values(g) for g in grid])[pick, np.arange(len(pick))], keep=~fitted)
        choice = {j: float(grid[k]) if f else None for j, k, f in zip(model.robot.joint_names, pick, fitted)}
        log(f"{field} search, per joint: " + "  ".join(f"{j}:{'excluded' if g is None else f'{g:.3g}'}"
                                                       for j, g in choice.items()))
    else:
        best = grid[int(np.argmin(losses))]
        model.assign(field, values(best))
        choice = dict.fromkeys(model.robot.joint_names, float(best))
        log(f"{field} search: " + "  ".join(f"{g:.3g}:{x:.2e}" for g, x in zip(grid, losses)) + f"  -> {best:.3g}")
    return GridChoice(field, choice, losses)


def _snapshot(model) -> dict:
    """A copy of ``model``'s state, a selection candidate."""
    return {k: v.clone() for k, v in model.state_dict().items()}


def _refine(cfg, robot, bank, dt, start: PhysicalParams, score, start_validation: float, weights, curve, log):
    """``cfg.refine`` L-BFGS steps from ``start`` on fixed windows of ``bank`` (the training trajectories; its delay
    is set to ``start``'s) (:attr:`SysIdConfig.refine`); returns the best parameters on validation (``start`` when
    no step beats ``start_validation``). Appends to ``curve``.

    Adam's steps through the multiple-shooting loss stop in a long, ill-conditioned valley: on the shipped data the
    loss keeps falling along the straight line to the true parameters (``benchmarks/sysid_valley.py``), and a
    quasi-Newton method on a fixed batch moves along such valleys far faster. Not checkpointed: under a minute on
    2 cores, rerun on resume."""
    from ..sim import Simulator

    fields = [f for f in cfg.fit if f not in ("effort", "delay")]
    model = PhysicsModel(robot, start, fit=fields, dt=dt)
    h = max(cfg.horizon_curriculum or (64,))
    sim = Simulator(robot, cfg.refine_windows, dt, solver=cfg.solver, device=cfg.device, requires_grad=True,
                    param_grads=True)
    bank.set_delay(torch.as_tensor(start.delay / dt, dtype=torch.float32, device=sim.device))
    window = bank.sample(np.random.default_rng(cfg.seed + 1), cfg.refine_windows, h)
    params = [p for p in model.parameters() if p.requires_grad]
    optim = torch.optim.LBFGS(params, lr=1.0, max_iter=20, history_size=50, line_search_fn="strong_wolfe")

    def closure():
        optim.zero_grad()
        loss, _ = _window_loss(cfg, model, sim, window, weights)
        if not torch.isfinite(loss):
            raise FloatingPointError("identification: non-finite loss in the L-BFGS refinement (simulation diverged)")
        loss.backward()
        for p in params:  # L-BFGS flattens the gradients with view()
            if p.grad is not None and not p.grad.is_contiguous():
                p.grad = p.grad.contiguous()
        return loss

    best, best_v = start, start_validation
    t0 = time.perf_counter()
    wall0 = curve[-1]["wall"] if curve else 0.0
    for k in range(cfg.refine):
        loss = float(optim.step(closure).detach())
        model.project()
        row = {"iteration": (curve[-1]["iteration"] if curve else 0) + 1, "stage": "refine",
               "wall": wall0 + time.perf_counter() - t0, "loss": loss}
        if score is not None:
            t_eval = time.perf_counter()
            row["validation"] = score(model.values())
            t0 += time.perf_counter() - t_eval
            if row["validation"] < best_v:
                best, best_v = model.values(), row["validation"]
        else:
            best = model.values()
        curve.append(row)
        log(f"refine {k + 1:3d}/{cfg.refine}  H={h:3d}  loss {loss:.3e}"
            + (f"  validation {row['validation']:.4f} rad" if "validation" in row else "") + f"  {row['wall']:.0f}s")
    log(f"refined: validation {best_v:.4f} rad")
    return best


def identify(robot, dataset, cfg: SysIdConfig, out: str | Path | None = None, log=print,
             start: PhysicalParams | None = None, on_search=None):
    """Identify the simulator's physical parameters from ``dataset``'s training split.

    Args:
        robot: The nominal robot (the simulator side).
        dataset: A :class:`~wresdyn.data.dataset.Dataset` (``q``, ``qd``, ``q_cmd`` of train; validation selects).
        cfg: Settings.
        out: Optional run folder: ``checkpoint.pt`` (resumed; a changed config is refused), ``physics.json`` (the
            selected parameters), ``curve.json``.
        log: Progress printer.
        start: Values to start from (default the robot file's).
        on_search: Optional ``callable(GridChoice)``, called after each grid search (kp, delay, effort) with what
            it chose.

    Returns:
        ``(params, curve)``: the selected :class:`~wresdyn.sim.physics.PhysicalParams` and the learning curve.
    """
    from ..sim import Simulator, TrajectoryBank
    from .runs import check_resume, joint_weights, load_checkpoint, save_checkpoint, start_window_fit

    rng, train, dt = start_window_fit(cfg, dataset)
    model = PhysicsModel(robot, start, fit=cfg.fit, dt=dt)
    groups = [[model.u_kp, model.u_kd, model.u_armature],
              [model.u_damping, model.u_friction, model.u_effort, model.u_delay],
              [model.u_body_logdiag, model.u_body_off]]
    optim = torch.optim.Adam([{"params": [p for p in g if p.requires_grad], "scale": f}
                              for g, f in zip(groups, cfg.lr_scale)], lr=cfg.lr)
    effort_from = int(round(cfg.effort_after * cfg.iterations)) if "effort" in cfg.fit else cfg.iterations
    validation = dataset.split("validation")
    score = PhysicsScore(robot, validation, dataset.rate_hz, cfg.solver, cfg.device,
                         weights=dataset.fit_weights()) if validation else None
    select_every = max(1, cfg.select_every or cfg.iterations // 10)
    config = dataclasses.asdict(cfg)
    ckpt = Path(out) / "checkpoint.pt" if out else None
    curve, start_it, wall0 = [], 0, 0.0
    best = {"validation": float("inf"), "iteration": 0, "state": None}
    if ckpt and ckpt.exists():
        state = load_checkpoint(ckpt, map_location="cpu", keys=("model", "optim", "best", "meta"))
        meta = state["meta"]
        check_resume(ckpt.parent, meta["config"], config, RESUME_MAY_CHANGE)
        model.load_state_dict(state["model"])
        optim.load_state_dict(state["optim"])
        rng.bit_generator.state = meta["rng"]
        curve, start_it, wall0 = meta["curve"], meta["iteration"], meta["wall"]
        best = {"validation": meta["best_validation"], "iteration": meta["best_iteration"],
                "state": state["best"] or None}
        log(f"resumed from {ckpt} at iteration {start_it}")
    else:
        if score is not None:
            v0 = score(model.values())
            best = {"validation": v0, "iteration": 0, "state": _snapshot(model)}
            log(f"start: validation {v0:.4f} rad")
    sim = Simulator(robot, cfg.windows, dt, solver=cfg.solver, device=cfg.device, requires_grad=True,
                    param_grads=True)
    bank = TrajectoryBank(train, sim.device)
    weights = joint_weights(dataset, sim.device)  # joints excluded from fitting weigh 0 in the loss
    horizons = cfg.horizon_curriculum or (64,)
    t0 = time.perf_counter() - wall0
    if start_it == 0 and cfg.gain_grid:
        start_kp = model.values().kp
        searched = _grid_search(cfg, model, sim, train, rng, "kp", cfg.gain_grid, lambda g: g * start_kp, log,
                                weights, per_joint=True)
        if score is not None:  # the searched start is a candidate of the selection too, as the file's is
            v = score(model.values())  # counted in the wall-clock, as the search itself
            log(f"after the kp search: validation {v:.4f} rad")
            searched = dataclasses.replace(searched, validation=v)
            if v < best["validation"]:
                best = {"validation": v, "iteration": 0, "state": _snapshot(model)}
        if on_search:
            on_search(searched)
    with bar(log, cfg.iterations, "identify", start_it) as progress:
        for it in range(start_it, cfg.iterations):
            h = horizons[min(it * len(horizons) // cfg.iterations, len(horizons) - 1)]
            for group in optim.param_groups:
                group["lr"] = group["scale"] * float(cfg.lr_final + 0.5 * (cfg.lr - cfg.lr_final) *
                                                     (1 + np.cos(np.pi * it / cfg.iterations)))
            if it == effort_from:
                file_effort = np.asarray(robot.effort, dtype=np.float64)
                searched = [_grid_search(cfg, model, sim, train, rng, "delay", cfg.delay_grid,
                                         lambda g: np.full(robot.n_dof, g * dt), log, weights)
                            if "delay" in cfg.fit else None,
                            _grid_search(cfg, model, sim, train, rng, "effort", cfg.effort_grid,
                                         lambda g: np.where(np.isfinite(file_effort), g * file_effort, np.inf), log,
                                         weights)]
                for choice in searched:
                    if choice is not None and on_search:
                        on_search(choice)
            bank.set_delay(model.delay_steps().float().to(sim.device))
            window = bank.sample(rng, cfg.windows, h)
            loss, parts = _window_loss(cfg, model, sim, window, weights)
            loss = loss + cfg.w_prior * model.prior().to(loss.device)
            if not torch.isfinite(loss):
                raise FloatingPointError(f"identification: non-finite loss at iteration {it} (simulation diverged)")
            optim.zero_grad()
            loss.backward()
            if it < effort_from and model.u_effort.grad is not None:
                model.u_effort.grad = None  # not yet part of the fit (Adam skips a parameter without gradient)
            torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
            optim.step()
            model.project()
            row = {"iteration": it + 1, "wall": time.perf_counter() - t0, "loss": float(loss.detach()), **parts}
            if score is not None and ((it + 1) % select_every == 0 or it + 1 == cfg.iterations):
                t_eval = time.perf_counter()
                row["validation"] = score(model.values())
                t0 += time.perf_counter() - t_eval
                if row["validation"] < best["validation"]:
                    best = {"validation": row["validation"], "iteration": it + 1, "state": _snapshot(model)}
            curve.append(row)
            progress.update(1, f"H={h}  loss {row['loss']:.2e}")
            if (it + 1) % max(1, cfg.iterations // 20) == 0 or it + 1 == cfg.iterations:
                msg = f"iter {it + 1:5d}/{cfg.iterations}  H={h:3d}  loss {row['loss']:.3e}  |dq|² {parts['pos']:.3e}"
                log(msg + (f"  validation {row['validation']:.4f} rad" if "validation" in row else "") +
                    f"  {row['wall']:.0f}s")
                if ckpt:
                    meta = {"config": config, "rng": rng.bit_generator.state, "curve": curve, "iteration": it + 1,
                            "wall": row["wall"], "best_validation": best["validation"],
                            "best_iteration": best["iteration"]}
                    save_checkpoint({"model": model.state_dict(), "optim": optim.state_dict(), "meta": meta,
                                     "best": best["state"] or {}}, ckpt)
    if best["state"] is not None:
        model.load_state_dict(best["state"])
        log(f"selected iteration {best['iteration']} by validation ({best['validation']:.4f} rad)")
    params = model.values()
    if cfg.share_effort_ratio and "effort" in cfg.fit:
        params = _share_effort_ratio(cfg, robot, dataset, train, dt, params, score, best["validation"], log)
    if cfg.refine:
        params = _refine(cfg, robot, bank, dt, params, score, best["validation"], weights, curve, log)
    if out:
        Path(out).mkdir(parents=True, exist_ok=True)
        params.save(Path(out) / "physics.json")
        Path(out, "curve.json").write_text(json.dumps(curve, indent=1))
    return params, curve
