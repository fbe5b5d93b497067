import dataclasses, tempfile, numpy as np
from wresdyn.data.loading import load_data
from wresdyn.learn.gradfit import GradFitConfig, fit
data, robot = load_data("data/dataset.npz")
data = dataclasses.replace(data, trajectories=data.split("train")[:2] + data.split("validation")[:1])
cfg = GradFitConfig(model="network", windows=8, horizon_curriculum=(4, 8), iterations=12, select_every=6, device="cuda:0", cuda_graph=True)
with tempfile.TemporaryDirectory() as a, tempfile.TemporaryDirectory() as b:
    _, straight = fit(robot, data, cfg, out=a, log=lambda *_: None)
    fit(robot, data, cfg, out=b, until=6, log=lambda *_: None)
    _, resumed = fit(robot, data, cfg, out=b, log=print)
    for x, y in zip(straight, resumed):
        for k in ("loss", "validation"):
            if k in x:
                assert np.isclose(x[k], y[k], rtol=1e-4, atol=1e-7), (x["iteration"], k, x[k], y[k])
    print("graph fit stopped at 6 and resumed == straight over", len(straight), "rows; last loss", straight[-1]["loss"], resumed[-1]["loss"])
