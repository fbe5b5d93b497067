"""Why identification stops short of the truth on armature and damping (issue 12): the training loss along the way.

    python benchmarks/fidelity/sysid_valley.py RUN/physics.json [DATA]      # DATA: default the shipped dataset

Identification's own loss (:func:`wresdyn.identify.sysid.physics_window_loss`: w_q |Δq|² + w_qd |Δq̇|², the training
split's windows, open loop from each window's recorded start) is evaluated, forward only, on the same fixed windows for:

- the identified parameters (RUN/physics.json) and the real robot's true parameters (``RealRobot.physics()``);
- the identified parameters with armature, damping or both set to the truth;
- points on the straight line from the identified parameters to the truth (every field, links included).

If the truth's loss is lower than the identified one's, the loss can tell them apart and the optimiser stopped
short; if it is higher, the loss itself prefers the identified parameters (the data, the windows and the
simulator's remaining difference from the real robot decide), and no optimiser would move to the truth.
Also prints the validation split's whole-trajectory error of each point (what selection sees), and each joint's
effective inertia: the diagonal of the links' joint-space mass matrix M_ii(q), averaged over training poses, plus
the armature, identified against true (armature and the links' inertia about the same axis add up; the data fix
mostly their sum). 20 s on 2 cores.
"""

from __future__ import annotations

import argparse

import numpy as np


def blend(a, b, t: float):
    """(1 − t) a + t b, field by field (links' inertias stay symmetric positive: a convex combination)."""
    from wresdyn.sim.physics import PhysicalParams

    return PhysicalParams(**{f: (getattr(a, f) if isinstance(getattr(a, f), list)
                                 else (1 - t) * getattr(a, f) + t * getattr(b, f)) for f in a.__dataclass_fields__})


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("physics", help="identified physics.json (`wresdyn identify`)")
    p.add_argument("data", nargs="?", default=None, help="dataset (default: the shipped one)")
    p.add_argument("--windows", type=int, default=256, help="fixed training windows per horizon")
    p.add_argument("--horizons", default="16,64,128", help="window lengths [steps]")
    args = p.parse_args()
    import torch
    import warp as wp

    from wresdyn.data.loading import load_data
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.evaluation.open_loop import evaluate_split
    from wresdyn.learn.window_fit import joint_weights, squared_error
    from wresdyn.identify.sysid import SysIdConfig
    from wresdyn.paths import DEFAULT_DATASET
    from wresdyn.sim import Simulator, TrajectoryBank, rollout
    from wresdyn.sim.physics import PhysicalParams

    wp.config.quiet = True
    torch.set_num_threads(2)
    data = args.data or str(DEFAULT_DATASET)
    ds, robot = load_data(data)
    ident = PhysicalParams.load(args.physics, robot)
    truth = RealRobot(robot, Mismatch.from_dict(ds.mismatch, "the dataset's mismatch"), ds.rate_hz).physics()
    cfg = SysIdConfig()
    dt = 1.0 / ds.rate_hz
    train = ds.split("train")
    bank = TrajectoryBank(train, "cpu")
    weights = joint_weights(ds, "cpu")
    sim = Simulator(robot, args.windows, dt, solver="replay")
    rng = np.random.default_rng(0)
    horizons = [int(h) for h in args.horizons.split(",")]
    draws = {h: bank.draw(rng, args.windows, h) for h in horizons}

    def loss(params) -> dict:
        out = {}
        sim.set_physics(params)
        bank.set_delay(torch.as_tensor(params.delay / dt, dtype=torch.float32))
        for h, (traj, start) in draws.items():
            window = bank.window(traj, start, h)
            with torch.no_grad():
                run = rollout(sim, window)
            pos = float(squared_error(run.q[:, 1:], window.q[:, 1:], weights))
            vel = float(squared_error(run.qd[:, 1:], window.qd[:, 1:], weights))
            out[h] = cfg.w_q * pos + cfg.w_qd * vel
        return out

    def validation(params) -> float:
        summary, _ = evaluate_split(robot, ds.split("validation"), ds.rate_hz, physics=params)
        return summary["pd_residual"]["mean_abs_dq"]

    points = {"identified": ident, "truth": truth}
    for fields in (("armature",), ("damping",), ("armature", "damping")):
        q = ident.copy()
        for f in fields:
            setattr(q, f, getattr(truth, f).copy())
        points["identified, " + " and ".join(fields) + " from the truth"] = q
    for t in (0.25, 0.5, 0.75):
        points[f"identified -> truth, t = {t:g}"] = blend(ident, truth, t)
    print(f"{data}: identification loss (w_q |dq|^2 + w_qd |dqd|^2, mean over steps, summed over joints) on "
          f"{args.windows} fixed training windows per horizon; validation mean |dq| [rad] of whole trajectories")
    print(f"{'parameters':55s} " + " ".join(f"H={h:<9d}" for h in horizons) + " validation")
    for name, params in points.items():
        row = loss(params)
        print(f"{name:55s} " + " ".join(f"{row[h]:.3e}  " for h in horizons) + f" {validation(params):.4f}",
              flush=True)
    ratio = {f: float(np.median(getattr(ident, f) / np.maximum(getattr(truth, f), 1e-12)))
             for f in ("armature", "damping")}
    print("median identified / true: " + ", ".join(f"{f} {v:.2f}" for f, v in ratio.items()))
    inertia_table(robot, train, ds.rate_hz, ident, truth)


def inertia_table(robot, train, rate_hz: float, ident, truth, poses: int = 33) -> None:
    """Per joint: mean over ``poses`` training poses of the links' M_ii(q) [kg m^2 or kg], the armature, their sum,
    identified against true."""
    from wresdyn.sim import Simulator

    q = np.concatenate([t.q for t in train])
    q = q[np.linspace(0, len(q) - 1, poses).astype(int)]

    def mean_diag(params):
        sim = Simulator(robot, 1, 1.0 / rate_hz, solver="replay")
        sim.set_physics(params)
        return np.mean([np.diag(sim.solver.dynamics_terms(qi, np.zeros_like(qi))[0][0]) for qi in q], axis=0)

    mt, mi = mean_diag(truth), mean_diag(ident)
    st, si = mt + truth.armature, mi + ident.armature
    print(f"\neffective inertia over {poses} training poses: links' M_ii (mean), armature a, M_ii + a; true / identified")
    print(f"{'joint':22s} {'M_ii':>15s} {'a':>15s} {'M_ii + a':>15s} {'ratio':>6s}")
    for j, name in enumerate(robot.joint_names):
        print(f"{name:22s} {mt[j]:7.4f} {mi[j]:7.4f} {truth.armature[j]:7.4f} {ident.armature[j]:7.4f} "
              f"{st[j]:7.4f} {si[j]:7.4f} {si[j] / st[j]:6.2f}")
    print(f"median identified / true: armature {np.median(ident.armature / truth.armature):.2f}, links' M_ii "
          f"{np.median(mi / mt):.2f}, M_ii + a {np.median(si / st):.2f}")


if __name__ == "__main__":
    main()
