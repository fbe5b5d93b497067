"""Generate ``scenes/so101/``: the SO-101 arm (TheRobotStudio/SO-ARM100, ``Simulation/SO101/``, Apache-2.0).

Copies the MJCF of the "new_calib" zero convention (0 rad at the middle of each calibrated range, the
convention of the SAGE real logs) as ``so101.xml`` with a provenance comment and nothing else changed, and
decimates every STL mesh it references into ``assets/`` (vertices merged on a 0.5 mm grid, then quadric
decimation to at most ``--faces`` triangles: the upstream meshes are 16 MB, the decimated ones 1.6 MB). The
meshes carry no dynamics: every body of the file has an explicit ``<inertial>``, the replay runs without
contacts, and wresdyn loads collision geometry only. The licence file is copied alongside.

Run once, with the upstream folder unpacked (``tar -xJf so101-robot.tar.xz`` gives ``robot/``)::

    pip install fast-simplification trimesh     # decimation only, not a wresdyn dependency
    python scenes/so101/make_so101.py /path/to/robot

The generated files are committed; this script documents how they were made.
"""

from __future__ import annotations

import argparse
import re
import shutil
from pathlib import Path

HERE = Path(__file__).resolve().parent
HEADER = (
    "<!-- SO-101 arm, \"new_calib\" convention: TheRobotStudio/SO-ARM100, Simulation/SO101/so101_new_calib.xml,\n"
    "     Apache-2.0 (LICENSE-SO-ARM100). Unchanged except this comment; meshes decimated by make_so101.py. -->\n"
)


CLUSTER = 0.5e-3
"""Vertices closer than this are merged before the quadric decimation, which stalls on the upstream meshes'
many thin slivers otherwise [m]."""


def _decimate(mesh, faces: int, fast_simplification, trimesh):
    import numpy as np

    cells, inverse = np.unique(np.round(mesh.vertices / CLUSTER), axis=0, return_inverse=True)
    f = inverse.reshape(-1)[mesh.faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    merged = trimesh.Trimesh(cells * CLUSTER, f, process=True)
    merged.update_faces(merged.unique_faces())
    v, f = fast_simplification.simplify(merged.vertices, merged.faces, target_count=faces)
    return trimesh.Trimesh(v, f, process=True)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("upstream", type=Path, help="the unpacked robot/ folder (so101_new_calib.xml, assets/)")
    p.add_argument("--faces", type=int, default=2500, help="most triangles per mesh (default 2500)")
    args = p.parse_args(argv)
    import fast_simplification
    import trimesh

    src = args.upstream / "so101_new_calib.xml"
    text = src.read_text()
    meshes = sorted(set(re.findall(r'<mesh file="([^"]+)"', text)))
    out_assets = HERE / "assets"
    out_assets.mkdir(exist_ok=True)
    for name in meshes:
        mesh = trimesh.load(args.upstream / "assets" / name, force="mesh")
        if len(mesh.faces) > args.faces:
            mesh = _decimate(mesh, args.faces, fast_simplification, trimesh)
        mesh.export(out_assets / name)
        print(f"{name}: {len(mesh.faces)} faces, {(out_assets / name).stat().st_size / 1e3:.0f} kB")
    first, rest = text.split("\n", 1) if text.startswith("<?xml") else ("", text)
    (HERE / "so101.xml").write_text((first + "\n" if first else "") + HEADER + rest)
    shutil.copy(args.upstream / "LICENSE-SO-ARM100", HERE / "LICENSE-SO-ARM100")


if __name__ == "__main__":
    main()
