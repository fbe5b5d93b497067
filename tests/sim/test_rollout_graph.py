"""The branch-free rollout loop (the one a CUDA graph captures) against the loop that reads the host at every step
(the CPU's default), the capture's gating, its key, and (on a GPU) the captured replay against the eager one."""

from __future__ import annotations

import contextlib
import dataclasses
import importlib

import numpy as np
import pytest
import torch
import warp as wp

from wresdyn.errors import SimulationDiverged
from wresdyn.fit.gradfit import build_policy
from wresdyn.learn.residual import ResidualConfig, obs_stats
from wresdyn.sim import DivergenceLimits, Simulator, TrajectoryBank, replay_trajectories, rollout
from wresdyn.sim.bank import servo_goal_accel
from wresdyn.sim.residual_kinds import apply_residual, observation
from wresdyn.sim.rollout_graph import _WARM, MAX_GRAPHS, capture_blocker, rollout_key


def host_read_rollout(sim, window, policy=None, *, kind="torque", policy_worlds=None, residual=None,
                      limits=DivergenceLimits(), on_diverge="freeze"):
    """The no-gradient loop written out on its own: divergence read on the host at every step, the frozen worlds
    written back only when there are any, a raise at the first diverged step."""
    b, steps = window.cmd.shape[0], window.steps
    pw = slice(None) if policy_worlds is None else policy_worlds
    if policy is not None and hasattr(policy, "reset"):
        policy.reset()
    q, qd, qdd = window.q[:, 0], window.qd[:, 0], window.qdd[:, 0]
    qs, qds, actions = [q], [qd], []
    dead = torch.zeros(b, dtype=torch.bool)
    diverged_at = torch.full((b,), -1, dtype=torch.long)
    sim.set_state(None, q, qd)
    for k in range(steps):
        res = None
        if policy is not None:
            r = policy(observation(q[pw], qd[pw], qdd[pw], window.cmd[pw, k]))
            actions.append(r / policy.scale)
            res = r if policy_worlds is None else torch.zeros_like(q).index_put_((torch.arange(b)[pw],), r)
        elif residual is not None:
            res = residual[:, k]
        target, tau = apply_residual(window.target[:, k], res, kind)
        q_new, qd_new = sim.step(target, tau)
        bad = sim.diverged(q_new, qd_new, limits, window.q[:, k + 1]) & ~dead
        if bad.any():
            if on_diverge == "raise":
                raise SimulationDiverged(f"{sim.robot.source.name}: Newton replay diverged in world "
                                         f"{int(bad.nonzero()[0])} at step {k + 1} (t = {(k + 1) * sim.dt:.3f} s)")
            dead |= bad
            diverged_at[bad] = k + 1
        if dead.any():
            q_new = torch.where(dead[:, None], q, q_new)
            qd_new = torch.where(dead[:, None], torch.zeros_like(qd_new), qd_new)
            sim.set_state(dead.nonzero().squeeze(-1), q_new[dead], qd_new[dead])
        qdd = (qd_new - qd) / sim.dt
        q, qd = q_new, qd_new
        qs.append(q)
        qds.append(qd)
    return torch.stack(qs, 1), torch.stack(qds, 1), torch.stack(actions, 1) if actions else None, diverged_at


@pytest.fixture(scope="module")
def setup(robot, data):
    """The tiny dataset's trajectories as one window batch, PD-only and residual copies (4 worlds), a residual MLP
    and a GRU at their start."""
    trajs = data.split("train") + data.split("validation")
    bank = TrajectoryBank(trajs, "cpu", 0.0, servo_goal_accel(robot, None, 1.0 / data.rate_hz, "cpu"))
    window = bank.whole().repeat(2)
    torch.manual_seed(0)
    stats = obs_stats(data.split("train"))
    mlp = build_policy(robot, ResidualConfig(fraction=0.5), *stats).eval()
    gru = build_policy(robot, ResidualConfig(fraction=0.5, arch="gru", hidden_dims=(32,)), *stats).eval()
    with torch.no_grad():
        for p in list(mlp.parameters()) + list(gru.parameters()):
            p.add_(0.3 * torch.randn_like(p))  # an untrained network's output is near zero: make the residual count
    return window, mlp, gru, 1.0 / data.rate_hz


