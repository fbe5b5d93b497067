"""wresdyn's Adam steps as torch.optim.Adam does, bit for bit, loads torch's checkpoints (and torch loads its), and
never imports torch._dynamo."""

import copy
import subprocess
import sys

import pytest
import torch

from wresdyn.learn.adam import Adam


def _problem(seed: int):
    """Two groups (one with an extra key, as identification's), a parameter without a gradient, float32."""
    g = torch.Generator().manual_seed(seed)
    a = torch.randn(7, 5, generator=g).requires_grad_()
    b = torch.randn(5, generator=g).requires_grad_()
    c = torch.randn(3, generator=g).requires_grad_()
    unused = torch.randn(2, generator=g).requires_grad_()
    groups = [{"params": [a, b], "scale": 1.0}, {"params": [c, unused], "scale": 0.1, "lr": 3e-3}]
    x = torch.randn(9, 7, generator=g)

    def loss():
        return ((x @ a).tanh() @ b).square().mean() + (c ** 3).sum() * 0.1

    return groups, loss


def _run(make, steps: int, seed: int = 0, lrs=None):
    groups, loss = _problem(seed)
    opt = make(groups)
    for i in range(steps):
        opt.zero_grad()
        loss().backward()
        if lrs is not None:
            for group in opt.param_groups:
                group["lr"] = lrs[i]
        opt.step()
    return opt, [p.detach().clone() for grp in groups for p in grp["params"]]


@pytest.mark.parametrize("options", [{"foreach": False}, {"foreach": True}, {"fused": True}, {},
                                     {"weight_decay": 0.01, "amsgrad": True}, {"maximize": True, "foreach": True}])
def test_the_steps_are_torchs_bit_for_bit(options):
    lrs = [1e-2 * 0.97 ** i for i in range(25)]
    ours, p_ours = _run(lambda g: Adam(g, lr=1e-2, **options), 25, lrs=lrs)
    theirs, p_theirs = _run(lambda g: torch.optim.Adam(g, lr=1e-2, **options), 25, lrs=lrs)
    for x, y in zip(p_ours, p_theirs):
        assert torch.equal(x, y)
    s_ours, s_theirs = ours.state_dict(), theirs.state_dict()
    assert s_ours["param_groups"] == s_theirs["param_groups"]
    assert s_ours["state"].keys() == s_theirs["state"].keys() == {0, 1, 2}  # the parameter without a gradient: none
    for k, state in s_ours["state"].items():
        assert state.keys() == s_theirs["state"][k].keys()
        for name, value in state.items():
            assert value.dtype == s_theirs["state"][k][name].dtype and torch.equal(value, s_theirs["state"][k][name])


@pytest.mark.parametrize("direction", ["torch_to_ours", "ours_to_torch"])
def test_a_checkpoint_of_either_continues_in_the_other_bit_for_bit(direction):
    first, second = (torch.optim.Adam, Adam) if direction == "torch_to_ours" else (Adam, torch.optim.Adam)
    groups, loss = _problem(1)
    opt = first(groups, lr=5e-3)
    for _ in range(6):
        opt.zero_grad()
        loss().backward()
        opt.step()
    saved = opt.state_dict()  # live tensors, which a loading optimiser then steps in place: a copy each time
    params = [p.detach().clone() for grp in groups for p in grp["params"]]

    def resume(kind):
        fresh, fresh_loss = _problem(1)
        for grp, values in zip(fresh, [params[:2], params[2:]]):
            for p, v in zip(grp["params"], values):
                p.data.copy_(v)
        other = kind(fresh, lr=1.0)  # the saved groups' settings replace these
        other.load_state_dict(copy.deepcopy(saved))
        for _ in range(5):
            other.zero_grad()
            fresh_loss().backward()
            other.step()
        return [p.detach() for grp in fresh for p in grp["params"]], other

    got, other = resume(second)
    want, _ = resume(first)
    assert other.param_groups[1]["lr"] == 3e-3 and other.param_groups[0]["lr"] == 5e-3
    for x, y in zip(got, want):
        assert torch.equal(x, y)


def test_a_mismatched_checkpoint_is_refused():
    groups, _ = _problem(2)
    saved = torch.optim.Adam(groups).state_dict()
    other, _ = _problem(2)
    with pytest.raises(ValueError, match="number of parameter groups"):
        Adam(other[:1]).load_state_dict(saved)
    other[1]["params"] = other[1]["params"][:1]
    with pytest.raises(ValueError, match="doesn't match the size"):
        Adam(other).load_state_dict(saved)


def test_unsupported_options_are_refused():
    p = [torch.zeros(2, requires_grad=True)]
    with pytest.raises(TypeError, match="differentiable"):
        Adam(p, differentiable=True)
    with pytest.raises(TypeError, match="momentum"):
        Adam(p, momentum=0.9)
    with pytest.raises(ValueError, match="empty"):
        Adam([])


def test_it_never_imports_dynamo():
    code = (
        "import sys, torch\n"
        "from wresdyn.learn.adam import Adam\n"
        "p = torch.nn.Linear(3, 2)\n"
        "for options in ({}, {'foreach': True}, {'fused': True}):\n"
        "    opt = Adam(p.parameters(), lr=1e-3, **options)\n"
        "    p(torch.randn(4, 3)).sum().backward()\n"
        "    opt.step(); opt.zero_grad()\n"
        "    opt.load_state_dict(opt.state_dict())\n"
        "torch.nn.utils.clip_grad_norm_(p.parameters(), 1.0)\n"
        "sys.exit(3 if 'torch._dynamo' in sys.modules else 0)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]


def test_zero_grad_sets_to_none_or_zeroes_in_place_as_torch():
    groups, loss = _problem(3)
    opt = Adam(groups)
    loss().backward()
    grad = groups[0]["params"][0].grad
    opt.zero_grad(set_to_none=False)
    assert groups[0]["params"][0].grad is grad and not grad.any()  # the same tensor, zeroed
    assert groups[1]["params"][1].grad is None  # never had one
    loss().backward()
    opt.zero_grad()
    assert all(p.grad is None for g in groups for p in g["params"])
