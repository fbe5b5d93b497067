"""SolverReplay's branches in threads of their own (:func:`wresdyn.sim.solver_replay.codegen._lanes`): a robot's
subtrees hanging from the fixed base step in one thread each, forward and adjoint, with the one thread's results
bit for bit, and gradients that match central differences.

The kernels run on the CPU here (``$WRESDYN_REPLAY_LANES=1``), the same generated code a GPU runs; their speed is
measured on a GPU (``benchmarks/results/speed_paths/lanes/``).
"""

import numpy as np
import pytest
import warp as wp
from test_adjoint_pieces import W, gradients
from test_solver_replay import DT

from wresdyn.robot.description import load_robot
from wresdyn.sim.solver_replay import SolverReplay, TreeError
from wresdyn.sim.solver_replay import launch as launch_module
from wresdyn.sim.solver_replay.kernels import branch_lanes, lane_width, load_kernels

_LINK = ('<link name="{}"><inertial><origin xyz="{} 0.01 -0.1" rpy="0.1 0.0 0.2"/><mass value="{}"/>'
         '<inertia ixx="0.004" iyy="0.005" izz="0.002" ixy="0.0003" ixz="0.0" iyz="0.0002"/></inertial></link>')
_JOINT = ('<joint name="{}" type="{}"><parent link="{}"/><child link="{}"/><origin xyz="{}" rpy="{}"/>'
          '<axis xyz="{}"/><limit lower="-2.0" upper="2.0" effort="30.0" velocity="20.0"/></joint>')
FORK_URDF = "\n".join([
    '<?xml version="1.0"?>', '<robot name="fork">',
    '<link name="base"><inertial><mass value="3.0"/><inertia ixx="0.03" iyy="0.03" izz="0.03" ixy="0" ixz="0" '
    'iyz="0"/></inertial></link>',
    *(_LINK.format(name, x, m) for name, x, m in (("l1", 0.02, 1.1), ("l2", 0.0, 0.7), ("r1", -0.01, 0.9),
                                                   ("r2", 0.03, 0.4), ("t1", 0.0, 2.0), ("ta", 0.02, 0.5),
                                                   ("tb", -0.02, 0.6))),
    _JOINT.format("left", "revolute", "base", "l1", "0 0.2 1.0", "0 0 0.3", "0 1 0"),
    _JOINT.format("left_knee", "revolute", "l1", "l2", "0 0.05 -0.3", "0.2 0 0", "0.6 0 0.8"),
    _JOINT.format("right", "revolute", "base", "r1", "0 -0.2 1.0", "0.1 0 0", "1 0 0"),
    _JOINT.format("right_slide", "prismatic", "r1", "r2", "0.1 0 -0.1", "0 0.3 0", "0 0 1"),
    _JOINT.format("waist", "revolute", "base", "t1", "0 0 1.2", "0 0 0", "0 0 1"),
    _JOINT.format("arm_a", "revolute", "t1", "ta", "0 0.15 0.2", "0 0 0", "0 1 0"),
    _JOINT.format("arm_b", "revolute", "t1", "tb", "0 -0.15 0.2", "0.3 0 0", "1 0 0"),
    "</robot>",
])
"""A fixed base with three branches: a revolute pair, a revolute joint carrying a prismatic one, and a waist with
two arms (a branch that branches again); skewed axes, rotated frames, a different inertia on every link."""

@pytest.fixture(scope="module")
def fork(tmp_path_factory):
    """Dry friction on two branches, none on the right one (its friction solve is the one thread's choice, not the
    branch's), servo drives on the left pair."""
    path = tmp_path_factory.mktemp("fork") / "fork.urdf"
    path.write_text(FORK_URDF)
    gains = {"joint": [{"match": "*", "kp": 30.0, "kd": 1.0, "armature": 0.01, "damping": 0.1, "friction": 0.3},
                       {"match": "right*", "friction": 0.0},
                       {"match": "left*", "drive": "servo", "deadband": 0.02, "noload_speed": 10.0}]}
    return load_robot(path, gains=gains)


