"""Real-log formats beyond CSV / NPZ, and datasets of many runs with split assignment.

* **SAGE** (isaac-sim2real/sage real-robot logs): a run folder with ``control.csv`` (``CONTROL,<t_us>,"[n]"``
  commanded positions), ``state_motor.csv`` (``STATE_MOTOR,<t_us>,"[n]","[n]","[n]"`` measured positions,
  velocities, torque estimate), ``joint_list.txt`` (the n column names) and optionally ``event.csv``
  (``MOTION_START`` / ``DISABLE`` bound the motion). Commands and states keep their own stamps.
* **LeRobot** datasets, codebase v2.x (``data/chunk-*/episode_*.parquet``) and v3.0
  (``data/chunk-*/file-*.parquet`` with an ``episode_index`` column), read with ``pyarrow`` only:
  ``observation.state`` = measured positions, ``action`` = commands, ``timestamp`` [s]; one trajectory per
  episode, named ``<dataset>_ep<k>``. Without a mapping file, a follower arm whose ``robot_type`` is known
  (:mod:`wresdyn.data.lerobot`) is mapped from its own metadata and LeRobot's units.
* **MCAP** (ROS 2 bags, :mod:`wresdyn.data.mcap_logs`): one ``.mcap`` file per run, a JointState topic and a
  command topic.

:func:`import_runs` reads any mix of these and of CSV / NPZ logs (:mod:`wresdyn.data.log_files`) into one
:class:`~wresdyn.data.dataset.Dataset`, assigning each run a split by name pattern or by a deterministic fraction
(:class:`SplitRule`). Everything is read and checked before anything is returned, so a caller that saves only
the returned dataset never leaves a half-written file.
"""

from __future__ import annotations

import csv
import fnmatch
import hashlib
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .dataset import SPLITS, Dataset, DatasetError
from .lerobot import LeRobotUnits, lerobot_root, read_lerobot, read_lerobot_runs
from .log_files import (
    IDENTITY,
    LogMap,
    Run,
    check_finite,
    check_stamps,
    map_joints,
    read_file,
    read_toml,
)
from .log_resample import log_stats, to_trajectory
from .mcap_logs import McapTopics, is_mcap, mcap_files, read_mcap
from .telemetry import check_runs

__all__ = ["Run", "SplitRule", "sage_run", "lerobot_root", "read_sage", "read_lerobot", "read_runs", "import_runs",
           "parse_assign", "load_split_map"]

SAGE_FILES = ("control.csv", "state_motor.csv")
SAGE_STAMP_UNIT = 1e-6
"""SAGE time stamps are microseconds."""


# ---------------------------------------------------------------------------------------------------------- SAGE

def sage_run(path) -> Path | None:
    """The SAGE run folder that ``path`` names (the folder, or its ``control.csv`` / ``state_motor.csv`` when both
    are there), else ``None``."""
    p = Path(path)
    if p.is_dir():
        return p if any((p / f).is_file() for f in SAGE_FILES) else None
    if p.name in SAGE_FILES and all((p.parent / f).is_file() for f in SAGE_FILES):
        return p.parent
    return None


def read_sage(path, joint_names: list[str], log_map: LogMap | None = None) -> dict:
    """Read a SAGE run (its folder, ``control.csv`` or ``state_motor.csv``) into :func:`~wresdyn.data.logs.read_log`
    arrays in ``joint_names`` order: ``t`` (N,) [s] and ``q``, ``qd``, ``tau`` (N, n) at the state stamps,
    ``t_cmd`` (M,) [s] and ``q_cmd`` (M, n) at the command stamps. States before ``MOTION_START`` and after
    ``DISABLE`` (event.csv) are dropped; the command in force at the first kept state is kept."""
    return _read_sage(Path(path), joint_names, log_map or IDENTITY)[0]


