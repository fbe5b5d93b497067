import sys, time
import torch, warp, newton  # noqa: F401  (what the fit has imported before it loads the data)
import wresdyn.cli.fit  # noqa: F401
from wresdyn.data.loading import load_data
t = time.perf_counter()
load_data(sys.argv[1])
print(f"load_data {time.perf_counter() - t:.2f} s; scipy.signal imported by it: {'scipy.signal' in sys.modules}")
t = time.perf_counter()
load_data(sys.argv[1])
print(f"load_data again (scipy.signal loaded) {time.perf_counter() - t:.2f} s")