def kick(window, worlds, step: int, torque: float = 2e3) -> torch.Tensor:
    """An open-loop torque residual (B, L, n) that throws ``worlds`` off from ``step`` on."""
    res = torch.zeros_like(window.cmd)
    res[worlds, step:] = torque
    return res


CASES = {
    "pd": dict(),
    "mlp": dict(policy="mlp"),
    "gru": dict(policy="gru"),
    "mlp_policy_worlds": dict(policy="mlp", policy_worlds=slice(3, 6)),
    "gru_policy_worlds": dict(policy="gru", policy_worlds=slice(3, 6)),
    # the limits sit between the worlds' peaks (PD only: |q - q_rec| <= 0.27 rad, |qd| <= 4.2 rad/s; the MLP:
    # 10.7-11.7 rad/s; a kicked world passes the default 100 rad/s), so some worlds diverge and some do not
    "diverging_residual": dict(kick=[1, 4], limits=DivergenceLimits(max_error=0.5)),
    "diverging_mlp": dict(policy="mlp", limits=DivergenceLimits(max_qd=11.5)),
    "diverging_mlp_policy_worlds": dict(policy="mlp", policy_worlds=slice(3, 6), limits=DivergenceLimits(max_qd=8.0)),
}


@pytest.mark.parametrize("case", list(CASES))
def test_branch_free_loop_equals_the_host_read_loop_bit_for_bit(robot, setup, case):
    window, mlp, gru, dt = setup
    c = dict(CASES[case])
    policy = {"mlp": mlp, "gru": gru}.get(c.pop("policy", None))
    kicked = c.pop("kick", None)
    if kicked is not None:
        c["residual"] = kick(window, kicked, 20)
    sim = Simulator(robot, window.cmd.shape[0], dt, solver="replay")
    with torch.no_grad():
        ref = host_read_rollout(sim, window, policy, **c)
        eager = rollout(sim, window, policy, kind="torque", **c)
        out = rollout(sim, window, policy, kind="torque", branch_free=True, **c)
    for run in (eager, out):
        for name, a, b in zip(("q", "qd", "actions", "diverged_at"), ref, (run.q, run.qd, run.actions,
                                                                           run.diverged_at)):
            assert (a is None) == (b is None), name
            if a is not None:
                assert torch.equal(a, b), f"{name}: max |diff| {(a.double() - b.double()).abs().nan_to_num(1e9).max()}"
    at = out.diverged_at.numpy()
    if "limits" in c:  # the case exists to diverge: some worlds do, mid-window, and some do not
        assert (at > 0).any() and (at == -1).any(), at
        frozen = at[at > 0]
        assert (frozen < window.steps).all()
        w = int(np.flatnonzero(at > 0)[0])
        q = out.q[w].numpy()
        assert (q[at[w]:] == q[at[w] - 1]).all() and (out.qd[w, at[w]:] == 0).all()  # held at rest
    else:
        assert (at == -1).all()


@pytest.mark.parametrize("case", ["diverging_residual", "diverging_mlp"])
def test_raise_names_the_first_world_and_step_as_the_host_read_loop(robot, setup, case):
    window, mlp, _, dt = setup
    c = dict(CASES[case])
    policy = mlp if c.pop("policy", None) else None
    if c.pop("kick", None) is not None:
        c["residual"] = kick(window, [4], 15) + kick(window, [1], 30)  # world 4 first, though 1 is listed first
    sim = Simulator(robot, window.cmd.shape[0], dt, solver="replay")
    with torch.no_grad():
        with pytest.raises(SimulationDiverged) as ref:
            host_read_rollout(sim, window, policy, on_diverge="raise", **c)
        with pytest.raises(SimulationDiverged) as eager:
            rollout(sim, window, policy, kind="torque", on_diverge="raise", **c)
        with pytest.raises(SimulationDiverged) as out:
            rollout(sim, window, policy, kind="torque", on_diverge="raise", branch_free=True, **c)
    assert str(out.value) == str(ref.value) == str(eager.value)
    if policy is None:
        assert "world 4 at step" in str(out.value)


