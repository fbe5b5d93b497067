"""What the SO-101's servos do where they hold still: a diagnostic of the real-data benchmark (issue 13).

For every hold of the command (unchanged for at least 1 s) in a dataset of real runs, the position error at the end
of the hold, e = q − q_cmd [rad], is regressed per joint on the gravity torque G(q) [N·m] (Pinocchio, the robot
file's links) and on the direction the command last came from (sign of its change, ±1):
e ≈ a·G + b·dir + c, fitted on the training runs and applied to the validation runs.

A PD drive with the file's kp (998 N·m/rad) would hold within a few mrad: a = −1/kp ≈ −0.001 rad/(N·m) and no
direction term. The recorded servos sag under gravity by far more (−1/a is the effective stiffness) and stop short
of the target in the direction they came from (b < 0: a dead band, friction against a soft position loop). That is
why `wresdyn identify --gain-grid` searches kp below the file's value. Held-out runs are not read.

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


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: so101_servo_holds.py DATASET.npz")
    main(sys.argv[1])
