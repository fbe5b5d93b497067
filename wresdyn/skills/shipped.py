"""Skill policies that ship inside the package, so that a CPU run fine-tunes and deploys instead of training from
scratch: the nominal floor policy (a) trained at full size on a GPU, and for the CPU run that only deploys
(``wresdyn deploy --floor --shipped``) the calibrated policy (b) and the oracle (d) fine-tuned from it at full size.

A shipped policy is a folder under ``wresdyn/skills/policies/<name>/``: the skill run's last rsl-rl checkpoint
``model_<it>.pt`` (actor, critic, optimiser: what a fine-tuning starts from), its exported ``policy.pt``, its
``config.json`` and ``train_summary.json``, and ``shipped.json``: the command that trained it, the commit, the
machine, and the sha256 of every file, checked before a file is used.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from ..errors import WresdynError
from ..paths import file_sha256

__all__ = ["SHIPPED", "shipped_folder", "install_policy", "ship_policy"]

SHIPPED = Path(__file__).parent / "policies"
"""Where the shipped policies live (package data)."""

_FILES = ("config.json", "train_summary.json", "policy.pt")
"""The run files a shipped policy keeps, beside its last checkpoint."""



def shipped_folder(name: str) -> Path:
    """The folder of the shipped policy ``name`` (e.g. ``floor_nominal``), its files checked against their hashes."""
    folder = SHIPPED / name
    manifest = folder / "shipped.json"
    if not manifest.is_file():
        have = sorted(p.name for p in SHIPPED.iterdir() if (p / "shipped.json").is_file()) if SHIPPED.is_dir() else []
        raise WresdynError(f"no shipped policy {name!r} (shipped: {', '.join(have) or 'none'})")
    record = json.loads(manifest.read_text())
    for file, digest in record["sha256"].items():
        if not (folder / file).is_file() or file_sha256(folder / file) != digest:
            raise WresdynError(f"{folder / file}: missing or changed since it was shipped (sha256 differs)")
    return folder


def install_policy(source: str | Path, dst: Path) -> Path:
    """Copy a policy into the run folder ``dst`` (created): ``source`` is a shipped policy's name or a skill run
    folder. Returns ``dst``. An existing ``dst`` with the same files is kept; one with others is refused."""
    src = Path(source)
    if not src.is_dir():
        src = shipped_folder(str(source))
    ckpts = sorted(src.glob("model_*.pt"), key=lambda p: int(p.stem.split("_")[1]))
    missing = [f for f in _FILES if not (src / f).is_file()]
    if not ckpts or missing:
        raise WresdynError(f"{src}: not a finished skill run (missing {', '.join(missing) or 'model_<it>.pt'})")
    files = (*_FILES, ckpts[-1].name)
    dst = Path(dst)
    if dst.exists():
        if all((dst / f).is_file() and file_sha256(dst / f) == file_sha256(src / f) for f in files):
            return dst
        raise WresdynError(f"{dst}: holds another policy; remove it or choose another output folder")
    tmp = dst.with_name(dst.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    for f in files:
        shutil.copy2(src / f, tmp / f)
    tmp.rename(dst)
    return dst


def ship_policy(run: str | Path, name: str, command: str, machine: str, commit: str, extra: dict | None = None) -> Path:
    """Copy the finished skill run ``run`` into the package as the shipped policy ``name``, with its manifest
    (``extra``: more fields of it, e.g. the real robot's mismatch an oracle was trained on)."""
    folder = install_policy(run, SHIPPED / name)
    files = sorted(p.name for p in folder.iterdir() if p.name != "shipped.json")
    record = {"name": name, "command": command, "machine": machine, "commit": commit, "source": str(run),
              **(extra or {}), "sha256": {f: file_sha256(folder / f) for f in files}}
    (folder / "shipped.json").write_text(json.dumps(record, indent=1) + "\n")
    return folder
