"""The simulator's physical parameters as fitted quantities (:mod:`wresdyn.sim.physics`): the log-Cholesky
parametrisation, the JSON file, the real robot's true values, and gradients to the model's own arrays through
:meth:`Simulator.step_diff` against central finite differences."""

import numpy as np
import pytest
import torch

from conftest import check_directional_gradients
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.sim import Simulator, TrajectoryBank
from wresdyn.sim.physics import PhysicalParams, PhysicsError, PhysicsModel, pseudo_inertia

DT = 0.002


def test_start_values_are_reproduced_exactly(humanoid):
    """At u = start, the module returns the start values (the Cholesky round trip is exact to float64)."""
    start = PhysicalParams.nominal(humanoid)
    v = PhysicsModel(humanoid, start).values()
    for f in ("kp", "kd", "armature", "damping", "friction", "effort", "body_mass", "body_com", "body_inertia"):
        np.testing.assert_allclose(getattr(v, f), getattr(start, f), rtol=1e-9, atol=1e-12, err_msg=f)


def test_any_coordinates_give_a_physical_body(humanoid):
    """Random coordinates: positive masses, positive-definite inertias obeying the triangle inequalities."""
    model = PhysicsModel(humanoid)
    with torch.no_grad():
        model.u_body_logdiag.add_(torch.randn_like(model.u_body_logdiag))
        model.u_body_off.add_(0.3 * torch.randn_like(model.u_body_off))
    v = model.values()
    moving = model.moving.numpy()
    assert (v.body_mass[moving] > 0).all()
    eig = np.linalg.eigvalsh(v.body_inertia[moving])
    assert (eig > 0).all()
    assert (eig[:, 0] + eig[:, 1] >= eig[:, 2] * (1 - 1e-9)).all()  # triangle inequality of principal moments
    j = pseudo_inertia(v.body_mass[moving], v.body_com[moving], v.body_inertia[moving])
    ev = np.linalg.eigvalsh(j)  # positive definite up to round-off of the J -> (m, c, I) -> J round trip
    assert (ev[:, 0] > -1e-9 * ev[:, -1]).all()


