"""Effort limits the training data never reaches: a shared derating instead of a number the data cannot tell.

A drive's effort limit shows in the recordings only where the drive saturates. Identification (:mod:`.sysid`)
starts every limit from one searched fraction of the robot file's and refines it by gradient, which is zero on a
joint whose drive never saturates in the replay: that joint keeps the searched fraction, a compromise of all
joints, however far it is from its own. On a robot hung on a stand this is the rule, not the exception: the legs
swing free, so hip roll, knees and ankles never need the torque that balance on the floor does, and their limits
come out where the search left them (1.6x the true ones on the shipped data, ``benchmarks/skills/effort_limits.py``).

What the data does say about such a joint:

- a lower bound: the drive delivered every torque the replay demands of it, τ = kp·(q_cmd(t − delay) − q) − kd·q̇
  on the recorded states, so its limit is at least the largest |τ| (with it the training data replays unchanged:
  the change is one the data cannot see);
- how far below the file the drives of this robot are derated: the ratio identified / file of the joints that do
  saturate (battery voltage, current limits and firmware derating act on every drive alike).

:func:`limit_unexcited_efforts` gives each joint that saturates on fewer than ``saturated_min`` of the training
samples the median ratio of those that do, times its own file limit, and never below its lower bound:
``effort_j = max(r̃ · effort_file_j, max_t |τ_j(t)|)``. It changes nothing where no joint saturates
(no ratio to share), on joints excluded from fitting and on unlimited drives.

The lower bound fails where the real drive did saturate but the fit explained the clipped torque away (friction,
gains and damping bent to the lag instead of a low limit): the joint lagged behind its command, so kp·(q_cmd − q)
grew past the torque it delivered, and the bound keeps a limit the drive never had. On the uneven mismatch's probe
data the right ankle pitch saturates on 1.3 % of the training samples against its true 15 N·m; the fit put its limit
at 34.9 N·m, its own largest demand, and the bound kept it there (``benchmarks/results/floor_fair/ident55_cpu/``).
:func:`search_unexcited_efforts` is a per-joint line search on such limits: each is replayed on the whole training
trajectories at limits from its own down to the shared derating, and takes the lowest whose own position error is
within a tolerance of the line's least.

After identification's selection, :func:`share_effort_ratio`, :func:`reset_effort_limits` and
:func:`search_unexcited_efforts` are the candidates it keeps only where validation is no worse (the search: by no
more than its tolerance): the shared ratio, the robot file's own limits put back, the searched limits
(:func:`effort_candidates` runs them in that order).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..learn.selection import ValidationScore
from ..robot.physical import PhysicalParams
from ..sim.bank import delay_commands

__all__ = ["UnexcitedLimits", "demanded_torque", "limit_unexcited_efforts", "share_effort_ratio",
           "reset_effort_limits", "search_unexcited_efforts", "effort_candidates"]


@dataclass(frozen=True)
class UnexcitedLimits:
    """What :func:`limit_unexcited_efforts` found and set."""

    saturated: np.ndarray
    """Fraction of training samples on which each joint's demanded torque exceeds its identified limit, (n,)."""
    bound: np.ndarray
    """Lower bound of each joint's limit from the data: the largest demanded torque [N·m], (n,)."""
    applied: np.ndarray
    """The largest demanded torque at or below the identified limit [N·m], (n,): the largest torque the data ask of
    the drive without saturating it, what bounds a limit the data do not saturate from below; ``bound`` where the
    data never saturate it."""
    ratio: float | None
    """Median identified / file limit over the saturating joints (``None``: no joint saturates)."""
    changed: tuple[str, ...]
    """Joints whose limit was set from the shared ratio."""
    before: np.ndarray
    """Identified limits before [N·m], (n,)."""
    after: np.ndarray
    """Limits after [N·m], (n,)."""

    def describe(self) -> str:
        """One line for the run's log."""
        if self.ratio is None:
            return "effort limits: no joint saturates in the training data; identified limits kept"
        if not self.changed:
            return f"effort limits: every fitted joint saturates in the training data (median {self.ratio:.3f} of file)"
        return (f"effort limits: {len(self.changed)} joints never saturate in the training data and take the "
                f"saturating joints' median {self.ratio:.3f} of the file's limit, at least what the data demands "
                f"({', '.join(self.changed)})")


