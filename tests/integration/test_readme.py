"""The README stays true: at most 150 lines, and every row of its results table one line whose figures equal, at the
precision it prints them, the files under ``benchmarks/results/`` that the row names.

``ROWS`` holds one entry per row, as data: the start of the row's first cell, the files it reads (each must be named
in the row's source cell), and the strings the row must print, in order, each computed from those files. A figure
edited by hand, a result file remade with other numbers, or a row whose source is renamed fails here.
"""

from __future__ import annotations

import itertools
import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
MAX_LINES = 150
"""The README's length limit [lines]: what it is, the two commands, a picture, the results, then pointers."""

PD = "grey_box/soft_friction/plateau/demo_fit_eval_metrics.json"
"""The demo's fit on the shipped data: its PD-only errors are the gap every humanoid row divides."""
PD_UNEVEN = "grey_box/soft_friction/uneven/fit_default_eval_metrics.json"
"""A fit on the uneven mismatch's data (``wresdyn collect --mismatch data/mismatch_uneven.toml``, deterministic)."""


def js(path: str, *keys):
    """The value at ``keys`` in the JSON file ``path`` (under ``benchmarks/results/``)."""
    value = json.loads((RESULTS / path).read_text())
    for k in keys:
        value = value[k]
    return value


def rx(path: str, pattern: str, group: int = 1) -> float:
    """The first match of ``pattern`` (multi-line) in the text file ``path``, as a number."""
    m = re.search(pattern, (RESULTS / path).read_text(), re.M)
    assert m, f"{pattern!r} not in {path}"
    return float(m.group(group))


def pd(split: str, path: str = PD) -> float:
    """PD-only mean |dq| [rad] of ``split`` in an evaluation's metrics."""
    return js(path, "splits", split, "pd_only", "mean_abs_dq")


def drift(label: str) -> tuple[int, int, int]:
    """From the drift benchmark's stream summary: (streams, streams with a no-drift second above 1.05x, the longest
    time back within 1.5x of the oracle after a change [s]) of the line starting with ``label``."""
    line = next(ln for ln in (RESULTS / "adapt_drift/track_confirm/rule.txt").read_text().splitlines()
                if ln.startswith(label))
    runs, above = re.search(r"(\d+) runs; a no-drift second above 1\.05x in (\d+)", line).groups()
    backs = re.search(r"after \(friction, payload, derate\) (\[.*?\])", line).group(1)
    return int(runs), int(above), max(itertools.chain(*json.loads(backs.replace("(", "[").replace(")", "]"))))


def streams() -> list[str]:
    (v, va, vb), (h, ha, hb), (e, ea, eb) = (drift(k) for k in (
        "policy, defaults:", "held-out policy timeline, defaults", "excitation, defaults:"))
    return [f"{v + h + e} streams", f"at most {max(vb, hb, eb)} s", f"{va} of {v} validation",
            f"{ha} of {h} held-out", f"{ea} of {e} on the excitation"]


def floor(mismatch: str) -> list[str]:
    """Held-out success over three seeds, from the floor summary: nominal, calibrated, calibrated with narrow
    randomisation, domain randomisation, the equal-budget oracle."""
    return [f"{100 * js(FLOOR, mismatch, p, 'success'):.0f} %" for p in "abfed"]


def stand() -> list[str]:
    cpu = [100 * js(f"deploy/{s}/results.json", "gap_closed", "b_calibrated") for s in ("default", "seed1", "seed2")]
    gpu = 100 * js("deploy/full_h200/results.json", "gap_closed", "b_calibrated")
    return [f"{min(cpu):.0f}–{max(cpu):.0f} %", f"{gpu:.0f} %"]


def gradient_cpu() -> float:
    """Wall-clock of the gradient fit to 2.5x on validation on 2 CPU cores [s]."""
    rows = js("speed_paths/cpu_2core_time_to_fidelity.json", "rows")
    return next(r["wall_s"] for r in rows if r["learner"] == "gradient")


def zoo() -> list[str]:
    robots = ("g1", "solo12", "ur5", "panda")
    return [" / ".join(f"{js('robot_zoo/summary.json', r, f'{k}_ratio'):.1f}×" for r in robots)
            for k in ("heldout", "ood")]


