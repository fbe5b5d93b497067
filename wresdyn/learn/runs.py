"""Run folders shared by the learners: resume only what was started, load only weights, keep the best.

A :class:`RunFolder` owns a learner's folder: its ``config.json``, the resume check, the weights-only checkpoint, the
learning curve (``curve.json``) and the best iterate on validation; a :class:`RunnerFolder` the folder of a runner that
keeps its own checkpoints (rsl-rl's PPO): the record, the resume check against it and the summary. A resumed run must
learn what it started learning, so the configuration saved with the checkpoint is compared with the new one field by
field (:func:`~wresdyn.learn.config_diff.config_diff`, :func:`check_resume`), and the refusal names the fields.
Checkpoints are read with ``torch.load(..., weights_only=True)`` (:func:`load_checkpoint`): tensors and plain
containers only, so a run folder from elsewhere cannot run code by being resumed.
"""

from __future__ import annotations

import json
import math
import re
import threading
from dataclasses import dataclass
from pathlib import Path

from ..errors import WresdynError
from ..robot.physical import PhysicalParams
from .config_diff import config_diff, describe_diff, plain_json

__all__ = ["RunError", "RunFolder", "RunnerFolder", "Best", "check_resume", "read_unset", "UNSET_WAS_ZERO",
           "run_physics", "load_checkpoint", "save_checkpoint", "write_json", "host_copy"]


class RunError(WresdynError):
    """A run folder that cannot be used as asked (another config, nothing to load, a bad checkpoint)."""


UNSET_WAS_ZERO = ("select_every", "grad_truncation", "torch_threads", "restart_std")
"""Config fields whose "use another value" is ``None``, and was 0 in the run folders written before it was: a 0 saved
there reads as ``None`` (:func:`read_unset`), so those runs resume and evaluate as they were."""


def run_physics(run: str | Path, robot) -> PhysicalParams | None:
    """The identified physics a run folder holds (its ``physics.json``: ``wresdyn identify``, a hybrid ``wresdyn
    fit``, a PPO residual on identified physics), checked against ``robot``; ``None`` where it holds none."""
    path = Path(run) / "physics.json"
    return PhysicalParams.load(path, robot) if path.is_file() else None


def read_unset(config):
    """``config`` (JSON-like) with a 0 (or 0.0: ``restart_std``) in a :data:`UNSET_WAS_ZERO` field, at any depth,
    read as ``None``."""
    if isinstance(config, dict):
        return {k: None if k in UNSET_WAS_ZERO and type(v) in (int, float) and v == 0 else read_unset(v)
                for k, v in config.items()}
    return config


def _added_unset(old, new):
    """``old`` with the keys that only ``new`` has where ``new`` holds ``None``, at any depth: a config field added
    after the run was written, at its ``None`` default (which keeps the behaviour from before the field), is not a
    change, so such runs resume."""
    if not (isinstance(old, dict) and isinstance(new, dict)):
        return old
    out = {k: _added_unset(v, new.get(k)) for k, v in old.items()}
    out.update({k: None for k, v in new.items() if k not in old and v is None})
    return out


def check_resume(run_dir, old: dict, new: dict, may_change=(), what: str = "configuration") -> None:
    """Raise :class:`RunError` naming the fields if ``new`` differs from the saved ``old`` outside ``may_change``.

    Args:
        run_dir: The run folder (named in the message).
        old, new: JSON-like configs (the saved one and the one asked for), both read with :func:`read_unset`.
        may_change: Dotted paths (as :func:`~wresdyn.learn.config_diff.config_diff` gives them) that a resumed run
            may change, e.g. ``("ppo.iterations", "ppo.device")``; a path also covers everything under it.
        what: What the dicts are, for the message (``"configuration"``, ``"data"``).
    """
    keep = tuple(may_change)

    def allowed(p: str) -> bool:
        return any(p == k or p.startswith(k + ".") or p.startswith(k + "[") for k in keep)

    old, new = read_unset(old), read_unset(new)
    changed = [p for p in config_diff(_added_unset(old, new), new) if not allowed(p)]
    if not changed:
        return
    # only the refused fields are described: the allowed ones changing is the normal case
    on = "trained with" if what == "configuration" else f"trained on other {what}:"
    raise RunError(f"{run_dir} was {on} {describe_diff(old, new, changed)}; resume with the same {what} "
                   "or choose another folder")


