"""The non-gradient rollout reads its divergence state on the host only every ``sync_every`` steps (``SYNC_EVERY`` on
a GPU; the CPU's default with a policy, every step, is checked too): its outputs (q, q̇, actions, diverged_at), the simulator's final
state and its error message stay bit-identical to checking every step.

The reference is a frozen copy of the rollout that read the host at every step (two reads: any new divergence, any
frozen world) and reset the frozen worlds' solver state at each step.
"""

import numpy as np
import pytest
import torch

from wresdyn.errors import SimulationDiverged
from wresdyn.learn.residual import MLPResidualPolicy, obs_stats
from wresdyn.paths import DEFAULT_DATASET
from wresdyn.sim import Simulator
from wresdyn.sim.bank import TrajectoryBank, servo_goal_accel
from wresdyn.sim.residual_kinds import apply_residual, observation
from wresdyn.sim.rollout import SYNC_EVERY, Rollout, rollout
from wresdyn.sim.simulator import DivergenceLimits

STEPS = 70  # past two sync points of SYNC_EVERY = 32, and a partial last stretch


def per_step_rollout(sim, window, policy=None, *, kind=None, policy_worlds=None, residual=None,
                     limits=DivergenceLimits(), on_diverge="freeze") -> Rollout:
    """The non-gradient rollout as it was with a host read at every step (no observation noise)."""
    b, steps = window.cmd.shape[0], window.steps
    pw = slice(None) if policy_worlds is None else policy_worlds
    active = policy is not None or residual is not None
    kind = (kind or policy.kind) if policy is not None else (kind or "torque")
    scale = getattr(policy, "scale", None)
    q, qd, qdd = window.q[:, 0], window.qd[:, 0], window.qdd[:, 0]
    qs, qds, actions = [q], [qd], []
    dead = torch.zeros(b, dtype=torch.bool, device=sim.device)
    diverged_at = torch.full((b,), -1, dtype=torch.long, device=sim.device)
    sim.set_state(None, q, qd)
    for k in range(steps):
        res = None
        if policy is not None:
            r = policy(observation(q[pw], qd[pw], qdd[pw], window.cmd[pw, k]))
            if scale is not None:
                actions.append(r / scale)
            res = r if policy_worlds is None else torch.zeros_like(q).index_put_((torch.arange(b)[pw],), r)
        elif residual is not None:
            res = residual[:, k]
        target, tau = apply_residual(window.target[:, k], res, kind) if active else (window.target[:, k], None)
        q_new, qd_new = sim.step(target, tau)
        bad = sim.diverged(q_new, qd_new, limits, window.q[:, k + 1]) & ~dead
        if bad.any():
            if on_diverge == "raise":
                w = int(bad.nonzero()[0])
                raise SimulationDiverged(f"{sim.robot.source.name}: Newton replay diverged in world {w} at step "
                                         f"{k + 1} (t = {(k + 1) * sim.dt:.3f} s)")
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
    return Rollout(torch.stack(qs, 1), torch.stack(qds, 1), torch.stack(actions, 1) if actions else None, diverged_at)


class NaNAt(torch.nn.Module):
    """A residual network that returns NaN for world ``world`` at its call ``call`` (a policy blowing up mid-way)."""

    def __init__(self, inner: MLPResidualPolicy, world: int, call: int) -> None:
        super().__init__()
        self.inner, self.world, self.call, self.calls = inner, world, call, 0
        self.kind, self.scale = inner.kind, inner.scale

    def reset(self) -> None:
        self.calls = 0

    def forward(self, obs):
        r = self.inner(obs)
        if self.calls == self.call:
            r = r.clone()
            r[self.world] = float("nan")
        self.calls += 1
        return r


@pytest.fixture(scope="module")
def setup(humanoid):
    from wresdyn.data.dataset import load_dataset

    ds = load_dataset(DEFAULT_DATASET, robot=humanoid)
    val = ds.split("validation")
    bank = TrajectoryBank(val, torch.device("cpu"), 0.0, servo_goal_accel(humanoid, None, 1.0 / ds.rate_hz, "cpu"))
    traj = torch.arange(len(val)).repeat(2)  # 8 worlds: each validation trajectory from two start samples
    start = torch.tensor([0] * len(val) + [400] * len(val))
    window = bank.window(traj, start, STEPS)
    n = humanoid.n_dof
    torch.manual_seed(3)
    mlp = torch.nn.Sequential(torch.nn.Linear(4 * n, 32), torch.nn.ELU(), torch.nn.Linear(32, n))
    policy = MLPResidualPolicy(mlp, *obs_stats(ds.split("train")), np.full(n, 2.0), "torque").eval()
    return humanoid, ds.rate_hz, window, policy


def same_bits(a: torch.Tensor, b: torch.Tensor) -> bool:
    """Equal to the bit (NaN payloads and signed zeros included)."""
    if a.dtype == torch.float32 and b.dtype == torch.float32:
        a, b = a.contiguous().view(torch.int32), b.contiguous().view(torch.int32)
    return a.shape == b.shape and a.dtype == b.dtype and torch.equal(a, b)


