"""Why floor skills fail on the "real" robot: redeploy a finished ``wresdyn deploy --floor`` run's policies on its
held-out motions and print, per policy and family, the successes and each failure's cause and step.

    python benchmarks/skills/floor_failures.py RUN [--data DATASET]

RUN is the deploy folder (its ``results.json`` gives the sizes, seed and task; ``skills/*/policy.pt`` the policies).
The motions are drawn again from the run's seed, and the real robot is the dataset's mismatch with the benchmark's
deployment seed, so the rollouts are the benchmark's own.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run")
    p.add_argument("--data", default=None, help="the dataset whose mismatch is the real robot (default: shipped)")
    args = p.parse_args()

    import torch

    from floor_run import held_out
    from wresdyn.skills.evaluate import deploy, metrics
    from wresdyn.skills.plants import RealPlant
    from wresdyn.skills.skill_ppo import load_skill

    torch.set_num_threads(2)
    run = Path(args.run)
    res, task, _, motions, real = held_out(run, args.data)
    cfg = res["config"]
    print(f"{run}: {len(motions)} held-out motions of {cfg['duration']:g} s, "
          f"{int(cfg['duration'] * real.rate_hz / task.decimation)} policy steps each")
    for name in ("reference", *res["policies"]):
        policy = None if name == "reference" else load_skill(run / "skills" / name)
        plant = RealPlant(real, len(motions), task.decimation, seed=cfg["seed"] + 100,
                          imu_noise=(task.gyro_noise, task.gravity_noise))
        per = metrics(deploy(policy, plant, motions, task))["motions"]
        fam = defaultdict(list)
        for m, r in zip(motions, per):
            fam[m.family].append(r)
        rows = []
        for f, rs in fam.items():
            fails = [f"{r['cause']}@{r['failed_at']}" for r in rs if not r["success"]]
            rows.append(f"{f} {sum(r['success'] for r in rs)}/{len(rs)}"
                        + (f" [{', '.join(fails)}]" if fails else "")
                        + f" max base error {max(r['base_error_max'] for r in rs):.2f} m")
        print(f"{name:15s} " + "; ".join(rows))
        expected = res["real"]["heldout"][name]["mean"]["success"]
        got = float(np.mean([r["success"] for r in per]))
        if abs(got - expected) > 1e-9:
            print(f"  (success {got:.2f} here against {expected:.2f} in results.json)")


if __name__ == "__main__":
    main()
