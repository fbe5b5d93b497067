"""Seconds ``wresdyn fit`` spends importing before its first iteration, and which heavy packages it loads then.

    python benchmarks/speed/fit_imports.py [--runs 3]

Each run is a fresh interpreter that imports what ``wresdyn fit`` imports before it builds its first simulator: the
command line (``wresdyn.cli``), then the modules ``wresdyn.cli.fit.run`` imports (data loading, the gradient fit,
the hybrid fit, identification, the kernel warm-up, the Newton check), then Warp and Newton, which the first
simulator needs whatever is lazy. It prints the seconds of each run (the interpreter's own start excluded) and the
packages of :data:`HEAVY` that are loaded at the end: those the first iteration does not use are candidates for a
lazy import. The interpreters run in the temporary folder, so the wresdyn they import is the one ``PYTHONPATH`` (else
the installed package) names, e.g. an older tree's for a comparison.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

FIT_PATH = ("wresdyn.cli", "wresdyn.cli.fit", "wresdyn.data.loading", "wresdyn.fit.gradfit", "wresdyn.fit.hybrid",
            "wresdyn.identify.sysid", "wresdyn.progress", "wresdyn.learn.schedule", "wresdyn.sim.physics",
            "wresdyn.sim.warmup", "wresdyn.sim.first_steps", "warp", "newton")
"""What the fit imports before its first simulator (``wresdyn/cli/fit.py``'s ``run``), in its order."""

HEAVY = ("rsl_rl", "tensordict", "tensorboard", "torch.utils.tensorboard", "torch._dynamo", "sympy", "matplotlib",
         "onnx", "onnxruntime", "onnxscript", "pxr", "scipy", "scipy.signal", "scipy.spatial", "mujoco",
         "mujoco_warp", "pinocchio", "pandas", "tyro")
"""Packages worth a lazy import when the first iteration does not need them."""

CHILD = """
import json, sys, time
t0 = time.perf_counter()
import torch
t1 = time.perf_counter()
for name in {path!r}:
    __import__(name)
t2 = time.perf_counter()
print(json.dumps({{"torch_s": t1 - t0, "rest_s": t2 - t1, "total_s": t2 - t0,
                  "loaded": [m for m in {heavy!r} if m in sys.modules],
                  "wresdyn": __import__("wresdyn").__file__}}))
"""


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=3)
    args = p.parse_args()
    env = dict(os.environ, OMP_NUM_THREADS="1")
    code = CHILD.format(path=FIT_PATH, heavy=HEAVY)
    runs = []
    for i in range(args.runs):
        # run outside any checkout: the wresdyn imported is the one PYTHONPATH (else the install) names
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                             cwd=tempfile.gettempdir())
        r = json.loads(out.stdout.strip().splitlines()[-1])
        runs.append(r)
        print(f"run {i + 1}: torch {r['torch_s']:.2f} s, the rest of the fit's imports {r['rest_s']:.2f} s, "
              f"total {r['total_s']:.2f} s (load average {os.getloadavg()[0]:.2f})", flush=True)
    totals = sorted(r["total_s"] for r in runs)
    print(f"median total {totals[len(totals) // 2]:.2f} s over {len(runs)} runs (min {totals[0]:.2f}, "
          f"max {totals[-1]:.2f})")
    print(f"heavy packages loaded: {', '.join(runs[-1]['loaded']) or 'none'}")
    print(f"wresdyn imported from {runs[-1]['wresdyn']}")


if __name__ == "__main__":
    main()
