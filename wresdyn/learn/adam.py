"""Adam as ``torch.optim.Adam`` steps it, without ``torch.optim.Optimizer``'s machinery.

``torch.optim.Optimizer`` imports ``torch._dynamo`` in its constructor (``add_param_group`` is wrapped in
``torch._disable_dynamo``) and in every ``step`` (``torch._dynamo.graph_break``): 4.2 s of a warm 52.5 s GPU fit
(``benchmarks/results/speed/warm57_accounting.md``, row 2) and about 167,000 objects, for a compiler no fit uses.
:class:`Adam` keeps what the fits use of that class (``param_groups`` with their extra keys, ``state`` per parameter,
``zero_grad``, ``step``, ``state_dict`` and ``load_state_dict`` in the same format) and steps through torch's own
functional update, :func:`torch.optim.adam.adam`, with the arguments ``torch.optim.Adam.step`` passes: the same
single-tensor, foreach, fused and capturable kernels, so the parameters after each step are torch's bit for bit
(``tests/learn/test_adam.py``), and either class loads the other's checkpoints.
"""

from __future__ import annotations

import copy
from itertools import chain

import torch
from torch.optim.adam import adam as _adam_update

__all__ = ["Adam"]

_DEFAULTS = {"lr": 1e-3, "betas": (0.9, 0.999), "eps": 1e-8, "weight_decay": 0.0, "amsgrad": False,
             "maximize": False, "foreach": None, "capturable": False, "differentiable": False, "fused": None,
             "decoupled_weight_decay": False}


def _step_dtype(fused) -> torch.dtype:
    """The step count's dtype, as torch's Adam makes it (``optimizer._get_scalar_dtype``)."""
    if fused:
        return torch.float32
    return torch.float64 if torch.get_default_dtype() == torch.float64 else torch.float32


