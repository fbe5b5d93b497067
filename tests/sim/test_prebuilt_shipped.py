"""The kernels the package ships (``wresdyn/sim/prebuilt_kernels/``, :mod:`wresdyn.sim.prebuilt`): their index is the
one a run on their GPU reads, every file it lists is there with its recorded SHA-256 and is package data, and where
they do not fit (another Warp version, another architecture) nothing is copied and the module compiles and runs as
without them. CPU only: no shipped binary is loaded here (they are CUDA binaries); a module of this file stands in
for the mismatches."""

from __future__ import annotations

import json
import shutil
import tomllib
from pathlib import Path, PurePosixPath
from types import SimpleNamespace

import numpy as np
import pytest
import warp as wp

from wresdyn.paths import REPO, file_sha256
from wresdyn.sim import prebuilt

INDEXES = sorted(prebuilt.SHIPPED.glob("*/*/" + prebuilt.INDEX))
"""Every shipped index: ``<Warp version>/<arch>/index.json`` under the package folder."""


@pytest.fixture(autouse=True)
def _fresh_indexes(monkeypatch):
    """Each test reads the indexes from disk (the reader caches per folder) and looks in the shipped folder unless it
    says otherwise."""
    monkeypatch.delenv("WRESDYN_PREBUILT_KERNELS", raising=False)
    prebuilt._read_index.cache_clear()
    yield
    prebuilt._read_index.cache_clear()


def test_the_shipped_kernels_are_package_data():
    assert INDEXES, f"no index under {prebuilt.SHIPPED}"
    patterns = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["wresdyn.sim"]
    base = prebuilt.SHIPPED.parent
    files = [PurePosixPath(p.relative_to(base).as_posix()) for p in prebuilt.SHIPPED.rglob("*") if p.is_file()]
    # setuptools' "*" stops at a "/": a pattern covers a file of exactly as many parts
    missed = [f for f in files if not any(f.match(g) and len(f.parts) == len(PurePosixPath(g).parts) for g in patterns)]
    assert files and not missed, missed


@pytest.mark.parametrize("index_path", INDEXES, ids=lambda p: f"{p.parent.parent.name}/{p.parent.name}")
def test_every_shipped_file_is_listed_and_matches_its_hash(index_path):
    folder = index_path.parent
    index = json.loads(index_path.read_text())
    assert index["warp"] == folder.parent.name and index["arch"] == folder.name, (index["warp"], index["arch"])
    modules = index["modules"]
    idents = [e["identifier"] for e in modules]
    assert modules and len(set(idents)) == len(idents)
    # nothing unlisted beside them: a folder fetch would never read is dead weight in the package
    assert {p.name for p in folder.iterdir() if p.is_dir()} == set(idents)
    for e in modules:
        assert e["identifier"] == f"wp_{e['name']}_{e['hash'][:7]}", e["identifier"]
        assert e["binary"] == f"{e['identifier']}.{index['arch']}.cubin" and e["meta"] == f"{e['identifier']}.meta"
        assert set(e["sha256"]) == {e["binary"], e["meta"]}
        assert {p.name for p in (folder / e["identifier"]).iterdir()} == set(e["sha256"])
        for name, digest in e["sha256"].items():
            path = folder / e["identifier"] / name
            assert path.stat().st_size > 0 and file_sha256(path) == digest, path


@pytest.mark.parametrize("index_path", INDEXES, ids=lambda p: f"{p.parent.parent.name}/{p.parent.name}")
def test_a_run_of_that_warp_and_architecture_reads_the_shipped_index(index_path, monkeypatch):
    index = json.loads(index_path.read_text())
    arch = index["arch"]
    gpu = SimpleNamespace(is_cpu=False, arch=int(arch.removeprefix("sm")))  # a device of that architecture
    assert prebuilt.root() == prebuilt.SHIPPED
    assert prebuilt.root() / index["warp"] / prebuilt.arch_tag(gpu) == index_path.parent
    entries = prebuilt._read_index(str(index_path.parent), index["warp"])
    assert set(entries) == {e["identifier"] for e in index["modules"]}
    # another Warp reads nothing from it, even pointed at the folder itself
    assert prebuilt._read_index(str(index_path.parent), index["warp"] + ".post1") == {}


