"""Compare two fit run folders: every JSON leaf of the files below less the wall-clocks and run paths, every
checkpoint tensor bit for bit, the exported files, JSON files and plots byte for byte.

    python benchmarks/speed/compare_fit_runs.py BEFORE_RUN AFTER_RUN
"""
import json
import sys

FILES = ("train_summary.json", "eval/metrics.json", "curve.json", "identify/curve.json", "identify/physics.json",
         "residual.json")
SKIP = ("wall", "wall_s", "residual_wall_s", "identify_wall_s", "run", "physics")  # clocks; paths of the run folder


def leaves(d, p=""):
    if isinstance(d, dict):
        return {k: v for key, val in d.items() for k, v in leaves(val, f"{p}/{key}").items()}
    if isinstance(d, list):
        return {k: v for i, val in enumerate(d) for k, v in leaves(val, f"{p}[{i}]").items()}
    return {p: d}


bad = 0
for f in FILES:
    a, b = (leaves(json.load(open(f"{run}/{f}"))) for run in sys.argv[1:3])
    keys = [k for k in sorted(set(a) | set(b)) if k.rsplit("/", 1)[-1] not in SKIP]
    diff = [k for k in keys if a.get(k) != b.get(k)]
    bad += len(diff)
    print(f"{f}: {len(keys)} values compared, {len(diff)} differ {diff[:5]}")

# every checkpoint tensor bit for bit, and the exported files and plots byte for byte
import filecmp  # noqa: E402
from pathlib import Path  # noqa: E402

import torch  # noqa: E402


def tensors(obj, p=""):
    if isinstance(obj, torch.Tensor):
        return {p: obj}
    if isinstance(obj, dict):
        return {k: v for key, val in obj.items() for k, v in tensors(val, f"{p}/{key}").items()}
    if isinstance(obj, (list, tuple)):
        return {k: v for i, val in enumerate(obj) for k, v in tensors(val, f"{p}[{i}]").items()}
    return {}


for f in ("checkpoint.pt", "identify/checkpoint.pt"):
    a, b = (tensors(torch.load(f"{run}/{f}", map_location="cpu", weights_only=False)) for run in sys.argv[1:3])
    same = [k for k in a if k in b and a[k].dtype == b[k].dtype and a[k].shape == b[k].shape
            and a[k].contiguous().view(-1).view(torch.uint8).equal(b[k].contiguous().view(-1).view(torch.uint8))]
    bad += len(a) - len(same) + len(set(b) - set(a))
    print(f"{f}: {len(a)} tensors, {len(same)} bit-identical")
names = sorted(str(p.relative_to(sys.argv[1])) for p in Path(sys.argv[1]).rglob("*") if p.is_file()
               and p.suffix in (".pt", ".onnx", ".png", ".json") and "checkpoint" not in p.name)
for name in names:
    equal = (Path(sys.argv[2]) / name).exists() and filecmp.cmp(Path(sys.argv[1]) / name, Path(sys.argv[2]) / name,
                                                                shallow=False)
    print(f"{name}: {'byte-equal' if equal else 'differs'}")
print("identical" if bad == 0 else f"{bad} differ")
