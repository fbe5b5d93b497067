"""The non-tensor part of both checkpoints of two fit run folders (``meta``: config, curve, iteration, best, window
sampler and schedule state), leaf for leaf less the wall-clocks; ``compare.py`` covers the tensors.

    python compare_meta.py BEFORE_RUN AFTER_RUN
"""
import sys

import torch

SKIP = ("wall", "physics")  # clocks; the config's physics is a path into the run folder


def leaves(d, p=""):
    if isinstance(d, dict):
        return {k: v for key, val in d.items() for k, v in leaves(val, f"{p}/{key}").items()}
    if isinstance(d, (list, tuple)):
        return {k: v for i, val in enumerate(d) for k, v in leaves(val, f"{p}[{i}]").items()}
    return {p: d}


bad = 0
for f in ("checkpoint.pt", "identify/checkpoint.pt"):
    a, b = (leaves(torch.load(f"{run}/{f}", weights_only=True)["meta"]) for run in sys.argv[1:3])
    keys = [k for k in sorted(set(a) | set(b)) if k.rsplit("/", 1)[-1].split("[")[0] not in SKIP]
    diff = [k for k in keys if a.get(k) != b.get(k)]
    bad += len(diff)
    print(f"{f} meta: {len(keys)} values compared, {len(diff)} differ {diff[:5]}")
print("identical" if not bad else f"{bad} differ")
