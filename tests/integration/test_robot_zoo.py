"""The robot zoo benchmark (``benchmarks/fidelity/robot_zoo/``): every robot of ``robots.toml`` is found inside its
installed package, loads with its gains file, has the joints the table states and builds in MuJoCo; each gains file
is what ``make_gains.py``'s rule writes; a tiny recording on the Panda (a ``world`` link, 0.04 m fingers) goes
through."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ZOO_DIR = Path(__file__).resolve().parents[2] / "benchmarks" / "fidelity" / "robot_zoo"
sys.path.insert(0, str(ZOO_DIR))

from zoo import load_zoo  # noqa: E402


@pytest.fixture(scope="module")
def zoo():
    return load_zoo()


@pytest.fixture(scope="module")
def robots(zoo):
    from wresdyn.robot.description import load_robot

    return {name: load_robot(z.path, gains=z.gains) for name, z in zoo.items()}


def test_every_robot_loads_with_its_gains_and_builds_in_mujoco(zoo, robots):
    from wresdyn.robot.mujoco_model import build_mujoco

    assert list(zoo) == ["g1", "solo12", "ur5", "panda"]
    for name, robot in robots.items():
        z = zoo[name]
        assert z.path.is_file() and z.gains.is_file() and z.source and z.licence
        assert robot.n_dof == z.dof, name
        robot.check_replay()  # gains and stated effort limits on every joint: collect would accept it
        assert np.all(robot.kp > 0) and np.all(robot.kd > 0) and np.all(np.isfinite(robot.effort)), name
        m = build_mujoco(robot)
        assert m.nu == robot.n_dof and m.njnt == robot.n_dof, name  # the base on the stand: no free joint


def test_gains_files_follow_the_rule(zoo, robots):
    """Each gains file is what ``make_gains.py`` writes now: edit the rule, not the files."""
    import make_gains

    for name, robot in robots.items():
        assert zoo[name].gains.read_text() == make_gains.gains_toml(name, robot), f"{name}: rerun make_gains.py"
    assert np.allclose(robots["solo12"].effort, 2.7) and np.allclose(robots["solo12"].upper, np.pi)
    assert np.allclose(robots["ur5"].kp, robots["ur5"].effort)  # kp = effort / 1 rad


def test_tiny_collect_on_the_panda(zoo, tmp_path):
    """``wresdyn collect`` as run.py calls it, at a tiny size and without the Newton gap replay: the Panda's
    ``world`` link builds in the MuJoCo real robot and its fingers (narrower than the limit margin) are excited."""
    from wresdyn.cli import main
    from wresdyn.data.dataset import Dataset

    z = zoo["panda"]
    out = tmp_path / "data"
    assert main(["collect", "--robot", str(z.path), "--gains", str(z.gains), "--out", str(out), "--quiet", "--no-gap",
                 "--train", "1", "--validation", "0", "--heldout", "0", "--ood", "1", "--duration", "0.5"]) == 0
    ds = Dataset.load(out / "dataset.npz")
    assert len(ds.joint_names) == 9 and len(ds.split("train")) == 1 and len(ds.split("ood")) == 1
    finger = ds.joint_names.index("panda_finger_joint1")
    for tr in ds.trajectories:
        assert np.ptp(tr.q_cmd[:, finger]) > 1e-4 and np.all(np.isfinite(tr.q))


def test_readme_results_equal_summary(zoo):
    """The README's results rows are ``benchmarks/results/robot_zoo/summary.json`` (and each ``result.json``'s
    PD-only gap), rounded as printed."""
    import json
    import re

    results = ZOO_DIR.parents[1] / "results" / "robot_zoo"
    summary = json.loads((results / "summary.json").read_text())
    row = r"^\| (\w+) \| (\d+) \| ([\d.]+) \| ([\d.]+)× \| ([\d.]+)× \| ([\d.]+)× \| (\d+) \|$"
    rows = {m[0]: m[1:] for m in re.findall(row, (ZOO_DIR / "README.md").read_text(), re.M)}
    assert set(rows) == set(summary) == set(zoo)
    for name, s in summary.items():
        gap = json.loads((results / name / "result.json").read_text())["pd_only_rad"]["heldout"]
        assert rows[name] == (str(s["dof"]), f"{gap:.4f}", f"{s['heldout_ratio']:.1f}", f"{s['ood_ratio']:.1f}",
                              f"{s['validation_ratio']:.1f}", f"{s['fit_seconds']:.0f}"), name
