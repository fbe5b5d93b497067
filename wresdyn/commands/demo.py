"""``wresdyn demo``: the main job on the embedded defaults."""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="runs/demo", help="output folder")


def run(args: argparse.Namespace) -> int:
    from ..robot import DEFAULT_ROBOT, load_robot
    from ..validate import joint_table, pd_agreement

    robot = load_robot(DEFAULT_ROBOT)
    print(joint_table(robot))
    for integrator in ("Euler", "implicitfast"):
        a = pd_agreement(robot, 2.0, 0.002, integrator=integrator)
        print(f"Newton {a.solver} vs MuJoCo C {integrator}, 2 s PD replay: max |dq| {a.max_abs:.2e} rad, mean {a.mean_abs:.2e} rad")
    return 0
