"""The seconds of a whole ``wresdyn fit`` outside its training loops, call by call, in this process.

    python timeline.py [FIT FLAGS...]      (run from the repository root, PYTHONPATH naming the tree to time)

Wraps the calls named in :data:`CALLS` with a clock (seconds since this script started) and runs
``wresdyn.cli`` with the given flags; prints one line per call (the first 3 of each name), then the calls' totals.
No profiler: the clocks are the command's own.
"""
import functools
import importlib
import sys
import time

T0 = time.perf_counter()
CALLS = ("wresdyn.data.loading:load_data", "wresdyn.sim.warmup:compile_kernels", "wresdyn.sim.first_steps:check_newton",
         "wresdyn.sim.simulator:Simulator.__init__", "wresdyn.identify.sysid:identify",
         "wresdyn.identify.sysid:IdentifyLearner.__init__", "wresdyn.identify.sysid:IdentifyLearner.begin",
         "wresdyn.identify.sysid:_report_identifiability", "torch.optim:Adam.__init__",
         "wresdyn.fit.gradfit:fit", "wresdyn.fit.gradfit:_FitLearner.begin", "wresdyn.fit.gradfit:export_run",
         "wresdyn.learn.window_fit:run_window_fit", "wresdyn.evaluation.evaluate_run:evaluate_run",
         "wresdyn.evaluation.evaluate_run:load_run_model", "wresdyn.evaluation.open_loop:evaluate_splits",
         "wresdyn.evaluation.plots:plot_fig3", "wresdyn.evaluation.plots:plot_learning_curves")
EVENTS, COUNTS, TOTAL = [], {}, {}


def timed(key, fn):
    @functools.wraps(fn)
    def wrapper(*a, **k):
        t = time.perf_counter() - T0
        try:
            return fn(*a, **k)
        finally:
            s = time.perf_counter() - T0 - t
            COUNTS[key] = COUNTS.get(key, 0) + 1
            TOTAL[key] = TOTAL.get(key, 0.0) + s
            if COUNTS[key] <= 3:
                EVENTS.append((t, s, key))
    return wrapper


def main():
    import wresdyn.cli
    import wresdyn.cli.fit  # noqa: F401
    print(f"imports of the CLI done at {time.perf_counter() - T0:.2f} s", flush=True)
    for target in CALLS:
        mod_name, qual = target.split(":")
        mod = importlib.import_module(mod_name)
        owner, name = mod, qual
        if "." in qual:
            cls, name = qual.split(".")
            owner = getattr(mod, cls)
        setattr(owner, name, timed(qual, getattr(owner, name)))
    # modules that imported a function by name hold the unpatched one: patch those references too
    for target in CALLS:
        mod_name, qual = target.split(":")
        if "." in qual:
            continue
        mod = importlib.import_module(mod_name)
        for other in list(sys.modules.values()):
            d = getattr(other, "__dict__", None)
            if d and other is not mod and qual in d and getattr(d[qual], "__wrapped__", None) is None \
                    and getattr(d[qual], "__module__", None) == mod_name:
                d[qual] = getattr(mod, qual)
    try:
        wresdyn.cli.main(sys.argv[1:])
    finally:
        end = time.perf_counter() - T0
        for t, s, key in sorted(EVENTS):
            print(f"{t:7.2f} {s:7.2f}  {key}")
        print(f"{end:7.2f}          end")
        for key, s in TOTAL.items():
            print(f"total {s:7.2f} s over {COUNTS[key]:3d} calls  {key}")


if __name__ == "__main__":
    main()
