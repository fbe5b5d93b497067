"""The servo drive's synthetic check: a "real" SO-101 whose drives are servos of known parameters, recorded
in MuJoCo C (:class:`wresdyn.data.real_robot.RealRobot`, affine actuators driven by the servo law each physics step),
then (1) replayed with its true parameters in SolverReplay (how closely the two simulators agree) and (2) identified
by ``wresdyn identify``'s learner from a start off by 30-60 % on the servo fields, which must come back within 10 %
where the excitation exercises them.

The commands are ``wresdyn collect``'s joint-space families in turn (multisines, minimum-jerk steps with pauses,
chirps: :data:`FAMILIES`), sent as a teleoperated arm gets them: updated at ``COMMAND_HZ`` and held in between, so
each update is a step the servo's goal profile smooths (LeRobot sends goals at 30 Hz). Multisines alone left the
dead band and the no-load speed 20-37 % off on three joints (kp trades with both while the arm tracks smoothly);
the steps' pauses show the band, their fast moves the torque-speed line.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/real/so101_servo_synthetic.py OUT_DIR [ADAM_ITERATIONS [LBFGS_STEPS]]

Raw output: ``benchmarks/results/so101_servo/``. Which fields the excitation exercises is measured, not assumed: the
training loss's relative change when a field moves by 10 % on one joint from the truth (``sensitivity``).
"""

import sys
import time
from pathlib import Path

import numpy as np

from wresdyn.data import excitation as ex
from wresdyn.data.dataset import Dataset, Trajectory, derive_qdd
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.identify.sysid import SysIdConfig, identify
from wresdyn.robot.description import load_robot
from wresdyn.robot.servo import STS3215
from wresdyn.sim import replay_trajectories

RATE_HZ = 250.0
"""Recording and replay rate [Hz]; the MuJoCo robot steps at the same rate (its servo law, like the replay's, treats its velocity term implicitly)."""
TRUTH = {"kp": 6.0, "kd": 0.01, "deadband": 0.004, "noload_speed": 5.0, "goal_accel": 8.0}
"""The "real" servos (every joint), near the STS3215's priors (:data:`wresdyn.robot.servo.STS3215`)."""
START = {"kp": 1.4, "deadband": 0.5, "noload_speed": 1.3, "goal_accel": 1.6}
"""Factors on the truth the identification starts from."""
FAMILIES = ("multisine", "steps", "chirp")
"""Excitation families, one per trajectory in turn."""
COMMAND_HZ = 31.25
"""Command update rate [Hz] (every 8th sample)."""
FIT = ("kp", "deadband", "noload_speed", "goal_accel")
SO101 = Path(__file__).resolve().parents[2] / "scenes" / "so101" / "so101.xml"


def gains(values: dict) -> dict:
    return {"joint": [{"match": "*", "drive": "servo", "effort": STS3215.effort, **values}]}


