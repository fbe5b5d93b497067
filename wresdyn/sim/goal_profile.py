"""The servo goal profile over whole trajectories as Warp kernels, differentiable in the targets and the acceleration.

:func:`profile_goals` runs :func:`~wresdyn.robot.servo.profile_step` over every sample of a concatenated table of
delayed commands: one thread per (trajectory, joint) walks its trajectory's rows in time, from rest on its first
target. The gradient (:class:`_Profile`, a ``torch.autograd.Function``) is a hand-written adjoint kernel walking the
same rows backwards from the stored states; Warp's own reverse mode does not differentiate a loop whose carried
state is reassigned. Its branches follow torch's derivatives of the same expressions (``sign`` and ``abs`` with
derivative 0 at 0, ``clamp`` passing the gradient inside its closed interval and to the bound it crossed outside,
``minimum`` splitting a tie in half), so it is torch autograd's gradient of the step-by-step torch loop.
"""

import functools

import torch

__all__ = ["profile_goals", "profile_modules"]

_FLOOR = 1e-30
"""Floor of ``2 a |e|`` under the square root, as :func:`~wresdyn.robot.servo.profile_step`'s."""


@functools.cache
def _kernels(dtype: torch.dtype):
    """The forward and adjoint kernels in the precision of ``dtype`` (float32 or float64)."""
    import warp as wp

    wp.init()
    real = {torch.float32: wp.float32, torch.float64: wp.float64}[dtype]
    floor = real(_FLOOR)
    zero, half, two = real(0.0), real(0.5), real(2.0)

    @wp.func
    def sgn(x: real):
        if x > zero:
            return real(1.0)
        if x < zero:
            return real(-1.0)
        return zero

    @wp.kernel(enable_backward=False, module="unique")
    def forward(goal_in: wp.array2d(dtype=real), start_in: wp.array(dtype=wp.int32),
                end_in: wp.array(dtype=wp.int32), accel_in: wp.array(dtype=real),
                pos_out: wp.array2d(dtype=real), vel_out: wp.array2d(dtype=real)):
        j, i = wp.tid()
        a = accel_in[i]
        r0 = start_in[j]
        p = goal_in[r0, i]
        v = zero
        for r in range(r0, end_in[j]):
            e = goal_in[r, i] - p
            d = wp.abs(e)
            brake = wp.sqrt(wp.max(two * a * d, floor))
            want = sgn(e) * wp.min(brake, d)
            v = v + wp.clamp(want - v, -a, a)
            p = p + v
            pos_out[r, i] = p
            vel_out[r, i] = v

    @wp.kernel(enable_backward=False, module="unique")
    def adjoint(goal_in: wp.array2d(dtype=real), start_in: wp.array(dtype=wp.int32),
                end_in: wp.array(dtype=wp.int32), accel_in: wp.array(dtype=real),
                pos_in: wp.array2d(dtype=real), vel_in: wp.array2d(dtype=real), adj_pos_in: wp.array2d(dtype=real),
                adj_goal_out: wp.array2d(dtype=real), adj_accel_out: wp.array2d(dtype=real)):
        j, i = wp.tid()
        a = accel_in[i]
        r0 = start_in[j]
        r1 = end_in[j]
        adj_p = zero  # adjoints of the state after the step being walked back
        adj_v = zero
        adj_a = zero
        for k in range(r1 - r0):
            r = r1 - 1 - k
            p = goal_in[r0, i]  # the state before step r
            v = zero
            if r > r0:
                p = pos_in[r - 1, i]
                v = vel_in[r - 1, i]
            # p' = p + v', v' = v + c
            adj_p = adj_p + adj_pos_in[r, i]
            adj_c = adj_v + adj_p
            adj_v = adj_c
            e = goal_in[r, i] - p
            d = wp.abs(e)
            s = two * a * d
            b = wp.sqrt(wp.max(s, floor))
            sg = sgn(e)
            x = sg * wp.min(b, d) - v
            # c = clamp(x, -a, a)
            adj_x = zero
            if x < -a:
                adj_a = adj_a - adj_c
            elif x > a:
                adj_a = adj_a + adj_c
            else:
                adj_x = adj_c
            adj_v = adj_v - adj_x
            adj_m = sg * adj_x
            adj_b = zero
            adj_d = zero
            if b < d:
                adj_b = adj_m
            elif d < b:
                adj_d = adj_m
            else:
                adj_b = half * adj_m
                adj_d = half * adj_m
            if s >= floor:
                adj_s = adj_b * half / b
                adj_a = adj_a + two * d * adj_s
                adj_d = adj_d + two * a * adj_s
            adj_e = sg * adj_d
            adj_goal_out[r, i] = adj_e
            adj_p = adj_p - adj_e
        adj_goal_out[r0, i] = adj_goal_out[r0, i] + adj_p  # the start: p = goal[r0], v = 0
        adj_accel_out[j, i] = adj_a

    return forward, adjoint


