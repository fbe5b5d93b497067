"""Skills on the floor: the threaded MuJoCo C worlds of the simulator, floor motions, floating plants, the balance task
and ``wresdyn deploy --floor``, at tiny sizes on the real code paths (Newton's SolverMuJoCo model, MuJoCo C for the
real robot, rsl-rl's PPO)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import torch

from wresdyn.cli import main
from wresdyn.cli.clock import CLOCK_ENV
from wresdyn.skills.env import TrackingEnv
from wresdyn.skills.evaluate import deploy, gaps_or_why_not, metrics
from wresdyn.skills.motions import TASK_FAMILIES, make_motions
from wresdyn.skills.plants import RealPlant, SimPlant
from wresdyn.skills.reference import base_frame_imu
from wresdyn.skills.report import gaps_text
from wresdyn.skills.skill_config import SkillTaskConfig

import skill_runs
from skill_runs import fit_run

RATE = skill_runs.RATE


@pytest.fixture(scope="module")
def motions(humanoid, floating):
    return make_motions(humanoid, {"train": 1, "validation": 1, "heldout": 1}, duration=2.0, rate_hz=RATE, seed=3,
                        floating=floating, screen=False)  # 2 s is too short for references the soles carry


@pytest.fixture(scope="module")
def quiet_real(floating, shipped_mismatch):
    """The shipped real robot without sensor noise (exact comparisons)."""
    return skill_runs.quiet_real(floating, shipped_mismatch)


def test_threaded_mujoco_worlds_step_as_newtons_one_world_solver(floating):
    """Several CPU worlds on the floor (SolverMuJoCoThreads) follow Newton's own MuJoCo C world step for step, each
    joint driven to its own target (a per-joint target mapped to the wrong joint would tip the robot)."""
    from wresdyn.robot.ground import standing_state
    from wresdyn.sim import Simulator

    torch.set_num_threads(1)
    st = standing_state(floating)
    out = {}
    for w in (1, 3):
        sim = Simulator(floating, w, 1.0 / RATE, ground=True)
        assert type(sim.solver).__name__ == ("SolverMuJoCo" if w == 1 else "SolverMuJoCoThreads")
        f = lambda a: torch.as_tensor(np.tile(a, (w, 1)), dtype=torch.float32)  # noqa: E731
        sim.set_full_state(None, f(st.base_pose), f(st.base_twist), f(st.q), f(st.qd))
        target = 0.2 * np.sin(np.arange(floating.n_dof))  # a different target for every joint
        rows = []
        for _ in range(150):
            q, _ = sim.step(f(target))
            rows.append(np.concatenate([sim.base_pose[-1].numpy(), q[-1].numpy()]))
        out[w] = np.array(rows)
    # float32 state round trips between Newton and MuJoCo each step: measured 4e-7 over 150 steps
    assert np.abs(out[1] - out[3]).max() < 1e-5
    # each joint follows its own target, not its neighbour's (measured mean error 0.04 rad against 0.10)
    err = np.abs(out[3][-1, 7:] - target).mean()
    assert err < 0.06 and err < 0.6 * np.abs(out[3][-1, 7:] - np.roll(target, 1)).mean()


def test_floor_motions_keep_planted_soles_still_and_the_weight_over_them(humanoid, floating, motions):
    from wresdyn.sim.kinematics import BodyPositions

    fam = TASK_FAMILIES["floor"]
    assert [m.family for m in motions["train"]] == list(fam.train)
    assert [m.family for m in motions["heldout"]] == list(fam.train + fam.held_out)
    fk = BodyPositions(floating, 1)
    feet = [list(floating.body_names).index(b) for b in ("left_foot", "right_foot")]
    lifted = 0
    for m in motions["heldout"]:
        assert m.planted.any(-1).all(), m.name  # one foot always on the floor
        pos = np.array([fk(torch.as_tensor(m.base[k:k + 1]), torch.as_tensor(m.q[k:k + 1]))[0, feet].numpy()
                        for k in range(0, len(m.q), 25)])
        planted = m.planted[::25]
        for f in range(2):
            p = pos[planted[:, f], f]
            # a planted foot stays where it stood (the IK reaches its keyframes to 10 um; float32 FK)
            assert np.abs(p - pos[0, f]).max() < 2e-3, (m.name, f)
        lifted += int((~m.planted).any())
    assert lifted >= 2  # the kick and the stepping lift a foot


def test_real_plant_on_the_floor_steps_as_the_real_robot(floating, motions, quiet_real):
    """The threaded real plant and RealRobot.step agree exactly (no noise), base included."""
    from wresdyn.robot.ground import FloatingState

    m = motions["train"][0]
    plant = RealPlant(quiet_real, 2, 5)
    q0 = torch.as_tensor(m.q[:1].repeat(2, 0))
    plant.reset_full(torch.arange(2), torch.as_tensor(m.base[:1].repeat(2, 0)), torch.zeros(2, 6), q0, 0 * q0)
    quiet_real.reset(FloatingState(m.base[0], np.zeros(6), m.q[0], np.zeros(floating.n_dof)))
    for k in range(4):
        cmd = m.q[5 * (k + 1)]
        q, _, bad = plant.step(torch.as_tensor(np.tile(cmd, (2, 1))))
        for _ in range(5):
            obs = quiet_real.step(cmd)
        assert not bad.any()
        np.testing.assert_allclose(q[1].numpy(), obs.q, atol=1e-5)
        np.testing.assert_allclose(plant.base_pose[1].numpy(), obs.base_pose, atol=1e-5)


def test_imu_of_a_tilted_base():
    """A base pitched by 0.3 rad about y sees gravity along +x by sin(0.3) in its own axes; its angular velocity
    about the world z axis appears rotated likewise."""
    a = 0.3
    pose = torch.tensor([[0.0, 0.0, 0.8, 0.0, np.sin(a / 2), 0.0, np.cos(a / 2)]], dtype=torch.float32)
    twist = torch.tensor([[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]])
    gyro, grav = base_frame_imu(pose, twist)
    np.testing.assert_allclose(grav[0].numpy(), [np.sin(a), 0.0, -np.cos(a)], atol=1e-6)
    np.testing.assert_allclose(gyro[0].numpy(), [-np.sin(a), 0.0, np.cos(a)], atol=1e-6)


def test_floor_env_observes_no_base_position_and_counts_a_fall(floating, motions, quiet_real):
    """The actor's observation is 6n + 6 (joints, reference, action, IMU), the critic's adds 11 privileged values;
    the reference played open loop on the real robot's floor (ankles weaker than gravity's toppling torque) fails,
    and the metrics count it and stay finite."""
    cfg = SkillTaskConfig.floor(decimation=5)
    mot = motions["validation"]
    env = TrackingEnv(SimPlant(floating, 2, RATE, 5, ground=True), mot[:2], cfg)
    obs = env.get_observations()
    assert obs["policy"].shape == (2, 6 * floating.n_dof + 6) and obs["critic"].shape == (2, 11)
    _, rew, _, extras = env.step(torch.zeros(2, floating.n_dof))
    assert torch.isfinite(rew).all() and "Reward/slip" in extras["log"]
    dep = deploy(None, RealPlant(quiet_real, len(mot), 5), mot, cfg)
    res = metrics(dep)
    assert res["mean"]["failures"] >= 1 and res["mean"]["success"] < 1.0
    failed = [p for p in res["motions"] if not p["success"]]
    assert all(np.isfinite(p["mpjpe"]) and np.isfinite(p["g_mpjpe"]) for p in failed)
    # g-MPJPE is in metres of link position: a fallen robot is decimetres off, a standing one millimetres
    assert 0.0 < res["mean"]["g_mpjpe"] < 1.0


def test_wresdyn_deploy_floor_end_to_end_and_resume(tmp_path, humanoid, data, capsys, monkeypatch):
    data_path = tmp_path / "dataset.npz"
    data.save(data_path)
    cal = fit_run(tmp_path, humanoid, data, "torque", physics=True)
    delta = fit_run(tmp_path, humanoid, data, "delta_action", physics=False)
    out = tmp_path / "floor"
    args = ["deploy", str(data_path), "--floor", "--out", str(out), "--calibrated", str(cal), "--delta", str(delta),
            "--iterations", "2", "--finetune", "1", "--num-worlds", "4", "--oracle-num-worlds", "3", "--train-per-family", "1",
            "--heldout-per-family", "1", "--duration", "1.0", "--no-screen", "--ppo.torch-threads", "1",  # one thread: conftest.py says why
            "--nominal", "None",  # (a) trained here, whatever the package ships
            "--policies", "a_nominal", "b_calibrated", "c_delta_action", "d_oracle"]  # (c) too, as on a GPU
    # the oracle in a process of its own beside (b), as on a GPU, and (c) in another, as on a second GPU
    ledger = tmp_path / "bench" / "heldout_ledger.jsonl"
    monkeypatch.setenv(CLOCK_ENV, "1")  # the deploy's own lines stamped with the process's seconds (a seed's phases)
    assert main(args + ["--oracle-beside", "True", "--beside-devices", "cpu", "--heldout-ledger", str(ledger)]) == 0
    monkeypatch.delenv(CLOCK_ENV)
    res = json.loads((out / "results.json").read_text())
    # the held-out scoring went into the run's ledger and the one given, and the report lists it
    for path in (out / "heldout_ledger.jsonl", ledger):
        (line,) = path.read_text().splitlines()
        assert set(json.loads(line)["figures"]) == set(res["real"]["heldout"])
    for split in ("validation", "heldout"):
        assert set(res["real"][split]) == {"reference", "a_nominal", "b_calibrated", "c_delta_action", "d_oracle"}
        for r in res["real"][split].values():
            assert {"success", "falls", "failures", "mpjpe", "g_mpjpe", "orientation_error", "action_rate"} \
                <= set(r["mean"])
    log = (out / "deploy.log").read_text()
    assert re.match(r"\[ *\d+\.\d s\] wresdyn deploy: skills on the floor", log), log[:80]
    assert "d_oracle: 1 PPO iterations x 3 worlds" in log
    # it starts once (a) is trained, before (b)
    assert log.index("d_oracle: training on the real robot beside") < log.index("policy b_calibrated:")
    assert log.index("c_delta_action: training on cpu beside") < log.index("policy b_calibrated:")
    assert "c_delta_action: 1 PPO iterations x 4 worlds on the floor of the delta_action simulator" in log
    assert (out / "skills" / "c_delta_action" / "train.log").is_file()
    assert set(res["gap_closed_mpjpe"]) == set(res["gap_closed_g_mpjpe"]) == {"b_calibrated", "c_delta_action"}
    assert {"report.md", "tracking_heldout.png", "deployed_heldout.usda"} <= {p.name for p in out.iterdir()}
    report = (out / "report.md").read_text()
    assert "g-MPJPE" in report and "step" in report and "## Held-out ledger" in report
    # failures by kind, the fall rule stated, and a gap ratio only where the oracle beats (a)
    assert "| falls | drifts | diverged |" in report and "tilted more than 0.8 rad\n(46°) from upright" in report
    g, why = gaps_or_why_not(res["real"]["heldout"])
    assert (f"MPJPE no gap ratio: {why};" in report) if why else (f"MPJPE {gaps_text(g)};" in report)
    cfg = json.loads((out / "skills" / "a_nominal" / "config.json").read_text())
    assert cfg["motions"]["floor"] is True
    # the oracle trains on its own number of worlds, the others on --envs
    assert json.loads((out / "skills" / "d_oracle" / "config.json").read_text())["num_worlds"] == 3
    before = (out / "skills" / "a_nominal" / "config.json").read_text()
    capsys.readouterr()
    assert main(args + ["--oracle-beside", "True", "--seed", "5"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "a_nominal" in err
    # another motion set (the combo family added) is refused as well
    assert main(args + ["--oracle-beside", "True", "--extra-families", "combo"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "a_nominal" in err
    assert (out / "skills" / "a_nominal" / "config.json").read_text() == before
    # run again as it was: every policy, done earlier, is reused as it is (no process beside, no summary rewritten)
    summaries = {p: p.read_bytes() for p in out.glob("skills/*/train_summary.json")}
    logged = len((out / "deploy.log").read_text())
    assert main(args + ["--oracle-beside", "True", "--beside-devices", "cpu", "--no-animation", "--quiet"]) == 0
    again = (out / "deploy.log").read_text()[logged:]
    for name in ("a_nominal", "b_calibrated", "c_delta_action", "d_oracle"):
        assert f"[3/4] policy {name}: done earlier ({2 if name == 'a_nominal' else 1} iterations), reused" in again
    assert "beside" not in again and "resuming" not in again, again
    assert again.startswith("wresdyn deploy: skills on the floor"), again[:80]  # no clock asked: no stamps
    assert len(summaries) == 4 and all(p.read_bytes() == b for p, b in summaries.items())


@pytest.mark.slow  # its code path is the floor deploy end to end above; examples' imports and flags: test_examples
def test_skill_on_the_floor_example_runs(tmp_path, humanoid, data):
    import subprocess
    import sys

    from wresdyn.paths import REPO

    cal = fit_run(tmp_path, humanoid, data, "torque", physics=True)
    res = subprocess.run([sys.executable, "examples/skill_on_the_floor.py", str(cal), "--out", str(tmp_path / "skills"),
                          "--iterations", "2", "--finetune", "1", "--envs", "4", "--motions", "1", "--duration", "1.0",
                          "--no-screen"],
                         capture_output=True, text=True, cwd=REPO, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    rows = {ln.split()[0]: ln.split() for ln in res.stdout.splitlines()
            if ln.split()[:1] in (["reference"], ["a_nominal"], ["b_calibrated"])}
    assert set(rows) == {"reference", "a_nominal", "b_calibrated"}
    # success is a percentage of the held-out motions; MPJPE in mrad and g-MPJPE in mm of a standing robot
    # measured on 2 CPU cores after 2 + 1 iterations on one motion: every row 100 %, MPJPE 40.0-40.1 mrad, g-MPJPE
    # 51 mm; the bounds leave 25 % for other CPUs' float rounding
    for r in rows.values():
        assert r[1] == "100%" and 30 < float(r[3]) < 50 and 38 < float(r[4]) < 64, rows


def _still(floating, name: str, seconds: float = 1.5):
    """A floor motion that stands still in the standing pose (the real code path's Motion, built by hand)."""
    from wresdyn.robot.ground import standing_state
    from wresdyn.skills.motions import Motion

    st, t = standing_state(floating), int(seconds * RATE) + 1
    return Motion(name, "still", np.tile(st.q, (t, 1)), np.zeros((t, floating.n_dof)), np.zeros((t, 2, 3)),
                  base=np.tile(st.base_pose, (t, 1)), planted=np.ones((t, 2), dtype=bool))


def test_a_topple_that_drifts_first_counts_as_a_fall_and_an_upright_drift_as_a_drift(floating):
    """Deployed on the real robot's floor (nominal drives, the task's default limits): a robot pushed sideways at
    2 m/s drifts past max_base_error while tilted ~26 deg, well short of fall_tilt, and topples after; it plays on and
    is counted a fall (tilted). A robot standing upright while its reference jumps 1 m away stays a drift."""
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.skills.report import _tilt

    push, away = _still(floating, "push"), _still(floating, "away")
    push.base[0, 1] -= 2.0 / RATE  # the reference's base velocity at the start is the push: 2 m/s along +y
    away.base[100:, 0] += 1.0
    cfg = SkillTaskConfig.floor(decimation=5)
    dep = deploy(None, RealPlant(RealRobot(floating, Mismatch(), RATE), 2, 5), [push, away], cfg)
    res = metrics(dep)
    p, a = res["motions"]
    tilt_at_failure = np.degrees(_tilt(dep.base[[0, 1], dep.failed_at, 3:]))
    # the push: the drift rule fires first (measured at step 27, 26 deg), the topple past fall_tilt 12 steps later
    assert p["cause"] == "tilted" and p["fell"] and not p["success"]
    assert 0 < p["failed_at"] < p["fell_at"] <= p["failed_at"] + 25
    assert 15.0 < tilt_at_failure[0] < np.degrees(cfg.fall_tilt) - 10.0
    assert p["base_error_max"] > cfg.max_base_error
    # the steps it played on after the drift count in no error mean
    assert np.isfinite(dep.q[0, :p["failed_at"] + 1]).all() and np.isnan(dep.q[0, p["failed_at"] + 1:]).all()
    # the upright drift: 1 m from its reference, untilted, never a fall
    assert a["cause"] == "drifted" and not a["fell"] and a["fell_at"] == -1 and tilt_at_failure[1] < 1.0
    assert 0.95 < a["base_error_max"] < 1.05
    m = res["mean"]
    assert (m["falls"], m["drifts"], m["diverged"], m["failures"], m["success"]) == (1, 1, 0, 2, 0.0)
