"""Every example runs end to end (small sizes), so examples never rot."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _run(*args):
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, cwd=ROOT, timeout=600)


@pytest.mark.parametrize(
    "robot, gains",
    [
        ("scenes/humanoid.usda", None),
        ("newton:quadruped.urdf", "examples/gains/quadruped.toml"),
        ("newton:cartpole.urdf", "examples/gains/cartpole.toml"),
    ],
)
def test_load_custom_robot(robot, gains):
    res = _run("examples/load_custom_robot.py", robot, *(["--gains", gains] if gains else []), "--seconds", "0.5")
    assert res.returncode == 0, res.stderr
    assert "kp" in res.stdout and "armature" in res.stdout
    line = [ln for ln in res.stdout.splitlines() if ln.startswith("Newton")][-1]
    max_dq = float(line.split("max |dq| = ")[1].split(",")[0])
    assert max_dq < 1e-4  # Newton and MuJoCo agree on the short replay


def test_load_custom_robot_without_gains_says_how_to_supply_them():
    res = _run("examples/load_custom_robot.py", "newton:quadruped.urdf")
    assert res.returncode == 2
    assert "no PD gains" in res.stderr and "--gains" in res.stderr and "nan" not in res.stdout.lower()


@pytest.mark.parametrize("example", ["examples/ppo_vs_gradient.py", "examples/train_residual_ppo.py"])
def test_learning_examples_smoke(tmp_path, example):
    res = _run(example, "--test", "--out", tmp_path / "run")
    assert res.returncode == 0, res.stderr[-2000:]


def test_demo_quick(tmp_path):
    res = subprocess.run([sys.executable, "-m", "wresdyn.cli", "demo", "--quick", "--out", str(tmp_path)],
                         capture_output=True, text=True, cwd=ROOT, timeout=900)
    assert res.returncode == 0, res.stderr[-2000:]
    report = (tmp_path / "report.md").read_text()
    assert "| calibrated (gradient fit) |" in report and "| residual by PPO |" in report
    assert "| b_calibrated |" in report and "| d_oracle |" in report and "Gap closed" in report
    assert (tmp_path / "fit" / "export" / "actuated.usda").is_file()
    assert (tmp_path / "deploy" / "report.md").is_file()
