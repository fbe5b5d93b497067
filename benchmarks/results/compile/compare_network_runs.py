import json, sys
a_dir, b_dir = sys.argv[1], sys.argv[2]
for f in ("curve.json", "residual.json", "train_summary.json"):
    a = json.load(open(f"{a_dir}/{f}")); b = json.load(open(f"{b_dir}/{f}"))
    def flat(x, p=""):
        if isinstance(x, dict):
            for k, v in x.items(): yield from flat(v, f"{p}.{k}")
        elif isinstance(x, list):
            for i, v in enumerate(x): yield from flat(v, f"{p}[{i}]")
        else: yield p, x
    fa, fb = dict(flat(a)), dict(flat(b))
    skip = ("time", "wall", "seconds", "elapsed", "_s", "date", "out", "path")
    keys = [k for k in fa if not any(s in k.lower() for s in skip)]
    diff = [k for k in keys if fa[k] != fb.get(k)]
    print(f"{f}: {len(keys)} entries compared (wall-clock and path entries skipped); {len(diff)} differ {diff[:5]}")
