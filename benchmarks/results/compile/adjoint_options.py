"""Cold compile time and speed of SolverReplay's modules under one set of code-generation and Warp module options.

usage: adjoint_options.py DEVICE WORLDS TAG [OPT_LEVEL|-] [INLINE:0|1|-] [MIN_LEN|-] [REFERENCE.npz]

Run in a fresh process with empty caches (WARP_CACHE_PATH, WRESDYN_KERNEL_DIR), with PYTHONPATH set to the tree to
measure (a script's own folder, not the current one, comes first on sys.path). Builds the humanoid in WORLDS worlds
(model arrays carrying gradients, as identification has them; friction 0.3 N m on every DoF so that the adjoint
differentiates the friction solve), compiles the forward module's rollout and the adjoint module's step kernel
(forward + backward), then times a Tape over a 32-step rollout (forward + backward, median and best of 7; CPU: per CPU-second) and saves the
gradients to /tmp/adjopt_TAG.npz; with REFERENCE, prints the largest relative difference to it.
OPT_LEVEL: Warp's ``optimization_level`` module option of the adjoint module's kernels ('-': Warp's default, -O2 CPU,
-O3 CUDA); INLINE: the ``inline`` hint of the outlined chunks ('-': the solver's choice); MIN_LEN: the chunk size.
"""
import functools
import os
import sys
import time

import numpy as np
import warp as wp

wp.config.quiet = True
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot  # noqa: E402
from wresdyn.sim.solver_replay import codegen, solver as solver_mod  # noqa: E402

device, worlds, tag = sys.argv[1], int(sys.argv[2]), sys.argv[3]
opt, inline, min_len = (sys.argv[4:7] + ["-"] * 3)[:3]
reference = sys.argv[7] if len(sys.argv) > 7 else None
if min_len != "-":
    codegen.outline = functools.partial(codegen.outline, min_len=int(min_len))
generate = codegen.generate_source


def patched(tree, scalar="float32", backward=True, inline_=None, **kw):
    hint = kw.pop("inline", inline_)
    if inline != "-":
        hint = bool(int(inline))
    src = generate(tree, scalar, backward, inline=hint, **kw)
    if backward and opt != "-":
        src = src.replace('@wp.kernel(enable_backward=True, module="unique")',
                          f'@wp.kernel(enable_backward=True, module="unique", module_options={{"optimization_level": {int(opt)}}})')
    return src


solver_mod.generate_source = patched
from wresdyn.sim.solver_replay import SolverReplay  # noqa: E402

wp.init()
t_start = time.perf_counter()
robot = load_robot(DEFAULT_ROBOT)
fwd_model = robot.build_model(worlds, device)
fwd = SolverReplay(fwd_model)
t0, c0 = time.perf_counter(), time.process_time()
if os.environ.get("ADJOPT_FORWARD", "1") != "0":  # 0: leave the forward module out (its options do not change)
    fwd.kernels.replay_rollout.module.load(wp.get_device(device))
t_fwd, c_fwd = time.perf_counter() - t0, time.process_time() - c0
model = robot.build_model(worlds, device, requires_grad=True)
model.joint_friction.assign(np.full(model.joint_dof_count, 0.3, np.float32))
solver = SolverReplay(model)
t0, c0 = time.perf_counter(), time.process_time()
solver.kernels.replay_step.module.load(wp.get_device(device))
t_adj, c_adj = time.perf_counter() - t0, time.process_time() - c0
print(f"{tag}: cold compile on {device}: forward rollout {t_fwd:.1f} s wall / {c_fwd:.1f} CPU-s, adjoint step (forward + "
      f"backward) {t_adj:.1f} s wall / {c_adj:.1f} CPU-s (options: optimization_level {opt}, inline {inline}, min_len "
      f"{min_len})", flush=True)

n, T = solver.tree.dofs_per_world, 32
span = np.where(np.isfinite(robot.upper - robot.lower), robot.upper - robot.lower, 2.0)
lo, hi = np.where(np.isfinite(robot.lower), robot.lower, -1.0), np.where(np.isfinite(robot.upper), robot.upper, 1.0)
q0 = np.clip(np.zeros(n), lo + 0.3 * span, hi - 0.3 * span)
amp = np.minimum(0.2, 0.12 * span)
t = np.arange(T)[:, None, None] * 0.002
f = np.linspace(0.3, 1.0, n)[None, None, :]
targ = (q0 + amp * np.sin(2 * np.pi * f * t + np.arange(worlds)[None, :, None] * 0.1)).astype(np.float32)
tq = wp.array(targ[:, :, robot.qd_index.argsort()], dtype=float, device=device, requires_grad=True)
qi = np.zeros((T + 1, worlds, n), np.float32)
qi[0] = q0[robot.q_index.argsort()] + 0.1
q = wp.array(qi, dtype=float, device=device, requires_grad=True)
qd = wp.zeros((T + 1, worlds, n), dtype=float, device=device, requires_grad=True)
jf = wp.zeros((T, worlds, n), dtype=float, device=device, requires_grad=True)
seed = np.zeros((T + 1, worlds, n), np.float32)
seed[T] = np.random.default_rng(0).normal(size=(worlds, n))
seed = wp.array(seed, device=device)
names = ("joint_target_ke", "joint_friction", "joint_armature", "body_mass", "body_inertia")


def fwd_bwd():
    for name in names:
        getattr(model, name).grad.zero_()
    tape = wp.Tape()
    with tape:
        solver.rollout(q, qd, tq, 0.002, joint_f=jf)
    tape.backward(grads={q: seed})
    wp.synchronize_device(device)
    return tape


timer = time.perf_counter if device.startswith("cuda") else time.process_time  # CPU: CPU-seconds, robust to load
times = []
for _ in range(8):
    t0 = timer()
    tape = fwd_bwd()
    times.append(timer() - t0)
    out = {"q": q.numpy(), "q0_grad": q.grad.numpy()[0], "qd0_grad": qd.grad.numpy()[0], "tq_grad": tq.grad.numpy(),
           "jf_grad": jf.grad.numpy(), **{name: getattr(model, name).grad.numpy() for name in names}}
    tape.zero()
rate, best = worlds * T / np.median(times[1:]), worlds * T / np.min(times[1:])
unit = "env-steps/s" if device.startswith("cuda") else "env-steps per CPU-second"
print(f"{tag}: Tape rollout forward + backward, {worlds} worlds x {T} steps: median {rate / 1e3:.1f}k, best "
      f"{best / 1e3:.1f}k {unit} (7 after one warm-up)", flush=True)
np.savez(f"/tmp/adjopt_{tag}.npz", **out)
if reference:
    ref = np.load(reference)
    worst = max(float(np.max(np.abs(out[k] - ref[k]) / (np.abs(ref[k]).max() + 1e-30))) for k in out)
    same = all(np.array_equal(out[k], ref[k]) for k in out)
    print(f"{tag}: against {reference}: {'bit-equal' if same else 'not bit-equal'}, largest difference / array's "
          f"largest magnitude {worst:.2e}", flush=True)
print(f"{tag}: total {time.perf_counter() - t_start:.1f} s", flush=True)
