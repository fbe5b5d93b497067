"""What the data can identify: the Gauss-Newton (Fisher) information of the validation loss at the identified
parameters, and the parameters the recordings never excite, each with one line of advice.

The identification loss (:func:`~wresdyn.identify.sysid.physics_window_loss`) is a sum of squares of weighted
residuals r = [√w_q (q − q_r), √w_qd (q̇ − q̇_r)] over steps and fitted joints. Over B validation windows of H steps,
with the parameters θ in relative coordinates (θ_i = log v_i, so a unit of θ is a factor e and a small step a
fraction of the value; a parameter whose value is 0 moves in its reference unit instead, ``PhysicsModel.ref``):

    J = ∂r/∂θ                   forward differences, every parameter perturbed in its own worlds of ONE batched replay
    σ² = |r|² / (N − P)          the residual variance (N residuals, P parameters)
    F = Jᵀ J / σ²                the Gauss-Newton approximation of the Fisher information
    SE_i = √(F⁻¹)_ii             the standard error of θ_i: ×100 a relative error in %
    ρ_ij = (F⁻¹)_ij / (SE_i SE_j)   the correlation of the estimates

F is inverted on unit columns (J_i / |J_i|) with a ridge of :data:`RIDGE`, so an exactly degenerate pair gets an
enormous but finite error. The residuals are model error as much as noise and correlated in time, so the errors are
a lower bound and best read as a ranking; groups with |ρ| > :data:`CORRELATED` are combinations the data fix while
the members trade against each other.

Beside the information, the excitation itself, read on the training split (the data identification learns from):
effort limits whose drive never saturates (:func:`~wresdyn.identify.unexcited_limits.limit_unexcited_efforts`, the
rule identification applies: the validation windows of a robot on a stand rarely saturate a drive either, so the
information there says nothing about the limit a probe's training trajectories do identify), joints that barely
move, command delays below one sample period, and parameters with tiny sensitivity (|J_i| < σ: a 100 % error even
with every other parameter known). The same pass over the training data records, per limited fitted joint, the
largest torque the identified drive is asked for without saturating (``demanded_effort_nm``) and the share of
samples that ask for more (``effort_saturated``): a limit saturated on fewer than ``saturated_min`` of them is bounded
by the data from below only, by that torque. Written as ``identifiability.json`` and ``identifiability.md``
(:func:`write_identifiability`).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..data.dataset import MOVING_SPEED
from ..sim import Simulator, TrajectoryBank, rollout
from ..sim.bank import servo_goal_accel
from ..sim.physics import PhysicsModel
from .unexcited_limits import limit_unexcited_efforts

__all__ = ["Identifiability", "identifiability", "write_identifiability", "weighted_residuals", "CORRELATED", "STEP",
           "RIDGE", "MIN_RANGE", "MIN_MOVING"]

STEP = 0.01
"""Forward-difference step in θ (1 % of a value, or 0.01 of the reference unit where the value is 0): far above the
float32 replay's rounding (~1e-7 of a joint angle), small against the curvature of the loss."""
RIDGE = 1e-9
"""Ridge on the unit-diagonal information before its inversion (an exactly degenerate pair stays finite)."""
CORRELATED = 0.95
"""|ρ| above which two parameters count as ones the data cannot tell apart."""
MIN_RANGE = 0.05
"""Range of motion [rad] below which a joint counts as still (its inertia, damping and gains barely show)."""
MIN_MOVING = 0.05
"""Fraction of moving samples below which a joint counts as still."""
MAX_WORLDS = 1024
"""Worlds per batched replay (the parameters' perturbations in chunks of this many, bounding memory)."""

