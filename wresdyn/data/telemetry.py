"""Telemetry checks of imported real-robot logs: sampling, stuck signals, idle commands, units.

Every importer's runs pass through :func:`~wresdyn.data.importers.import_runs`, which calls :func:`check_run` on
each run as read (the log's own stamps, robot joint order, SI units, before resampling, so gaps and jitter are still
visible). Each defect is a :class:`Finding` with a one-line message; ``wresdyn collect --logs`` prints them as
``warning:`` lines and writes them to ``OUT/telemetry.json``. A run that cannot be used at all (gaps over most of
it, every fitted joint's measurement frozen while commands move) is a :class:`~wresdyn.data.dataset.DatasetError`
instead. The checks and what to do about each: docs/logs.md, "Telemetry checks".

Pure numpy; every threshold is a named constant below with the reason for its size.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from .dataset import DatasetError

__all__ = ["Finding", "check_run", "check_runs", "check_sampling", "check_stuck", "check_commands",
           "check_never_excited", "check_units"]

JITTER_WARN = 0.10
"""Std of the sample interval / median interval (gaps left out) above which the sampling is called jittery. A
loop whose period varies by more than 10 % was late often enough that its commands took effect at times the
stamps only roughly say; the shipped SO-101 logs (SAGE, 50 Hz) stay below 0.1 %."""
GAP_FACTOR = 2.5
"""An interval this many median intervals long or longer is a gap: at least one sample is missing. 2.5 stays clear
of jitter (an interval 1.5x the median is a late sample, not a lost one) and counts a single dropped sample (2x)
once it is late by a quarter of a period."""
GAP_UNUSABLE_FRACTION = 0.5
"""Gaps covering more than this fraction of a run's duration make it unusable (an error): most of the resampled
trajectory would be straight lines drawn across missing data."""
STUCK_ERROR_RAD = 0.2
"""A measured position that repeats exactly while the held command is this far from it [rad] is stuck. Larger than
what a working position servo leaves: on the shipped SO-101 logs the STS3215's deadband and stiction hold a joint
still against command changes of up to 0.1 rad, and its response lag briefly lets steps of 0.24 rad (PRBS) pass
before the joint follows."""
STUCK_SECONDS = 0.5
"""...for at least this long [s]: several times a position servo's response lag (about 0.1 s on the SO-101), so a
command step the joint is about to follow is not called stuck."""
STUCK_MIN_SAMPLES = 5
"""...and at least this many samples, so a 30 fps log or a short run needs more than a couple of repeats."""
UNITS_BEYOND_RAD = 1.0
"""A position (measured or commanded) this far outside the robot file's joint range [rad] has wrong units, scale
or zero: a calibration offset or a loose limit in the file is a few tenths of a radian, degrees read as radians
put a 10 degree angle 9.8 rad out."""
UNITS_DEG_MARGIN_RAD = 0.2
"""Degrees are suggested when the values spread wider than the joint range plus this much [rad] and, times pi/180,
lie within the range widened by this much (the few tenths a calibration may be off by)."""
VELOCITY_RATIO_MAX = 5.0
"""A logged velocity whose typical size is more than this factor off the derivative of the logged position has
other units (degrees per second: 57x; a raw tick rate: hundreds). Servo velocity estimates are coarse: on the
shipped SO-101 logs the ratio is 0.67-1.34 on the arm joints and 2.3 on the gripper's remapped 0..1 range."""
VELOCITY_MOVING_RAD_S = 0.05
"""Only samples where the position's derivative exceeds this [rad/s] enter the velocity ratio: at rest both are
quantisation noise."""
VELOCITY_MIN_SAMPLES = 10
"""Moving samples needed before the velocity ratio is judged at all."""


@dataclass(frozen=True)
class Finding:
    """One defect of one run (one joint, or the whole run for the sampling checks)."""

    run: str
    """The run's name (the trajectory it becomes); ``""`` for a check over every run (``never_excited``)."""
    joint: str
    """The robot joint; ``""`` for a check of the whole run (sampling); comma-separated joints for
    ``command_constant``."""
    check: str
    """``"jitter"``, ``"gaps"``, ``"clipped"``, ``"frozen"``, ``"command_constant"``, ``"never_excited"``,
    ``"units"`` or ``"velocity_units"``."""
    numbers: dict = field(default_factory=dict)
    """The figures behind it (SI units; keys say which)."""
    message: str = ""
    """One line, naming the run, the joint and what to do."""

    def to_dict(self) -> dict:
        return asdict(self)


