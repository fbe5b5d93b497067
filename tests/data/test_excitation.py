"""Excitation: foot IK reach and limits, eq. 2, command limits and smoothness, frequency content."""

import numpy as np
import pytest

from wresdyn.data import excitation as ex
from wresdyn.data.spectrum import band_fraction, command_spectrum, plot_spectrum

RATE = 500.0
IK_ACCEPT = 1e-3
"""Acceptance of the issue: every sole target reached within 1 mm."""


@pytest.fixture(scope="module")
def ik(humanoid):
    from wresdyn.data.ik import FootIK

    return FootIK(humanoid)


@pytest.fixture(scope="module")
def ws(ik):
    return ex.foot_workspace(ik, ex.ExcitationConfig())


def _fk_independent(humanoid, q, frame):
    """Sole position by a fresh Pinocchio model and data, not the IK's own."""
    import pinocchio as pin

    from wresdyn.robot.pinocchio_model import build_pinocchio

    model = build_pinocchio(humanoid)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[model.getFrameId(frame)].translation.copy()


def test_ellipsoid_path_is_eq2():
    p = {"a": 0.05, "b": 0.03, "c": 0.04, "x0": 0.1, "y0": 0.12, "z0": 0.02,
         "A_phi": 9.0, "w_phi": 1.3, "phi0": 0.4, "A_theta": 5.0, "w_theta": 0.7, "theta0": -0.2}
    t = np.arange(2000) / RATE
    xyz = ex.ellipsoid_path(p, t)
    # every point lies on the ellipsoid surface
    u = (xyz - [p["x0"], p["y0"], p["z0"]]) / [p["a"], p["b"], p["c"]]
    np.testing.assert_allclose((u ** 2).sum(axis=1), 1.0, atol=1e-12)
    # at t = 0: φ = φ0, θ = θ0 and the angles are at rest (φ̇ = A sin(ω t) = 0), so the foot starts at rest
    expect0 = [p["a"] * np.cos(-0.2) * np.cos(0.4) + 0.1, p["b"] * np.cos(-0.2) * np.sin(0.4) + 0.12,
               p["c"] * np.sin(-0.2) + 0.02]
    np.testing.assert_allclose(xyz[0], expect0, atol=1e-15)
    v0 = np.linalg.norm(xyz[1] - xyz[0]) * RATE
    v_mid = np.linalg.norm(np.diff(xyz, axis=0), axis=1).max() * RATE
    assert v0 < 0.01 * v_mid