def record(robot, counts: dict, duration: float, seed: int) -> Dataset:
    """Commands of :data:`FAMILIES` held at :data:`COMMAND_HZ`, executed by the MuJoCo servo robot (noise-free, float32 as
    stored by ``collect``)."""
    real = RealRobot(robot, Mismatch(), RATE_HZ)
    plan = ex.plan(robot)
    hold = int(round(RATE_HZ / COMMAND_HZ))
    trajs = []
    for split, count in counts.items():
        for i in range(count):
            rng = np.random.default_rng([seed, len(trajs)])
            q_cmd = plan.generate(FAMILIES[i % len(FAMILIES)], duration, RATE_HZ, rng).q_cmd
            q_cmd = q_cmd[np.arange(len(q_cmd)) // hold * hold].astype(np.float32).astype(np.float64)
            q, qd, _ = real.record(q_cmd)
            q, qd = q.astype(np.float32).astype(np.float64), qd.astype(np.float32).astype(np.float64)
            trajs.append(Trajectory(f"{split}_{i:03d}", split, np.arange(len(q)) / RATE_HZ, q, qd,
                                    derive_qdd(qd, RATE_HZ), q_cmd))
    return Dataset(list(robot.joint_names), RATE_HZ, trajs, str(SO101), robot.source_sha256, Mismatch().to_dict(),
                   seed, {"generator": "benchmarks/real/so101_servo_synthetic.py"}, robot.gains_record())


def main(out: Path, iterations: int, refine: int) -> None:
    out.mkdir(parents=True, exist_ok=True)
    log = open(out / "log.txt", "w")

    def say(*a):
        line = " ".join(str(x) for x in a)
        print(line, flush=True)
        log.write(line + "\n")
        log.flush()

    true_robot = load_robot(SO101, gains=gains(TRUTH))
    t0 = time.perf_counter()
    ds = record(true_robot, {"train": 8, "validation": 2, "heldout": 2}, duration=4.0, seed=3)
    say(f"recorded {len(ds.trajectories)} runs of 4 s at {RATE_HZ:.0f} Hz, commands at {COMMAND_HZ} Hz, in "
        f"{time.perf_counter() - t0:.0f} s")
    truth = RealRobot(true_robot, Mismatch(), RATE_HZ).physics()

    # (1) parity: the true parameters replayed open loop from each recording's first state
    t0 = time.perf_counter()
    rep = replay_trajectories(true_robot, ds.trajectories, RATE_HZ, solver="replay", physics=truth)["residual"]
    err = [np.abs(q - t.q) for q, t in zip(rep.q, ds.trajectories)]
    moved = [np.abs(t.q - t.q[0]).max() for t in ds.trajectories]
    say(f"parity: SolverReplay with the true parameters against the MuJoCo recording ({time.perf_counter() - t0:.0f} s):"
        f" mean |dq| {np.mean([e.mean() for e in err]):.2e} rad, max {max(e.max() for e in err):.2e} rad "
        f"(joints move up to {max(moved):.2f} rad)")

    # which fields the excitation exercises: each moved by 10 % on one joint, the training runs' replay error
    train = ds.split("train")
    base = replay_trajectories(true_robot, train, RATE_HZ, solver="replay", physics=truth)["residual"].q
    say("sensitivity: mean |dq| [mrad] of the training runs' replay when one field of one joint is 10 % off the truth")
    say(f"{'joint':<14}" + "".join(f"{f:>14}" for f in FIT))
    for j, name in enumerate(true_robot.joint_names):
        row = f"{name:<14}"
        for f in FIT:
            p = truth.copy()
            getattr(p, f)[j] *= 1.1
            q = replay_trajectories(true_robot, train, RATE_HZ, solver="replay", physics=p)["residual"].q
            row += f"{1e3 * np.mean([np.abs(a - b).mean() for a, b in zip(q, base)]):14.4f}"
        say(row)

    # (2) identification from a start off on every servo field
    start_values = {**TRUTH, **{k: TRUTH[k] * f for k, f in START.items()}}
    start_robot = load_robot(SO101, gains=gains(start_values))
    cfg = SysIdConfig(fit=FIT, iterations=iterations, windows=16, horizon_curriculum=(32, 64, 128), effort_grid=(),
                      select_every=max(iterations // 10, 1), lr=0.03, lr_final=0.003, share_effort_ratio=False,
                      refine=refine, refine_windows=32)
    say(f"identify {', '.join(FIT)} from {START} x truth, {iterations} Adam iterations (16 windows), {refine} L-BFGS "
        "steps (32 windows)")
    t0 = time.perf_counter()
    params, curve = identify(start_robot, ds, cfg, log=say)
    say(f"identified in {time.perf_counter() - t0:.0f} s")
    params.save(out / "physics.json")
    truth.save(out / "truth.json")
    say(f"{'joint':<14}" + "".join(f"{f:>26}" for f in FIT))
    worst = {}
    for j, name in enumerate(true_robot.joint_names):
        row = f"{name:<14}"
        for f in FIT:
            t, v = getattr(truth, f)[j], getattr(params, f)[j]
            rel = (v - t) / t
            worst[f] = max(worst.get(f, 0.0), abs(rel))
            row += f"  {t:8.4f} -> {v:8.4f} ({rel:+6.1%})"
        say(row)
    say("worst relative error per field: " + ", ".join(f"{f} {w:.1%}" for f, w in worst.items()))
    # where a hold ends: the drive lets go at |e| = b, friction holds the joint until kp (|e| - b) exceeds it
    offset = [p.deadband + p.friction / p.kp for p in (truth, params)]
    say("hold offset b + friction / kp [mrad], truth -> identified: " + ", ".join(
        f"{name} {1e3 * t:.2f} -> {1e3 * v:.2f} ({(v - t) / t:+.1%})"
        for name, t, v in zip(true_robot.joint_names, *offset)))


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 400, int(sys.argv[3]) if len(sys.argv) > 3 else 10)
