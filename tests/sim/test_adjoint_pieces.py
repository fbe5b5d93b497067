"""SolverReplay's adjoint as a chain of kernels (:mod:`wresdyn.sim.solver_replay.split`) gives the one kernel's
gradients: through the fused rollout and the per-step tape, with the friction solve (a gated region cut into pieces
of its own) on, in one and in two CPU threads; and the choice of pieces is validated.

The humanoid's chain (12 pieces) is checked against its one kernel by ``benchmarks/speed/adjoint_pieces.py check`` on the
CPU and on a GPU (``benchmarks/results/first_fit/h100_pieces/``): its Clang compile is too slow for the suite.
"""

import os
from types import SimpleNamespace

import numpy as np
import pytest
import warp as wp
from test_solver_replay import TRI_URDF, rollout_tape, step_tape

from wresdyn.robot.description import load_robot
from wresdyn.sim.solver_replay import SolverReplay
from wresdyn.sim.solver_replay.kernels import choose_pieces, compile_in_processes, load_kernels

T, W = 8, 3
PARAMS = ("body_mass", "body_com", "body_inertia", "joint_friction", "joint_armature", "joint_target_ke",
          "joint_target_kd", "joint_damping")


@pytest.fixture(scope="module")
def tri_friction(tmp_path_factory):
    path = tmp_path_factory.mktemp("tri") / "tri.urdf"
    path.write_text(TRI_URDF)
    gains = {"joint": [{"match": "*", "kp": 30.0, "kd": 1.0, "armature": 0.01, "friction": 0.3}]}
    return load_robot(path, gains=gains)


def gradients(robot, pieces, threads=1, stepped=False, friction_grad=True):
    """The end state and the gradients of a random loss on it, through T steps of W worlds."""
    model = robot.build_model(W, "cpu", requires_grad=True)
    solver = SolverReplay(model, adjoint_pieces=pieces, threads=threads, friction_grad=friction_grad)
    n = solver.tree.dofs_per_world
    rng = np.random.default_rng(3)
    q0, tq, jf = rng.uniform(-0.3, 0.3, (W, n)), rng.uniform(-0.3, 0.3, (T, W, n)), rng.normal(size=(T, W, n))
    seed = rng.normal(size=(W, n)).astype(np.float32)
    if stepped:
        states, controls, tape = step_tape(solver, q0, tq, jf)
        tape.backward(grads={states[T].joint_q: wp.array(seed.ravel())})
        out = {"q": states[T].joint_q.numpy(), "q0": states[0].joint_q.grad.numpy(),
               "jf": np.stack([c.joint_f.grad.numpy() for c in controls])}
    else:
        q, qd, tqa, jfa, tape = rollout_tape(solver, q0, tq, jf)
        full = np.zeros((T + 1, W, n), np.float32)
        full[T] = seed
        tape.backward(grads={q: wp.array(full)})
        out = {"q": q.numpy()[T], "q0": q.grad.numpy()[0], "qd0": qd.grad.numpy()[0], "tq": tqa.grad.numpy(),
               "jf": jfa.grad.numpy()}
    servo = () if solver.servo is None else ("joint_servo_deadband", "joint_servo_noload_speed",
                                             "joint_servo_stiction")
    out.update({p: getattr(model, p).grad.numpy() for p in (*PARAMS, *servo)})
    return {k: v.copy() for k, v in out.items()}, solver


@pytest.fixture(scope="module")
def tri_servo(tmp_path_factory):
    """Two of three joints servo drives (dead band, torque-speed line, stiction), dry friction on all."""
    from test_servo import make_robot

    return make_robot(tmp_path_factory.mktemp("servo"), joints="[ss]*", stiction=0.4)


@pytest.mark.parametrize("stepped", [False, True], ids=["rollout", "step"])
@pytest.mark.parametrize("which", ["tri_friction", "tri_servo"])
def test_pieces_give_the_one_kernels_gradients(which, stepped, request):
    robot = request.getfixturevalue(which)
    ref, one = gradients(robot, 0, stepped=stepped)
    got, chain = gradients(robot, 5, stepped=stepped)
    assert one.adjoint_pieces == 0 and chain.adjoint_pieces == 5
    assert len(chain.kernels.PIECES) >= 8  # the friction sweeps are pieces of their own: the gate is cut too
    assert np.array_equal(got["q"], ref["q"])  # the forward is the one step kernel either way
    for k, v in ref.items():
        assert np.abs(v).max() > 0.0, k
        # float32: the pieces round at their boundaries where the one kernel may fuse (measured <= 1e-7 relative)
        assert np.allclose(got[k], v, rtol=1e-5, atol=1e-6 * np.abs(v).max()), k


def test_pieces_split_over_threads_agree(tri_friction):
    one, _ = gradients(tri_friction, 5)
    two, _ = gradients(tri_friction, 5, threads=2)
    for k, v in one.items():
        assert np.array_equal(two[k], v), k


