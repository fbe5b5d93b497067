"""The ``mujoco.sysid`` adapter of the peer benchmark (``benchmarks/peers/peer_adapter.py``) at tiny size: the peer's
model of the robot is the nominal MuJoCo model, its pseudo-inertia writer round-trips every link, the control history
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
    spec = importlib.util.spec_from_file_location("peer_adapter", BENCH / "peers" / "peer_adapter.py")
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


# --- the fight on the humanoid (benchmarks/peers/humanoid.py) --------------------------------------------------------

@pytest.fixture(scope="module")
def fight(peer):
    spec = importlib.util.spec_from_file_location("peers_humanoid", BENCH / "peers" / "humanoid.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("length,horizon", [(2000, 250), (2001, 250), (2010, 250), (7, None), (100, 40)])
def test_tiles_cover_every_sample_once(peer, length, horizon):
    """The windows are consecutive, cover ``range(length)`` exactly once, and none is a lone sample (a window's first
    sample is its start state: a one-sample window would carry no residual)."""
    tiles = peer.tiles(length, horizon)
    covered = np.concatenate([np.arange(s, e) for s, e in tiles])
    np.testing.assert_array_equal(covered, np.arange(length))
    assert all(e - s >= 2 for s, e in tiles)
    assert all(e - s <= (horizon or length) + 1 for s, e in tiles)


def test_tiled_sequences_at_the_real_step(peer, humanoid, data):
    """At the real robot's 1 ms step each window's measured samples are the trajectory's, in order, every training
    sample in exactly one window, and its controls are the recorded commands each held for two model steps."""
    spec = peer.peer_spec(humanoid, data.rate_hz, 0.001)
    train = data.split("train")
    ms = peer.tiled_sequences(spec, train, data.rate_hz, 40)
    got = np.vstack([s.sensordata.data for s in ms.measured_rollout])
    want = np.vstack([np.hstack([t.q, t.qd]) for t in train])
    np.testing.assert_array_equal(got, want)
    first = ms.measured_rollout[0]
    np.testing.assert_array_equal(first.control.data[::2], train[0].q_cmd[:40])
    np.testing.assert_array_equal(first.control.data[1::2], train[0].q_cmd[:40])


def test_delay_at_the_real_step(peer, humanoid, data):
    """At a 1 ms model step a 4 ms actuator delay replays the command shifted by two 2 ms samples."""
    t = data.split("train")[0]
    spec = peer.peer_spec(humanoid, data.rate_hz, 0.001)
    for a in spec.actuators:
        a.delay = 0.004
    delayed = peer.replay(spec.compile(), [t], 1, data.rate_hz)
    shifted = type(t)(t.name, t.split, t.t, t.q, t.qd, t.qdd, np.vstack([t.q_cmd[:1], t.q_cmd[:1], t.q_cmd[:-2]]))
    plain = peer.replay(peer.peer_spec(humanoid, data.rate_hz, 0.001).compile(), [shifted], 1, data.rate_hz)
    np.testing.assert_allclose(delayed.q[0], plain.q[0], atol=1e-9)


TINY = ["--threads", "1", "--horizon", "40", "--stages", "damping", "delay", "--max-iters", "2"]
"""Two stages of 21 parameters, two Gauss-Newton iterations each at most: the whole run in a few seconds."""
RESUMED = 1e-4
"""Relative agreement of a resumed run's parameters with an uninterrupted run's: the backend restarts its regulariser
at 0 on resume, where the uninterrupted run may have raised it after a rejected step (measured: stage 1 equal, stage
2 within 2e-6)."""


def test_peer_resumes_and_refuses_a_changed_config(fight, data, tmp_path, capsys):
    """Stopped after every iteration (``--max-seconds 0``) and resumed until done, the peer leg walks the same
    stages and iterations as an uninterrupted run, to the same parameters up to :data:`RESUMED`; a resume with
    another horizon is refused in one line."""
    import json

    path = str(tmp_path / "tiny.npz")
    data.save(path)
    fight.main(["peer", path, "--out", str(tmp_path / "whole"), *TINY])
    whole = json.loads((tmp_path / "whole" / "peer" / "checkpoint.json").read_text())
    assert whole["done"] and len(whole["stops"]) == 2
    calls = 0
    while True:
        calls += 1
        fight.main(["peer", path, "--out", str(tmp_path / "parts"), *TINY, "--max-seconds", "0", "--resume"])
        parts = json.loads((tmp_path / "parts" / "peer" / "checkpoint.json").read_text())
        if parts["done"] or calls > 10:
            break
    assert parts["done"] and calls > 2
    assert [c["iteration"] for c in parts["curve"]] == [c["iteration"] for c in whole["curve"]]
    assert [c["stage"] for c in parts["curve"]] == [c["stage"] for c in whole["curve"]]
    assert [s["stop"] for s in parts["stops"]] == [s["stop"] for s in whole["stops"]]
    for got, want in zip(parts["returned"], whole["returned"]):
        np.testing.assert_allclose(got, want, rtol=RESUMED)
    assert (tmp_path / "parts" / "peer" / "final.json").exists()

    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        fight.main(["peer", path, "--out", str(tmp_path / "parts"), *TINY[:2], "--horizon", "30", *TINY[4:],
                    "--resume"])
    message = str(e.value.code)
    assert message.startswith("error:") and "horizon" in message and "\n" not in message