def test_ik_reaches_workspace_targets_within_limits(humanoid, ik, ws):
    cfg = ex.ExcitationConfig()
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.0, 4.0, size=60))
    pos = np.empty((len(t), 2, 3))
    for f in range(2):
        pos[:, f] = ex.ellipsoid_path(ex._draw_ellipsoid(rng, ws.lo[f], ws.hi[f], cfg), t)
    rot = np.broadcast_to(ws.level, (len(t), 2, 3, 3))
    q, err = ik.solve_path(pos, rot, ws.home)
    assert err[:, :, 0].max() <= IK_ACCEPT
    assert err[:, :, 1].max() <= IK_ACCEPT  # orientation [rad]
    assert (q >= humanoid.lower).all() and (q <= humanoid.upper).all()
    for k in (0, len(t) // 2, len(t) - 1):
        for f, frame in enumerate(("left_sole", "right_sole")):
            assert np.linalg.norm(_fk_independent(humanoid, q[k], frame) - pos[k, f]) <= IK_ACCEPT


def test_ik_respects_limits_on_unreachable_target(humanoid, ik, ws):
    pos, rot = ik.forward(ws.home)
    pos[0] += [0.0, 0.0, -1.0]  # 1 m below the hip: beyond a straight leg
    q, err = ik.solve(pos, rot, ws.home)
    assert err[0, 0] > 0.1
    assert (q >= humanoid.lower).all() and (q <= humanoid.upper).all()
    rest = np.setdiff1d(np.arange(humanoid.n_dof), ik.dofs)
    np.testing.assert_array_equal(q[rest], ws.home[rest])  # non-leg joints untouched


@pytest.mark.parametrize("family", ex.FAMILIES)
def test_commands_inside_limits_smooth_and_every_joint_moves(humanoid, ik, ws, family):
    cfg = ex.ExcitationConfig()
    e = ex.generate(family, humanoid, ik, ws, 3.0, RATE, np.random.default_rng(11), cfg)
    q = e.q_cmd
    assert q.shape == (1500, humanoid.n_dof)
    assert (q >= humanoid.lower + 0.5 * cfg.limit_margin).all() and (q <= humanoid.upper - 0.5 * cfg.limit_margin).all()
    assert np.abs(np.diff(q, axis=0)).max() * RATE <= cfg.max_velocity
    # smooth: the second difference stays at the size of a 12 rad/s, 8 Hz motion, no steps from IK branch jumps
    assert np.abs(np.diff(q, 2, axis=0)).max() * RATE ** 2 < cfg.max_velocity * 2 * np.pi * cfg.band[1] * 2
    # every joint is excited (identifiable): a standard deviation of 0.01 rad is 40 encoder counts
    assert q.std(axis=0).min() > 0.01, dict(zip(humanoid.joint_names, q.std(axis=0).round(3)))
    # starts at rest: the first command step is tiny
    assert np.abs(q[1] - q[0]).max() * RATE < 0.05


def test_same_seed_same_excitation(humanoid, ik, ws):
    a = ex.generate("ellipsoid", humanoid, ik, ws, 1.0, RATE, np.random.default_rng(5))
    b = ex.generate("ellipsoid", humanoid, ik, ws, 1.0, RATE, np.random.default_rng(5))
    c = ex.generate("ellipsoid", humanoid, ik, ws, 1.0, RATE, np.random.default_rng(6))
    np.testing.assert_array_equal(a.q_cmd, b.q_cmd)
    assert np.abs(a.q_cmd - c.q_cmd).max() > 0.01


def test_excitation_spans_a_broad_frequency_range(humanoid, ik, ws, tmp_path):
    """The paper's claim (Sec. II-A): the training excitation spans a broad band. Across a small training set
    every joint has energy both below 0.5 Hz and above 2 Hz; a single 1 Hz sine fails the same check."""
    rng = np.random.default_rng(0)
    qs = [ex.generate("ellipsoid", humanoid, ik, ws, 4.0, RATE, rng).q_cmd for _ in range(4)]
    f, psd = command_spectrum(qs, RATE)
    low, high = band_fraction(f, psd, 0.0, 0.5), band_fraction(f, psd, 2.0, RATE / 2)
    assert low.min() > 0.03 and high.min() > 0.005, (low.round(3), high.round(3))
    assert low.mean() > 0.1 and high.mean() > 0.1
    leg = ik.dofs  # the eq. 2 part alone
    assert high[leg].mean() > 0.1 and low[leg].mean() > 0.1
    t = np.arange(2000) / RATE
    f1, p1 = command_spectrum(np.sin(2 * np.pi * 1.0 * t)[:, None] * np.ones((1, 3)), RATE)
    assert band_fraction(f1, p1, 0.0, 0.5).max() < 0.01 and band_fraction(f1, p1, 2.0, RATE / 2).max() < 0.01
    png = tmp_path / "spectrum.png"
    plot_spectrum({"train": qs}, RATE, png, humanoid.joint_names)
    assert png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


_FINGER_URDF = """<robot name="gripper">
  <link name="base"><inertial><mass value="1"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="arm"><inertial><origin xyz="0.1 0 0"/><mass value="1"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="finger"><inertial><mass value="0.02"/>
    <inertia ixx="1e-5" iyy="1e-5" izz="1e-5" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="20" velocity="2"/></joint>
  <joint name="finger_joint" type="prismatic"><parent link="arm"/><child link="finger"/><origin xyz="0.2 0 0"/>
    <axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="20" velocity="0.2"/></joint>
</robot>
"""


@pytest.mark.parametrize("family", ["multisine", "chirp", "steps"])
def test_a_joint_narrower_than_the_margin_still_moves(tmp_path, family):
    """A Panda-like finger (0.04 m of travel) is narrower than twice the 0.05 limit margin: its margin shrinks to a
    quarter of its range, so every joint-space family still draws inside the limits and moves it."""
    from wresdyn.data.joint_excitation import generate_joint
    from wresdyn.data.signals import ExcitationConfig, limit_margin
    from wresdyn.robot.description import load_robot

    assert limit_margin(0.0, 0.04, 0.05) == pytest.approx(0.01)
    assert limit_margin(-1.0, 1.0, 0.05) == pytest.approx(0.05)
    (tmp_path / "g.urdf").write_text(_FINGER_URDF)
    robot = load_robot(tmp_path / "g.urdf", gains={"joint": [{"match": "*", "kp": 50.0, "kd": 2.0}]})
    e = generate_joint(family, robot, 2.0, 100.0, np.random.default_rng(0), ExcitationConfig())
    finger = e.q_cmd[:, robot.joint_names.index("finger_joint")]
    assert finger.min() >= 0.005 and finger.max() <= 0.035  # inside the halved margin (0.01 / 2)
    assert np.ptp(finger) > 1e-3
