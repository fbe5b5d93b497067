"""The replay solver against one GPU's physical limit: env-steps/s, mujoco_warp's own benchmark, and the step kernel's
achieved memory bandwidth and FLOP rate against the card's peak, in one process (docs/performance.md).

    python benchmarks/speed/physical_limit.py OUT --device cuda:0 --worlds 4096,16384
    python benchmarks/speed/physical_limit.py OUT --device cpu --worlds 16 --min-time 0.2   # every path, no figures

Per world count: (1) forward env-steps/s of ``wresdyn bench``'s rows ``replay rollout`` and ``replay step``, by its
own code (:mod:`wresdyn.sim.solver_benchmark`). (2) ``mjwarp-testspeed`` (``python -m mujoco_warp.testspeed``) on
mujoco_warp's own humanoid (free base, floor contacts: another workload), ``--nworld N --format json
--overflow_behavior=continue`` (its default, ``error``, aborts the run at the first world whose line search reaches
its iteration cap: ``--mjw-overflow error`` keeps that), raw output kept. (3) ``SolverReplay.step``'s kernel alone, launched eagerly, timed by Warp's CUDA activity timing (CPU: the
wall-clock of a synchronised step). Bytes: the distinct per-world array elements the generated kernel loads and
stores, each once, a lower bound of the compulsory traffic (L2, 50 MB on H100 and H200, may hold a small run's arrays
between launches). FLOPs: the kernel is straight-line scalar code (:mod:`wresdyn.sim.solver_replay.codegen`), so
each ``+ - * /`` in it is one FLOP per world (the friction block only where the robot has friction; calls such as
sin, cos, min are listed, not counted). Peaks: NVIDIA's datasheets; other devices null. A failing part records its
error and the run goes on; OUT/physical_limit.json is rewritten after every part.
"""

from __future__ import annotations

import argparse
import ast
import json
import shlex
import subprocess
import sys
import time
from collections import Counter
from importlib.util import find_spec
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[2]
PEAKS = {"H200": (4800.0, 67.0), "H100 80GB HBM3": (3350.0, 67.0)}
"""Device name part -> (HBM bandwidth [GB/s], FP32 [TFLOP/s]), NVIDIA's datasheets (H100 SXM: "H100 80GB HBM3")."""
FIELDS = ("replay_env_steps_per_s", "mujoco_warp_steps_per_s", "replay_step_kernel_s", "bytes_per_world_step",
          "achieved_gb_per_s", "fraction_of_peak_bandwidth", "flops_per_world_step", "achieved_tflops",
          "fraction_of_peak_flops")
"""Each row's figures (None until measured; ``<part>_error`` says why one is missing)."""
BINOPS = {ast.Add: "add", ast.Sub: "sub", ast.Mult: "mul", ast.Div: "div"}
LS_WARNING = "linesearch iterations limit reached"
"""The line mujoco_warp prints where a line search reaches its iteration cap (``--overflow_behavior=continue``)."""


def count_code(source: str, friction: bool) -> tuple[dict, float]:
    """Arithmetic of ``replay_step`` and the module functions it calls (``+ - * /`` by kind, calls by name; the
    ``if fric_on:`` block only where ``friction``), and the bytes of the distinct per-world array elements its code
    loads and stores (``name[index]`` with a world-dependent index; float32 scalar 4 B, vec3 12 B, mat33 36 B)."""
    funcs = {f.name: f for f in ast.parse(source).body if isinstance(f, ast.FunctionDef)}
    size = {a.arg: {"S": 4, "V3": 12, "M33": 36, "int32": 4}.get(ast.unparse(a.annotation).split("dtype=")[-1]
                                                                  .strip(")").split(".")[-1], 0)
            for a in funcs["replay_step"].args.args}
    ops, elements = Counter(), set()

    def walk(node):
        if isinstance(node, ast.If) and ast.unparse(node.test) == "fric_on" and not friction:
            return
        if isinstance(node, ast.Assign) and ast.unparse(node.targets[0]) in ("w", "bq", "bd", "bb"):
            return  # the world's integer offsets: no FLOPs
        if isinstance(node, ast.Subscript):  # an array element (its index's integer arithmetic is no FLOP)
            if (name := ast.unparse(node.value)) in size and any(isinstance(x, ast.Name) for x in ast.walk(node.slice)):
                elements.add((name, ast.unparse(node.slice)))  # a constant index is shared by the worlds: left out
            return
        if isinstance(node, (ast.BinOp, ast.AugAssign)) and type(node.op) in BINOPS:
            ops[BINOPS[type(node.op)]] += 1
        if isinstance(node, ast.Call):
            for stmt in getattr(funcs.get(name := ast.unparse(node.func).split(".")[-1]), "body", ()):
                walk(stmt)  # a helper's code runs at each call
            if name not in funcs and name not in ("S", "V3", "M33", "tid"):
                ops["call " + name] += 1
        for child in ast.iter_child_nodes(node):
            walk(child)

    for stmt in funcs["replay_step"].body:
        walk(stmt)
    return dict(ops), float(sum(size[name] for name, _ in elements))


