"""Warp kernels compiled ahead for the shipped robots, copied into Warp's cache instead of compiling on an exact match.

A first ``wresdyn fit`` on a fresh GPU machine spends most of its first minute compiling (the humanoid's generated
replay kernels above all). Warp keeps a compiled module in its kernel cache (``wp.config.kernel_cache_dir``) as a
folder named by the module's identifier, ``wp_<module name>_<first 7 hex digits of the module hash>``, holding the
binary (``<identifier>.o``, ``.cpu<target hash>.o`` on the CPU; ``.sm<arch>.cubin`` or ``.ptx`` on CUDA), the
``<identifier>.meta`` it loads with, and the generated source. The module hash covers the kernels' code, the
options and Warp's version, so a module whose full hash and binary name are those of a folder compiled elsewhere
would compile to that folder's binary.

:func:`export` (``wresdyn warmup --export DIR``) copies the binary and meta of every module this process loaded on
a device into ``DIR/<Warp version>/<arch>/`` (``arch``: ``cpu``, or ``sm<N>`` of a CUDA device) with an
``index.json``: Warp's version, the device, and per module its name, ``block_dim``, full hash, file names and each
file's SHA-256. Before Warp loads a module that its cache lacks (:func:`enable` wraps ``Module.load``; the replay
solver asks :func:`fetch` before it checks the cache itself), :func:`fetch` copies the entry in when Warp's version,
the full module hash, the binary's name (device architecture, CPU target, PTX or CUBIN) and every file's SHA-256
match; anything else (an index of another Warp, a changed kernel, a tampered or truncated file) is ignored and the
module compiles as it would without it. The folder looked in is ``$WRESDYN_PREBUILT_KERNELS`` where set, else
:data:`SHIPPED`, which holds the humanoid's kernels for Warp 1.19.0 on ``sm90`` (H100, H200), exported by
``wresdyn warmup --device cuda:0 --no-shipped --robot scenes/humanoid.usda --export`` from the kernel sources they
match. Another Warp, another architecture or a changed kernel finds no exact entry there and compiles as before.
"""

from __future__ import annotations

import functools
import json
import os
import shutil
import threading
from pathlib import Path

import warp as wp
from warp._src import context as _wpc

from ..paths import file_sha256

__all__ = ["SHIPPED", "arch_tag", "enable", "export", "fetch", "root"]

SHIPPED = Path(__file__).resolve().parent / "prebuilt_kernels"
"""The kernels the package ships (``<Warp version>/<arch>/index.json`` and a folder per module): exported on the GPU
they are for (``wresdyn warmup --export``) and valid only while the kernel sources and Warp's version are theirs."""

INDEX = "index.json"
_LOCK = threading.Lock()
_ORIGINAL_LOAD = None  # Warp's Module.load while enable() has wrapped it


def root() -> Path:
    """The prebuilt-kernel folder in use: ``$WRESDYN_PREBUILT_KERNELS`` where set and not empty, else
    :data:`SHIPPED`."""
    given = os.environ.get("WRESDYN_PREBUILT_KERNELS", "").strip()
    return Path(given).expanduser() if given else SHIPPED


def arch_tag(device) -> str:
    """``cpu`` or ``sm<N>``: the sub-folder of a Warp version's prebuilt kernels for ``device``."""
    return "cpu" if device.is_cpu else f"sm{device.arch}"