def check_run(name: str, log: dict, joint_names: list[str], lower: np.ndarray, upper: np.ndarray,
              excluded: tuple[str, ...] = (), where: str = "") -> list[Finding]:
    """Every check on one run as read (:func:`~wresdyn.data.logs.read_log` arrays).

    Args:
        name: the run's name.
        log: ``t`` (N,) [s], ``q`` (N, n) [rad], ``q_cmd`` (M, n) [rad] on ``t_cmd`` (M,) [s] (or on ``t``),
            ``qd`` (N, n) [rad/s] or None.
        joint_names: the robot's joints, the columns, (n,).
        lower, upper: the robot's joint limits [rad], (n,), infinite where unlimited.
        excluded: joints not fitted: only their units are checked.
        where: prefix of an error message (the run's file).

    Raises:
        DatasetError: the run cannot be used (gaps over most of it; every fitted joint frozen while commands move).
    """
    t, q = log["t"], log["q"]
    t_cmd = log.get("t_cmd")
    held = q_cmd_at(log)  # (N, n): the command in force at each state stamp
    fitted = [j for j, n in enumerate(joint_names) if n not in excluded]
    findings = check_sampling(name, t, where)
    if fitted and len(t) >= STUCK_MIN_SAMPLES:
        whole = np.ptp(q[:, fitted], axis=0) == 0
        moving = np.ptp(log["q_cmd"][:, fitted], axis=0) > STUCK_ERROR_RAD  # further than a servo's deadband
        if whole.all() and moving.any():
            raise DatasetError(f"{where or name}: every fitted joint's measured position is constant over the whole "
                               "run while commands move: the state stream is frozen (positions never read?); fix or "
                               "drop this run")
    for j in fitted:
        findings += check_stuck(name, joint_names[j], t, q[:, j], held[:, j])
    findings += check_commands(name, [joint_names[j] for j in fitted], log["q_cmd"][:, fitted],
                               t if t_cmd is None else t_cmd)
    for j, joint in enumerate(joint_names):
        findings += check_units(name, joint, q[:, j], log["q_cmd"][:, j], float(lower[j]), float(upper[j]),
                                t, None if log.get("qd") is None else log["qd"][:, j])
    return findings


def check_runs(runs: list[tuple[str, dict, tuple[str, ...], str]], joint_names: list[str], lower: np.ndarray,
               upper: np.ndarray) -> list[Finding]:
    """:func:`check_run` on every ``(name, log, excluded joints, where)`` of ``runs``, then
    :func:`check_never_excited` over them all (on the joints no run excludes)."""
    findings = [f for name, log, excluded, where in runs
                for f in check_run(name, log, joint_names, lower, upper, excluded, where)]
    fitted = [j for j in joint_names if not any(j in r[2] for r in runs)]
    return findings + check_never_excited(findings, [r[0] for r in runs], fitted)


def q_cmd_at(log: dict) -> np.ndarray:
    """The command in force at each state stamp (zero-order hold on the command stamps), (N, n) [rad]; before
    the first command, the first command."""
    t_cmd = log.get("t_cmd")
    if t_cmd is None:
        return log["q_cmd"]
    k = np.clip(np.searchsorted(t_cmd, log["t"], side="right") - 1, 0, len(t_cmd) - 1)
    return log["q_cmd"][k]