def _read_sage(path: Path, joint_names: list[str], log_map: LogMap) -> tuple[dict, dict]:
    run = sage_run(path) or (path.parent if path.is_file() else path)
    for f in SAGE_FILES:
        if not (run / f).is_file():
            raise DatasetError(f"{run}: SAGE run has no {f}")
    jl = run / "joint_list.txt"
    if not jl.is_file():
        raise DatasetError(f"{run}: SAGE run has no joint_list.txt (the names of the columns)")
    try:
        names = [line.strip() for line in jl.read_text(encoding="utf-8").splitlines() if line.strip()]
    except (OSError, UnicodeDecodeError) as e:
        raise DatasetError(f"{jl}: cannot read: {e}") from None
    if not names or len(set(names)) != len(names):
        raise DatasetError(f"{jl}: needs one distinct joint name per line, got {names}")
    t_cmd, cmd = _sage_csv(run / "control.csv", names, ("positions",), ())
    t, st = _sage_csv(run / "state_motor.csv", names, ("positions",), ("velocities", "torques"))
    start, end = _sage_events(run / "event.csv")
    keep = (t >= (start if start is not None else -np.inf)) & (t <= (end if end is not None else np.inf))
    if keep.sum() < 2:
        raise DatasetError(f"{run / 'event.csv'}: fewer than two states between MOTION_START and DISABLE")
    info = {"format": "sage", "trimmed_s": [float(t[keep][0] - t[0]), float(t[-1] - t[keep][-1])]}
    if not t_cmd[0] <= t[keep][-1]:
        raise DatasetError(f"{run / 'control.csv'}: the first command (t = {t_cmd[0]:.6g} s) comes after the last "
                           "state")
    where = f"{jl}"
    states = map_joints(names, {"q": st["positions"][keep],
                                "qd": st["velocities"][keep] if "velocities" in st else None,
                                "tau": st["torques"][keep] if "torques" in st else None}, joint_names, log_map, where)
    cmds = map_joints(names, {"q_cmd": cmd["positions"]}, joint_names, log_map, where)
    log = {"t": t[keep], "q": states["q"], "qd": None if log_map.velocity == "derived" else states["qd"],
           "q_cmd": cmds["q_cmd"], "tau": states["tau"], "t_cmd": t_cmd}
    return log, info


def _csv_rows(path: Path) -> tuple[list[list[str]], list[str]]:
    """The non-empty rows of a CSV file and its stripped header (``[]`` for an empty file)."""
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = [r for r in csv.reader(f) if r]
    except (OSError, UnicodeDecodeError) as e:
        raise DatasetError(f"{path}: cannot read CSV: {e}") from None
    return rows, ([h.strip() for h in rows[0]] if rows else [])


def _sage_csv(path: Path, names: list[str], required: tuple, optional: tuple) -> tuple[np.ndarray, dict]:
    """Time stamps [s] (N,) and the vector columns (N, n) of a SAGE CSV file, checked."""
    rows, header = _csv_rows(path)
    for c in ("timestamp",) + required:
        if c not in header:
            raise DatasetError(f"{path}: no {c!r} column (header: {','.join(header) or 'none'})")
    cols = [c for c in required + optional if c in header]
    data = rows[1:]
    if len(data) < 2:
        raise DatasetError(f"{path}: needs at least two data rows, has {len(data)}")
    n = len(names)
    t = np.empty(len(data))
    out = {c: np.empty((len(data), n)) for c in cols}
    it, ic = header.index("timestamp"), {c: header.index(c) for c in cols}
    for i, r in enumerate(data):
        if len(r) != len(header):
            raise DatasetError(f"{path}: data row {i + 1} has {len(r)} fields, the header {len(header)}")
        t[i] = _number(r[it], path, i, "'timestamp'")
        for c in cols:
            text = r[ic[c]].strip()
            if not (text.startswith("[") and text.endswith("]")):
                raise DatasetError(f"{path}: data row {i + 1}, column {c!r}: {text[:40]!r} is not a [list] of numbers")
            parts = text[1:-1].split(",")
            if len(parts) != n:
                raise DatasetError(f"{path}: data row {i + 1}, column {c!r} has {len(parts)} values, joint_list.txt "
                                   f"names {n} joints")
            out[c][i] = [_number(x, path, i, f"{c!r}[{j}] ({names[j]})") for j, x in enumerate(parts)]
    t *= SAGE_STAMP_UNIT
    check_finite(str(path), "timestamp", t, ["'timestamp'"])
    for c in cols:
        check_finite(str(path), c, out[c], [f"{c!r}[{j}] ({names[j]})" for j in range(n)])
    check_stamps(str(path), t)
    return t, out


