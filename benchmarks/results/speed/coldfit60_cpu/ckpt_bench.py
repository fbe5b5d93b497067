import time, io, torch, tempfile, os
from pathlib import Path
from wresdyn.learn.runs import save_checkpoint
torch.set_num_threads(1)
rows = [{"iteration": i+1, "wall": 0.1*i, "sim_steps": 1000*i, "loss": 0.1, "pos": 0.01, "vel": 0.02, "torque": 0.0,
         "rate": 0.0, **({"validation": 0.05} if i % 40 == 39 else {})} for i in range(1880)]
state = {"model": {f"p{i}": torch.randn(21) for i in range(12)}, "optim": {"state": {i: {"step": torch.tensor(1.), "exp_avg": torch.randn(21), "exp_avg_sq": torch.randn(21)} for i in range(12)}, "param_groups": [{"lr": 0.01, "params": list(range(12))}]}}
d = tempfile.mkdtemp()
for n in (40, 940, 1880):
    data = {**state, "meta": {"config": {"a": 1}, "curve": rows[:n], "iteration": n}, "best": state["model"]}
    t = time.perf_counter(); buf = io.BytesIO(); torch.save(data, buf); t1 = time.perf_counter()
    buf.seek(0); torch.load(buf, weights_only=True); t2 = time.perf_counter()
    save_checkpoint(data, Path(d) / "c.pt"); t3 = time.perf_counter()
    print(n, f"save {t1-t:.4f} verify {t2-t1:.4f} whole {t3-t2:.4f} bytes {len(buf.getvalue())}")
