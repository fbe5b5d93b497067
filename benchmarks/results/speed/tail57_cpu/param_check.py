"""A tiny parametric fit and a tiny GRU-network fit with --eval, each with WRESDYN_FIT_HELPERS=0 and 1 (the cartpole data
of tests/conftest.py), and their exported residual and evaluation compared byte for byte: run from the repository
root, `PYTHONPATH=$PWD python param_check.py`."""
import filecmp, os, sys
sys.path.insert(0, "tests")
from conftest import record_multisine
from wresdyn.robot import load_robot
from wresdyn.data.mismatch import Mismatch
from wresdyn.cli import main
robot = load_robot("newton:cartpole.urdf", gains="examples/gains/cartpole.toml")
data = record_multisine(robot, Mismatch(), {"train": 2, "validation": 1, "heldout": 1, "ood": 1}, 0.4)
data.gains = robot.gains_record()
data.save("/tmp/t57/cart.npz")
for arch, extra in (("parametric", ["--model", "parametric"]), ("gru", ["--model", "network", "--residual.arch", "gru"])):
    for h in ("0", "1"):
        os.environ["WRESDYN_FIT_HELPERS"] = h
        os.system("rm -rf /tmp/t57/pfit")
        assert main(["fit", "/tmp/t57/cart.npz", "--out", "/tmp/t57/pfit", "--iterations", "2", "--eval", "--quiet", *extra]) == 0
        os.system(f"rm -rf /tmp/t57/{arch}{h}; mv /tmp/t57/pfit /tmp/t57/{arch}{h}")
    for name in ("policy.pt", "policy.onnx", "residual.json", "eval/metrics.json", "eval/report.md", "eval/fig3_ood.png", "eval/fig4_learning_curves.png"):
        print(arch, name, filecmp.cmp(f"/tmp/t57/{arch}0/{name}", f"/tmp/t57/{arch}1/{name}", shallow=False))
