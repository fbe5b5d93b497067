"""Residual models: what the learner adds to the PD replay so the simulator follows the real robot.

Two kinds, one flag (:attr:`ResidualConfig.kind`):

* ``"torque"`` (the paper, eq. 1): M(q)q̈ + C(q,q̇)q̇ + G(q) + f(q,q̇,q̈) = τ_pd + τ_res, with
  τ_res = clip(g · a, −1, 1) · fraction · effort_limit per joint for network output a, written to
  ``control.joint_f``.
* ``"delta_action"`` (ASAP): the action shifts the PD target, q_target = q_cmd + clip(g · a, −1, 1) · Δ_max.
  With Δ_max = fraction · effort_limit / kp the two kinds have the same authority: kp · Δ_max = τ_res max.

The action gain g (:attr:`ResidualConfig.action_gain`) < 1 lets the network work in units where rsl-rl's
Gaussian starts at std 1, the scale its adaptive learning rate is tuned for: KL between two Gaussians
depends on Δμ/σ, and Adam moves the output by about the same amount per step whatever σ is, so a
small σ in action units pins the learning rate at its floor and the policy random-walks.

Observations (paper Sec. II-B) are the simulated joint states and the command, [q, q̇, q̈, q_cmd],
shape (N, 4·n_dof), normalised by fixed per-channel statistics of the training recordings.

The networks are rsl-rl models (MLP with ELU, or GRU + MLP), trained by :mod:`wresdyn.ppo.trainer`.
:class:`ResidualPolicy` is the deterministic, batched, exportable form that every consumer uses
(evaluation, a gradient learner, deployment): raw observation in, physical residual out.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn

from ..choices import Arch, choices
from .network_file import export_onnx, save_program
from .residual_config import ResidualConfig

__all__ = [
    "ARCHS",
    "ResidualConfig",
    "obs_stats",
    "EluMLP",
    "ResidualMLPModel",
    "ResidualRNNModel",
    "actor_critic_cfg",
    "ResidualPolicy",
    "MLPResidualPolicy",
    "GRUResidualPolicy",
    "policy_from_actor",
    "export_policy",
    "export_run_files",
]

ARCHS = choices(Arch)
"""Network architectures: MLP with ELU, or GRU followed by the MLP (paper Fig. 4)."""


OBS_MIN_STD = (0.05, 0.5, 5.0, 0.05)
"""Floor of the normalising std per observation group q [rad], q̇ [rad/s], q̈ [rad/s²], q_cmd [rad]: a joint
that barely moves in the recordings moves more in simulation (exploration, the gap itself), and dividing
by its tiny recorded std would turn that into inputs of ±100."""


def obs_stats(trajectories, min_std=OBS_MIN_STD) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel mean and std of :func:`observation` over recorded trajectories, each shape (4n,),
    the std floored per group by ``min_std`` (see :data:`OBS_MIN_STD`)."""
    parts = [np.concatenate([t.q, t.qd, t.qdd, t.q_cmd], axis=1) for t in trajectories]
    x = np.concatenate(parts, axis=0)
    n = x.shape[1] // 4
    return x.mean(0), np.maximum(x.std(0), np.repeat(np.asarray(min_std, dtype=np.float64), n))


def _shrink_last_layer(mlp: nn.Module, gain: float) -> None:
    last = [m for m in mlp.modules() if isinstance(m, nn.Linear)][-1]
    with torch.no_grad():
        last.weight.mul_(gain)
        last.bias.zero_()