def _reason(e: Exception) -> str:
    # torch's refusal is several paragraphs; the class it would have had to import is the useful part
    text = str(e)
    m = re.search(r"GLOBAL (\S+)", text)
    if m:
        return f" (it would import {m.group(1)})"
    m = re.search(r"Unsupported operand \d+", text)
    return f" ({m.group(0)})" if m else ""


def load_checkpoint(path, map_location=None, keys=()) -> dict:
    """A checkpoint written by :func:`save_checkpoint` or ``torch.save``, read as weights only.

    ``torch.load(..., weights_only=True)`` rebuilds tensors and plain containers (dict, list, tuple, str, numbers,
    None) and refuses anything else, so a foreign or tampered file cannot run code here. Raises a one-line
    :class:`RunError` naming the file if it cannot be read that way, is not a dict, or lacks one of ``keys``.
    """
    import pickle

    import torch

    path = Path(path)
    try:
        data = torch.load(path, map_location=map_location, weights_only=True)
    except FileNotFoundError:
        raise RunError(f"{path}: no such checkpoint") from None
    except pickle.UnpicklingError as e:
        raise RunError(f"{path}: not a weights-only checkpoint, refused without loading it{_reason(e)}") from None
    except EOFError:
        raise RunError(f"{path}: not a readable checkpoint (empty or cut short)") from None
    except (RuntimeError, OSError, ValueError, KeyError, IndexError, TypeError, AttributeError) as e:
        first = (str(e).splitlines() or [type(e).__name__])[0][:120]
        raise RunError(f"{path}: not a readable checkpoint ({first})") from None
    if not isinstance(data, dict):
        raise RunError(f"{path}: not a checkpoint of this project (holds a {type(data).__name__}, not a dict)")
    missing = [k for k in keys if k not in data]
    if missing:
        raise RunError(f"{path}: not a checkpoint of this kind of run (no {', '.join(missing)})")
    return data


def save_checkpoint(data: dict, path) -> Path:
    """Write ``data`` (tensors and plain containers) with ``torch.save``, atomically: a kill mid-write leaves
    the previous checkpoint, never a truncated file that a resume would pick. Refuses what
    :func:`load_checkpoint` could not read back, so the failure shows when saving, not hours later."""
    import io

    import torch

    path = Path(path)
    buf = io.BytesIO()
    torch.save(data, buf)
    buf.seek(0)
    try:
        torch.load(buf, weights_only=True)
    except Exception as e:  # noqa: BLE001 - any failure here means the file would not load back
        raise TypeError(f"checkpoint for {path} holds more than tensors and plain containers{_reason(e)}") from None
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(buf.getvalue())
    tmp.replace(path)
    return path


def host_copy(data):
    """``data`` (tensors and plain containers) with every tensor copied to host memory and every container rebuilt,
    so that another thread can serialise it while the caller goes on changing the originals (an optimiser stepping
    its weights in place, the curve growing). Rows of a list of dicts (a learning curve: flat rows, never changed
    once appended) are copied shallowly."""
    import torch

    if isinstance(data, torch.Tensor):
        return data.detach().to("cpu", copy=True)
    if isinstance(data, dict):
        return {k: host_copy(v) for k, v in data.items()}
    if isinstance(data, list):
        if data and all(type(r) is dict for r in data) and all(
                not isinstance(v, (dict, list, tuple, torch.Tensor)) for v in data[-1].values()):
            return [dict(r) for r in data]
        return [host_copy(v) for v in data]
    if isinstance(data, tuple):
        return tuple(host_copy(v) for v in data)
    return data