class Adam:
    """``torch.optim.Adam(params, lr, ...)`` for the fits: ``params`` an iterable of tensors or of parameter groups
    (dicts with ``params`` and any other keys, kept as given); every keyword of ``torch.optim.Adam`` but
    ``differentiable``."""

    def __init__(self, params, lr: float = 1e-3, **options) -> None:
        unknown = set(options) - set(_DEFAULTS)
        if unknown or options.get("differentiable"):
            raise TypeError(f"Adam: unsupported options {sorted(unknown) or ['differentiable']}")
        if options.get("fused") and options.get("foreach"):
            raise RuntimeError("`fused` and `foreach` cannot be `True` together.")
        if not 0.0 <= float(lr):
            raise ValueError(f"Invalid learning rate: {lr}")
        self.defaults = {**_DEFAULTS, **options, "lr": lr}
        self.defaults["betas"] = tuple(float(b) for b in self.defaults["betas"])
        params = list(params)
        if not params:
            raise ValueError("optimizer got an empty parameter list")
        self.param_groups: list[dict] = []
        self.state: dict = {}  # parameter -> {"step", "exp_avg", "exp_avg_sq"[, "max_exp_avg_sq"]}
        for group in params if isinstance(params[0], dict) else [{"params": params}]:
            group = dict(group)
            group["params"] = [group["params"]] if torch.is_tensor(group["params"]) else list(group["params"])
            for key, value in self.defaults.items():
                group.setdefault(key, value)
            self.param_groups.append(group)

    def zero_grad(self, set_to_none: bool = True) -> None:
        for group in self.param_groups:
            for p in group["params"]:
                if p.grad is None:
                    continue
                if set_to_none:
                    p.grad = None
                    continue
                if p.grad.grad_fn is not None:
                    p.grad.detach_()
                else:
                    p.grad.requires_grad_(False)
                p.grad.zero_()

    def _new_state(self, p: torch.Tensor, group: dict) -> dict:
        # the step count on the host unless a capture or the fused kernel reads it (torch's "special device hosting")
        on_device = group["capturable"] or group["fused"]
        state = {"step": torch.zeros((), dtype=_step_dtype(group["fused"]), device=p.device) if on_device
                 else torch.tensor(0.0, dtype=_step_dtype(None), device="cpu"),
                 "exp_avg": torch.zeros_like(p, memory_format=torch.preserve_format),
                 "exp_avg_sq": torch.zeros_like(p, memory_format=torch.preserve_format)}
        if group["amsgrad"]:
            state["max_exp_avg_sq"] = torch.zeros_like(p, memory_format=torch.preserve_format)
        return state

    @torch.no_grad()
    def step(self) -> None:
        for group in self.param_groups:
            params, grads, exp_avgs, exp_avg_sqs, max_sqs, steps = [], [], [], [], [], []
            has_complex = False
            for p in group["params"]:
                if p.grad is None:
                    continue
                if p.grad.is_sparse:
                    raise RuntimeError("Adam does not support sparse gradients")
                has_complex |= torch.is_complex(p)
                state = self.state.get(p)
                if not state:
                    state = self.state[p] = self._new_state(p, group)
                params.append(p)
                grads.append(p.grad)
                exp_avgs.append(state["exp_avg"])
                exp_avg_sqs.append(state["exp_avg_sq"])
                if group["amsgrad"]:
                    max_sqs.append(state["max_exp_avg_sq"])
                steps.append(state["step"])
            beta1, beta2 = group["betas"]
            _adam_update(params, grads, exp_avgs, exp_avg_sqs, max_sqs, steps, amsgrad=group["amsgrad"],
                         has_complex=has_complex, beta1=beta1, beta2=beta2, lr=group["lr"],
                         weight_decay=group["weight_decay"], eps=group["eps"], maximize=group["maximize"],
                         foreach=group["foreach"], capturable=group["capturable"], differentiable=False,
                         fused=group["fused"], grad_scale=None, found_inf=None,
                         decoupled_weight_decay=group["decoupled_weight_decay"])

    def state_dict(self) -> dict:
        """``torch.optim.Optimizer.state_dict``'s format: the state keyed by each parameter's index over the groups,
        each group's settings with its parameters' indices."""
        index: dict[int, int] = {}
        groups = []
        for group in self.param_groups:
            packed = {k: v for k, v in group.items() if k != "params"}
            for p in group["params"]:
                index.setdefault(id(p), len(index))
            packed["params"] = [index[id(p)] for p in group["params"]]
            groups.append(packed)
        return {"state": {index[id(p)]: s for p, s in self.state.items()}, "param_groups": groups}

    def load_state_dict(self, state_dict: dict) -> None:
        """Load a state saved by :meth:`state_dict` or by ``torch.optim.Adam`` (the saved groups' settings replace
        these, as torch's does); the moments are cast to their parameter's dtype and device, the step count moved
        only where a capture or the fused kernel reads it."""
        saved_groups = copy.deepcopy(state_dict["param_groups"])
        if len(saved_groups) != len(self.param_groups):
            raise ValueError("loaded state dict has a different number of parameter groups")
        if [len(g["params"]) for g in saved_groups] != [len(g["params"]) for g in self.param_groups]:
            raise ValueError("loaded state dict contains a parameter group that doesn't match the size of "
                             "optimizer's group")
        params = dict(zip(chain.from_iterable(g["params"] for g in saved_groups),
                          chain.from_iterable(g["params"] for g in self.param_groups)))
        group_of = {i: g for g in saved_groups for i in g["params"]}
        state = {}
        for key, values in state_dict["state"].items():
            p = params.get(key)
            if p is None:
                state[key] = values
                continue
            on_device = group_of[key].get("capturable", False) or group_of[key].get("fused", False)
            state[p] = {name: self._cast(p, name, value, on_device) for name, value in values.items()}
        for saved, group in zip(saved_groups, self.param_groups):
            saved["params"] = group["params"]
            for key, value in self.defaults.items():
                saved.setdefault(key, value if key != "lr" else group["lr"])
        self.param_groups, self.state = saved_groups, state

    @staticmethod
    def _cast(p: torch.Tensor, name: str, value, on_device: bool):
        if not torch.is_tensor(value):
            return value
        if name == "step":
            return value.to(dtype=torch.float32, device=p.device) if on_device else value
        return value.to(dtype=p.dtype, device=p.device) if p.is_floating_point() else value.to(device=p.device)
