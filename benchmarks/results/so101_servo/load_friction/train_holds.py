"""Where a servo model ends the TRAINING runs' command holds (>= 1 s) against the arm, binned by the direction the
command came from and by the gravity torque the joint holds (the run's own links): the diagnosis the load friction was
built from, on training data only (validation, held-out and OOD are not read).

Per joint, hold ends ``e = q - c`` (mean over the hold's last 0.1 s) of the arm (``real``) and of the model replayed
open loop over the whole run (``model``), their difference, and how far each moves between 0.3 s into the hold and its
end (``drift``: a position-loop integral would pull the arm toward the command while it holds).

    OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/results/so101_servo/load_friction/train_holds.py DATA RUN
"""

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "real"))
from so101_servo_holds import SETTLE_S, hold_ends  # noqa: E402


def main(path: str, run: str) -> None:
    import pinocchio as pin

    from wresdyn.data.loading import load_data
    from wresdyn.evaluation.evaluate_run import load_run_model, run_friction_kappa
    from wresdyn.robot.pinocchio_model import build_pinocchio
    from wresdyn.sim.rollout import replay_trajectories

    ds, robot = load_data(path, None, None)
    rate, s = ds.rate_hz, int(SETTLE_S * ds.rate_hz)
    trs = list(ds.split("train"))
    policy, meta, physics, solver, substeps = load_run_model(run, robot, rate)
    qs = replay_trajectories(robot, trs, rate, policy, kind=meta["kind"], solver=solver, substeps=substeps,
                             physics=physics, friction_kappa=run_friction_kappa(run))["residual"].q
    fitted = dataclasses.replace(robot, body_mass=physics.body_mass, body_com=physics.body_com,
                                 body_inertia=physics.body_inertia)
    pm = build_pinocchio(fitted)
    pdata = pm.createData()
    rows = []  # per hold: e_real, e_model, drift_real, drift_model, G, dir
    for tr, qm in zip(trs, qs):
        c = tr.q_cmd
        for t, u in hold_ends(c, rate):
            a = min(t + int(0.3 * rate), u - s)
            er, em = tr.q[u - s:u].mean(0) - c[u - 1], qm[u - s:u].mean(0) - c[u - 1]
            rows.append((er, em, er - (tr.q[a:a + s].mean(0) - c[u - 1]), em - (qm[a:a + s].mean(0) - c[u - 1]),
                         pin.computeGeneralizedGravity(pm, pdata, tr.q[u - 1].astype(np.float64))[:robot.n_dof],
                         np.sign(c[t] - c[max(t - s, 0)])))
    er, em, dr, dm, g, d = (np.array(x) for x in zip(*rows))
    err = np.concatenate([np.abs(qm - tr.q) for tr, qm in zip(trs, qs)])
    keep = np.flatnonzero(ds.fit_weights() > 0)
    print(f"{path}, run {run}: {len(er)} holds of >= 1 s on {len(trs)} training runs; whole training runs mean |dq| "
          f"{err[:, keep].mean():.5f} rad. Hold ends e = q - c [rad]; G the model's gravity torque at the arm's end "
          f"[N*m] (> 0: the joint holds against a pull toward -q); dir the sign of the command's last change; bins "
          f"of |G| in thirds per direction")
    for j in keep:
        diff = er[:, j] - em[:, j]
        rms = np.sqrt((diff ** 2).mean())
        print(f"{robot.joint_names[j]}: |e_real - e_model| {np.abs(diff).mean():.4f} (rms {rms:.4f}); "
              f"drift over the hold real {np.abs(dr[:, j]).mean():.4f}, model {np.abs(dm[:, j]).mean():.4f}; "
              f"kp {physics.kp[j]:.2f}, dead band {physics.deadband[j]:.4f}, friction {physics.friction[j]:.3f}, "
              f"stiction {physics.stiction[j]:.3f}, load friction {physics.load_friction[j]:.3f}")
        for dv in (-1.0, 1.0):
            m = np.flatnonzero(d[:, j] == dv)
            for part in np.array_split(m[np.argsort(np.abs(g[m, j]))], 3):
                if len(part):
                    print(f"   dir {dv:+.0f}  |G| {np.abs(g[part, j]).mean():.3f}  n {len(part):2d}  real e "
                          f"{er[part, j].mean():+.4f}  model e {em[part, j].mean():+.4f}  "
                          f"diff {diff[part].mean():+.4f}  "
                          f"|diff| {np.abs(diff[part]).mean():.4f}")


if __name__ == "__main__":
    main(*sys.argv[1:3])
