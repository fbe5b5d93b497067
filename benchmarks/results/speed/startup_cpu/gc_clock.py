"""Seconds the cyclic garbage collector takes during a ``wresdyn`` command, by generation.

    python gc_clock.py fit DATA [FLAGS...]      (from the tree to time, PYTHONPATH naming it)

Runs ``wresdyn.cli.main`` in this process with a ``gc.callbacks`` clock around every collection; prints, at the end,
the count and seconds of the collections of each generation, the collections over 50 ms (start s since this script
started, generation, seconds, objects collected) and the objects the collector tracks at the end.
"""
import gc
import sys
import time

T0 = time.perf_counter()
stats = {0: [0, 0.0], 1: [0, 0.0], 2: [0, 0.0]}
big = []
_t = [0.0]


def clock(phase, info):
    if phase == "start":
        _t[0] = time.perf_counter()
        return
    d = time.perf_counter() - _t[0]
    g = info["generation"]
    stats[g][0] += 1
    stats[g][1] += d
    if d > 0.05:
        big.append((round(_t[0] - T0, 2), g, round(d, 3), info["collected"]))


gc.callbacks.append(clock)
import wresdyn.cli  # noqa: E402

try:
    wresdyn.cli.main(sys.argv[1:])
finally:
    print("gc by generation: count, seconds", {g: [n, round(s, 3)] for g, (n, s) in stats.items()})
    print("collections over 50 ms (start s, gen, seconds, collected):", big)
    print("end", round(time.perf_counter() - T0, 2), "s; objects tracked", len(gc.get_objects()))
