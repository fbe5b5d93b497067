"""The goal profile's Warp kernels (:mod:`wresdyn.sim.goal_profile`) against the step-by-step torch loop they replace:
values, torch autograd's gradients of that loop, and central differences (float64); and the bank's windows take
their goals from the profile run from each trajectory's start (the servo's state at a window's start is the one the
whole run left there, not a fresh rest)."""

import numpy as np
import torch

from wresdyn.robot.servo import profile_step
from wresdyn.sim import TrajectoryBank
from wresdyn.sim.goal_profile import profile_goals


def loop_profile(targets, first, accel):
    """The reference: :func:`profile_step` in torch, one Python step per sample over all trajectories at once."""
    starts = torch.unique_consecutive(first)
    traj = torch.searchsorted(starts, first)
    k = torch.arange(len(first)) - first
    t_max = int(k.max()) + 1
    last = torch.cat([starts[1:], torch.tensor([len(first)])]) - 1
    rows = torch.minimum(starts[:, None] + torch.arange(t_max)[None], last[:, None])
    goal = targets[rows]
    on = accel > 0
    a = torch.where(on, accel, torch.ones_like(accel)).to(targets.dtype)
    pos, vel = goal[:, 0], torch.zeros_like(goal[:, 0])
    out = []
    for t in range(t_max):
        pos, vel = profile_step(torch, goal[:, t], pos, vel, a)
        out.append(pos)
    return torch.where(on, torch.stack(out, 1)[traj, k], targets)


def table(dtype, seed=0):
    """Three trajectories (120, 80, 60 samples) of commands with steps and drifts; accelerations [rad/step²] per joint
    that profile the steps over several samples, one joint off."""
    rng = np.random.default_rng(seed)
    parts = []
    for t in (120, 80, 60):
        c = np.cumsum(rng.normal(scale=0.01, size=(t, 4)), 0)
        c[t // 3:] += rng.uniform(-0.4, 0.4, 4)
        parts.append(c)
    first = torch.tensor(np.repeat(np.cumsum([0, 120, 80]), [120, 80, 60]))
    accel = torch.tensor([2e-3, 0.0, 5e-4, 1e-2], dtype=dtype)
    return torch.tensor(np.concatenate(parts), dtype=dtype), first, accel


def test_values_match_the_torch_loop():
    """float64 equal to the last bits (the same IEEE operations in the same order: 0 measured); float32 within a few
    ulps of the 0.5 rad goals after 120 steps of accumulation (8e-8 rad measured: the C compiler's contractions)."""
    targets, first, accel = table(torch.float64)
    np.testing.assert_allclose(profile_goals(targets, first, accel), loop_profile(targets, first, accel),
                               rtol=0, atol=1e-15)
    t32, a32 = targets.float(), accel.float()
    np.testing.assert_allclose(profile_goals(t32, first, a32), loop_profile(t32, first, a32), rtol=0, atol=5e-7)
    assert (profile_goals(targets, first, accel) - targets).abs().max() > 0.05  # the steps are profiled


def test_gradients_match_torch_autograd_and_central_differences():
    """∂(w · goals)/∂targets and /∂accel for a random weighting w: the adjoint kernel against torch autograd through
    the loop (same branches, float64 rounding apart: 1e-12 measured), and against central differences (step 1e-7
    relative: the profile is piecewise smooth, a kink crossed inside ±h would show as an error of order 1; 2e-9
    relative measured). Most targets' gradients are exactly 0 (the goal accelerating at a_max does not see them):
    the rows checked are ones where it is not."""
    targets, first, accel = table(torch.float64)
    w = torch.tensor(np.random.default_rng(1).normal(size=targets.shape))
    grads = []
    for f in (profile_goals, loop_profile):
        t, a = targets.clone().requires_grad_(), accel.clone().requires_grad_()
        (w * f(t, first, a)).sum().backward()
        grads.append((t.grad, a.grad))
    (gt, ga), (rt, ra) = grads
    np.testing.assert_allclose(gt, rt, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(ga, ra, rtol=1e-10, atol=1e-10)
    assert ga[1] == 0.0 and (ga[[0, 2, 3]].abs() > 1.0).all()
    for i in (0, 2, 3):
        h = 1e-7 * float(accel[i])
        up, down = accel.clone(), accel.clone()
        up[i] += h
        down[i] -= h
        fd = float(((w * profile_goals(targets, first, up)).sum() - (w * profile_goals(targets, first, down)).sum())
                   / (2 * h))
        assert abs(fd - float(ga[i])) <= 1e-7 * abs(fd), (i, fd, float(ga[i]))
    # the targets' gradient (the delay's path) at a few rows, one per trajectory and joint
    for r, i in ((5, 0), (181, 2), (250, 3)):
        h = 1e-7
        up, down = targets.clone(), targets.clone()
        up[r, i] += h
        down[r, i] -= h
        fd = float(((w * profile_goals(up, first, accel)).sum() - (w * profile_goals(down, first, accel)).sum())
                   / (2 * h))
        assert fd != 0.0 and abs(fd - float(gt[r, i])) <= 1e-7 * abs(fd), (r, i, fd, float(gt[r, i]))


def test_windows_carry_the_profile_state_of_the_whole_run():
    """A window starting mid-run takes its goals from the profile run from the trajectory's first sample and sliced
    (at its start the internal goal is still moving toward a step), not from a profile restarted at rest there."""
    targets, first, accel = table(torch.float32)
    lengths = [120, 80, 60]
    traj = []
    for j, t in enumerate(lengths):
        c = targets[first == int(np.cumsum([0, *lengths])[j])].numpy()
        traj.append(type("T", (), {"q": c, "qd": np.zeros_like(c), "qdd": np.zeros_like(c), "q_cmd": c})())
    bank = TrajectoryBank(traj, torch.device("cpu"), 0.0, accel)
    whole = profile_goals(targets, first, accel)
    start, steps = 41, 30  # trajectory 0's step is at sample 40: the profile moves there
    w = bank.window(torch.tensor([0]), torch.tensor([start]), steps)
    np.testing.assert_array_equal(w.target[0], whole[start:start + steps])
    restarted = profile_goals(targets[start:start + steps], torch.zeros(steps, dtype=torch.long), accel)
    assert (w.target[0] - restarted).abs().max() > 0.05
