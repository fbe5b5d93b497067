"""Where an identified servo model ends a hold and where the real arm does, per joint: which term is missing.

For every command hold of >= 1 s on the validation runs (``--split train``: the training runs, where a model term is
looked for without reading validation) (:func:`so101_servo_holds.hold_ends`), the run's identified
model (``physics.json``) is replayed open loop over the whole run, and at each hold's end (averaged over its last
0.1 s) per joint:

- the offset from the command, real ``e_r = q_r - c`` and model ``e_m = q_m - c`` [rad], signed along the direction
  the command came from (``dir``: negative = short of the target) and in encoder ticks (2 pi / 4096 rad);
- the static balance at the real end: the model's servo torque there at rest, ``tau_s = servo_torque(c, q_r, 0)``
  (its kp, dead band b, startup torque u0, effort U), against the model's gravity torque ``G(q_r)`` (Pinocchio, the
  run's identified link masses and centres of mass; ``G_file``: the robot file's links, for comparison) and the
  model's friction at rest, the dry friction f and the stiction s. The model can rest at the real end only where
  ``|tau_s - G| <= f + s``; the share of holds
  where it cannot, and the mean residual ``r = tau_s - G`` [N*m];
- a least-squares split of ``r`` into ``a G + d dir + c0`` over the holds: what the missing torque follows (a: the
  stiffness/gravity side, d: a direction-dependent term such as stiction or a dead band wider than the model's,
  c0: a constant such as an encoder offset between the goal and the present position).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/real/so101_hold_diagnosis.py DATA/dataset.npz --run RUN
"""

import numpy as np
from so101_servo_holds import SETTLE_S, hold_ends

TICK = 2.0 * np.pi / 4096.0
"""One encoder tick of the STS3215 [rad]."""