def test_branches_of_the_base(fork, humanoid):
    tree = SolverReplay(fork.build_model(1, "cpu")).tree
    assert tree.branches() == [[0, 1], [2, 3], [4, 5, 6]]
    arms = tree.restrict([4, 5, 6])
    assert arms.parent.tolist() == [-1, 0, 0] and arms.qd_offset.tolist() == [4, 5, 6]
    assert sorted(set(arms.body_dof.tolist())) == [-1, 0, 1, 2]  # the other branches' bodies do not move
    with pytest.raises(TreeError, match="whole subtrees"):
        tree.restrict([5, 6])
    sizes = [len(b) for b in SolverReplay(humanoid.build_model(1, "cpu")).tree.branches()]
    assert sizes == [6, 6, 9]  # two legs, the waist with both arms


def run(robot, stepped, pieces=0):
    """The end state and the gradients of a random loss through T steps of W worlds (``pieces``: the adjoint's);
    friction solved only in worlds with friction, as by default."""
    return gradients(robot, pieces, stepped=stepped, friction_grad=False)


@pytest.mark.parametrize("stepped", [False, True], ids=["rollout", "step"])
def test_lanes_give_the_one_threads_results_bit_for_bit(fork, stepped, monkeypatch):
    monkeypatch.setenv("WRESDYN_REPLAY_LANES", "0")
    ref, one = run(fork, stepped)
    monkeypatch.setenv("WRESDYN_REPLAY_LANES", "1")
    got, laned = run(fork, stepped)
    assert not hasattr(one.kernels, "LANES") and laned.kernels.LANES == 3
    assert np.abs(ref["joint_friction"].reshape(W, -1)[:, 2:4]).max() > 0.0  # the frictionless branch solved
    for k, v in ref.items():
        assert np.abs(v).max() > 0.0, k
        assert np.array_equal(got[k], v), k


@pytest.mark.parametrize("stepped", [False, True], ids=["rollout", "step"])
def test_laned_pieces_give_the_laned_kernels_gradients(fork, stepped, monkeypatch):
    """The adjoint as a chain of kernels (:mod:`wresdyn.sim.solver_replay.split`), each lane cut on its own and the
    lanes' pieces aligned at the chain's end, against the one laned kernel and the one thread's chain."""
    monkeypatch.setenv("WRESDYN_REPLAY_LANES", "1")
    ref, _ = run(fork, stepped)
    got, chain = run(fork, stepped, pieces=6)
    assert chain.kernels.LANES == 3 and len(chain.kernels.PIECES) >= 6
    monkeypatch.setenv("WRESDYN_REPLAY_LANES", "0")
    one, _ = run(fork, stepped, pieces=6)
    assert np.array_equal(got["q"], ref["q"])  # the forward is the one laned step kernel either way
    for k, v in ref.items():
        scale = np.abs(v).max()
        assert scale > 0.0, k
        # float32: the pieces round at their boundaries where the one kernel may fuse, as the one thread's chain does
        # (measured on this robot: within 1.4e-5 of the largest gradient, either way; the two chains within 7e-8)
        assert np.abs(got[k] - v).max() <= 4e-5 * scale, k
        assert np.abs(got[k] - one[k]).max() <= 5e-7 * scale, k


@pytest.mark.parametrize("stepped", [False, True], ids=["rollout", "step"])
def test_threads_past_the_last_world_write_nothing(fork, stepped, monkeypatch):
    """On CUDA a branch's threads are rounded up to a warp, so that a warp runs one branch's code; the threads past a
    chunk's last world return at once. Padded on the CPU here (29 threads more per branch, in chunks of two CPU
    threads), forward, adjoint in one kernel and in pieces: the results are the unpadded ones bit for bit."""
    assert (lane_width(8, True), lane_width(32, True), lane_width(33, True), lane_width(8, False)) == (32, 32, 64, 8)
    monkeypatch.setenv("WRESDYN_REPLAY_LANES", "1")
    for pieces in (0, 6):
        ref, _ = gradients(fork, pieces, threads=2, stepped=stepped, friction_grad=False)
        with monkeypatch.context() as m:
            m.setattr(launch_module, "lane_width", lambda worlds, cuda: worlds + 29)
            got, solver = gradients(fork, pieces, threads=2, stepped=stepped, friction_grad=False)
        assert solver.kernels.LANES == 3 and len(solver._chunks()) == 2
        for k, v in ref.items():
            assert np.abs(v).max() > 0.0, k
            assert np.array_equal(got[k], v), (pieces, k)