def both(setup, solver="replay", sync_every=SYNC_EVERY, **kw):
    robot, rate, window, _ = setup
    runs, states = [], []
    for f in (lambda s: per_step_rollout(s, window, **kw), lambda s: rollout(s, window, sync_every=sync_every, **kw)):
        sim = Simulator(robot, window.cmd.shape[0], 1.0 / rate, solver=solver, device="cpu")
        with torch.no_grad():
            runs.append(f(sim))
        states.append((sim.q, sim.qd))
    return runs, states


def assert_identical(runs, states):
    old, new = runs
    for name in ("q", "qd", "actions", "diverged_at"):
        a, b = getattr(old, name), getattr(new, name)
        assert (a is None) == (b is None), name
        assert a is None or same_bits(a, b), name
    for a, b in zip(*states):  # the solver's state at the end too (frozen worlds put back at the last sync point)
        assert same_bits(a, b)


@pytest.mark.parametrize("sync_every", [SYNC_EVERY, 5, None])
def test_normal_replay_identical(setup, sync_every):
    """A replay where no world diverges: PD in four worlds, the residual network in the other four."""
    _, _, window, policy = setup
    runs, states = both(setup, sync_every=sync_every, policy=policy, policy_worlds=slice(4, 8))
    assert (runs[1].diverged_at == -1).all()
    assert_identical(runs, states)


@pytest.mark.parametrize("sync_every", [SYNC_EVERY, 5, None])
def test_diverging_worlds_identical(setup, sync_every):
    """Worlds diverge mid-way: a NaN torque in one (non-finite), a huge torque in another (past a joint limit),
    between sync points; they hold their last sane state while the others go on unchanged."""
    _, _, window, _ = setup
    b, n = window.cmd.shape[0], window.cmd.shape[2]
    residual = torch.zeros(b, STEPS, n)
    residual[1, 10] = float("nan")
    residual[6, 40:] = 500.0  # [N*m] far past every effort limit: the joints run into their limits
    runs, states = both(setup, sync_every=sync_every, residual=residual, kind="torque")
    at = runs[1].diverged_at
    assert at[1] == 11 and 40 < at[6] < STEPS  # the case it exists for: two worlds frozen at different steps
    assert (at[[0, 2, 3, 4, 5, 7]] == -1).all()
    assert (runs[1].qd[1, 11:] == 0).all() and (runs[1].q[1, 11:] == runs[1].q[1, 10]).all()
    assert_identical(runs, states)


@pytest.mark.parametrize("sync_every", [SYNC_EVERY, 5, None])
def test_diverging_policy_identical(setup, sync_every):
    """The residual network's own output turns NaN in one world: the network then sees that world frozen, and its
    actions there stay those of the per-step check."""
    _, _, window, policy = setup
    runs, states = both(setup, sync_every=sync_every, policy=NaNAt(policy, world=2, call=20))
    assert runs[1].diverged_at[2] == 21 and (runs[1].diverged_at[[0, 1, 3, 4, 5, 6, 7]] == -1).all()
    assert torch.isfinite(runs[1].actions[2, 21:]).all()  # the frozen state's observation, not NaN
    assert_identical(runs, states)


@pytest.mark.parametrize("solver", ["featherstone", "mujoco"])
def test_other_solver_identical(setup, solver):
    """Solvers that refresh the bodies' poses when the state is written (Featherstone, MuJoCo without a floor)."""
    _, _, window, _ = setup
    b, n = window.cmd.shape[0], window.cmd.shape[2]
    residual = torch.zeros(b, STEPS, n)
    residual[5, 12] = float("nan")
    runs, states = both(setup, solver=solver, residual=residual, kind="torque")
    assert runs[1].diverged_at[5] == 13
    assert_identical(runs, states)


def test_raise_message_identical(setup):
    """``on_diverge="raise"``: the same world and step as the per-step check, the lowest world among those
    diverged at the earliest step (worlds 3 and 5 at step 12, world 0 later), though the error comes at the next
    sync point."""
    robot, rate, window, _ = setup
    b, n = window.cmd.shape[0], window.cmd.shape[2]
    residual = torch.zeros(b, STEPS, n)
    residual[0, 19] = residual[3, 11] = residual[5, 11] = float("nan")
    messages = []
    for sync_every in ("per step", SYNC_EVERY, 5, None):
        sim = Simulator(robot, b, 1.0 / rate, solver="replay", device="cpu")
        with pytest.raises(SimulationDiverged) as err, torch.no_grad():
            if sync_every == "per step":
                per_step_rollout(sim, window, residual=residual, kind="torque", on_diverge="raise")
            else:
                rollout(sim, window, residual=residual, kind="torque", on_diverge="raise", sync_every=sync_every)
        messages.append(str(err.value))
    assert "world 3 at step 12 " in messages[0]
    assert messages[1:] == messages[:1] * 3


def test_sync_every_checked(setup):
    robot, rate, window, _ = setup
    sim = Simulator(robot, window.cmd.shape[0], 1.0 / rate, solver="replay", device="cpu")
    with pytest.raises(ValueError, match="sync_every"):
        rollout(sim, window, sync_every=0)
