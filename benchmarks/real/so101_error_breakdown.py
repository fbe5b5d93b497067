"""Where an identified model's whole-run error on the real SO-101 splits lies: per run and joint, moving or at rest.

The run's model (``physics.json``, its friction law) is replayed open loop over every validation, held-out and OOD
run from its first recorded state, as ``wresdyn identify --eval`` does. Per run: mean |q_model - q_real| [rad] over
the fitted joints and per joint, and the share of the run's summed error on samples where the real joint moves
(|qd| > 0.1 rad/s, the ``moving`` column of ``identification.md``) against where it rests; per split the same pooled
over its runs (the split's mean |dq| of ``eval/metrics.json``). ``--set FIELD=VALUE`` (repeatable) replays the model
with a per-joint field of ``physics.json`` set to VALUE on every joint instead, no refit: a probe of what a term does
where the error is, not a model to choose (that is validation's).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/real/so101_error_breakdown.py DATA/dataset.npz --run RUN [--set effort=1.91]
"""

import numpy as np

MOVING = 0.1
"""Speed above which a real joint counts as moving [rad/s]."""


def main(path: str, run: str, overrides: dict[str, float]) -> None:
    import torch

    from wresdyn.data.loading import load_data
    from wresdyn.evaluation.evaluate_run import load_run_model, run_friction_kappa
    from wresdyn.sim.rollout import replay_trajectories

    torch.set_num_threads(1)
    ds, robot = load_data(path, None, None)
    rate = ds.rate_hz
    keep = np.flatnonzero(ds.fit_weights() > 0)
    policy, meta, physics, solver, substeps = load_run_model(run, robot, rate)
    for field, value in overrides.items():
        getattr(physics, field)[:] = value
    names = [robot.joint_names[j] for j in keep]
    print(f"{path}, run {run} (friction_kappa {run_friction_kappa(run)}"
          f"{''.join(f', {k} = {v:g}' for k, v in overrides.items())}): mean |q_model - q_real| [rad] per run over "
          f"the fitted joints and per joint; 'moving': share of the summed error where the real joint moves "
          f"(|qd| > {MOVING:g} rad/s), 'samples': share of samples moving")
    print(f"{'split':10s} {'run':28s} {'s':>6s} {'mean':>7s} " + " ".join(f"{n[:12]:>12s}" for n in names)
          + f" {'moving':>7s} {'samples':>8s}")
    for split in ("validation", "heldout", "ood"):
        trs = list(ds.split(split))
        qs = replay_trajectories(robot, trs, rate, policy, kind=meta["kind"], solver=solver, substeps=substeps,
                                 physics=physics, friction_kappa=run_friction_kappa(run))["residual"].q
        pooled_e, pooled_m = [], []
        for tr, qm in zip(trs, qs):
            e = np.abs(qm - tr.q)[:, keep]
            m = np.abs(tr.qd)[:, keep] > MOVING
            pooled_e.append(e)
            pooled_m.append(m)
            print(f"{split:10s} {tr.name:28s} {len(e) / rate:6.1f} {e.mean():7.4f} "
                  + " ".join(f"{x:12.4f}" for x in e.mean(0)) + f" {e[m].sum() / e.sum():7.2f} {m.mean():8.2f}")
        e, m = np.concatenate(pooled_e), np.concatenate(pooled_m)
        print(f"{split:10s} {'(all)':28s} {len(e) / rate:6.1f} {e.mean():7.4f} "
              + " ".join(f"{x:12.4f}" for x in e.mean(0)) + f" {e[m].sum() / e.sum():7.2f} {m.mean():8.2f}",
              flush=True)


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", help="dataset of real runs (.npz)")
    parser.add_argument("--run", required=True, help="identify run folder (its physics.json)")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="replay with a per-joint physics field set to VALUE on every joint (no refit)")
    args = parser.parse_args()
    main(args.dataset, args.run, {k: float(v) for k, v in (s.split("=", 1) for s in args.set)})
