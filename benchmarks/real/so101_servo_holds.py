"""What the SO-101's servos do where they hold still, and how well they repeat themselves: a diagnostic of the
real-data benchmark (issue 13).

For every hold of the command (unchanged for at least 1 s) in a dataset of real runs, the position error at the end
of the hold, e = q − q_cmd [rad], is regressed per joint on the gravity torque G(q) [N·m] (Pinocchio, the robot
file's links) and on the direction the command last came from (sign of its change, ±1):
e ≈ a·G + b·dir + c, fitted on the training runs and applied to the validation runs.

A PD drive with the file's kp (998 N·m/rad) would hold within a few mrad: a = −1/kp ≈ −0.001 rad/(N·m) and no
direction term. The recorded servos sag under gravity by far more (−1/a is the effective stiffness) and stop short
of the target in the direction they came from (b < 0: a dead band, friction against a soft position loop). That is
why `wresdyn identify --gain-grid` searches kp below the file's value.

Second, where a run's command repeats, the arm's position is compared with where it was the first time: if it comes
back to within a few mrad while it misses the command by tens, the error left is deterministic, a function of the
command's history that a model could learn. Held-out runs are not read.

    .venv/bin/python benchmarks/real/so101_servo_holds.py OUT/data/dataset.npz   # the dataset of benchmarks/real/so101_real.sh

Third, with ``--run RUN_DIR`` (repeatable), each run's model is replayed open loop on the validation runs and scored
where the holds end: mean |q_model − q_real| per joint, against the arm's repeatability (the training runs' where
no validation run repeats its command) and the ratio, with the robot file's PD model as the reference row.

    .venv/bin/python benchmarks/real/so101_servo_holds.py DATA/dataset.npz --run RUN   # e.g. a servo-drive identify run
"""

import numpy as np

MIN_GRAVITY_SPAN = 0.05
"""Least spread of a joint's gravity torque over the training holds [N·m] for its sag to be fitted."""

SETTLE_S = 0.1
"""The position at the end of a hold is averaged over the hold's last ``SETTLE_S`` [s]."""


def hold_ends(c: np.ndarray, rate_hz: float, hold_s: float = 1.0):
    """``(t, u)`` of every hold of the command ``c`` (T, n) lasting at least ``hold_s`` [s]: it is still from sample
    ``t`` to ``u`` (exclusive)."""
    still = np.abs(np.diff(c, axis=0)).max(1) < 1e-6
    t = 0
    while t < len(still):
        if not still[t]:
            t += 1
            continue
        u = t
        while u < len(still) and still[u]:
            u += 1
        if u - t >= hold_s * rate_hz:
            yield t, u
        t = u + 1


def holds(ds, split: str, model, data, n: int, rate_hz: float, hold_s: float = 1.0):
    """(e, G, dir) of every command hold of ``split``: arrays (holds, n)."""
    import pinocchio as pin

    rows = []
    settle = int(SETTLE_S * rate_hz)
    for tr in ds.split(split):
        c, q = tr.q_cmd[:, :n], tr.q[:, :n]
        for t, u in hold_ends(c, rate_hz, hold_s):
            e = q[u - settle:u].mean(0) - c[u - 1]
            g = pin.computeGeneralizedGravity(model, data, tr.q[u - 1].astype(np.float64))[:n]
            rows.append((e, g, np.sign(c[t] - c[max(t - settle, 0)])))
    return [np.array(x) for x in zip(*rows)] if rows else None


def model_hold_errors(trajectories, replayed, rate_hz: float, hold_s: float = 1.0) -> np.ndarray:
    """|q_model − q_real| at the end of every command hold of ``trajectories`` (the holds of :func:`holds`, both
    averaged over the hold's last :data:`SETTLE_S`), ``replayed``: the model's q per trajectory. Shape (holds, n)."""
    settle = int(SETTLE_S * rate_hz)
    rows = [np.abs(qm[u - settle:u].mean(0) - tr.q[u - settle:u].mean(0))
            for tr, qm in zip(trajectories, replayed) for _, u in hold_ends(tr.q_cmd, rate_hz, hold_s)]
    return np.array(rows)


