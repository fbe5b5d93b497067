"""Drift benchmark of the online identifier (``wresdyn adapt``), sim to sim: the real robot changes during a long run.

    python benchmarks/adapt/adapt_drift.py --out benchmarks/results/adapt_drift          # ~15 min on 2 loaded CPU cores
    python benchmarks/adapt/adapt_drift.py --quick --out /tmp/adapt_drift_quick           # a 40 s timeline, smoke test
    python benchmarks/adapt/adapt_drift.py --splits validation --seed 1 --oracles DIR --out OUT   # the validation timeline
    python benchmarks/adapt/adapt_drift.py --motion skill --splits heldout --oracles DIR --out OUT  # a skill as the motion
    python benchmarks/adapt/adapt_drift.py --motion policy --policy RUN/skills/b_calibrated --splits heldout --oracles DIR \
        --out OUT                                                          # a deployed skill closed loop

The "real" robot is the shipped one (``data/mismatch_default.toml`` on the humanoid, MuJoCo C at 1 kHz, sensor noise),
driven by the shipped excitation: the commands of ``data/dataset.npz`` (train, validation, held-out splits in turn,
joined by 1 s raised-cosine blends), cycled for the whole run. ``--splits validation --seed 1`` is the validation
timeline the adapter's defaults are chosen on (the validation trajectories' commands only, other sensor noise); the
reported one is the default. ``--motion skill`` drives it with the stand skills' reference motions under PD instead
(:func:`skill_commands`: kick, squat, wave, march); ``--motion policy`` with a tracking policy trained by ``wresdyn
deploy`` closed loop over the same motions (``adapt_drift_policy.py``: the stream is the robot's log, the command the
PD target the policy wrote). Its MuJoCo model changes while it runs, through
:meth:`wresdyn.data.real_robot.RealRobot.record`'s ``on_sample`` hook (default timeline, robot time; under the policy,
before every policy step):

- 0-20 s: no drift;
- 20-80 s: the dry friction of the twelve leg drives rises linearly to twice its value (then stays);
- 100 s: a 2 kg payload on the torso, 12 cm behind and 5 cm above its centre of mass (a backpack);
- 130 s: the left knee's drive derates to 60 % of its effort limit; the run ends at 160 s.

Three models predict the robot, each scored every second on the *next* second of the stream (not yet seen by the
adapter), replayed open loop from its first recorded state (mean |q_sim - q| [rad] over joints and steps):

(i) ``fixed``: the offline calibration (``benchmarks/results/grey_box/soft_friction/physics.json``, ``wresdyn identify``
    on the shipped data);
(ii) ``online``: :class:`wresdyn.adapt.adapter.Adapter` warm-started from it, the model it holds at that second;
(iii) ``oracle``: identified offline (``wresdyn identify``'s code, warm-started from the calibration) on a fresh
recording of each new condition held fixed (the friction doubled; plus the payload; plus the derated knee), the
calibration itself before any drift; none during the ramp.

Reported: the errors over time (``timeline.csv``, ``adapt_drift.png``), per phase the mean of each, the time after
each change until the online error's 3 s running mean is within 1.5x the oracle's, the no-drift ratio online / fixed
(target <= 1.05 at every second), the real-time factor (robot time / the adapter's compute) and the tracked
parameters against the truth read back from the MuJoCo model (``summary.json``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
LEGS = slice(0, 12)
"""The leg drives (hips, knees, ankles of both legs)."""
KNEE = "left_knee"
PAYLOAD_KG, PAYLOAD_AT = 2.0, np.array([-0.12, 0.0, 0.05])
"""The payload [kg] and where it sits relative to the torso's centre of mass [m], torso frame."""


def phases(total: float) -> dict:
    """Change times [s] scaled to a run of ``total`` seconds (160 s: the module docstring's)."""
    s = total / 160.0
    return {"ramp": (20 * s, 80 * s), "payload": 100 * s, "derate": 130 * s, "end": total}


def commands(ds, seconds: float, rate: float, blend: float = 1.0, splits=("train", "validation", "heldout")
             ) -> np.ndarray:
    """The dataset's commands of ``splits`` in turn, joined by raised-cosine blends, ``seconds`` long: (T, n)
    [rad]."""
    trajs = [t.q_cmd for t in ds.trajectories if t.split in splits]
    return _cycle(trajs, seconds, rate, blend)