def test_json_round_trip_and_bad_files(humanoid, tmp_path):
    p = PhysicsModel(humanoid).values()
    p.effort[0] = np.inf
    p.save(tmp_path / "p.json")
    q = PhysicalParams.load(tmp_path / "p.json", humanoid)
    assert q.effort[0] == np.inf and np.array_equal(q.body_inertia, p.body_inertia)
    with pytest.raises(PhysicsError, match="not found"):
        PhysicalParams.load(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(PhysicsError, match="malformed"):
        PhysicalParams.load(tmp_path / "bad.json")
    d = p.to_json()
    d["joint_names"] = d["joint_names"][::-1]
    (tmp_path / "names.json").write_text(__import__("json").dumps(d))
    with pytest.raises(PhysicsError, match="joint names"):
        PhysicalParams.load(tmp_path / "names.json", humanoid)


def test_the_mean_of_parameters_is_each_field_s_mean_and_stays_physical(humanoid):
    """An ensemble's model: the mean of one set is that set bit for bit; of two, each field's midpoint (an
    unlimited effort stays unlimited), which passes the robot's checks as both sets do."""
    a = PhysicsModel(humanoid).values()
    a.effort[0] = np.inf
    b = a.copy()
    b.kp, b.body_mass, b.stiction = 2.0 * a.kp, 3.0 * a.body_mass, a.stiction + 0.1
    b.body_inertia = 0.5 * a.body_inertia
    one = PhysicalParams.mean([a])
    assert all(np.array_equal(getattr(one, f), getattr(a, f)) for f in ("kp", "effort", "body_inertia", "stiction"))
    two = PhysicalParams.mean([a, b])
    np.testing.assert_allclose(two.kp, 1.5 * a.kp)
    np.testing.assert_allclose(two.body_mass, 2.0 * a.body_mass)
    np.testing.assert_allclose(two.body_inertia, 0.75 * a.body_inertia)
    np.testing.assert_allclose(two.stiction, a.stiction + 0.05)
    assert two.effort[0] == np.inf
    two.check(humanoid)
    other = a.copy()
    other.joint_names = other.joint_names[::-1]
    with pytest.raises(PhysicsError, match="different robots"):
        PhysicalParams.mean([a, other])


def test_real_robot_truth_is_the_mujoco_model(humanoid):
    """The true parameters read back from the perturbed MuJoCo model: nominal when the mismatch is off, the
    configured scales when on."""
    nominal = RealRobot(humanoid, Mismatch()).physics()
    ref = PhysicalParams.nominal(humanoid)
    for f in ("kp", "kd", "armature", "friction", "effort", "body_mass", "body_com", "body_inertia"):
        np.testing.assert_allclose(getattr(nominal, f), getattr(ref, f), rtol=1e-6, atol=1e-9, err_msg=f)
    mm = Mismatch(kp_scale=0.75, damping=0.5, friction=0.1, torque_limit_scale=0.2, delay=0.006, substep=0.001)
    t = RealRobot(humanoid, mm).physics()
    np.testing.assert_allclose(t.kp, 0.75 * humanoid.kp)
    np.testing.assert_allclose(t.damping, 0.5 * humanoid.kd)
    np.testing.assert_allclose(t.friction, 0.1 * humanoid.effort)
    np.testing.assert_allclose(t.effort, 0.2 * humanoid.effort)
    np.testing.assert_allclose(t.delay, 0.006)


EPS = 1e-2
"""Finite-difference step in the module's coordinates (1 % for the exp fields, 0.01 reference units for the
linear ones): the loss is O(100) in float32 (ulp 1e-5), so a 1e-3 step left the difference quantised to ~1/6
of these gradients; at 1e-2 round-off is ~2 % of the smallest and the truncation error O(eps²) below it."""


def test_parameter_gradients_match_finite_differences(humanoid):
    """d loss / d coordinates of every field through 4 SolverReplay steps of the humanoid, with friction,
    damping, a saturating drive and a fractional delay all active: directional derivatives per field."""
    start = PhysicalParams.nominal(humanoid)
    start.friction = 0.02 * humanoid.effort
    start.damping = 0.3 * humanoid.kd
    start.effort = 0.32 * humanoid.effort  # no drive exactly at its limit (the loss jumps there: the FD would see it)
    start.delay[:] = 1.4 * DT
    model = PhysicsModel(humanoid, start, dt=DT)
    b, h = 2, 4
    sim = Simulator(humanoid, b, DT, solver="replay", requires_grad=True, param_grads=True)
    rng = np.random.default_rng(0)
    t_len = 12
    traj = []
    for i in range(b):
        cmd = humanoid.q0 + 0.4 * np.sin(np.linspace(0, 3, t_len))[:, None] * rng.uniform(-1, 1, humanoid.n_dof)
        traj.append(type("T", (), {"q": cmd + 0.01, "qd": np.zeros_like(cmd), "qdd": np.zeros_like(cmd),
                                   "q_cmd": cmd})())
    q_ref = torch.as_tensor(rng.uniform(-0.2, 0.2, (b, h, humanoid.n_dof)), dtype=torch.float32)

    def loss():
        bank = TrajectoryBank(traj, sim.device, delay=model.delay_steps().float())
        w = bank.window(torch.arange(b), torch.full((b,), 6), h)
        sim.set_physics(model())
        q, qd, total = w.q[:, 0], w.qd[:, 0] + 0.5, 0.0
        for k in range(h):
            q, qd = sim.step_diff(k, q, qd, w.target[:, k])
            total = total + ((q - q_ref[:, k]) ** 2).sum() + 0.01 * (qd ** 2).sum()
        return total

    params = {k: p for k, p in model.named_parameters() if p.requires_grad}  # the servo fields are not fitted here
    model.zero_grad()
    loss().backward()
    check_directional_gradients(loss, params, {k: p.grad.clone() for k, p in params.items()}, eps=EPS)


def test_per_world_physics_replay_as_each_world_set_alone(humanoid):
    """Simulator.set_world_physics: world 1 with other gains and link masses steps as a simulator given those values
    for every world (set_physics), and world 0 as the file's."""
    nominal = PhysicalParams.nominal(humanoid)
    other = nominal.copy()
    other.kp = 0.7 * nominal.kp
    other.body_mass = 1.3 * nominal.body_mass
    fields = ("kp", "body_mass")
    per_world = {f: torch.as_tensor(np.stack([getattr(nominal, f), getattr(other, f)])) for f in fields}
    q0 = torch.zeros(2, humanoid.n_dof)
    target = torch.full((2, humanoid.n_dof), 0.2)

    def run(sim):
        sim.set_state(None, q0, q0)
        for _ in range(20):
            q, _ = sim.step(target)
        return q

    both = Simulator(humanoid, 2, 0.002)
    both.set_world_physics(per_world)
    mixed = run(both)
    for w, params in enumerate((nominal, other)):
        alone = Simulator(humanoid, 2, 0.002)
        alone.set_physics(params)
        assert torch.equal(mixed[w], run(alone)[w])
    assert not torch.equal(mixed[0], mixed[1])
    with pytest.raises(ValueError, match="worlds"):
        both.set_world_physics({"kp": per_world["kp"][:1]})


def test_shared_delay_is_one_delay_with_one_gradient(humanoid):
    """``shared_delay``: every joint reads the mean coordinate, so the joints' gradients are equal and Adam moves them
    together; without it each joint keeps its own."""
    start = PhysicalParams.nominal(humanoid)
    start.delay = np.linspace(0.0, 0.006, humanoid.n_dof)
    model = PhysicsModel(humanoid, start, dt=DT, shared_delay=True)
    np.testing.assert_allclose(model.values().delay, np.full(humanoid.n_dof, start.delay.mean()), rtol=1e-12)
    weights = torch.arange(humanoid.n_dof, dtype=torch.float64)
    (model.delay_steps() * weights).sum().backward()
    grad = model.u_delay.grad
    assert torch.allclose(grad, grad[0].expand_as(grad)) and float(grad[0]) > 0
    apart = PhysicsModel(humanoid, start, dt=DT)
    np.testing.assert_allclose(apart.values().delay, start.delay, rtol=1e-12)