def repeats(ds, split: str, keep, rate_hz: float, min_lag_s: float = 2.0, history_s: float = 1.0,
            tol: float = 0.002, min_matched_s: float = 2.0, min_motion: float = 0.05):
    """How well the arm repeats itself: per run of ``split``, the lag L (≥ ``min_lag_s``) at which its command
    repeats best, the samples whose last ``history_s`` of command equals the one L earlier within ``tol`` [rad] on
    every joint and moved by more than ``min_motion`` [rad, path length summed over joints], and there
    mean |q(t) − q(t − L)| against the run's mean |q − q_cmd| [rad]. Runs with less than
    ``min_matched_s`` of such samples are left out. ``keep``: the joints compared. Returns rows ``(name, L [s],
    matched [s], repeat, gap, per-joint repeat (len(keep),))``."""
    rows = []
    w = int(history_s * rate_hz)
    for tr in ds.split(split):
        c, q = tr.q_cmd[:, keep], tr.q[:, keep]
        lags = range(int(min_lag_s * rate_hz), len(c) // 2, 25)
        if not len(lags):
            continue
        lag = min(lags, key=lambda k: np.abs(c[k:] - c[:-k]).mean())
        same = np.abs(c[lag:] - c[:-lag]).max(1) < tol
        idx = np.flatnonzero(np.convolve(same, np.ones(w), "valid") == w) + w - 1  # whole history matches
        # ... and the command moved in it (a hold repeats trivially): path length over the history [rad]
        path = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(c, axis=0)).sum(1))])
        idx = idx[path[idx + lag] - path[idx + lag - w + 1] > min_motion]
        if len(idx) < min_matched_s * rate_hz:
            continue
        rep = np.abs(q[lag:][idx] - q[:-lag][idx])
        rows.append((tr.name, lag / rate_hz, len(idx) / rate_hz, float(rep.mean()), float(np.abs(q - c).mean()),
                     rep.mean(0)))
    return rows


def model_holds(path: str, ds, robot, runs, hold_s: float = 1.0) -> None:
    """Each model replayed open loop on the validation runs (``wresdyn.sim.rollout.replay_trajectories``, as ``wresdyn
    identify --eval`` does, under the run's own dry-friction law): per fitted joint, mean |q_model − q_real| at the end
    of the command holds, against the arm's repeatability, and the ratio. ``runs``: run folders (their identified
    physics, and residual if any); the robot file's PD model (no gains config) is the reference row."""
    from wresdyn.data.loading import dataset_robot
    from wresdyn.evaluation.evaluate_run import load_run_model, run_friction_kappa
    from wresdyn.sim.rollout import replay_trajectories

    keep = np.flatnonzero(ds.fit_weights() > 0)
    val = list(ds.split("validation"))
    rate = ds.rate_hz
    reps, source = repeats(ds, "validation", keep, rate), "validation"
    if not reps:
        reps, source = repeats(ds, "train", keep, rate), "training"
    # pooled over the matched samples of every qualifying run
    weight = np.array([r[2] for r in reps])
    rep = (np.stack([r[5] for r in reps]) * weight[:, None]).sum(0) / weight.sum()
    print(f"\nmodel hold error on validation ({len(val)} runs, "
          f"{sum(1 for tr in val for _ in hold_ends(tr.q_cmd, rate, hold_s))} holds of >= {hold_s:g} s): "
          f"mean |q_model - q_real| at each hold's end (both averaged over its last {SETTLE_S:g} s) [rad], "
          f"open-loop replay of the whole run from its first recorded state")
    if source == "validation":
        print(f"repeatability: the validation runs' |q(t) - q(t-L)| per joint, pooled over their matched samples "
              f"({', '.join(r[0] for r in reps)})")
    else:
        print(f"repeatability: no validation run repeats its command for >= 2 s (above), so the training runs' "
              f"|q(t) - q(t-L)| per joint is used, pooled over their matched samples "
              f"({', '.join(f'{r[0]} {r[2]:.1f} s' for r in reps)})")
    names = [robot.joint_names[j] for j in keep]
    print(f"{'model':34s} {'':6s} " + " ".join(f"{n:>13s}" for n in names) + f" {'mean':>8s}")
    print(f"{'repeatability (' + source + ')':34s} {'[rad]':6s} " + " ".join(f"{x:13.4f}" for x in rep)
          + f" {rep.mean():8.4f}")
    pd_robot = dataset_robot(ds.robot_file)
    models = [("robot file's PD (kp " + "/".join(f"{k:.0f}" for k in sorted(set(pd_robot.kp))) + ")",
               lambda: replay_trajectories(pd_robot, val, rate)["pd"])]
    for run in runs:
        def replay(run=run):
            policy, meta, physics, solver, substeps = load_run_model(run, robot, rate)
            return replay_trajectories(robot, val, rate, policy, kind=meta["kind"], solver=solver, substeps=substeps,
                                       physics=physics, friction_kappa=run_friction_kappa(run))["residual"]
        models.append((str(run), replay))
    for label, replay in models:
        replayed = replay()
        err = model_hold_errors(val, replayed.q, rate, hold_s)[:, keep].mean(0)
        whole = np.concatenate([np.abs(qm - tr.q)[:, keep] for tr, qm in zip(val, replayed.q)]).mean()
        diverged = sum(a >= 0 for a in replayed.diverged_at)
        print(f"{label:34s} {'[rad]':6s} " + " ".join(f"{x:13.4f}" for x in err) + f" {err.mean():8.4f}"
              f"   (whole runs: mean |dq| {whole:.4f} rad{f', {diverged} diverged' if diverged else ''})")
        print(f"{'':34s} {'/ rep.':6s} " + " ".join(f"{x:12.1f}x" for x in err / rep)
              + f" {err.mean() / rep.mean():7.1f}x")


