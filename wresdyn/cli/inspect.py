"""``wresdyn inspect ROBOT``: joint table, then a short PD replay in Newton and MuJoCo C and their agreement.

A joint whose effort limit the file does not state (the importer's placeholder) is flagged in a ``note`` column
and a warning line: inspect still runs the PD check, but ``collect``, ``fit``, ``train``, ``identify`` and
``eval`` refuse such a robot until a gains config sets ``effort``. A robot file without PD gains (most URDFs) is
listed with a warning line too; the PD check is skipped, as it has nothing to drive the joints with."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import tyro

from ..choices import SolverKind
from .command import Command


@dataclass(frozen=True)
class Inspect(Command):
    """``wresdyn inspect``: the robot file and the PD replay check."""

    robot: Annotated[str | None, tyro.conf.Positional, tyro.conf.arg(metavar="ROBOT")] = None
    """Robot file: .usd/.usda/.usdc, .urdf or .xml (default: scenes/humanoid.usda)."""
    gains: str | None = None
    """TOML file of PD gains and joint parameters by joint-name pattern."""
    floating: bool = False
    """Load with a floating base (default: fixed, on a stand)."""
    seconds: float = 1.0
    """Length of the PD replay check [s]."""
    dt: float = 0.002
    """Time step [s]."""
    solver: SolverKind = "auto"
    """Newton solver."""


COMMAND = Inspect


def run(args: Inspect) -> int:
    from ..robot.description import DEFAULT_ROBOT, load_robot
    from ..sim.parity import joint_table, pd_agreement

    robot = load_robot(args.robot or DEFAULT_ROBOT, gains=args.gains, base="floating" if args.floating else "fixed")
    print(f"{robot.source}  ({robot.n_dof} actuated joints, {robot.n_bodies} bodies, "
          f"{robot.body_mass.sum():.2f} kg, {robot.base} base, frames: {', '.join(robot.frames) or 'none'})")
    print(_flagged(joint_table(robot), robot))
    bad = robot.placeholder_effort()
    no_gains = robot.missing_gains()
    if no_gains:
        print(f"warning: {len(no_gains)} of {robot.n_dof} joints have no PD gains in the file; collect/fit/train/"
              "identify/eval refuse them until a gains config sets them: [[joint]] match = \"*\" kp = ... kd = ..., "
              "passed with --gains FILE.toml")
    if bad:
        print(f"warning: {len(bad)} of {robot.n_dof} joints have no effort limit in the file (only the importer's "
              "placeholder); collect/fit/train/identify/eval refuse them until a gains config sets it: "
              "[[joint]] match = \"*\" effort = ... (N*m), passed with --gains FILE.toml")
    if robot.base == "floating":
        print("PD replay check skipped: it runs on a fixed base (load without --floating)")
        return 0
    if no_gains:
        print("PD replay check skipped: no PD gains to drive the replay with")
        return 0
    for integrator in ("Euler", "implicitfast"):
        a = pd_agreement(robot, args.seconds, args.dt, integrator=integrator, solver=args.solver)
        print(f"PD replay {args.seconds:g} s at dt={args.dt:g}: Newton {a.solver} vs MuJoCo C {integrator}: "
              f"max |dq| {a.max_abs:.2e}, mean |dq| {a.mean_abs:.2e} (tracking error {a.tracking:.3f})")
    return 0


def _flagged(table: str, robot) -> str:
    """The joint table with a ``note`` column flagging placeholder effort limits (rows follow the joint order
    after the header and its rule)."""
    bad = set(robot.placeholder_effort())
    if not bad:
        return table
    lines = table.splitlines()
    head, rule, rows = lines[0], lines[1], lines[2:]
    out = [f"{head}  note", rule + "-" * 6]
    for name, row in zip(robot.joint_names, rows):
        out.append(f"{row}  {'effort: placeholder, set it with --gains' if name in bad else ''}".rstrip())
    return "\n".join(out + rows[len(robot.joint_names):])
