"""``wresdyn inspect ROBOT``: joint table, then a short PD replay in Newton and MuJoCo C and their agreement."""

from __future__ import annotations

import argparse

from ..choices import SolverKind, choices


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("robot", nargs="?", default=None, help="robot file: .usd/.usda/.usdc, .urdf or .xml (default: scenes/humanoid.usda)")
    p.add_argument("--gains", default=None, help="TOML file of PD gains and joint parameters by joint-name pattern")
    p.add_argument("--floating", action="store_true", help="load with a floating base (default: fixed, on a stand)")
    p.add_argument("--seconds", type=float, default=1.0, help="length of the PD replay check [s]")
    p.add_argument("--dt", type=float, default=0.002, help="time step [s]")
    p.add_argument("--solver", choices=choices(SolverKind), default="auto", help="Newton solver (default: auto)")


def run(args: argparse.Namespace) -> int:
    from ..robot.description import DEFAULT_ROBOT, load_robot
    from ..sim.parity import joint_table, pd_agreement

    robot = load_robot(args.robot or DEFAULT_ROBOT, gains=args.gains, base="floating" if args.floating else "fixed")
    print(f"{robot.source}  ({robot.n_dof} actuated joints, {robot.n_bodies} bodies, "
          f"{robot.body_mass.sum():.2f} kg, {robot.base} base, frames: {', '.join(robot.frames) or 'none'})")
    print(joint_table(robot))
    if robot.base == "floating":
        print("PD replay check skipped: it runs on a fixed base (load without --floating)")
        return 0
    robot.check_gains()
    for integrator in ("Euler", "implicitfast"):
        a = pd_agreement(robot, args.seconds, args.dt, integrator=integrator, solver=args.solver)
        print(f"PD replay {args.seconds:g} s at dt={args.dt:g}: Newton {a.solver} vs MuJoCo C {integrator}: "
              f"max |dq| {a.max_abs:.2e}, mean |dq| {a.mean_abs:.2e} (tracking error {a.tracking:.3f})")
    return 0
