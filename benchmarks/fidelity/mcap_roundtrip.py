"""Does an MCAP recording of the shipped "real" robot import and fit to the same figures as the NPZ it came from?

    OMP_NUM_THREADS=1 python benchmarks/fidelity/mcap_roundtrip.py [--data data/dataset.npz] [--per-split N]
        [--seconds S] [--out DIR] [--learner fit|identify] [--args "ARGS"]

Writes every trajectory of the dataset (the first ``--per-split`` of each split, each cut to its first ``--seconds``
where given) as one ROS 2 bag in MCAP, the way rosbag2 records a robot: ``/joint_states`` (``sensor_msgs/msg/
JointState``: measured ``position`` and ``velocity``, ``effort`` where the dataset stores τ) and ``/joint_commands``
(``JointState``: the commanded ``position``), one message each per recorded step at the dataset's rate, header stamps
in epoch nanoseconds (each run 60 s after the previous one), written by ``mcap-ros2-support``'s own writer. Then
imports the folder with ``wresdyn collect --logs BAGS --rate RATE --split-map SPLITS.toml`` (each run's split as
recorded), compares every array of the two datasets, and runs ``wresdyn fit DATA --eval`` (or ``identify``; with
``--args``) on both, comparing every identified parameter, every training and validation figure of their curves and
their open-loop figures. Prints everything it checks and writes it to ``OUT/roundtrip.json``; exits 1 when a
difference passes its bound. Run folders go under ``--out`` (default: a temporary folder).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from wresdyn.data.dataset import SPLITS, Dataset, derive_qdd, load_dataset

T0_NS = 1_764_400_000_000_000_000
"""Epoch stamp [ns] of the first run's first message (late 2025); float64 seconds since 1970 could not hold it."""
RUN_GAP_NS = 60_000_000_000
"""Each run starts this long after the previous one [ns], as separate recordings do."""
TRANSPORT_NS = 1_000_000
"""The recorder logs each message this long after its header stamp [ns]; the importer reads header stamps."""
ARRAY_BOUND = 1e-12
"""Largest |Δ| allowed between an imported and the NPZ array, relative to the array's largest magnitude (at least
1 [SI]): positions, velocities and commands travel as float64 and stamps as integer nanoseconds, but the grid the
import resamples onto is k / rate in float64 seconds, so interpolation weights differ from 0 or 1 by float64 rounding
(~1e-16), and q̈ is q̇'s derivative (Savitzky-Golay over 1 / rate), which scales that rounding by about the rate."""
FIT_BOUND = 1e-12
"""Largest relative difference allowed between the two runs' numbers: the same data to ``ARRAY_BOUND`` and the same
seeds make the same run up to that rounding carried through training (measured on the whole shipped dataset: 7.4e-15
after 1840 identification iterations)."""
FIELDS = ("t", "q", "qd", "qdd", "q_cmd", "tau")

_RULE = "=" * 80
JOINT_STATE = f"""std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
{_RULE}
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
{_RULE}
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""
"""ROS 2 Humble's ``sensor_msgs/msg/JointState`` definition as rosbag2 stores it (dependencies after ``=`` rules)."""


def subset(ds: Dataset, per_split: int | None, seconds: float | None) -> Dataset:
    """The first ``per_split`` trajectories of each split (None: all), each cut to its first ``seconds`` (None: all;
    the cut's q̈ derived again from its q̇, as any import derives it)."""
    keep = [tr for s in SPLITS for tr in ds.split(s)[:per_split]]
    if seconds is not None:
        n = int(round(seconds * ds.rate_hz))
        keep = [replace(tr, t=tr.t[:n], q=tr.q[:n], qd=tr.qd[:n], qdd=derive_qdd(tr.qd[:n], ds.rate_hz),
                        q_cmd=tr.q_cmd[:n], tau=None if tr.tau is None else tr.tau[:n]) for tr in keep]
    return replace(ds, trajectories=keep)