@functools.lru_cache(maxsize=None)
def _read_index(folder: str, version: str) -> dict:
    """Identifier -> entry of the index in ``folder``, {} where there is none or it is unreadable or of another Warp
    (read once per folder)."""
    try:
        index = json.loads((Path(folder) / INDEX).read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(index, dict) or index.get("warp") != version:
        return {}
    return {e["identifier"]: e for e in index.get("modules", []) if isinstance(e, dict) and "identifier" in e}



def _place(src: Path, dest_dir: Path, name: str) -> None:
    """Copy ``src`` to ``dest_dir/name`` through a temporary name, so that no process sees a part-written file."""
    tmp = dest_dir / f".{name}.p{os.getpid()}_t{threading.get_ident()}"
    shutil.copyfile(src, tmp)
    os.replace(tmp, dest_dir / name)


def fetch(module, device, block_dim: int | None = None) -> bool:
    """Copy ``module``'s compiled binary for ``device`` into Warp's cache from the prebuilt kernels when the cache lacks
    it and an entry matches exactly (Warp version, full hash, binary name, file hashes). Returns whether it did."""
    folder = root() / wp.config.version / arch_tag(device)
    entries = _read_index(str(folder), wp.config.version)
    if not entries:
        return False
    bd = module.options["block_dim"] if block_dim is None else block_dim
    ident = module.get_module_identifier(block_dim=bd)
    entry = entries.get(ident)
    if entry is None or module.options["strip_hash"]:
        return False
    binary = module._get_compile_output_name(device, block_dim=bd)
    meta = module._get_meta_name(block_dim=bd)
    cache = Path(wp.config.kernel_cache_dir) / ident
    if (cache / binary).exists() and (cache / meta).exists():
        return False
    if (entry.get("hash") != module.get_module_hash(bd).hex() or entry.get("binary") != binary
            or entry.get("meta") != meta or entry.get("block_dim") != bd):
        return False
    src = folder / ident
    files = entry.get("sha256", {})
    if set(files) != {binary, meta} or any(file_sha256(src / name) != digest for name, digest in files.items()):
        return False
    cache.mkdir(parents=True, exist_ok=True)
    _place(src / binary, cache, binary)
    _place(src / meta, cache, meta)  # last: Warp takes a module as cached once both files are there
    return True


def _load(self, device, block_dim=None, binary_path=None, *args, **kwargs):
    """Warp's ``Module.load``, after :func:`fetch` where the module is not loaded yet and no binary is given."""
    if binary_path is None:
        try:
            dev = _wpc.runtime.get_device(device)
            bd = block_dim if block_dim is not None else self.options["block_dim"]
            if self.execs.get((dev.context, bd)) is None:
                fetch(self, dev, block_dim)
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            pass  # a broken prebuilt folder costs a compile, never the run
    return _ORIGINAL_LOAD(self, device, block_dim, binary_path, *args, **kwargs)


def enable() -> bool:
    """Have every Warp module load look in the prebuilt kernels first (once per process; nothing where the folder in
    use does not exist). Returns whether the wrapper is in place."""
    global _ORIGINAL_LOAD
    with _LOCK:
        if _ORIGINAL_LOAD is None and root().is_dir():
            _ORIGINAL_LOAD = _wpc.Module.load
            _wpc.Module.load = _load
        return _ORIGINAL_LOAD is not None


def export(device, dest) -> list[str]:
    """Copy the binary and meta of every module this process has loaded on ``device`` (a Warp device) from Warp's cache
    into ``dest/<Warp version>/<arch>/`` and write its ``index.json`` (see the module). Returns the identifiers."""
    folder = Path(dest) / wp.config.version / arch_tag(device)
    folder.mkdir(parents=True, exist_ok=True)
    cache = Path(wp.config.kernel_cache_dir)
    old = _read_index(str(folder), wp.config.version)
    entries = {}
    for module in list(_wpc.user_modules.values()):
        for (ctx, bd), ex in list(module.execs.items()):
            if ctx != device.context or module.options["strip_hash"]:
                continue
            ident = module.get_module_identifier(block_dim=bd)
            binary = module._get_compile_output_name(device, block_dim=bd)
            meta = module._get_meta_name(block_dim=bd)
            if not ((cache / ident / binary).exists() and (cache / ident / meta).exists()):
                continue
            (folder / ident).mkdir(exist_ok=True)
            for name in (binary, meta):
                _place(cache / ident / name, folder / ident, name)
            entries[ident] = {"identifier": ident, "name": module.name, "block_dim": bd, "hash": ex.module_hash.hex(),
                              "binary": binary, "meta": meta,
                              "sha256": {n: file_sha256(folder / ident / n) for n in (binary, meta)}}
    merged = {**old, **entries}  # a second export (another robot) adds to the first
    index = {"warp": wp.config.version, "arch": arch_tag(device), "device": device.name,
             "modules": sorted(merged.values(), key=lambda e: e["identifier"])}
    tmp = folder / f".{INDEX}.p{os.getpid()}"
    tmp.write_text(json.dumps(index, indent=1))
    os.replace(tmp, folder / INDEX)
    _read_index.cache_clear()
    return sorted(entries)
