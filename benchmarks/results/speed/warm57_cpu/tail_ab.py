"""The fit's tail on a finished run, in one process or with the helper: `python tail_ab.py MODE RUN DATA [LEAD]`.

MODE `here`: the evaluation (figures drawn here) then `policy.onnx` from `policy.pt`, one after the other (the GPU
path's order before this branch); `helper`: a `wresdyn.cli.fit_tail.Helper` started LEAD seconds (20) before (the
fit's time to import and warm up), then the ONNX job, the evaluation with its figures drawn there, and the wait. Both
evaluate on the CPU into RUN/eval_MODE and write RUN/MODE.onnx. Prints the tail's seconds (from the ONNX request or the
evaluation's start to the last file) and the helper's wait at the end."""
import sys
import time

from wresdyn.cli.fit_tail import Helper, onnx_from_archive
from wresdyn.data.loading import load_data
from wresdyn.evaluation.evaluate_run import evaluate_run

mode, run, data = sys.argv[1:4]
lead = float(sys.argv[4]) if len(sys.argv) > 4 else 20.0
ds, robot = load_data(data, None, None)
# kernels, modules and the exporter loaded and used once, as in a fit at its end
evaluate_run(run, ds, robot, out=f"{run}/eval_warm", data_label=data)
onnx_from_archive(f"{run}/policy.pt", f"{run}/warm.onnx", ["obs"], ["residual"])
helper = Helper() if mode == "helper" else None
if helper:
    time.sleep(lead)
start = time.monotonic()
if helper:
    helper.submit(onnx_from_archive, f"{run}/policy.pt", f"{run}/{mode}.onnx", ["obs"], ["residual"])
    evaluate_run(run, ds, robot, out=f"{run}/eval_{mode}", data_label=data, draw=helper.submit)
    evaluated = time.monotonic()
    helper.close()
else:
    evaluate_run(run, ds, robot, out=f"{run}/eval_{mode}", data_label=data)
    evaluated = time.monotonic()
    onnx_from_archive(f"{run}/policy.pt", f"{run}/{mode}.onnx", ["obs"], ["residual"])
end = time.monotonic()
print(f"{mode}: tail {end - start:.2f} s (evaluation {evaluated - start:.2f} s, then {end - evaluated:.2f} s)", flush=True)
