"""The steps after Adam's (:func:`~wresdyn.identify.sysid.identify`): an L-BFGS refinement (:func:`lbfgs_refine`) and
a Levenberg-Marquardt polish in the directions the data determine only (:func:`polish`), each on fixed training
windows, each step validated and the best kept; and the loss of a batch of windows they share with Adam's
(:func:`physics_window_loss`).

**The polish.** Adam's loss carries the prior w_prior |u − u_0|² (:mod:`.sysid`), which settles what the data cannot
tell apart but also pulls every well-excited coordinate towards the robot file's value: at the optimum of L_data +
w_prior |u − u_0|² a direction of data curvature H sits a fraction w_prior / (H + w_prior) of its distance from the
start short of the data's optimum (on ``mujoco.sysid``'s known-truth cases 0.05-0.4 %,
``benchmarks/peers/known_truth.py``). The polish removes that bias where the data dominate and keeps the prior's values
elsewhere::

    r(u)                  weighted residuals [√w_q (q − q_r), √w_qd (q̇ − q̇_r)] of M samples (fixed training windows)
    J = ∂r/∂u             forward differences, every coordinate perturbed in its own worlds of one batched replay
    H = JᵀJ / M           the Gauss-Newton curvature of the data loss (Adam's loss is |r|² / M)
    P                     the prior's curvature per coordinate (1, or the body off-diagonals' 1 / scale², as in
                          PhysicsModel.prior; 1 for the linear fields it leaves out)
    P^-½ H P^-½ = V Λ Vᵀ  determined directions: λ_k > polish_threshold · w_prior
    Δu = −P^-½ V_d (Λ_d + μ)⁻¹ V_dᵀ P^-½ Jᵀr / M      the step, in the determined directions only

μ is Levenberg-Marquardt's damping: a step that raises the training loss is refused and retried with ten times more.
Every accepted step replays validation and the best parameters there are kept (the start if none beats it), as the
L-BFGS refinement's. The effort limit (a flat or kinked loss) and the command path's fields (delay, servo goal
acceleration: they move the PD targets, not the model) keep their values.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np
import torch

from ..learn.window_fit import squared_error
from ..sim import Simulator, rollout
from ..sim.bank import servo_goal_accel
from ..sim.fused import can_fuse, fused_rollout
from ..sim.physics import PhysicalParams, PhysicsModel
from .identifiability import weighted_residuals

__all__ = ["lbfgs_refine", "physics_window_loss", "polish", "POLISH_FROZEN", "STEP", "MAX_WORLDS"]

POLISH_FROZEN = ("effort", "delay", "goal_accel")
"""Fields of ``fit`` the polish keeps: the effort limit (flat where a drive does not saturate, kinked where it
starts to) and the command path's fields."""
STEP = 1e-3
"""Forward-difference step in the coordinates (0.1 % of a log-scaled value): the Jacobian's truncation error (~STEP of
it) and float32 rounding (~1e-7 of an angle against a change of ~1e-4) are both about 1e-3 of it, which slows
Gauss-Newton's convergence by that factor per iteration but does not move its fixed point, where Jᵀr = 0."""
MAX_WORLDS = 1024
"""Worlds per batched replay (the coordinates' perturbations in chunks of this many, bounding memory)."""
MAX_STEP = 0.5
"""Largest change of one coordinate in a step (a factor 1.65 of a log-scaled value): far from the optimum a
Gauss-Newton step can fly to where the joint barely moves (a huge armature), whose flat loss then holds it."""
MIN_GAIN = 1e-3
"""Relative fall of the training loss below which a step ends the polish: Gauss-Newton near its optimum gains
orders of magnitude a step, so a step that gains less sits at the float32 replay's floor."""
RANK = 1e-12
"""Eigenvalues of the whitened curvature below this fraction of the largest count as zero (with ``w_prior`` 0)."""


