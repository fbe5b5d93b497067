"""Seconds of ``load_dataset`` (the npz read and every trajectory's Savitzky-Golay q̈) in the tree on PYTHONPATH, best
and median of N loads in one process, and a hash of every array loaded.

    PYTHONPATH=TREE python load_ab.py DATA [N]
"""
import hashlib
import statistics
import sys
import time

from wresdyn.data.dataset import load_dataset

data, n = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 5
times, h = [], None
for _ in range(n):
    t = time.perf_counter()
    ds = load_dataset(data)
    times.append(time.perf_counter() - t)
    d = hashlib.sha256()
    for tr in ds.trajectories:
        for a in (tr.q, tr.qd, tr.qdd, tr.q_cmd):
            d.update(a.tobytes())
    h = d.hexdigest()[:16]
print(f"load_dataset best {min(times):.3f} s median {statistics.median(times):.3f} s of {n}; arrays sha256 {h}")