class EluMLP(nn.Sequential):
    """Linear layers with ELU between them, the last one linear: rsl-rl's ``MLP`` (same layers, names, one shared
    activation, the same draws from torch's generator, so the same weights under one seed) without importing
    rsl-rl, whose package import loads tensordict and torch's compiler (seconds) that a gradient fit never uses.
    Input (N, ``n_in``) -> output (N, ``n_out``)."""

    def __init__(self, n_in: int, n_out: int, hidden_dims) -> None:
        super().__init__()
        act = nn.ELU()
        sizes = [n_in, *hidden_dims]
        layers = []
        for a, b in zip(sizes[:-1], sizes[1:]):
            layers += [nn.Linear(a, b), act]
        layers.append(nn.Linear(sizes[-1], n_out))
        for i, layer in enumerate(layers):
            self.add_module(str(i), layer)


_RSL_MODELS = ("ResidualMLPModel", "ResidualRNNModel")
"""The actor classes built on rsl-rl's models: made on first access (:func:`__getattr__`)."""


def _rsl_models() -> dict[str, type]:
    """rsl-rl's :class:`~rsl_rl.models.MLPModel` and :class:`~rsl_rl.models.RNNModel` (GRU + MLP) whose output starts
    near zero (``output_gain``): ``ResidualMLPModel`` and ``ResidualRNNModel``, the actors of residual PPO."""
    from rsl_rl.models import MLPModel, RNNModel

    class ResidualMLPModel(MLPModel):
        def __init__(self, *args, output_gain: float = 1.0, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            _shrink_last_layer(self.mlp, output_gain)

    class ResidualRNNModel(RNNModel):
        def __init__(self, *args, output_gain: float = 1.0, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            _shrink_last_layer(self.mlp, output_gain)

    out = {"ResidualMLPModel": ResidualMLPModel, "ResidualRNNModel": ResidualRNNModel}
    for name, cls in out.items():  # named as module attributes: pickle and rsl-rl's "module:Class" find them
        cls.__qualname__ = name
        cls.__module__ = __name__
    return out


def __getattr__(name: str):
    """``ResidualMLPModel`` and ``ResidualRNNModel`` on first access (rsl-rl resolving :func:`actor_critic_cfg`'s
    class names, an import, pickle): rsl-rl loads with PPO only, not with every user of this module."""
    if name in _RSL_MODELS:
        globals().update(_rsl_models())
        return globals()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def actor_critic_cfg(cfg: ResidualConfig) -> tuple[dict, dict]:
    """rsl-rl ``actor`` and ``critic`` config dicts for :class:`~rsl_rl.runners.OnPolicyRunner`."""
    dist = {"class_name": "GaussianDistribution", "init_std": cfg.init_std, "std_type": "log"}
    actor = {
        "class_name": f"{__name__}:ResidualMLPModel",
        "hidden_dims": list(cfg.hidden_dims),
        "activation": "elu",
        # on top of the environment's fixed data statistics: q̈ and q̇ in simulation, under exploration
        # noise, spread several times wider than in the recordings
        "obs_normalization": cfg.obs_normalization,
        "distribution_cfg": dist,
        "output_gain": cfg.output_gain,
    }
    if cfg.arch == "gru":
        actor.update(class_name=f"{__name__}:ResidualRNNModel", rnn_type="gru", rnn_hidden_dim=cfg.gru_hidden_dim,
                     rnn_num_layers=cfg.gru_layers)
    critic = {"class_name": "MLPModel", "hidden_dims": list(cfg.critic_hidden_dims), "activation": "elu",
              "obs_normalization": cfg.obs_normalization}
    return actor, critic


class MaskedClip(torch.autograd.Function):
    """``clamp(a, −1, 1)`` whose backward is one ``where`` on the mask ``clamp(a) == a`` kept from the forward pass
    (an eq there), where autograd's own runs five kernels a call (a 0-dim zero, ``a >= −1``, ``a <= 1``, their and, a
    where). The same mask (NaN: outside, as for the comparisons), values and gradients, bit for bit."""

    @staticmethod
    def forward(ctx, a):
        c = a.clamp(-1.0, 1.0)
        ctx.save_for_backward(torch.eq(c, a))
        return c

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad):
        (inside,) = ctx.saved_tensors
        return torch.where(inside, grad, 0.0)  # +0 outside, as torch's clamp backward writes


def residual_grad(g_r, g_a, scale: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """The gradient at a residual r from those of r and of its action r / scale (either ``None``: no gradient), summed
    in one ``addcdiv``: the same g_r + g_a / scale that the division's backward and autograd's addition form; zeros
    shaped as ``like`` where neither came."""
    if g_a is not None:
        return g_a / scale if g_r is None else torch.addcdiv(g_r, g_a, scale)
    return torch.zeros_like(like, dtype=scale.dtype) if g_r is None else g_r


class ClipScale(torch.autograd.Function):
    """(a, scale) -> (clamp(a, −1, 1) · scale, that / scale): a residual and its normalised action (what a
    differentiable rollout keeps for the loss) in one node, with :class:`MaskedClip`'s mask. Its backward sums the two
    gradients in one ``addcdiv`` (g_r + g_a / scale, the sum autograd forms from the division's backward and an
    addition), then the product's and the clip's backward; the same values and gradients bit for bit."""

    @staticmethod
    def forward(ctx, a, scale, out=None):
        c = a.clamp(-1.0, 1.0)
        ctx.save_for_backward(torch.eq(c, a), scale)
        ctx.set_materialize_grads(False)
        r = c * scale if out is None else torch.mul(c, scale, out=out).view(c.shape)  # a fresh view: the output
        return r, r / scale

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_r, g_a):
        inside, scale = ctx.saved_tensors
        return torch.where(inside, residual_grad(g_r, g_a, scale, inside) * scale, 0.0), None, None


class ResidualPolicy(nn.Module):
    """Deterministic residual: raw observation (N, 4n) -> physical residual (N, n) [N*m or rad].

    residual = scale · clip(gain · net(norm((obs − mean) / std)), −1, 1), ``norm`` an optional second
    normaliser (identity by default). Differentiable in the parameters.
    """

    def __init__(self, obs_mean, obs_std, scale, kind: str, gain: float = 1.0, norm: nn.Module | None = None) -> None:
        super().__init__()
        self.kind = kind
        self.gain = float(gain)
        self.norm = nn.Identity() if norm is None else norm
        self.register_buffer("obs_mean", torch.as_tensor(obs_mean, dtype=torch.float32))
        self.register_buffer("obs_std", torch.as_tensor(obs_std, dtype=torch.float32))
        self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32))

    def _to_residual(self, a: torch.Tensor) -> torch.Tensor:
        # at gain 1 (every residual but PPO's with an action gain) the product is ``a`` itself, bit for bit: skip it,
        # one kernel forward and one backward per step of a differentiable rollout
        a = a if self.gain == 1.0 else self.gain * a
        # training with gradients (the gradient fit's plain path): the clip with a backward of one kernel; evaluation,
        # export and no-grad calls keep torch's own clamp
        return (MaskedClip.apply(a) if self._masked(a) else a.clamp(-1.0, 1.0)) * self.scale

    def _masked(self, a: torch.Tensor) -> bool:
        return self.training and torch.is_grad_enabled() and a.requires_grad

    def _to_residual_action(self, a: torch.Tensor, out=None) -> tuple[torch.Tensor, torch.Tensor]:
        """(residual, residual / scale) of network output ``a``, the second what a rollout records as the action;
        with gradients the residual written into ``out`` where given."""
        a = a if self.gain == 1.0 else self.gain * a
        if self._masked(a):
            return ClipScale.apply(a, self.scale, out)
        r = a.clamp(-1.0, 1.0) * self.scale
        return r, r / self.scale

    def residual_kind(self) -> str:
        """``"torque"`` or ``"delta_action"`` (the exported residual has it too)."""
        return self.kind


