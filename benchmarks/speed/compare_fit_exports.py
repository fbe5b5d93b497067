"""Compare two runs' exported residuals, ``policy.pt`` and ``policy.onnx``, less the source locations the exporters
record (file paths and line numbers of the code that was traced, which move with any edit of that code) and the
archive's random serialization id: every weight byte for byte, the graphs field for field, and both files' outputs
on the same random observations bit for bit.

    python benchmarks/speed/compare_fit_exports.py BEFORE_RUN AFTER_RUN
"""
import json
import sys
import zipfile

import numpy as np
import onnx
import onnxruntime
import torch

from wresdyn.learn.run_residual import load_policy


def drop(obj, keys=("stack_trace",)):
    if isinstance(obj, dict):
        return {k: drop(v, keys) for k, v in obj.items() if k not in keys}
    if isinstance(obj, list):
        return [drop(v, keys) for v in obj]
    return obj


def archive(path):
    with zipfile.ZipFile(path) as z:
        out = {n: z.read(n) for n in z.namelist() if not n.endswith("serialization_id")}
    return {n: json.dumps(drop(json.loads(b)), sort_keys=True).encode() if n.endswith(".json") else b
            for n, b in out.items()}


def onnx_graph(path):
    model = onnx.load(path)
    del model.metadata_props[:]
    for graph in [model.graph] + [f for f in model.functions]:
        for node in graph.node:
            del node.metadata_props[:]
            node.doc_string = ""
    model.graph.doc_string = ""
    return model.SerializeToString(deterministic=True)


before, after = sys.argv[1:3]
a, b = archive(f"{before}/policy.pt"), archive(f"{after}/policy.pt")
differ = sorted(n for n in set(a) | set(b) if a.get(n) != b.get(n))
print(f"policy.pt: {len(a)} members compared (less serialization_id; model.json less stack_trace), differ: {differ}")
same_graph = onnx_graph(f"{before}/policy.onnx") == onnx_graph(f"{after}/policy.onnx")
print(f"policy.onnx: graph, weights and attributes {'equal' if same_graph else 'DIFFER'} (less metadata_props, doc_string)")
n_obs = json.loads(open(f"{before}/residual.json").read())
obs = np.random.default_rng(0).standard_normal((64, 4 * len(n_obs["joint_names"]))).astype(np.float32)
outs = [onnxruntime.InferenceSession(f"{r}/policy.onnx").run(None, {"obs": obs})[0] for r in (before, after)]
pts = [load_policy(r)[0](torch.from_numpy(obs)).detach().numpy() for r in (before, after)]
print(f"onnxruntime outputs on 64 random observations: {'bit-identical' if np.array_equal(*outs) else 'DIFFER'}")
print(f"policy.pt outputs on the same: {'bit-identical' if np.array_equal(*pts) else 'DIFFER'}")
ok = not differ and same_graph and np.array_equal(*outs) and np.array_equal(*pts)
print("identical" if ok else "differ")
