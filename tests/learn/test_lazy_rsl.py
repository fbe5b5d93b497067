"""The gradient fit's path does not import rsl-rl (its package import loads tensordict and torch's compiler: seconds
before a first iteration), yet its network is rsl-rl's MLP layer for layer, and PPO still finds its actor classes."""

from __future__ import annotations

import pickle
import subprocess
import sys

import torch

from wresdyn.learn import residual


def test_fit_path_imports_no_rsl_rl():
    code = ("import sys, wresdyn.cli.fit, wresdyn.fit.gradfit, wresdyn.fit.hybrid, wresdyn.sim.warmup; "
            "print(sorted(m for m in ('rsl_rl', 'tensordict', 'torch._dynamo', 'tensorboard') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout


def test_elu_mlp_is_rsl_rl_mlp_layer_for_layer():
    from rsl_rl.modules.mlp import MLP

    torch.manual_seed(3)
    ref = MLP(12, 3, [32, 16], "elu")
    torch.manual_seed(3)
    ours = residual.EluMLP(12, 3, [32, 16])
    assert [n for n, _ in ref.named_children()] == [n for n, _ in ours.named_children()]
    assert [type(m) for m in ref] == [type(m) for m in ours]
    a, b = ref.state_dict(), ours.state_dict()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    x = torch.randn(5, 12)
    assert torch.equal(ref(x), ours(x))


def test_actor_classes_resolve_lazily():
    from rsl_rl.utils.utils import resolve_callable

    from wresdyn.learn.residual import ResidualMLPModel

    assert resolve_callable("wresdyn.learn.residual:ResidualMLPModel") is ResidualMLPModel
    assert resolve_callable("wresdyn.learn.residual:ResidualRNNModel") is residual.ResidualRNNModel
    assert pickle.loads(pickle.dumps(ResidualMLPModel)) is ResidualMLPModel
    try:
        residual.NoSuchName  # noqa: B018
    except AttributeError:
        pass
    else:
        raise AssertionError("an unknown name resolved")
