"""The pieces of the zero-shot skill benchmark (:mod:`.skills`), on the stand and on the floor: the four policies and
the plant each trains on, the corrections fitted on the stand's dataset, and the results file."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from ..data.mismatch import Mismatch
from ..fit.gradfit import GradFitConfig, export_run, fit
from ..fit.hybrid import fit_hybrid
from ..identify.sysid import SysIdConfig
from ..sim.devices import require_device
from ..skills.skill_config import SkillPPOConfig

__all__ = ["POLICIES", "BASE_POLICIES", "RANDOMIZED", "BenchmarkStart", "start_benchmark", "fit_corrections",
           "write_results"]

POLICIES = {"a_nominal": "nominal", "b_calibrated": "calibrated", "c_delta_action": "delta_action", "d_oracle": "real",
            "e_randomized": "randomized", "f_calibrated_narrow": "calibrated_narrow"}
"""Policy run folders and the plant each trains on."""
BASE_POLICIES = ("a_nominal", "b_calibrated", "c_delta_action", "d_oracle")
"""What a benchmark trains unless told: the domain-randomised baselines (e), (f) are asked for by name."""
RANDOMIZED = {"randomized": "nominal", "calibrated_narrow": "calibrated"}
"""The domain-randomised settings and the simulator each randomises (:mod:`wresdyn.skills.randomize`): (e) the
nominal one over the peers' wide ranges, (f) the calibrated one over narrow ranges from the identification."""


class BenchmarkStart(NamedTuple):
    """What :func:`start_benchmark` resolves."""

    policies: list[str]
    """The policies to train and deploy, in :data:`POLICIES` order (``a_nominal`` always)."""
    ppo: SkillPPOConfig
    """The skills' PPO with the benchmark's ``seed`` and ``device`` (the worlds are the plants')."""
    mismatch: Mismatch
    """The real robot's mismatch."""
    counts: dict[str, int]
    """Motions per family of each split."""


def start_benchmark(out: Path, cfg, ppo, mismatch, dataset, policies) -> BenchmarkStart:
    """Create ``out``, resolve what a benchmark's arguments leave to their defaults (``ppo``: a default
    :class:`~wresdyn.skills.skill_config.SkillPPOConfig`; ``mismatch``: the dataset's) and pin torch's threads to
    ``ppo.torch_threads``. ``cfg``: the benchmark's :class:`~wresdyn.experiments.deploy_config.DeployConfig` or
    :class:`~wresdyn.experiments.deploy_config.FloorDeployConfig`. The devices the floor's fine-tunings take beside
    the others are checked first, not minutes later when the corrections are fitted."""
    for device in getattr(cfg, "beside_devices", ()):
        require_device(device)
    policies = [p for p in POLICIES if p in policies or p == "a_nominal"]
    out.mkdir(parents=True, exist_ok=True)
    ppo = replace(ppo or SkillPPOConfig(), seed=cfg.seed, device=cfg.device)
    if ppo.torch_threads is not None:
        torch.set_num_threads(ppo.torch_threads)
    mismatch = mismatch if mismatch is not None else Mismatch.from_dict(dataset.mismatch, "the dataset's mismatch")
    counts = {"train": cfg.train_per_family, "validation": cfg.validation_per_family,
              "heldout": cfg.heldout_per_family}
    if getattr(cfg, "shipped", False):  # every policy taken as it is: no training motions to draw
        del counts["train"]
    return BenchmarkStart(policies, ppo, mismatch, counts)


def fit_corrections(dataset, data_path, robot, out: Path, calibrated, delta, device, log, need_delta=True,
                    need_calibrated=True):
    """Run folders of the calibrated robot and the delta-action residual, fitted into ``out`` when not given (and
    needed: ``None`` for one that is not)."""
    if calibrated is None and need_calibrated:
        calibrated = out / "calibrated"
        if not (calibrated / "policy.pt").is_file():
            log(f"fitting the calibrated robot (hybrid, `wresdyn fit`) -> {calibrated}")
            cfg = replace(GradFitConfig(), device=device)
            hybrid = fit_hybrid(robot, dataset, replace(SysIdConfig(), device=device), cfg, calibrated,
                                data_path=data_path, log=lambda s: None)
            export_run(hybrid.policy, calibrated, hybrid.config, dataset, data_path, physics=hybrid.physics)
    if delta is None and need_delta:
        delta = out / "delta_action"
        if not (delta / "policy.pt").is_file():
            log(f"fitting the delta-action residual alone (`wresdyn fit --model network --residual delta_action`) "
                f"-> {delta}")
            cfg = GradFitConfig()
            cfg = replace(cfg, model="network", device=device, residual=replace(cfg.residual, kind="delta_action"))
            policy, _ = fit(robot, dataset, cfg, out=delta, log=lambda s: None)
            export_run(policy, delta, cfg, dataset, data_path)
    return None if calibrated is None else Path(calibrated), None if delta is None else Path(delta)


def write_results(out: Path, results: dict) -> Path:
    """Write ``results`` to ``out/results.json`` (written next to it and renamed into place); returns the path."""
    tmp = out / "results.json.tmp"
    tmp.write_text(json.dumps(results, indent=1, default=_json))
    tmp.replace(out / "results.json")
    return out / "results.json"


def _json(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(type(x))
