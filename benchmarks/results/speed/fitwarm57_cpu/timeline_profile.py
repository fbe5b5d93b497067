"""Where a first ``wresdyn fit`` spends its seconds before its first iteration, from empty kernel caches.

    python benchmarks/speed/first_fit_profile.py [DATA] [--device cpu] [--cache DIR] [--full] [-- FIT FLAGS...]

Runs ``wresdyn fit DATA --device DEVICE`` in this process with an empty Warp kernel cache and an empty
generated-kernel folder (both temporary unless ``--cache DIR`` names a Warp cache to use and keep: a warm run, or one
``wresdyn warmup`` filled) and prints a timeline, seconds since the script started:

- the imports the command needs (torch, Warp and its ``init``, Newton, wresdyn's fit modules), each timed alone first;
- every call of the pipeline's stages (data load, robot build, kernel warm-up, the Newton check, simulators,
  the learners' starting validation, each stage's first iteration);
- every Warp module loaded, with the seconds spent compiling it (``compiled``) or loading it from the cache.

It stops after the first iteration of the first training loop (the hybrid fit's identification) unless ``--full``,
which runs the whole fit and marks each loop's first iteration (Ctrl-C ends it with the timeline so far). Flags after
``--`` go to ``wresdyn fit``.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import os
import sys
import tempfile
import time

T0 = time.perf_counter()

STAGES = (
    "wresdyn.data.loading:load_data",
    "wresdyn.robot.description:load_robot",
    "wresdyn.sim.warmup:compile_kernels",
    "wresdyn.sim.first_steps:check_newton",
    "wresdyn.sim.simulator:Simulator.__init__",
    "wresdyn.sim.solver_replay.kernels:load_kernels",
    "wresdyn.sim.solver_replay.kernels:compile_batch",
    "wresdyn.identify.sysid:identify",
    "wresdyn.identify.sysid:IdentifyLearner.begin",
    "wresdyn.identify.sysid:IdentifyLearner.step",
    "wresdyn.fit.gradfit:fit",
    "wresdyn.fit.gradfit:_FitLearner.begin",
    "wresdyn.fit.gradfit:_FitLearner.step",
    "wresdyn.identify.sysid:IdentifyLearner.__init__",
    "wresdyn.identify.sysid:PhysicsScore.__init__",
    "wresdyn.identify.sysid:PhysicsScore.__call__",
    "wresdyn.sim.physics:PhysicsModel.__init__",
    "torch.optim.adam:Adam.__init__",
    "wresdyn.sim.bank:TrajectoryBank.__init__",
    "wresdyn.learn.window_fit:start_window_fit",
    "wresdyn.learn.runs:RunFolder.__init__",
    "wresdyn.sim.rollout:replay_setup",
    "wresdyn.sim.rollout:run_replay",
)
"""``module:qualname`` of the calls the timeline times (the first few of each); a name missing from this tree is
skipped with a note."""


class Stop(Exception):
    """Raised from the first iteration's progress update to end the run there."""


def now() -> float:
    return time.perf_counter() - T0


EVENTS: list[tuple[float, float, str]] = []  # (start s, seconds, what)
COUNTS: dict[str, int] = {}


def timed(key: str, fn, keep: int = 4):
    @functools.wraps(fn)
    def wrapper(*a, **k):
        t = now()
        try:
            return fn(*a, **k)
        finally:
            COUNTS[key] = COUNTS.get(key, 0) + 1
            if COUNTS[key] <= keep:
                EVENTS.append((t, now() - t, f"call {key}"))
    return wrapper


def patch_stage(target: str) -> str | None:
    mod_name, qual = target.split(":")
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as e:
        return f"{target}: {e}"
    owner, attr = mod, qual
    if "." in qual:
        cls, attr = qual.split(".")
        owner = getattr(mod, cls, None)
    original = getattr(owner, attr, None) if owner is not None else None
    if original is None:
        return f"{target}: not in this tree"
    wrapped = timed(qual, original)
    setattr(owner, attr, wrapped)
    if owner is mod:  # modules that imported the name already
        for other in list(sys.modules.values()):
            if getattr(other, "__name__", "").startswith("wresdyn") and getattr(other, attr, None) is original:
                setattr(other, attr, wrapped)
    return None


