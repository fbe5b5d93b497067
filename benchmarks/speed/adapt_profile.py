"""Where an online update's time goes (``wresdyn adapt``'s :class:`~wresdyn.adapt.adapter.Adapter`), per part.

    PYTHONPATH=. python benchmarks/speed/adapt_profile.py [--device cuda] [--set NAME=VALUE ...] [--cprofile N] [--kernels N]

Streams the shipped validation and held-out trajectories (``data/dataset.npz``, 32 s at 500 Hz) through an adapter
warm-started from ``benchmarks/results/grey_box/soft_friction`` (the realtime command of ``docs/adaptation.md``) and
times each part of every update (the Adam steps, the held-back open-loop replay, the one-step errors, the effort
grid), synchronising the GPU around each part so that a part's time is its own. The first update (kernel loads,
on a fresh machine the compiles) is reported apart. ``--cprofile N``: the N functions with the most own time over the
later updates.
``--kernels N`` (CUDA): N later updates run under ``torch.profiler`` (CUPTI sees Warp's kernels as well as torch's);
each kernel is counted in the part whose synchronised interval holds its start, by kind (the replay solver's forward,
its adjoint, Warp's other kernels, copies and memsets, torch), with its GPU time: a part's wall-clock against its
kernels' busy time tells how much of it is work and how much the host's launches and synchronisations.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time
from pathlib import Path

import numpy as np

from profile_gradfit import kernel_kind  # this folder: the same grouping of kernels by name

ROOT = Path(__file__).resolve().parents[2]
PARTS = ("_steps", "_open_loop", "_one_step", "_effort_grid")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="AdaptConfig fields")
    p.add_argument("--run", default=str(ROOT / "benchmarks/results/grey_box/soft_friction"))
    p.add_argument("--data", default=str(ROOT / "data/dataset.npz"))
    p.add_argument("--cprofile", type=int, default=0)
    p.add_argument("--kernels", type=int, default=0, metavar="N", help="CUDA: profile N later updates' kernels")
    args = p.parse_args()

    import torch

    from wresdyn.adapt.adapter import Adapter
    from wresdyn.adapt.config import AdaptConfig
    from wresdyn.adapt.stream import dataset_blocks
    from wresdyn.cli.command import CommandLineError, ConfigRefused, parse
    from wresdyn.data.loading import load_data
    from wresdyn.learn.runs import run_physics

    flags = [t for item in args.set for t in ("--" + item.partition("=")[0].replace("_", "-"),
                                               *item.partition("=")[2].split(","))]
    try:  # NAME=VALUE items as AdaptConfig's flags (a list's items comma-separated)
        cfg = parse(AdaptConfig, flags + ["--device", args.device], prog="adapt_profile.py --set")
    except (CommandLineError, ConfigRefused) as e:
        p.error(str(e))
    ds, robot = load_data(args.data)
    adapter = Adapter(robot, run_physics(args.run, robot), ds.rate_hz, cfg)
    cuda = str(adapter.device).startswith("cuda")
    if args.kernels and not cuda:
        p.error("--kernels needs a CUDA device (--device cuda)")
    spent = {k: [] for k in PARTS}

    def timed(name, fn):
        def wrapper(*a, **kw):
            if cuda:
                torch.cuda.synchronize()
            t0 = time.perf_counter()
            with torch.profiler.record_function(f"part:{name}"):
                out = fn(*a, **kw)
                if cuda:
                    torch.cuda.synchronize()
            spent[name].append((len(adapter.updates), time.perf_counter() - t0))
            return out
        return wrapper

    for name in PARTS:
        setattr(adapter, name, timed(name, getattr(adapter, name)))
    prof = cProfile.Profile() if args.cprofile else None
    kspan = (1, 1 + args.kernels)  # the updates profiled: after the first (its compiles and loads)
    kprof = kernels = None
    streamed, t_all = 0.0, time.perf_counter()
    for t, q, qd, q_cmd in dataset_blocks(ds, ["validation", "heldout"]):
        for i in range(0, len(t), 50):  # 0.1 s blocks, as a live stream delivers them
            if prof is not None and len(adapter.updates) >= 1:
                prof.enable()
            if args.kernels and kprof is None and kernels is None and len(adapter.updates) == kspan[0]:
                kprof = _start_kernels()
            elif kprof is not None and len(adapter.updates) >= kspan[1]:
                kernels, kprof = _stop_kernels(kprof, len(adapter.updates) - kspan[0]), None
            adapter.push(t[i:i + 50], q[i:i + 50], qd[i:i + 50], q_cmd[i:i + 50])
            if prof is not None:
                prof.disable()
        streamed += len(t) / ds.rate_hz
    wall = time.perf_counter() - t_all
    ups = adapter.updates
    comp = np.array([u.compute for u in ups])
    print(f"device {adapter.device} ({torch.cuda.get_device_name() if cuda else 'CPU'}), torch threads "
          f"{torch.get_num_threads()}; {streamed:.1f} s streamed, {len(ups)} updates, wall {wall:.1f} s")
    print(f"first update {comp[0]:.2f} s; later updates mean {comp[1:].mean():.3f} s, median "
          f"{np.median(comp[1:]):.3f}, max {comp[1:].max():.3f}; real-time factor without the first "
          f"{(len(ups) - 1) * cfg.update_every / comp[1:].sum():.2f}, with it {streamed / comp.sum():.2f}")
    total = comp[1:].sum()
    for name in PARTS:
        later = [s for k, s in spent[name] if k >= 1]
        if later:
            print(f"  {name:13s} {len(later):3d} calls, {np.mean(later) * 1e3:7.1f} ms each, "
                  f"{sum(later) / total:5.1%} of the later updates' compute")
    parts = sum(sum(s for k, s in spent[n] if k >= 1) for n in PARTS)
    print(f"  (rest: buffers, decisions, publishing: {1 - parts / total:.1%})")
    if args.kernels:
        if kprof is not None:  # the stream ended first
            kernels = _stop_kernels(kprof, len(adapter.updates) - kspan[0])
        _print_kernels(kernels, spent, comp, kspan[0])
    if prof is not None:
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(args.cprofile)
        print(buf.getvalue())


def _start_kernels():
    import torch

    torch.cuda.synchronize()
    # CPU activity too: the parts' record_function ranges, in the same clock as the kernels
    prof = torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU,
                                              torch.profiler.ProfilerActivity.CUDA])
    prof.__enter__()
    return prof


def _stop_kernels(prof, updates: int) -> dict:
    """{part: {kind: [count, GPU seconds]}} of the profiled updates' kernels, each in the part whose range (host
    time, the device synchronised at its start and end) holds its start; "(between parts)" where none does."""
    import torch

    torch.cuda.synchronize()
    prof.__exit__(None, None, None)
    events = prof.events()
    ranges = [(e.name[len("part:"):], e.time_range.start, e.time_range.end) for e in events
              if e.name.startswith("part:")]
    out: dict = {"updates": updates}
    for e in events:
        if e.device_type != torch.autograd.DeviceType.CUDA or e.name.startswith("part:"):
            continue
        at = e.time_range.start
        part = next((r[0] for r in ranges if r[1] <= at <= r[2]), "(between parts)")
        row = out.setdefault(part, {}).setdefault(kernel_kind(e.name), [0, 0.0])
        row[0] += 1
        row[1] += e.device_time * 1e-6  # us -> s
    return out


def _print_kernels(kernels: dict, spent: dict, comp: np.ndarray, first: int) -> None:
    """Per update, each part's kernels and their GPU time against the part's wall-clock over the updates after the
    profiled ones (the profiler slows the host down)."""
    n = kernels.pop("updates", 0)
    if not n:
        print("kernels: no update profiled")
        return
    after = first + n  # the updates timed unprofiled
    print(f"\nkernels of updates {first}..{after - 1}, per update; wall-clock of the {len(comp) - after} after them")
    print("| part | wall [ms] | kernels | GPU busy [ms] | solver forward | solver adjoint | torch | other |")
    print("|---|---|---|---|---|---|---|---|")
    walls = {p: sum(s for k, s in spent[p] if k >= after) / max(len(comp) - after, 1) for p in PARTS}
    walls["(between parts)"] = comp[after:].mean() - sum(walls.values()) if len(comp) > after else float("nan")
    for part in (*PARTS, "(between parts)"):
        rows = kernels.get(part, {})
        busy = {k: 1e3 * v[1] / n for k, v in rows.items()}
        other = sum(v for k, v in busy.items() if k not in ("solver forward", "solver adjoint", "torch"))
        print(f"| {part} | {1e3 * walls[part]:.1f} | {sum(v[0] for v in rows.values()) / n:.0f} | "
              f"{sum(busy.values()):.1f} | {busy.get('solver forward', 0):.1f} | {busy.get('solver adjoint', 0):.1f} | "
              f"{busy.get('torch', 0):.1f} | {other:.1f} |")
    count = sum(v[0] for rows in kernels.values() for v in rows.values()) / n
    busy = sum(v[1] for rows in kernels.values() for v in rows.values()) / n
    print(f"| update | {1e3 * comp[after:].mean():.1f} | {count:.0f} | {1e3 * busy:.1f} | | | | |")

if __name__ == "__main__":
    main()
