"""Where the calibrated simulator's prediction of a floor skill departs from the "real" robot: a finished ``wresdyn
deploy --floor`` run's policies replayed on its VALIDATION motions of one family (default: kick), on the real robot
(the benchmark's deployment, :class:`~wresdyn.skills.plants.RealPlant`) and in the calibrated simulator the policies
trained in (its centre: no randomisation), then on the real robot with one group of its true parameters replaced by
the calibrated robot's identified ones (a *transplant*: what the kick needs the calibrated model to have got right).

    python benchmarks/skills/floor_kick_gap.py RUN --data DATASET --calibrated CAL [--policies P ...]
        [--family kick] [--sim] [--transplant T ...]

Per policy and plant: each motion's success or failure cause and step; on the real robot, per joint the share of
physics substeps its drive sat at the upper / lower torque limit (the truth's) over the motion until it ended, and
on the same real states the share of samples whose torque demand under the identified gains and delay passes the
identified limit (the calibrated model's view of the same motion), the joints listed where either is at least
``--min-share``. ``--sim``: the same policies in the calibrated simulator, its saturation against the identified
limits. Transplants (``--transplant``, each alone): ``floor`` (the nominal floor the simulator has: friction and
softness), ``floor_friction``, ``floor_soft``, ``effort`` (every drive's limit), ``effort:JOINT``, ``gains`` (kp, kd),
``joint_friction``, ``damping``, ``armature``, ``joints`` (the five together), ``links`` (masses and centres of mass),
``link:BODY`` (one body's mass and centre of mass; ``mass:BODY``, ``com:BODY`` each alone), ``model`` (joints and
links) and ``model+floor``; ``seed:N`` is the untouched real robot with its sensor and IMU noise drawn from seed N
instead (how far an outcome moves with the noise alone, against which a transplant's is read). The real robot is
deployed over every validation motion in one batch (its sensor noise is drawn per batch), so the untouched one
reproduces the run's ``results.json``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

TRANSPLANTS = ("floor", "floor_friction", "floor_soft", "effort", "gains", "joint_friction", "damping", "armature",
               "joints", "links", "model", "model+floor")
"""The transplants :func:`transplanted` knows (besides ``effort:JOINT``)."""
JOINT_GROUPS = ("effort", "gains", "joint_friction", "damping", "armature")
"""The joint parameter groups ``joints`` transplants together."""


def transplanted(res: dict, floating, rate_hz: float, ident, what: str):
    """The run's real robot with the group ``what`` of its true parameters replaced by ``ident``'s
    (:class:`~wresdyn.sim.physics.PhysicalParams`, the calibrated robot's identified physics); ``""``: untouched."""
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot

    mm = dict(res["mismatch"])
    if what in ("floor", "floor_friction", "model+floor"):
        mm["floor_friction_scale"] = 1.0
    if what in ("floor", "floor_soft", "model+floor"):
        mm["floor_timeconst_scale"] = 1.0
    real = RealRobot(floating, Mismatch.from_dict(mm, "the run's mismatch"), rate_hz)
    m, n, v0 = real.model, floating.n_dof, 6
    dof = slice(v0, v0 + n)
    groups = set(JOINT_GROUPS) if what in ("joints", "model", "model+floor") else {what}
    finite = np.isfinite(floating.effort)
    if "effort" in groups:
        m.actuator_forcerange[:n][finite] = np.stack([-ident.effort, ident.effort], -1)[finite]
    if what.startswith("effort:"):
        j = list(floating.joint_names).index(what.split(":", 1)[1])
        m.actuator_forcerange[j] = (-ident.effort[j], ident.effort[j])
    if "gains" in groups:
        m.actuator_gainprm[:n, 0] = ident.kp
        m.actuator_biasprm[:n, 1] = -ident.kp
        m.actuator_biasprm[:n, 2] = -ident.kd
    if "joint_friction" in groups:
        m.dof_frictionloss[dof] = ident.friction
    if "damping" in groups:
        m.dof_damping[dof] = ident.damping
    if "armature" in groups:
        m.dof_armature[dof] = ident.armature
    if what in ("links", "model", "model+floor"):
        m.body_mass[1:] = ident.body_mass
        m.body_ipos[1:] = ident.body_com
    kind, _, body = what.partition(":")
    if kind in ("link", "mass", "com"):  # one body's mass (its inertia scaled with it) and/or centre of mass
        b = list(floating.body_names).index(body)
        if kind != "com":
            m.body_inertia[b + 1] *= ident.body_mass[b] / m.body_mass[b + 1]
            m.body_mass[b + 1] = ident.body_mass[b]
        if kind != "mass":
            m.body_ipos[b + 1] = ident.body_com[b]
    return real


def delayed(cmd: np.ndarray, delay_samples: np.ndarray) -> np.ndarray:
    """The commands (T, n) [rad] held per sample as they reach each joint's drive ``delay_samples`` (n,) later
    (linear between samples, the first command before the start, as :class:`~wresdyn.skills.plants.SimPlant`'s
    delay line)."""
    t = np.arange(len(cmd))[:, None] - delay_samples[None, :]
    whole = np.floor(t).astype(int)
    lo, hi = np.clip(whole, 0, len(cmd) - 1), np.clip(whole + 1, 0, len(cmd) - 1)
    a = t - np.floor(t)
    cols = np.arange(cmd.shape[1])[None, :]
    return (1 - a) * cmd[lo, cols] + a * cmd[hi, cols]


def saturation(log: dict, ends: np.ndarray, ident, rate_hz: float, lim: np.ndarray) -> dict:
    """Per motion and joint, over its policy steps until ``ends`` (N,): the real drive's share of substeps at its
    upper and lower true limit (``lim`` (n, 2)) and, on the same true states, the share of samples whose torque
    demand kp (q_cmd(t - delay) - q) - kd q̇ under the identified ``ident`` passes ± its identified limit, upper
    and lower (the torque residual's share left out). ``log``: the per-step records of :class:`_Logged`."""
    tau, cmd = np.stack(log["tau"], 1), np.stack(log["cmd"], 1)  # (N, K, S, n), (N, K, n)
    qs, qds = np.stack(log["q"], 1), np.stack(log["qd"], 1)  # (N, K, dec, n)
    n_w, k_n, dec, n = qs.shape
    out = {k: np.zeros((n_w, n)) for k in ("real_hi", "real_lo", "id_hi", "id_lo")}
    d = np.asarray(ident.delay) * rate_hz
    for i in range(n_w):
        k = int(ends[i]) if ends[i] > 0 else k_n
        t = tau[i, :k].reshape(-1, n)
        out["real_hi"][i] = (t >= 0.999 * lim[:, 1]).mean(0)
        out["real_lo"][i] = (t <= 0.999 * lim[:, 0]).mean(0)
        c = delayed(np.repeat(cmd[i, :k], dec, axis=0), d)
        dem = ident.kp * (c - qs[i, :k].reshape(-1, n)) - ident.kd * qds[i, :k].reshape(-1, n)
        out["id_hi"][i] = (dem > ident.effort).mean(0)
        out["id_lo"][i] = (dem < -ident.effort).mean(0)
    return out


def sim_saturation(log: dict, ends: np.ndarray, ident) -> dict:
    """Per motion and joint, the calibrated simulator's share of samples whose PD demand on its own states passes
    ± the identified limit (upper, lower), over its policy steps until ``ends``."""
    tgt, q, qd = (np.stack(log[k], 1) for k in ("target", "q", "qd"))  # (N, K * dec, n), state before each sample
    dec = tgt.shape[1] // max(len(log["steps"]), 1)
    dem = ident.kp * (tgt - q) - ident.kd * qd
    out = {"sim_hi": np.zeros(tgt.shape[::2]), "sim_lo": np.zeros(tgt.shape[::2])}
    for i in range(tgt.shape[0]):
        k = (int(ends[i]) if ends[i] > 0 else len(log["steps"])) * dec
        out["sim_hi"][i] = (dem[i, :k] > ident.effort).mean(0)
        out["sim_lo"][i] = (dem[i, :k] < -ident.effort).mean(0)
    return out


def logged_real(real, worlds: int, decimation: int, seed: int, imu_noise):
    """A :class:`~wresdyn.skills.plants.RealPlant` that keeps each step's command, drive torques and true states."""
    from wresdyn.skills.plants import RealPlant

    class _Logged(RealPlant):
        def step(self, cmd):
            out = super().step(cmd)
            self.log["cmd"].append(np.asarray(cmd, np.float64))
            self.log["tau"].append(self.tau.copy())
            self.log["q"].append(self.q_samples.copy())
            self.log["qd"].append(self.qd_samples.copy())
            return out

    plant = _Logged(real, worlds, decimation, seed=seed, imu_noise=imu_noise)
    plant.log = {"cmd": [], "tau": [], "q": [], "qd": []}
    return plant


def logged_sim(cal: str, floating, worlds: int, rate_hz: float, decimation: int):
    """The calibrated simulator (:func:`~wresdyn.skills.plants.sim_plant`, on the floor, no randomisation) keeping
    every sample's delayed PD target and the joint state it was applied to."""
    import torch

    from wresdyn.skills.plants import sim_plant

    plant = sim_plant("calibrated", floating, worlds, rate_hz, decimation, cal, ground=True)
    plant.log = {"target": [], "q": [], "qd": [], "steps": []}
    sim_step, plant_step = plant.sim.step, plant.step
    state = {"q": None, "qd": None}

    def step_logged(target, tau=None):
        q0 = plant.q if state["q"] is None else state["q"]
        qd0 = plant.qd if state["qd"] is None else state["qd"]
        plant.log["target"].append(torch.as_tensor(target).cpu().numpy().astype(np.float64))
        plant.log["q"].append(torch.as_tensor(q0).cpu().numpy().astype(np.float64))
        plant.log["qd"].append(torch.as_tensor(qd0).cpu().numpy().astype(np.float64))
        q, qd = sim_step(target, tau)
        state["q"], state["qd"] = q, qd
        return q, qd

    def step(cmd):
        state["q"], state["qd"] = plant.q, plant.qd
        plant.log["steps"].append(1)
        return plant_step(cmd)

    plant.sim.step, plant.step = step_logged, step
    return plant


def joint_rows(names, sat: dict, idx, keys, min_share: float) -> list[str]:
    """Joints where any of ``keys`` (shares, mean over the motions ``idx``) reaches ``min_share``, one line each."""
    mean = {k: sat[k][idx].mean(0) for k in keys}
    hit = [j for j in range(len(names)) if max(mean[k][j] for k in keys) >= min_share]
    hit.sort(key=lambda j: -max(mean[k][j] for k in keys))
    return [f"    {names[j]:20s} " + "  ".join(f"{k} {100 * mean[k][j]:5.1f} %" for k in keys) for j in hit]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run")
    p.add_argument("--data", default=None, help="the dataset whose robot file the run used (default: shipped)")
    p.add_argument("--calibrated", required=True, help="the calibrated robot (b) and (f) trained in")
    p.add_argument("--policies", nargs="+", default=["f_calibrated_narrow", "d_oracle"])
    p.add_argument("--family", default="kick")
    p.add_argument("--sim", action="store_true", help="also deploy in the calibrated simulator")
    p.add_argument("--transplant", nargs="*", default=[],
                   help=f"{', '.join(TRANSPLANTS)}, effort:JOINT, link:BODY, mass:BODY, com:BODY or seed:N")
    p.add_argument("--min-share", type=float, default=0.005, help="joints listed from this saturated share")
    args = p.parse_args()

    import torch

    from floor_run import held_out
    from floor_step import drift_rows
    from wresdyn.learn.runs import run_physics
    from wresdyn.skills.evaluate import deploy, metrics
    from wresdyn.skills.skill_ppo import load_skill

    torch.set_num_threads(1)
    run = Path(args.run)
    res, task, floating, motions, real = held_out(run, args.data, split="validation")
    names = list(floating.joint_names)
    ident = run_physics(args.calibrated, floating)
    idx = [i for i, m in enumerate(motions) if m.family == args.family]
    seed, rate, imu = res["config"]["seed"] + 100, real.rate_hz, (task.gyro_noise, task.gravity_noise)
    print(f"{run}: {len(motions)} validation motions, {len(idx)} of family {args.family}; calibrated {args.calibrated}")
    true = real.physics()
    print("limits [N*m] true / identified where they differ by over 10 %: " + ", ".join(
        f"{names[j]} {true.effort[j]:.1f}/{ident.effort[j]:.1f}" for j in range(len(names))
        if np.isfinite(true.effort[j]) and abs(ident.effort[j] / true.effort[j] - 1) > 0.1))
    print(f"delay [ms] true {1e3 * true.delay[0]:.1f}, identified {1e3 * np.min(ident.delay):.1f}-"
          f"{1e3 * np.max(ident.delay):.1f}; floor: real friction x{res['mismatch'].get('floor_friction_scale', 1):g}, "
          f"time constant x{res['mismatch'].get('floor_timeconst_scale', 1):g}, the simulator's nominal")
    summary = {}
    for name in args.policies:
        policy = load_skill(run / "skills" / name)
        for what in ["", *args.transplant]:
            noise = what.startswith("seed:")
            rr = transplanted(res, floating, rate, ident, what) if what and not noise else real
            plant = logged_real(rr, len(motions), task.decimation, int(what[5:]) if noise else seed, imu)
            dep = deploy(policy, plant, motions, task)
            per = metrics(dep)["motions"]
            ok = [int(per[i]["success"]) for i in idx]
            label = f"real, noise {what}" if noise else f"real, {what} transplanted" if what else "real"
            summary[f"{name} | {label}"] = ok
            how = ", ".join("ok" if per[i]["success"] else f"{per[i]['cause']}@{per[i]['failed_at']}" for i in idx)
            print(f"{name} on the {label}: {args.family} {sum(ok)}/{len(idx)} [{how}]; "
                  f"all {sum(r['success'] for r in per)}/{len(per)}", flush=True)
            if not what:
                want = [int(m["success"]) for m in res["real"]["validation"][name]["motions"]]
                if want != [int(r["success"]) for r in per]:
                    print(f"  (results.json has {want}, this deployment {[int(r['success']) for r in per]})")
                print("\n".join(r for k, r in enumerate(drift_rows(dep, per)) if k in idx))
                ends = np.array([r["failed_at"] for r in per])
                sat = saturation(plant.log, ends, ident, rate, plant.lim)
                for label, sub in (("failed", [i for i in idx if not per[i]["success"]]),
                                   ("succeeded", [i for i in idx if per[i]["success"]])):
                    if sub:
                        print(f"  saturation on the real robot's {args.family} motions that {label} ({len(sub)}): "
                              "real = its drives against the true limits, id = the identified model's demand on "
                              "the same states")
                        print("\n".join(joint_rows(names, sat, sub, ("real_hi", "real_lo", "id_hi", "id_lo"),
                                                   args.min_share)))
        if args.sim:
            plant = logged_sim(args.calibrated, floating, len(idx), rate, task.decimation)
            kicks = [motions[i] for i in idx]
            dep = deploy(policy, plant, kicks, task)
            per = metrics(dep)["motions"]
            summary[f"{name} | calibrated sim"] = [int(r["success"]) for r in per]
            print(f"{name} in the calibrated simulator: {args.family} {sum(r['success'] for r in per)}/{len(per)}")
            print("\n".join(drift_rows(dep, per)))
            sat = sim_saturation(plant.log, np.array([r["failed_at"] for r in per]), ident)
            print("  saturation in the calibrated simulator (its demand against the identified limits)")
            print("\n".join(joint_rows(names, sat, list(range(len(per))), ("sim_hi", "sim_lo"), args.min_share)))
    print("summary " + json.dumps(summary))


if __name__ == "__main__":
    main()
