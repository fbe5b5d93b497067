"""Identification's Adam step replayed from a CUDA graph (``SysIdConfig.cuda_graph``,
:class:`~wresdyn.learn.graph_step.StepGraphs`): on the CPU its control flow with the capture stood in by eager
replays, which must equal the eager identification bit for bit and capture again after every event; on CUDA the
captured identification against the eager one."""

import copy
import dataclasses

import numpy as np
import pytest
import torch

from wresdyn.data.mismatch import Mismatch
from wresdyn.identify.sysid import IdentifyLearner, SysIdConfig, identify
from wresdyn.learn.graph_step import StepGraphs
from wresdyn.learn.window_fit import start_window_fit

REAL = Mismatch(kp_scale=0.8, kd_scale=1.3, friction=0.03, damping=0.3, delay=0.004, torque_limit_scale=0.5)
TINY = SysIdConfig(iterations=30, windows=3, horizon_curriculum=(6, 10), select_every=10, effort_grid=(0.3, 1.0),
                   gain_grid=(0.8, 1.0), delay_grid=(0.0, 2.0), identifiability=False)
"""Every event a graph must be captured again after: the kp search before the first step, the delay and effort
searches where the effort limit joins (iteration 12 of 30, mid-stage), the second horizon stage (iteration 15)."""
CUDA_RTOL = 1e-4
"""Relative tolerance of the captured identification's parameters against the eager one's on CUDA: capturable
Adam's float32 step size differs from the eager Python float's by about an ulp per step (as the PPO update's
graph, ``wresdyn.ppo.graph_update.CUDA_RTOL``); an allowance the test met on an H200
(``benchmarks/results/speed/h200x2_20261130f/checks/checks/sysid_graph.txt``)."""


@pytest.fixture(scope="module")
def recorded(humanoid, record):
    return record(humanoid, REAL, {"train": 2, "validation": 1}, seconds=0.3, amplitude=0.3)


def _addresses(learner) -> tuple[int, ...]:
    """What a captured step reads besides its inputs: the model's parameters and buffers, Adam's state."""
    tensors = [*learner.model.state_dict().values()]
    tensors += [t for s in learner.optim.state.values() for t in s.values() if torch.is_tensor(t)]
    return tuple(t.data_ptr() for t in tensors)


class _Recorded:
    """A stand-in for a captured graph on the CPU: its replay runs the step, after checking that no tensor the step
    reads was replaced (or made: Adam's state of a parameter joining the fit) since the capture."""

    def __init__(self, graphs: StepGraphs, fn) -> None:
        self.learner, self.fn = graphs.before_capture.__self__, fn
        self.inputs = _addresses(self.learner)

    def replay(self) -> torch.Tensor:
        assert _addresses(self.learner) == self.inputs, "a tensor the graph reads was replaced without a recapture"
        return self.fn()


@pytest.fixture
def recorded_capture(monkeypatch) -> list:
    """The CUDA path on the CPU: warm-up without a side stream, captures replaced by :class:`_Recorded`; the captures
    made, with the iteration each was made at."""
    captures = []
    monkeypatch.setattr(StepGraphs, "available", staticmethod(lambda device: True))
    monkeypatch.setattr(StepGraphs, "_on_side_stream", lambda self, fn: fn())

    def capture(self, fn):
        captures.append(_Recorded(self, fn))
        return captures[-1]
    monkeypatch.setattr(StepGraphs, "_capture", capture)
    return captures


def _rows(curve):
    return [{k: v for k, v in row.items() if k != "wall"} for row in curve]


def test_graph_path_equals_the_eager_identification_and_captures_after_every_event(humanoid, recorded,
                                                                                   recorded_capture):
    """Three captures (after the kp search, after the effort limit joins with its searches, at the second stage),
    each replayed with the tensors it read, and the same parameters and curve as the eager steps, bit for bit."""
    eager, eager_curve = identify(humanoid, recorded, dataclasses.replace(TINY, cuda_graph=False), log=lambda *_: None)
    assert not recorded_capture
    graph, graph_curve = identify(humanoid, recorded, TINY, log=lambda *_: None)  # the default captures
    assert len(recorded_capture) == 3
    for f in ("kp", "kd", "armature", "damping", "friction", "effort", "delay", "body_mass", "body_inertia"):
        assert np.array_equal(getattr(graph, f), getattr(eager, f)), f
    assert _rows(graph_curve) == _rows(eager_curve)


