"""The ``mujoco.sysid`` adapter of the peer benchmark (``benchmarks/peer_adapter.py``) at tiny size: the peer's model
of the robot is the nominal MuJoCo model, its pseudo-inertia writer round-trips every link, the control history
carries the delay, and the peer's own Gauss-Newton recovers a joint damping it can identify."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

if not hasattr(pytest.importorskip("mujoco.sysid"), "optimize"):  # its imports need the extra's packages
    pytest.skip("mujoco[sysid] extra not installed (pip install -e '.[bench]')", allow_module_level=True)

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
EXACT = 1e-12
"""Round trips of the same numbers through the compiler [SI]: float64 noise only."""


@pytest.fixture(scope="module")
def peer():
    spec = importlib.util.spec_from_file_location("peer_adapter", BENCH / "peer_adapter.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["peer_adapter"] = module
    spec.loader.exec_module(module)
    return module


def test_inertia_round_trip_and_nominal_replay(peer, humanoid, data):
    """At its start (the file's values) every link's pseudo-inertia written by the peer compiles back to the same
    mass, centre of mass and inertia, so does every field written by ``with_params``, and the peer's replay with
    zero delay is the nominal MuJoCo replay."""
    from mujoco import sysid

    from wresdyn.robot.mujoco_model import build_mujoco, mujoco_replay

    spec = peer.peer_spec(humanoid, data.rate_hz)
    params = peer.peer_parameters(spec, humanoid, ("bodies",))
    for p in params.values():
        p.value = p.nominal.copy()
    got = peer.physical_params(sysid.apply_param_modifiers(params, spec), humanoid)
    want = peer.physical_params(build_mujoco(humanoid, 1.0 / data.rate_hz), humanoid)
    for f in ("body_mass", "body_com", "body_inertia"):
        np.testing.assert_allclose(getattr(got, f), getattr(want, f), atol=EXACT, err_msg=f)
    written = peer.physical_params(peer.with_params(peer.peer_spec(humanoid, data.rate_hz), want), humanoid)
    for f in ("kp", "kd", "armature", "damping", "friction", "effort", "delay", "body_mass", "body_com",
              "body_inertia"):
        np.testing.assert_allclose(getattr(written, f), getattr(want, f), atol=EXACT, err_msg=f)
    t = data.split("train")[0]
    q, qd = mujoco_replay(build_mujoco(humanoid, 1.0 / data.rate_hz), t.q_cmd[:-1], t.q[0], t.qd[0])
    run = peer.replay(spec.compile(), [t], threads=1)
    np.testing.assert_allclose(run.q[0], q, atol=EXACT)
    np.testing.assert_allclose(run.qd[0], qd, atol=EXACT)


def test_delay_is_the_command_shifted(peer, humanoid, data):
    """A delay of two sample periods replays the command shifted by two samples (the first held before)."""
    t = data.split("train")[0]
    spec = peer.peer_spec(humanoid, data.rate_hz)
    for a in spec.actuators:
        a.delay = 2.0 / data.rate_hz
    delayed = peer.replay(spec.compile(), [t], threads=1)
    shifted = type(t)(t.name, t.split, t.t, t.q, t.qd, t.qdd, np.vstack([t.q_cmd[:1], t.q_cmd[:1], t.q_cmd[:-2]]))
    plain = peer.replay(peer.peer_spec(humanoid, data.rate_hz).compile(), [shifted], threads=1)
    np.testing.assert_allclose(delayed.q[0], plain.q[0], atol=1e-9)


def test_peer_recovers_damping(peer, cartpole, record):
    """The peer's Gauss-Newton, started from the file's zero damping, finds the damping the "real" cartpole has
    (half its kd, every joint) to 1 %: the recording is noise-free and stepped as the peer steps, so the damping
    is exactly representable and the finite-difference Jacobian sees it."""
    from wresdyn.data.real_robot import Mismatch

    ds = record(cartpole, Mismatch(damping=0.5), {"train": 2}, seconds=0.5)
    run = peer.identify_peer(cartpole, ds.split("train"), ds.rate_hz, fields=("damping",), horizon=None,
                             max_iters=20, threads=1, log=lambda s: None)
    found = peer.physical_params(run.model(run.best()[1]), cartpole).damping
    np.testing.assert_allclose(found, 0.5 * cartpole.kd, rtol=0.01)
    assert run.best()[2] < 1e-3 * run.evaluations[0][2]
