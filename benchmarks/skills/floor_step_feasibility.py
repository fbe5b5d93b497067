"""Can the floor references be played at all: the zero-moment point against the planted soles' support polygon, and
the joint torques each motion needs (Pinocchio, :mod:`wresdyn.skills.feasibility`) against the robot file's
effort limits (the nominal masses) and against the "real" robot's (its masses, limits, friction and damping), over
a finished ``wresdyn deploy --floor`` run's held-out motions.

    python benchmarks/skills/floor_step_feasibility.py RUN [--data DATASET] [--every 2] [--combo N]

Per motion: the zero-moment point's smallest margin inside the support [mm] (negative: outside) and the share of the
samples it is outside, with the samples within 10 ms of a change of the planted soles left out (the reference's base
steps there, see the module); then per family the joints whose torque demand is largest against each robot's limits:
the 99th percentile of |τ| / τ_max over the motion and the share of samples above the limit; and in single support
the stance leg's drives (the median of |τ| / τ_max and the share above 1). ``--combo N`` adds the zero-moment points
of N training motions of the ``combo`` family (drawn from the run's seed). The first stepping motion's margin is
also shown every 0.25 s, with the soles the reference plants then (L, R).
"""

from __future__ import annotations

import argparse
import dataclasses
from collections import defaultdict
from pathlib import Path

import numpy as np


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run")
    p.add_argument("--data", default=None, help="the dataset whose mismatch is the real robot (default: shipped)")
    p.add_argument("--every", type=int, default=2, help="analyse every this many samples")
    p.add_argument("--combo", type=int, default=0, help="also this many combo training motions (ZMP only)")
    args = p.parse_args()

    import torch

    from floor_run import held_out
    from wresdyn.robot.description import load_robot
    from wresdyn.skills.feasibility import floor_feasibility
    from wresdyn.skills.motions import make_motions

    torch.set_num_threads(1)
    res, task, floating, motions, real = held_out(Path(args.run), args.data)
    ph = real.physics()
    robots = {"nominal": (floating, floating.effort, None, None),
              "real": (dataclasses.replace(floating, body_mass=ph.body_mass, body_com=ph.body_com,
                                           body_inertia=ph.body_inertia), ph.effort, ph.friction, ph.damping)}
    names = list(floating.joint_names)
    print(f"{args.run}: {len(motions)} held-out motions at {real.rate_hz:g} Hz, every {args.every} samples; "
          f"mass nominal {floating.body_mass.sum():.1f} kg, real {ph.body_mass.sum():.1f} kg")
    legs = ("hip_roll", "hip_pitch", "knee", "ankle_pitch", "ankle_roll")
    leg = np.array([[names.index(f"{side}_{j}") for j in legs] for side in ("left", "right")])
    ratio = {k: defaultdict(list) for k in robots}
    stance = {k: defaultdict(list) for k in robots}
    if args.combo:
        stand = load_robot(floating.source, gains=floating.gains)
        combos = make_motions(stand, {"train": args.combo}, res["config"]["duration"], real.rate_hz,
                              res["config"]["seed"], floating=floating, families=(), extra=("combo",),
                              workers=0)["train"]
        for m in combos:
            f = floor_feasibility(floating, m, real.rate_hz, every=args.every, skip=0.01)
            print(f"{m.name:24s} ZMP margin min {1e3 * f.margin.min():+6.0f} mm, outside the support on "
                  f"{100 * (f.margin < 0).mean():4.1f} % of the samples; {' '.join(m.params['plan'])}, time scale "
                  f"{m.params['time_scale']:.2f}", flush=True)
    done = []
    for m in motions:
        line = []
        for key, (rob, effort, fr, dmp) in robots.items():
            f = floor_feasibility(rob, m, real.rate_hz, effort, fr, dmp, every=args.every, skip=0.01)
            r = np.abs(f.tau) / effort
            ratio[key][m.family].append(r)
            one = f.planted.sum(-1) == 1
            stance[key][m.family].append(r[one][np.arange(one.sum())[:, None], leg[1 - f.planted[one, 0]]])
            if key == "nominal":
                line.append(f"ZMP margin min {1e3 * f.margin.min():+6.0f} mm, outside the support on "
                            f"{100 * (f.margin < 0).mean():4.1f} % of the samples")
            if key == "nominal" and m.family == "step" and not any(x.family == "step" for x in done):
                t = f.index / real.rate_hz
                for t0 in np.arange(0.0, t[-1], 0.25):
                    w = (t >= t0) & (t < t0 + 0.25)
                    pl = "".join("LR"[i] if f.planted[w][0, i] else "-" for i in range(2))
                    line.append(f"  t {t0:4.2f}-{t0 + 0.25:4.2f} s, planted {pl}: margin min "
                                f"{1e3 * f.margin[w].min():+5.0f} mm, base y {m.base[f.index[w][0], 1]:+.3f} m")
        done.append(m)
        base = m.base[:, :3]
        speed = np.linalg.norm(np.gradient(base, 1.0 / real.rate_hz, axis=0), axis=-1).max()
        print(f"{m.name:24s} {line[0]}; base speed peak {speed:.2f} m/s", flush=True)
        for row in line[1:]:
            print(row, flush=True)
    for key in robots:
        print(f"\njoint torques against the {key} robot's limits (its masses, friction and damping), per family:")
        for fam, rs in ratio[key].items():
            r = np.concatenate(rs)
            top = np.argsort(-np.percentile(r, 99, axis=0))[:4]
            print(f"  {fam:13s} " + "; ".join(f"{names[j]} p99 {np.percentile(r[:, j], 99):.2f} (over "
                                              f"{100 * (r[:, j] > 1).mean():.0f} %)" for j in top))
            s = np.concatenate(stance[key][fam])
            if len(s):
                print(f"  {'':13s} single support, the stance leg: " + "; ".join(
                    f"{j} median {np.median(s[:, i]):.2f} (over {100 * (s[:, i] > 1).mean():.0f} %)"
                    for i, j in enumerate(legs)))


if __name__ == "__main__":
    main()
