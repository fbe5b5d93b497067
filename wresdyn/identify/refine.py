"""The identification's loss on a batch of windows and the L-BFGS refinement that may follow its Adam steps
(:attr:`~wresdyn.identify.sysid_config.SysIdConfig.refine`)."""

from __future__ import annotations

import time

import numpy as np
import torch

from ..learn.window_fit import squared_error
from ..sim import Simulator, rollout
from ..sim.bank import servo_goal_accel
from ..sim.fused import fused_rollout
from ..sim.physics import PhysicalParams, PhysicsModel

__all__ = ["physics_window_loss", "refine"]


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


def refine(cfg, robot, bank, dt, start: PhysicalParams, score, start_validation: float, weights, curve, log):
    """``cfg.refine`` L-BFGS steps from ``start`` on fixed windows of ``bank`` (the training trajectories; its delay
    is set to ``start``'s, or to the fitted one at every evaluation when the delay is refined) of the fields of
    ``cfg.fit`` outside ``cfg.refine_frozen`` (:attr:`~wresdyn.identify.sysid_config.SysIdConfig.refine`); returns
    the best parameters on validation (``start`` when no step beats ``start_validation``). Appends to ``curve``.

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
    if delayed or profiled:  # the bank's command path back to plain values, the selected parameters'
        bank.set_command_path(torch.as_tensor(best.delay / dt, dtype=torch.float32, device=sim.device),
                              servo_goal_accel(robot, best, dt, sim.device))
    log(f"refined: validation {best_v:.4f} rad")
    return best