ADVICE = {
    "unexcited_effort": "record with `wresdyn collect --probe-saturation 6` (steps each leg joint of the foot "
                        "excitation into its limit); a joint the probe does not step (arms, joint-space robots) "
                        "needs a recording that loads it to its limit: fast steps, or holds where gravity exceeds it",
    "still_joint": "larger amplitude: `--excitation.amplitude`, `--excitation.radius-frac`, `--excitation.tilt` "
                   "(hip yaw, ankles), so the joint moves over more than a few degrees",
    "delay_below_sample": "a delay under one sample shows only as phase at the top of the band: faster chirps "
                          "(`--excitation.band` up to 15-20 Hz) or a higher `--rate`",
    "correlated": "the data fix only a combination: excite the members apart (other poses, amplitudes, frequency "
                  "bands) or leave one out of `--fit`",
}
"""One line of advice per flag kind: the ``collect`` option or recording that would excite it."""
INSENSITIVE_ADVICE = {
    "kp": "steps and holds against gravity: larger amplitude and longer holds",
    "kd": "faster chirps (`--excitation.band`, `--excitation.peak-rate`)",
    "armature": "faster chirps and larger accelerations (`--excitation.band`, `--excitation.peak-rate`)",
    "damping": "faster motion: higher `--excitation.peak-rate`, larger `--excitation.amplitude`",
    "friction": "longer holds and slow reversals (a lower `--excitation.band` and `--excitation.omega`)",
    "delay": "faster chirps (`--excitation.band` up to 15-20 Hz)",
    "effort": ADVICE["unexcited_effort"],
    "body_mass": "larger amplitude over more poses (`--excitation.radius-frac`, `--excitation.amplitude`)",
    "body_inertia": "faster chirps over more poses (`--excitation.peak-rate`, `--excitation.radius-frac`)",
}
"""Advice for a parameter with tiny sensitivity, by field."""


@dataclass
class Identifiability:
    """What :func:`identifiability` found (the module docstring's quantities)."""

    names: list[str]
    """Parameter names, ``field:joint`` or ``field:body``, (P,)."""
    values: np.ndarray
    """Identified values [SI], (P,)."""
    relative: np.ndarray
    """Whether θ_i is relative (value > 0) or in the reference unit ``unit`` (value 0), (P,) bool."""
    unit: np.ndarray
    """Reference unit of an absolute θ_i [SI], (P,)."""
    sensitivity: np.ndarray
    """|J_i| / √N: RMS change of the weighted residual per unit θ_i, (P,)."""
    se: np.ndarray
    """Standard error of θ_i (×100: % of the value), (P,)."""
    se_alone: np.ndarray
    """Standard error of θ_i with every other parameter known, σ / |J_i|, (P,)."""
    corr: np.ndarray
    """Correlation of the estimates, (P, P)."""
    sigma: float
    """Residual standard deviation σ (weighted, ~rad)."""
    n_residuals: int
    groups: list[list[str]]
    """Parameter groups with |ρ| > :data:`CORRELATED` (connected), largest first."""
    flags: list[dict]
    """``{"kind", "parameters", "detail", "advice"}``, one per finding."""
    windows: int
    steps: int
    seconds: float
    """Wall-clock of the report [s]."""
    effort_demand: dict | None = None
    """``{"demanded_effort_nm": {joint: N·m}, "effort_saturated": {joint: share}, "effort_saturated_min": share}``
    over the training data, for each limited fitted joint (``None``: the effort limit not fitted)."""

    def to_dict(self) -> dict:
        params = [{"name": n, "value": float(v), "coordinate": "relative" if r else f"absolute ({u:.3g} SI)",
                   "sensitivity": float(s), "se_pct": 100 * float(e) if r else None,
                   "se": _finite(e), "se_alone": _finite(a)}
                  for n, v, r, u, s, e, a in zip(self.names, self.values, self.relative, self.unit, self.sensitivity,
                                                 self.se, self.se_alone)]
        return {"windows": self.windows, "steps": self.steps, "n_residuals": self.n_residuals, "sigma": self.sigma,
                "seconds": round(self.seconds, 3), "correlated_above": CORRELATED, "parameters": params,
                "groups": self.groups, "flags": self.flags, "names": self.names,
                "correlation": np.round(self.corr, 4).tolist(), **(self.effort_demand or {})}

    def markdown(self) -> str:
        """The run report's section."""
        lines = ["## What the data can identify", "",
                 f"Gauss-Newton information of the validation loss over {self.windows} windows of {self.steps} steps "
                 f"(σ = {self.sigma:.2e}, {len(self.names)} parameters, {self.seconds:.1f} s; "
                 "`identifiability.json`). Standard errors are lower bounds (model error counts as noise).", ""]
        order = np.argsort(-np.where(np.isfinite(self.se), self.se, -np.inf))
        rel = [i for i in order if self.relative[i] and np.isfinite(self.se[i])][:10]
        if rel:  # the infinite ones (nothing in the loss moves with them) are flagged below
            lines += ["Largest finite relative standard errors: " + ", ".join(
                f"{self.names[i]} {_pct(self.se[i])}" for i in rel) + ".", ""]
        if not self.flags:
            lines += ["No flags: every parameter is excited and told apart.", ""]
        else:
            lines += ["| flag | parameters | detail | advice |", "|---|---|---|---|"]
            for f in self.flags:
                lines.append(f"| {f['kind']} | {', '.join(f['parameters'])} | {f['detail']} | {f['advice']} |")
            lines.append("")
        return "\n".join(lines)

    def summary(self) -> str:
        """One line for the run's log."""
        kinds: dict[str, int] = {}
        for f in self.flags:
            kinds[f["kind"]] = kinds.get(f["kind"], 0) + len(f["parameters"])
        what = ", ".join(f"{k} {v}" for k, v in kinds.items()) or "no flags"
        return (f"identifiability: {len(self.names)} parameters over {self.windows} validation windows of "
                f"{self.steps} steps in {self.seconds:.1f} s: {what}")