def test_lane_gradients_match_central_differences(fork, monkeypatch):
    """d loss / d (q0, qd0, target_q, joint_f, armature) through a 10-step Tape of the laned rollout, float64."""
    monkeypatch.setenv("WRESDYN_REPLAY_LANES", "1")
    solver = SolverReplay(fork.build_model(2, "cpu", requires_grad=True), dtype=wp.float64)
    assert solver.kernels.LANES == 3
    t_len, w, n = 10, 2, solver.tree.n_dof
    rng = np.random.default_rng(0)
    inputs = {"q0": rng.uniform(-0.3, 0.3, (w, n)), "qd0": rng.normal(size=(w, n)),
              "tq": rng.normal(scale=0.3, size=(t_len, w, n)), "jf": rng.normal(scale=0.5, size=(t_len, w, n))}
    weights = rng.normal(size=(w, n))
    arm = solver.parameters["joint_armature"]
    arm0 = arm.numpy().copy()

    def arrays(q0, qd0, tq, jf, grad):
        q, qd = np.zeros((t_len + 1, w, n)), np.zeros((t_len + 1, w, n))
        q[0], qd[0] = q0, qd0
        return [wp.array(a, dtype=wp.float64, requires_grad=grad) for a in (q, qd, tq, jf)]

    def value(armature=arm0, **x):
        arm.assign(armature)
        q, qd, tqa, jfa = arrays(**x, grad=False)
        solver.rollout(q, qd, tqa, DT, joint_f=jfa)
        return float((q.numpy()[t_len] * weights).sum() + 0.1 * (qd.numpy()[t_len] * weights).sum())

    q, qd, tqa, jfa = arrays(**inputs, grad=True)
    tape = wp.Tape()
    with tape:
        solver.rollout(q, qd, tqa, DT, joint_f=jfa)
    seed_q, seed_qd = np.zeros((t_len + 1, w, n)), np.zeros((t_len + 1, w, n))
    seed_q[t_len], seed_qd[t_len] = weights, 0.1 * weights
    tape.backward(grads={q: wp.array(seed_q, dtype=wp.float64), qd: wp.array(seed_qd, dtype=wp.float64)})
    grads = {"q0": q.grad.numpy()[0], "qd0": qd.grad.numpy()[0], "tq": tqa.grad.numpy(), "jf": jfa.grad.numpy(),
             "armature": arm.grad.numpy()}
    eps = 1e-6
    for key, idx in [("q0", (0, 0)), ("q0", (1, 3)), ("q0", (0, 6)), ("qd0", (1, 5)), ("tq", (0, 0, 2)),
                     ("tq", (5, 1, 4)), ("jf", (9, 1, 6)), ("jf", (3, 0, 1)), ("armature", (5,)), ("armature", (8,))]:
        plus, minus = ({k: v.copy() for k, v in inputs.items()} | {"armature": arm0.copy()} for _ in range(2))
        plus[key][idx] += eps
        minus[key][idx] -= eps
        fd = (value(**plus) - value(**minus)) / (2 * eps)
        assert abs(grads[key][idx]) > 1e-6, (key, idx)
        # float64 central differences: truncation ~eps^2, round-off ~1e-16 / eps
        assert grads[key][idx] == pytest.approx(fd, rel=1e-6, abs=1e-9), (key, idx)


def test_lanes_by_device_and_override(fork, monkeypatch):
    """On by default on CUDA, off on the CPU, where threads run one after another; the variable overrides either, and
    a bad value is refused. A robot of one branch has no lanes to split."""
    monkeypatch.delenv("WRESDYN_REPLAY_LANES", raising=False)
    assert branch_lanes(True) and not branch_lanes(False)
    solver = SolverReplay(fork.build_model(1, "cpu", requires_grad=True))
    cuda = load_kernels(solver.tree, "float32", True, True, solver.friction_sweeps, solver.servo, 0)
    assert cuda.LANES == 3 and not hasattr(solver.kernels, "LANES")
    monkeypatch.setenv("WRESDYN_REPLAY_LANES", "0")
    assert not branch_lanes(True)
    assert not hasattr(load_kernels(solver.tree, "float32", True, True, solver.friction_sweeps, solver.servo, 0),
                       "LANES")
    monkeypatch.setenv("WRESDYN_REPLAY_LANES", "yes")
    with pytest.raises(ValueError, match="WRESDYN_REPLAY_LANES"):
        branch_lanes(True)
