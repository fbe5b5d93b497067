"""Which modules a fit imports after its set-up's freeze (in ``wresdyn.cli.fit._fit``, the collector on), and the
collections there: the command run in this process, ``_fit`` wrapped.

    PYTHONPATH=TREE python fit_imports.py fit DATA [FLAGS...]

Prints (stderr) the number of modules ``_fit`` imported with their names to three levels, then its collections, their
seconds and the seconds of each full one."""
import gc, sys, time
import wresdyn.cli.fit as F
orig = F._fit
D = []
def cb(phase, info, t=[0.0]):
    if phase == "start":
        t[0] = time.perf_counter()
    else:
        D.append((info["generation"], time.perf_counter() - t[0]))
def wrapped(*a, **k):
    before = set(sys.modules)
    gc.callbacks.append(cb)
    try:
        return orig(*a, **k)
    finally:
        gc.callbacks.remove(cb)
        new = sorted(set(sys.modules) - before)
        tops = sorted({m.split(".")[0] + ("." + m.split(".")[1] if "." in m else "") for m in new})
        print("late:", len(new), sorted({".".join(m.split(".")[:3]) for m in new}), file=sys.stderr)
        print(f"_fit: {len(D)} collections, {sum(d for _, d in D):.2f} s; full ones: "
              + ", ".join(f"{d:.3f}" for g, d in D if g == 2), file=sys.stderr)
F._fit = wrapped
from wresdyn.cli import main
sys.exit(main(sys.argv[1:]))
