"""No refit: the recipe's servo model (``effort/k1e5_reset``) replayed over the TRAINING runs with the stiction's speed
(:data:`wresdyn.robot.servo.STICTION_SPEED`, a constant of the law, 0.05 rad/s) set to another value in the replay's
code generation: whether where moves freeze is a term worth fitting (a probe on training data, not a model to choose).

    OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/results/so101_servo/load_friction/stiction_speed_probe.py DATA V_S
"""

import sys
from pathlib import Path

import numpy as np

import wresdyn.sim.solver_replay.codegen as codegen

RUN = Path(__file__).resolve().parents[1] / "effort" / "k1e5_reset"


def main(path: str, v_s: float) -> None:
    from wresdyn.data.loading import load_data
    from wresdyn.evaluation.evaluate_run import load_run_model, run_friction_kappa
    from wresdyn.sim.rollout import replay_trajectories

    codegen.STICTION_SPEED = v_s  # read when the kernels' source is generated
    ds, robot = load_data(path, None, None)
    trs = list(ds.split("train"))
    policy, meta, physics, solver, substeps = load_run_model(RUN, robot, ds.rate_hz)
    qs = replay_trajectories(robot, trs, ds.rate_hz, policy, kind=meta["kind"], solver=solver, substeps=substeps,
                             physics=physics, friction_kappa=run_friction_kappa(RUN))["residual"].q
    keep = np.flatnonzero(ds.fit_weights() > 0)
    err = np.concatenate([np.abs(qm - tr.q)[:, keep] for tr, qm in zip(trs, qs)])
    print(f"v_s {v_s:g} rad/s: training runs mean |dq| {err.mean():.6f} rad, per fitted joint "
          + " ".join(f"{x:.5f}" for x in err.mean(0)))


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]))
