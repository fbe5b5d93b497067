"""Why stepping in place fails on the floor: each policy of a finished ``wresdyn deploy --floor`` run deployed on the
plant it trained on and on the "real" robot, with how its base drifts, over the run's held-out motions of the
families that stand on one foot (stepping in place, kick).

    python benchmarks/skills/floor_step.py RUN --data DATASET --calibrated CAL --delta DELTA [--families step,kick]
        [--series] [--combo N] [--slow D]

RUN is the deploy folder (``results.json``, ``skills/*/policy.pt``); CAL and DELTA the corrections it trained (b) and
(c) on. Per policy and plant, per motion: success, failure cause and policy step; then, on the stance foot (a sole
the reference keeps planted), its slide over the floor while planted [mm], the landing error of each sole set down
again (its distance from the reference's place, in the world [mm]), and at the failure (or the end) the base's
distance from its reference [m], its height error [m], tilt and yaw [deg]. A slide of millimetres with a base far
off means the robot toppled over its stance foot rather than walking off. ``--series`` adds, for the first motion of
each family, every 0.5 s: the base's offset from its reference (x, y) [m], tilt and yaw [deg], and each sole's
distance from its reference place [mm] (``*``: the reference plants it). ``--combo N`` plays N motions of the
``combo`` family drawn from the validation stream instead (no held-out motion); ``--slow D`` plays 4 stepping
motions of D seconds instead (another seed's draws, not the held-out ones: the same keyframes, every transfer slower
by D / the run's duration), with their zero-moment point's smallest margin in the planted soles.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

SETTING = {"a_nominal": "nominal", "b_calibrated": "calibrated", "c_delta_action": "delta_action", "d_oracle": "real"}


def _yaw_tilt(quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Yaw and tilt [rad] of unit quaternions [x y z w] (..., 4)."""
    x, y, z, w = np.moveaxis(quat, -1, 0)
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    tilt = np.arccos(np.clip(1 - 2 * (x * x + y * y), -1, 1))
    return yaw, tilt


def drift_rows(dep, per) -> list[str]:
    """One line per motion of a :class:`~wresdyn.skills.evaluate.Deployment` on the floor: see the module docstring."""
    rows = []
    for i, r in enumerate(per):
        end = r["failed_at"] if r["failed_at"] > 0 else int(np.isfinite(dep.base[i, :, 0]).sum()) - 1
        feet = dep.bodies[i][:, dep.feet]  # (K + 1, 2, 3)
        feet_ref = dep.bodies_ref[i][:, dep.feet]
        pl = dep.planted[i]
        slide, land = [], []
        for f in range(2):
            both = pl[1:end + 1, f] & pl[:end, f]
            d = np.linalg.norm(np.diff(feet[:end + 1, f, :2], axis=0), axis=-1)
            slide.append(1e3 * float(d[both].sum()))
            for k in np.flatnonzero(pl[1:end + 1, f] & ~pl[:end, f]) + 1:
                land.append(1e3 * float(np.linalg.norm(feet[k, f, :2] - feet_ref[k, f, :2])))
        yaw, tilt = _yaw_tilt(dep.base[i, end, 3:])
        dz = dep.base[i, end, 2] - dep.base_ref[i, end, 2]
        dist = np.linalg.norm(dep.base[i, end, :3] - dep.base_ref[i, end, :3])
        dxy = dep.base[i, end, :2] - dep.base_ref[i, end, :2]
        rows.append(f"  {r['motion']:18s} {'ok' if r['success'] else r['cause'] + '@' + str(r['failed_at']):13s} "
                    f"stance slide L {slide[0]:5.0f} R {slide[1]:5.0f} mm; landings "
                    f"{', '.join(f'{x:.0f}' for x in land) or '-'} mm; at step {end}: base off {dist:.2f} m "
                    f"(x {dxy[0]:+.2f}, y {dxy[1]:+.2f}, z {dz:+.2f}), tilt {np.degrees(tilt):.0f} deg, "
                    f"yaw {np.degrees(yaw):+.0f} deg")
    return rows


