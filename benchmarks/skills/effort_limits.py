"""Effort limits of a calibrated robot against the "real" robot's: per joint, the robot file's limit, the identified
one (``physics.json`` of a ``wresdyn fit`` or ``wresdyn identify`` run) and the real robot's (its MuJoCo model's
actuator force range: the file's limit times the mismatch's ``torque_limit_scale``), in N·m.

    python benchmarks/skills/effort_limits.py RUN [--data DATASET]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run")
    p.add_argument("--data", default=None, help="the dataset whose mismatch is the real robot (default: shipped)")
    args = p.parse_args()

    from wresdyn.data.dataset import load_dataset
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.paths import DEFAULT_DATASET
    from wresdyn.robot.description import load_robot

    ds = load_dataset(args.data or DEFAULT_DATASET)
    robot = load_robot(ds.robot_file)
    identified = json.loads((Path(args.run) / "physics.json").read_text())["effort"]
    real = RealRobot(robot, Mismatch.from_dict(ds.mismatch, "the dataset's mismatch"), float(ds.rate_hz))
    limits = real.model.actuator_forcerange[:robot.n_dof, 1]
    print(f"{'joint':22s} {'file':>7s} {'identified':>11s} {'real':>7s} {'identified/real':>16s}")
    for name, file, ident, lim in zip(robot.joint_names, robot.effort, identified, limits):
        print(f"{name:22s} {file:7.1f} {ident:11.2f} {lim:7.2f} {ident / lim:16.2f}")


if __name__ == "__main__":
    main()