def patch_warp() -> None:
    from warp._src import context

    load, compile_ = context.Module.load, context.Module._compile

    def timed_load(self, device, *a, **k):
        t = now()
        before = len(EVENTS)
        try:
            return load(self, device, *a, **k)
        finally:
            compiled = any(e[2].startswith(f"  compile {self.name} ") for e in EVENTS[before:])
            if compiled or now() - t > 0.05:
                how = "compiled" if compiled else "cached"
                EVENTS.append((t, now() - t, f"warp load {self.name} on {device} ({how})"))

    def timed_compile(self, device, *a, **k):
        t = now()
        done = compile_(self, device, *a, **k)
        if done:
            EVENTS.append((t, now() - t, f"  compile {self.name} on {device}"))
        return done

    context.Module.load, context.Module._compile = timed_load, timed_compile


def patch_progress(full: bool) -> None:
    from wresdyn import progress

    update = progress._Bar.update

    def first_update(self, n=1, note=None):
        if not getattr(self, "_profiled", False):
            self._profiled = True
            EVENTS.append((now(), 0.0, f"FIRST ITERATION of '{self.desc}' done"))
            if not full:
                raise Stop
        return update(self, n, note)

    progress._Bar.update = first_update


def main() -> None:
    argv = sys.argv[1:]
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    argv = argv[:argv.index("--")] if "--" in argv else argv
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data", nargs="?", default="data/dataset.npz")
    p.add_argument("--device", default="cpu")
    p.add_argument("--cache", default=None, help="Warp kernel cache to use and keep (default: a new empty one)")
    p.add_argument("--full", action="store_true", help="run the whole fit, not only to its first iteration")
    args = p.parse_args(argv)
    scratch = tempfile.mkdtemp(prefix="first_fit_")
    cache = args.cache or os.path.join(scratch, "warp")
    os.environ["WARP_CACHE_PATH"] = cache  # the compile workers read it too
    if not args.cache:
        os.environ["WRESDYN_KERNEL_DIR"] = os.path.join(scratch, "kernels")
    print(f"{now():7.2f}  python started; Warp cache {cache} ({'given' if args.cache else 'empty'}); "
          f"load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} cores", flush=True)
    for name in ("torch", "warp", "warp.init", "newton", "wresdyn.cli", "wresdyn.fit.gradfit", "wresdyn.fit.hybrid",
                 "wresdyn.identify.sysid", "wresdyn.sim"):
        t = now()
        if name == "warp.init":
            import warp as wp

            wp.config.kernel_cache_dir = cache
            wp.config.quiet = True
            wp.init()
        else:
            importlib.import_module(name)
        EVENTS.append((t, now() - t, f"import {name}"))
    patch_warp()
    skipped = [s for s in map(patch_stage, STAGES) if s]
    patch_progress(args.full)
    from wresdyn.cli import main as cli

    out = os.path.join(scratch, "run")
    cmd = ["fit", args.data, "--device", args.device, "--out", out, *extra]
    EVENTS.append((now(), 0.0, f"wresdyn {' '.join(cmd)}"))
    t = now()
    try:
        rc = cli(cmd)
    except Stop:
        rc = "stopped after the first iteration"
    except KeyboardInterrupt:  # Ctrl-C (SIGINT) ends a long --full run with the timeline so far
        rc = "interrupted"
    EVENTS.append((t, now() - t, f"wresdyn fit returned {rc}"))
    print("\ntimeline (start s, seconds, what); 'compile' lines are inside the 'warp load' above them:")
    for start, dur, what in sorted(EVENTS, key=lambda e: (e[0], -e[1])):
        print(f"{start:7.2f}  {dur:7.2f}  {what}")
    compiles = [e for e in EVENTS if e[2].startswith("  compile")]
    loads = [e for e in EVENTS if e[2].startswith("warp load")]
    first = next((e[0] for e in EVENTS if e[2].startswith("FIRST")), None)
    slowest = ", ".join(f"{e[2].split()[1]} {e[1]:.1f} s" for e in sorted(compiles, key=lambda e: -e[1])[:4])
    imports = sum(e[1] for e in EVENTS if e[2].startswith("import"))
    print(f"\nWarp modules compiled: {len(compiles)}, {sum(e[1] for e in compiles):.1f} s in all (slowest: {slowest})")
    print(f"Warp module loads listed: {len(loads)}; imports {imports:.1f} s")
    print(f"first iteration done at {first:.1f} s after the script started" if first else "no iteration reached")
    for s in skipped:
        print(f"not timed: {s}")


if __name__ == "__main__":
    main()
