"""Experiment: would training data that saturates EVERY drive close an arm's OOD gap? ``collect
--probe-saturation`` steps the foot IK chains only (it refuses a joint-space robot such as the UR5), so this adds
joint-space probe trajectories to a recorded dataset's training split, recorded on the same simulated real robot
(same mismatch), and writes a new dataset; validation, held-out and OOD stay the very same recordings.

A probe trajectory starts at the first commanded pose of a training trajectory (a pose the excitation visits) and
steps each joint in turn, in a random order, by δ and back (a 10 ms minimum-jerk rise, as
:class:`wresdyn.data.probe.SaturationProbe`), the PD demand kp·δ drawn in 0.6-0.9 of the file's effort limit and δ
kept 0.05 rad inside the joint's limits, every other joint holding.

    python benchmarks/fidelity/robot_zoo/joint_probe.py DATASET OUT_DATASET [--probes 6]
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

RISE = 0.01
"""Step rise [s] (the library probe's)."""
FRACTION = (0.6, 0.9)
"""PD demand of a step as a fraction of the file's effort limit (the library probe's)."""
MARGIN = 0.05
"""Steps stay this far inside the joint limits [rad]."""


def probe_command(robot, home, duration: float, rate_hz: float, rng, pairs: int = 4) -> np.ndarray:
    """(T, n) commands: from ``home``, each joint in turn (random order) steps out and back ``pairs`` times."""
    n, t_len = robot.n_dof, int(round(duration * rate_hz))
    q_cmd = np.tile(home, (t_len, 1))
    moves = [j for _ in range(pairs) for j in rng.permutation(n)]
    hold = (t_len - int(0.1 * rate_hz)) // (2 * len(moves))
    rise = max(1, int(round(RISE * rate_hz)))
    s = np.linspace(0, 1, rise + 1)[1:]
    shape = 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5  # minimum jerk
    lo, hi = np.asarray(robot.lower, float) + MARGIN, np.asarray(robot.upper, float) - MARGIN
    k = int(0.1 * rate_hz)
    for j in moves:
        delta = rng.uniform(*FRACTION) * robot.effort[j] / robot.kp[j]
        side = rng.choice([-1, 1]) if home[j] + delta <= hi[j] and home[j] - delta >= lo[j] else (
            1 if hi[j] - home[j] > home[j] - lo[j] else -1)
        goal = np.clip(home[j] + side * delta, lo[j], hi[j])
        for a, b in ((home[j], goal), (goal, home[j])):
            q_cmd[k:k + rise, j] = a + (b - a) * shape
            q_cmd[k + rise:k + hold, j] = b
            k += hold
    return q_cmd


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data")
    p.add_argument("out")
    p.add_argument("--probes", type=int, default=6)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    from wresdyn.data.dataset import Trajectory, derive_qdd
    from wresdyn.data.loading import load_data
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot

    ds, robot = load_data(args.data)
    real = RealRobot(robot, Mismatch.from_dict(ds.mismatch), ds.rate_hz)
    train = ds.split("train")
    duration = (len(train[0].q) - 1) / ds.rate_hz
    rng = np.random.default_rng(args.seed)
    new = []
    for i in range(args.probes):
        q_cmd = probe_command(robot, train[i % len(train)].q_cmd[0], duration + 1 / ds.rate_hz, ds.rate_hz, rng)
        q_cmd = q_cmd.astype(np.float32).astype(np.float64)
        q, qd, tau = real.record(q_cmd, rng)
        t = np.arange(len(q_cmd)) / ds.rate_hz
        new.append(Trajectory(f"train_jprobe_{i:03d}", "train", t, q.astype(np.float32), qd.astype(np.float32),
                              derive_qdd(qd.astype(np.float32), ds.rate_hz), q_cmd, tau.astype(np.float32)))
        sat = (np.abs(tau) >= 0.99 * real.physics().effort).mean(0)
        print(f"{new[-1].name}: saturated " + " ".join(f"{x:.3f}" for x in sat), flush=True)
    meta = {**ds.meta, "joint_probe": {"trajectories": args.probes, "seed": args.seed, "rise_s": RISE,
                                       "effort_fraction": FRACTION}}
    dataclasses.replace(ds, trajectories=ds.trajectories + new, meta=meta).save(args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
