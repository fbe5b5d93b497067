"""SolverReplay's dry friction against MuJoCo C, and what the friction law costs identification (issue 12).

    python benchmarks/fidelity/friction_law.py [DATA]        # DATA: a dataset recorded on the "real" robot (default: shipped)

Prints three measurements (mean / max |q - q_mujoco| [rad]):

1. one hinge (H = 0.03 kg m^2, mu = 1 N m) under a constant torque from rest, 1 s, at 0.5, 0.9, 1.5 and 3 mu;
2. the humanoid replaying a 2 s multisine under PD with ``frictionloss = 0.1 x effort`` on every joint, with 4, 8
   and 16 Gauss-Seidel sweeps;
3. the "real" robot of DATA (its mismatch, sensor noise off) recorded on DATA's held-out commands with parts of the
   mismatch switched off, replayed in SolverReplay with its *true* parameters: the error no identification can
   remove, i.e. the difference between the two simulators;
4. DATA itself (its sensor noise included) replayed with the real robot's true parameters, per split: what a perfect
   identification would score in the README's tables (default law only).

Each runs with the default friction law (MuJoCo's soft ``frictionloss`` per DoF) and with the older damper law
(``friction_kappa=FRICTION_KAPPA``), side by side. The cases of (3) need no fitting: a minute on 2 cores.
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np

LAWS = {"soft (default)": {}, "damper (kappa 947)": None}  # None: filled with FRICTION_KAPPA below


def hinge_and_humanoid(laws: dict) -> None:
    from hinge import DT, MU, make_hinge, mujoco_rollout, newton_rollout

    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
    from wresdyn.sim.parity import multisine_command

    hinge = make_hinge(tempfile.mkdtemp())
    print("1. one hinge, constant torque from rest, 1 s: max |q - q_mujoco| [rad] (q_mujoco at 1 s)")
    for ratio in (0.5, 0.9, 1.5, 3.0):
        tau, cmd = np.full((500, 1), ratio * MU), np.zeros((500, 1))
        mq, _ = mujoco_rollout(hinge, np.zeros(1), cmd, tau)
        row = [f"{ratio:.1f} mu (q_mujoco {mq[-1, 0]:.5f})"]
        for name, kw in laws.items():
            q, _ = newton_rollout(hinge, np.zeros(1), cmd, tau, **kw)
            row.append(f"{name} {np.abs(q[:, 0] - mq[:, 0]).max():.1e}")
        print("   " + "; ".join(row))
    plain = load_robot(DEFAULT_ROBOT)
    robot = load_robot(DEFAULT_ROBOT, gains={"joint": [
        {"match": n, "friction": 0.1 * float(e)} for n, e in zip(plain.joint_names, plain.effort)]})
    cmd = multisine_command(robot, 2.0, DT)
    mq, _ = mujoco_rollout(robot, cmd[0], cmd)
    print("2. humanoid, 2 s multisine, frictionloss 0.1 x effort: |q - q_mujoco| [rad] max / mean")
    for name, kw in laws.items():
        for sweeps in (4, 8, 16):
            q, _ = newton_rollout(robot, cmd[0], cmd, friction_sweeps=sweeps, **kw)
            err = np.abs(q - mq)
            print(f"   {name}, {sweeps:2d} sweeps: {err.max():.4f} / {err.mean():.5f}")


def true_parameters(data: str, laws: dict) -> None:
    import torch

    from wresdyn.data.dataset import Trajectory, derive_qdd
    from wresdyn.data.loading import load_data
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.evaluation.open_loop import metrics
    from wresdyn.sim import Simulator
    from wresdyn.sim.rollout import replay_trajectories
    from wresdyn.sim.solver_replay import SolverReplay

    torch.set_num_threads(1)
    ds, robot = load_data(data)
    base = Mismatch.from_dict(ds.mismatch, "the dataset's mismatch").to_dict()
    quiet = dict(position_noise=0.0, velocity_noise=0.0, encoder_resolution=0.0, velocity_resolution=0.0,
                 torque_resolution=0.0)
    cases = {"the dataset's mismatch": {}, "without friction": dict(friction=0.0),
             "friction only": dict(torque_limit_scale=100.0, delay=0.0)}
    trajs = ds.split("heldout")
    print(f"3. the real robot of {data} (noise off) on {len(trajs)} held-out commands, replayed with its true "
          "parameters: mean |dq| [rad]")
    for case, over in cases.items():
        real = RealRobot(robot, Mismatch.from_dict({**base, **quiet, **over}, case), ds.rate_hz)
        truth = real.physics()
        rec = []
        for tr in trajs:
            q, qd, _ = real.record(tr.q_cmd, np.random.default_rng(0))
            rec.append(Trajectory(tr.name, "heldout", tr.t, q, qd, derive_qdd(qd, ds.rate_hz), tr.q_cmd))
        row = [case]
        for name, kw in laws.items():
            sim = Simulator(robot, len(rec), 1.0 / ds.rate_hz, solver="replay")
            if kw:  # the older law: the same model under another SolverReplay
                sim.solver = SolverReplay(sim.model, **kw)
            out = replay_trajectories(robot, rec, ds.rate_hz, physics=truth, sim=sim)["residual"]
            row.append(f"{name} {metrics(rec, out).mean_abs_dq:.4f}")
        print("   " + "; ".join(row))
    from wresdyn.evaluation.open_loop import evaluate_split

    truth = RealRobot(robot, Mismatch.from_dict(base, "the dataset's mismatch"), ds.rate_hz).physics()
    print(f"4. {data} replayed with the real robot's true parameters (default law): mean |dq| [rad]")
    for split in ("validation", "heldout", "ood"):
        if ds.split(split):
            summary, _ = evaluate_split(robot, ds.split(split), ds.rate_hz, physics=truth)
            print(f"   {split:10s} PD only {summary['pd_only']['mean_abs_dq']:.4f}, true parameters "
                  f"{summary['pd_residual']['mean_abs_dq']:.4f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data", nargs="?", default=None, help="dataset (default: the shipped one)")
    args = p.parse_args()
    import warp as wp

    from wresdyn.paths import DEFAULT_DATASET
    from wresdyn.sim.solver_replay import FRICTION_KAPPA

    wp.config.quiet = True
    laws = {name: ({} if kw is not None else {"friction_kappa": FRICTION_KAPPA}) for name, kw in LAWS.items()}
    hinge_and_humanoid(laws)
    true_parameters(args.data or str(DEFAULT_DATASET), laws)


if __name__ == "__main__":
    main()
