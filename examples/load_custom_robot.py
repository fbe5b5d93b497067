"""Load your own robot file and check that Newton and MuJoCo see the same robot.

    python examples/load_custom_robot.py path/to/robot.usd [--gains gains.toml]

Prints the actuated-joint table (limits, PD gains, effort limits, armature), replays a short multisine
command under PD in Newton and in MuJoCo C, and reports how closely they agree. Many robot files carry
no drive gains: give them with a TOML file of joint-name patterns, e.g.

    [[joint]]
    match = "*"          # every joint
    kp = 100.0           # [N*m/rad]
    kd = 4.0             # [N*m*s/rad]
    [[joint]]
    match = "*ankle*"
    kp = 40.0
    armature = 0.01      # reflected rotor inertia [kg*m^2]
"""

import argparse
import sys

import wresdyn
from wresdyn.sim.parity import joint_table, pd_agreement


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robot", nargs="?", default=str(wresdyn.DEFAULT_ROBOT))
    parser.add_argument("--gains", default=None)
    parser.add_argument("--seconds", type=float, default=1.0)
    args = parser.parse_args()
    try:
        robot = wresdyn.load_robot(args.robot, gains=args.gains)
        print(joint_table(robot))
        robot.check_gains()
        agreement = pd_agreement(robot, seconds=args.seconds)
    except wresdyn.RobotError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"Newton ({agreement.solver}) vs MuJoCo C ({agreement.integrator}) over {args.seconds:g} s of PD replay: "
          f"max |dq| = {agreement.max_abs:.2e}, mean |dq| = {agreement.mean_abs:.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
