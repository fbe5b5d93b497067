"""Floor motions drawn in a process pool: the same set, bit for bit, as drawn serially; each draw the same with the
floor cache the draws share as with one of its own; the workers' import without torch; and how many processes the
floor benchmark asks for. At 100 Hz, as in ``test_motions.py``: the IK costs a tenth of the simulation's rate."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from wresdyn.experiments.deploy_config import FloorDeployConfig
from wresdyn.skills import motions as motions_module
from wresdyn.skills.motions import make_motions, pool_workers

RATE = 100.0


def _same(a, b) -> None:
    """Every field of two motions equal, arrays bit for bit (same dtype, shape and values)."""
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y), (a.name, f.name)
        else:
            assert x == y, (a.name, f.name, x, y)


def test_a_pool_of_two_draws_the_serial_set_bit_for_bit(humanoid, floating):
    # seed 0's third validation weight shift is slowed x1.3 by the screening (test_motions.py), so the pool repeats
    # a slowed draw too; the held-out split adds a step (two splits, two families, results in the serial order)
    kw = dict(floating=floating, families=("weight_shift",))
    counts = {"validation": 3, "heldout": 1}
    serial = make_motions(humanoid, counts, 4.0, RATE, seed=0, workers=1, **kw)
    pooled = make_motions(humanoid, counts, 4.0, RATE, seed=0, workers=2, **kw)
    assert list(pooled.splits) == list(serial.splits) == ["validation", "heldout"]
    assert [m.name for m in pooled["validation"]] == [f"validation_weight_shift_{i}" for i in range(3)]
    assert [m.screen for m in serial["validation"]] == ["ok", "ok", "slowed x1.3"]
    assert [m.name for m in pooled["heldout"]] == ["heldout_weight_shift_0", "heldout_step_0"]
    for s in serial.splits:
        assert len(pooled[s]) == len(serial[s])
        for a, b in zip(serial[s], pooled[s]):
            _same(a, b)
    assert pooled.rate_hz == serial.rate_hz


def test_a_shared_floor_cache_draws_what_a_cache_per_draw_draws(monkeypatch, humanoid, floating):
    # make_motions shares one FloorCache (the Pinocchio model, the standing pose of each start) over every draw; with
    # make_motion's own per draw (floor_cache=None) every motion must be the same, the slowed third draw included
    kw = dict(floating=floating, families=("weight_shift",))
    shared = make_motions(humanoid, {"validation": 3}, 4.0, RATE, seed=0, workers=1, **kw)
    draw = motions_module.make_motion
    built = []

    def own_cache(*args, floor_cache=None, **kwargs):
        built.append(floor_cache)
        return draw(*args, **kwargs)

    monkeypatch.setattr(motions_module, "make_motion", own_cache)
    alone = make_motions(humanoid, {"validation": 3}, 4.0, RATE, seed=0, workers=1, **kw)
    assert len(built) == 3 and all(isinstance(c, motions_module.FloorCache) for c in built)
    assert [m.screen for m in shared["validation"]] == ["ok", "ok", "slowed x1.3"]
    for a, b in zip(shared["validation"], alone["validation"]):
        _same(a, b)


def test_a_motion_worker_imports_no_torch():
    # what a spawned worker imports before its first draw (torch would add seconds to each one's start)
    code = "import sys, wresdyn.skills.motions; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "False"


def test_automatic_workers_are_the_usable_cores_for_enough_motions_and_serial_on_two(monkeypatch):
    monkeypatch.setattr(motions_module.os, "sched_getaffinity", lambda pid: set(range(2)), raising=False)
    assert pool_workers(0, 130) == 1
    monkeypatch.setattr(motions_module.os, "sched_getaffinity", lambda pid: set(range(32)), raising=False)
    assert pool_workers(0, 130) == 16 and pool_workers(0, 300) == 32  # at least 8 motions a worker
    assert pool_workers(0, 5) == 1 and pool_workers(0, 16) == 2
    assert pool_workers(4, 130) == 4 and pool_workers(4, 2) == 2 and pool_workers(1, 130) == 1


def test_motion_workers_is_validated():
    assert FloorDeployConfig().motion_workers == 0
    assert FloorDeployConfig(motion_workers=8).motion_workers == 8
    for bad in (-1, 1.5):
        with pytest.raises(ValueError, match="floor.motion_workers"):
            FloorDeployConfig(motion_workers=bad)