class MLPResidualPolicy(ResidualPolicy):
    """MLP (ELU) residual; stateless, ``reset`` is a no-op."""

    def __init__(self, mlp: nn.Module, obs_mean, obs_std, scale, kind: str, gain: float = 1.0,
                 norm: nn.Module | None = None) -> None:
        super().__init__(obs_mean, obs_std, scale, kind, gain, norm)
        self.mlp = mlp

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self._to_residual(self.mlp(self.norm((obs - self.obs_mean) / self.obs_std)))

    def residual_and_action(self, obs: torch.Tensor, out: torch.Tensor | None = None):
        """(residual, residual / scale): :meth:`forward` and the normalised action a rollout records
        (:func:`wresdyn.sim.rollout`), in one node where gradients flow (:class:`ClipScale`, which writes the residual
        into ``out`` where given: the simulator's torque input, :func:`~wresdyn.sim.tape_step.step_forces`)."""
        return self._to_residual_action(self.mlp(self.norm((obs - self.obs_mean) / self.obs_std)), out)

    def reset(self) -> None:
        pass


class GRUResidualPolicy(ResidualPolicy):
    """GRU + MLP residual. ``forward`` keeps the hidden state between calls; call ``reset()`` at the start of
    each rollout (a batch of a new size also starts from zeros). ``step`` is the pure form (what the exports hold)."""

    def __init__(self, gru: nn.GRU, mlp: nn.Module, obs_mean, obs_std, scale, kind: str, gain: float = 1.0,
                 norm: nn.Module | None = None) -> None:
        super().__init__(obs_mean, obs_std, scale, kind, gain, norm)
        self.gru = gru
        self.mlp = mlp
        self.hidden = torch.zeros(gru.num_layers, 0, gru.hidden_size)

    def step(self, obs: torch.Tensor, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """One step: obs (N, 4n), hidden (layers, N, H) -> residual (N, n), new hidden."""
        y, h = self.gru(self.norm((obs - self.obs_mean) / self.obs_std).unsqueeze(0), h)
        return self._to_residual(self.mlp(y.squeeze(0))), h

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        h = self.hidden
        if h.shape[1] != obs.shape[0]:
            h = torch.zeros(self.gru.num_layers, obs.shape[0], self.gru.hidden_size, dtype=obs.dtype, device=obs.device)
        out, h = self.step(obs, h)
        self.hidden = h
        return out

    def reset(self) -> None:
        self.hidden = torch.zeros(self.gru.num_layers, 0, self.gru.hidden_size, device=self.obs_mean.device)


def policy_from_actor(actor, obs_mean, obs_std, scale, kind: str, gain: float = 1.0) -> ResidualPolicy:
    """Copy a trained rsl-rl actor (an ``MLPModel`` or ``RNNModel``) into a :class:`ResidualPolicy` (CPU, eval mode)."""
    import copy

    mlp = copy.deepcopy(actor.mlp).cpu()
    norm = copy.deepcopy(actor.obs_normalizer).cpu()
    if getattr(actor, "is_recurrent", False):
        pol = GRUResidualPolicy(copy.deepcopy(actor.rnn.rnn).cpu(), mlp, obs_mean, obs_std, scale, kind, gain, norm)
    else:
        pol = MLPResidualPolicy(mlp, obs_mean, obs_std, scale, kind, gain, norm)
    return pol.eval()


class _PureGRU(nn.Module):
    """The GRU residual's pure step, (obs, h_in) -> (residual, h_out): what its exports hold."""

    def __init__(self, policy: GRUResidualPolicy) -> None:
        super().__init__()
        self.policy = policy

    def forward(self, obs: torch.Tensor, h_in: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.policy.step(obs, h_in)


def export_policy(policy: ResidualPolicy, path: str | Path, onnx_path: str | Path | None = None):
    """Save ``policy`` as a ``torch.export`` archive at ``path`` (:mod:`wresdyn.learn.network_file`; loaded back by
    :func:`~wresdyn.learn.network_file.load_residual`) and, with ``onnx_path``, as ONNX, both with a dynamic batch axis.

    MLP: ``obs`` (N, 4n) -> ``residual`` (N, n). GRU: (``obs``, ``h_in`` (layers, N, H)) -> (``residual``,
    ``h_out``); the caller carries the hidden state, starting from zeros (``load_residual`` does).
    """
    program, names_in, names_out = _save_archive(policy, path)
    if onnx_path is not None:
        export_onnx(program, onnx_path, names_in, names_out)
    return program


def _save_archive(policy: ResidualPolicy, path: str | Path):
    """:func:`export_policy`'s archive: ``(program, input names, output names)``, the program saved at ``path``."""
    n_obs = policy.obs_mean.shape[0]
    batch = torch.export.Dim("batch", min=1)
    obs = torch.zeros(2, n_obs)  # a batch of 2: torch.export specialises a size-1 axis to the constant 1
    meta = {"kind": policy.kind, "hidden": None}
    if isinstance(policy, GRUResidualPolicy):
        module, args = _PureGRU(policy), (obs, torch.zeros(policy.gru.num_layers, 2, policy.gru.hidden_size))
        shapes = {"obs": {0: batch}, "h_in": {1: batch}}
        names_in, names_out = ["obs", "h_in"], ["residual", "h_out"]
        meta["hidden"] = [policy.gru.num_layers, policy.gru.hidden_size]
    else:
        module, args, shapes = policy, (obs,), {"obs": {0: batch}}
        names_in, names_out = ["obs"], ["residual"]
    return save_program(module, args, shapes, path, meta), names_in, names_out


def export_run_files(policy: ResidualPolicy, run_dir: str | Path, dataset, onnx_later: bool = False,
                     archive_later: bool = False, **meta):
    """Write what ``wresdyn eval`` and a deployment read from a run folder: ``policy.pt`` (the ``torch.export``
    archive of :func:`export_policy`, under the name tools check for a trained run), ``policy.onnx`` and
    ``residual.json`` (kind, joints, rate, scale, I/O units, plus ``meta``).

    With ``onnx_later`` the ONNX file is left to the caller: the function that writes it (the same file, from the
    same program) is returned, so that it can run beside other work (the evaluation reads ``policy.pt`` only, and
    the ONNX export is most of the export's time); otherwise it is written here and ``None`` is returned. With
    ``archive_later`` both ``policy.pt`` and ``policy.onnx`` are left to the caller: the picklable call that writes
    them (:func:`export_archive_and_onnx` of ``policy``, e.g. for another process) is returned.
    """
    import json

    run_dir = Path(run_dir)
    if archive_later:
        run_dir.mkdir(parents=True, exist_ok=True)
        write_onnx = functools.partial(export_archive_and_onnx, policy, run_dir / "policy.pt", run_dir / "policy.onnx")
    else:
        program, names_in, names_out = _save_archive(policy, run_dir / "policy.pt")
        write_onnx = functools.partial(export_onnx, program, run_dir / "policy.onnx", names_in, names_out)
        if not onnx_later:
            write_onnx()
    info = {"kind": policy.kind, "joint_names": list(dataset.joint_names), "rate_hz": float(dataset.rate_hz),
            "scale": [float(s) for s in policy.scale], **meta,
            "observation": "[q, qd, qdd, q_cmd] raw SI units, (N, 4 n_dof)",
            "output": "N*m added to the PD torque" if policy.kind == "torque" else "rad added to q_cmd"}
    (run_dir / "residual.json").write_text(json.dumps(info, indent=2))
    return write_onnx if onnx_later or archive_later else None


def export_archive_and_onnx(policy: ResidualPolicy, archive: str | Path, onnx_path: str | Path) -> None:
    """Write ``policy``'s archive at ``archive`` and its ONNX twin at ``onnx_path`` from that one program: the two
    files of :func:`export_run_files`."""
    program, names_in, names_out = _save_archive(policy, archive)
    export_onnx(program, onnx_path, names_in, names_out)