FLOOR = "floor_fair/summary.json"
SO101 = "so101_servo/hybrid/summary.txt"
SERVO = r"^{}: .*{} [\d.]+ \(([\d.]+)x\)"
"""A run's ratio to PD only in the SO-101 summary: the run, then the split."""
SWEEP = r"^\| frac025 \| [^|]+ \| [\d.]+ \(([\d.]+)x\)"
PPO_HELDOUT = r"^heldout .*\(([\d.]+)x\)"
TTF_GPU = r"^\| gradient \| 1024 \| [^|]+ \| ([\d.]+) \|"
WHOLE = r"^whole command: ([\d.]+) s"
TRAINING = r"^done: (\d+) s of training"
LANES = "speed_paths/lanes/bench_lanes.txt"
ROLLOUT = r"^\| replay rollout \| ([\d.]+)M \| ([\d.]+)M \| ([\d.]+)M \| ([\d.]+)M \|"
ZOO_RUN = "peers/humanoid/default/wresdyn_cpu.json"
UNEVEN = "peer_sysid/uneven/summary.json"
SPEED = "speed/summary.json"
EAGER = "speed/h200_20261130g/coldfit/fit_warm_eager.log"
"""The default fit warm with the identification stepped eagerly: the baseline of its CUDA graph."""
FUSED = "speed/h200_20261201c/gradfit10_rows1/fused.json"
"""The gradient fit's 2000 iterations with the fused MLP alone (no tile kernels), warm."""
PLAIN = "speed/h200_20261201q/plain.json"
"""The gradient fit's 2000 iterations on the plain path, in the run of ``summary.json``'s figure (the CUDA default)."""
COLD = "speed/h200x2_20261130/coldfit/fit_cold.log"
"""The default fit of an earlier tree from an empty Warp cache without the shipped kernels."""

ROWS = {
    "gap to close on the shipped data": ([PD], lambda: [
        f"{pd('heldout'):.4f} rad held-out", f"{pd('ood'):.4f} rad OOD"]),
    "residual network alone": (["validation_protocol/fit_sweep_summary.md",
                                "validation_protocol/ppo_cpu_4000_defaults.txt"], lambda: [
        f"{rx('validation_protocol/fit_sweep_summary.md', SWEEP):.2f}×",
        f"{rx('validation_protocol/ppo_cpu_4000_defaults.txt', PPO_HELDOUT):.2f}×"]),
    "identified physics (`wresdyn identify`": ([ZOO_RUN, PD], lambda: [
        f"{js(ZOO_RUN, 'train_s'):.0f} s of training",
        f"{pd('heldout') / js(ZOO_RUN, 'scores', 'heldout'):.1f}× held-out",
        f"{pd('ood') / js(ZOO_RUN, 'scores', 'ood'):.1f}× OOD"]),
    "online identification under drift": (["adapt_drift/track_confirm/rule.txt"], streams),
    "**the calibrated robot": ([PD], lambda: [
        f"{js(PD, 'splits', 'heldout', 'improvement'):.1f}× held-out",
        f"{js(PD, 'splits', 'ood', 'improvement'):.1f}× OOD"]),
    "robots it never saw": (["robot_zoo/summary.json"], zoo),
    "identified physics on a second, uneven mismatch": ([UNEVEN, "peer_sysid/uneven/wresdyn/config.json", PD_UNEVEN],
                                                         lambda: [
        f"{js('peer_sysid/uneven/wresdyn/config.json', 'sysid', 'iterations')} it.",
        f"{pd('heldout', PD_UNEVEN) / js(UNEVEN, 'wresdyn', 'final', 'heldout'):.1f}× held-out",
        f"{pd('ood', PD_UNEVEN) / js(UNEVEN, 'wresdyn', 'final', 'ood'):.1f}× OOD"]),
    "real SO-101 arm": ([SO101], lambda: [
        f"{rx(SO101, SERVO.format('hybrid/gru_delta', 'heldout')):.2f}× held-out",
        f"{rx(SO101, SERVO.format('hybrid/gru_delta', 'ood')):.2f}× OOD",
        f"the servo model alone: {rx(SO101, SERVO.format('effort/k1e5_reset', 'heldout')):.2f}×",
        f"{rx(SO101, SERVO.format('effort/k1e5_reset', 'ood')):.2f}×"]),
    "skills on the stand": (["deploy/default/results.json", "deploy/seed1/results.json", "deploy/seed2/results.json",
                             "deploy/full_h200/results.json"], stand),
    "skills on the floor, full size": ([FLOOR], lambda: floor("default")),
    "the same on the uneven mismatch": ([FLOOR], lambda: floor("uneven")),
    "SolverReplay on an H200": ([LANES], lambda: [
        f"{rx(LANES, ROLLOUT, 3):.0f}M / {rx(LANES, ROLLOUT, 4):.1f}M at 16,384 worlds",
        f"{rx(LANES, ROLLOUT, 1):.0f}M / {rx(LANES, ROLLOUT, 2):.1f}M at 1024"]),
    "gradient fit: to 2.5×": (["speed_paths/cpu_2core_time_to_fidelity.json", "speed_paths/lanes/ttf_lanes.txt",
                               SPEED, PLAIN, FUSED], lambda: [
        f"{gradient_cpu():.1f} s (2 CPU cores)", f"{js(SPEED, 'gradfit_2000_s'):.1f} s",
        f"plain path {js(PLAIN, 'train_s'):.1f} s", f"fused MLP alone {js(FUSED, 'train_s'):.1f} s", f"{rx('speed_paths/lanes/ttf_lanes.txt', TTF_GPU):.1f} s"]),
    "the first `wresdyn fit --device cuda:0`": (["first_fit/h200_lanes/pieces_laned/fit_first.log",
                                                 "speed_paths/lanes/fit_lanes.log", SPEED, EAGER, COLD], lambda: [
        f"{rx('first_fit/h200_lanes/pieces_laned/fit_first.log', WHOLE):.1f} s",
        f"{rx('speed_paths/lanes/fit_lanes.log', TRAINING):.0f} s",
        f"{js(SPEED, 'first_fit_cold_s'):.1f} s", f"first iteration {js(SPEED, 'first_iteration_cold_s'):.1f} s",
        f"{js(SPEED, 'first_fit_warm_s'):.1f} s warm", f"{rx(EAGER, WHOLE):.1f} s warm",
        f"{rx(COLD, WHOLE):.1f} s without"]),
}