def check_sampling(name: str, t: np.ndarray, where: str = "") -> list[Finding]:
    """Jitter (std of the intervals / their median, gaps left out) and gaps (intervals of ``GAP_FACTOR`` median
    intervals or more) of the state stamps ``t`` (N,) [s]; gaps over more than ``GAP_UNUSABLE_FRACTION`` of the
    run are an error."""
    dt = np.diff(t)
    if len(dt) < 2:
        return []
    med = float(np.median(dt))
    gap = dt >= GAP_FACTOR * med
    out = []
    regular = dt[~gap]
    jitter = float(regular.std() / med) if len(regular) else 0.0
    if jitter > JITTER_WARN:
        out.append(Finding(name, "", "jitter", {"jitter": jitter, "median_interval_s": med},
                           f"{name}: sampling jitter {100 * jitter:.1f} % of the {1e3 * med:.2f} ms median interval "
                           f"(> {100 * JITTER_WARN:g} %): the loop ran irregularly; command timing on the grid is "
                           "that uncertain"))
    if gap.any():
        dropped = int(np.sum(np.rint(dt[gap] / med) - 1))
        lost = float(dt[gap].sum() - med * gap.sum())
        duration = float(t[-1] - t[0])
        if lost > GAP_UNUSABLE_FRACTION * duration:
            raise DatasetError(f"{where or name}: gaps cover {100 * lost / duration:.0f} % of the run "
                               f"({int(gap.sum())} gaps, about {dropped} samples dropped, longest "
                               f"{float(dt.max()):.3g} s): too little data left to use; fix or drop this run")
        k = int(np.argmax(dt))
        out.append(Finding(name, "", "gaps", {"gaps": int(gap.sum()), "dropped_samples": dropped,
                                               "longest_gap_s": float(dt[k]), "at_s": float(t[k] - t[0]),
                                               "lost_s": lost, "median_interval_s": med},
                           f"{name}: {int(gap.sum())} gap(s), about {dropped} sample(s) dropped, longest "
                           f"{1e3 * float(dt[k]):.1f} ms at t = {float(t[k] - t[0]):.2f} s "
                           f"({float(dt[k]) / med:.1f}x the {1e3 * med:.2f} ms interval): resampling draws straight "
                           "lines across them"))
    return out