def _stamp(ns: int) -> dict:
    return {"sec": int(ns // 1_000_000_000), "nanosec": int(ns % 1_000_000_000)}


def write_bag(path: Path, tr, joint_names: list[str], rate_hz: float, t0_ns: int) -> None:
    """One trajectory as a ROS 2 bag: a state and a command message per recorded step, header stamps
    ``t0_ns + round(t_k [ns])``; the command of step k is in force from t_k on (the dataset's zero-order hold)."""
    from mcap_ros2.writer import Writer

    names = list(joint_names)
    stamps = t0_ns + np.round(tr.t * 1e9).astype(np.int64)
    with open(path, "wb") as f:
        w = Writer(f)
        schema = w.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE)
        for k, ns in enumerate(stamps.tolist()):
            header = {"stamp": _stamp(ns), "frame_id": ""}
            state = {"header": header, "name": names, "position": tr.q[k].tolist(), "velocity": tr.qd[k].tolist(),
                     "effort": [] if tr.tau is None else tr.tau[k].tolist()}
            w.write_message("/joint_states", schema, state, log_time=ns + TRANSPORT_NS)
            cmd = {"header": header, "name": names, "position": tr.q_cmd[k].tolist(), "velocity": [], "effort": []}
            w.write_message("/joint_commands", schema, cmd, log_time=ns + TRANSPORT_NS)
        w.finish()


def write_bags(ds: Dataset, folder: Path) -> Path:
    """Every trajectory of ``ds`` as ``folder/<name>.mcap`` and the split of each in ``splits.toml`` beside
    ``folder`` (``--split-map``: exact run names, so the splits are the recorded ones); returns the split map's path."""
    folder.mkdir(parents=True, exist_ok=True)
    for i, tr in enumerate(ds.trajectories):
        write_bag(folder / f"{tr.name}.mcap", tr, ds.joint_names, ds.rate_hz, T0_NS + i * RUN_GAP_NS)
    split_map = folder.parent / "splits.toml"
    split_map.write_text("".join(f'"{tr.name}" = "{tr.split}"\n' for tr in ds.trajectories))
    return split_map


def compare_data(a: Dataset, b: Dataset) -> tuple[dict, list[str]]:
    """Largest |Δ| per array [SI] over all trajectories, matched by name (``None``: absent in both), and the list of
    what differs in structure or metadata (names, splits, each split's order, rate, joints, robot, gains) or passes
    :data:`ARRAY_BOUND`. The order across splits is not compared: an import lists runs in file-name order, and
    every reader of a dataset takes one split at a time."""
    bad = []
    for what, x, y in (("rate_hz", a.rate_hz, b.rate_hz), ("joint_names", a.joint_names, b.joint_names),
                       ("robot_sha256", a.robot_sha256, b.robot_sha256),
                       ("gains config", a.gains_config, b.gains_config),
                       *((f"{s} split", [(t.name, t.n_samples) for t in a.split(s)],
                          [(t.name, t.n_samples) for t in b.split(s)]) for s in SPLITS)):
        if x != y:
            bad.append(f"{what}: {x!r} != {y!r}")
    others = {t.name: t for t in b.trajectories}
    pairs = [(t, others[t.name]) for t in a.trajectories if t.name in others]
    diffs: dict[str, float | None] = {}
    for f in FIELDS:
        d, scale = None, 1.0
        for ta, tb in pairs:
            xa, xb = getattr(ta, f), getattr(tb, f)
            if (xa is None) != (xb is None) or (xa is not None and xa.shape != xb.shape):
                bad.append(f"{ta.name}.{f}: present or shaped differently")
            elif xa is not None:
                d, scale = max(d or 0.0, float(np.abs(xa - xb).max())), max(scale, float(np.abs(xa).max()))
        diffs[f] = d
        if d is not None and not d <= ARRAY_BOUND * scale:
            bad.append(f"{f}: max |diff| {d:.3g} > {ARRAY_BOUND:g} x {scale:.3g}")
    return diffs, bad


def figures(run: Path) -> dict[str, dict[str, float]]:
    """Open-loop figures of a ``--eval`` run per split: PD-only and calibrated mean |Δq| [rad], the ratio."""
    doc = json.loads((run / "eval" / "metrics.json").read_text())
    return {s: {"pd_only": r["pd_only"]["mean_abs_dq"], "calibrated": r["pd_residual"]["mean_abs_dq"],
                "improvement": r["improvement"]} for s, r in doc["splits"].items()}


def _numbers(doc, key: str = "") -> dict[str, float]:
    """Every number in a JSON document by its path (wall-clock times left out: they are no result)."""
    if isinstance(doc, dict):
        return {k: v for kk, vv in doc.items() if kk != "wall" for k, v in _numbers(vv, f"{key}.{kk}").items()}
    if isinstance(doc, list):
        return {k: v for i, vv in enumerate(doc) for k, v in _numbers(vv, f"{key}[{i}]").items()}
    return {key: float(doc)} if isinstance(doc, (int, float)) and not isinstance(doc, bool) else {}


def run_numbers(run: Path) -> dict[str, float]:
    """What a run learned and how it went: every number of ``physics.json`` (the identified parameters) and of
    ``curve.json`` (training loss terms and validation error per iteration)."""
    return {f"{f}{k}": v for f in ("physics.json", "curve.json") if (run / f).is_file()
            for k, v in _numbers(json.loads((run / f).read_text())).items()}


def compare_fits(a: dict, b: dict) -> tuple[float, list[str]]:
    """Largest relative difference between two flat ``{name: number}`` dicts (:func:`run_numbers`, or
    :func:`figures` flattened), and what passes :data:`FIT_BOUND` (a name in one only counts as a difference)."""
    if a.keys() != b.keys():
        return float("inf"), [f"entries differ: {sorted(set(a) ^ set(b))[:5]}"]
    worst, bad = 0.0, []
    for k in a:
        rel = abs(a[k] - b[k]) / max(abs(a[k]), 1e-300) if a[k] != b[k] else 0.0
        worst = max(worst, rel)
        if not rel <= FIT_BOUND:
            bad.append(f"{k}: {a[k]:.10g} != {b[k]:.10g}")
    return worst, bad


def cli(args: list[str]) -> float:
    """Run ``wresdyn ARGS`` in this process (the kernels compile once for every step); its wall-clock [s]."""
    from wresdyn.cli import main

    print("$ wresdyn " + " ".join(shlex.quote(a) for a in args), flush=True)
    t = time.perf_counter()
    if main(args) != 0:
        raise SystemExit(f"wresdyn {args[0]} failed")
    return time.perf_counter() - t


def record_and_import(data: Path, out: Path, per_split: int | None, seconds: float | None) -> dict:
    """The dataset's :func:`subset` saved as ``out/npz/dataset.npz``, written as bags (``out/bags``), imported by
    ``wresdyn collect --logs`` into ``out/mcap/dataset.npz`` and compared (:func:`compare_data`)."""
    ds = subset(load_dataset(data), per_split, seconds)
    npz = out / "npz" / "dataset.npz"
    npz.parent.mkdir(parents=True, exist_ok=True)
    ds.save(npz)
    t = time.perf_counter()
    split_map = write_bags(ds, out / "bags")
    size = sum(p.stat().st_size for p in (out / "bags").glob("*.mcap"))
    print(f"wrote {len(ds.trajectories)} bags ({size / 1e6:.1f} MB) in {time.perf_counter() - t:.1f} s: "
          f"{', '.join(f'{len(ds.split(s))} {s}' for s in SPLITS if ds.split(s))}; {ds.rate_hz:g} Hz", flush=True)
    gains = []
    if ds.gains is not None:
        if not ds.gains.get("file"):
            raise SystemExit(f"{data}: its gains config is stored inline; import needs it as a file (--gains)")
        gains = ["--gains", ds.gains["file"]]
    cli(["collect", "--logs", str(out / "bags"), "--robot", ds.robot_file, *gains, "--rate", f"{ds.rate_hz:g}",
         "--split-map", str(split_map), "--no-tau" if all(tr.tau is None for tr in ds.trajectories) else "--tau",
         "--no-gap", "--quiet", "--out", str(out / "mcap")])
    diffs, bad = compare_data(ds, load_dataset(out / "mcap" / "dataset.npz"))
    print("imported vs NPZ, max |diff| over every trajectory: "
          + ", ".join(f"{f} {'absent' if d is None else f'{d:.3g}'}" for f, d in diffs.items()), flush=True)
    return {"trajectories": len(ds.trajectories), "rate_hz": ds.rate_hz, "max_abs_diff": diffs,
            "data_differences": bad}


def learn_both(out: Path, learner: str, args: list[str], evaluate: bool = True) -> dict:
    """``wresdyn LEARNER`` with ``args`` on ``out/npz`` and ``out/mcap``'s datasets (``evaluate``: with ``--eval``,
    whose open-loop figures are compared too), into ``out/LEARNER_npz`` and ``out/LEARNER_mcap``; returns the
    figures and the comparisons (:func:`run_numbers`, :func:`figures`)."""
    runs, learned = {}, {}
    for name in ("npz", "mcap"):
        run = out / f"{learner}_{name}"
        wall = cli([learner, str(out / name / "dataset.npz"), "--out", str(run), *(["--eval"] if evaluate else []),
                    "--quiet", *args])
        learned[name] = run_numbers(run)
        if evaluate:
            runs[name] = figures(run)
            print(f"{learner} on the {name.upper()} dataset ({wall:.0f} s): " + "; ".join(
                f"{s} PD only {r['pd_only']:.6f} rad, calibrated {r['calibrated']:.6f} rad ({r['improvement']:.4f}x)"
                for s, r in runs[name].items()), flush=True)
    worst_run, run_bad = compare_fits(learned["npz"], learned["mcap"])
    print(f"{learner} runs: largest relative difference of an identified parameter or a training / validation "
          f"figure {worst_run:.3g} over {len(learned['npz'])} numbers (bound {FIT_BOUND:g})", flush=True)
    worst, fit_bad = 0.0, []
    if evaluate:
        flat = {name: {f"{s}.{k}": v for s, r in f.items() for k, v in r.items()} for name, f in runs.items()}
        worst, fit_bad = compare_fits(flat["npz"], flat["mcap"])
        print(f"{learner} runs: largest relative difference of an open-loop figure {worst:.3g} (bound {FIT_BOUND:g})",
              flush=True)
    return {"learner": learner, "args": args, "figures": runs, "fit_max_rel_diff": worst,
            "run_max_rel_diff": worst_run, "run_numbers": len(learned["npz"]), "fit_differences": fit_bad + run_bad}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default="data/dataset.npz", help="the NPZ dataset to record as bags")
    p.add_argument("--per-split", type=int, help="the first N trajectories of each split (default: all)")
    p.add_argument("--seconds", type=float, help="cut each trajectory to its first S seconds (default: whole)")
    p.add_argument("--out", help="folder for the bags, datasets and runs (default: a temporary one)")
    p.add_argument("--learner", choices=("fit", "identify", "none"), default="fit",
                   help="`wresdyn fit` or `wresdyn identify` on both datasets, or none: compare the data only")
    p.add_argument("--args", default="", help="further arguments of both learner runs, one string")
    a = p.parse_args(argv)
    out = Path(a.out or tempfile.mkdtemp(prefix="mcap_roundtrip."))
    r = record_and_import(Path(a.data), out, a.per_split, a.seconds)
    if a.learner != "none":
        r.update(learn_both(out, a.learner, shlex.split(a.args)))
    (out / "roundtrip.json").write_text(json.dumps(r, indent=2) + "\n")
    failed = r["data_differences"] + r.get("fit_differences", [])
    for line in failed:
        print(f"DIFFERS: {line}")
    print(f"wrote {out / 'roundtrip.json'}; " + ("the MCAP round trip differs" if failed else
          "the imported data and the fits match the NPZ's"))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
