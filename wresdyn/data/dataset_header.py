"""The dataset file's header: its format name, the schema versions read and written, the checks of the JSON header
(:func:`header_from`, :func:`read_header`) and the error every dataset problem raises (:class:`DatasetError`). The
arrays and the :class:`~wresdyn.data.dataset.Dataset` itself are :mod:`wresdyn.data.dataset`'s."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ..errors import WresdynError

__all__ = ["FORMAT", "SCHEMA_VERSION", "READ_VERSIONS", "DatasetError", "read_header", "header_from", "check_gains",
           "first_line"]

SCHEMA_VERSION = 2
"""Version of the file layout that :meth:`Dataset.save` writes."""
READ_VERSIONS = {1: ("train", "heldout", "ood"), 2: ("train", "validation", "heldout", "ood")}
"""Schema versions :meth:`Dataset.load` reads, with the splits each allows; any other version is refused.
Version 1 is version 2 without the validation split (``wresdyn migrate`` rewrites it as version 2)."""
FORMAT = "wresdyn-dataset"
"""The ``format`` of every dataset header."""


class DatasetError(WresdynError):
    """A dataset file or object that wresdyn cannot use; the message is one line naming the file."""


def read_header(path) -> dict:
    """The checked JSON header of a dataset file (its ``schema_version`` included), without reading the arrays."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: dataset file not found")
    try:
        with np.load(path, allow_pickle=False) as z:
            files = {"header": z["header"]} if "header" in z.files else {}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
        raise DatasetError(f"{path}: not a wresdyn dataset (.npz) file: {npz_failure(e)}") from None
    return header_from(files, path)


def header_from(files: dict, path: Path) -> dict:
    """The checked JSON header among a dataset file's arrays ``files`` (name -> array; ``path`` names the file)."""
    if "header" not in files:
        raise DatasetError(f"{path}: no header: not a wresdyn dataset file")
    try:
        h = json.loads(files["header"].astype(np.uint8).tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DatasetError(f"{path}: malformed header: {e}") from None
    if not isinstance(h, dict) or h.get("format") != FORMAT:
        raise DatasetError(f"{path}: not a wresdyn dataset file (header format is not {FORMAT!r})")
    version = h.get("schema_version")
    if type(version) is not int or version not in READ_VERSIONS:  # JSON true is not version 1
        raise DatasetError(f"{path}: schema version {version!r} is not supported (this wresdyn reads versions "
                           f"{', '.join(map(str, READ_VERSIONS))})")
    need = {"joint_names": list, "rate_hz": (int, float), "robot_file": str, "robot_sha256": str, "mismatch": dict,
            "meta": dict, "trajectories": list}
    for key, typ in need.items():
        if not isinstance(h.get(key), typ):
            raise DatasetError(f"{path}: header field {key!r} is missing or has the wrong type")
    if h.get("seed") is not None and not isinstance(h["seed"], int):
        raise DatasetError(f"{path}: header field 'seed' must be an integer or null")
    h.setdefault("seed", None)
    h.setdefault("gains", None)
    check_gains(h["gains"], str(path))
    return h


def check_gains(gains, where: str) -> None:
    """The optional gains record: ``None`` or ``{"file": str or None, "config": {"joint": [tables]}}``."""
    if gains is None:
        return
    if not isinstance(gains, dict) or set(gains) != {"file", "config"} or not isinstance(gains["config"], dict) \
            or not (gains["file"] is None or isinstance(gains["file"], str)):
        raise DatasetError(f"{where}: gains must be null or {{\"file\": path or null, \"config\": {{...}}}}")
    joints = gains["config"].get("joint")
    if not isinstance(joints, list) or not all(isinstance(e, dict) for e in joints):
        raise DatasetError(f"{where}: gains config needs a list of [[joint]] tables")


def npz_failure(e: Exception) -> str:
    """Why ``np.load(allow_pickle=False)`` refused a file, in words for a user: NumPy reads anything that is neither
    a zip archive nor an ``.npy`` file as pickled data, and its hint to allow pickles is not one to follow with a file
    from elsewhere."""
    if "allow_pickle" in str(e):
        return "not a NumPy .npz archive (or one holding pickled objects, which are never loaded)"
    return first_line(e)


def first_line(e: Exception) -> str:
    """The first line of an exception's message (its type's name where it has none)."""
    s = str(e).strip()
    return s.splitlines()[0] if s else type(e).__name__
