"""``benchmarks/speed/prebuild_tiles.py``: the tile kernels compiled for sm_90 on a host without a GPU (NVRTC) into a
prebuilt-kernel folder whose index holds what :func:`wresdyn.sim.prebuilt.fetch` compares: the identifier, full
module hash and ``block_dim`` that the kernels :class:`~wresdyn.learn.tile_mlp.TileMLP` launches compute, the
binary's and meta's names, their SHA-256. A small network with Warp's own GEMM (seconds; MathDx's takes minutes)."""

import importlib.util
import json
from pathlib import Path

import pytest
import torch

from wresdyn.learn.tile_mlp import TileBlock, TileMLP

ROOT = Path(__file__).resolve().parents[2]
WIDTHS, BLOCK = "8,16,4", "4x8x32"


def _script():
    spec = importlib.util.spec_from_file_location("prebuild_tiles", ROOT / "benchmarks/speed/prebuild_tiles.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _nvrtc() -> bool:
    import warp as wp

    wp.init()
    return 90 in (wp._src.context.runtime.nvrtc_supported_archs or ())


@pytest.mark.skipif(not _nvrtc(), reason="Warp without NVRTC for sm_90")
def test_prebuilt_entries_are_what_fetch_compares(tmp_path):
    import warp as wp

    script = _script()
    entries = script.build(tmp_path, WIDTHS, 1.0, [BLOCK], 90, 1)
    folder = tmp_path / wp.config.version / "sm90"
    index = json.loads((folder / "index.json").read_text())
    assert index["warp"] == wp.config.version and index["arch"] == "sm90"
    net = TileMLP([8, 16, 4], 1.0, torch.device("cpu"), TileBlock.parse(BLOCK))  # the kernels a run launches
    assert len(index["modules"]) == 2 == len(entries)
    for kernel, entry in zip((net.forward_kernel, net.backward_kernel), sorted(
            index["modules"], key=lambda e: "backward" in e["name"]), strict=True):
        m = kernel.module
        assert entry["block_dim"] == 32
        assert entry["hash"] == m.get_module_hash(32).hex()
        assert entry["identifier"] == m.get_module_identifier(block_dim=32)
        assert entry["binary"] == f"{entry['identifier']}.sm90.cubin" and entry["meta"] == m._get_meta_name(32)
        assert (folder / entry["identifier"] / entry["binary"]).stat().st_size > 10_000
    assert script.check(tmp_path, WIDTHS, 1.0, [BLOCK], 90) == 0
    binary = folder / entries[0]["identifier"] / entries[0]["binary"]
    binary.write_bytes(binary.read_bytes()[:-1])  # a truncated binary no longer matches its SHA-256
    assert script.check(tmp_path, WIDTHS, 1.0, [BLOCK], 90) == 1
