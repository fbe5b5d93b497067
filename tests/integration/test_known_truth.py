"""Known-truth cases from ``mujoco.sysid``'s own tests, rebuilt for wresdyn (``benchmarks/peers/known_truth.py``):
the rebuilt recordings carry the injected truth, the peer's own optimiser recovers every parameter within the
tolerance its authors assert, and wresdyn's identification recovers the spring-mass mass within that tolerance."""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

if not hasattr(pytest.importorskip("mujoco.sysid"), "optimize"):  # its imports need the extra's packages
    pytest.skip("mujoco[sysid] extra not installed (pip install -e '.[bench]')", allow_module_level=True)

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "peers" / "known_truth.py"


@pytest.fixture(scope="module")
def kt():
    spec = importlib.util.spec_from_file_location("known_truth", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules["known_truth"] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def spring(kt):
    return kt.dataset(kt.CASES["spring_mass"])


def test_recording_carries_the_injected_truth(kt, spring):
    """The real robot reports the truth, not the file's start, and records it: the file's 2 kg ball driven by the
    same force moves differently from the recording by far more than the recording's own precision (float64 MuJoCo
    at one step a sample: the peer replays it to 1e-14 m)."""
    from wresdyn.data.mismatch import Mismatch

    robot, ds, truth = spring
    assert truth.body_mass[robot.body_names.index("ball")] == pytest.approx(1.0, abs=1e-12)
    assert robot.body_mass[robot.body_names.index("ball")] == 2.0
    nominal = kt.real_robot(robot, Mismatch())
    train = ds.split("train")[0]
    q, _ = kt.record(nominal, train.q_cmd)
    assert np.abs(q - train.q).mean() > 1e-3  # metres: a doubled mass shifts the resonance


@pytest.mark.parametrize("name", ["spring_mass", "arm5_armature"])
def test_peer_recovers_within_its_own_tolerance(kt, name):
    """The rebuild is the peer's problem: ``mujoco.sysid`` from its published start and bounds recovers every
    injected parameter within the tolerance its own test asserts (``atol`` 1e-4)."""
    case = kt.CASES[name]
    robot, ds, _ = kt.dataset(case)
    run = kt.run_peer(case, robot, ds, log=lambda s: None)
    rec = kt.recovery(case, run["estimates"])
    assert all(r["pass"] for r in rec.values()), rec
    assert run["converged"]


def test_wresdyn_recovers_the_spring_mass_within_the_peer_tolerance(kt, spring):
    """wresdyn's identification, fixed at 200 iterations and without the pull towards the file's values
    (``w_prior`` 0; the default 1e-5 leaves the mass 5e-4 high, over the peer's 1e-4), recovers the 1 kg mass from
    the file's 2 kg within the peer's tolerance (measured 4e-5 kg)."""
    from wresdyn.identify.sysid_config import SysIdConfig

    robot, ds, _ = spring
    case = kt.CASES["spring_mass"]
    cfg = SysIdConfig(fit=case.fit, identifiability=False, w_prior=0.0, iterations=200)
    run = kt.run_wresdyn(case, robot, ds, cfg, log=lambda s: None)
    rec = kt.recovery(case, run["estimates"])["ball_mass"]
    assert rec["pass"], rec


@pytest.mark.parametrize("threshold", [1.0, 1e30])
def test_polish_moves_only_what_the_data_determine(kt, spring, threshold):
    """With the default prior (``w_prior`` 1e-5) and one Adam step, the Levenberg-Marquardt polish
    (``SysIdConfig.polish``) recovers the 1 kg mass within the peer's tolerance, and leaves the ball's centre of mass
    and rotational inertia, which a slide joint never shows, where the prior holds them; with no direction above the
    threshold it changes nothing at all."""
    from wresdyn.identify.sysid import identify
    from wresdyn.identify.sysid_config import SysIdConfig

    robot, ds, _ = spring
    case, ball = kt.CASES["spring_mass"], robot.body_names.index("ball")
    base = SysIdConfig(fit=case.fit, identifiability=False, iterations=1)
    before, _ = identify(robot, ds, base, log=lambda s: None)
    logs = []
    after, curve = identify(robot, ds, dataclasses.replace(base, polish=10, polish_threshold=threshold),
                            log=logs.append)
    if threshold > 1.0:
        assert any("nothing the data determine" in s for s in logs)
        np.testing.assert_array_equal(after.body_mass, before.body_mass)
        return
    assert abs(after.body_mass[ball] - 1.0) <= case.params[0].atol, after.body_mass[ball]
    assert any(row.get("stage") == "polish" for row in curve)
    np.testing.assert_allclose(after.body_com[ball], before.body_com[ball], atol=1e-9)
    np.testing.assert_allclose(after.body_inertia[ball], before.body_inertia[ball], rtol=1e-6)
