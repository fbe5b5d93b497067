"""Write ``gains/<robot>.toml`` for every robot of ``robots.toml`` by one rule (the URDFs carry no drive gains).

Rule, the same for every robot:

* **kp**: the drive reaches its effort limit at an error of ``E_SAT`` (1 rad; 0.1 m for a prismatic joint):
  ``kp = effort / E_SAT``. The shipped humanoid's drives saturate at 0.7-1.3 rad; on the G1 this gives 25-139
  N*m/rad, near Unitree's published G1 gains (legs 100-150, ankles and arms 40), on the Solo12 2.7 against ODRI's
  usual kp = 3.
* **kd**: critically damped on the inertia the joint feels: ``kd = 2 zeta sqrt(kp I)`` with ``zeta = ZETA`` and
  ``I`` the joint's diagonal entry of the joint-space mass matrix (MuJoCo ``mj_fullM`` of the model wresdyn builds;
  no armature, as the files state none) at the reference pose: every joint at 0, clipped into its limits.
* **effort**: the file's ``<limit effort>``; where the file's value is a placeholder (``PLACEHOLDERS``), the vendor's
  published peak torque.
* **limits**: the file's; where they are placeholders, +-pi (what wresdyn assumes for a joint without limits,
  :func:`wresdyn.data.signals.finite_limits`).

Run from the repository root: ``python benchmarks/fidelity/robot_zoo/make_gains.py [--robots a,b]``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from zoo import load_zoo

E_SAT = {"revolute": 1.0, "prismatic": 0.1}
"""Position error at which the PD torque (force) reaches the effort limit [rad, m]: kp = effort / E_SAT. A tenth of
a metre for a slide is the same error at a 0.1 m lever, and lets a Panda finger (0.04 m of travel) push past the
default mismatch's dry friction (0.1 of its effort)."""
ZETA = 1.0
"""Damping ratio [-]: critically damped, no overshoot."""
PLACEHOLDERS = {
    "solo12": {
        "effort": (2.7, "ODRI Solo12 actuator peak: 0.025 N*m/A x 12 A x 9:1 gear (robot_properties_solo; Grimminger "
                        "et al. 2020); the URDF's 1000 N*m is a placeholder"),
        "limits": "the URDF's +-10 rad are placeholders",
    },
}
"""Robots whose file states placeholder values, and the published values used instead (with their source)."""


def joint_inertia(robot) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's inertia ``I`` [kg*m^2, or kg for a prismatic joint] at the reference pose, and that pose [rad]."""
    import mujoco

    from wresdyn.data.signals import finite_limits
    from wresdyn.robot.mujoco_model import build_mujoco

    m = build_mujoco(robot)
    d = mujoco.MjData(m)
    lo, hi = finite_limits(robot)
    q_ref = np.clip(np.zeros(robot.n_dof), lo, hi)
    d.qpos[:] = q_ref
    mujoco.mj_forward(m, d)
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    return np.diag(full).copy(), q_ref


def _g(x: float) -> str:
    return f"{x:.4g}"


def gains_toml(name: str, robot) -> str:
    """The gains config of ``robot`` (loaded without gains) by the rule above, every value's origin in a comment."""
    inertia, q_ref = joint_inertia(robot)
    fix = PLACEHOLDERS.get(name, {})
    lines = [f"# {name}: PD gains and effort limits by one rule for every zoo robot; written by",
             "# benchmarks/fidelity/robot_zoo/make_gains.py (rerun it rather than edit this file).",
             f"# kp = effort / e_sat (e_sat {E_SAT['revolute']:g} rad, {E_SAT['prismatic']:g} m for a slide);",
             f"# kd = 2 zeta sqrt(kp I), zeta = {ZETA:g}, I = the joint's diagonal of the joint-space mass matrix",
             "# (MuJoCo mj_fullM, no armature) at every joint 0 clipped into its limits;",
             "# effort: the URDF's <limit effort> unless noted.",
             ""]
    for i, joint in enumerate(robot.joint_names):
        kind = robot.joint_type[int(robot.dof_body[i])]
        unit = "kg" if kind == "prismatic" else "kg*m^2"
        effort, why = fix.get("effort", (float(robot.effort[i]), "URDF <limit effort>"))
        kp = effort / E_SAT[kind]
        f_n = math.sqrt(kp / inertia[i]) / (2 * math.pi)
        lines += ["[[joint]]", f'match = "{joint}"', f"kp = {_g(kp)}  # effort / {E_SAT[kind]:g}",
                  f"kd = {_g(2 * ZETA * math.sqrt(kp * inertia[i]))}  # I = {inertia[i]:.4g} {unit} at q = "
                  f"{q_ref[i]:g}: natural frequency {f_n:.3g} Hz",
                  f"effort = {_g(effort)}  # {why}"]
        if "limits" in fix:
            lines += [f"lower = {-math.pi:.6f}  # {fix['limits']}: +-pi", f"upper = {math.pi:.6f}"]
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", default=None, help="comma-separated robot names (default: all of robots.toml)")
    args = p.parse_args(argv)
    from wresdyn.robot.description import load_robot

    zoo = load_zoo()
    names = args.robots.split(",") if args.robots else list(zoo)
    for name in names:
        z = zoo[name]
        robot = load_robot(z.path)
        z.gains.parent.mkdir(parents=True, exist_ok=True)
        z.gains.write_text(gains_toml(name, robot))
        print(f"wrote {z.gains} ({robot.n_dof} joints)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
