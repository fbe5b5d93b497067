"""``package://NAME/...`` URIs of a URDF, resolved to files before any importer sees them.

ROS description packages name their meshes ``package://NAME/path/in/package``. Newton resolves such URIs only
through ``resolve-robotics-uri-py`` (not a dependency) and otherwise guesses, warns and drops the mesh; wresdyn
resolves them itself, so a mesh that cannot be found (by URI or by path) is a one-line
:class:`~wresdyn.errors.RobotError` naming the URI and the folders searched instead of a robot silently missing its
geometry.

A package ``NAME`` is looked for, in this order, in:

1. the user's package roots (``wresdyn --package-path DIR``, repeatable or ``os.pathsep``-separated): ``DIR/NAME``,
   or ``DIR`` itself when it is named ``NAME``;
2. the description's own folder tree: every folder from the URDF's up to the file system's root, that folder if
   it is named ``NAME``, else its child ``NAME/`` (a description unpacked anywhere finds its own meshes);
3. ``ROS_PACKAGE_PATH`` (``os.pathsep``-separated roots, as in 1).

The first candidate that holds the file wins. Relative mesh paths are made absolute against the URDF's folder, so
the rewritten XML (:func:`resolved_urdf`) no longer depends on where it is read from. Pinocchio needs no
resolution of its own: :mod:`wresdyn.robot.pinocchio_model` builds its model from the same Newton import.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from pathlib import Path

from ..errors import RobotError

__all__ = ["resolve_package_uri", "resolved_urdf", "set_package_path", "user_roots"]

_USER_ROOTS: list[Path] = []
"""Package roots given on the command line (``--package-path``); set once per command by :func:`set_package_path`."""

PREFIX = "package://"
"""The scheme of a ROS package URI: ``package://NAME/path/in/package``."""


def _split(entries: Iterable[str | Path] | str | None) -> list[Path]:
    """Folders from ``os.pathsep``-separated strings or paths, empty entries dropped, order kept."""
    if entries is None:
        return []
    if isinstance(entries, (str, Path)):
        entries = [entries]
    out = []
    for e in entries:
        out += [Path(p).expanduser() for p in str(e).split(os.pathsep) if p]
    return out


def set_package_path(entries: Iterable[str | Path] | str | None) -> None:
    """Set the user's package roots (the global ``--package-path`` option) for every later robot load.

    Raises:
        RobotError: an entry is not a folder.
    """
    roots = _split(entries)
    for r in roots:
        if not r.is_dir():
            raise RobotError(f"--package-path {r}: not a folder")
    _USER_ROOTS[:] = roots


def user_roots() -> list[Path]:
    """The ``--package-path`` roots set for this command (a copy)."""
    return list(_USER_ROOTS)


def _package_dir(name: str, root: Path) -> Path | None:
    """The folder of package ``name`` under a root: the root itself when it is named ``name``, else ``root/name``."""
    if root.name == name:
        return root
    child = root / name
    return child if child.is_dir() else None


def resolve_package_uri(uri: str, urdf: Path, roots: Iterable[str | Path] | str | None = None) -> Path:
    """The file a ``package://NAME/rest`` URI names, looked for as the module docstring says.

    Args:
        uri: The URI as written in the URDF.
        urdf: The URDF file (its folder tree is searched).
        roots: The user's package roots (default: the ``--package-path`` ones); ``ROS_PACKAGE_PATH`` is read here.

    Raises:
        RobotError: no candidate folder holds the file; the message names the URI and the folders searched.
    """
    name, _, rest = uri[len(PREFIX):].partition("/")
    user = list(_USER_ROOTS) if roots is None else _split(roots)
    env = _split(os.environ.get("ROS_PACKAGE_PATH"))
    here = urdf.resolve().parent
    for root in [*user, here, *here.parents, *env]:
        pkg = _package_dir(name, root) if name and rest else None
        if pkg is not None and (pkg / rest).is_file():
            return (pkg / rest).resolve()
    searched = ([f"--package-path {os.pathsep.join(map(str, user))}"] if user else []) + [f"the folders above {here}"] \
        + ([f"ROS_PACKAGE_PATH {os.pathsep.join(map(str, env))}"] if env else [])
    raise RobotError(f"{urdf}: cannot resolve {uri}: no package {name!r} holding {rest!r} in {'; '.join(searched)} "
                     "(name the folder that holds it with --package-path DIR)")


def resolved_urdf(path: Path, roots: Iterable[str | Path] | str | None = None) -> str | None:
    """The URDF's XML with the ``filename`` of every ``<mesh>`` and ``<texture>`` made an absolute path (``package://``
    URIs resolved, relative paths against the URDF's folder), or ``None`` when the file names no file at all (it
    is then imported as it is). A mesh Newton could not find would only be warned about and dropped.

    Raises:
        RobotError: a ``package://`` URI resolves to no file, or a mesh path names a missing file.
    """
    text = path.read_text(errors="replace")
    if "filename" not in text:
        return None
    try:
        tree = ET.ElementTree(ET.fromstring(text))
    except ET.ParseError:
        return None  # the importer reports malformed XML in its own words
    for el in tree.iter():
        fn = el.get("filename")
        if not fn or el.tag not in ("mesh", "texture"):  # gazebo plugins name libraries in a filename too
            continue
        if fn.startswith(PREFIX):
            el.set("filename", str(resolve_package_uri(fn, path, roots)))
        elif "://" not in fn and not fn.lower().startswith("file:"):
            full = (path.resolve().parent / fn).resolve()  # an absolute path stays itself
            if not full.is_file():
                raise RobotError(f"{path}: mesh {fn!r} not found (looked for {full})")
            el.set("filename", str(full))
    return ET.tostring(tree.getroot(), encoding="unicode")
