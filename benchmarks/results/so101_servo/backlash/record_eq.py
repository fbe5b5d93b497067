"""Record the SO-101 servo robot (MuJoCo "real" robot, scenes/so101/servo.toml + mismatch.toml) for 2 s; save q, qd."""
import sys
import numpy as np
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.paths import REPO
from wresdyn.robot.description import load_robot
from wresdyn.sim.parity import multisine_command

so = REPO / "scenes" / "so101"
robot = load_robot(so / "so101.xml", gains=so / "servo.toml")
real = RealRobot(robot, Mismatch.load(so / "mismatch.toml"), 250.0)
cmd = multisine_command(robot, 2.0, 1 / 250.0, 0.3, seed=3)
q, qd, tau = real.record(cmd, np.random.default_rng(0))
np.savez(sys.argv[1], q=q, qd=qd, tau=tau)
