"""What the floor diagnostics share: a finished ``wresdyn deploy --floor`` run's configuration, its held-out motions
drawn again from its seed, and its real robot."""

from __future__ import annotations

import json
from pathlib import Path


def held_out(run, data=None, split="heldout"):
    """``(results, task, floating robot, held-out motions, real robot)`` of the floor run folder ``run``; ``data``:
    the dataset whose robot file it used (default: the shipped one); ``split`` ``"validation"``: its validation
    motions instead."""
    from wresdyn.data.dataset import load_dataset
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.paths import DEFAULT_DATASET
    from wresdyn.robot.description import load_robot
    from wresdyn.skills.motions import make_motions
    from wresdyn.skills.skill_config import FloorTaskConfig

    res = json.loads((Path(run) / "results.json").read_text())
    cfg, task = res["config"], FloorTaskConfig(**res["task"])
    ds = load_dataset(data or DEFAULT_DATASET)
    stand, floating = load_robot(ds.robot_file), load_robot(ds.robot_file, base="floating")
    # each split draws from a stream of its own position: the run's held-out motions without drawing the others
    counts = {"train": 0, "validation": 0, "heldout": 0, split: cfg[f"{split}_per_family"]}
    motions = make_motions(stand, counts, cfg["duration"], float(ds.rate_hz), cfg["seed"], floating=floating,
                           workers=0)[split]
    real = RealRobot(floating, Mismatch.from_dict(res["mismatch"], "the run's mismatch"), float(ds.rate_hz))
    return res, task, floating, motions, real