def _finite(x: float):
    return float(x) if np.isfinite(x) else None


def _pct(x: float) -> str:
    return f"{100 * x:.3g} %" if np.isfinite(x) else "∞"


def _parameters(robot, params, fields, fitted: np.ndarray):
    """The parameters in θ: (name, field, index, value, unit) for each fitted joint field's fitted, finite joints
    and, with ``"bodies"``, each moving link's mass and inertia (scaled whole: the principal moments together)."""

    model = PhysicsModel(robot, params, fit=fields)
    refs, moving = model.ref, set(model.moving.tolist())
    out = []
    for f in ("kp", "kd", "armature", "damping", "friction", "effort", "delay"):
        if f not in fields:
            continue
        v = np.asarray(getattr(params, f), dtype=np.float64)
        for j, name in enumerate(robot.joint_names):
            if fitted[j] and np.isfinite(v[j]) and (f != "effort" or v[j] > 0):
                unit = float(refs[f][j]) if f in refs else 1.0
                out.append((f"{f}:{name}", f, j, float(v[j]), unit))
    if "bodies" in fields:
        mass = np.asarray(params.body_mass)
        for b, name in enumerate(robot.body_names):
            if b in moving:  # as identification fits them: mass > 0 and not welded to the world
                out.append((f"body_mass:{name}", "body_mass", b, float(mass[b]), 1.0))
                out.append((f"body_inertia:{name}", "body_inertia", b, float(np.trace(params.body_inertia[b])), 1.0))
    return out


def weighted_residuals(run, window, weights, w_q: float, w_qd: float, copies: int) -> torch.Tensor:
    """Weighted residuals of ``copies`` blocks of the window batch: (copies, N) float64."""
    w = torch.sqrt(torch.as_tensor(weights, dtype=torch.float32, device=run.q.device))
    q = (run.q[:, 1:] - window.q[:, 1:].repeat(copies, 1, 1)) * w * w_q ** 0.5
    qd = (run.qd[:, 1:] - window.qd[:, 1:].repeat(copies, 1, 1)) * w * w_qd ** 0.5
    r = torch.cat([q, qd], -1).reshape(copies, -1)
    return torch.nan_to_num(r.double().cpu(), nan=1e3, posinf=1e3, neginf=-1e3)  # a diverged world: a large residual


