"""Where an online update's time goes (``wresdyn adapt``'s :class:`~wresdyn.adapt.adapter.Adapter`), per part.

    PYTHONPATH=. python benchmarks/adapt_profile.py [--device cuda] [--set NAME=VALUE ...] [--cprofile N]

Streams the shipped validation and held-out trajectories (``data/dataset.npz``, 32 s at 500 Hz) through an adapter
warm-started from ``benchmarks/results/grey_box/soft_friction`` (the realtime command of ``docs/adaptation.md``) and
times each part of every update (the Adam steps, the held-back open-loop replay, the one-step errors, the effort
grid), synchronising the GPU around each part so that a part's time is its own. The first update (kernel loads,
on a fresh machine the compiles) is reported apart. ``--cprofile N``: the N functions with the most own time over the
later updates.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PARTS = ("_steps", "_open_loop", "_one_step", "_effort_grid")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="AdaptConfig fields")
    p.add_argument("--run", default=str(ROOT / "benchmarks/results/grey_box/soft_friction"))
    p.add_argument("--data", default=str(ROOT / "data/dataset.npz"))
    p.add_argument("--cprofile", type=int, default=0)
    args = p.parse_args()

    import torch

    from wresdyn.adapt.adapter import Adapter
    from wresdyn.adapt.config import AdaptConfig
    from wresdyn.adapt.stream import dataset_blocks
    from wresdyn.cli import UserError
    from wresdyn.cli.config_flags import build_config, parse_assignments
    from wresdyn.data.loading import load_data
    from wresdyn.learn.runs import run_physics

    try:
        cfg = build_config(AdaptConfig(), {**parse_assignments(AdaptConfig, args.set), "device": args.device})
    except UserError as e:
        p.error(str(e))
    ds, robot = load_data(args.data)
    adapter = Adapter(robot, run_physics(args.run, robot), ds.rate_hz, cfg)
    cuda = str(adapter.device).startswith("cuda")
    spent = {k: [] for k in PARTS}

    def timed(name, fn):
        def wrapper(*a, **kw):
            if cuda:
                torch.cuda.synchronize()
            t0 = time.perf_counter()
            out = fn(*a, **kw)
            if cuda:
                torch.cuda.synchronize()
            spent[name].append((len(adapter.updates), time.perf_counter() - t0))
            return out
        return wrapper

    for name in PARTS:
        setattr(adapter, name, timed(name, getattr(adapter, name)))
    prof = cProfile.Profile() if args.cprofile else None
    streamed, t_all = 0.0, time.perf_counter()
    for t, q, qd, q_cmd in dataset_blocks(ds, ["validation", "heldout"]):
        for i in range(0, len(t), 50):  # 0.1 s blocks, as a live stream delivers them
            if prof is not None and len(adapter.updates) >= 1:
                prof.enable()
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
    if prof is not None:
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(args.cprofile)
        print(buf.getvalue())


if __name__ == "__main__":
    main()