def main(path: str, runs=()) -> None:
    from wresdyn.data.loading import load_data
    from wresdyn.robot.pinocchio_model import build_pinocchio

    ds, robot = load_data(path, None, None)
    n = robot.n_dof
    model = build_pinocchio(robot)
    data = model.createData()
    train = holds(ds, "train", model, data, n, ds.rate_hz)
    val = holds(ds, "validation", model, data, n, ds.rate_hz)
    fitted = ds.fit_weights() > 0
    print(f"{path}: {len(train[0])} holds of >= 1 s in the training runs, {len(val[0])} in the validation runs")
    print(f"{'joint':14s} {'a [rad/N·m]':>12s} {'-1/a [N·m/rad]':>15s} {'b [rad]':>8s} {'c [rad]':>8s} "
          f"{'train |e|':>10s} {'-> model':>9s} {'valid |e|':>10s} {'-> model':>9s}")
    for j, name in enumerate(robot.joint_names):
        if not fitted[j]:
            continue
        # a joint whose gravity torque barely changes over the holds (a vertical axis, a roll) says nothing of a
        gravity = np.ptp(train[1][:, j]) >= MIN_GRAVITY_SPAN
        a_mat = np.stack([train[1][:, j] * gravity, train[2][:, j], np.ones(len(train[0]))], 1)
        coef = np.linalg.lstsq(a_mat, train[0][:, j], rcond=None)[0]
        v_mat = np.stack([val[1][:, j] * gravity, val[2][:, j], np.ones(len(val[0]))], 1)
        a_txt = f"{coef[0]:12.4f}" if gravity else f"{'–':>12s}"
        stiff = f"{-1.0 / coef[0]:15.1f}" if gravity and coef[0] < 0 else f"{'–':>15s}"
        print(f"{name:14s} {a_txt} {stiff} {coef[1]:8.4f} {coef[2]:8.4f} "
              f"{np.abs(train[0][:, j]).mean():10.4f} {np.abs(train[0][:, j] - a_mat @ coef).mean():9.4f} "
              f"{np.abs(val[0][:, j]).mean():10.4f} {np.abs(val[0][:, j] - v_mat @ coef).mean():9.4f}")
    print(f"the robot file's kp: {', '.join(f'{k:.0f}' for k in robot.kp)} N·m/rad; "
          f"effort limit {', '.join(f'{e:.2f}' for e in robot.effort)} N·m")
    print("\nrepeatability: where a run's command repeats (the last 1 s within 2 mrad of the one L earlier, and "
          "moving), how "
          "close the arm comes to where it was then, against its distance from the command (all joints but the "
          "excluded ones) [rad]")
    keep = np.flatnonzero(fitted)
    for split in ("train", "validation"):
        for name, lag, matched, rep, gap, _ in repeats(ds, split, keep, ds.rate_hz):
            print(f"  {split:10s} {name:24s} L {lag:6.2f} s  matched {matched:6.1f} s  |q(t) - q(t-L)| {rep:.4f}  "
                  f"|q - q_cmd| {gap:.4f}")
    if runs:
        model_holds(path, ds, robot, runs)


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", help="dataset of real runs (.npz)")
    parser.add_argument("--run", action="append", default=[], metavar="RUN_DIR",
                        help="a run folder whose model (identified physics, residual if any) to replay on the "
                             "validation runs and score at the holds' ends against the arm's repeatability "
                             "(repeatable)")
    args = parser.parse_args()
    main(args.dataset, args.run)
