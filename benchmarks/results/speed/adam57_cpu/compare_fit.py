"""Two runs of the same `wresdyn fit --eval` (the tree before and after the optimiser change): every number the same.
JSON files are compared without wall-clock keys and the run folder; policy.pt by its exported weights; policy.onnx by
its initializers; checkpoints by every tensor of the model and of the optimiser's state; the logs without seconds and
the run folder. Usage: python compare_fit.py RUN_A RUN_B"""
import json
import re
import sys
from pathlib import Path

import numpy as np
import onnx
import torch
from onnx import numpy_helper

a, b = Path(sys.argv[1]), Path(sys.argv[2])
TIMING = re.compile(r"wall|seconds|time")


def clean(x):
    if isinstance(x, dict):
        return {k: clean(v) for k, v in x.items() if not TIMING.search(k) and k not in ("run", "out")}
    if isinstance(x, list):
        return [clean(v) for v in x]
    if isinstance(x, str):  # the run folder recorded in a path
        return x.replace(str(a), "RUN").replace(str(b), "RUN")
    return x


def tensors(x, prefix=""):
    if torch.is_tensor(x):
        yield prefix, x
    elif isinstance(x, dict):
        for k, v in x.items():
            if not TIMING.search(str(k)):
                yield from tensors(v, f"{prefix}/{k}")
    elif isinstance(x, (list, tuple)):
        for i, v in enumerate(x):
            yield from tensors(v, f"{prefix}/{i}")


for p in sorted(q.relative_to(a) for q in a.rglob("*") if q.is_file()):
    x, y = a / p, b / p
    if p.suffix == ".json":
        same = clean(json.loads(x.read_text())) == clean(json.loads(y.read_text()))
    elif p.name == "policy.pt":
        sa, sb = (torch.export.load(str(f)).state_dict for f in (x, y))
        same = sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)
    elif p.suffix == ".onnx":
        ia, ib = ({i.name: numpy_helper.to_array(i) for i in onnx.load(str(f)).graph.initializer} for f in (x, y))
        same = ia.keys() == ib.keys() and all(np.array_equal(ia[k], ib[k]) for k in ia)
    elif p.suffix == ".pt":
        ta, tb = (dict(tensors(torch.load(f, map_location="cpu", weights_only=True))) for f in (x, y))
        same = ta.keys() == tb.keys() and all(torch.equal(ta[k], tb[k]) for k in ta)
    elif p.suffix in (".log", ".md"):
        def norm(f):
            return re.sub(r"\d+(\.\d+)? ?s\b", "S", f.read_text().replace(str(f.parents[len(p.parts) - 1]), "RUN"))
        same = norm(x) == norm(y)
    else:
        same = x.read_bytes() == y.read_bytes()
    print(f"{'same' if same else 'DIFFERS':8s} {p}")
