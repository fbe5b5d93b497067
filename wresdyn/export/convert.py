"""MJCF and URDF robots to USD for ``wresdyn export``, through the maintained converters.

``wresdyn export`` writes its layers over a USD robot file; a robot recorded from MJCF or URDF is first converted
into the export folder (``source/<name>.usda`` with its ``Payload/``) by NVIDIA's converters:
``mujoco-usd-converter`` (MJCF) and ``urdf-usd-converter`` (URDF), and the layers go over that file.

The converters build on ``usd-exchange``, whose wheel bundles its own OpenUSD build (``pxr``): installed next to
``usd-core`` (which Newton and wresdyn import) one of the two breaks, and ``mujoco-usd-converter`` 0.8.0 pins
``mujoco<3.17`` while Newton 1.8 pins 3.17 (it converts under 3.17 all the same). So they live in a virtual
environment of their own, ``.venv-usd`` beside ``.venv`` (``scripts/setup.sh usd``, part of ``scripts/setup.sh dev``),
and run as a subprocess; ``WRESDYN_USD_CONVERTER_PYTHON`` names another interpreter that has them. The converted
file is plain USD, read by ``usd-core``.

The converted robot is loaded back with Newton's USD importer and matched to the original by joint and body name:
the identified parameters are authored on the converted prims, and a joint or a body with mass that the
conversion lost is an error (massless links that the converter folds into their parent are dropped).
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np

from ..errors import WresdynError
from ..paths import REPO
from ..robot.description import load_robot

__all__ = ["CONVERTERS", "converter_python", "convert_robot_file", "converted_robot", "is_usd"]

CONVERTERS = {".xml": "mujoco_usd_converter", ".urdf": "urdf_usd_converter"}
"""Robot file suffix -> the converter's Python module (run as ``python -m MODULE INPUT OUTPUT_DIR``)."""
_PACKAGES = {".xml": "mujoco-usd-converter", ".urdf": "urdf-usd-converter"}
ENV = "WRESDYN_USD_CONVERTER_PYTHON"
"""Environment variable naming the Python interpreter that has the converters (default ``REPO/.venv-usd``)."""
_TIMEOUT_S = 600.0
"""A conversion takes seconds (the SO-101: 5 s); a hung one fails the export rather than blocking it."""


class ConvertError(WresdynError):
    """A robot file that cannot be converted to USD (no converter, the converter failed, a lost joint or body)."""


def is_usd(path: str | Path) -> bool:
    return Path(path).suffix.lower() in (".usd", ".usda", ".usdc")


def converter_python() -> str | None:
    """The interpreter that runs the converters: ``$WRESDYN_USD_CONVERTER_PYTHON``, else ``REPO/.venv-usd``'s,
    else ``None``."""
    env = os.environ.get(ENV)
    if env:
        return env
    default = REPO / ".venv-usd" / "bin" / "python"
    return str(default) if default.is_file() else None


def converter_missing(src: str | Path) -> str | None:
    """Why the robot file ``src`` cannot be exported as USD here, in one line (not MJCF/URDF, or no interpreter with
    its converter), else ``None``: checked before anything is written."""
    suffix = Path(src).suffix.lower()
    if suffix not in CONVERTERS:
        return (f"{src}: export writes USD layers over a USD robot file, or over one converted from MJCF (.xml) or "
                f"URDF (.urdf); {suffix or 'this file'} is neither")
    py = converter_python()
    if py is not None and (Path(py).is_file() or shutil.which(py)):
        return None
    return (f"{src}: exporting a {suffix} robot to USD needs {_PACKAGES[suffix]}: run `scripts/setup.sh usd` (a "
            f"separate .venv-usd) or set {ENV} to a Python that has it")


def convert_robot_file(src: str | Path, dest: str | Path) -> Path:
    """Convert the MJCF or URDF file ``src`` into the new folder ``dest``; the converted root layer's path.

    Raises:
        ConvertError: not MJCF/URDF, no converter installed, the converter failed or wrote no USD.
    """
    src, dest = Path(src), Path(dest)
    suffix = src.suffix.lower()
    if suffix not in CONVERTERS:
        raise ConvertError(f"{src}: export converts MJCF (.xml) and URDF (.urdf) robots to USD, not {suffix or 'this'}")
    py = converter_python()
    if py is None:
        raise ConvertError(f"{src}: exporting a {suffix} robot needs {_PACKAGES[suffix]}: run `scripts/setup.sh usd` "
                           f"(a separate .venv-usd) or set {ENV} to a Python that has it")
    dest.mkdir(parents=True)
    try:
        done = subprocess.run([py, "-m", CONVERTERS[suffix], str(src.resolve()), str(dest.resolve())],
                              capture_output=True, text=True, timeout=_TIMEOUT_S)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise ConvertError(f"{src}: {_PACKAGES[suffix]} did not run ({py}): {e}") from None
    roots = sorted(dest.glob("*.usd*"))
    if done.returncode != 0 or len(roots) != 1:
        lines = [ln for ln in (done.stderr + done.stdout).splitlines() if ln.strip()]
        why = lines[-1].strip() if lines else f"exit {done.returncode}, {len(roots)} root layers"
        raise ConvertError(f"{src}: {_PACKAGES[suffix]} failed: {why}")
    return roots[0]


def converted_robot(robot, physics, dest: str | Path):
    """Convert ``robot``'s file into ``dest`` and load it; ``(usd_robot, physics on usd_robot)``.

    Args:
        robot: A :class:`~wresdyn.robot.description.Robot` loaded from MJCF or URDF.
        physics: :class:`~wresdyn.robot.physical.PhysicalParams` on ``robot``.
        dest: New folder for the converted files.

    Raises:
        ConvertError: the conversion failed, or lost a joint, a body with mass, or the joints' limits.
    """
    root = convert_robot_file(robot.source, dest)
    usd = load_robot(root, gains=robot.gains, base=robot.base)
    if sorted(usd.joint_names) != sorted(robot.joint_names):
        raise ConvertError(f"{robot.source.name}: the converted USD has joints {sorted(usd.joint_names)}, the robot "
                           f"{sorted(robot.joint_names)}")
    j = [list(robot.joint_names).index(n) for n in usd.joint_names]
    for name in ("lower", "upper"):
        a, b = np.asarray(getattr(robot, name))[j], np.asarray(getattr(usd, name))
        if not np.allclose(a, b, atol=1e-5):  # float32 in USD: limits agree to ~1e-7 rad
            raise ConvertError(f"{robot.source.name}: the converted USD changed the joint limits ({name})")
    body = list(robot.body_names)
    missing = [n for n in usd.body_names if n not in body]
    lost = [n for n, m in zip(body, physics.body_mass) if n not in usd.body_names and m > 0]
    if missing or lost:
        raise ConvertError(f"{robot.source.name}: the converted USD's bodies do not match the robot's (lost "
                           f"{lost}, new {missing})")
    b = [body.index(n) for n in usd.body_names]
    p = physics.copy()
    p.joint_names, p.body_names = list(usd.joint_names), list(usd.body_names)
    for f in ("kp", "kd", "armature", "damping", "friction", "effort", "delay", "deadband", "noload_speed",
              "goal_accel", "startup_torque", "stiction", "backlash", "encoder_offset", "load_friction"):
        v = getattr(physics, f)
        if v is not None:
            setattr(p, f, np.asarray(v)[j].copy())
    for f in ("body_mass", "body_com", "body_inertia"):
        setattr(p, f, np.asarray(getattr(physics, f))[b].copy())
    p.check(usd, "physics")
    return usd, p
