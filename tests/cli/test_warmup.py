"""``wresdyn warmup``: after it a robot's fit, identification, PPO and evaluation compile nothing, and a second call
compiles nothing either. Each command runs in a process of its own on a temporary Warp cache (a module loaded in this
process would never reach that cache)."""

from __future__ import annotations

import os
import subprocess
import sys
import resource
from pathlib import Path

import pytest

from wresdyn.cli import main
from wresdyn.data.mismatch import Mismatch
from wresdyn.paths import REPO

CARTPOLE = ("--robot", "newton:cartpole.urdf", "--gains", str(REPO / "examples" / "gains" / "cartpole.toml"))
"""The smallest robot at hand (3 DoF): its kernels compile in seconds on the CPU."""
# the checkout first, then the caller's path (where a machine installs its wheels off the default path)
PATH = os.pathsep.join(filter(None, (str(REPO), os.environ.get("PYTHONPATH"))))


def _modules(cache: Path) -> set[str]:
    """Warp's compiled modules in ``cache`` (one folder each, under Warp's version folder)."""
    return {p.name for p in cache.rglob("wp_*") if p.is_dir()}


def _wresdyn(env: dict, *argv: str) -> tuple[subprocess.CompletedProcess, float]:
    """Run ``wresdyn ARGV``; its result and the CPU-seconds it took (every load, so a busy machine does not count)."""
    cpu = resource.getrusage(resource.RUSAGE_CHILDREN)
    res = subprocess.run([sys.executable, "-m", "wresdyn.cli", *argv], env=env, cwd=REPO, capture_output=True,
                         text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert res.returncode == 0, res.stderr[-2000:]
    return res, after.ru_utime + after.ru_stime - cpu.ru_utime - cpu.ru_stime


def test_warmup_refuses_an_empty_list_gains_without_a_robot_and_a_bad_device(capsys):
    assert main(["warmup", "--no-shipped"]) == 2
    assert "nothing to compile" in capsys.readouterr().err
    assert main(["warmup", "--gains", "scenes/so101/servo.toml"]) == 2
    assert "--gains applies to --robot" in capsys.readouterr().err
    assert main(["warmup", "--device", "gpu"]) == 2
    assert capsys.readouterr().err.strip() == "wresdyn warmup: error: --device = 'gpu' is not a device: cpu, cuda or cuda:N"


@pytest.mark.slow  # three fresh processes and a robot's first compile: ~35 CPU-seconds
def test_after_warmup_fit_train_and_eval_compile_nothing(tmp_path, cartpole, record):
    data = record(cartpole, Mismatch(), {"train": 2, "validation": 1, "heldout": 1, "ood": 1}, 0.4)
    data.gains = cartpole.gains_record()
    data.save(tmp_path / "cart.npz")
    cache = tmp_path / "warp"
    env = dict(os.environ, WARP_CACHE_PATH=str(cache), WRESDYN_KERNEL_DIR=str(tmp_path / "kernels"),
               PYTHONPATH=PATH)

    first, cold = _wresdyn(env, "warmup", "--no-shipped", *CARTPOLE)
    compiled = _modules(cache)
    # the forward and the adjoint step, the fused rollout, the dynamics terms, Newton's model-building kernels
    kinds = {m.rsplit("_", 2)[0] for m in compiled}
    assert {"wp_replay_step", "wp_replay_rollout", "wp_replay_terms"} <= kinds, first.stdout
    assert sum(m.startswith("wp_replay_step") for m in compiled) == 2  # forward and adjoint

    again, warm = _wresdyn(env, "warmup", "--no-shipped", *CARTPOLE)
    assert "all compiled already" in again.stdout
    assert _modules(cache) == compiled
    assert warm < 0.5 * cold, (warm, cold)  # imports and two Newton models only

    # the default (hybrid) fit with its evaluation, then PPO: every module they load is in the cache already
    _wresdyn(env, "fit", str(tmp_path / "cart.npz"), "--out", str(tmp_path / "fit"), "--iterations", "2",
             "--identify.iterations", "2", "--eval")
    _wresdyn(env, "train", str(tmp_path / "cart.npz"), "--out", str(tmp_path / "ppo"), "--ppo.iterations", "1",
             "--env.num-worlds", "4")
    assert _modules(cache) == compiled
