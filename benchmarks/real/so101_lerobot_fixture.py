"""Write tests/data/lerobot_so101/: a LeRobot dataset of the SO-101 follower made by LeRobot's own writer from the
SAGE logs of data/so101/logs, as if recorded with ``lerobot-record --robot.type=so101_follower
--robot.use_degrees=false`` (LeRobot 0.4.4: ``robot_type`` ``so_follower``, arm joints in range units).

Needs LeRobot, which the project does not depend on: run it in a throwaway environment of its own, from the
repository root (the project's package is not imported: this script reads the SAGE files itself)::

    python3 -m venv /tmp/lerobot-venv && /tmp/lerobot-venv/bin/pip install lerobot==0.4.4
    /tmp/lerobot-venv/bin/python benchmarks/real/so101_lerobot_fixture.py tests/data/lerobot_so101

Each episode is the first EPISODE_S seconds after ``MOTION_START`` of one SAGE run, one frame per SAGE state row
(about 50 Hz, written at fps 50): ``observation.state`` the measured positions, ``action`` the command in force at
that row. SAGE logs the arm in radians about the middle of each calibrated range (2π/4096 rad per encoder tick) and
the jaw as 0..1 of its range; a calibration of plausible ranges (CALIBRATION: each arm range spans the robot file's
joint range) turns them into encoder ticks about the range's middle, and LeRobot's Feetech bus normalises the ticks
as it does on the robot (its ``_normalize``: RANGE_M100_100 for the arm, RANGE_0_100 for the gripper). The
calibration is saved beside the dataset folder as LeRobot saves it (``<dataset>_calibration.json``).
"""

import csv
import json
import math
import shutil
import sys
from pathlib import Path

import numpy as np

EPISODE_S = 6.0
"""Length of each episode [s]."""
RUNS = ("multisine", "prbs_excitation", "step_response", "pick_place")
"""SAGE runs of data/so101/logs, one episode each, in episode order."""
SAGE_TO_MOTOR = {"Rotation": "shoulder_pan", "Pitch": "shoulder_lift", "Elbow": "elbow_flex",
                 "Wrist_Pitch": "wrist_flex", "Wrist_Roll": "wrist_roll", "Jaw": "gripper"}
CALIBRATION = {"shoulder_pan": (796, 3300), "shoulder_lift": (910, 3186), "elbow_flex": (946, 3150),
               "wrist_flex": (967, 3129), "wrist_roll": (228, 3868), "gripper": (2010, 3381)}
"""(range_min, range_max) [ticks] per motor: the arm's half spans are the robot file's joint ranges in ticks
(shoulder_pan ±1.92 rad = ±1252 ticks, ...), the gripper's a 1371-tick opening."""
TICK = 2 * math.pi / 4096
"""rad per encoder tick."""


def sage_rows(run: Path):
    """(measured positions (N, 6), commands in force (N, 6)) of a SAGE run from MOTION_START on, SAGE units."""
    def vectors(path):
        with open(path, newline="") as f:
            rows = list(csv.reader(f))[1:]
        return np.array([float(r[1]) for r in rows]), np.array([json.loads(r[2]) for r in rows])

    names = (run / "joint_list.txt").read_text().split()
    t_cmd, cmd = vectors(run / "control.csv")
    t, q = vectors(run / "state_motor.csv")
    with open(run / "event.csv", newline="") as f:
        start = next(float(r[1]) for r in csv.reader(f) if r[-1] == "MOTION_START")
    keep = np.flatnonzero(t >= start)
    keep = keep[t[keep] - t[keep[0]] < EPISODE_S * 1e6]
    held = np.searchsorted(t_cmd, t[keep], side="right") - 1
    order = [names.index(s) for s in SAGE_TO_MOTOR]
    return q[keep][:, order], cmd[held][:, order]


def main(out: Path) -> None:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.motors import Motor, MotorCalibration, MotorNormMode
    from lerobot.motors.feetech import FeetechMotorsBus

    motors = list(SAGE_TO_MOTOR.values())
    calibration = {m: MotorCalibration(id=i + 1, drive_mode=0, homing_offset=0, range_min=lo, range_max=hi)
                   for i, (m, (lo, hi)) in enumerate(CALIBRATION.items())}
    bus = FeetechMotorsBus("/dev/null", {m: Motor(i + 1, "sts3215", MotorNormMode.RANGE_0_100 if m == "gripper"
                                                  else MotorNormMode.RANGE_M100_100)
                                         for i, m in enumerate(motors)}, calibration)

    def normalise(sage: np.ndarray) -> np.ndarray:
        """SAGE units (N, 6) -> encoder ticks -> LeRobot's units, through LeRobot's own normalisation."""
        out = np.empty_like(sage)
        for k, row in enumerate(sage):
            ticks = {}
            for j, m in enumerate(motors):
                lo, hi = CALIBRATION[m]
                ticks[j + 1] = lo + row[j] * (hi - lo) if m == "gripper" else (lo + hi) / 2 + row[j] / TICK
            norm = bus._normalize(ticks)
            out[k] = [norm[j + 1] for j in range(len(motors))]
        return out

    names = [f"{m}.pos" for m in motors]
    features = {"action": {"dtype": "float32", "shape": (6,), "names": names},
                "observation.state": {"dtype": "float32", "shape": (6,), "names": names}}
    if out.exists():
        shutil.rmtree(out)
    ds = LeRobotDataset.create("wresdyn/so101_sage", fps=50, features=features, root=out, robot_type="so_follower",
                               use_videos=False)
    logs = Path(__file__).resolve().parents[2] / "data" / "so101" / "logs"
    for run in RUNS:
        q, cmd = sage_rows(logs / run)
        for state, action in zip(normalise(q), normalise(cmd)):
            ds.add_frame({"observation.state": state.astype(np.float32), "action": action.astype(np.float32),
                          "task": f"SAGE {run}"})
        ds.save_episode()
    ds.finalize()
    import draccus

    with open(out.parent / f"{out.name}_calibration.json", "w") as f, draccus.config_type("json"):
        draccus.dump(calibration, f, indent=4)
    print(f"wrote {out}: {len(RUNS)} episodes, {sum(p.stat().st_size for p in out.rglob('*') if p.is_file())} bytes")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "tests/data/lerobot_so101"))
