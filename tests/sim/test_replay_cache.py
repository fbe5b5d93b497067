"""SolverReplay's generated-kernel cache: in the user cache folder only, and never runs a file it did not write.

Generated kernel modules are written to :func:`wresdyn.sim.solver_replay.kernel_dir` as ``replay_<hash>.py``, the
hash being the SHA-256 of the generated source; Warp needs the file to read the kernels' source.
"""

import hashlib

import numpy as np
import pytest
from test_solver_replay import TRI_URDF

from wresdyn.robot.description import load_robot
from wresdyn.sim.solver_replay import KernelCacheError, SolverReplay, kernel_dir
from wresdyn.sim.solver_replay import cache as kernel_cache

DT = 0.002


def test_kernel_dir_is_the_user_cache(monkeypatch, tmp_path):
    monkeypatch.delenv("WRESDYN_KERNEL_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert kernel_dir() == tmp_path / "xdg" / "wresdyn" / "kernels"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/ignored")  # the XDG spec ignores relative paths
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert kernel_dir() == tmp_path / "home" / ".cache" / "wresdyn" / "kernels"
    monkeypatch.setenv("WRESDYN_KERNEL_DIR", str(tmp_path / "override"))
    assert kernel_dir() == tmp_path / "override"


def test_unwritable_kernel_dir_is_a_one_line_error(monkeypatch, tmp_path):
    """No fallback to a shared temporary folder: the user is told which folder and how to choose another."""
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv("WRESDYN_KERNEL_DIR", str(blocker / "kernels"))  # no folder can be made under a file
    with pytest.raises(KernelCacheError) as err:
        kernel_dir()
    assert "\n" not in str(err.value) and "WRESDYN_KERNEL_DIR" in str(err.value)


def test_tampered_kernel_file_is_rewritten_not_run(monkeypatch, tmp_path):
    monkeypatch.setenv("WRESDYN_KERNEL_DIR", str(tmp_path))
    monkeypatch.setattr(kernel_cache, "_MODULES", {})  # as in a new process
    urdf = tmp_path / "tri.urdf"
    urdf.write_text(TRI_URDF)
    robot = load_robot(urdf, gains={"joint": [{"match": "*", "kp": 30.0, "kd": 1.0, "armature": 0.01}]})

    def one_step():
        model = robot.build_model(1, "cpu")
        solver = SolverReplay(model)
        state, out = model.state(), model.state()
        state.joint_q.assign(np.array([0.3, -0.4, 0.05], np.float32))
        solver.step(state, out, None, None, DT)
        return out.joint_qd.numpy()

    expected = one_step()
    files = list(tmp_path.glob("replay_*.py"))
    assert len(files) == 1
    src = files[0].read_bytes()
    assert hashlib.sha256(src).hexdigest()[:20] == files[0].stem.removeprefix("replay_")
    # an edit that keeps the name (stale or malicious): gravity flipped
    files[0].write_bytes(src.replace(b"gz = g[2]", b"gz = -g[2]"))
    monkeypatch.setattr(kernel_cache, "_MODULES", {})
    again = one_step()
    assert files[0].read_bytes() == src, "the tampered file must be rewritten"
    assert np.array_equal(again, expected), "the generated code must run, not the tampered file"
