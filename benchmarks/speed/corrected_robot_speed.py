"""Floating-base env-steps/s of the calibrated robot against the nominal one, on the floor, in one run.

Both robots stand on a ground plane in plain Newton with ``SolverMuJoCo`` (MuJoCo C on the CPU with one world;
mujoco_warp on CUDA), 500 Hz, holding the neutral pose:
- nominal: the robot file, its own joint drives (MuJoCo position actuators);
- calibrated: ``wresdyn export``'s ``actuated.usda``: identified physics, the drive path in ``model.actuators``
  (PD, delay, effort clamping) and the residual network (:class:`~wresdyn.export.residual_torque.ResidualTorque`,
  torch) every step.
On CUDA each is captured as one CUDA graph of two steps (Warp's capture on its stream, torch's residual ops
issued on the same stream after a warm-up has filled torch's allocator cache); ``--no-graph`` times plain launches. The ratio is the residual's and the actuators' cost.

    python benchmarks/speed/corrected_robot_speed.py runs/fit/export --device cpu --worlds 1
    python benchmarks/speed/corrected_robot_speed.py runs/fit/export --device cuda:0 --worlds 1024 4096
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]


def measure(usd: str, worlds: int, device: str, steps: int, graph: bool, residual_on: bool) -> dict:
    import torch
    import warp as wp

    from wresdyn.export.residual_torque import ResidualTorque

    spec = importlib.util.spec_from_file_location("standing", REPO / "examples" / "corrected_robot_standing.py")
    standing = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(standing)
    dt = 0.002
    model, solver = standing.build(usd, worlds, device)
    states = [model.state(), model.state()]
    control = model.control()
    standing.stand(model, states[0])
    acts = list(model.actuators)
    ast = [[a.state() for a in acts], [a.state() for a in acts]]
    res = ResidualTorque.from_usd(usd, model, dt) if residual_on else None
    if res is not None:
        res.reset()

    def step(i: int) -> None:  # state i -> state 1 - i
        s0, s1 = states[i], states[1 - i]
        if acts:
            control.joint_f.zero_()
            for a, sa, sb in zip(acts, ast[i], ast[1 - i]):
                a.step(s0, control, sa, sb, dt=dt)
        if res is not None:
            res.apply(s0, control, wp.to_torch(control.joint_target_q)[res.q_index])
        solver.step(s0, s1, control, None, dt)

    def pair() -> None:
        step(0)
        step(1)

    cuda = device.startswith("cuda")
    run, captured, err = pair, False, ""
    if cuda:
        torch_stream = torch.cuda.Stream(device=wp.device_to_torch(device))
        warp_stream = wp.stream_from_torch(torch_stream)
        with torch.cuda.stream(torch_stream), wp.ScopedStream(warp_stream):
            for _ in range(3):  # warm up: compile, first allocations
                pair()
        torch.cuda.synchronize()
        if graph:
            try:  # Warp opens the capture on its stream; torch's ops of the residual run on the same stream
                with torch.cuda.stream(torch_stream), wp.ScopedStream(warp_stream):
                    with wp.ScopedCapture(stream=warp_stream) as cap:
                        pair()
                run, captured = (lambda: wp.capture_launch(cap.graph, stream=warp_stream)), True
            except Exception as e:  # report, time without the graph
                err = f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"

        def timed() -> None:
            with torch.cuda.stream(torch_stream), wp.ScopedStream(warp_stream):
                run()
    else:
        for _ in range(3):
            pair()
        timed = run
    sync = torch.cuda.synchronize if cuda else (lambda: None)
    sync()
    t0 = time.perf_counter()
    for _ in range(steps // 2):
        timed()
    sync()
    wall = time.perf_counter() - t0
    z = states[0].joint_q.numpy().reshape(worlds, -1)[:, 2]
    return {"worlds": worlds, "steps": 2 * (steps // 2), "wall_s": wall,
            "env_steps_per_s": worlds * 2 * (steps // 2) / wall, "graph": captured, "graph_error": err,
            "base_height_mean": float(np.nanmean(z)), "non_finite_worlds": int((~np.isfinite(z)).sum())}


def main() -> None:
    import torch
    import warp as wp

    wp.config.quiet = True
    torch.set_num_threads(1)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("export", help="folder written by `wresdyn export`")
    p.add_argument("--device", default="cpu")
    p.add_argument("--worlds", type=int, nargs="+", default=[1])
    p.add_argument("--steps", type=int, default=500, help="solver steps timed per configuration")
    p.add_argument("--no-graph", action="store_true")
    args = p.parse_args()
    info = json.loads((Path(args.export) / "export.json").read_text())
    nominal = info["robot_file"] if Path(info["robot_file"]).exists() else str(REPO / info["robot_file"])
    calibrated = str(Path(args.export) / "actuated.usda")
    print(f"device {args.device}, dt 0.002 s, SolverMuJoCo ({'MuJoCo C' if args.device == 'cpu' else 'mujoco_warp'}),"
          f" free base on a ground plane, {args.steps} steps")
    for w in args.worlds:
        a = measure(nominal, w, args.device, args.steps, not args.no_graph, False)
        b = measure(calibrated, w, args.device, args.steps, not args.no_graph, True)
        for name, r in (("nominal", a), ("calibrated", b)):
            print(f"{name:>10} {w:6d} worlds: {r['env_steps_per_s']:12,.0f} env-steps/s  graph {r['graph']}"
                  f"{' (' + r['graph_error'] + ')' if r['graph_error'] else ''}  base z {r['base_height_mean']:.3f} m"
                  f"  non-finite {r['non_finite_worlds']}", flush=True)
        print(f"{'':>10} {w:6d} worlds: calibrated / nominal = {b['env_steps_per_s'] / a['env_steps_per_s']:.2f}")


if __name__ == "__main__":
    main()
