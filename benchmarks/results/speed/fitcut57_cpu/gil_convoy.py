"""Does a thread exporting ONNX slow a loop that waits outside the interpreter twice a step? A CPU stand-in for the
evaluation's replay on a GPU (interpreter-bound launches and two device reads a step), not a GPU measurement.

The loop: ``STEPS`` steps of a few small torch operations on a (24, 84) batch (the evaluation's 24 worlds, the
humanoid's observation) and two waits that release the interpreter (``time.sleep(WAIT)``, as a device read does).
The export: the fit's residual network (``build_policy``'s MLP, 21 joints) written as ONNX by ``export_run_files``'
function. Timed, alternating, ``ROUNDS`` times: the loop alone, the export alone, both at once (the export on a
thread, as ``run_beside`` runs it); "sum" is loop + export alone (the two one after the other).

    PYTHONPATH=. OMP_NUM_THREADS=1 python benchmarks/results/speed/fitcut57_cpu/gil_convoy.py [ROUNDS [WAIT_US [CALLS]]]

``WAIT_US`` (default 50): each wait [µs]; a long one (500) stands in for the CPU's replay, whose steps are mostly
Warp's kernels outside the interpreter. ``CALLS`` (default 0): brief releases of the interpreter a step
(``time.sleep(0)``), as each Warp launch through ctypes releases and takes it back.
"""
import statistics
import sys
import tempfile
import threading
import time
import types

import numpy as np
import torch

from wresdyn.learn.residual import MLPResidualPolicy, export_run_files

STEPS, WAIT, N, CALLS = 2000, 50e-6, 21, 0
torch.set_num_threads(1)


def loop():
    x = torch.zeros(24, 4 * N)
    w = torch.randn(4 * N, N) * 0.01
    for _ in range(STEPS):
        y = torch.tanh(x @ w)
        x = torch.cat([x[:, N:], y], 1) * 0.5
        for _ in range(CALLS):  # foreign calls that release the interpreter briefly (Warp's launches via ctypes)
            time.sleep(0)
        time.sleep(WAIT)  # a device read: the interpreter released while it waits
        bool((y.abs() > 10).any())
        time.sleep(WAIT)


def exporter(tmp):
    torch.manual_seed(0)
    mlp = torch.nn.Sequential(torch.nn.Linear(4 * N, 256), torch.nn.ELU(), torch.nn.Linear(256, 128), torch.nn.ELU(),
                              torch.nn.Linear(128, 64), torch.nn.ELU(), torch.nn.Linear(64, N))
    policy = MLPResidualPolicy(mlp, np.zeros(4 * N), np.ones(4 * N), np.full(N, 3.0), "torque")
    data = types.SimpleNamespace(joint_names=[f"j{i}" for i in range(N)], rate_hz=500.0)
    return export_run_files(policy, tmp, data, onnx_later=True, arch="mlp")


def timed(f):
    t = time.perf_counter()
    f()
    return time.perf_counter() - t


def both(write):
    th = threading.Thread(target=write)
    t = time.perf_counter()
    th.start()
    loop()
    t_loop = time.perf_counter() - t
    th.join()
    return t_loop, time.perf_counter() - t


rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 3
if len(sys.argv) > 2:
    WAIT = float(sys.argv[2]) * 1e-6
if len(sys.argv) > 3:
    CALLS = int(sys.argv[3])
print(f"{STEPS} steps, two waits of {WAIT * 1e6:.0f} us and {CALLS} brief releases a step, {rounds} rounds")
with tempfile.TemporaryDirectory() as tmp:
    write = exporter(tmp)
    write()  # the exporter's imports and first-use costs, outside the timings
    loop()
    rows = {"loop alone": [], "export alone": [], "beside: loop": [], "beside: both done": []}
    for _ in range(rounds):
        rows["loop alone"].append(timed(loop))
        rows["export alone"].append(timed(write))
        a, b = both(write)
        rows["beside: loop"].append(a)
        rows["beside: both done"].append(b)
    for name, v in rows.items():
        print(f"{name:18s} median {statistics.median(v):6.2f} s  ({' '.join(f'{x:.2f}' for x in v)})")
    s = statistics.median(rows["loop alone"]) + statistics.median(rows["export alone"])
    print(f"{'sum (one after the other)':18s} {s:6.2f} s")
