"""An identified servo model replayed with other dry-friction laws of the replay solver, without refitting.

``SolverReplay``'s default dry friction is MuJoCo's soft ``frictionloss``: below its bound a joint creeps at
``tau / (948 m0)`` (0.007-0.011 rad/s for 0.3 N*m on the SO-101's joints), so a servo model cannot rest under a load
its friction holds. The damper law of rate kappa creeps at ``tau / (kappa H_ii)``, hard Coulomb friction
(kappa = inf) not at all. Per law: mean |q_model - q_real| [rad] over the fitted joints on the whole validation,
held-out and OOD runs (all samples pooled; against the robot file's PD model's figures), and at the ends of the
validation runs' holds (:func:`so101_servo_holds.hold_ends`).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/real/so101_friction_probe.py DATA/dataset.npz --run RUN
"""

import numpy as np
from so101_servo_holds import SETTLE_S, hold_ends

PD_ONLY = {"validation": 0.0210, "heldout": 0.0251, "ood": 0.0219}
"""Whole-run mean |dq| of the robot file's PD model on the SAGE splits [rad]
(benchmarks/results/so101/so101_full.txt)."""
KAPPAS = (None, 1e4, np.inf)
"""Friction laws probed: the soft default, the damper of rate 1e4 /s, hard Coulomb."""


def main(path: str, run: str) -> None:
    import torch

    from wresdyn.data.loading import load_data
    from wresdyn.evaluation.evaluate_run import load_run_model
    from wresdyn.sim.rollout import replay_trajectories

    torch.set_num_threads(1)
    ds, robot = load_data(path, None, None)
    rate, settle = ds.rate_hz, int(SETTLE_S * ds.rate_hz)
    keep = np.flatnonzero(ds.fit_weights() > 0)
    splits = {k: list(ds.split(k)) for k in PD_ONLY}
    policy, meta, physics, solver, substeps = load_run_model(run, robot, rate)
    print(f"{path}, run {run}: mean |q_model - q_real| over joints {keep.tolist()} [rad], whole runs of each split "
          f"(x: the robot file's PD model's {PD_ONLY} over it) and the validation holds' ends")
    for kappa in KAPPAS:
        whole, ends = {}, []
        for split, trs in splits.items():
            qs = replay_trajectories(robot, trs, rate, policy, kind=meta["kind"], solver=solver, substeps=substeps,
                                     physics=physics, friction_kappa=kappa)["residual"].q
            whole[split] = np.concatenate([np.abs(m - tr.q)[:, keep] for m, tr in zip(qs, trs)]).mean()
            if split == "validation":
                ends = [np.abs(m[u - settle:u].mean(0) - tr.q[u - settle:u].mean(0))[keep]
                        for m, tr in zip(qs, trs) for _, u in hold_ends(tr.q_cmd, rate)]
        per = np.mean(ends, 0)
        name = "soft (default)" if kappa is None else f"kappa {kappa:g}"
        print(f"{name:16s} " + "  ".join(f"{k} {v:.4f} ({PD_ONLY[k] / v:.2f}x)" for k, v in whole.items())
              + f"  | {len(ends)} hold ends {per.mean():.4f}  per joint " + " ".join(f"{x:.4f}" for x in per),
              flush=True)


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", help="dataset of real runs (.npz)")
    parser.add_argument("--run", required=True, help="identify run folder (its physics.json)")
    args = parser.parse_args()
    main(args.dataset, args.run)
