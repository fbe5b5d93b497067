"""The fit's set-up (wresdyn/cli/fit.py, _set_up) with torch._dynamo imported in order (A) or in a thread started
before the dataset loads and joined after the Newton check (B): seconds since the process started at the set-up's
end. Usage: python dyn_thread.py A|B DATA"""
import gc, sys, threading, time
gc.disable()
from wresdyn.cli.clock import since_start
from wresdyn.data.loading import load_data
from wresdyn.fit.gradfit import fit  # noqa: F401
from wresdyn.fit.hybrid import fit_hybrid  # noqa: F401
mode, data = sys.argv[1], sys.argv[2]
imported = since_start()
def dyn():
    import torch._dynamo  # noqa: F401
if mode == "A":
    dyn(); th = None
else:
    th = threading.Thread(target=dyn); th.start()
ds, robot = load_data(data, None, None)
from wresdyn.sim.warmup import compile_kernels
compile_kernels(robot, ds.rate_hz, ("forward", "param_grads"), solver="auto", device="cpu", say=lambda *a, **k: None)
from wresdyn.sim.first_steps import check_newton
first = ds.split("train")[0]
check_newton(robot, ds.rate_hz, first.q[0], first.qd[0], first.q_cmd, solver="auto", device="cpu", physics=None)
if th is not None:
    th.join()
print(f"{mode} imported {imported:.2f} set-up end {since_start():.2f} after imports {since_start() - imported:.2f}")
