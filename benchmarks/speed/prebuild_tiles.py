"""The fused MLP's tile kernels (:mod:`wresdyn.learn.tile_mlp`) compiled ahead for a CUDA architecture on a machine
without a GPU, as a prebuilt-kernel folder (:mod:`wresdyn.sim.prebuilt`) a GPU process copies into Warp's cache.

    PYTHONPATH=. python benchmarks/speed/prebuild_tiles.py DEST --blocks 16x32x128m,8x32x128m --jobs 2
    PYTHONPATH=. python benchmarks/speed/prebuild_tiles.py DEST --check          # the index against fresh hashes
    PYTHONPATH=. python benchmarks/speed/prebuild_tiles.py DEST --merge SRC      # SRC's entries added to DEST's
    WRESDYN_PREBUILT_KERNELS=DEST PYTHONPATH=. python benchmarks/speed/prebuild_tiles.py DEST --load cuda:0 --which 0

Each block (``ROWSxCHUNKxTHREADS[m]``, :meth:`TileBlock.parse`) gives two modules (forward, backward) for the
network of ``--widths`` (the fit's by default; ``BLOCK@WIDTHS``, the widths joined by ``-``, for another network:
``16x32x128m@84-32-32-21`` is the small one of ``tests/learn/test_tile_mlp.py``). A module's full hash covers the
generated source, the resolved options (``block_dim``: the block's threads, as ``wp.launch_tiled`` loads it) and
Warp's version, none of them the host's, so the hash computed here is the one a GPU process computes. Each module is
compiled (NVRTC, and MathDx's link-time GEMMs with ``m``) into a scratch cache as ``<identifier>.sm<arch>.cubin``
and its ``.meta``, the names a GPU of that architecture loads when Warp emits CUBIN (a driver older than Warp's
NVRTC, as on the H200s so far; with a newer driver Warp asks for PTX, finds no entry and compiles as without one).
DEST gets ``<Warp version>/sm<arch>/`` in :func:`prebuilt.export`'s index format, merged with an index already
there. ``--jobs`` modules compile at once, one process each (1: in this process).

``--check`` recomputes in a fresh process every module's identifier, full hash, ``block_dim`` and file names (what
:func:`prebuilt.fetch` compares) and the files' SHA-256, and exits 1 on a mismatch. ``--device cuda:0`` (on a GPU
host) builds or checks for what that device loads: its architecture, CUBIN or PTX as Warp picks for its driver.
``--merge SRC`` copies SRC's entries of this Warp version into DEST (the shipped replay kernels and these in one
``WRESDYN_PREBUILT_KERNELS`` folder, which replaces the shipped one). ``--load DEVICE`` loads the modules on DEVICE
as a run does (an exact prebuilt entry copied into Warp's cache, else a compile), ``--which`` 0 the forward modules
only, 1 the backward ones, and prints per module whether the prebuilt entry was taken and the seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

FIT_WIDTHS = "84,256,128,64,21"  # the humanoid's observation 4 x 21, ResidualConfig's hidden widths, 21 joints
BLOCKS = "16x32x128m,8x32x128m,16x32x256m,32x32x256m,16x32x128m@84-32-32-21"  # the last: the tests' small network


def _modules(widths: str, alpha: float, text: str):
    """(forward, backward) Warp modules of the block ``text`` and its threads (the modules' ``block_dim``)."""
    from wresdyn.learn import tile_mlp

    text, _, other = text.partition("@")  # BLOCK@WIDTHS: this block for another network
    block = tile_mlp.TileBlock.parse(text)
    widths = other.replace("-", ",") or widths
    dims = tuple(int(w) for w in widths.split(","))
    kernels = tile_mlp._kernels(dims, float(alpha), block.rows, block.chunk, block.mathdx)
    return [k.module for k in kernels], block.threads


def _target(arch: int, device: str) -> tuple[int, int, bool]:
    """(the prebuilt folder's architecture, the one compiled for, PTX rather than CUBIN): ``arch``'s CUBIN, or where a
    CUDA ``device`` is given what Warp builds for it (PTX for an older architecture under a newer driver)."""
    import warp as wp

    if not device:
        return arch, arch, False
    wp.init()
    dev = wp.get_device(device)
    if dev.is_cpu:
        raise ValueError("--device: a CUDA device (the entries are CUDA binaries)")
    return dev.arch, dev.get_cuda_compile_arch(), dev.get_cuda_output_format() == "ptx"


def _names(module, bd: int, arch: int, ptx: bool = False) -> dict:
    return {"identifier": module.get_module_identifier(block_dim=bd), "name": module.name, "block_dim": bd,
            "hash": module.get_module_hash(bd).hex(), "meta": module._get_meta_name(block_dim=bd),
            "binary": module._get_compile_output_name(None, output_arch=arch, use_ptx=ptx, block_dim=bd)}


def _compile_one(widths: str, alpha: float, text: str, which: int, arch: int, ptx: bool, scratch: str) -> dict:
    """One module compiled for ``arch`` into ``scratch``; its index entry (without hashes of files) and seconds."""
    import warp as wp

    wp.config.quiet = True
    wp.init()
    modules, bd = _modules(widths, alpha, text)
    module = modules[which]
    entry = _names(module, bd, arch, ptx)
    t = time.perf_counter()
    module._compile(None, output_dir=os.path.join(scratch, entry["identifier"]), output_arch=arch, use_ptx=ptx,
                    options=module.resolve_options(wp.config, block_dim=bd))
    entry["compile_s"] = round(time.perf_counter() - t, 1)
    entry["block"] = text
    return entry


def _folder(dest: Path, arch: int) -> Path:
    import warp as wp

    return Path(dest) / wp.config.version / f"sm{arch}"


def _write(folder: Path, new: list, device: str, arch: int) -> None:
    import warp as wp

    from wresdyn.sim import prebuilt

    old = prebuilt._read_index(str(folder), wp.config.version)
    merged = {**old, **{e["identifier"]: e for e in new}}
    index = {"warp": wp.config.version, "arch": f"sm{arch}", "device": device,
             "modules": sorted(merged.values(), key=lambda e: e["identifier"])}
    (folder / prebuilt.INDEX).write_text(json.dumps(index, indent=1))
    prebuilt._read_index.cache_clear()


def build(dest: Path, widths: str, alpha: float, blocks: list, arch: int, jobs: int, device: str = "") -> list:
    from wresdyn.paths import file_sha256
    from wresdyn.sim import prebuilt

    arch, out_arch, ptx = _target(arch, device)
    folder = _folder(dest, arch)
    folder.mkdir(parents=True, exist_ok=True)
    scratch = tempfile.mkdtemp(prefix="prebuild_tiles_")
    work = [(widths, alpha, b, which, out_arch, ptx, scratch) for b in blocks for which in (0, 1)]
    import multiprocessing

    if jobs <= 1:  # in this process (its Warp cache keeps MathDx's link-time pieces, as a worker's does)
        entries = [_compile_one(*w) for w in work]
    else:
        with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            entries = list(pool.map(_compile_one, *zip(*work, strict=True)))
    for e in entries:
        ident = e["identifier"]
        (folder / ident).mkdir(exist_ok=True)
        for name in (e["binary"], e["meta"]):
            prebuilt._place(Path(scratch) / ident / name, folder / ident, name)
        e["sha256"] = {n: file_sha256(folder / ident / n) for n in (e["binary"], e["meta"])}
        e["bytes"] = sum((folder / ident / n).stat().st_size for n in (e["binary"], e["meta"]))
        print(f"{e['block']} {e['name']}: {e['compile_s']} s, {e['bytes'] / 1e6:.2f} MB -> {ident}", flush=True)
    shutil.rmtree(scratch, ignore_errors=True)
    _write(folder, [{k: e[k] for k in ("identifier", "name", "block_dim", "hash", "binary", "meta", "sha256")}
                    for e in entries], device or f"sm_{arch} compiled ahead on a host without a GPU", arch)
    return entries


def check(dest: Path, widths: str, alpha: float, blocks: list, arch: int, device: str = "") -> int:
    """Mismatches between the index and what this process computes for ``blocks`` (0: every entry as fetch wants),
    the binary named as ``device`` would load it where given (its architecture, CUBIN or PTX)."""
    import warp as wp

    from wresdyn.paths import file_sha256
    from wresdyn.sim import prebuilt

    wp.config.quiet = True
    wp.init()
    arch, out_arch, ptx = _target(arch, device)
    folder = _folder(dest, arch)
    entries = prebuilt._read_index(str(folder), wp.config.version)
    bad = 0
    for text in blocks:
        modules, bd = _modules(widths, alpha, text)
        for module in modules:
            want = _names(module, bd, out_arch, ptx)
            got = entries.get(want["identifier"], {})
            same = {k: got.get(k) == v for k, v in want.items()}
            files = got.get("sha256", {})
            same["sha256"] = bool(files) and all(file_sha256(folder / want["identifier"] / n) == d
                                                 for n, d in files.items())
            ok = all(same.values())
            bad += not ok
            print(f"{text} {module.name}: {'ok' if ok else 'MISMATCH ' + str(same)} {want['identifier']}")
    return bad


def merge(dest: Path, src: Path) -> int:
    """SRC's entries of this Warp version (every architecture) copied into DEST; returns how many."""
    import warp as wp

    from wresdyn.sim import prebuilt

    n = 0
    for arch_dir in sorted((Path(src) / wp.config.version).glob("*")):
        entries = prebuilt._read_index(str(arch_dir), wp.config.version)
        folder = Path(dest) / wp.config.version / arch_dir.name
        folder.mkdir(parents=True, exist_ok=True)
        for ident in entries:
            shutil.copytree(arch_dir / ident, folder / ident, dirs_exist_ok=True)
        old = json.loads((arch_dir / prebuilt.INDEX).read_text())
        _write(folder, list(entries.values()), old.get("device", ""), int(arch_dir.name[2:]))
        n += len(entries)
    return n


def load(widths: str, alpha: float, blocks: list, device: str, which: int | None) -> int:
    """Each block's modules loaded on ``device``; returns how many came from the prebuilt folder."""
    import warp as wp

    from wresdyn.sim import prebuilt

    wp.config.quiet = True
    wp.init()
    prebuilt.enable()
    dev = wp.get_device(device)
    print(f"prebuilt folder {prebuilt.root()}, Warp {wp.config.version}, {dev.name} ({prebuilt.arch_tag(dev)})")
    taken = 0
    for text in blocks:
        modules, bd = _modules(widths, alpha, text)
        for module in modules if which is None else modules[which:which + 1]:
            t = time.perf_counter()
            hit = prebuilt.fetch(module, dev, bd)
            module.load(dev, block_dim=bd)
            taken += hit
            print(f"{text} {module.name}: {'prebuilt' if hit else 'cache or compile'} "
                  f"{time.perf_counter() - t:.1f} s", flush=True)
    return taken


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dest", type=Path)
    p.add_argument("--widths", default=FIT_WIDTHS)
    p.add_argument("--alpha", type=float, default=1.0)
    p.add_argument("--blocks", default=BLOCKS, help="comma list of ROWSxCHUNKxTHREADS[m][@WIDTHS]")
    p.add_argument("--arch", type=int, default=90)
    p.add_argument("--jobs", type=int, default=2, help="modules compiled at once")
    p.add_argument("--check", action="store_true", help="compare the index with fresh hashes; compile nothing")
    p.add_argument("--merge", type=Path, default=None, help="copy this prebuilt folder's entries into DEST")
    p.add_argument("--device", default="", help="build or check for this CUDA device (its arch, CUBIN or PTX)")
    p.add_argument("--load", default="", help="load the modules on this device (prebuilt folder first)")
    p.add_argument("--which", type=int, choices=(0, 1), default=None, help="--load: forward (0) or backward (1)")
    args = p.parse_args(argv)
    if args.merge is not None:
        print(f"{merge(args.dest, args.merge)} entries of {args.merge} merged into {args.dest}")
        return 0
    blocks = args.blocks.split(",")
    if args.load:
        load(args.widths, args.alpha, blocks, args.load, args.which)
        return 0
    if args.check:
        return int(check(args.dest, args.widths, args.alpha, blocks, args.arch, args.device) > 0)
    t = time.perf_counter()
    entries = build(args.dest, args.widths, args.alpha, blocks, args.arch, args.jobs, args.device)
    print(f"{len(entries)} modules, {sum(e['bytes'] for e in entries) / 1e6:.2f} MB, "
          f"{time.perf_counter() - t:.0f} s wall-clock ({args.jobs} at once)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