def _stretches(x: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) sample index of every stretch of ``x`` (N,) that repeats one value exactly, 2+ samples."""
    change = np.flatnonzero(np.diff(x) != 0) + 1
    starts = np.r_[0, change]
    ends = np.r_[change - 1, len(x) - 1]
    return [(int(a), int(b)) for a, b in zip(starts, ends) if b > a]


def check_stuck(name: str, joint: str, t: np.ndarray, q: np.ndarray, q_cmd: np.ndarray) -> list[Finding]:
    """Clipped or frozen measurements of one joint: ``q`` (N,) [rad] repeats one value exactly while the held
    command ``q_cmd`` (N,) [rad] stays more than ``STUCK_ERROR_RAD`` away for ``STUCK_SECONDS`` or longer.
    *Clipped* when the value is the run's extreme for this joint and the command lies beyond it (a joint, servo or
    sensor limit); *frozen* otherwise (a stale reading, a stalled or disabled joint)."""
    found: dict[str, list] = {"clipped": [], "frozen": []}
    lo, hi = float(q.min()), float(q.max())
    for a, b in _stretches(q):
        v = q[a]
        far = np.abs(q_cmd[a:b + 1] - v) > STUCK_ERROR_RAD
        # the longest run of samples, within the stretch, whose command is far from the value
        edges = np.flatnonzero(np.diff(np.r_[0, far.astype(np.int8), 0]))
        if not len(edges):
            continue
        i, k = max(zip(edges[::2], edges[1::2] - 1), key=lambda p: t[a + p[1]] - t[a + p[0]])
        seconds = float(t[a + k] - t[a + i])
        if k - i + 1 < STUCK_MIN_SAMPLES or seconds < STUCK_SECONDS:
            continue
        c = q_cmd[a + i:a + k + 1]
        beyond = (v >= hi and c.max() > v) or (v <= lo and c.min() < v)
        worst = float(c[np.argmax(np.abs(c - v))])
        found["clipped" if beyond else "frozen"].append((seconds, float(t[a + i] - t[0]), float(v), worst))
    out = []
    for check, hits in found.items():
        if not hits:
            continue
        seconds, at, value, cmd = max(hits)
        total = float(sum(h[0] for h in hits))
        numbers = {"stretches": len(hits), "total_s": total, "longest_s": seconds, "at_s": at, "value_rad": value,
                   "command_rad": cmd}
        what = ("held at its run extreme while the command went beyond: a joint, servo or sensor limit; the fit "
                "sees a robot that does not follow" if check == "clipped" else
                "repeats exactly while the command moved away: a stale reading or a stalled joint")
        out.append(Finding(name, joint, check, numbers,
                           f"{name}: {joint} {check}: {value:+.3f} rad for {seconds:.2f} s at t = {at:.2f} s while "
                           f"commanded to {cmd:+.3f} rad ({len(hits)} stretch(es), {total:.1f} s in all): {what}"))
    return out


def check_commands(name: str, joints: list[str], q_cmd: np.ndarray, t_cmd: np.ndarray) -> list[Finding]:
    """The joints (of ``joints``, the columns of ``q_cmd`` (M, n) [rad] on stamps ``t_cmd`` (M,) [s]) whose command
    never changes over the run: nothing in it excites them. One finding for all of them (``joint`` lists them,
    comma-separated): a single-joint test holds all but one by design."""
    idle = [j for j in range(len(joints)) if np.ptp(q_cmd[:, j]) == 0]
    if not idle:
        return []
    duration = float(t_cmd[-1] - t_cmd[0])
    held = ", ".join(f"{joints[j]} {float(q_cmd[0, j]):+.3f}" for j in idle)
    return [Finding(name, ",".join(joints[j] for j in idle), "command_constant",
                    {"joints": [joints[j] for j in idle], "command_rad": [float(q_cmd[0, j]) for j in idle],
                     "duration_s": duration},
                    f"{name}: command constant over the whole run ({duration:.1f} s) on {held} rad: the run only "
                    "holds them (fine for a hold or single-joint test; else check the command columns)")]


def check_never_excited(findings: list[Finding], runs: list[str], joints: list[str]) -> list[Finding]:
    """Joints (fitted, ``joints``) whose command is constant in every one of ``runs`` (the per-run
    ``command_constant`` findings): no run of the dataset excites them, so no fit can identify them."""
    idle: dict[str, set] = {}
    for f in findings:
        if f.check == "command_constant":
            for j in f.numbers["joints"]:
                idle.setdefault(j, set()).add(f.run)
    if len(runs) < 2:  # one run: its command_constant finding already says it
        return []
    never = [j for j in joints if len(idle.get(j, ())) == len(runs)]
    return [Finding("", j, "never_excited", {"runs": len(runs)},
                    f"{j}: command constant in every run ({len(runs)}): no data excites it, its physics cannot be "
                    "identified; add runs that move it or exclude it in the map") for j in never]


def check_units(name: str, joint: str, q: np.ndarray, q_cmd: np.ndarray, lower: float, upper: float,
                t: np.ndarray, qd: np.ndarray | None = None) -> list[Finding]:
    """Positions ``q`` (N,), ``q_cmd`` (M,) [rad] far outside the joint range [lower, upper] [rad] (degrees read as
    radians when the values times pi/180 fit it), and a logged velocity ``qd`` (N,) [rad/s] whose size is far off
    the derivative of ``q`` on the stamps ``t`` (N,) [s]. Joints without limits (wheels) skip the range test."""
    out = []
    x = np.concatenate([q, q_cmd])
    if math.isfinite(lower) and math.isfinite(upper):
        beyond = float(max(lower - x.min(), x.max() - upper, 0.0))
        if beyond > UNITS_BEYOND_RAD:
            r = x * math.pi / 180.0
            # degrees: the values spread wider than the joint can move, and times pi/180 they fit; a spread that
            # fits but sits outside the range is a zero offset instead
            degrees = bool(np.ptp(x) > upper - lower + UNITS_DEG_MARGIN_RAD and r.min() >= lower - UNITS_DEG_MARGIN_RAD
                           and r.max() <= upper + UNITS_DEG_MARGIN_RAD)
            hint = ("looks like degrees read as radians (times pi/180 it fits the range): map it with units "
                    "\"deg\"" if degrees else "wrong zero offset, scale or units: check the map's [units]")
            out.append(Finding(name, joint, "units", {"min_rad": float(x.min()), "max_rad": float(x.max()),
                                                      "lower_rad": lower, "upper_rad": upper, "beyond_rad": beyond,
                                                      "degrees": bool(degrees)},
                               f"{name}: {joint} positions span [{float(x.min()):.3g}, {float(x.max()):.3g}] rad, "
                               f"{beyond:.3g} rad outside the joint range [{lower:.3g}, {upper:.3g}]: {hint}"))
    if qd is not None and len(t) >= 3:
        dq = np.gradient(q, t)
        moving = np.abs(dq) > VELOCITY_MOVING_RAD_S
        if moving.sum() >= VELOCITY_MIN_SAMPLES:
            ratio = float(np.median(np.abs(qd[moving])) / np.median(np.abs(dq[moving])))
            if not 1 / VELOCITY_RATIO_MAX <= ratio <= VELOCITY_RATIO_MAX:
                hint = " (degrees per second?)" if 30 < ratio < 110 else ""
                out.append(Finding(name, joint, "velocity_units", {"ratio": ratio},
                                   f"{name}: {joint} logged velocity is {ratio:.3g}x the derivative of its position"
                                   f"{hint}: wrong velocity units; fix its scale or set velocity = \"derived\" in "
                                   "the map"))
    return out