def test_piece_choice_is_validated(tri_friction, monkeypatch):
    model = tri_friction.build_model(1, "cpu", requires_grad=True)
    with pytest.raises(ValueError, match="adjoint_pieces"):
        SolverReplay(model, adjoint_pieces=-1)
    solver = SolverReplay(model)
    assert solver.adjoint_pieces == 0  # the CPU default: one kernel
    cpu = wp.get_device("cpu")
    args = (solver.tree, "float32", True, cpu, solver.friction_sweeps, None, None)
    monkeypatch.setenv("WRESDYN_ADJOINT_PIECES", "7")
    assert choose_pieces(*args) == (7, None)
    assert SolverReplay(model).adjoint_pieces == 7
    assert choose_pieces(*args[:2], False, *args[3:]) == (0, None)  # no adjoint, no pieces
    for bad in ("many", "-3"):
        monkeypatch.setenv("WRESDYN_ADJOINT_PIECES", bad)
        with pytest.raises(ValueError, match="WRESDYN_ADJOINT_PIECES"):
            SolverReplay(model)


def test_cuda_block_size_is_built_into_the_modules(tri_friction, monkeypatch):
    """The CUDA modules are built for the block size the solver launches them with (Warp compiles a module per block
    size and launches at 256 unless told), one module per size; the CPU source has none; bad overrides are refused."""
    from wresdyn.sim.solver_replay import kernels as km

    solver = SolverReplay(tri_friction.build_model(1, "cpu", requires_grad=True))
    args = (solver.tree, "float32", True, True, solver.friction_sweeps, None, 0)
    cuda = load_kernels(*args)
    assert cuda.BLOCK_DIM == km.BLOCK_DIM == cuda.replay_step.module.options["block_dim"]
    cpu = load_kernels(*args[:3], False, *args[4:])
    assert cpu.KERNEL["module_options"] is None and cpu.BLOCK_DIM is None  # a CPU launch: Warp's one thread a block
    monkeypatch.setenv("WRESDYN_REPLAY_BLOCK_DIM", "64")
    wide = load_kernels(*args)
    assert wide.BLOCK_DIM == 64 == wide.replay_step.module.options["block_dim"]
    assert wide.replay_step.module.get_module_identifier() != cuda.replay_step.module.get_module_identifier()
    monkeypatch.setenv("WRESDYN_REPLAY_FAST_MATH", "1")
    assert load_kernels(*args).replay_step.module.options["fast_math"] is True
    monkeypatch.delenv("WRESDYN_REPLAY_FAST_MATH")
    for name, bad in (("WRESDYN_REPLAY_BLOCK_DIM", "0"), ("WRESDYN_REPLAY_BLOCK_DIM", "big"),
                      ("WRESDYN_REPLAY_SMEM_SPILL", "yes"), ("WRESDYN_REPLAY_FAST_MATH", "2")):
        monkeypatch.setenv(name, bad)
        with pytest.raises(ValueError, match=name):
            load_kernels(*args)
        monkeypatch.delenv(name)


def test_worker_processes_fill_the_cache_this_process_reads(tri_friction, tmp_path, monkeypatch):
    """The compile workers (NVRTC on the CPU, no GPU) write each module where this process's Warp looks for it: the
    module hash a worker computes from the generated file is this process's."""
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path))
    solver = SolverReplay(tri_friction.build_model(1, "cpu", requires_grad=True))
    kernels = load_kernels(solver.tree, "float32", True, True, solver.friction_sweeps, None, 5)
    mods = [k.module for k in kernels.PIECES[:2]]
    compile_in_processes(mods, 90, ptx=False)
    for m in mods:
        name = m.get_module_identifier()
        assert (tmp_path / name / f"{name}.sm90.cubin").stat().st_size > 0, name


def test_background_compile_is_a_detached_worker(tri_friction, tmp_path, monkeypatch):
    """The one-kernel adjoint compiles for the next run in a worker process of its own session (a command neither
    waits for it at exit nor takes it down), into the cache this process reads."""
    from wresdyn.sim.solver_replay import kernels as km

    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path))
    monkeypatch.setattr(km, "_ptx", lambda module, device: False)  # Warp's CUBIN naming, as for sm_90 on a GPU
    solver = SolverReplay(tri_friction.build_model(1, "cpu", requires_grad=True))
    module = load_kernels(solver.tree, "float32", True, True, solver.friction_sweeps, None, 0).replay_step.module
    key = module.get_module_identifier()
    km._compile_later(module, SimpleNamespace(arch=90, is_cuda=True))
    worker = km._BACKGROUND.pop(key)
    assert os.getsid(worker.pid) == worker.pid != os.getsid(0)
    assert worker.wait(timeout=300) == 0
    assert (tmp_path / key / f"{key}.sm90.cubin").stat().st_size > 0