def part(res: dict, key: str, fn, *a):
    """Run one measurement; on failure record its error under ``key + '_error'`` and go on."""
    print(f"worlds {res['worlds']}: {key}", flush=True)
    t = time.perf_counter()
    try:
        return fn(*a)
    except Exception as exc:  # one failing part must not lose the others
        res[key + "_error"] = f"{type(exc).__name__}: {exc}"[:500]
        print(f"  {key}: FAILED {res[key + '_error']}", flush=True)
    finally:
        print(f"  {key}: {time.perf_counter() - t:.1f} s", flush=True)


def replay_rates(b, w: int, steps: int) -> dict:
    """Forward env-steps/s of ``wresdyn bench``'s two replay rows."""
    return {"rollout": b.rollout(w, False),
            "step": b.step_api(lambda model: b.replay(model, "replay step", w), w, steps, False)}


def step_kernel(b, robot, w: int, repeat: int, row: dict) -> None:
    """Into ``row``: the step kernel's bytes and FLOPs per world step, then its time per launch (median)."""
    import numpy as np
    import warp as wp

    dev, dt = b.args.device, b.args.dt
    model = robot.build_model(w, dev)
    solver = b.replay(model, "kernel", w)
    a, o = b.states(model, w, 2, False)
    ctrl = b.control(model, w)
    arrays = {f"parameters.{k}": v for k, v in solver.parameters.items()}
    arrays |= {f"state_in.{k}": getattr(a, k) for k in ("joint_q", "joint_qd")}
    arrays |= {f"control.{k}": getattr(ctrl, k) for k in ("joint_target_q", "joint_target_qd", "joint_f")}
    arrays |= {f"state_out.{k}": getattr(o, k) for k in ("joint_q", "joint_qd")}
    per = {k: v.size * wp.types.type_size_in_bytes(v.dtype) / w for k, v in arrays.items()}
    friction = bool(np.any(model.joint_friction.numpy() != 0.0))
    ops, touched = count_code(Path(solver.kernels.__file__).read_text(), friction)
    row |= {"bytes_per_world_step": touched, "bytes_of_arrays_per_world_step": sum(per.values()),
            "bytes_of_arrays_by_name": per, "flops_per_world_step": sum(v for k, v in ops.items() if " " not in k),
            "ops_per_world_step": ops, "friction_solve_counted": friction}
    for _ in range(3):  # compile and warm up
        solver.step(a, o, ctrl, None, dt)
    wp.synchronize_device(dev)
    if b.cuda:
        wp.timing_begin(cuda_filter=wp.TIMING_KERNEL)
        for _ in range(repeat):
            solver.step(a, o, ctrl, None, dt)
        found = wp.timing_end()  # the loop launches the step kernel only (its name: kernel_names)
        times, timer = [r.elapsed * 1e-3 for r in found], "CUDA activity (wp.timing_begin, TIMING_KERNEL)"
        row["kernel_names"] = sorted({r.name for r in found})
    else:
        times, timer = [], "wall-clock of one synchronised step (CPU: no CUDA activity)"
        for _ in range(repeat):
            t = time.perf_counter()
            solver.step(a, o, ctrl, None, dt)
            wp.synchronize_device(dev)
            times.append(time.perf_counter() - t)
    if not times:
        raise RuntimeError("no kernel among the timed CUDA activity")
    row |= {"replay_step_kernel_s": float(np.median(times)), "kernel_launches_timed": len(times), "timer": timer}


