"""A default fit before and after the residual stage's start rule (``beat_start_within``): what must be equal is.

    PYTHONPATH=. python benchmarks/results/speed/fitcut57_cpu/compare_start_rule.py BEFORE_RUN AFTER_RUN

Equal, leaf for leaf less wall-clocks and run paths: the evaluation (``eval/metrics.json``), the identification
(``identify/``: curve, physics, checkpoint tensors bit for bit), ``residual.json`` and ``physics.json``. The residual
stage's curve after is the first rows of the one before (less wall-clocks), its selected state (the checkpoint's
``best``) bit for bit the one before, and ``train_summary.json`` differs in the iteration count, the simulated steps
and the new config field only. The exported ``policy.pt``'s outputs are compared by ``compare_fit_exports.py``.
"""
import json
import sys
from pathlib import Path

import torch

SKIP = ("wall", "wall_s", "residual_wall_s", "identify_wall_s", "run", "physics")  # clocks; paths of the run folder
before, after = (Path(p) for p in sys.argv[1:3])


def leaves(d, p=""):
    if isinstance(d, dict):
        return {k: v for key, val in d.items() for k, v in leaves(val, f"{p}/{key}").items()}
    if isinstance(d, list):
        return {k: v for i, val in enumerate(d) for k, v in leaves(val, f"{p}[{i}]").items()}
    return {p: d}


def differ(a, b):
    a, b = leaves(a), leaves(b)
    return [k for k in sorted(set(a) | set(b)) if k.rsplit("/", 1)[-1] not in SKIP and a.get(k) != b.get(k)]


def load(run, f):
    return json.loads((run / f).read_text())


def bits(a, b):
    return a.dtype == b.dtype and a.shape == b.shape and a.contiguous().view(-1).view(torch.uint8).equal(
        b.contiguous().view(-1).view(torch.uint8))


bad = 0
for f in ("eval/metrics.json", "identify/curve.json", "identify/physics.json", "residual.json", "physics.json"):
    d = differ(load(before, f), load(after, f))
    bad += len(d)
    print(f"{f}: {'equal' if not d else f'{len(d)} differ {d[:5]}'}")
cb, ca = load(before, "curve.json"), load(after, "curve.json")
strip = lambda rows: [{k: v for k, v in r.items() if k != "wall"} for r in rows]  # noqa: E731
prefix = strip(ca) == strip(cb[:len(ca)])
bad += not prefix
print(f"curve.json: after's {len(ca)} rows {'are' if prefix else 'are NOT'} the first of before's {len(cb)}")
d = differ(load(before, "train_summary.json"), load(after, "train_summary.json"))
expected = {"/iterations", "/sim_steps", "/config/beat_start_within"}
bad += bool(set(d) - expected)
print(f"train_summary.json: differ {d} (expected only {sorted(expected)})")
for f in ("checkpoint.pt", "identify/checkpoint.pt"):
    kb, ka = (torch.load(run / f, map_location="cpu", weights_only=False) for run in (before, after))
    part = kb["best"] if f == "checkpoint.pt" else kb
    other = ka["best"] if f == "checkpoint.pt" else ka

    def flat(o, p=""):
        if isinstance(o, torch.Tensor):
            return {p: o}
        if isinstance(o, dict):
            return {k: v for key, val in o.items() for k, v in flat(val, f"{p}/{key}").items()}
        if isinstance(o, (list, tuple)):
            return {k: v for i, val in enumerate(o) for k, v in flat(val, f"{p}[{i}]").items()}
        return {}

    tb, ta = flat(part), flat(other)
    same = [k for k in tb if k in ta and bits(tb[k], ta[k])]
    bad += len(tb) - len(same) + len(set(ta) - set(tb))
    what = "selected state ('best')" if f == "checkpoint.pt" else "all tensors"
    print(f"{f} {what}: {len(tb)} tensors, {len(same)} bit-identical")
    if f == "checkpoint.pt":
        mb, ma = kb["meta"], ka["meta"]
        same_best = (mb["best_iteration"], mb["best_validation"]) == (ma["best_iteration"], ma["best_validation"])
        bad += not same_best
        print(f"  selected iteration {mb['best_iteration']} ({mb['best_validation']!r} rad) before, "
              f"{ma['best_iteration']} ({ma['best_validation']!r} rad) after")
print("as claimed" if bad == 0 else f"{bad} differ")