def demanded_torque(params: PhysicalParams, trajectories, dt: float) -> np.ndarray:
    """|τ| the PD drives of ``params`` demand on the recorded states, unsaturated [N·m], shape (Σ T, n):
    τ = kp·(q_cmd(t − delay) − q) − kd·q̇, the delayed command as the replay interpolates it
    (:func:`~wresdyn.sim.bank.delay_commands`)."""
    steps = torch.as_tensor(np.asarray(params.delay, dtype=np.float64) / dt)
    tau = []
    for tr in trajectories:
        rows = torch.arange(len(tr.q_cmd))
        target = delay_commands(torch.as_tensor(tr.q_cmd, dtype=torch.float64), rows, torch.zeros_like(rows), steps)
        tau.append(params.kp * (target.numpy() - tr.q) - params.kd * tr.qd)
    return np.abs(np.concatenate(tau))


def limit_unexcited_efforts(params: PhysicalParams, file_effort, trajectories, dt: float, fitted=None,
                            saturated_min: float = 0.01) -> tuple[PhysicalParams, UnexcitedLimits]:
    """Set the effort limits that the training data cannot identify (module docstring).

    Args:
        params: Identified parameters (not modified).
        file_effort: The robot file's effort limits [N·m], (n,).
        trajectories: Training recordings (``q``, ``qd``, ``q_cmd``, (T, n) each).
        dt: Sample period [s].
        fitted: Per joint, whether it is fitted, (n,) bool (default: all); the others are left alone.
        saturated_min: Fraction of samples on which a joint must saturate for its limit to count as identified.

    Returns:
        ``(params, found)``: a copy of ``params`` with the limits set, and :class:`UnexcitedLimits`.
    """
    tau = demanded_torque(params, trajectories, dt)
    before = np.asarray(params.effort, dtype=np.float64)
    file_effort = np.asarray(file_effort, dtype=np.float64)
    n = len(before)
    fitted = np.ones(n, dtype=bool) if fitted is None else np.asarray(fitted, dtype=bool)
    limited = fitted & np.isfinite(before) & np.isfinite(file_effort) & (file_effort > 0)
    saturated = (tau > before).mean(0)
    bound = tau.max(0)
    applied = np.where(tau <= before, tau, 0.0).max(0)
    seen = limited & (saturated >= saturated_min)
    out = params.copy()
    if not seen.any():
        return out, UnexcitedLimits(saturated, bound, applied, None, (), before, before.copy())
    ratio = float(np.median(before[seen] / file_effort[seen]))
    unseen = limited & ~seen
    after = before.copy()
    after[unseen] = np.maximum(ratio * file_effort[unseen], bound[unseen])
    out.effort = after
    changed = tuple(name for name, u in zip(params.joint_names, unseen) if u)
    return out, UnexcitedLimits(saturated, bound, applied, ratio, changed, before, after.copy())


def share_effort_ratio(cfg, robot, dataset, train, dt, params, score, validation, log):
    """Identification's selected ``params`` with the effort limits the training data never reaches set from the
    saturating joints' ratio (:func:`limit_unexcited_efforts`, ``cfg.share_effort_ratio``), unless that is worse on
    validation (``score(params) -> rad``, ``None``: no validation split; ``validation``: the selected parameters');
    returns (parameters, their validation, or ``None`` where nothing was replayed)."""
    shared, found = limit_unexcited_efforts(params, robot.effort, train, dt, fitted=dataset.fit_weights() > 0,
                                            saturated_min=cfg.saturated_min)
    log(found.describe())
    if not found.changed or score is None:
        return shared, None
    v = score(shared)
    if v > validation:
        log(f"  not kept: validation {v:.4f} rad against {validation:.4f} rad")
        return params, None
    log(f"  validation {v:.4f} rad (was {validation:.4f} rad)")
    return shared, v


def reset_effort_limits(robot, params, score, validation, fitted, log):
    """The selected parameters with the fitted joints' effort limits put back at the robot file's, if that is better
    on validation (:attr:`~wresdyn.identify.sysid_config.SysIdConfig.effort_reset`); returns (parameters, their
    validation)."""
    file = np.asarray(robot.effort, dtype=np.float64)
    reset = params.copy()
    reset.effort = np.where(fitted & np.isfinite(file), file, params.effort)
    if score is None or np.array_equal(reset.effort, params.effort):
        return params, validation
    v = score(reset)
    kept = v < validation
    log(f"effort limits at the file's: validation {v:.4f} rad against {validation:.4f} rad, "
        + ("kept" if kept else "not kept"))
    return (reset, v) if kept else (params, validation)


