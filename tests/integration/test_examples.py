"""Every example imports and parses its flags here; the runs end to end (small sizes) that another test already
covers through the same code path are opt-in (``--run-slow``), so examples never rot and the suite stays short."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]


def _run(*args):
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, cwd=ROOT, timeout=600)


def _example(name: str):
    """``examples/<name>`` loaded as a module (not run as a script)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"example_{name[:-3]}", ROOT / "examples" / name)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _run_main(name: str, *args, monkeypatch, capsys):
    """``python examples/<name> ARGS`` in this process, from the repository root: its ``main``'s return value and what
    it printed (stdout, stderr). The modules an example needs are loaded here already; a process of its own would
    load them again, most of a small run's time."""
    mod = _example(name)
    monkeypatch.chdir(ROOT)
    monkeypatch.setattr(sys, "argv", [name, *map(str, args)])
    capsys.readouterr()
    code = mod.main()
    out = capsys.readouterr()
    return code, out.out, out.err


def _draws(png, rgb, pixels: int = 50) -> bool:
    """Whether the picture has at least ``pixels`` pixels of colour ``rgb`` (0-255): a line of it is drawn."""
    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    return int((np.abs(img - rgb).sum(axis=-1) < 30).sum()) >= pixels


@pytest.mark.parametrize("example", sorted(p.name for p in (ROOT / "examples").glob("*.py") if p.name != "quickstart.py"))
def test_every_example_imports_and_answers_help(example, monkeypatch, capsys):
    """Loaded as a module (not run), its ``main`` prints the usage for ``--help``: imports, names it calls at import
    time and its flags are checked without the run. The quickstart has no flags; the docs test runs it."""
    mod = _example(example)
    monkeypatch.setattr(sys, "argv", [example, "--help"])
    with pytest.raises(SystemExit) as done:
        mod.main()
    assert done.value.code == 0 and "usage:" in capsys.readouterr().out


@pytest.mark.parametrize(
    "robot, gains",
    [
        ("scenes/humanoid.usda", None),
        ("newton:quadruped.urdf", "examples/gains/quadruped.toml"),
        ("newton:cartpole.urdf", "examples/gains/cartpole.toml"),
    ],
)
def test_load_custom_robot(robot, gains, monkeypatch, capsys):
    flags = (["--gains", gains] if gains else []) + ["--seconds", "0.5"]
    code, out, err = _run_main("load_custom_robot.py", robot, *flags, monkeypatch=monkeypatch, capsys=capsys)
    assert code == 0, err
    assert "kp" in out and "armature" in out
    line = [ln for ln in out.splitlines() if ln.startswith("Newton")][-1]
    max_dq = float(line.split("max |dq| = ")[1].split(",")[0])
    assert max_dq < 1e-4  # Newton and MuJoCo agree on the short replay


def test_load_custom_robot_without_gains_says_how_to_supply_them(monkeypatch, capsys):
    code, out, err = _run_main("load_custom_robot.py", "newton:quadruped.urdf", monkeypatch=monkeypatch, capsys=capsys)
    assert code == 2
    assert "no PD gains" in err and "--gains" in err and "nan" not in out.lower()


@pytest.mark.slow  # the ablation it drives runs end to end in tests/experiments/test_ablation.py
def test_ppo_vs_gradient_prints_the_table_of_its_runs(tmp_path):
    out = tmp_path / "run"
    res = _run("examples/ppo_vs_gradient.py", "--test", "--out", out)
    assert res.returncode == 0, res.stderr[-2000:]
    results = json.loads((out / "results.json").read_text())
    assert [r["learner"] for r in results] == ["ppo", "gradient"]
    pd = results[0]["heldout_pd_only"]["mean_abs_dq"]
    assert f"PD-only: held-out {pd:.4f} rad" in res.stdout
    for r in results:  # the printed row of each learner states its held-out error and its ratio to PD only
        row = f"| {r['learner']} | mlp | torque | 1 | {r['heldout']['mean_abs_dq']:.4f} | " \
              f"{pd / r['heldout']['mean_abs_dq']:.1f}x |"
        assert row in res.stdout, res.stdout[-2000:]
    # the learning curves it points to: PPO's and the gradient fit's lines (matplotlib's first two colours)
    assert f"learning curves: {out}/curves.png" in res.stdout
    assert _draws(out / "curves.png", (0x1F, 0x77, 0xB4)) and _draws(out / "curves.png", (0xFF, 0x7F, 0x0E))


def test_train_residual_ppo_prints_what_its_report_states(tmp_path, monkeypatch, capsys):
    out = tmp_path / "run"
    _, printed, _ = _run_main("train_residual_ppo.py", "--test", "--out", out, monkeypatch=monkeypatch, capsys=capsys)
    speed = re.search(r"^(\d+) env-steps/s, (\d+\.\d+) s/iteration$", printed, re.M)
    summary = json.loads((out / "train_summary.json").read_text())
    assert speed and int(speed[1]) == round(summary["env_steps_per_s"]) > 0, printed[-2000:]
    metrics = json.loads((out / "eval" / "metrics.json").read_text())["splits"]
    for split in ("heldout", "ood"):
        s = metrics[split]
        assert (f"{split}: mean |dq| PD only {s['pd_only']['mean_abs_dq']:.4f} rad, "
                f"PD + residual {s['pd_residual']['mean_abs_dq']:.4f} rad") in printed
        # its Fig. 3: the recording (red), PD only (green), PD + residual (blue)
        fig = out / "eval" / f"fig3_{split}.png"
        assert all(_draws(fig, rgb) for rgb in ((255, 0, 0), (0, 128, 0), (0, 0, 255))), split
    assert f"report: {out}/eval/report.md" in printed


def test_demo_quick(tmp_path):
    from wresdyn.cli import main

    # in this process: the modules it needs are loaded already (a command of its own would load them again)
    assert main(["demo", "--quick", "--out", str(tmp_path)]) == 0
    report = (tmp_path / "report.md").read_text()
    assert "| calibrated (gradient fit) |" in report and "| residual by PPO |" in report
    assert "| b_calibrated |" in report and "| d_oracle |" in report and "Gap closed" in report
    # the calibrated robot it exports: one Newton actuator per joint of the residual it carries
    export = tmp_path / "fit" / "export"
    joints = json.loads((export / "residual.json").read_text())["joint_names"]
    actuators = re.findall(r'def NewtonActuator "(\w+)"', (export / "actuated.usda").read_text())
    assert len(joints) == 21 and sorted(actuators) == sorted(joints)
    # the summary quotes the skills benchmark's results: its gap closed and held-out MPJPE [mrad] on the real robot
    deploy = json.loads((tmp_path / "deploy" / "results.json").read_text())
    gap = deploy["gap_closed"]["b_calibrated"]
    assert f"(a − b) / (a − d): {100 * gap:.0f} %" in report
    for name in ("b_calibrated", "d_oracle"):
        mpjpe = 1e3 * deploy["real"]["heldout"][name]["mean"]["mpjpe"]
        assert f"| {name} | {mpjpe:.2f} |" in report, (name, mpjpe)
