"""``wresdyn export``: the calibrated robot as USD + Newton actuators + residual, read back by plain Newton.

The run folder is made by the real code paths at a tiny size: a dataset recorded on ``RealRobot``, identified
physics (:class:`PhysicalParams`, here the nominal values moved by hand so every field differs from the robot
file) and a residual network exported by :func:`export_run_files` with weights large enough to matter.
"""

from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from wresdyn.cli import main
from wresdyn.paths import REPO

EXAMPLE = REPO / "examples" / "calibrated_robot_newton.py"


def _example():
    spec = importlib.util.spec_from_file_location("calibrated_robot_newton", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _physics(robot):
    from wresdyn.sim.physics import PhysicalParams

    p = PhysicalParams.nominal(robot)
    n = robot.n_dof
    p.kp *= 1.1
    p.kd *= 0.9
    p.armature *= 1.3
    p.damping += 0.4
    p.friction += 0.02 * np.where(np.isfinite(p.effort), p.effort, 10.0)
    p.effort = 0.8 * p.effort
    p.delay = np.where(np.arange(n) % 2 == 0, 0.004, 0.0)  # 2 steps at 500 Hz on every other joint
    p.body_mass = p.body_mass * 1.05
    p.body_com = p.body_com + 0.01
    rot = np.array([[0.96, -0.28, 0.0], [0.28, 0.96, 0.0], [0.0, 0.0, 1.0]])  # a rotated, non-diagonal inertia
    p.body_inertia = rot @ (p.body_inertia * 1.05) @ rot.T
    return p


def _run(tmp_path: Path, robot, data, physics=True, residual=True, scale=100.0) -> Path:
    """A run folder as `wresdyn fit` leaves it, from the real writers; the residual's last layer is ``scale``
    times its near-zero start."""
    from wresdyn.fit.gradfit import build_policy
    from wresdyn.learn.residual import ResidualConfig, export_run_files, obs_stats

    run = tmp_path / "run"
    run.mkdir()
    data_path = tmp_path / "dataset.npz"
    if not data_path.exists():
        data.save(data_path)
    (run / "config.json").write_text(json.dumps({"learner": "gradient", "data_path": str(data_path)}))
    if physics:
        _physics(robot).save(run / "physics.json")
    if residual:
        torch.manual_seed(0)
        mean, std = obs_stats(data.split("train"))
        policy = build_policy(robot, ResidualConfig(fraction=0.1), mean, std)
        with torch.no_grad():
            last = [m for m in policy.mlp.modules() if isinstance(m, torch.nn.Linear)][-1]
            last.weight.mul_(scale)  # undo the near-zero start: 100 gives the humanoid a residual of a few N*m
        export_run_files(policy, run, data, arch="mlp", learner="gradient")
    return run


@pytest.fixture(scope="module")
def exported(tmp_path_factory, humanoid, data):
    tmp = tmp_path_factory.mktemp("export")
    run = _run(tmp, humanoid, data)
    assert main(["export", str(run), "--out", str(tmp / "calibrated")]) == 0
    return run, tmp / "calibrated"


def test_export_writes_the_identified_physics_as_usd_newton_reads(exported, humanoid):
    from wresdyn.robot.description import load_robot
    from wresdyn.sim.physics import PhysicalParams

    run, out = exported
    assert {"robot.usda", "actuated.usda", "residual.pt2", "residual.onnx", "physics.json", "export.json"} <= {
        p.name for p in out.iterdir()}
    want = PhysicalParams.load(run / "physics.json", humanoid)
    cal = load_robot(out / "robot.usda")  # Newton's USD importer, through the layer over the untouched file
    for f in ("kp", "kd", "armature", "damping", "friction", "effort"):
        np.testing.assert_allclose(getattr(cal, f), getattr(want, f), rtol=1e-5, err_msg=f)
    np.testing.assert_allclose(cal.body_mass, want.body_mass, rtol=1e-6)
    np.testing.assert_allclose(cal.body_com, want.body_com, atol=1e-6)
    np.testing.assert_allclose(cal.body_inertia, want.body_inertia, atol=1e-6 * np.abs(want.body_inertia).max())
    assert not np.allclose(cal.body_inertia, humanoid.body_inertia)  # it did change the robot
    assert cal.source_sha256 != humanoid.source_sha256 and humanoid.source.read_bytes()  # the original is untouched


def test_actuator_prims_parse_into_newton_actuators(exported, humanoid):
    import newton
    from newton.actuators import ClampingMaxEffort, Delay, DrivePD, parse_actuator_prim
    from pxr import Usd

    from wresdyn.sim.physics import PhysicalParams

    run, out = exported
    want = PhysicalParams.load(run / "physics.json", humanoid)
    stage = Usd.Stage.Open(str(out / "actuated.usda"))
    parsed = {p.GetName(): parse_actuator_prim(p) for p in stage.Traverse() if p.GetTypeName() == "NewtonActuator"}
    assert sorted(parsed) == sorted(humanoid.joint_names)
    for i, name in enumerate(humanoid.joint_names):
        a = parsed[name]
        assert a.drive_class is DrivePD and a.target_path.endswith("/" + name)
        assert a.drive_kwargs["kp"] == pytest.approx(want.kp[i], rel=1e-6)
        assert a.drive_kwargs["kd"] == pytest.approx(want.kd[i], rel=1e-6)
        comps = dict(a.component_specs)
        assert comps[ClampingMaxEffort]["max_effort"] == pytest.approx(want.effort[i], rel=1e-6)
        assert (Delay in comps) == (want.delay[i] > 0)
        if Delay in comps:
            assert comps[Delay]["delay_steps"] == 2
    builder = newton.ModelBuilder()
    builder.add_usd(str(out / "actuated.usda"), floating=False, load_visual_shapes=False)
    model = builder.finalize()
    assert sum(a.num_actuators for a in model.actuators) == humanoid.n_dof
    assert np.all(model.joint_target_ke.numpy() == 0.0)  # the joints' own drives are off: PD is applied once


def test_plain_newton_reproduces_the_corrected_replay(exported, humanoid, data):
    """The round trip: examples/calibrated_robot_newton.py (Newton + the residual component only) against wresdyn's
    corrected replay (SolverReplay with the identified physics, fractional delay and residual) on held-out data.

    Tolerance 2e-3 rad mean, 1e-2 max over 0.2 s: the two differ by solver (MuJoCo C's implicitfast with a soft
    frictionloss constraint against SolverReplay's stiction), by the delay (whole actuator steps against
    wresdyn's interpolated command) and the PD (explicit in the actuator, implicit damping in SolverReplay);
    measured 2.4e-3 rad mean over 2 s of the default benchmark (README). The residual's own effect is asserted
    larger, so dropping it would fail."""
    from wresdyn.learn.network_file import load_residual
    from wresdyn.sim.physics import PhysicalParams
    from wresdyn.sim.rollout import replay_trajectories

    run, out = exported
    physics = PhysicalParams.load(run / "physics.json", humanoid)
    policy = load_residual(run / "policy.pt")
    traj = data.split("heldout")[0]
    q_plain = _example().replay(str(out / "actuated.usda"), traj.q[0], traj.qd[0], traj.qdd[0], traj.q_cmd,
                                1.0 / data.rate_hz)
    ref = replay_trajectories(humanoid, [traj], data.rate_hz, policy, physics=physics)["residual"].q[0]
    bare = replay_trajectories(humanoid, [traj], data.rate_hz, None, physics=physics)["residual"].q[0]
    diff = np.abs(q_plain - ref)
    print(f"round trip {diff.mean():.2e} mean, {diff.max():.2e} max; residual effect {np.abs(bare - ref).mean():.2e}")
    assert diff.mean() < 2e-3 and diff.max() < 1e-2, (diff.mean(), diff.max())
    assert np.abs(bare - ref).mean() > 3 * diff.mean()  # the residual matters more than the round-trip error


def test_export_refuses_bad_runs_and_writes_nothing(tmp_path, humanoid, data, capsys):
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import collect

    no_res = _run(tmp_path, humanoid, data, residual=False)
    out = tmp_path / "out"
    assert main(["export", str(no_res), "--out", str(out)]) == 2
    assert "has no residual" in capsys.readouterr().err and not out.exists()
    assert main(["export", str(no_res), "--out", str(out), "--physics-only"]) == 0  # identified physics alone
    assert (out / "robot.usda").exists() and not (out / "residual.pt2").exists()
    assert main(["export", str(no_res), "--out", str(out), "--physics-only"]) == 2  # exists, no --force
    assert "already exists" in capsys.readouterr().err
    assert main(["export", str(no_res), "--out", str(out), "--physics-only", "--force"]) == 0

    # a robot file that changed after the recording
    robot_copy = tmp_path / "robot" / "humanoid.usda"
    robot_copy.parent.mkdir()
    shutil.copyfile(humanoid.source, robot_copy)
    from wresdyn.robot.description import load_robot

    copy = load_robot(robot_copy)
    ds = collect(copy, Mismatch(), {"train": 1}, duration=0.02)
    ds.save(tmp_path / "copy.npz")
    run = tmp_path / "run_copy"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"data_path": str(tmp_path / "copy.npz")}))
    _physics(copy).save(run / "physics.json")
    robot_copy.write_text(robot_copy.read_text() + "\n")
    out2 = tmp_path / "out2"
    assert main(["export", str(run), "--out", str(out2), "--physics-only"]) == 2
    err = capsys.readouterr().err
    assert "changed since the run's data were recorded" in err and len(err.strip().splitlines()) == 1
    assert not out2.exists() and not any(p.name.startswith(".out2") for p in tmp_path.iterdir())