def test_capture_gating():
    mlp = torch.nn.Linear(4, 2)
    ok = dict(grad=False, enabled=True, policy=mlp, policy_device=torch.device("cuda:0"))
    assert capture_blocker("cuda:0", **ok) is None
    assert capture_blocker("cuda:0", **{**ok, "policy": None, "policy_device": None}) is None  # PD only
    assert capture_blocker(torch.device("cuda", 0), **ok, obs_noise=0.1, noise=torch.zeros(1)) is None  # fixed buffer
    blocked = {
        "cpu": ("cpu", ok),
        "off": ("cuda:0", {**ok, "enabled": False}),
        "grad": ("cuda:0", {**ok, "grad": True}),
        "callable": ("cuda:0", {**ok, "policy": lambda obs: obs, "policy_device": None}),
        "policy on the CPU": ("cuda:0", {**ok, "policy_device": torch.device("cpu")}),
        "generator noise": ("cuda:0", {**ok, "obs_noise": 0.1}),
    }
    for name, (device, kw) in blocked.items():
        assert capture_blocker(device, **kw) is not None, name


def test_simulator_switch_defaults_to_the_solver_graph_flag(robot):
    sim = Simulator(robot, 2, 0.002, solver="replay")
    assert sim.rollout_graph is False  # the CPU has no graphs
    sim = Simulator(robot, 2, 0.002, solver="replay", graph=True)
    assert sim.rollout_graph is False


def test_rollout_key_follows_what_the_graph_reads(robot, setup):
    window, mlp, gru, dt = setup
    sim = Simulator(robot, window.cmd.shape[0], dt, solver="replay")
    lim = DivergenceLimits()

    def key(policy=mlp, win=window, pw=None):
        return rollout_key(sim, win, policy, "torque", pw, None, 0.0, None, lim)

    base = key()
    assert key() == base
    with torch.no_grad():
        next(mlp.parameters()).add_(1.0)  # an optimiser's in-place update: the graph reads it, same key
    assert key() == base
    moved = dataclasses.replace(window, cmd=window.cmd[:, :-1], target=window.target[:, :-1])
    changed = [key(policy=gru), key(policy=None), key(pw=slice(3, 6)), key(win=moved)]
    assert all(k != base for k in changed) and len(set(changed)) == len(changed)
    p = next(mlp.parameters())
    old = p.data
    p.data = p.data.clone()  # new storage (a module rebuilt or moved): a new graph
    assert key() != base
    p.data = old


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need a GPU")
@pytest.mark.parametrize("arch", ["none", "mlp", "gru"])
def test_captured_validation_replay_equals_the_eager_one(robot, data, arch):
    trajs = data.split("train") + data.split("validation")
    policy = None
    if arch != "none":
        cfg = ResidualConfig(fraction=0.5, arch=arch, hidden_dims=(32,) if arch == "gru" else (64, 64))
        policy = build_policy(robot, cfg, *obs_stats(data.split("train"))).eval().to("cuda:0")
    worlds = len(trajs) * (1 if policy is None else 2)  # PD only; or the PD baseline and the residual's worlds
    sims = {g: Simulator(robot, worlds, 1.0 / data.rate_hz, solver="replay", device="cuda:0") for g in (True, False)}
    sims[False].rollout_graph = False
    graphs = []
    for call in range(4):  # eager warm-up, capture and replay, replays; the parameters change in between
        if policy is not None:
            with torch.no_grad():
                for p in policy.parameters():
                    p.add_(0.2 * torch.randn_like(p))  # in place, as an optimiser
        runs = {g: replay_trajectories(robot, trajs, data.rate_hz, policy, kind="torque", sim=sims[g],
                                       with_baseline=True) for g in (True, False)}
        for group in runs[False]:
            a, b = runs[True][group], runs[False][group]
            assert a.diverged_at == b.diverged_at
            for qa, qb in zip(a.q + a.qd, b.q + b.qd):
                assert np.abs(qa - qb).max() < 1e-4, (call, group)
        entries = [e for e in sims[True]._rollout_graphs.values() if e is not _WARM]
        graphs.append(entries[0][0] if entries else None)
    assert graphs[0] is None and graphs[1] is not None and graphs[2] is graphs[1] and graphs[3] is graphs[1]
    assert not sims[False]._rollout_graphs and len(sims[True]._rollout_graphs) == 1  # one key: the same simulator


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need a GPU")
def test_captured_replay_freezes_and_raises_as_the_eager_one(robot, data):
    trajs = data.split("train") + data.split("validation")
    sim = Simulator(robot, len(trajs), 1.0 / data.rate_hz, solver="replay", device="cuda:0")
    window = TrajectoryBank(trajs, sim.device, 0.0, servo_goal_accel(robot, None, 1.0 / data.rate_hz, sim.device)
                            ).whole()
    res = kick(window, [1], 20)
    lim = DivergenceLimits(max_error=0.5)
    with torch.no_grad():
        eager = rollout(sim, window, residual=res, limits=lim, graph=False)
        runs = [rollout(sim, window, residual=res, limits=lim) for _ in range(3)]
        with pytest.raises(SimulationDiverged, match="world 1 at step"):
            rollout(sim, window, residual=res, limits=lim, on_diverge="raise")
    assert any(e is not _WARM for e in sim._rollout_graphs.values())
    assert int(eager.diverged_at[1]) > 0
    for out in runs:
        assert torch.equal(out.diverged_at, eager.diverged_at)
        assert (out.q - eager.q).abs().max() < 1e-4


