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

    .venv/bin/python benchmarks/so101_servo_holds.py OUT/data/dataset.npz   # the dataset of benchmarks/so101_real.sh
"""

import sys

import numpy as np

MIN_GRAVITY_SPAN = 0.05
"""Least spread of a joint's gravity torque over the training holds [N·m] for its sag to be fitted."""


def holds(ds, split: str, model, data, n: int, rate_hz: float, hold_s: float = 1.0):
    """(e, G, dir) of every command hold of ``split``: arrays (holds, n)."""
    import pinocchio as pin

    rows = []
    settle = int(0.1 * rate_hz)  # the error is averaged over the hold's last 0.1 s
    for tr in ds.split(split):
        c, q = tr.q_cmd[:, :n], tr.q[:, :n]
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
                e = q[u - settle:u].mean(0) - c[u - 1]
                g = pin.computeGeneralizedGravity(model, data, tr.q[u - 1].astype(np.float64))[:n]
                rows.append((e, g, np.sign(c[t] - c[max(t - settle, 0)])))
            t = u + 1
    return [np.array(x) for x in zip(*rows)] if rows else None


def repeats(ds, split: str, keep, rate_hz: float, min_lag_s: float = 2.0, history_s: float = 1.0,
            tol: float = 0.002, min_matched_s: float = 2.0, min_motion: float = 0.05):
    """How well the arm repeats itself: per run of ``split``, the lag L (≥ ``min_lag_s``) at which its command
    repeats best, the samples whose last ``history_s`` of command equals the one L earlier within ``tol`` [rad] on
    every joint and moved by more than ``min_motion`` [rad, path length summed over joints], and there
    mean |q(t) − q(t − L)| against the run's mean |q − q_cmd| [rad]. Runs with less than
    ``min_matched_s`` of such samples are left out. ``keep``: the joints compared. Returns rows ``(name, L [s], matched [s], repeat, gap)``."""
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
        rows.append((tr.name, lag / rate_hz, len(idx) / rate_hz, float(np.abs(q[lag:][idx] - q[:-lag][idx]).mean()),
                     float(np.abs(q - c).mean())))
    return rows


def main(path: str) -> None:
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
    print("\nrepeatability: where a run's command repeats (the last 1 s within 2 mrad of the one L earlier, and moving), how "
          "close the arm comes to where it was then, against its distance from the command (all joints but the "
          "excluded ones) [rad]")
    keep = np.flatnonzero(fitted)
    for split in ("train", "validation"):
        for name, lag, matched, rep, gap in repeats(ds, split, keep, ds.rate_hz):
            print(f"  {split:10s} {name:24s} L {lag:6.2f} s  matched {matched:6.1f} s  |q(t) - q(t-L)| {rep:.4f}  "
                  f"|q - q_cmd| {gap:.4f}")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: so101_servo_holds.py DATASET.npz")
    main(sys.argv[1])
