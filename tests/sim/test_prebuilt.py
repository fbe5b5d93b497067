"""Prebuilt kernels (:mod:`wresdyn.sim.prebuilt`): a fit on an empty Warp cache that finds its modules exported by
``wresdyn warmup --export`` compiles none of them and ends where a fresh compile ends; an entry whose hash does not
match is never used (that module compiles). Each command runs in a process of its own, on a Warp cache of its own (a
module loaded in this process would never reach that cache). The binaries are built here, in a temporary folder."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import warp as wp

from wresdyn.data.mismatch import Mismatch
from wresdyn.paths import REPO

CARTPOLE = ("--robot", "newton:cartpole.urdf", "--gains", str(REPO / "examples" / "gains" / "cartpole.toml"))
"""The smallest robot at hand (3 DoF): its kernels compile in seconds on the CPU."""
# the checkout first, then the caller's path (where a machine installs its wheels off the default path)
PATH = os.pathsep.join(filter(None, (str(REPO), os.environ.get("PYTHONPATH"))))


def _compiled_here(cache: Path) -> set[str]:
    """Modules Warp compiled into ``cache`` itself: a compile leaves the generated source next to the binary, a copy
    from the prebuilt kernels only the binary and its meta."""
    return {p.parent.name for p in cache.rglob("wp_*/*.cpp")}


def _modules(cache: Path) -> set[str]:
    return {p.name for p in cache.rglob("wp_*") if p.is_dir()}


def _wresdyn(env: dict, *argv: str) -> subprocess.CompletedProcess:
    res = subprocess.run([sys.executable, "-m", "wresdyn.cli", *argv], env=env, cwd=REPO, capture_output=True,
                         text=True)
    assert res.returncode == 0, res.stderr[-3000:]
    return res


def _fit(tmp_path: Path, name: str, data: Path, prebuilt: Path) -> tuple[Path, Path]:
    """The default (hybrid) fit, two iterations of each stage, on an empty cache; (Warp cache, run folder)."""
    cache, run = tmp_path / f"warp_{name}", tmp_path / f"run_{name}"
    env = dict(os.environ, WARP_CACHE_PATH=str(cache), WRESDYN_KERNEL_DIR=str(tmp_path / f"kernels_{name}"),
               WRESDYN_PREBUILT_KERNELS=str(prebuilt), PYTHONPATH=PATH)
    _wresdyn(env, "fit", str(data), "--out", str(run), "--iterations", "2", "--identify.iterations", "2")
    return cache, run


def _curves(run: Path) -> list:
    """Each stage's learning curve without its clock times: (stage, iteration, every loss and validation figure)."""
    out = []
    for stage, folder in (("identify", run / "identify"), ("fit", run)):
        for row in json.loads((folder / "curve.json").read_text()):
            out.append((stage, *sorted((k, v) for k, v in row.items() if k != "wall")))
    return out


@pytest.mark.slow  # a warmup and three fits in fresh processes, two of them compiling: ~2 CPU-minutes
def test_prebuilt_kernels_replace_the_compile_only_on_an_exact_match(tmp_path, cartpole, record):
    data = record(cartpole, Mismatch(), {"train": 2, "validation": 1, "heldout": 1, "ood": 1}, 0.4)
    data.gains = cartpole.gains_record()
    data.save(tmp_path / "cart.npz")
    shipped = tmp_path / "prebuilt"
    env = dict(os.environ, WARP_CACHE_PATH=str(tmp_path / "warp_export"), PYTHONPATH=PATH,
               WRESDYN_KERNEL_DIR=str(tmp_path / "kernels_export"), WRESDYN_PREBUILT_KERNELS=str(tmp_path / "none"))
    out = _wresdyn(env, "warmup", "--no-shipped", *CARTPOLE, "--export", str(shipped)).stdout
    index_path = next(shipped.rglob("index.json"))
    index = json.loads(index_path.read_text())
    exported = {e["identifier"] for e in index["modules"]}
    assert index_path.parent.name == "cpu" and index["warp"] == index_path.parent.parent.name, index_path
    assert f"exported {len(exported)} compiled modules" in out and len(exported) >= 5, out

    # an empty cache and the exported folder: every module the fit loads comes from it, none is compiled
    cache, run = _fit(tmp_path, "prebuilt", tmp_path / "cart.npz", shipped)
    assert _compiled_here(cache) == set(), _compiled_here(cache)
    loaded = _modules(cache)
    assert {"wp_replay_step", "wp_replay_rollout", "wp_replay_terms"} <= {m.rsplit("_", 2)[0] for m in loaded}
    assert loaded <= exported, loaded - exported

    # the same fit compiling everything (no prebuilt folder) ends at the same weights
    fresh_cache, fresh = _fit(tmp_path, "fresh", tmp_path / "cart.npz", tmp_path / "none")
    assert _compiled_here(fresh_cache) == _modules(fresh_cache) == loaded
    assert len(_curves(run)) >= 4 and _curves(run) == _curves(fresh)
    for name in ("identify/physics.json", "physics.json", "residual.json"):
        assert json.loads((run / name).read_text()) == json.loads((fresh / name).read_text()), name
    a = torch.load(run / "checkpoint.pt", map_location="cpu", weights_only=False)["policy"]
    b = torch.load(fresh / "checkpoint.pt", map_location="cpu", weights_only=False)["policy"]
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)

    # a tampered entry (the forward step's hash) is not used: that module compiles, the others are still copied
    step = next(e for e in index["modules"] if e["name"].startswith("replay_step") and e["identifier"] in loaded)
    step["hash"] = ("0" if step["hash"][0] != "0" else "1") + step["hash"][1:]
    index_path.write_text(json.dumps(index))
    cache, _ = _fit(tmp_path, "tampered", tmp_path / "cart.npz", shipped)
    assert _compiled_here(cache) == {step["identifier"]}, _compiled_here(cache)
    assert _modules(cache) == loaded