def skill_motions(robot, rate: float, split: str, seed: int) -> list:
    """The stand skills' reference motions of ``split`` (:func:`wresdyn.skills.motions.make_motions`: kick, squat,
    wave and, in the held-out split, march; two of each, 2 s each, every one from and back to the neutral stance)."""
    from wresdyn.skills.motions import make_motions

    return make_motions(robot, {split: 2}, duration=2.0, rate_hz=rate, seed=seed).split(split)


def skill_commands(robot, seconds: float, rate: float, split: str, seed: int) -> np.ndarray:
    """:func:`skill_motions` in turn, as the PD command: the motion a tracking policy asks for, without the policy.
    (T, n) [rad]."""
    return _cycle([m.q for m in skill_motions(robot, rate, split, seed)], seconds, rate, 0.2)


def skill_reference(robot, samples: int, rate: float, split: str, seed: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`skill_motions` in turn as one reference for a tracking policy, ``samples`` long: joint positions [rad]
    (samples, n) (:func:`skill_commands`' command), the soles [m] (samples, n_feet, 3) (blended linearly between
    motions) and the name of the motion each sample belongs to (samples,) (``blend`` between two)."""
    motions = skill_motions(robot, rate, split, seed)
    seconds = samples / rate + 1.0
    q = _cycle([m.q for m in motions], seconds, rate, 0.2)[:samples]
    feet = _cycle([m.feet.reshape(len(m.feet), -1) for m in motions], seconds, rate, 0.2)[:samples]
    names, i = [], 0
    while len(names) < samples:  # _cycle's order: the first motion, then a blend and the next, in turn
        m = motions[i % len(motions)]
        names += ([] if i == 0 else ["blend"] * int(0.2 * rate)) + [m.name] * len(m.q)
        i += 1
    return q, feet.reshape(samples, *motions[0].feet.shape[1:]), np.array(names[:samples])


def _cycle(trajs, seconds: float, rate: float, blend: float) -> np.ndarray:
    nb = int(blend * rate)
    w = 0.5 - 0.5 * np.cos(np.pi * np.arange(1, nb + 1) / (nb + 1))
    out, n, i = [trajs[0]], len(trajs[0]), 1
    while n < seconds * rate:
        nxt = trajs[i % len(trajs)]
        out += [out[-1][-1] + w[:, None] * (nxt[0] - out[-1][-1]), nxt]
        n += nb + len(nxt)
        i += 1
    return np.concatenate(out)[: int(seconds * rate)]


class Drift:
    """The real robot's model fields as a function of robot time (the ``on_sample`` hook of ``RealRobot.record``)."""

    def __init__(self, real, robot, times: dict, rate: float) -> None:
        from scipy.spatial.transform import Rotation

        m = real.model
        self.m, self.times, self.rate, self.robot = m, times, rate, robot
        self.friction0 = m.dof_frictionloss.copy()
        self.force0 = m.actuator_forcerange.copy()
        b = robot.body_names.index("torso") + 1  # MuJoCo body 0 is the world
        self.body = b
        self.body0 = (m.body_mass[b].copy(), m.body_ipos[b].copy(), m.body_inertia[b].copy(), m.body_iquat[b].copy())
        mass, com, inertia, quat = self.body0
        rot = Rotation.from_quat(quat, scalar_first=True).as_matrix()
        i_c = rot @ np.diag(inertia) @ rot.T
        p = com + PAYLOAD_AT
        total = mass + PAYLOAD_KG
        c = (mass * com + PAYLOAD_KG * p) / total

        def shift(mm, d):  # parallel axis: a mass mm at offset d
            return mm * (d @ d * np.eye(3) - np.outer(d, d))

        i_new = i_c + shift(mass, com - c) + shift(PAYLOAD_KG, p - c)
        vals, vecs = np.linalg.eigh(i_new)
        if np.linalg.det(vecs) < 0:
            vecs[:, 0] *= -1
        self.body1 = (total, c, vals, Rotation.from_matrix(vecs).as_quat(scalar_first=True))
        self.knee = robot.joint_names.index(KNEE)

    def condition(self, t: float) -> tuple[float, bool, bool]:
        """(friction factor on the leg drives, payload on, knee derated) at robot time ``t`` [s]."""
        r0, r1 = self.times["ramp"]
        return (1.0 + float(np.clip((t - r0) / (r1 - r0), 0.0, 1.0)), t >= self.times["payload"],
                t >= self.times["derate"])

    def apply(self, friction: float, payload: bool, derate: bool) -> None:
        m = self.m
        m.dof_frictionloss[:] = self.friction0
        m.dof_frictionloss[LEGS] = friction * self.friction0[LEGS]
        b = self.body
        m.body_mass[b], m.body_ipos[b], m.body_inertia[b], m.body_iquat[b] = self.body1 if payload else self.body0
        m.actuator_forcerange[:] = self.force0
        if derate:
            m.actuator_forcerange[self.knee] = 0.6 * self.force0[self.knee]

    def __call__(self, k: int, m) -> None:
        self.apply(*self.condition(k / self.rate))


def oracle(robot, ds, mismatch, drift_args, calib, iterations: int, n_train: int, log):
    """Identify offline on a recording of one condition held fixed (``drift_args`` of :meth:`Drift.apply`)."""
    from wresdyn.data.dataset import Trajectory, derive_qdd
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.identify.sysid import SysIdConfig, identify

    real = RealRobot(robot, mismatch, ds.rate_hz)
    Drift(real, robot, phases(160.0), ds.rate_hz).apply(*drift_args)
    trajs = []
    picks = ds.split("train")[:n_train] + ds.split("validation")
    for i, tr in enumerate(picks):
        q, qd, _ = real.record(tr.q_cmd, np.random.default_rng(100 + i))
        trajs.append(Trajectory(tr.name, tr.split, tr.t, q, qd, derive_qdd(qd, ds.rate_hz), tr.q_cmd))
    data = dataclasses.replace(ds, trajectories=trajs)
    params, _ = identify(robot, data, SysIdConfig(iterations=iterations), start=calib, log=log)
    return params, real.physics()


def score(robot, segments, models, rate: float) -> np.ndarray:
    """Open-loop error [rad] of ``models[i]`` (PhysicalParams or None) on ``segments[i]`` (q, qd, q_cmd), each
    replayed from its first sample with the model's own command delay; NaN where the model is None."""
    import torch

    from wresdyn.sim import Simulator, TrajectoryBank, rollout
    from wresdyn.sim.bank import Window

    idx = [i for i, m in enumerate(models) if m is not None]
    sim = Simulator(robot, len(idx), 1.0 / rate, param_grads=True)
    parts = []
    for w, i in enumerate(idx):
        sim.set_physics(models[i], worlds=slice(w, w + 1))
        q, qd, q_cmd = segments[i]
        seg = SimpleNamespace(q=q, qd=qd, qdd=np.zeros_like(q), q_cmd=q_cmd)
        delay = torch.as_tensor(models[i].delay * rate, dtype=torch.float32)
        parts.append(TrajectoryBank([seg], sim.device, delay).whole())
    window = Window(*(torch.cat([getattr(p, f) for p in parts]) for f in ("q", "qd", "qdd", "cmd", "target",
                                                                           "length")))
    with torch.no_grad():
        run = rollout(sim, window)
    out = np.full(len(models), np.nan)
    out[idx] = (run.q[:, 1:] - window.q[:, 1:]).abs().mean((1, 2)).cpu().numpy()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="benchmarks/results/adapt_drift")
    ap.add_argument("--seconds", type=float, default=160.0, help="robot time of the run [s]")
    ap.add_argument("--oracle-iterations", type=int, default=300)
    ap.add_argument("--oracle-train", type=int, default=8, help="training trajectories (4 s) of each oracle")
    ap.add_argument("--set", nargs="*", default=[], help="AdaptConfig overrides, name=value (e.g. lr=0.005)")
    ap.add_argument("--oracles", default=None,
                    help="reuse the oracle_*.json of an earlier run's folder (same timeline and conditions)")
    ap.add_argument("--quick", action="store_true", help="a 40 s run, 40-iteration oracles on 2 trajectories")
    ap.add_argument("--motion", choices=("excitation", "skill", "policy"), default="excitation",
                    help="what the robot does: the shipped excitation's commands, the stand skills' reference "
                         "motions under PD, or a tracking policy (--policy) closed loop over those motions")
    ap.add_argument("--policy", default=None, metavar="SKILL_RUN",
                    help="the skill of --motion policy: a `wresdyn deploy` folder's skills/<name> (policy.pt)")
    ap.add_argument("--splits", default="train,validation,heldout",
                    help="the splits the motion is drawn from (excitation: the dataset's; skill: one of train, "
                         "validation, heldout); `validation` is the timeline settings are chosen on")
    ap.add_argument("--seed", type=int, default=0, help="seed of the sensor noise and of the skill motions' draw")
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from wresdyn.adapt.adapter import Adapter, AdaptConfig
    from wresdyn.data.loading import load_data
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.paths import DEFAULT_MISMATCH
    from wresdyn.sim.physics import PhysicalParams

    if args.quick:
        args.seconds, args.oracle_iterations, args.oracle_train = 40.0, 40, 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = []

    def log(msg=""):
        print(msg, flush=True)
        lines.append(str(msg))

    ds, robot = load_data(str(ROOT / "data" / "dataset.npz"))
    rate = ds.rate_hz
    calib = PhysicalParams.load(ROOT / "benchmarks" / "results" / "grey_box" / "soft_friction" / "physics.json", robot)
    mismatch = Mismatch.load(DEFAULT_MISMATCH)
    over = {k: _value(getattr(AdaptConfig(), k), v) for k, v in (s.split("=") for s in args.set)}
    cfg = AdaptConfig(**over)
    times = phases(args.seconds)
    log(f"adapt_drift: {args.seconds:g} s at {rate:g} Hz, phases {times}, {cfg}")

    # the stream
    t0 = time.perf_counter()
    splits = tuple(args.splits.split(","))
    if args.motion != "excitation" and len(splits) != 1:
        raise SystemExit(f"--motion {args.motion} takes one split")
    if args.motion == "policy" and not args.policy:
        raise SystemExit("--motion policy needs --policy SKILL_RUN (a `wresdyn deploy` folder's skills/<name>)")
    real = RealRobot(robot, mismatch, rate)
    drift = Drift(real, robot, times, rate)
    truth_at = {}

    def hook(k, m):
        drift(k, m)
        if k % int(rate) == 0:
            truth_at[k // int(rate)] = real.physics()

    run = None
    if args.motion == "policy":
        from adapt_drift_policy import policy_stream, policy_tracking

        ref_q, ref_feet, ref_names = skill_reference(robot, int(round(args.seconds * rate)) + 1, rate, splits[0],
                                                     args.seed)
        run = policy_stream(args.policy, real, hook, ref_q, ref_feet, rate, args.seed)
        q, qd, q_cmd = run.q, run.qd, run.q_cmd
    else:
        q_cmd = (skill_commands(robot, args.seconds, rate, splits[0], args.seed) if args.motion == "skill" else
                 commands(ds, args.seconds, rate, splits=splits))
        q, qd, _ = real.record(q_cmd, np.random.default_rng(args.seed), on_sample=hook)
    t = np.arange(len(q)) / rate
    log(f"recorded {t[-1] + 1 / rate:.0f} s of the drifting robot in {time.perf_counter() - t0:.0f} s")

    # the online identifier, on the stream sample by sample in blocks of 0.1 s
    adapter = Adapter(robot, calib, rate, cfg, publish=out / "physics")
    held = {}  # second -> the adapter's model at that second
    for s0 in range(0, len(t), int(rate / 10)):
        s1 = min(s0 + int(rate / 10), len(t))
        for u in adapter.push(t[s0:s1], q[s0:s1], qd[s0:s1], q_cmd[s0:s1]):
            verdict = "acc" if u.accepted else "rev" if u.reverted else "rej"
            mode = f"  track (jump {u.jump:.2f})" if u.tracking else ""
            grid = f"  effort grid {u.effort_tried}: {u.effort_set or 'none kept'}" if u.effort_tried else ""
            log(f"t {u.t:7.2f} s  {verdict}  held-back {u.open_loop:.5f} "
                f"(fixed {u.open_loop_start:.5f})  compute {u.compute:.2f} s{mode}{grid}")
        if s1 % int(rate) == 0:
            held[s1 // int(rate)] = adapter.physics
    robot_time = len(t) / rate
    rtf = robot_time / adapter.compute
    comp = np.array([u.compute for u in adapter.updates])
    log(f"online: {len(adapter.updates)} updates, {sum(u.accepted for u in adapter.updates)} accepted, compute "
        f"{adapter.compute:.1f} s for {robot_time:.0f} s (real-time factor {rtf:.2f}; per update mean "
        f"{comp.mean():.2f} s, max {comp.max():.2f} s)")

    # the oracles
    conds = {"friction": (2.0, False, False), "payload": (2.0, True, False), "derate": (2.0, True, True)}
    oracles, truths = {}, {}
    for name, c in conds.items():
        t1 = time.perf_counter()
        if args.oracles:
            oracles[name] = PhysicalParams.load(Path(args.oracles) / f"oracle_{name}.json", robot)
            log(f"oracle {name}: from {args.oracles}")
        else:
            oracles[name], truths[name] = oracle(robot, ds, mismatch, c, calib, args.oracle_iterations,
                                                 args.oracle_train, lambda *_: None)
            log(f"oracle {name}: identified in {time.perf_counter() - t1:.0f} s")
        oracles[name].save(out / f"oracle_{name}.json")

    # scoring every second on the next second
    secs = list(range(1, int(robot_time) - 1))
    r0, r1 = times["ramp"]

    def phase(s):
        return ("none" if s < r0 else "ramp" if s < r1 else "friction" if s < times["payload"]
                else "payload" if s < times["derate"] else "derate")

    segs = [tuple(a[s * int(rate):(s + 1) * int(rate) + 1] for a in (q, qd, q_cmd)) for s in secs]
    online = [held.get(s, calib) for s in secs]
    orc = [calib if phase(s) == "none" else oracles.get(phase(s)) for s in secs]
    errs = {k: score(robot, segs, models, rate) for k, models in
            (("fixed", [calib] * len(secs)), ("online", online), ("oracle", orc))}
    rows = [{"t": s, "phase": phase(s), **{k: float(v[i]) for k, v in errs.items()}} for i, s in enumerate(secs)]
    with open(out / "timeline.csv", "w") as f:
        f.write("t,phase,fixed,online,oracle\n" + "".join(
            f"{r['t']},{r['phase']},{r['fixed']:.6f},{r['online']:.6f},{r['oracle']:.6f}\n" for r in rows))
    summary = report(rows, times, errs, secs, held, truth_at, oracles, truths, calib, robot, log)
    if run is not None:
        summary["policy"] = policy_tracking(run, phase, out / "tracking.csv", log, robot.joint_names,
                                            ref_names[np.round(run.step_t * rate).astype(int)])
        summary["policy"]["run"] = str(args.policy)
    if args.oracles:  # the oracles' sizes are the earlier run's
        earlier = json.loads((Path(args.oracles) / "summary.json").read_text())
        args.oracle_iterations, args.oracle_train = earlier["oracle_iterations"], earlier["oracle_train"]
    summary.update({"seconds": args.seconds, "rate_hz": rate, "config": dataclasses.asdict(cfg),
                    "robot_time_s": robot_time, "compute_s": adapter.compute, "real_time_factor": rtf,
                    "update_compute_mean_s": float(comp.mean()), "update_compute_max_s": float(comp.max()),
                    "updates": len(adapter.updates), "accepted": int(sum(u.accepted for u in adapter.updates)),
                    "oracle_iterations": args.oracle_iterations, "oracle_train": args.oracle_train,
                    "oracles_from": args.oracles, "motion": args.motion, "splits": list(splits),
                    "seed": args.seed, "reverted": int(sum(u.reverted for u in adapter.updates)),
                    "tracking": [u.t for u in adapter.updates if u.tracking],
                    "effort_set": {f"{u.t:g}": u.effort_set for u in adapter.updates if u.effort_set}})
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    (out / "updates.json").write_text(json.dumps([u.row() for u in adapter.updates]))
    plot(out / "adapt_drift.png", rows, times, held, truth_at, calib, robot)
    (out / "run.txt").write_text("\n".join(lines) + "\n")


def _value(default, text: str):
    """``text`` as the type of ``default`` (an AdaptConfig field's)."""
    if isinstance(default, bool):
        return {"true": True, "false": False}[text.lower()]
    if isinstance(default, tuple):
        return tuple(float(x) for x in text.split(",") if x)
    return type(default)(text)


def report(rows, times, errs, secs, held, truth_at, oracles, truths, calib, robot, log) -> dict:
    """Per-phase means, recovery times, the no-drift ratio and the tracked parameters against the truth."""
    out = {"phases": {}, "recovery_s": {}, "parameters": {}}
    for ph in ("none", "ramp", "friction", "payload", "derate"):
        sel = [r for r in rows if r["phase"] == ph]
        if sel:
            out["phases"][ph] = {k: float(np.mean([r[k] for r in sel])) for k in ("fixed", "online", "oracle")}
            log(f"{ph:>9}: fixed {out['phases'][ph]['fixed']:.5f}  online {out['phases'][ph]['online']:.5f}  "
                f"oracle {out['phases'][ph]['oracle']:.5f} rad  ({len(sel)} s)")
    none = [r for r in rows if r["phase"] == "none"]
    if none:
        ratio = [r["online"] / r["fixed"] for r in none]
        out["no_drift_max_ratio"] = float(max(ratio))
        log(f"no drift: online / fixed at most {max(ratio):.3f} (target <= 1.05), mean {np.mean(ratio):.3f}")
    for ph, start in (("friction", times["ramp"][1]), ("payload", times["payload"]), ("derate", times["derate"])):
        idx = [i for i, r in enumerate(rows) if r["phase"] == ph]
        # 3 s running mean within the phase (the scores of one second are noisy: each is one second of motion)
        near = [[j for j in (i - 1, i, i + 1) if j in idx] for i in idx]
        ratio = [np.mean([rows[j]["online"] for j in w]) / np.mean([rows[j]["oracle"] for j in w]) for w in near]
        out.setdefault("online_over_oracle", {})[ph] = [float(x) for x in ratio]
        hit = [rows[i]["t"] - start for i, x in zip(idx, ratio) if x <= 1.5]
        out["recovery_s"][ph] = float(hit[0]) if hit else None
        log(f"{ph:>9}: online within 1.5x the oracle (3 s mean) after "
            f"{'%.0f s' % hit[0] if hit else 'never in this phase'}")
    last = max(set(held) & set(truth_at))
    picks = {"friction[left_knee]": ("friction", robot.joint_names.index("left_knee")),
             "friction[left_hip_pitch]": ("friction", robot.joint_names.index("left_hip_pitch")),
             "effort[left_knee]": ("effort", robot.joint_names.index("left_knee")),
             "body_mass[torso]": ("body_mass", robot.body_names.index("torso"))}
    checkpoints = sorted({int(times["ramp"][0]) - 1, int(times["payload"]) - 1, int(times["derate"]) - 1, last})
    for name, (f, j) in picks.items():
        row = {}
        for s in checkpoints:
            if s in held and s in truth_at:
                row[str(s)] = {"truth": float(getattr(truth_at[s], f)[j]), "online": float(getattr(held[s], f)[j]),
                               "fixed": float(getattr(calib, f)[j])}
        row["oracle_derate"] = float(getattr(oracles["derate"], f)[j])
        out["parameters"][name] = row
        log(f"{name}: " + "  ".join(f"t={s}: truth {v['truth']:.3g} online {v['online']:.3g} fixed {v['fixed']:.3g}"
                                    for s, v in row.items() if isinstance(v, dict))
            + f"  oracle(derate) {row['oracle_derate']:.3g}")
    moved = np.flatnonzero(~np.isclose(held[last].effort, calib.effort, rtol=1e-3))
    out["effort_moved"] = {robot.joint_names[j]: {"truth": float(truth_at[last].effort[j]),
                                                  "online": float(held[last].effort[j]),
                                                  "fixed": float(calib.effort[j])} for j in moved}
    log("effort limits the online model moved, at t=%d: " % last + ("  ".join(
        f"{k}: truth {v['truth']:.3g} online {v['online']:.3g} fixed {v['fixed']:.3g}"
        for k, v in out["effort_moved"].items()) or "none"))
    return out


def plot(path, rows, times, held, truth_at, calib, robot) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = [r["t"] for r in rows]
    fig, ax = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    for k, style in (("fixed", "-"), ("online", "-"), ("oracle", "--")):
        ax[0].plot(t, [r[k] for r in rows], style, label={"fixed": "(i) offline calibration, fixed",
                                                          "online": "(ii) online-adapted",
                                                          "oracle": "(iii) oracle (offline, per condition)"}[k])
    for x in (*times["ramp"], times["payload"], times["derate"]):
        for a in ax:
            a.axvline(x, color="0.7", lw=0.8)
    ax[0].set_ylabel("next-second open-loop |q_sim - q| [rad]")
    ax[0].set_yscale("log")
    ax[0].legend(fontsize=8)
    secs = sorted(s for s in held if s in truth_at)
    for name, f, j, c in (("friction left knee", "friction", robot.joint_names.index("left_knee"), "C0"),
                          ("friction left hip pitch", "friction", robot.joint_names.index("left_hip_pitch"), "C1"),
                          ("effort left knee", "effort", robot.joint_names.index("left_knee"), "C2")):
        ref = getattr(calib, f)[j]
        ax[1].plot(secs, [getattr(held[s], f)[j] / ref for s in secs], color=c, label=f"{name}, online")
        ax[1].plot(secs, [getattr(truth_at[s], f)[j] / ref for s in secs], ":", color=c, label=f"{name}, truth")
    ax[1].set_ylabel("value / offline calibration")
    ax[1].set_xlabel("robot time [s]")
    ax[1].legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