def main(path: str, run: str, split: str = "validation") -> None:
    import dataclasses

    import pinocchio as pin

    from wresdyn.data.loading import load_data
    from wresdyn.evaluation.evaluate_run import load_run_model, run_friction_kappa
    from wresdyn.robot.pinocchio_model import build_pinocchio
    from wresdyn.robot.servo import servo_torque
    from wresdyn.sim.rollout import replay_trajectories

    ds, robot = load_data(path, None, None)
    rate, settle = ds.rate_hz, int(SETTLE_S * ds.rate_hz)
    keep = np.flatnonzero(ds.fit_weights() > 0)
    val = list(ds.split(split))
    policy, meta, physics, solver, substeps = load_run_model(run, robot, rate)
    model_q = replay_trajectories(robot, val, rate, policy, kind=meta["kind"], solver=solver, substeps=substeps,
                                  physics=physics, friction_kappa=run_friction_kappa(run))["residual"].q
    # the gravity the model holds against is its own: the fit moves link masses and centres of mass
    fitted = dataclasses.replace(robot, body_mass=physics.body_mass, body_com=physics.body_com,
                                 body_inertia=physics.body_inertia)
    pin_models = [build_pinocchio(fitted), build_pinocchio(robot)]
    pin_datas = [m.createData() for m in pin_models]
    rows = []  # per hold: e_r, e_m, dir, G, tau_s, G_file (each (n,))
    for tr, qm in zip(val, model_q):
        c = tr.q_cmd
        for t, u in hold_ends(c, rate):
            q_r = tr.q[u - settle:u].mean(0)
            goal = c[u - 1]
            g, g_file = (pin.computeGeneralizedGravity(m, dt, q_r.astype(np.float64))[:robot.n_dof]
                         for m, dt in zip(pin_models, pin_datas))
            tau = servo_torque(goal, q_r, 0.0, physics.kp, physics.kd, physics.deadband, physics.effort,
                               physics.noload_speed, startup_torque=physics.startup_torque)
            rows.append((q_r - goal, qm[u - settle:u].mean(0) - goal, np.sign(c[t] - c[max(t - settle, 0)]), g, tau,
                         g_file))
    e_r, e_m, d, g, tau, g_file = (np.array(x) for x in zip(*rows))
    r = tau - g
    print(f"{path}, run {run}: {len(e_r)} holds of >= 1 s on {len(val)} {split} runs; offsets [rad] at each "
          f"hold's end (mean over its last {SETTLE_S:g} s), e = q - c, 'along' = e * dir (< 0: short of the target)")
    rest_bound = physics.friction + physics.stiction
    print(f"{'joint':14s} {'kp':>6s} {'b':>7s} {'u0':>5s} {'U':>5s} {'f':>6s} {'s':>6s} | {'|e_r|':>7s} {'ticks':>6s} {'along_r':>8s} "
          f"{'|e_m|':>7s} {'along_m':>8s} {'|e_r-e_m|':>9s} | {'G_file':>6s} {'G':>6s} {'tau_s':>6s} {'r':>7s} {'|r|>fs':>6s} "
          f"{'kp|e_r|/U':>9s} | {'a':>7s} {'d':>7s} {'c0':>7s} {'rms r':>6s} {'->':>6s}")
    for j in keep:
        ones = np.ones(len(r))
        a_mat = np.stack([g[:, j], d[:, j], ones], 1)
        coef = np.linalg.lstsq(a_mat, r[:, j], rcond=None)[0]
        rest = r[:, j] - a_mat @ coef
        print(f"{robot.joint_names[j]:14s} {physics.kp[j]:6.2f} {physics.deadband[j]:7.4f} "
              f"{physics.startup_torque[j]:5.3f} {physics.effort[j]:5.2f} "
              f"{physics.friction[j]:6.3f} {physics.stiction[j]:6.3f} | {np.abs(e_r[:, j]).mean():7.4f} {np.abs(e_r[:, j]).mean() / TICK:6.1f} "
              f"{(e_r[:, j] * d[:, j]).mean():8.4f} {np.abs(e_m[:, j]).mean():7.4f} {(e_m[:, j] * d[:, j]).mean():8.4f} "
              f"{np.abs(e_r[:, j] - e_m[:, j]).mean():9.4f} | {g_file[:, j].mean():6.3f} {g[:, j].mean():6.3f} {tau[:, j].mean():6.3f} "
              f"{r[:, j].mean():7.3f} {(np.abs(r[:, j]) > rest_bound[j]).mean():6.2f} "
              f"{(physics.kp[j] * np.abs(e_r[:, j]) / physics.effort[j]).mean():9.2f} | {coef[0]:7.3f} {coef[1]:7.3f} "
              f"{coef[2]:7.3f} {np.sqrt((r[:, j] ** 2).mean()):6.3f} {np.sqrt((rest ** 2).mean()):6.3f}")
    print("columns: kp [N*m/rad], b dead band [rad], u0 startup torque [N*m], U effort [N*m], f dry friction, "
          "s stiction [N*m] (the run's); G_file gravity with the file's links, G with the run's, tau_s the model's servo torque at the real end at rest, "
          "r = tau_s - G [N*m] (mean); |r|>fs: share of holds the model cannot rest at (|r| > f + s); kp|e_r|/U: the P term at the real offset over the effort limit; r ~ a G + d dir + "
          "c0 [-, N*m, N*m], rms of r before and after the split")
    print("by direction and gravity side, per joint: mean r [N*m] (holds)")
    for j in keep:
        cells = []
        for dv in (-1.0, 1.0):
            for gs in (-1.0, 1.0):
                m = (d[:, j] == dv) & (np.sign(g[:, j]) == gs)
                cells.append(f"dir {dv:+.0f} G {'+' if gs > 0 else '-'}: " + (f"{r[m, j].mean():+.3f} ({m.sum()})"
                                                                             if m.any() else "   -   (0)"))
        print(f"  {robot.joint_names[j]:14s} " + "   ".join(cells))


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", help="dataset of real runs (.npz)")
    parser.add_argument("--run", required=True, help="identify run folder (its physics.json)")
    parser.add_argument("--split", default="validation", choices=("train", "validation"),
                        help="whose holds (held-out and OOD are never read)")
    args = parser.parse_args()
    main(args.dataset, args.run, args.split)