def series_rows(dep, i: int, every: int = 25) -> list[str]:
    """Motion ``i`` of a deployment every ``every`` policy steps: see the module docstring."""
    rows = []
    for k in range(0, dep.base.shape[1], every):
        if not np.isfinite(dep.base[i, k, 0]):
            break
        yaw, tilt = _yaw_tilt(dep.base[i, k, 3:])
        off = dep.base[i, k, :2] - dep.base_ref[i, k, :2]
        feet = np.linalg.norm(dep.bodies[i, k, dep.feet, :2] - dep.bodies_ref[i, k, dep.feet, :2], axis=-1)
        mark = ["*" if p else " " for p in dep.planted[i, k]]
        rows.append(f"    t {k * dep.policy_dt:4.1f} s: base off x {off[0]:+.3f} y {off[1]:+.3f} m, tilt "
                    f"{np.degrees(tilt):4.1f} yaw {np.degrees(yaw):+5.1f} deg; soles off "
                    f"L {1e3 * feet[0]:4.0f}{mark[0]} R {1e3 * feet[1]:4.0f}{mark[1]} mm")
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run")
    p.add_argument("--data", default=None, help="the dataset whose mismatch is the real robot (default: shipped)")
    p.add_argument("--calibrated", required=True, help="the calibrated robot (b) trained in")
    p.add_argument("--delta", required=True, help="the delta action (c) trained with")
    p.add_argument("--families", default="step,kick")
    p.add_argument("--series", action="store_true", help="the first motion of each family every 0.5 s")
    p.add_argument("--combo", type=int, default=0, help="N combo motions of the validation stream instead")
    p.add_argument("--slow", type=float, default=0.0, help="4 stepping motions of this length [s] instead")
    args = p.parse_args()

    import torch

    from floor_run import held_out
    from wresdyn.robot.description import load_robot
    from wresdyn.skills.evaluate import deploy, metrics
    from wresdyn.skills.motions import make_motions
    from wresdyn.skills.plants import RealPlant, sim_plant
    from wresdyn.skills.skill_ppo import load_skill

    torch.set_num_threads(1)
    run = Path(args.run)
    res, task, floating, motions, real = held_out(run, args.data)
    fams = args.families.split(",")
    motions = [m for m in motions if m.family in fams]
    if args.combo:
        stand = load_robot(floating.source, gains=floating.gains)
        motions = make_motions(stand, {"train": 0, "validation": args.combo}, res["config"]["duration"], real.rate_hz,
                               res["config"]["seed"], floating=floating, families=(), extra=("combo",),
                               workers=0)["validation"]
        fams = ["combo"]
    if args.slow:
        from wresdyn.skills.feasibility import floor_feasibility

        stand = load_robot(floating.source, gains=floating.gains)
        motions = make_motions(stand, {"heldout": 4}, args.slow, real.rate_hz, res["config"]["seed"] + 1000,
                               floating=floating, families=(), workers=0)["heldout"]
        for m in motions:
            m.name = m.name.replace("heldout", "slow")
            margin = floor_feasibility(floating, m, real.rate_hz, every=5, skip=0.01).margin
            print(f"{m.name}: {args.slow:g} s, ZMP margin min {1e3 * margin.min():+.0f} mm, outside the soles on "
                  f"{100 * (margin < 0).mean():.1f} % of the samples", flush=True)
        fams = ["step"]
    runs = {"calibrated": args.calibrated, "delta_action": args.delta}
    seed = res["config"]["seed"] + 100
    kind = "validation" if args.combo else "slowed" if args.slow else "held-out"
    print(f"{run}: {len(motions)} {kind} motions ({', '.join(fams)}), "
          f"{task.decimation} samples per policy step")
    if args.combo:
        print("plans: " + "; ".join(f"{m.name} {' '.join(m.params['plan'])}" for m in motions), flush=True)
    for name in ("reference", *res["policies"]):
        policy = None if name == "reference" else load_skill(run / "skills" / name)
        setting = SETTING.get(name, "nominal")
        plants = {"own": setting, "real": "real"} if setting != "real" else {"own = real": "real"}
        for label, s in plants.items():
            if s == "real":
                plant = RealPlant(real, len(motions), task.decimation, seed=seed,
                                  imu_noise=(task.gyro_noise, task.gravity_noise))
            else:
                plant = sim_plant(s, floating, len(motions), real.rate_hz, task.decimation, runs.get(s), ground=True)
            dep = deploy(policy, plant, motions, task)
            per = metrics(dep)["motions"]
            ok = sum(r["success"] for r in per)
            print(f"{name} on the {s} plant ({label}): {ok}/{len(per)} succeed", flush=True)
            print("\n".join(drift_rows(dep, per)), flush=True)
            if args.series:
                for fam in fams:
                    i = next(j for j, m in enumerate(motions) if m.family == fam)
                    print(f"  {motions[i].name}:\n" + "\n".join(series_rows(dep, i)), flush=True)


if __name__ == "__main__":
    main()