def _jacobian(robot, params, plist, validation, dt, cfg, weights):
    """(r0 (N,), Jᵀ (P, N), windows, steps) by forward differences, the perturbations batched (:data:`MAX_WORLDS`
    worlds a replay)."""
    b = cfg.identifiability_windows
    blocks = [None, *range(len(plist))]  # None: the identified parameters themselves
    n_chunks = -(-len(blocks) * b // MAX_WORLDS)
    per_chunk = -(-len(blocks) // n_chunks)
    padded = blocks + [None] * (n_chunks * per_chunk - len(blocks))  # equal chunks: one simulator for all
    sim = Simulator(robot, per_chunk * b, dt, solver=cfg.solver, device=cfg.device, friction_kappa=cfg.friction_kappa,
                    solver_threads=cfg.sim_threads)
    delay0 = torch.as_tensor(params.delay / dt, dtype=torch.float32, device=sim.device)
    goal = servo_goal_accel(robot, params, dt, sim.device)  # servo joints' goal profile (None without servos)
    bank = TrajectoryBank(validation, sim.device, delay=delay0, goal_accel=goal)
    steps = min(max(cfg.horizon_curriculum or (64,)), int(max(len(t.q) for t in validation)) - 1)
    traj, first = bank.draw(np.random.default_rng(cfg.seed + 2), b, steps)
    window = bank.window(traj, first, steps)
    rows = bank.rows(traj, first, steps)[:, :-1]
    servo = () if goal is None else ("deadband", "noload_speed", "startup_torque", "stiction", "backlash",
                                   "encoder_offset", "load_friction")  # kept as identified
    base = {f: torch.as_tensor(np.asarray(getattr(params, f), dtype=np.float64))
            for f in ("kp", "kd", "armature", "damping", "friction", "effort", "body_mass", "body_inertia", *servo)}
    r_all = []
    for c in range(0, len(padded), per_chunk):
        chunk = padded[c:c + per_chunk]
        values = {f: v.unsqueeze(0).repeat(len(chunk), *([1] * v.dim())) for f, v in base.items()}
        target = window.target.repeat(len(chunk), 1, 1)
        for k, p in enumerate(chunk):
            if p is None:
                continue
            _, f, i, v, unit = plist[p]
            if f == "delay":  # the command path's: other PD targets in this block's worlds
                delay = delay0.clone()
                delay[i] = (v * (1 + STEP) if v > 0 else STEP * unit) / dt
                bank.set_command_path(delay, goal)
                target[k * b:(k + 1) * b] = bank.target(rows)
                bank.set_command_path(delay0, goal)
            else:
                x = values[f][k]
                x[i] = x[i] * (1 + STEP) if v > 0 else x[i] + STEP * unit
        sim.set_world_physics({f: v.repeat_interleave(b, 0) for f, v in values.items()})
        big = window.repeat(len(chunk))
        big.target = target
        with torch.no_grad():
            run = rollout(sim, big)
        r_all.append(weighted_residuals(run, window, weights, cfg.w_q, cfg.w_qd, len(chunk)))
    r = torch.cat(r_all).numpy()[:len(blocks)]
    scale = np.array([np.log1p(STEP) if v > 0 else STEP for *_, v, _ in plist])  # the step in θ
    return r[0], (r[1:] - r[0]) / scale[:, None], b, steps


def _groups(names, corr, valid) -> list[list[str]]:
    """Connected components of |ρ| > :data:`CORRELATED` among ``valid`` parameters, largest first."""
    p = len(names)
    parent = list(range(p))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in zip(*np.nonzero(np.triu(np.abs(corr) > CORRELATED, 1))):
        if valid[i] and valid[j]:
            parent[root(i)] = root(j)
    comps: dict[int, list[str]] = {}
    for i in range(p):
        if valid[i]:
            comps.setdefault(root(i), []).append(names[i])
    return sorted((c for c in comps.values() if len(c) > 1), key=len, reverse=True)


def _excitation_flags(robot, params, train, dt, fitted, fields, cfg) -> tuple[list[dict], dict | None]:
    """Flags from the training recordings: unsaturated effort limits, still joints, delays below a sample; and the
    effort demand (:attr:`Identifiability.effort_demand`)."""
    flags, demand = [], None
    if "effort" in fields:
        _, found = limit_unexcited_efforts(params, robot.effort, train, dt, fitted=fitted,
                                           saturated_min=cfg.saturated_min)
        effort = np.asarray(params.effort)
        limited = [j for j in range(robot.n_dof) if fitted[j] and np.isfinite(effort[j]) and effort[j] > 0]
        demand = {"demanded_effort_nm": {robot.joint_names[j]: float(found.applied[j]) for j in limited},
                  "effort_saturated": {robot.joint_names[j]: float(found.saturated[j]) for j in limited},
                  "effort_saturated_min": float(cfg.saturated_min)}
        never = [j for j in range(robot.n_dof) if fitted[j] and np.isfinite(effort[j])
                 and found.saturated[j] < cfg.saturated_min]
        if never:
            flags.append({"kind": "unexcited_effort", "parameters": [f"effort:{robot.joint_names[j]}" for j in never],
                          "detail": "saturated on " + ", ".join(f"{100 * found.saturated[j]:.2g} %" for j in never)
                                    + f" of training samples (< {100 * cfg.saturated_min:.3g} %); the data bound "
                                    "them from below only", "advice": ADVICE["unexcited_effort"]})
    qd = np.concatenate([t.qd for t in train])
    span = np.max([t.q.max(0) - t.q.min(0) for t in train], axis=0)
    moving = (np.abs(qd) > MOVING_SPEED).mean(0)
    still = [j for j in range(robot.n_dof) if fitted[j] and (span[j] < MIN_RANGE or moving[j] < MIN_MOVING)]
    if still:
        flags.append({"kind": "still_joint", "parameters": [robot.joint_names[j] for j in still],
                      "detail": "range / moving: " + ", ".join(f"{span[j]:.3f} rad / {100 * moving[j]:.2g} %"
                                                               for j in still)
                                + f" (thresholds {MIN_RANGE} rad, {100 * MIN_MOVING:.3g} %)",
                      "advice": ADVICE["still_joint"]})
    if "delay" in fields:
        short = [j for j in range(robot.n_dof) if fitted[j] and params.delay[j] < dt]
        if short:
            flags.append({"kind": "delay_below_sample", "parameters": [f"delay:{robot.joint_names[j]}" for j in short],
                          "detail": ", ".join(f"{1e3 * params.delay[j]:.2g} ms" for j in short)
                                    + f" < the sample period {1e3 * dt:.3g} ms",
                          "advice": ADVICE["delay_below_sample"]})
    return flags, demand


def identifiability(robot, dataset, params, cfg) -> Identifiability | None:
    """The identifiability of ``params`` (the identified :class:`~wresdyn.robot.physical.PhysicalParams`) on
    ``dataset`` under the identification settings ``cfg`` (:class:`~wresdyn.identify.sysid_config.SysIdConfig`:
    its fields, loss weights, solver and ``identifiability_windows``); ``None`` without a validation split."""
    t0 = time.perf_counter()
    validation, train = dataset.split("validation"), dataset.split("train")
    if not validation:
        return None
    dt = 1.0 / dataset.rate_hz
    fitted = dataset.fit_weights() > 0
    fields = set(cfg.fit)
    plist = _parameters(robot, params, fields, fitted)
    r0, jac_t, b, steps = _jacobian(robot, params, plist, validation, dt, cfg, dataset.fit_weights())
    p, n = jac_t.shape
    sigma2 = float(r0 @ r0) / max(n - p, 1)
    info = jac_t @ jac_t.T  # JᵀJ
    norm = np.sqrt(np.diag(info))
    valid = norm > 0
    inv_norm = 1.0 / np.where(valid, norm, 1.0)
    info = info * np.outer(inv_norm, inv_norm) + RIDGE * np.eye(p)  # of the unit columns J_i / |J_i|
    cov = np.linalg.inv(info)
    d = np.sqrt(np.diag(cov))
    with np.errstate(divide="ignore", invalid="ignore"):
        se = np.where(valid, np.sqrt(sigma2) * d / norm, np.inf)
        se_alone = np.where(valid, np.sqrt(sigma2) / norm, np.inf)
        corr = np.where(np.outer(valid, valid), cov / np.outer(d, d), 0.0)
    names = [x[0] for x in plist]
    groups = _groups(names, corr, valid)
    flags, demand = _excitation_flags(robot, params, train, dt, fitted, fields, cfg)
    weak = [i for i in range(p) if se_alone[i] > 1.0 and plist[i][1] != "effort"]
    for f in dict.fromkeys(plist[i][1] for i in weak):
        members = [i for i in weak if plist[i][1] == f]
        flags.append({"kind": "insensitive", "parameters": [names[i] for i in members],
                      "detail": "error alone " + ", ".join(_pct(se_alone[i]) for i in members)
                                + " (|J_i| < σ: 100 % even with every other parameter known)",
                      "advice": INSENSITIVE_ADVICE[f]})
    for g in groups:
        idx = [names.index(x) for x in g]
        worst = max(abs(corr[i, j]) for i in idx for j in idx if i != j)
        flags.append({"kind": "correlated", "parameters": g, "detail": f"|ρ| up to {worst:.3f}",
                      "advice": ADVICE["correlated"]})
    return Identifiability(names, np.array([x[3] for x in plist]), np.array([x[3] > 0 for x in plist]),
                           np.array([x[4] for x in plist]), norm / np.sqrt(n), se, se_alone, corr,
                           float(np.sqrt(sigma2)), n, groups, flags, b, steps, time.perf_counter() - t0, demand)


def write_identifiability(out, found: Identifiability) -> Path:
    """Write ``identifiability.json`` and ``identifiability.md`` to the run folder ``out``; returns the JSON's path."""
    out = Path(out)
    (out / "identifiability.json").write_text(json.dumps(found.to_dict(), indent=1))
    (out / "identifiability.md").write_text(found.markdown())
    return out / "identifiability.json"