def mujoco_warp(out: Path, device: str, w: int, nstep: int, timeout: float, overflow: str = "continue",
                extra: tuple[str, ...] = ()) -> dict:
    """``mjwarp-testspeed`` on mujoco_warp's humanoid at ``w`` worlds: its raw output kept, its steps/s read.

    ``overflow``: its ``--overflow_behavior``. With ``error`` (its default) one world whose line search reaches its
    iteration cap (``LS_ITERATIONS``) aborts the whole run; ``continue`` times every step and prints a warning line
    per such line search instead, counted here (``mujoco_warp_overflow_warnings``). ``extra``: more flags, as given.
    """
    xml = Path(find_spec("mujoco_warp").origin).parent / "test_data" / "humanoid" / "humanoid.xml"
    cmd = [sys.executable, "-m", "mujoco_warp.testspeed", str(xml), f"--nworld={w}", f"--nstep={nstep}",
           "--format=json", f"--device={device}", f"--overflow_behavior={overflow}", *extra]
    print(f"  {' '.join(cmd)} (timeout {timeout:.0f} s)", flush=True)
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        rc, stdout, stderr = p.returncode, p.stdout, p.stderr
    except subprocess.TimeoutExpired as exc:
        text = [x.decode(errors="replace") if isinstance(x, bytes) else x or "" for x in (exc.stdout, exc.stderr)]
        rc, stdout, stderr = "timeout", text[0], text[1] + f"\ntimed out after {timeout} s"
    warnings = stdout.count(LS_WARNING)
    raw = out / f"mjwarp_testspeed_{w}.txt"
    raw.write_text(f"$ {' '.join(cmd)}\n# exit {rc}\n## stdout\n{shorten(stdout)}\n## stderr\n{shorten(stderr)}")
    res = {"mujoco_warp_command": " ".join(cmd), "mujoco_warp_raw": raw.name, "mujoco_warp_overflow_behavior": overflow,
           "mujoco_warp_overflow_warnings": warnings}
    line = next((x for x in reversed(stdout.splitlines()) if x.startswith("{")), None)
    if rc != 0 or line is None:
        last = [x for x in (stderr + "\n" + stdout).splitlines() if x.strip()]
        return res | {"mujoco_warp_error": f"exit {rc}: {last[-1] if last else 'no output'}"[:500]}
    report = json.loads(line)
    return res | {"mujoco_warp_steps_per_s": report["steps_per_second"], "mujoco_warp_report": report}


def shorten(text: str, keep: int = 100) -> str:
    """``text`` whole up to ``2 * keep`` lines, else its first and last ``keep`` lines around a count of the rest (with
    ``continue`` the overflow warnings can run to thousands of lines)."""
    lines = text.splitlines()
    if len(lines) <= 2 * keep:
        return text
    return "\n".join([*lines[:keep], f"[... {len(lines) - 2 * keep} lines left out ...]", *lines[-keep:]]) + "\n"


def commit() -> str:
    def git(*a):
        try:
            return subprocess.run(["git", "-C", str(ROOT), *a], capture_output=True, text=True).stdout.strip()
        except OSError:  # no git where it runs
            return ""
    return (git("rev-parse", "--short", "HEAD") or "unknown (no git checkout: see --commit)") + (
        " (uncommitted changes)" if git("status", "--porcelain", "-uno") else "")


