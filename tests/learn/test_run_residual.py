"""Loading a trained residual (what ``wresdyn eval``, ``export`` and ``deploy`` do) imports no learner: the exported
archive reads back with torch alone, without the PPO trainer, the gradient fit or identification."""

import subprocess
import sys
import types

import numpy as np
import pytest
import torch

from wresdyn.learn.residual import MLPResidualPolicy, export_run_files
from wresdyn.learn.run_residual import load_policy
from wresdyn.learn.runs import RunError

LOAD = """
import sys
import torch
import wresdyn.evaluation.evaluate_run, wresdyn.export.residual_torque, wresdyn.skills.plants
from wresdyn.learn.run_residual import load_policy
policy, meta = load_policy(sys.argv[1])
out = policy(torch.ones(3, 8))
learners = sorted(m for m in sys.modules if m.startswith(("wresdyn.ppo.trainer", "wresdyn.fit.", "wresdyn.identify.")))
print(meta["kind"], tuple(out.shape), learners)
"""


def test_loading_a_residual_imports_no_learner(tmp_path):
    n = 2
    torch.manual_seed(0)
    policy = MLPResidualPolicy(torch.nn.Linear(4 * n, n), np.zeros(4 * n), np.ones(4 * n), np.full(n, 3.0), "torque")
    export_run_files(policy, tmp_path, types.SimpleNamespace(joint_names=["a", "b"], rate_hz=500.0), arch="mlp")
    loaded, meta = load_policy(tmp_path)
    obs = torch.randn(5, 4 * n)
    with torch.no_grad():
        assert torch.allclose(loaded(obs), policy(obs), atol=1e-6)
    assert meta["joint_names"] == ["a", "b"]
    res = subprocess.run([sys.executable, "-c", LOAD, str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip().splitlines()[-1] == "torque (3, 2) []"


def test_a_run_without_an_exported_residual_is_a_run_error(tmp_path):
    with pytest.raises(RunError, match="no exported residual"):
        load_policy(tmp_path)


def _gru(seed: int, n: int = 2, kind: str = "delta_action"):
    from wresdyn.learn.residual import EluMLP, GRUResidualPolicy

    torch.manual_seed(seed)
    return GRUResidualPolicy(torch.nn.GRU(4 * n, 8), EluMLP(8, n, [8]), np.zeros(4 * n), np.ones(4 * n),
                             np.full(n, 0.1), kind).eval()


def _steps(policy, obs):
    policy.reset()
    with torch.no_grad():
        return torch.stack([policy(o) for o in obs])


def test_an_ensemble_of_one_is_its_member_bit_for_bit():
    from wresdyn.learn.run_residual import MeanResidual

    obs = torch.randn(20, 5, 8)
    alone, ensemble = _gru(0), MeanResidual([_gru(0)])
    assert torch.equal(_steps(ensemble, obs), _steps(alone, obs))
    assert torch.equal(ensemble.scale, alone.scale) and ensemble.residual_kind() == "delta_action"


def test_an_ensemble_steps_the_mean_of_its_members_each_with_its_own_state():
    """Each member's GRU carries its own hidden state through the steps (a shared or reset state would change every
    step after the first), and ``reset`` starts every member again."""
    from wresdyn.learn.run_residual import MeanResidual

    obs = torch.randn(20, 5, 8)
    a, b = _steps(_gru(0), obs), _steps(_gru(1), obs)
    assert not torch.allclose(a, b, atol=1e-4)  # the members differ, else the mean would prove nothing
    ensemble = MeanResidual([_gru(0), _gru(1)])
    first = _steps(ensemble, obs)
    torch.testing.assert_close(first, (a + b) / 2, rtol=0, atol=1e-7)
    assert torch.equal(_steps(ensemble, obs), first)


def test_residuals_of_different_kinds_are_not_averaged():
    from wresdyn.learn.run_residual import MeanResidual

    with pytest.raises(ValueError, match="different kinds"):
        MeanResidual([_gru(0), _gru(1, kind="torque")])
