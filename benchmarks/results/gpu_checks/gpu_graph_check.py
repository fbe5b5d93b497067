import dataclasses, time, numpy as np, torch
from wresdyn.data.loading import load_data
from wresdyn.learn.gradfit import GradFitConfig, fit
data, robot = load_data("data/dataset.npz")
data = dataclasses.replace(data, trajectories=data.split("train")[:2] + data.split("validation")[:1])
for arch in ("mlp", "gru"):
    cfg = GradFitConfig(model="network", windows=8, horizon_curriculum=(4, 8), iterations=12, select_every=6, device="cuda:0")
    cfg = dataclasses.replace(cfg, residual=dataclasses.replace(cfg.residual, arch=arch))
    runs = {}
    for g in (True, False):
        t = time.perf_counter()
        runs[g] = fit(robot, data, dataclasses.replace(cfg, cuda_graph=g), log=lambda *_: None)
        print(arch, "graph" if g else "eager", f"{time.perf_counter()-t:.1f}s")
    (pg, cg), (pe, ce) = runs[True], runs[False]
    for a, b in zip(cg, ce):
        for k in ("loss", "pos", "validation"):
            if k in a:
                assert np.isclose(a[k], b[k], rtol=1e-4, atol=1e-7), (arch, a["iteration"], k, a[k], b[k])
    print(arch, "graph == eager over", len(cg), "rows; last loss", cg[-1]["loss"], ce[-1]["loss"])