def _number(text: str, path: Path, i: int, column: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise DatasetError(f"{path}: data row {i + 1}, column {column}: {text.strip()!r} is not a number") from None


def _sage_events(path: Path) -> tuple[float | None, float | None]:
    """MOTION_START and DISABLE stamps [s] of event.csv (``None`` where absent, or without the file)."""
    if not path.is_file():
        return None, None
    rows, header = _csv_rows(path)
    if "timestamp" not in header or "event" not in header:
        raise DatasetError(f"{path}: needs 'timestamp' and 'event' columns (header: {','.join(header) or 'none'})")
    it, ie = header.index("timestamp"), header.index("event")
    stamps: dict[str, list[float]] = {}
    for i, r in enumerate(rows[1:]):
        if len(r) != len(header):
            raise DatasetError(f"{path}: data row {i + 1} has {len(r)} fields, the header {len(header)}")
        stamps.setdefault(r[ie].strip(), []).append(_number(r[it], path, i, "'timestamp'") * SAGE_STAMP_UNIT)
    start, end = stamps.get("MOTION_START"), stamps.get("DISABLE")
    return (min(start) if start else None), (max(end) if end else None)


# ------------------------------------------------------------------------------------------------ many runs, splits

def read_runs(path, joint_names: list[str], log_map: LogMap | None = None, lerobot: LeRobotUnits | None = None,
              topics: McapTopics | None = None) -> list[Run]:
    """The runs at ``path``, format detected: a SAGE run (folder with control.csv and state_motor.csv, or one of
    those files), a LeRobot dataset folder (meta/info.json: one run per episode; ``lerobot``: its units where no
    ``log_map`` is given, :func:`read_lerobot`), a ``.csv`` / ``.npz`` log, an ``.mcap`` file (``topics``:
    :func:`~wresdyn.data.mcap_logs.read_mcap`), a folder of ``.mcap`` files (one run each), or a folder whose
    sub-folders are any of these folders (each of them, in name order)."""
    log_map = log_map or IDENTITY
    p = Path(path)
    run = sage_run(p)
    if run is not None:
        log, info = _read_sage(run, joint_names, log_map)
        name = run.resolve().name
        if re.fullmatch(r"run_\d+", name):  # SAGE's output/real/<robot>/<set>/<motion>/run_<N>/ layout
            name = f"{run.resolve().parent.name}_{name}"
        return [Run(name, "sage", str(run), log, info)]
    if lerobot_root(p) is not None:
        return read_lerobot_runs(p, joint_names, log_map, lerobot)
    if mcap_files(p):
        return [r for f in mcap_files(p) for r in read_runs(f, joint_names, log_map, lerobot, topics)]
    if p.is_dir():
        subs = sorted(c for c in p.iterdir() if c.is_dir() and (sage_run(c) or lerobot_root(c) or mcap_files(c)))
        if not subs:
            raise DatasetError(f"{p}: neither a SAGE run (control.csv, state_motor.csv), a LeRobot dataset "
                               "(meta/info.json), a folder of .mcap files nor a folder of them")
        return [r for s in subs for r in read_runs(s, joint_names, log_map, lerobot, topics)]
    if is_mcap(p):
        log, info = read_mcap(p, joint_names, log_map, topics)
        return [Run(p.stem, "mcap", str(p), log, info)]
    log = read_file(p, joint_names, log_map)
    return [Run(p.stem, p.suffix.lower().lstrip("."), str(p), log, {"format": p.suffix.lower().lstrip(".")})]


def parse_assign(text: str) -> tuple[str, str]:
    """``"PATTERN=SPLIT"`` -> (pattern, split); the pattern is an fnmatch pattern on the run name."""
    pattern, sep, split = text.rpartition("=")
    if not sep or not pattern or split not in SPLITS:
        raise DatasetError(f"--assign {text!r}: expected PATTERN=SPLIT with SPLIT one of {', '.join(SPLITS)}")
    return pattern, split


def load_split_map(path) -> list[tuple[str, str]]:
    """A split map file (TOML): ``"PATTERN" = "SPLIT"`` lines, fnmatch patterns on run names, first match wins."""
    path = Path(path)
    raw = read_toml(path, "split map")
    for k, v in raw.items():
        if v not in SPLITS:
            raise DatasetError(f"{path}: {k!r} = {v!r}: the split must be one of {', '.join(SPLITS)}")
    return list(raw.items())


def _count(fraction: float, n: int) -> int:
    """Runs a fraction takes out of n: rounded half up, at least one when the fraction is positive."""
    return 0 if fraction <= 0 or n == 0 else max(1, int(fraction * n + 0.5))


@dataclass(frozen=True)
class SplitRule:
    """How runs get their split: the first matching pattern, else the fractions, else ``default``."""

    default: str = "heldout"
    """Split of every run no pattern or fraction assigns."""
    patterns: tuple[tuple[str, str], ...] = ()
    """(fnmatch pattern on the run name, split) pairs; the first that matches decides."""
    validation_fraction: float = 0.0
    """Fraction of the runs no pattern matched that go to validation (whole runs)."""
    heldout_fraction: float = 0.0
    """Fraction of the runs no pattern matched that go to heldout (whole runs)."""

    def __post_init__(self):
        bad = [s for s in [self.default] + [s for _, s in self.patterns] if s not in SPLITS]
        if bad:
            raise DatasetError(f"unknown split {bad[0]!r}; choose from {SPLITS}")
        fv, fh = self.validation_fraction, self.heldout_fraction
        if not (0 <= fv <= 1 and 0 <= fh <= 1 and fv + fh <= 1):
            raise DatasetError(f"validation and heldout fractions must be in [0, 1] and sum to at most 1, "
                               f"not {fv:g} and {fh:g}")

    def assign(self, names: list[str]) -> list[str]:
        """The split of each run. The runs no pattern matches are ranked by the SHA-256 of their name (a fixed,
        order-independent shuffle): the first ``validation_fraction`` of them go to validation, the next
        ``heldout_fraction`` to heldout, the rest to ``default``."""
        out: list[str | None] = [next((s for p, s in self.patterns if fnmatch.fnmatchcase(n, p)), None) for n in names]
        rest = sorted((i for i, s in enumerate(out) if s is None),
                      key=lambda i: hashlib.sha256(names[i].encode("utf-8")).hexdigest())
        n_val, n_held = _count(self.validation_fraction, len(rest)), _count(self.heldout_fraction, len(rest))
        if n_val + n_held > len(rest):
            raise DatasetError(f"the validation and heldout fractions ask for {n_val} + {n_held} runs out of "
                               f"{len(rest)}")
        for r, i in enumerate(rest):
            out[i] = "validation" if r < n_val else "heldout" if r < n_val + n_held else self.default
        return out

    def unused(self, names: list[str]) -> list[str]:
        """Patterns that match no run (most likely a typo)."""
        return [p for p, _ in self.patterns if not any(fnmatch.fnmatchcase(n, p) for n in names)]


def import_runs(paths, robot, rate_hz: float = 500.0, log_map: LogMap | None = None, splits: SplitRule | None = None,
                store_tau: bool = True, lerobot: LeRobotUnits | None = None, topics: McapTopics | None = None
                ) -> Dataset:
    """A :class:`~wresdyn.data.dataset.Dataset` of real logs (no mismatch, no seed): every run of every path
    (:func:`read_runs`), resampled onto ``rate_hz``, its split from ``splits``. Names are made unique with the
    run's index when two runs share one. ``meta`` gets ``source_logs`` (per run: name, split, file, format,
    samples, duration, median rate, jitter, max gap; LeRobot followers read without a map: their ``units``),
    ``excluded_joints``, ``log_map`` and ``telemetry`` (the :mod:`wresdyn.data.telemetry` findings of every run,
    as dicts; a run those checks find unusable is an error). ``lerobot``: calibration and units of LeRobot
    datasets read without a ``log_map`` (a map sets the units itself: giving both is an error). ``topics``: the
    topics and stamps of MCAP logs (:class:`~wresdyn.data.mcap_logs.McapTopics`)."""
    joint_names = list(robot.joint_names)
    if log_map is not None and lerobot is not None:
        raise DatasetError(f"{log_map.source}: a mapping file sets the units itself; give it or LeRobot's "
                           "calibration / degrees, not both")
    log_map = log_map or IDENTITY
    log_map.check(joint_names, Path(robot.source).name)
    splits = splits or SplitRule()
    ranges = {j: (float(lo), float(hi)) for j, lo, hi in zip(joint_names, robot.lower, robot.upper)}
    lerobot = replace(lerobot or LeRobotUnits(), ranges=ranges)
    runs = [r for p in paths for r in read_runs(p, joint_names, log_map, lerobot, topics)]
    if not runs:
        raise DatasetError("no logs given")
    maps = [r.log_map or log_map for r in runs]
    excluded = [j for j in joint_names if any(j in m.excluded_joints(joint_names) for m in maps)]
    shown = maps[0] if all(m == maps[0] for m in maps) else log_map  # one derived map for every run, or the given
    names = [r.name for r in runs]
    names = [f"{n}_{i}" if names.count(n) > 1 else n for i, n in enumerate(names)]
    wheres = [f"{r.file}: episode {r.info['episode_index']}" if r.format == "lerobot" else r.file for r in runs]
    findings = check_runs([(n, r.log, tuple(m.excluded_joints(joint_names)), w)
                           for r, n, m, w in zip(runs, names, maps, wheres)], joint_names, robot.lower, robot.upper)
    trajs, sources = [], []
    for run, name, split, where in zip(runs, names, splits.assign(names), wheres):
        trajs.append(to_trajectory(run.log, rate_hz, name, split, where, store_tau))
        sources.append({"name": name, "split": split, "file": run.file, **log_stats(run.log["t"]), **run.info})
    meta = {"generator": "wresdyn collect --logs", "source_logs": sources, "excluded_joints": excluded,
            "telemetry": [f.to_dict() for f in findings],
            "log_map": shown.to_dict(),
            "split_rule": {"default": splits.default, "patterns": [list(p) for p in splits.patterns],
                           "validation_fraction": splits.validation_fraction,
                           "heldout_fraction": splits.heldout_fraction}}
    ds = Dataset(joint_names, float(rate_hz), trajs, str(robot.source), robot.source_sha256, {}, None, meta,
                 robot.gains_record())
    ds.validate("imported logs")
    return ds