def write_json(data, path) -> Path:
    """Write ``data`` as indented JSON, atomically (a kill mid-write leaves the previous file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2))
    tmp.replace(path)
    return path


@dataclass
class Best:
    """The best iterate on validation so far: a selection candidate."""

    value: float = math.inf
    """Its validation error (the learner's score, e.g. mean |Δq| [rad]); ``inf`` before any."""
    iteration: int = 0
    """The iteration it was scored after (0: the starting point)."""
    state: dict | None = None
    """A copy of the module's ``state_dict`` then; ``None`` before any."""

    def take(self, value: float, iteration: int, module) -> None:
        """Keep ``module``'s current state as the best, scored ``value`` after ``iteration``."""
        self.value, self.iteration = value, iteration
        self.state = {k: v.detach().clone() for k, v in module.state_dict().items()}

    def consider(self, value: float, iteration: int, module) -> bool:
        """Keep ``module``'s current state if ``value`` beats the best so far; whether it did."""
        if not value < self.value:
            return False
        self.take(value, iteration, module)
        return True


class RunFolder:
    """A learner's run folder: ``config.json``, the resume check, a weights-only checkpoint, ``curve.json`` and the
    best iterate on validation.

    The checkpoint holds the learner's own entries (weights, optimiser, generator states) plus ``"best"`` (the best
    state) and ``"meta"`` (the configuration it was trained with, the curve, the iteration, the wall-clock, the best
    value and iteration, and the learner's extra bookkeeping), so it alone is enough to resume. ``config.json`` is
    the run's record (``record`` with the configuration under ``key``), written once :meth:`resume` has found the
    folder fit to continue, never over the record of a refused run.

    Args:
        path: The folder, made when first written; ``None`` for a run kept in memory only (nothing is read or written).
        config: The learner's configuration as a JSON-like dict (``dataclasses.asdict`` of its config): compared
            with the checkpoint's on resume and stored in both files.
        may_change: Dotted paths of ``config`` a resumed run may change (:func:`check_resume`).
        key: Where ``config`` goes in ``config.json``.
        record: The rest of ``config.json`` (what reads the run needs, e.g. ``{"learner": "identify"}``).
        checkpoint: The checkpoint's file name.
    """

    def __init__(self, path, config: dict, may_change=(), key: str = "config", record: dict | None = None,
                 checkpoint: str = "checkpoint.pt") -> None:
        self.path = None if path is None else Path(path)
        """The folder, or ``None`` (in memory)."""
        self.config = config
        """The configuration this run learns with (JSON-like)."""
        self.may_change = tuple(may_change)
        """Paths of :attr:`config` a resume may change."""
        self.key, self.record = key, dict(record or {})
        self.checkpoint = None if self.path is None else self.path / checkpoint
        """The checkpoint file, or ``None``."""
        self.curve: list[dict] = []
        """The learning curve: one dict per iteration (``iteration``, ``wall`` [s], the learner's loss parts,
        ``validation`` where scored)."""
        self.best = Best()
        """The best iterate on validation so far."""
        self.iteration = 0
        """Iterations done (where a resumed run continues)."""
        self.wall = 0.0
        """Training wall-clock of those iterations [s]."""
        self.meta: dict = {}
        """The resumed checkpoint's ``meta`` (the learner's extra bookkeeping is there); empty for a fresh run."""
        self._writer: threading.Thread | None = None
        self._write_error: BaseException | None = None

    def resume(self, keys=(), map_location=None) -> dict | None:
        """Continue from the checkpoint if there is one: read it as weights only (with ``keys``, ``"best"`` and
        ``"meta"``), refuse it with a one-line :class:`RunError` naming the fields if it was trained with another
        configuration, and take its curve, iteration, wall-clock and best. Then write ``config.json``.

        Returns:
            The checkpoint (the learner restores its own entries from it), or ``None`` for a fresh run.
        """
        data = None
        if self.checkpoint is not None and self.checkpoint.exists():
            data = load_checkpoint(self.checkpoint, map_location=map_location, keys=(*keys, "best", "meta"))
            meta = data["meta"]
            check_resume(self.path, meta["config"], self.config, self.may_change)
            self.meta, self.curve, self.iteration, self.wall = meta, meta["curve"], meta["iteration"], meta["wall"]
            self.best = Best(meta["best_validation"], meta["best_iteration"], data["best"] or None)
        self.write_config()
        return data

    def write_config(self, **record) -> None:
        """Write ``config.json``: the record (updated with ``record``) and the configuration under ``key``."""
        self.record.update(record)
        if self.path is not None:
            write_json({**self.record, self.key: self.config}, self.path / "config.json")

    def save(self, state: dict, *, background: bool = False, **meta) -> None:
        """Checkpoint ``state`` (the learner's weights-only entries) with the best and the bookkeeping, atomically;
        ``meta``: the learner's extra bookkeeping (e.g. its window sampler's state). Sets :attr:`iteration` and
        :attr:`wall` from the curve's last row.

        With ``background`` the checkpoint is copied to host memory here (:func:`host_copy`) and serialised, checked
        and written on a thread while the caller trains on: serialising the growing curve and reading it back
        through the weights-only unpickler (pure Python) costs more than a training iteration late in a run. The
        thread touches host memory only (the copy is taken here), so it cannot meet a CUDA graph being captured.
        Checkpoints are written one at a time, in order; :meth:`flush` waits for the last and raises its error."""
        if self.curve:
            self.iteration, self.wall = self.curve[-1]["iteration"], self.curve[-1]["wall"]
        if self.checkpoint is None:
            return
        self.flush()
        meta = {"config": self.config, **meta, "curve": self.curve, "iteration": self.iteration, "wall": self.wall,
                "best_validation": self.best.value, "best_iteration": self.best.iteration}
        data = {**state, "meta": meta, "best": self.best.state or {}}
        if not background:
            save_checkpoint(data, self.checkpoint)
            return
        self._writer = threading.Thread(target=self._write, args=(host_copy(data), self.checkpoint),
                                        name="checkpoint writer")
        self._writer.start()

    def _write(self, data: dict, path: Path) -> None:
        try:
            save_checkpoint(data, path)
        except BaseException as e:  # noqa: BLE001 - handed to the training thread by flush()
            self._write_error = e

    def flush(self, check: bool = True) -> None:
        """Wait for a checkpoint written in the background; raise its error (with ``check``)."""
        if self._writer is not None:
            self._writer.join()
            self._writer = None
        error, self._write_error = self._write_error, None
        if error is not None and check:
            raise error

    def write_curve(self) -> None:
        """Write ``curve.json``."""
        if self.path is not None:
            self.path.mkdir(parents=True, exist_ok=True)
            (self.path / "curve.json").write_text(json.dumps(self.curve, indent=1))


    def write_summary(self, summary: dict) -> None:
        """Write ``train_summary.json``: what the session did (iterations, speeds, the selection)."""
        if self.path is not None:
            write_json(summary, self.path / "train_summary.json")


class RunnerFolder(RunFolder):
    """The run folder of a runner that keeps its own checkpoints (rsl-rl's ``model_<it>.pt``: PPO of the residual,
    :mod:`wresdyn.ppo.trainer`, and of the skills, :mod:`wresdyn.skills.skill_ppo`).

    It owns the record ``config.json``, the resume check against it (:meth:`check`: the runner's checkpoint holds
    weights only, so the configuration it was trained with is the one ``config.json`` recorded) and
    ``train_summary.json``; the checkpoints stay the runner's. As for :class:`RunFolder`, ``config.json`` is written
    (:meth:`write_config`) once the folder is found fit to continue and the checkpoint has loaded.

    Args:
        path: The folder.
        record: All of ``config.json`` (JSON-like).
        may_change: Dotted paths of the compared configuration a resumed run may change (:func:`check_resume`).
        key: Where the compared configuration lies in ``record`` (``None``: the whole record).
        writer: What writes such folders, for the refusal of a ``config.json`` that is not one.
    """

    def __init__(self, path, record: dict, may_change=(), key: str | None = None, writer: str = "this learner"):
        record = plain_json(record)
        super().__init__(path, record if key is None else record[key], may_change, key or "", record)
        self.checkpoint = None
        self.writer = writer

    def check(self, checkpoint) -> dict | None:
        """Whether the runner may continue ``checkpoint`` (its latest; ``None``: a fresh run, nothing to check).

        Raises a one-line :class:`RunError` if the folder has no ``config.json``, one not written by
        :attr:`writer`, or one that records another configuration (naming the fields, outside ``may_change``).

        Returns:
            The saved record (the learner checks the rest of it, e.g. the data), or ``None`` for a fresh run.
        """
        if checkpoint is None:
            return None
        path = self.path / "config.json"
        if not path.is_file():
            raise RunError(f"{self.path} holds checkpoints but no config.json, so what they learned is unknown; "
                           "choose another folder")
        try:
            old = json.loads(path.read_text())
            saved = old[self.key] if self.key else old
            if not isinstance(saved, dict):
                raise TypeError
        except (ValueError, KeyError, TypeError):
            raise RunError(f"{path}: not a run configuration written by {self.writer}") from None
        check_resume(self.path, saved, self.config, self.may_change)
        return old

    def write_config(self, **record) -> None:
        """Write ``config.json``: the record (updated with ``record``)."""
        self.record.update(record)
        if self.path is not None:
            write_json(self.record, self.path / "config.json")
