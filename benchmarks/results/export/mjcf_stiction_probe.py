"""Which MuJoCo mapping of the servo's stiction brings the exported SO-101 closest to wresdyn's replay."""
import sys, re
from pathlib import Path
import numpy as np
from wresdyn.export.mjcf import round_trip, servo_goal_accel, ROUND_TRIP_TRAJECTORIES
from wresdyn.data.dataset import load_dataset
from wresdyn.data.loading import dataset_robot
from wresdyn.evaluation.evaluate_run import run_friction_kappa
from wresdyn.learn.runs import run_physics

run, xml, data = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
ds = load_dataset(data)
robot = dataset_robot(ds.robot_file, None, ds.gains_config)
phys = run_physics(run, robot)
kappa = run_friction_kappa(run)
held = list(ds.split("heldout")[:ROUND_TRIP_TRAJECTORIES])
acc = servo_goal_accel(robot, phys)
base = round_trip(xml, robot, phys, held, ds.rate_hz, None, None, kappa, acc)
ref = base.pop("q")
print("as exported", {k: base[k] for k in ("wresdyn", "mujoco", "between")}, flush=True)
text = xml.read_text()
names = list(robot.joint_names)
for frac in (1.0, 0.5):
    t = text
    for i, n in enumerate(names):
        f = float(phys.friction[i]) + frac * float(phys.stiction[i])
        t = re.sub(r'(<joint name="%s"[^>]*?frictionloss=")([^"]+)(")' % n, lambda m: m.group(1) + f"{f:.6g}" + m.group(3), t)
    p = xml.with_name(f"robot_stiction{frac}.xml"); p.write_text(t)
    r = round_trip(p, robot, phys, held, ds.rate_hz, None, None, kappa, acc, reference=ref); r.pop("q")
    print(f"frictionloss = friction + {frac} stiction", {k: r[k] for k in ("wresdyn", "mujoco", "between")}, flush=True)
