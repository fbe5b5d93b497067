"""The file format of wresdyn's exported networks (residuals and skills): a ``torch.export`` archive and its ONNX twin.

A network is exported once through ``torch.export`` (an :class:`~torch.export.ExportedProgram`: the graph and its
weights, no Python code); the same program is saved as the archive (the ``.pt2`` format of
:func:`torch.export.save`, with a ``wresdyn.json`` of metadata inside) and converted to ONNX by torch's current
exporter (``torch.onnx.export(program, dynamo=True)``). Both have a dynamic batch axis. Loading needs torch only:

- :func:`load_residual` gives the residual back as a module with ``forward(obs)``, ``reset()``,
  ``residual_kind()`` and the ``kind``, ``scale``, ``obs_mean``, ``obs_std`` the simulator reads; a recurrent one
  (GRU) carries its hidden state between calls, as the training-side policy does;
- :func:`load_program` gives the program and the metadata (``program.module()(*inputs)`` runs it).

A run folder keeps the archive under the name ``policy.pt`` (the name tools check to tell a trained run); an export
folder names it ``residual.pt2``. The archive is written and read as bytes so that torch accepts either name.
"""

from __future__ import annotations

import io
import json
import logging
import os
import warnings
import zipfile
from pathlib import Path

import torch

from ..errors import WresdynError

__all__ = ["save_program", "load_program", "export_onnx", "ExportedResidual", "load_residual"]

META = "wresdyn.json"
"""Name of the metadata file inside an archive."""


def save_program(module, args: tuple, dynamic_shapes, path, meta: dict):
    """Export ``module(*args)`` through ``torch.export`` with ``dynamic_shapes`` (as :func:`torch.export.export`)
    and save it with ``meta`` to ``path`` (written next to it and renamed into place). Returns the program."""
    with warnings.catch_warnings():
        # nn.GRU keeps its weights in a plain list (_flat_weights) that torch.export reads as assigned attributes;
        # the parameters themselves are registered, so the program holds the right weights
        warnings.filterwarnings("ignore", message=r"The tensor attributes .*_flat_weights")
        program = torch.export.export(module.eval(), args, dynamic_shapes=dynamic_shapes)
    buf = io.BytesIO()
    torch.export.save(program, buf, extra_files={META: json.dumps(meta)})
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, path)
    return program


def load_program(path):
    """The program of an archive and its metadata: ``(program, meta)``."""
    data = Path(path).read_bytes()
    try:
        names = zipfile.ZipFile(io.BytesIO(data)).namelist()
    except zipfile.BadZipFile:
        raise WresdynError(f"{path}: not a torch.export archive (corrupt or not a model file)") from None
    if not any(n.endswith("archive_format") for n in names):
        raise WresdynError(f"{path}: a TorchScript file, which this version of wresdyn no longer reads; train or "
                           "export the run again") from None
    extra = {META: ""}
    program = torch.export.load(io.BytesIO(data), extra_files=extra)
    return program, json.loads(extra[META] or "{}")


def export_onnx(program, path, input_names: list[str], output_names: list[str]) -> Path:
    """Write ``program`` as ONNX (opset 18) through torch's dynamo-based exporter, inputs and outputs named."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # the exporter logs a warning per torchvision operator it cannot register when torchvision is absent: none of
    # them is in a residual or a skill
    registration = logging.getLogger("torch.onnx._internal.exporter._registration")
    level = registration.level
    registration.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            # raised inside torch's exporter (it copies pytree specs with copyreg), not by anything passed to it
            warnings.filterwarnings("ignore", message=r"`isinstance\(treespec, LeafSpec\)` is deprecated")
            # external_data=False: one self-contained file (the networks are far below ONNX's 2 GB limit)
            torch.onnx.export(program, (), str(path), input_names=input_names, output_names=output_names,
                              dynamo=True, opset_version=18, external_data=False, verbose=False)
    finally:
        registration.setLevel(level)
    return path


class ExportedResidual(torch.nn.Module):
    """A residual loaded from its archive: ``forward(obs (N, 4n)) -> residual (N, n)`` [N*m or rad].

    A recurrent residual (``meta["hidden"]`` = [layers, size]) runs the program's pure step
    ``(obs, h_in) -> (residual, h_out)`` and keeps ``h`` between calls; ``reset()`` (or a batch of a new size)
    starts it from zeros.
    """

    def __init__(self, program, meta: dict) -> None:
        super().__init__()
        self.net = program.module()
        self.kind = str(meta["kind"])
        self.hidden_shape = tuple(meta["hidden"]) if meta.get("hidden") else None
        self.hidden = None
        for name in ("obs_mean", "obs_std", "scale"):
            value = next(v for k, v in program.state_dict.items() if k.rsplit(".", 1)[-1] == name)
            self.register_buffer(name, torch.as_tensor(value).detach().clone())

    def train(self, mode: bool = True):
        """Only the flag: the program was exported in eval mode and cannot switch (torch refuses ``train()``)."""
        self.training = mode
        return self

    def residual_kind(self) -> str:
        """``"torque"`` or ``"delta_action"``."""
        return self.kind

    def reset(self) -> None:
        self.hidden = None

    def forward(self, obs):
        if self.hidden_shape is None:
            return self.net(obs)
        layers, size = self.hidden_shape
        h = self.hidden
        if h is None or h.shape[1] != obs.shape[0]:
            h = torch.zeros(layers, obs.shape[0], size, dtype=obs.dtype, device=obs.device)
        out, self.hidden = self.net(obs, h)
        return out


def load_residual(path) -> ExportedResidual:
    """The residual of an archive (a run's ``policy.pt``, an export's ``residual.pt2``), on the CPU."""
    program, meta = load_program(path)
    return ExportedResidual(program, meta).eval()
