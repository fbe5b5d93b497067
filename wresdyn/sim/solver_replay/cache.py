"""The generated-kernel cache: where kernel sources are written, and how they are imported safely.

Warp reads a kernel's source through :mod:`inspect`, so the generated module must exist as a file. The
file lives in the user's cache folder (:func:`kernel_dir`), never in a shared temporary folder, and it is
never trusted: :func:`load_module` rewrites it unless its bytes are exactly the generated source and then
runs the generated source itself, not what the file holds.
"""

from __future__ import annotations

import hashlib
import linecache
import os
import sys
import tempfile
import types
from pathlib import Path

from ...errors import WresdynError

__all__ = ["KernelCacheError", "kernel_dir", "load_module"]

_MODULES: dict[str, types.ModuleType] = {}


class KernelCacheError(WresdynError):
    """The generated-kernel cache folder cannot be created or written."""


def kernel_dir() -> Path:
    """Folder for generated kernel sources: ``$WRESDYN_KERNEL_DIR``, else ``$XDG_CACHE_HOME/wresdyn/kernels``
    (``~/.cache/wresdyn/kernels`` without it). Never a shared temporary folder: what is imported from here
    is validated (:func:`load_module`), and a private folder keeps other users from racing the writes.

    Raises:
        KernelCacheError: the folder cannot be created or is not writable.
    """
    override = os.environ.get("WRESDYN_KERNEL_DIR")
    if override:
        d = Path(override).expanduser()
    else:
        xdg = os.environ.get("XDG_CACHE_HOME", "")
        base = Path(xdg) if os.path.isabs(xdg) else Path.home() / ".cache"  # XDG: a relative value is ignored
        d = base / "wresdyn" / "kernels"
    try:
        d.mkdir(parents=True, exist_ok=True, mode=0o700)
    except OSError as e:
        raise KernelCacheError(f"{d}: cannot create the kernel cache folder ({e.strerror}); "
                               "set WRESDYN_KERNEL_DIR to a writable folder") from None
    if not os.access(d, os.W_OK | os.X_OK):
        raise KernelCacheError(f"{d}: the kernel cache folder is not writable; "
                               "set WRESDYN_KERNEL_DIR to a writable folder")
    return d


def _write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a private temporary file in the same folder and ``os.replace``,
    so a reader sees the old file or the whole new one."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_module(src: str) -> types.ModuleType:
    """The module of generated source ``src``, written to ``kernel_dir()/replay_<sha256(src)[:20]>.py``.

    The file is rewritten atomically unless its bytes equal ``src`` (a stale or tampered file is never
    used), and the module is executed from ``src`` itself with :mod:`linecache` primed with the same text
    for Warp's :mod:`inspect`: what runs is what was generated, even if the file changes after the check.
    Modules are kept per process by content hash.
    """
    data = src.encode()
    key = hashlib.sha256(data).hexdigest()[:20]
    if key in _MODULES:
        return _MODULES[key]
    path = kernel_dir() / f"replay_{key}.py"
    try:
        current = path.read_bytes()
    except OSError:
        current = None
    if current != data:
        _write_atomic(path, data)
    name = f"wresdyn_replay_{key}"
    filename = str(path)
    linecache.cache[filename] = (len(src), None, src.splitlines(True), filename)  # mtime None: never reloaded
    mod = types.ModuleType(name)
    mod.__file__ = filename
    sys.modules[name] = mod
    exec(compile(src, filename, "exec"), mod.__dict__)
    _MODULES[key] = mod
    return mod