def test_without_a_prebuilt_folder_nothing_is_wrapped_or_copied(tmp_path, monkeypatch):
    import warp as wp

    from wresdyn.sim import prebuilt

    monkeypatch.setenv("WRESDYN_PREBUILT_KERNELS", str(tmp_path / "absent"))
    assert prebuilt.root() == tmp_path / "absent"
    wp.init()
    module = wp.get_module("wresdyn.sim.prebuilt_test_absent")
    assert prebuilt.fetch(module, wp.get_device("cpu")) is False
    assert not (tmp_path / "absent").exists()
    monkeypatch.delenv("WRESDYN_PREBUILT_KERNELS")
    assert prebuilt.root() == prebuilt.SHIPPED


@wp.kernel
def _double(x: wp.array(dtype=float)):  # the module fetch is tried on: this test file's kernels alone
    i = wp.tid()
    x[i] = 2.0 * x[i]


def _index_file(folder: Path) -> Path:
    return folder / wp.config.version / "cpu" / "index.json"


def test_fetch_copies_an_exact_match_and_nothing_else(tmp_path, monkeypatch):
    """In this process: one small module compiled into one cache, exported, then fetched into empty caches: copied
    (binary and meta only) where the index matches, left to compile where its hash or a file's SHA-256 does not."""
    from wresdyn.sim import prebuilt

    wp.init()
    cpu = wp.get_device("cpu")
    module = _double.module
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path / "a"))
    module.unload()
    wp.force_load(device=cpu, modules=[module])
    shipped = tmp_path / "shipped"
    names = prebuilt.export(cpu, shipped)
    ident = module.get_module_identifier(block_dim=next(bd for (ctx, bd) in module.execs if ctx == cpu.context))
    assert names == [ident]  # only what this cache holds, not the modules other tests loaded into theirs
    monkeypatch.setenv("WRESDYN_PREBUILT_KERNELS", str(shipped))
    entry = json.loads(_index_file(shipped).read_text())["modules"][0]
    bd = entry["block_dim"]

    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path / "b"))
    assert prebuilt.fetch(module, cpu, bd) is True
    assert sorted(p.name for p in (tmp_path / "b" / ident).iterdir()) == sorted([entry["binary"], entry["meta"]])
    assert prebuilt.fetch(module, cpu, bd) is False  # in the cache now: nothing to do
    # loaded from the copy, nothing compiled, and it runs
    module.unload()
    wp.force_load(device=cpu, modules=[module])
    assert not list((tmp_path / "b").rglob("*.cpp"))
    x = wp.array(np.arange(4, dtype=np.float32), device=cpu)
    wp.launch(_double, dim=4, inputs=[x], device=cpu)
    assert np.array_equal(x.numpy(), 2.0 * np.arange(4))

    index = json.loads(_index_file(shipped).read_text())
    good = index["modules"][0]["hash"]
    index["modules"][0]["hash"] = ("0" if good[0] != "0" else "1") + good[1:]
    _index_file(shipped).write_text(json.dumps(index))
    prebuilt._read_index.cache_clear()
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path / "c"))
    assert prebuilt.fetch(module, cpu, bd) is False and not (tmp_path / "c" / ident).exists()

    index["modules"][0]["hash"] = good
    _index_file(shipped).write_text(json.dumps(index))
    prebuilt._read_index.cache_clear()
    binary = shipped / wp.config.version / "cpu" / ident / entry["binary"]
    binary.write_bytes(binary.read_bytes() + b"\0")
    assert prebuilt.fetch(module, cpu, bd) is False and not (tmp_path / "c" / ident).exists()
    prebuilt._read_index.cache_clear()