def test_the_exported_robot_stands_on_the_floor_and_writes_an_animation(exported, tmp_path):
    """examples/corrected_robot_standing.py at a tiny size: free base, ground plane, SolverMuJoCo with contacts,
    the actuators and the residual every step; the USD animation opens with pxr and has time samples."""
    from pxr import Usd, UsdGeom

    spec = importlib.util.spec_from_file_location("corrected_robot_standing",
                                                  REPO / "examples" / "corrected_robot_standing.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    _, out = exported
    anim = tmp_path / "standing.usda"
    r = mod.run(str(out / "actuated.usda"), 0.3, str(anim))
    assert not r["fell"] and r["min_height"] > 0.9 * r["start_height"]  # on its feet, not through the floor
    assert abs(r["heights"][-1] - r["heights"][1]) < 0.02
    stage = Usd.Stage.Open(str(anim))
    assert stage.GetEndTimeCode() > stage.GetStartTimeCode()
    xforms = [p for p in stage.Traverse() if p.IsA(UsdGeom.Xformable)]
    assert xforms and any(UsdGeom.Xformable(p).GetTimeSamples() or
                          any(a.GetNumTimeSamples() > 1 for a in p.GetAttributes()) for p in stage.Traverse())


@pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning")  # writing the old format on purpose
def test_a_torchscript_or_corrupt_model_file_is_refused_in_one_line(tmp_path):
    """Run folders written before the torch.export format hold TorchScript ``policy.pt`` files: loading one names the
    file and what to do, as does a file that is no archive at all."""
    import torch

    from wresdyn.errors import WresdynError
    from wresdyn.learn.network_file import load_program

    old = tmp_path / "policy.pt"
    torch.jit.save(torch.jit.script(torch.nn.Linear(2, 2)), str(old))
    with pytest.raises(WresdynError, match="TorchScript file.*again"):
        load_program(old)
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a zip")
    with pytest.raises(WresdynError, match="not a torch.export archive"):
        load_program(bad)
