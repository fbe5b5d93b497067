"""The SO-101 servo model through the MJCF export: held-out error of plain MuJoCo against the wresdyn model's.

    OMP_NUM_THREADS=1 python benchmarks/fidelity/mjcf_so101.py [--seconds 1.0] [--heldout 2] [--out DIR]

Records held-out multisines on the SO-101's bench real robot (scenes/so101/so101.xml with scenes/so101/servo.toml,
scenes/so101/mismatch.toml), then exports two physics-only runs as MJCF (``wresdyn export RUN``, the default for an
MJCF robot): the nominal servo model, and the real robot's own parameters (``RealRobot.physics()``, a model whose
only error is what the replay cannot represent). Prints each ``mjcf_report.json``'s round trip with and without the
goal profile (mean |q - q_recorded| [rad]).
"""

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from wresdyn.cli import main
from wresdyn.data.dataset import Dataset, Trajectory, derive_qdd
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.paths import REPO
from wresdyn.robot.description import load_robot
from wresdyn.sim.parity import multisine_command
from wresdyn.sim.physics import PhysicalParams

RATE_HZ = 500.0


def record(robot, mismatch, seconds: float, count: int) -> Dataset:
    real = RealRobot(robot, mismatch, RATE_HZ)
    f32 = lambda a: np.asarray(a, dtype=np.float32).astype(np.float64)  # noqa: E731
    trajs = []
    for i in range(count):
        q_cmd = f32(multisine_command(robot, seconds, 1.0 / RATE_HZ, 0.3, seed=100 + i))
        q, qd, _ = real.record(q_cmd, np.random.default_rng([1, i]))
        q, qd = f32(q), f32(qd)
        trajs.append(Trajectory(f"heldout_{i:03d}", "heldout", np.arange(len(q_cmd)) / RATE_HZ, q, qd,
                                derive_qdd(qd, RATE_HZ), q_cmd))
    return Dataset(list(robot.joint_names), RATE_HZ, trajs, str(robot.source), robot.source_sha256,
                   mismatch.to_dict(), 0, {}, robot.gains_record())


def run() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=1.0)
    p.add_argument("--heldout", type=int, default=2)
    p.add_argument("--out", help="folder for the runs (default: a temporary one)")
    a = p.parse_args()
    so101 = REPO / "scenes" / "so101"
    robot = load_robot(so101 / "so101.xml", gains=so101 / "servo.toml")
    mismatch = Mismatch.load(so101 / "mismatch.toml")
    tmp = Path(a.out or tempfile.mkdtemp(prefix="mjcf_so101."))
    tmp.mkdir(parents=True, exist_ok=True)
    record(robot, mismatch, a.seconds, a.heldout).save(tmp / "dataset.npz")
    models = {"nominal": PhysicalParams.nominal(robot), "real_robot": RealRobot(robot, mismatch, RATE_HZ).physics()}
    print(f"SO-101 servo model, {a.heldout} held-out x {a.seconds} s at {RATE_HZ:g} Hz; mean |q - q_recorded| [rad]")
    for name, physics in models.items():
        folder = tmp / name
        folder.mkdir(exist_ok=True)
        (folder / "config.json").write_text(json.dumps({"data_path": str(tmp / "dataset.npz")}))
        physics.save(folder / "physics.json")
        if main(["export", str(folder), "--physics-only", "--force"]) != 0:
            return 1
        report = json.loads((folder / "export" / "mjcf_report.json").read_text())
        trip, bare = report["round_trip"], report["round_trip_without_goal_profile"]
        print(f"{name:<11} wresdyn {trip['wresdyn']:.4e}  MuJoCo {trip['mujoco']:.4e} "
              f"({100 * (trip['mujoco'] / trip['wresdyn'] - 1):+.1f} %)  between {trip['between']:.3e}  "
              f"MuJoCo without goal profile {bare['mujoco']:.4e}")
    return 0


if __name__ == "__main__":
    sys.exit(run())
