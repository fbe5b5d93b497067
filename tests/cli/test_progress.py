"""Progress lines where a command could otherwise sit silent: the first Warp compile of a robot's kernels
(:mod:`wresdyn.sim.warmup`, called by collect, fit, train, identify and eval) and the foot-IK workspace and draws
of ``collect``."""

from __future__ import annotations

import dataclasses
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from wresdyn.cli import main
from wresdyn.errors import WresdynError
from wresdyn.paths import REPO
from wresdyn.robot.description import RobotError, load_robot
from wresdyn.sim.warmup import compile_kernels

SO101 = REPO / "scenes" / "so101" / "so101.xml"
SHIPPED = REPO / "data" / "so101"
DONE = re.compile(r"^\.\.\. done in \d+\.\d s \(.+ \d+\.\d s\)$")


def test_compile_kernels_says_what_and_how_long_once_per_robot():
    import warp as wp

    robot = load_robot(SO101)
    lines = []
    seconds = compile_kernels(robot, 500.0, ("forward", "grad"), say=lines.append)
    assert len(lines) == 2, lines
    assert lines[0].startswith("compiling Warp kernels for so101.xml (6 joints; forward, grad): on a robot's first "
                               "run only")
    # the folder it names is the one Warp loads from (shown with ~ for the home folder)
    shown = re.fullmatch(r".*, then loaded from (.+) \.\.\.", lines[0])
    assert shown and Path(shown[1]).expanduser() == Path(wp.config.kernel_cache_dir), lines[0]
    assert DONE.match(lines[1]) and seconds > 0
    # the two modules compile side by side (Warp's thread pool), so one time covers both
    assert re.search(r"\(forward and grad in parallel \d+\.\d s\)$", lines[1]), lines[1]
    # compiled in this process: no second announcement; identification's variant runs on the gradient fit's module
    assert compile_kernels(robot, 500.0, ("grad", "forward"), say=lines.append) is None and len(lines) == 2
    assert compile_kernels(robot, 500.0, ("param_grads",), say=lines.append) is None and len(lines) == 2
    # another robot object (a new load) is announced again; variants of one module are named together
    assert compile_kernels(load_robot(SO101), 500.0, ("param_grads", "grad"), say=lines.append) is not None
    assert "(6 joints; param_grads)" in lines[2] and re.search(r"\(param_grads = grad \d+\.\d s\)$", lines[3])
    with pytest.raises(WresdynError, match="choose from forward, grad, param_grads"):
        compile_kernels(robot, 500.0, ("backward",))


def test_identified_physics_runs_on_the_robot_files_modules():
    """Identified physics makes friction and products of inertia non-zero where the robot file (the humanoid's) has
    none; SolverReplay reads them as run-time arrays, so a simulator set to it loads no module beyond the warm-up's,
    forward or with an adjoint."""
    from wresdyn.robot.description import DEFAULT_ROBOT
    from wresdyn.sim import Simulator
    from wresdyn.sim.physics import PhysicalParams
    from wresdyn.sim.solver_replay import cache

    robot = load_robot(DEFAULT_ROBOT)
    assert not robot.friction.any()
    physics = PhysicalParams.nominal(robot)
    physics.friction[:] = 0.5 + 0.01 * np.arange(robot.n_dof)  # [N*m]
    physics.body_inertia[1:, 0, 1] = physics.body_inertia[1:, 1, 0] = 1e-5  # [kg*m^2]

    def modules_loaded_by_a_run(**kw):
        before = len(cache._MODULES)
        sim = Simulator(robot, 2, 1 / 500.0, **kw)
        sim.set_physics(physics)
        sim.step(sim.q)
        return len(cache._MODULES) - before

    lines = []
    cache._MODULES.clear()  # the modules loaded in this process (not Warp's disk cache)
    compile_kernels(robot, 500.0, ("forward", "param_grads"), say=lines.append)
    assert len(cache._MODULES) == 2
    assert modules_loaded_by_a_run() == 0
    assert modules_loaded_by_a_run(requires_grad=True) == 0
    assert modules_loaded_by_a_run(requires_grad=True, param_grads=True) == 0