class _FakeStream:
    def wait_stream(self, other) -> None:
        pass


class _FakeGraph:
    """Stands in for ``torch.cuda.CUDAGraph`` on the CPU: the 'capture' runs the loop eagerly (a real capture runs
    nothing) and a replay does nothing, so the outputs are the capture's, as a real replay's are for the same inputs."""

    def __init__(self) -> None:
        self.replays = 0

    def replay(self) -> None:
        self.replays += 1


def test_capture_bookkeeping_with_a_fake_graph_on_the_cpu(robot, setup, monkeypatch):
    """The warm-up, capture and replay states of a key, the state buffer carried over, the outputs cloned and a raise
    after a replayed window, with the CUDA calls faked on the CPU (the GPU tests above check the graph itself)."""
    window, mlp, _, dt = setup
    rollout_module = importlib.import_module("wresdyn.sim.rollout")  # wresdyn.sim's `rollout` is the function
    monkeypatch.setattr(rollout_module, "capture_blocker", lambda *a, **k: None)
    monkeypatch.setattr(torch.cuda, "current_stream", lambda device=None: _FakeStream())
    monkeypatch.setattr(torch.cuda, "stream", lambda s: contextlib.nullcontext())
    monkeypatch.setattr(torch.cuda, "CUDAGraph", _FakeGraph)
    monkeypatch.setattr(torch.cuda, "graph", lambda graph, **k: contextlib.nullcontext())
    monkeypatch.setattr(wp, "capture_begin", lambda **k: None)
    monkeypatch.setattr(wp, "capture_end", lambda **k: None)
    sim = Simulator(robot, window.cmd.shape[0], dt, solver="replay")
    monkeypatch.setattr(sim, "side_stream", lambda: _FakeStream())
    assert window.steps % 2 == 1  # an odd step count: each replay leaves the other state buffer current
    with torch.no_grad():
        ref = host_read_rollout(sim, window, mlp, policy_worlds=slice(3, 6))
        graphs = []
        for call in range(4):
            out = rollout(sim, window, mlp, kind="torque", policy_worlds=slice(3, 6))
            assert torch.equal(out.q, ref[0]) and torch.equal(out.qd, ref[1]) and torch.equal(out.actions, ref[2])
            out.q.zero_()  # the caller's own tensors, not the graph's buffers
            (entry,) = sim._rollout_graphs.values()
            graphs.append(entry if entry is _WARM else entry[0])
        assert graphs[0] is _WARM and isinstance(graphs[1], _FakeGraph) and graphs[2] is graphs[1] is graphs[3]
        assert graphs[1].replays == 3
        start, after = sim._rollout_graphs[next(iter(sim._rollout_graphs))][5:7]
        assert after != start and sim._cur == after
        res = kick(window, [4], 15)
        for call in range(3):  # eager (raises in the loop), captured, replayed (both raise after the window)
            with pytest.raises(SimulationDiverged, match="world 4 at step 16"):
                rollout(sim, window, residual=res, on_diverge="raise")
        assert len(sim._rollout_graphs) == 2
        for i in range(MAX_GRAPHS):  # new keys push the oldest out
            rollout(sim, dataclasses.replace(window, cmd=window.cmd[:, :-1 - i], target=window.target[:, :-1 - i]))
        assert len(sim._rollout_graphs) == MAX_GRAPHS