def results_rows(text: str) -> list[str]:
    """The rows of the table under ``## Results`` (header and rule excluded)."""
    section = text.split("## Results", 1)[1].split("\n## ", 1)[0]
    return [ln for ln in section.splitlines() if ln.startswith("| ") and not ln.startswith(("| what |", "|---"))]


def named_files(cell: str) -> set[str]:
    """The files a source cell names: its code spans, ``{a,b}`` expanded."""
    out = set()
    for span in re.findall(r"`([^`]+)`", cell):
        m = re.search(r"\{([^}]+)\}", span)
        out |= {span[:m.start()] + o + span[m.end():] for o in m.group(1).split(",")} if m else {span}
    return out


def test_readme_is_short():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= MAX_LINES, f"README.md has {len(lines)} lines (at most {MAX_LINES})"


def test_every_results_row_has_its_check_and_names_existing_files():
    rows = results_rows((ROOT / "README.md").read_text())
    keys = [next((k for k in ROWS if row.startswith(f"| {k}")), None) for row in rows]
    assert None not in keys, f"rows without an entry in ROWS: {[r[:60] for r, k in zip(rows, keys) if k is None]}"
    assert sorted(keys) == sorted(ROWS), "ROWS and the README's results rows differ"
    for row, key in zip(rows, keys):
        cells = [c.strip() for c in row.strip().strip("|").split(" | ")]
        assert len(cells) == 4, f"{key}: {len(cells)} cells"
        named = named_files(cells[2])
        for f in named:
            assert (RESULTS / f).is_file(), f"{key}: {f} is not a file under benchmarks/results/"
        missing = set(ROWS[key][0]) - named
        assert not missing, f"{key}: reads {sorted(missing)}, which the row does not name"


def test_every_figure_equals_its_source():
    rows = results_rows((ROOT / "README.md").read_text())
    for key, (_, figures) in ROWS.items():
        row = next(r for r in rows if r.startswith(f"| {key}"))
        at = 0
        for want in figures():
            found = row.find(want, at)
            assert found >= 0, f"{key}: expected {want!r} (from the source) after {row[:at][-60:]!r}"
            at = found + len(want)
