"""What a replay runs at every step to find and hold diverged worlds, against plain definitions: ``Simulator.diverged``
against the form it had before (``torch.isfinite``, one reduction per test, the bounds computed per call), equal on
every edge case either could read differently (non-finite values, infinite limits, limits of every kind); and
``Simulator.set_state_where`` (written in place where the state's columns are a slice) against ``set_state`` of the
masked worlds, for a slice and for an index tensor."""

import math

import pytest
import torch

from wresdyn.sim import Simulator
from wresdyn.sim.simulator import DivergenceLimits


def reference(sim, q, qd, limits, q_ref=None):
    bad = ~(torch.isfinite(q).all(-1) & torch.isfinite(qd).all(-1))
    bad |= (qd.abs() > limits.max_qd).any(-1)
    bad |= ((q < sim.lower - limits.limit_margin) | (q > sim.upper + limits.limit_margin)).any(-1)
    if q_ref is not None and math.isfinite(limits.max_error):
        bad |= ((q - q_ref).abs() > limits.max_error).any(-1)
    return bad


@pytest.fixture(scope="module")
def sim(robot):
    return Simulator(robot, 1, 0.002)


SPECIAL = (0.0, -0.0, 1e-45, -1e-45, 3.4e38, -3.4e38, math.inf, -math.inf, math.nan, 99.0, 100.0, 101.0)


LIMITS = (DivergenceLimits(), DivergenceLimits(max_qd=math.inf, limit_margin=0.1, max_error=0.3),
          DivergenceLimits(max_qd=0.0, limit_margin=math.inf, max_error=0.0))


@pytest.mark.parametrize("limits", LIMITS)
@pytest.mark.parametrize("infinite_limits", [False, True])
def test_diverged_equals_its_isfinite_definition_on_every_edge_case(sim, limits, infinite_limits):
    n = sim.lower.shape[0]
    gen = torch.Generator().manual_seed(0)
    special = torch.tensor(SPECIAL, dtype=torch.float32)
    worlds = 600
    q = sim.lower + (sim.upper - sim.lower) * torch.rand(worlds, n, generator=gen)  # sane worlds, then specials
    qd = (torch.rand(worlds, n, generator=gen) - 0.5) * 120.0
    q_ref = q + (torch.rand(worlds, n, generator=gen) - 0.5) * 0.4
    for x in (q, qd, q_ref):  # a special value in a random joint of one world in four
        pick = torch.randint(0, len(special), (worlds,), generator=gen)
        where = torch.randint(0, n, (worlds,), generator=gen)
        x[torch.arange(worlds)[::4], where[::4]] = special[pick[::4]]
    lower, upper = sim.lower, sim.upper
    if infinite_limits:  # an unlimited joint (a wheel): q = ±inf is past no limit but still non-finite
        sim.lower, sim.upper = lower.clone().fill_(-math.inf), upper.clone().fill_(math.inf)
    try:
        want = reference(sim, q, qd, limits, q_ref)
        assert torch.equal(sim.diverged(q, qd, limits, q_ref), want)
        bounds = (sim.lower - limits.limit_margin, sim.upper + limits.limit_margin)
        assert torch.equal(sim.diverged(q, qd, limits, q_ref, bounds), want)
        assert torch.equal(sim.diverged(q, qd, limits), reference(sim, q, qd, limits))
        if limits == DivergenceLimits():
            assert 0 < int(want.sum()) < worlds  # both kinds of world are in the test
    finally:
        sim.lower, sim.upper = lower, upper


@pytest.mark.parametrize("as_tensor", [False, True])
def test_set_state_where_writes_the_masked_worlds_only(robot, as_tensor):
    sim = Simulator(robot, 5, 0.002)
    if as_tensor:  # the gather-and-scatter path of a robot whose coordinates are not contiguous
        for name in ("q_index", "qd_index"):
            index = getattr(sim, name)
            setattr(sim, name, torch.arange(index.start, index.stop))
    assert isinstance(sim.q_index, torch.Tensor) == as_tensor
    gen = torch.Generator().manual_seed(1)
    n = sim.lower.shape[0]
    q0, qd0 = torch.rand(5, n, generator=gen), torch.rand(5, n, generator=gen)
    q1, qd1 = torch.rand(5, n, generator=gen), torch.rand(5, n, generator=gen)
    mask = torch.tensor([True, False, True, False, False])
    sim.set_state(None, q0, qd0)
    sim.set_state_where(mask, q1, qd1)
    want_q, want_qd = torch.where(mask[:, None], q1, q0), torch.where(mask[:, None], qd1, qd0)
    assert torch.equal(sim.q, want_q) and torch.equal(sim.qd, want_qd)