def search_unexcited_efforts(cfg, robot, dataset, train, dt, params, score, validation, log):
    """The per-joint effort line search (``cfg.effort_line_points``, module docstring) from ``params``: returns
    (parameters, their validation; ``validation`` where nothing changed).

    The joints searched saturate on fewer than ``cfg.saturated_min`` of the training samples and have a limit above
    r̃·effort_file (:func:`limit_unexcited_efforts`'s shared ratio). Each is replayed alone, the others at ``params``,
    at ``cfg.effort_line_points`` limits geometrically spaced from its own (included) down to r̃·effort_file, and
    takes the lowest whose own mean |Δq| over the whole training trajectories is within ``cfg.effort_line_tolerance``
    of the line's least. The searched limits are replayed together on validation (``score(params) -> rad``,
    ``None``: no split) and kept unless worse than ``validation`` by more than the same tolerance."""
    fitted = dataset.fit_weights() > 0
    _, found = limit_unexcited_efforts(params, robot.effort, train, dt, fitted=fitted, saturated_min=cfg.saturated_min)
    if found.ratio is None:
        return params, validation
    floor = found.ratio * np.asarray(robot.effort, dtype=np.float64)
    before = np.asarray(params.effort, dtype=np.float64)
    joints = [j for j, name in enumerate(params.joint_names) if name in found.changed and before[j] > floor[j]]
    if not joints:
        log("effort line search: no unexcited limit above the shared derating")
        return params, validation
    # whole trajectories, not the grid searches' windows: a saturation on 1 % of the samples is a few short episodes
    # (the probe's steps), which a batch of random windows may miss and a whole replay never does
    replay = ValidationScore(robot, train, dataset.rate_hz, cfg.solver, cfg.device, weights=dataset.fit_weights(),
                             friction_kappa=cfg.friction_kappa)
    after = before.copy()
    for j in joints:
        line = np.geomspace(before[j], floor[j], cfg.effort_line_points + 1)
        errors = []
        for limit in line:
            replay.physics = params.copy()
            replay.physics.effort = np.where(np.arange(len(before)) == j, limit, before)
            replay()
            errors.append(replay.last_errors[j])
        errors = np.asarray(errors)
        after[j] = line[np.flatnonzero(errors <= (1 + cfg.effort_line_tolerance) * errors.min()).max()]
        log(f"effort line search {params.joint_names[j]}: "
            + "  ".join(f"{x:.3g}:{e:.3e}" for x, e in zip(line, errors)) + f"  -> {after[j]:.3g} N·m")
    if np.array_equal(after, before):
        return params, validation
    out = params.copy()
    out.effort = after
    if score is None:
        return out, validation
    v = score(out)
    if v > (1 + cfg.effort_line_tolerance) * validation:
        log(f"  not kept: validation {v:.4f} rad against {validation:.4f} rad")
        return params, validation
    log(f"  validation {v:.4f} rad (was {validation:.4f} rad)")
    return out, v


def effort_candidates(cfg, robot, dataset, train, dt, params, score, validation, log):
    """Identification's selected ``params`` through the effort-limit candidates ``cfg`` turns on, in order
    (:func:`share_effort_ratio`, :func:`reset_effort_limits`, :func:`search_unexcited_efforts`); returns (parameters,
    the validation the refinement starts from). Nothing is done unless the effort limit is fitted."""
    if "effort" not in cfg.fit:
        return params, validation
    shared = None
    if cfg.share_effort_ratio:
        params, shared = share_effort_ratio(cfg, robot, dataset, train, dt, params, score, validation, log)
    if cfg.effort_reset:
        params, validation = reset_effort_limits(robot, params, score, validation if shared is None else shared,
                                                 dataset.fit_weights() > 0, log)
    if cfg.effort_line_points:  # compared with the parameters it starts from: the reset's, else the shared ratio's
        current = validation if shared is None or cfg.effort_reset else shared
        searched, v = search_unexcited_efforts(cfg, robot, dataset, train, dt, params, score, current, log)
        if searched is not params:
            params, validation = searched, v
    return params, validation