def test_without_events_a_length_is_captured_once(humanoid, recorded, recorded_capture):
    """No grid search and no effort limit joining: one capture per window length."""
    cfg = dataclasses.replace(TINY, iterations=8, effort_grid=(), gain_grid=(), delay_grid=(), cuda_graph=True,
                              fit=("kp", "kd", "damping"))
    identify(humanoid, recorded, cfg, log=lambda *_: None)
    assert len(recorded_capture) == 2


def test_a_restored_checkpoint_is_captured_again(humanoid, recorded, recorded_capture):
    """A checkpoint loaded into the optimiser replaces Adam's state: the next step warms up again and the one after
    captures (a replay of the old capture would fail :class:`_Recorded`'s check)."""
    cfg = dataclasses.replace(TINY, cuda_graph=True, gain_grid=(), effort_grid=(), delay_grid=())
    rng, train, dt = start_window_fit(cfg, recorded)
    learner = IdentifyLearner(humanoid, recorded, cfg, None, rng, train, dt, lambda *_: None, None)
    for it in range(3):
        learner.step(it, 6, cfg.lr)
    assert len(recorded_capture) == 1
    learner.restore(copy.deepcopy({**learner.state(), "meta": learner.meta()}))
    for it in range(3, 6):
        learner.step(it, 6, cfg.lr)
    assert len(recorded_capture) == 2


def test_cuda_graph_refuses_multiple_shooting():
    with pytest.raises(ValueError, match="cuda_graph"):
        SysIdConfig(cuda_graph=True, shooting=2, horizon_curriculum=(8, 16))
    assert SysIdConfig(shooting=2, horizon_curriculum=(8, 16)).cuda_graph is None  # the default steps such a fit


def test_the_default_captures_only_what_can_be_captured(humanoid, recorded, recorded_capture):
    """``cuda_graph`` ``None`` (the default) captures where a graph can run and steps eagerly elsewhere; ``False``
    never captures."""
    assert SysIdConfig().cuda_graph is None
    rng, train, dt = start_window_fit(TINY, recorded)
    learner = IdentifyLearner(humanoid, recorded, TINY, None, rng, train, dt, lambda *_: None, None)
    assert learner.graphs is not None
    cfg = dataclasses.replace(TINY, cuda_graph=False)
    assert IdentifyLearner(humanoid, recorded, cfg, None, rng, train, dt, lambda *_: None, None).graphs is None


def test_on_the_cpu_the_default_is_the_eager_identification(humanoid, recorded):
    """No CUDA, no graph: the default identification equals the one with ``cuda_graph`` off, bit for bit."""
    cfg = dataclasses.replace(TINY, iterations=12)
    off, off_curve = identify(humanoid, recorded, dataclasses.replace(cfg, cuda_graph=False), log=lambda *_: None)
    default, curve = identify(humanoid, recorded, cfg, log=lambda *_: None)
    for f in ("kp", "kd", "armature", "damping", "friction", "effort", "delay", "body_mass", "body_inertia"):
        assert np.array_equal(getattr(default, f), getattr(off, f)), f
    assert _rows(curve) == _rows(off_curve)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA only")
def test_captured_identification_on_cuda_matches_the_eager_one(humanoid, recorded):
    """A few captured steps (warm-up, capture, replays at two lengths) against the eager identification on the same
    GPU, every fitted parameter within :data:`CUDA_RTOL`."""
    cfg = dataclasses.replace(TINY, iterations=12, effort_grid=(), gain_grid=(), delay_grid=(), device="cuda:0")
    eager, _ = identify(humanoid, recorded, dataclasses.replace(cfg, cuda_graph=False), log=lambda *_: None)
    graph, curve = identify(humanoid, recorded, dataclasses.replace(cfg, cuda_graph=True), log=lambda *_: None)
    assert all(np.isfinite(row["loss"]) for row in curve)
    for f in ("kp", "kd", "armature", "damping", "friction", "delay", "body_mass"):
        a, b = np.asarray(getattr(graph, f)), np.asarray(getattr(eager, f))
        assert np.abs(a - b).max() <= CUDA_RTOL * (np.abs(b).max() + 1e-7), f
