"""Published servo models replayed on the SO-101 real benchmark's validation, held-out and OOD runs,
scored as ``wresdyn eval`` scores the project's models: mean |Δq| [rad] over the five arm joints of whole
runs, open loop from the first recorded state, and the improvement over the same PD-only Newton replay
(:func:`wresdyn.evaluation.open_loop.evaluate_split`). The models and their sources:
:mod:`wresdyn.evaluation.servo_baselines`.

    python benchmarks/real/so101_baselines.py OUT/data/dataset.npz   # the dataset of benchmarks/real/so101_real.sh
"""

import argparse
import dataclasses
import json
import time
from pathlib import Path

from wresdyn.data.dataset import load_dataset
from wresdyn.evaluation.open_loop import evaluate_split
from wresdyn.evaluation.servo_baselines import BAM_STS3215_7V4, BamDrive, bam_model, evaluate_baseline, lerobot_model
from wresdyn.robot.description import load_robot

SPLITS = ("validation", "heldout", "ood")


def models(robot_file, rate_hz: float) -> dict:
    """name -> (MuJoCo model, drive factory or None)."""
    bam32 = dataclasses.replace(BAM_STS3215_7V4, kp=32.0)
    return {
        "LeRobot's MuJoCo model (kp 17.8, as it is)": (lerobot_model(robot_file, rate_hz), None),
        "BAM-style drive, STS3215 7.4 V m1, P 16 (LeRobot's)": (
            bam_model(robot_file, rate_hz), lambda q0: BamDrive(BAM_STS3215_7V4, q0)),
        "BAM-style drive, STS3215 7.4 V m1, P 32 (BAM's bench)": (
            bam_model(robot_file, rate_hz, bam32), lambda q0: BamDrive(bam32, q0)),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset")
    p.add_argument("--robot", default="scenes/so101/so101.xml")
    p.add_argument("--json", default=None, help="also write the figures to this JSON file")
    args = p.parse_args()
    robot = load_robot(args.robot)
    ds = load_dataset(args.dataset, robot)
    weights = ds.fit_weights()
    print(f"{args.dataset}: {len(ds.trajectories)} runs at {ds.rate_hz:g} Hz, excluded from the metrics: "
          f"{', '.join(ds.excluded_joints) or 'none'}", flush=True)
    pd_only = {}
    for split in SPLITS:
        summary, _ = evaluate_split(robot, ds.split(split), ds.rate_hz, weights=weights)
        pd_only[split] = summary["pd_only"]
        print(f"PD only (Newton, the robot file) {split:10s} {summary['n_trajectories']} runs  mean |dq| "
              f"{pd_only[split]['mean_abs_dq']:.4f} ± {pd_only[split]['std_abs_dq']:.4f} rad", flush=True)
    results = {}
    for name, (m, drive) in models(args.robot, ds.rate_hz).items():
        results[name] = {}
        for split in SPLITS:
            t0 = time.perf_counter()
            s = evaluate_baseline(m, ds.split(split), pd_only[split], drive, weights)
            results[name][split] = s
            r = s["model"]
            print(f"{name:52s} {split:10s} mean |dq| {r['mean_abs_dq']:.4f} ± {r['std_abs_dq']:.4f} rad "
                  f"({s['improvement']:.2f}x over PD only)  diverged {r['diverged']}  "
                  f"{time.perf_counter() - t0:.1f} s", flush=True)
    print("\n| model | " + " | ".join(SPLITS) + " |\n|---|" + "---|" * len(SPLITS))
    print("| PD only (Newton, the robot file) | " + " | ".join(f"{pd_only[s]['mean_abs_dq']:.4f}" for s in SPLITS)
          + " |")
    for name, per in results.items():
        print(f"| {name} | " + " | ".join(f"{per[s]['model']['mean_abs_dq']:.4f} ({per[s]['improvement']:.2f}×)"
                                          for s in SPLITS) + " |")
    if args.json:
        Path(args.json).write_text(json.dumps({"dataset": args.dataset, "pd_only": pd_only, "models": results},
                                              indent=2))


if __name__ == "__main__":
    main()