def profile_modules(dtype: torch.dtype = torch.float32) -> list:
    """The Warp modules of the goal profile's forward and adjoint kernels (a robot with servo drives loads them), for
    compiling ahead (:func:`wresdyn.sim.warmup.warm_up`)."""
    return [k.module for k in _kernels(dtype)]


def _launch(kernel, dim, device: torch.device, *tensors) -> None:
    import warp as wp

    args = [wp.from_torch(t.detach().contiguous()) for t in tensors]
    if device.type == "cuda":
        with wp.ScopedStream(wp.stream_from_torch(torch.cuda.current_stream(device))):
            wp.launch(kernel, dim=dim, inputs=args, device=wp.device_from_torch(device))
    else:
        wp.launch(kernel, dim=dim, inputs=args, device="cpu")


class _Profile(torch.autograd.Function):
    """Goals (R, n) of targets (R, n) with accelerations (n,) > 0 over the trajectories [start, end) (J,) int32."""

    @staticmethod
    def forward(ctx, targets, accel, start, end):
        targets, accel = targets.contiguous(), accel.contiguous()
        forward, _ = _kernels(targets.dtype)
        pos, vel = torch.empty_like(targets), torch.empty_like(targets)
        _launch(forward, (len(start), targets.shape[1]), targets.device, targets, start, end, accel, pos, vel)
        ctx.save_for_backward(targets, accel, start, end, pos, vel)
        return pos

    @staticmethod
    def backward(ctx, adj_pos):
        targets, accel, start, end, pos, vel = ctx.saved_tensors
        _, adjoint = _kernels(targets.dtype)
        adj_goal = torch.zeros_like(targets)
        adj_accel = torch.zeros(len(start), targets.shape[1], dtype=targets.dtype, device=targets.device)
        _launch(adjoint, (len(start), targets.shape[1]), targets.device, targets, start, end, accel, pos, vel,
                adj_pos.to(targets.dtype).contiguous(), adj_goal, adj_accel)
        return adj_goal, adj_accel.sum(0), None, None


def profile_goals(targets: torch.Tensor, first: torch.Tensor, accel: torch.Tensor) -> torch.Tensor:
    """Servo goals for the targets of a concatenated table: each trajectory's goal starts at rest on its first target
    and follows :func:`~wresdyn.robot.servo.profile_step`; joints with ``accel`` 0 follow the targets.

    Args:
        targets: Delayed commands [rad], (R, n) float32 or float64: trajectories concatenated along time.
        first: First row of each row's trajectory, (R,) long.
        accel: Goal acceleration limit per joint [rad/step²], (n,) (differentiable).

    Returns:
        Goals [rad], (R, n), differentiable in ``targets`` and ``accel``.
    """
    starts = torch.unique_consecutive(first)
    ends = torch.cat([starts[1:], torch.tensor([len(first)], device=first.device)])
    on = accel > 0
    a = torch.where(on, accel, torch.ones_like(accel)).to(targets.dtype)
    goals = _Profile.apply(targets, a, starts.to(torch.int32), ends.to(torch.int32))
    return torch.where(on, goals, targets)
