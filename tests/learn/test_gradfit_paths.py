"""``benchmarks/speed/gradfit_paths.py`` at a tiny size on the CPU: the fused path's loss of one batch is the plain
path's and its gradients agree to float32 rounding, at a length inside the truncation and one past it; torch's fused
Adam steps agree with its foreach form to rounding of the change."""

import importlib.util
from pathlib import Path

from wresdyn.fit.gradfit import GradFitConfig
from wresdyn.learn.residual import ResidualConfig

ROOT = Path(__file__).resolve().parents[2]


def _script():
    spec = importlib.util.spec_from_file_location("gradfit_paths", ROOT / "benchmarks/speed/gradfit_paths.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_fused_gradients_and_adam_agree_with_the_plain_path(robot, data):
    script = _script()
    cfg = GradFitConfig(residual=ResidualConfig(fraction=0.25, hidden_dims=(16, 16)), windows=4, iterations=4,
                        device="cpu")
    rows, plain = script.compare_gradients(robot, data, cfg, {"plain": {}, "fused": {"fused_network": True}}, [2, 17])
    assert [r["horizon"] for r in rows] == [2, 17]
    for row in rows:
        fused = row["paths"]["fused"]
        assert set(fused["gradient_relative"]) == {n for n, _ in plain.policy.named_parameters()}
        assert max(fused["gradient_relative"].values()) < 5e-6  # measured 9e-8 (H = 2), 5e-7 (H = 17)
        assert fused["loss_relative"] == 0.0  # the fused forward is the plain one's, bit for bit, on the CPU
    adam = script.compare_adam(plain, steps=3)
    assert adam["largest_change"] > 0 and adam["relative"] < 2e-5  # measured 2.5e-6