def physics_window_loss(cfg, model, sim, window, weights=None, fused: bool = False):
    """Identification loss of one batch of windows: w_q |q − q_r|² + w_qd |q̇ − q̇_r|², summed over joints with
    per-joint ``weights`` (n,) tensor (0: a joint excluded from fitting; ``None``: all 1), mean over steps.
    ``fused``: the windows replayed in one launch (:func:`~wresdyn.sim.fused.fused_rollout`), the same states."""
    sim.set_physics(model())
    if fused:
        q, qd = fused_rollout(sim, window)
    else:
        run = rollout(sim, window, grad=True, truncation=cfg.grad_truncation or 0)
        q, qd = run.q, run.qd
    pos = squared_error(q[:, 1:], window.q[:, 1:], weights)
    vel = squared_error(qd[:, 1:], window.qd[:, 1:], weights)
    return cfg.w_q * pos + cfg.w_qd * vel, {"pos": pos.detach(), "vel": vel.detach()}  # read when logged


class _Replay:
    """The weighted residuals of the fixed windows under many parameter sets at once, one per block of worlds."""

    def __init__(self, cfg, robot, dt: float, window, weights, blocks: int) -> None:
        self.cfg, self.window = cfg, window
        self.weights = torch.ones(robot.n_dof) if weights is None else weights  # None: every joint fitted
        b = window.cmd.shape[0]
        self.per = max(1, min(blocks, MAX_WORLDS // b))
        self.sim = Simulator(robot, self.per * b, dt, solver=cfg.solver, device=cfg.device,
                             friction_kappa=cfg.friction_kappa, solver_threads=cfg.sim_threads)
        self.fused = can_fuse(self.sim)
        self.big = window.repeat(self.per)

    def __call__(self, values: list[dict]) -> np.ndarray:
        """(len(values), N) float64 residuals, ``values`` a list of PhysicsModel outputs."""
        b, out = self.window.cmd.shape[0], []
        for c in range(0, len(values), self.per):
            chunk = values[c:c + self.per]
            chunk = chunk + [chunk[-1]] * (self.per - len(chunk))  # padded: one simulator for every chunk
            fields = [f for f in chunk[0] if f != "delay"]
            self.sim.set_world_physics({f: torch.stack([v[f] for v in chunk]).repeat_interleave(b, 0)
                                        for f in fields})
            with torch.no_grad():
                run = SimpleNamespace(**dict(zip(("q", "qd"), fused_rollout(self.sim, self.big)))) if self.fused \
                    else rollout(self.sim, self.big)
            out.append(weighted_residuals(run, self.window, self.weights, self.cfg.w_q, self.cfg.w_qd, self.per))
        return torch.cat(out).numpy()[:len(values)]


def _metric(model: PhysicsModel, params: list) -> np.ndarray:
    """The prior's curvature of each coordinate (:meth:`PhysicsModel.prior`), flattened as ``params``."""
    out = []
    for p in params:
        if p is model.u_body_off:
            scale = torch.exp(model.u0_body_logdiag).amax(-1, keepdim=True)
            out.append((1.0 / scale ** 2).expand_as(p).reshape(-1))
        else:
            out.append(torch.ones(p.numel(), dtype=torch.float64))
    return torch.cat(out).detach().cpu().numpy()


def _values(model: PhysicsModel, params: list, theta: np.ndarray) -> dict:
    """The model's values at coordinates ``theta`` (the model is left there)."""
    with torch.no_grad():
        at = 0
        for p in params:  # copied in place: a coordinate tensor may not be contiguous (torch's helpers view it)
            p.copy_(torch.as_tensor(theta[at:at + p.numel()], dtype=p.dtype).reshape(p.shape))
            at += p.numel()
        return {k: v.detach().cpu() for k, v in model().items()}


def _validated_row(curve: list, stage: str, wall: float, loss: float, score, model, best, best_v):
    """A step's row of ``curve`` (appended): its iteration, ``stage``, ``wall`` [s] and training ``loss``, and its
    validation by ``score`` of ``model``'s values where there is one. Returns the row, the best parameters and their
    validation so far (``best_v`` ``None``: none yet; without ``score`` the last step's) and the seconds the
    validation took (kept out of the stage's wall clock)."""
    row = {"iteration": (curve[-1]["iteration"] if curve else 0) + 1, "stage": stage, "wall": wall, "loss": loss}
    spent = 0.0
    if score is not None:
        t = time.perf_counter()
        row["validation"] = score(model.values())
        spent = time.perf_counter() - t
        if best_v is None or row["validation"] < best_v:
            best, best_v = model.values(), row["validation"]
    else:
        best = model.values()
    curve.append(row)
    return row, best, best_v, spent


def polish(cfg, robot, bank, dt: float, start: PhysicalParams, score, weights, curve: list, log) -> PhysicalParams:
    """``cfg.polish`` Levenberg-Marquardt iterations from ``start`` (module docstring) on ``cfg.polish_windows``
    fixed windows of ``bank`` (the training trajectories) of the longest horizon; returns the best parameters on
    validation (``score``, ``None`` without a validation split: the last accepted step; ``start`` when no step beats
    it). Appends a row per accepted step to ``curve``."""
    fields = [f for f in cfg.fit if f not in POLISH_FROZEN]
    model = PhysicsModel(robot, start, fit=fields, dt=dt, shared_delay=cfg.shared_delay)
    params = [p for p in model.parameters() if p.requires_grad]
    if not params:
        log("polish: no field to polish")
        return start
    theta = torch.cat([p.detach().reshape(-1) for p in params]).cpu().numpy().astype(np.float64)
    p_count = len(theta)
    h = max(cfg.horizon_curriculum or (64,))
    bank.set_command_path(torch.as_tensor(start.delay / dt, dtype=torch.float32, device=bank.device),
                          servo_goal_accel(robot, start, dt, bank.device))
    traj, first = bank.draw(np.random.default_rng(cfg.seed + 3), cfg.polish_windows, h)
    window = bank.window(traj, first, h)
    replay = _Replay(cfg, robot, dt, window, weights, p_count + 1)
    m = window.cmd.shape[0] * h  # the samples Adam's loss averages over
    root = np.sqrt(_metric(model, params))  # P^½
    best, best_v, mu, t0 = start, None if score is None else score(start), 0.0, time.perf_counter()
    wall0 = curve[-1]["wall"] if curve else 0.0
    r = replay([_values(model, params, theta)])[0]
    for k in range(cfg.polish):
        steps = theta[None, :] + STEP * np.eye(p_count)
        jac = (replay([_values(model, params, s) for s in steps]) - r) / STEP  # (P, N): Jᵀ
        grad = jac @ r / m
        lam, vec = np.linalg.eigh((jac @ jac.T / m) / np.outer(root, root))
        floor = max(cfg.polish_threshold * cfg.w_prior, RANK * max(lam.max(), 0.0))
        keep = lam > floor
        if not keep.any():
            log(f"polish: no direction above {floor:.2e} of curvature: nothing the data determine beyond the prior")
            break
        vd, ld, g = vec[:, keep], lam[keep], vec[:, keep].T @ (grad / root)
        loss = float(r @ r) / m
        while True:
            step = (vd @ (g / (ld + mu))) / root
            new = theta - step * min(1.0, MAX_STEP / max(float(np.abs(step).max()), 1e-300))
            r_new = replay([_values(model, params, new)])[0]
            loss_new = float(r_new @ r_new) / m
            if np.isfinite(loss_new) and loss_new <= loss:
                break
            mu = max(10.0 * mu, 1e-3 * float(ld.max()))
            if mu > 1e6 * float(ld.max()):
                break
        if not (np.isfinite(loss_new) and loss_new <= loss):
            log(f"polish {k + 1:3d}/{cfg.polish}: no step lowers the training loss {loss:.3e}: stopped")
            break
        theta, r, mu = new, r_new, mu / 10.0
        _values(model, params, theta)
        row, best, best_v, spent = _validated_row(curve, "polish", wall0 + time.perf_counter() - t0, loss_new,
                                                  score, model, best, best_v)
        t0 += spent
        log(f"polish {k + 1:3d}/{cfg.polish}  {int(keep.sum())}/{p_count} directions  loss {loss_new:.3e}"
            + (f"  validation {row['validation']:.3e} rad" if "validation" in row else "") + f"  {row['wall']:.1f}s")
        if loss - loss_new <= MIN_GAIN * loss:
            break
    log("polished" + (f": validation {best_v:.3e} rad" if best_v is not None else ""))
    return best


def lbfgs_refine(cfg, robot, bank, dt, start: PhysicalParams, score, start_validation: float, weights, curve, log):
    """``cfg.refine`` L-BFGS steps from ``start`` on fixed windows of ``bank`` (the training trajectories; its delay
    is set to ``start``'s, or to the fitted one at every evaluation when the delay is refined) of the fields of
    ``cfg.fit`` outside ``cfg.refine_frozen`` (:attr:`SysIdConfig.refine`); returns the best parameters on validation
    (``start`` when no step beats ``start_validation``). Appends to ``curve``.

    Adam's steps through the multiple-shooting loss stop in a long, ill-conditioned valley: on the shipped data the
    loss keeps falling along the straight line to the true parameters (``benchmarks/fidelity/sysid_valley.py``), and a
    quasi-Newton method on a fixed batch moves along such valleys far faster. Not checkpointed: under a minute on
    2 cores, rerun on resume."""
    fields = [f for f in cfg.fit if f not in cfg.refine_frozen]
    model = PhysicsModel(robot, start, fit=fields, dt=dt, effort_floor=cfg.effort_floor if "effort" in fields else None,
                         shared_delay=cfg.shared_delay)
    h = max(cfg.horizon_curriculum or (64,))
    sim = Simulator(robot, cfg.refine_windows, dt, solver=cfg.solver, device=cfg.device, requires_grad=True,
                    param_grads=True, friction_kappa=cfg.friction_kappa, solver_threads=cfg.sim_threads)
    delay = torch.as_tensor(start.delay / dt, dtype=torch.float32, device=sim.device)
    bank.set_command_path(delay, servo_goal_accel(robot, start, dt, sim.device))
    traj, first = bank.draw(np.random.default_rng(cfg.seed + 1), cfg.refine_windows, h)
    window = bank.window(traj, first, h)
    profiled = getattr(robot, "servo", None) is not None and "goal_accel" in fields
    delayed = "delay" in fields  # the windows' PD targets move with the fitted delay
    floor = model.ref_effort * torch.as_tensor(model.effort_floor_u()).to(model.ref_effort)

    def physics():  # the line search tries points outside what project() keeps: the delay and effort held there
        v = model()
        if delayed:
            v["delay"] = v["delay"].clamp(min=0.0)
        if "effort" in fields:
            v["effort"] = torch.maximum(v["effort"], floor)
        return v

    params = [p for p in model.parameters() if p.requires_grad]
    optim = torch.optim.LBFGS(params, lr=1.0, max_iter=20, history_size=50, line_search_fn="strong_wolfe")

    def closure():
        optim.zero_grad()
        w = window
        if profiled or delayed:  # the fixed windows' targets move with the fitted goal acceleration and delay
            d = model.delay_steps().clamp(min=0.0).float().to(sim.device) if delayed else delay
            goal = model.goal_accel_steps().float().to(sim.device) if profiled else bank.goal_accel
            bank.set_command_path(d, goal)
            w = bank.window(traj, first, h)
        loss, _ = physics_window_loss(cfg, physics if delayed or "effort" in fields else model, sim, w, weights)
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
        row, best, best_v, spent = _validated_row(curve, "refine", wall0 + time.perf_counter() - t0, loss, score,
                                                  model, best, best_v)
        t0 += spent
        log(f"refine {k + 1:3d}/{cfg.refine}  H={h:3d}  loss {loss:.3e}"
            + (f"  validation {row['validation']:.4f} rad" if "validation" in row else "") + f"  {row['wall']:.0f}s")
    if delayed or profiled:  # the bank's command path back to plain values, the selected parameters'
        bank.set_command_path(torch.as_tensor(best.delay / dt, dtype=torch.float32, device=sim.device),
                              servo_goal_accel(robot, best, dt, sim.device))
    log(f"refined: validation {best_v:.4f} rad")
    return best