def test_collect_logs_announces_the_compile_before_the_replay(tmp_path, capsys):
    run = tmp_path / "logs" / "step_response"
    run.mkdir(parents=True)
    for f in ("joint_list.txt", "event.csv"):
        shutil.copy(SHIPPED / "logs" / "step_response" / f, run / f)
    for f in ("control.csv", "state_motor.csv"):  # 1 s of the run
        lines = (SHIPPED / "logs" / "step_response" / f).read_text().splitlines()[:51]
        (run / f).write_text("\n".join(lines) + "\n")
    assert main(["collect", "--robot", str(SO101), "--logs", str(run), "--map", str(SHIPPED / "map.toml"),
                 "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out.splitlines()
    i = next(k for k, line in enumerate(out) if line.startswith("compiling Warp kernels for so101.xml (6 joints; "
                                                                 "forward)"))
    assert DONE.match(out[i + 1]) and out[i + 2].startswith("replaying 1 heldout run(s) PD-only"), out


def test_collect_foot_ik_reports_the_workspace(tmp_path, capsys):
    """The SO-101's gripper frame on its 5-joint chain: position-only IK, the case of a 5-joint leg."""
    assert main(["collect", "--robot", str(SO101), "--frames", "gripperframe", "--train", "1", "--validation", "0",
                 "--heldout", "0", "--ood", "0", "--duration", "0.2", "--no-gap", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "foot IK on gripperframe (position only, 5 joints): sampling the workspace" in out
    assert re.search(r"  400 of 400 sampled configurations usable \(\d+\.\d s\); checking the box is reachable", out)
    assert re.search(r"  workspace ready in \d+\.\d s: box sides gripperframe \d+\.\d-\d+\.\d cm", out)
    assert "[1/1] train_000" in out


def test_rejected_foot_draws_are_reported():
    from wresdyn.data import excitation as ex

    robot = load_robot(SO101)
    plan = ex.plan(robot, ex.ExcitationConfig(mode="foot", frames=("gripperframe",)))
    strict = dataclasses.replace(plan, cfg=dataclasses.replace(plan.cfg, max_velocity=1e-3, max_draws=2))
    lines = []
    with pytest.raises(RobotError, match="in 2 draws"):
        strict.generate("ellipsoid", 0.2, 500.0, np.random.default_rng(0), progress=lines.append)
    assert len(lines) == 2 and all("rejected: peak" in ln and "> 0.001 rad/s" in ln for ln in lines), lines
    assert lines[0].startswith("  ellipsoid draw 1/2") and lines[1].startswith("  ellipsoid draw 2/2")
    tight = dataclasses.replace(plan, cfg=dataclasses.replace(plan.cfg, ik_tol=1e-12, max_draws=1))
    lines.clear()
    with pytest.raises(RobotError):
        tight.generate("ellipsoid", 0.2, 500.0, np.random.default_rng(0), progress=lines.append)
    assert len(lines) == 1 and "rejected: IK error" in lines[0], lines


def _cut_logs(dest, runs=("multisine", "prbs_excitation", "step_response"), rows=51):
    """The first ``rows - 1`` data rows (1 s at 50 Hz) of shipped SO-101 runs, SAGE layout, under ``dest``."""
    for name in runs:
        run = dest / name
        run.mkdir(parents=True)
        for f in ("joint_list.txt", "event.csv"):
            shutil.copy(SHIPPED / "logs" / name / f, run / f)
        for f in ("control.csv", "state_motor.csv"):
            lines = (SHIPPED / "logs" / name / f).read_text().splitlines()[:rows]
            (run / f).write_text("\n".join(lines) + "\n")
    return dest


def test_fit_and_eval_announce_the_compile_and_the_excluded_gripper(tmp_path, capsys):
    logs = _cut_logs(tmp_path / "logs")
    data = tmp_path / "d"
    assert main(["collect", "--robot", str(SO101), "--logs", str(logs), "--map", str(SHIPPED / "map.toml"),
                 "--split-map", str(SHIPPED / "splits.toml"), "--no-gap", "--out", str(data)]) == 0
    capsys.readouterr()
    run = tmp_path / "fit"
    assert main(["fit", str(data / "dataset.npz"), "--model", "network", "--iterations", "2", "--windows", "2",
                 "--curriculum", "2", "--out", str(run)]) == 0
    out = capsys.readouterr().out.splitlines()
    i = next(k for k, ln in enumerate(out) if ln.startswith("compiling Warp kernels for so101.xml (6 joints; "
                                                             "forward, grad)"))
    assert out[i - 1].startswith("gradient fit of") and DONE.match(out[i + 1]), out
    assert main(["eval", str(run), "--splits", "heldout", "--joints", "2"]) == 0
    out = capsys.readouterr().out
    assert "compiling Warp kernels for so101.xml (6 joints; forward)" in out
    assert "excluded from fitting and from the metrics: gripper" in out
    assert "(over 5 fitted joints; excluded: gripper)" in out
    assert "excluded from fitting and from these figures: gripper" in (run / "eval" / "report.md").read_text()


# wresdyn.progress: the bar of the long loops, plain lines off a terminal, --quiet, the run folder's log


def _loop(log, n: int = 4):
    from wresdyn.progress import bar

    with bar(log, n, "fit") as b:
        for i in range(n):
            if i == 2:
                log("iter 3: a line of the loop")
            b.update(1, f"H={i}")


def test_plain_lines_off_a_terminal_and_every_line_in_the_file(tmp_path):
    import io

    from wresdyn.progress import Log

    out = io.StringIO()  # not a terminal: no bar, periodic plain lines (every update at every=0)
    log = Log(tmp_path / "run" / "fit.log", stream=out, every=0.0)
    log("before the run folder exists")
    assert not (tmp_path / "run").exists()  # a run refused before it starts leaves no folder
    (tmp_path / "run").mkdir()
    _loop(log)
    lines = out.getvalue().splitlines()
    plain = re.compile(r"^fit: (\d)/4 \((\d+) %\), 0:00 elapsed, 0:00 left, H=(\d)$")
    assert [plain.match(ln).group(1, 3) for ln in lines if plain.match(ln)] == [("1", "0"), ("2", "1"), ("3", "2"),
                                                                                ("4", "3")]
    assert "iter 3: a line of the loop" in lines and "\r" not in out.getvalue()
    # the log's lines, those from before the folder too; not the progress lines
    assert (tmp_path / "run" / "fit.log").read_text() == "before the run folder exists\niter 3: a line of the loop\n"


def test_quiet_prints_nothing_and_the_file_keeps_the_lines(tmp_path):
    import io

    from wresdyn.progress import Log

    out = io.StringIO()
    _loop(Log(tmp_path / "fit.log", quiet=True, stream=out, every=0.0))
    assert out.getvalue() == "" and (tmp_path / "fit.log").read_text() == "iter 3: a line of the loop\n"


def test_a_bar_with_elapsed_and_remaining_time_on_a_terminal(tmp_path):
    """On a real pseudo-terminal: tqdm redraws one bar (carriage returns), the loop's line printed above it."""
    import fcntl
    import os
    import struct
    import termios

    from wresdyn.progress import Log

    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a new pty is 0 columns wide
    with open(slave, "w", closefd=True) as tty:
        assert tty.isatty()
        _loop(Log(tmp_path / "fit.log", stream=tty))
    text = b""
    os.set_blocking(master, False)
    try:
        while chunk := os.read(master, 65536):
            text += chunk
    except OSError:  # drained: EAGAIN, or EIO once the closed terminal's output is all read (Linux)
        pass
    os.close(master)
    screen = text.decode()
    assert "\r" in screen and "iter 3: a line of the loop" in screen
    assert re.search(r"fit: 4/4 \|.*\| 00:00 elapsed, 00:00 left, H=3", screen), screen


def test_fit_quiet_writes_only_the_log(tmp_path, capsys):
    data = tmp_path / "d"
    assert main(["collect", "--robot", str(SO101), "--train", "1", "--validation", "1", "--heldout", "0", "--ood",
                 "0", "--duration", "0.4", "--no-gap", "--out", str(data)]) == 0
    capsys.readouterr()
    run = tmp_path / "fit"
    assert main(["fit", str(data / "dataset.npz"), "--model", "network", "--iterations", "3", "--windows", "2",
                 "--curriculum", "2", "--out", str(run), "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    log = (run / "fit.log").read_text().splitlines()
    assert log[0].startswith("gradient fit of a torque residual (mlp) on 1 trajectories")
    assert sum(ln.startswith("iter ") for ln in log) == 3 and log[-1].startswith("done: ")


# the other long jobs on the same helper: PPO of the residual (train), the skills' PPO (deploy), recording (collect)

PLAIN_END = r"^{}: {n}/{n} \(100 %\), \d+:\d\d elapsed, 0:00 left"


def _plain(desc: str, n: int):
    """The plain progress line of the last of ``n`` iterations of the loop ``desc``."""
    return re.compile(PLAIN_END.format(re.escape(desc), n=n), re.M)


def test_ppo_draws_a_line_per_iteration_and_keeps_rsl_rls_tables_in_the_run(robot, data, tmp_path):
    import io

    from conftest import tiny_ppo_config as tiny

    from wresdyn.ppo.trainer import train
    from wresdyn.progress import Log

    out = io.StringIO()  # not a terminal, every=0: a plain line after every iteration
    run = tmp_path / "run"
    train(data, robot, tiny(iterations=2), run, log=Log(run / "train.log", stream=out, every=0.0))
    text = out.getvalue()
    assert re.search(r"^train: 1/2 \(50 %\), \d+:\d\d elapsed, \d+:\d\d left, reward -?\d", text, re.M), text
    assert _plain("train", 2).search(text) and "validation after 2 iterations" in text
    assert "Learning iteration" not in text  # rsl-rl's block is in the run folder, not on the screen
    kept = (run / "train.log").read_text()
    assert kept.count("Learning iteration") == 2 and "validation after 2 iterations" in kept


def test_train_quiet_prints_nothing_and_train_log_has_every_line(data, tmp_path, capsys):
    path = tmp_path / "dataset.npz"
    data.save(path)
    run = tmp_path / "run"
    tiny = ["--iterations", "2", "--num-envs", "4", "--steps-per-env", "8", "--horizon", "8",
            "--set", "residual.hidden_dims=32,32", "--set", "residual.critic_hidden_dims=32,32",
            "--set", "ppo.num_mini_batches=2", "--set", "ppo.num_learning_epochs=2"]
    capsys.readouterr()
    assert main(["train", str(path), "--out", str(run), "--quiet"] + tiny) == 0
    assert capsys.readouterr().out == ""
    log = (run / "train.log").read_text()
    assert log.startswith("training a torque residual (mlp) on 2 trajectories")
    assert log.count("Learning iteration") == 2 and '"iterations_this_session": 2' in log
    # not quiet, off a terminal: the last iteration's plain line, with the elapsed and remaining time
    assert main(["train", str(path), "--out", str(tmp_path / "loud")] + tiny) == 0
    out = capsys.readouterr().out
    assert _plain("train", 2).search(out) and "Learning iteration" not in out, out


def test_a_skill_draws_a_line_per_iteration_named_after_its_policy(humanoid, tmp_path):
    import io

    from wresdyn.progress import Log
    from wresdyn.skills.env import SkillConfig, TrackingEnv
    from wresdyn.skills.motions import make_motions
    from wresdyn.skills.plants import SimPlant
    from wresdyn.skills.skill_ppo import SkillPPOConfig, train_skill

    motions = make_motions(humanoid, {"train": 1}, duration=0.4, rate_hz=500.0, seed=3)
    env = TrackingEnv(SimPlant(humanoid, 3, 500.0, 5), motions.split("train"), SkillConfig(decimation=5))
    cfg = SkillPPOConfig(iterations=2, num_steps_per_env=8, hidden_dims=(32, 32), num_mini_batches=1,
                         num_learning_epochs=1, torch_threads=1)
    out = io.StringIO()
    train_skill(env, cfg, tmp_path / "skills" / "a_nominal", log=Log(tmp_path / "deploy.log", stream=out, every=0.0))
    text = out.getvalue()
    assert re.search(r"^a_nominal: 1/2 \(50 %\), \d+:\d\d elapsed, \d+:\d\d left", text, re.M), text
    assert _plain("a_nominal", 2).search(text) and "Learning iteration" not in text
    assert (tmp_path / "skills" / "a_nominal" / "train.log").read_text().count("Learning iteration") == 2
    out = io.StringIO()  # quiet: nothing, not even the bar
    train_skill(env, dataclasses.replace(cfg, iterations=3), tmp_path / "skills" / "a_nominal",
                log=Log(tmp_path / "deploy.log", quiet=True, stream=out, every=0.0))
    assert out.getvalue() == "" and "resuming" in (tmp_path / "deploy.log").read_text()


def test_collect_draws_a_line_over_the_trajectories_and_quiet_keeps_them_in_collect_log(tmp_path, capsys):
    argv = ["collect", "--robot", str(SO101), "--train", "2", "--validation", "0", "--heldout", "0", "--ood", "0",
            "--duration", "0.2", "--no-gap"]
    assert main(argv + ["--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert _plain("collect", 2).search(out) and "[2/2] train_001" in out, out
    assert main(argv + ["--out", str(tmp_path / "b"), "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    log = (tmp_path / "b" / "collect.log").read_text()
    assert log.startswith("collecting 2 trajectories of 0.2 s") and "[2/2] train_001" in log
    assert log.splitlines()[-1].startswith("wrote ")
