"""Compare two run folders of the same fit file by file: `python compare.py RUN_A RUN_B [A_TREE B_TREE]`.

Each file is `same` (byte for byte), `same but the source path` (identical once B_TREE is read as A_TREE: torch.export's
archive and the ONNX file record the stack traces' source paths; zip members compared one by one, less the archive's
random serialization id), `same but timing`
(JSON: identical without the wall-clock keys; checkpoints: every tensor and value identical without them; fit.log:
identical without the clock stamps and the seconds of each line) or `DIFFERS`. Exit status 1 if any file differs."""
import io
import json
import re
import sys
import zipfile
from pathlib import Path

TIMING = {"wall", "wall_s", "residual_wall_s", "identify_wall_s", "seconds", "elapsed", "time", "wall_clock"}


def _drop(x):
    if isinstance(x, dict):
        return {k: _drop(v) for k, v in x.items() if k not in TIMING}
    if isinstance(x, list):
        return [_drop(v) for v in x]
    return x


def _equal(a, b) -> bool:
    import torch

    if isinstance(a, dict) and isinstance(b, dict):
        keys = set(a) - TIMING
        return keys == set(b) - TIMING and all(_equal(a[k], b[k]) for k in keys)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b))
    if isinstance(a, torch.Tensor) and isinstance(b, torch.Tensor):
        return a.dtype == b.dtype and a.shape == b.shape and bool(torch.equal(a, b))
    try:
        import numpy as np

        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            return np.array_equal(a, b)
    except ImportError:
        pass
    return a == b


def _log(text: str) -> list[str]:
    # the clock's stamp, the seconds a line reports (`0s`, `in 2.5 s`, `0:01 elapsed`), the progress bar's lines
    out = []
    for line in text.splitlines():
        line = re.sub(r"^\[ *[0-9.]+ s\] ", "", line)
        line = re.sub(r"\b\d+(\.\d+)? ?s\b", "S", line)
        if "elapsed" in line or "first iteration of" in line or line.startswith("start: imports"):
            continue
        out.append(line)
    return out


def compare(a: Path, b: Path, name: str, trees) -> str:
    x, y = a.read_bytes(), b.read_bytes()
    if x == y:
        return "same"
    if trees:
        y2 = y.replace(trees[1].encode(), trees[0].encode())
        if x == y2:
            return "same but the source path"
        if zipfile.is_zipfile(io.BytesIO(x)) and name.endswith("policy.pt"):
            za, zb = zipfile.ZipFile(io.BytesIO(x)), zipfile.ZipFile(io.BytesIO(y))
            if za.namelist() == zb.namelist() and all(
                    za.read(n) == zb.read(n).replace(trees[1].encode(), trees[0].encode())
                    for n in za.namelist() if not n.endswith("serialization_id")):
                return "same but the source path"
    if name.endswith(".json"):
        return "same but timing" if _drop(json.loads(x)) == _drop(json.loads(y)) else "DIFFERS"
    if name.endswith(".pt"):
        import torch

        ca, cb = (torch.load(io.BytesIO(d), map_location="cpu", weights_only=False) for d in (x, y))
        return "same but timing" if _equal(ca, cb) else "DIFFERS"
    if name.endswith(".log") or name.endswith(".md"):
        return "same but timing" if _log(x.decode()) == _log(y.decode()) else "DIFFERS"
    return "DIFFERS"


def main() -> int:
    a, b = Path(sys.argv[1]), Path(sys.argv[2])
    trees = sys.argv[3:5] or None
    names = sorted(str(p.relative_to(a)) for p in a.rglob("*") if p.is_file())
    other = sorted(str(p.relative_to(b)) for p in b.rglob("*") if p.is_file())
    bad = names != other
    if bad:
        print(f"file lists differ: {sorted(set(names) ^ set(other))}")
    for name in names:
        if (b / name).is_file():
            verdict = compare(a / name, b / name, name, trees)
            bad |= verdict == "DIFFERS"
            print(f"{verdict:26s} {name}")
    return int(bad)


if __name__ == "__main__":
    sys.exit(main())