def table(res: dict) -> str:
    def f(x, scale=1.0, fmt=".3g"):
        return "n/a" if x is None else format(x / scale, fmt)

    head = ("worlds", "replay rollout [M env-steps/s]", "replay step [M env-steps/s]", "mujoco_warp humanoid "
            "[M steps/s]", "step kernel [us]", "B / world step", "GB/s", "of peak", "FLOP / world step", "TFLOP/s",
            "of peak")
    lines = [f"{res['device']} ({res['device_name']}); peak {f(res['peak_gb_per_s'])} GB/s, FP32 "
             f"{f(res['peak_tflops'])} TFLOP/s ({res['peak_source']}); commit {res['commit']}",
             "| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    for r in res["rows"]:
        rate = r.get("replay_env_steps_per_s") or {}
        lines.append(f"| {r['worlds']} | {f(rate.get('rollout'), 1e6)} | {f(rate.get('step'), 1e6)} | "
                     f"{f(r.get('mujoco_warp_steps_per_s'), 1e6)} | {f(r.get('replay_step_kernel_s'), 1e-6)} | "
                     f"{f(r.get('bytes_per_world_step'), 1, '.0f')} | {f(r.get('achieved_gb_per_s'))} | "
                     f"{f(r.get('fraction_of_peak_bandwidth'), 0.01, '.2g')} % | "
                     f"{f(r.get('flops_per_world_step'), 1, '.0f')} | {f(r.get('achieved_tflops'))} | "
                     f"{f(r.get('fraction_of_peak_flops'), 0.01, '.2g')} % |")
    errors = [f"- {r['worlds']} worlds, {k}: {v}" for r in res["rows"] for k, v in r.items() if k.endswith("_error")]
    return "\n".join(lines + (["", "errors:", *errors] if errors else [])) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", help="output folder")
    p.add_argument("--device", default="cuda:0")  # a Warp device
    p.add_argument("--worlds", default="4096,16384", help="comma-separated world counts")
    p.add_argument("--steps", type=int, default=200, help="steps per forward measurement (as wresdyn bench)")
    p.add_argument("--min-time", type=float, default=0.5, help="seconds each env-steps/s measurement is timed")
    p.add_argument("--repeat", type=int, default=50, help="step kernel launches timed")
    p.add_argument("--nstep", type=int, default=1000, help="mjwarp-testspeed --nstep")
    p.add_argument("--budget", type=float, default=540.0, help="seconds for the run: what is left bounds mjwarp")
    p.add_argument("--commit", default=None, help="the commit to record (default: the checkout's, from git)")
    p.add_argument("--mjw-timeout", type=float, default=300.0, help="seconds one mjwarp-testspeed run may take")
    p.add_argument("--mjw-overflow", choices=("continue", "error"), default="continue",
                   help="mjwarp-testspeed --overflow_behavior: 'error' (its default) aborts the run at the first "
                        "world whose line search reaches its cap; 'continue' times every step")
    p.add_argument("--mjw-args", default="",
                   help="more mjwarp-testspeed flags, one string (e.g. '-o opt.ls_iterations=100')")
    args = p.parse_args()
    start = time.perf_counter()
    import warp as wp

    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
    from wresdyn.sim.solver_benchmark import _Bench

    wp.config.quiet = True
    (out := Path(args.out)).mkdir(parents=True, exist_ok=True)
    worlds = [int(x) for x in args.worlds.split(",")]
    dev = wp.get_device(args.device)
    src = next((k for k in PEAKS if k in dev.name), None)
    bw, fl = PEAKS.get(src, (None, None))
    res = {"device": str(dev), "device_name": dev.name, "worlds": worlds, "commit": args.commit or commit(),
           "command": " ".join([Path(sys.executable).name, *sys.argv]), "peak_gb_per_s": bw, "peak_tflops": fl,
           "peak_source": f"NVIDIA {src} datasheet" if src else "device not in the script's table", "rows": []}

    def save():
        (out / "physical_limit.json").write_text(json.dumps(res, indent=1))
        (out / "physical_limit.txt").write_text(table(res))

    robot = load_robot(DEFAULT_ROBOT)
    bench = _Bench(SimpleNamespace(device=args.device, threads=1, dt=0.002, min_time=args.min_time, steps=args.steps,
                                   horizon=32, adjoint="auto"), robot)
    for w in worlds:
        row = {"worlds": w} | dict.fromkeys(FIELDS)
        res["rows"].append(row)
        row["replay_env_steps_per_s"] = part(row, "replay_env_steps_per_s", replay_rates, bench, w, args.steps)
        save()
        part(row, "replay_step_kernel", step_kernel, bench, robot, w, args.repeat, row)
        if s := row["replay_step_kernel_s"]:  # bytes and FLOPs of all worlds in one launch's time
            row |= {"achieved_gb_per_s": row["bytes_per_world_step"] * w / s / 1e9,
                    "achieved_tflops": row["flops_per_world_step"] * w / s / 1e12}
            row["fraction_of_peak_bandwidth"] = row["achieved_gb_per_s"] / bw if bw else None
            row["fraction_of_peak_flops"] = row["achieved_tflops"] / fl if fl else None
        save()
    for row in res["rows"]:
        left = max(1.0, min(args.mjw_timeout, args.budget - (time.perf_counter() - start)))  # out of budget: 1 s
        row |= part(row, "mujoco_warp", mujoco_warp, out, args.device, row["worlds"], args.nstep, left,
                    args.mjw_overflow, tuple(shlex.split(args.mjw_args))) or {}
        save()
    print(table(res), flush=True)
    print(f"total {time.perf_counter() - start:.0f} s; wrote {out / 'physical_limit.json'}", flush=True)


if __name__ == "__main__":
    main()
