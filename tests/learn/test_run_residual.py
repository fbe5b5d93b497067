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