@wp.kernel
def _triple(x: wp.array(dtype=float)):  # the module the mismatches are tried on: this file's kernels alone
    i = wp.tid()
    x[i] = 3.0 * x[i]


def _runs(cpu) -> bool:
    x = wp.array(np.arange(4, dtype=np.float32), device=cpu)
    wp.launch(_triple, dim=4, inputs=[x], device=cpu)
    return bool(np.array_equal(x.numpy(), 3.0 * np.arange(4)))


def test_kernels_of_another_warp_or_architecture_are_ignored(tmp_path, monkeypatch):
    """This file's module exported on the CPU, then offered under another Warp version, under another architecture's
    folder, and with another architecture's binary name: never copied; with the shipped (CUDA) kernels in place the
    module compiles into an empty cache and runs."""
    wp.init()
    cpu = wp.get_device("cpu")
    module = _triple.module
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path / "a"))
    module.unload()
    wp.force_load(device=cpu, modules=[module])
    bd = next(b for (ctx, b) in module.execs if ctx == cpu.context)
    ident = module.get_module_identifier(block_dim=bd)
    good = tmp_path / "good"
    assert prebuilt.export(cpu, good) == [ident]
    here = good / wp.config.version / "cpu"

    def offered(folder: Path) -> bool:
        """Whether fetch copies the module from ``folder`` into an empty cache (and leaves that cache empty if not)."""
        prebuilt._read_index.cache_clear()
        cache = tmp_path / f"cache_{folder.name}"
        monkeypatch.setattr(wp.config, "kernel_cache_dir", str(cache))
        monkeypatch.setenv("WRESDYN_PREBUILT_KERNELS", str(folder))
        copied = prebuilt.fetch(module, cpu, bd)
        assert copied or not (cache / ident).exists()
        return copied

    assert offered(good)  # the exact match is copied: the cases below fail for their mismatch alone

    other_warp = tmp_path / "other_warp"  # an index written by another Warp, in this Warp's folder
    shutil.copytree(good, other_warp)
    index = json.loads((here / prebuilt.INDEX).read_text())
    (other_warp / wp.config.version / "cpu" / prebuilt.INDEX).write_text(json.dumps({**index, "warp": "1.0.0"}))
    assert not offered(other_warp)
    moved = tmp_path / "moved"  # the same files under another Warp version's folder
    shutil.copytree(here, moved / "1.0.0" / "cpu")
    assert not offered(moved)

    other_arch = tmp_path / "other_arch"  # built for a GPU: the sm90 folder, nothing for this CPU
    shutil.copytree(here, other_arch / wp.config.version / "sm90")
    assert not offered(other_arch)
    renamed = tmp_path / "renamed"  # this CPU's folder, but the binary another architecture's
    shutil.copytree(good, renamed)
    entry = index["modules"][0]
    cubin = f"{ident}.sm90.cubin"
    folder = renamed / wp.config.version / "cpu"
    (folder / ident / entry["binary"]).rename(folder / ident / cubin)
    entry = {**entry, "binary": cubin, "sha256": {cubin: entry["sha256"][entry["binary"]], entry["meta"]:
                                                  entry["sha256"][entry["meta"]]}}
    (folder / prebuilt.INDEX).write_text(json.dumps({**index, "modules": [entry]}))
    assert not offered(renamed)

    # the package's own folder on this CPU, every load through the prebuilt lookup: nothing to copy, the module
    # compiles into an empty cache and runs
    monkeypatch.delenv("WRESDYN_PREBUILT_KERNELS")
    assert prebuilt.enable()
    prebuilt._read_index.cache_clear()
    cache = tmp_path / "cache_shipped"
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(cache))
    assert prebuilt.fetch(module, cpu, bd) is False and not cache.exists()
    module.unload()
    wp.force_load(device=cpu, modules=[module])
    assert list(cache.rglob("*.cpp")) and _runs(cpu)
