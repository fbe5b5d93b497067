"""``report.md`` of the zero-shot skill benchmark, on the stand or on the floor: the tables, tracking plots (joints; on
the floor also base height and tilt) and the USD animation of the deployed rollouts side by side."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..evaluation.animation import write_animation
from .evaluate import gaps_or_why_not

__all__ = ["write_report", "plot_tracking", "table", "one_per_family", "plot_rollouts", "gaps_text", "gap_line",
           "randomization_text"]

LABELS = {"reference": "reference played open loop (no policy)", "a_nominal": "(a) nominal simulator",
          "b_calibrated": "(b) (a) fine-tuned, calibrated robot", "c_delta_action": "(c) (a) fine-tuned, delta action",
          "d_oracle": "(d) oracle: (a) fine-tuned on the real robot",
          "e_randomized": "(e) (a) fine-tuned, nominal + wide domain randomisation",
          "f_calibrated_narrow": "(f) (a) fine-tuned, calibrated + narrow randomisation"}
COLOURS = {"a_nominal": "tab:orange", "b_calibrated": "tab:blue", "c_delta_action": "tab:purple",
           "d_oracle": "tab:green", "e_randomized": "tab:red", "f_calibrated_narrow": "tab:cyan"}


def table(split: dict, sim: dict | None = None, floor: bool = False) -> str:
    """Markdown table of one split's deployments (``{policy: metrics(...)}``), optionally with each policy's MPJPE in
    the simulator it trained in; ``floor``: the floor's metrics."""
    if floor:
        return _floor_table(split, sim)
    head = "| policy | MPJPE [mrad] | foot error [mm] | success | action rate [mrad/step] | torque rate [N m/step] |"
    head += " MPJPE in its training sim [mrad] |" if sim else ""
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    for name, r in split.items():
        m = r["mean"]
        row = (f"| {LABELS.get(name, name)} | {1e3 * m['mpjpe']:.2f} | {1e3 * m['foot_error']:.2f} | "
               f"{100 * m['success']:.0f} % ({m['failures']} failed) | {1e3 * m['action_rate']:.2f} | "
               f"{m.get('torque_rate', float('nan')):.4f} |")
        if sim:
            s = sim.get(name)
            row += f" {1e3 * s['mpjpe']:.2f} |" if s else " – (trained on the real robot) |"
        rows.append(row)
    return "\n".join(rows)


def one_per_family(motions, most: int) -> list[int]:
    """Indices of up to ``most`` motions, one of each family first, in the order they come."""
    picked, seen = [], set()
    for i, m in enumerate(motions):
        if m.family not in seen:
            picked.append(i)
            seen.add(m.family)
    return picked[:most]


def plot_rollouts(ax, t: np.ndarray, ref: np.ndarray, rollouts: dict, get) -> None:
    """The reference (dashed) and ``get(rollout)`` of every policy's rollout in :data:`COLOURS`, against ``t`` [s]."""
    ax.plot(t, ref, "k--", lw=1.5, label="reference")
    for name, dep in rollouts.items():
        if name in COLOURS:
            ax.plot(t, get(dep), color=COLOURS[name], lw=1, label=name)


def plot_tracking(rollouts: dict, motions, robot, path, rate_hz: float, max_motions: int = 4, joints: int = 3) -> Path:
    """Reference vs the real robot's joints under each policy, for up to ``max_motions`` held-out motions (one of each
    family first) and their ``joints`` most moving joints (on the floor: :func:`_plot_floor_tracking`, 5 motions and
    2 joints besides the base's height and tilt)."""
    if next(iter(rollouts.values())).floating:
        return _plot_floor_tracking(rollouts, motions, robot, path, rate_hz)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    picked = one_per_family(motions, max_motions)
    fig, axes = plt.subplots(len(picked), joints, figsize=(4.2 * joints, 2.6 * len(picked)), squeeze=False)
    ref = next(iter(rollouts.values())).q_ref
    for r, i in enumerate(picked):
        order = np.argsort(-np.ptp(ref[i], axis=0))[:joints]
        t = np.arange(ref.shape[1]) / rate_hz
        for c, j in enumerate(order):
            ax = axes[r, c]
            plot_rollouts(ax, t, ref[i, :, j], rollouts, lambda d: d.q[i, :, j])
            ax.set_title(f"{motions[i].name}: {robot.joint_names[j]}", fontsize=9)
            ax.set_xlabel("t [s]")
            ax.set_ylabel("q [rad]")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def randomization_text(results: dict) -> str:
    """The report's paragraph on the domain-randomised policies (e), (f): their ranges (empty without them)."""
    r = results.get("randomization")
    if not r:
        return ""
    text = ("\nDomain randomisation (`wresdyn.skills.randomize`, each world drawn anew at its episode's reset"
            if r["redraw"] == "reset" else "\nDomain randomisation (`wresdyn.skills.randomize`, drawn once per world")
    text += (f", seed {r['seed']}): (e) link masses and inertias ×{r['mass_scale'][0]:g}–{r['mass_scale'][1]:g}, "
             f"{r['com_body']} centre of mass ±{', ±'.join(f'{x:g}' for x in r['com_offset'])} m, kp "
             f"×{r['kp_scale'][0]:g}–{r['kp_scale'][1]:g}, kd ×{r['kd_scale'][0]:g}–{r['kd_scale'][1]:g}, dry friction "
             f"{r['friction'][0]:g}–{r['friction'][1]:g} of the effort limit, armature "
             f"×{r['armature_scale'][0]:g}–{r['armature_scale'][1]:g}, effort limits "
             f"×{r['effort_scale'][0]:g}–{r['effort_scale'][1]:g}, command delay {1e3 * r['delay'][0]:g}–"
             f"{1e3 * r['delay'][1]:g} ms, floor friction {r['floor_friction'][0]:g}–{r['floor_friction'][1]:g} on "
             "the floor (the sources in `Randomization`'s docstrings)")
    return text + (f"; (f) around the identified values, {r['narrow']}.\n" if "narrow" in r else ".\n")


def gaps_text(g: dict) -> str:
    """The gaps closed (``{policy: fraction}``) as one line of the report."""
    return ", ".join(f"{LABELS[k][:3]} **{100 * v:.0f} %**" for k, v in g.items()) or "– (needs the oracle (d))"


def gap_line(split: dict, metric: str = "mpjpe") -> str:
    """The gaps closed on ``metric`` of one split's deployments (``{policy: metrics(...)}``), or, where the ratio
    would flatter, none and why (:func:`~.evaluate.gaps_or_why_not`): "no policy succeeded", or the oracle (d) not
    beating (a)."""
    g, why = gaps_or_why_not(split, metric)
    return f"no gap ratio: {why}" if why else gaps_text(g)


def write_report(out, robot, results: dict, rollouts: dict, motions, policy_rate_hz: float, animation: bool = True):
    """Write ``report.md``, ``tracking_heldout.png`` and (``animation``) ``deployed_heldout.usda`` into ``out``; on the
    floor (rollouts on the floor, ``robot`` with its free base) the floor's report."""
    if next(iter(rollouts.values())).floating:
        return _write_floor_report(out, robot, results, rollouts, motions, policy_rate_hz, animation)
    out = Path(out)
    plot_tracking(rollouts, motions, robot, out / "tracking_heldout.png", policy_rate_hz)
    anim = ""
    if animation:
        i = next((k for k, m in enumerate(motions) if m.family not in ("kick", "squat", "wave")), 0)
        traj = {"reference": rollouts["a_nominal"].q_ref[i]}
        traj.update({n: d.q[i] for n, d in rollouts.items() if n != "reference"})
        write_animation(robot, traj, policy_rate_hz, out / "deployed_heldout.usda")
        anim = (f"\n`deployed_heldout.usda`: held-out motion `{motions[i].name}` on the real robot, side by side along "
                f"+y: {', '.join(traj)}.\n")
    cfg = results["config"]
    text = f"""# Zero-shot skill deployment on the "real" robot

Robot `{robot.source.name}` on its stand; the "real" robot is the MuJoCo model with the dataset's mismatch. Skills:
motion-tracking policies (PPO, rsl-rl) at {policy_rate_hz:g} Hz, PD targets out. Motions per family: train
{cfg['train_per_family']}, validation {cfg['validation_per_family']}, held-out {cfg['heldout_per_family']} (families kick,
squat, wave; the held-out set adds march, a family no policy trained on), {cfg['duration']:g} s each. (a): {cfg['iterations']}
PPO iterations × {cfg['num_worlds']} worlds in the nominal simulator; (b), (c), (d): (a) fine-tuned {cfg['finetune']} iterations.
Every policy is its last iterate; nothing was selected on the real robot or on held-out motions.

## Held-out motions, deployed on the real robot

{table(results['real']['heldout'], results['sim']['heldout'])}

**Gap closed** (a − x) / (a − d) on MPJPE: {gap_line(results['real']['heldout'])} (validation motions:
{gap_line(results['real']['validation'])}).

## Validation motions, deployed on the real robot

{table(results['real']['validation'], results['sim']['validation'])}

## Per held-out motion, MPJPE on the real robot [mrad]

| motion | {' | '.join(results['real']['heldout'])} |
|---|{'---|' * len(results['real']['heldout'])}
""" + "\n".join(
        f"| {m.name} | " + " | ".join(
            f"{1e3 * r['motions'][k]['mpjpe']:.2f}" + ("" if r['motions'][k]['success'] else " (failed)")
            for r in results['real']['heldout'].values()) + " |" for k, m in enumerate(motions)) + f"""

![tracking](tracking_heldout.png)

`tracking_heldout.png`: reference (dashed) and the real robot's joints under (a)-(d), one held-out motion per family.
{anim}
Metrics: MPJPE = mean |q − q_ref| over joints and policy steps of the true joint state; foot error = mean distance of
the soles from the reference's (Pinocchio FK); success = no joint more than the task's fail error from its reference
and no runaway over the whole motion (a failed motion's errors count up to the failure); action rate = mean
|Δ q_cmd| per policy step; torque rate = mean |Δτ| of the real drives per physics step. A gap ratio is printed only
where the oracle (d) beats (a): a lower MPJPE and no lower success.

Corrections: {', '.join(f'{k} `{v}`' for k, v in results['corrections'].items())}. Wall clock: {results['wall_s']:.0f} s (fits {results['fit_wall_s']:.0f} s;
policies {', '.join(f'{k} {v:.0f} s' for k, v in results['train_wall_s'].items())}).
"""
    (out / "report.md").write_text(text + randomization_text(results))


def _floor_table(split: dict, sim: dict | None = None) -> str:
    """Markdown table of one split's floor deployments (``{policy: metrics(...)}``), optionally with each
    policy's MPJPE in the simulator it trained in."""
    head = ("| policy | success | falls | drifts | diverged | MPJPE [mrad] | g-MPJPE [mm] | base orientation [mrad] "
            "| foot slip [mm/s] | action rate [mrad/step] |")
    head += " MPJPE in its training sim [mrad] |" if sim else ""
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    nan = float("nan")
    for name, r in split.items():
        m = r["mean"]
        n = len(r["motions"])
        row = (f"| {LABELS.get(name, name)} | {100 * m['success']:.0f} % ({n - m['failures']}/{n}) | {m['falls']} | "
               f"{m.get('drifts', '–')} | {m.get('diverged', '–')} | "
               f"{1e3 * m.get('mpjpe', nan):.1f} | {1e3 * m.get('g_mpjpe', nan):.0f} | "
               f"{1e3 * m.get('orientation_error', nan):.0f} | {1e3 * m.get('foot_slip', nan):.0f} | "
               f"{1e3 * m.get('action_rate', nan):.1f} |")
        if sim:
            s = sim.get(name)
            gone = " – (trained on the real robot) |" if name == "d_oracle" else " – (its simulator not built here) |"
            row += f" {1e3 * s.get('mpjpe', nan):.1f} |" if s else gone
        rows.append(row)
    return "\n".join(rows)


def _tilt(quat: np.ndarray) -> np.ndarray:
    x, y = quat[..., 0], quat[..., 1]
    return np.arccos(np.clip(1.0 - 2.0 * (x * x + y * y), -1.0, 1.0))


def _plot_floor_tracking(rollouts: dict, motions, robot, path, rate_hz: float, max_motions: int = 5,
                        joints: int = 2) -> Path:
    """Per held-out motion (one of each family first): the reference and the real robot's base height, base tilt
    and its ``joints`` most moving joints under each policy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    picked = one_per_family(motions, max_motions)
    cols = 2 + joints
    fig, axes = plt.subplots(len(picked), cols, figsize=(3.6 * cols, 2.4 * len(picked)), squeeze=False)
    any_dep = next(iter(rollouts.values()))
    for r, i in enumerate(picked):
        t = np.arange(any_dep.q_ref.shape[1]) / rate_hz
        order = np.argsort(-np.ptp(any_dep.q_ref[i], axis=0))[:joints]
        series = [("base height [m]", lambda d: d.base[i, :, 2], any_dep.base_ref[i, :, 2]),
                  ("base tilt [rad]", lambda d: _tilt(d.base[i, :, 3:]), _tilt(any_dep.base_ref[i, :, 3:]))]
        series += [(f"{robot.joint_names[j]} [rad]", lambda d, j=j: d.q[i, :, j], any_dep.q_ref[i, :, j])
                   for j in order]
        for c, (label, get, ref) in enumerate(series):
            ax = axes[r, c]
            plot_rollouts(ax, t, ref, rollouts, get)
            ax.set_title(f"{motions[i].name}: {label}", fontsize=8)
            ax.set_xlabel("t [s]", fontsize=8)
    axes[0, 0].legend(fontsize=6)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _nominal_text(results: dict) -> str:
    """How (a) came to be: trained here, or taken as it is (a shipped policy or another run)."""
    cfg, a = results["config"], results.get("nominal")
    if not a:
        return f"{cfg['iterations']} PPO iterations × {cfg['num_worlds']} worlds in the nominal simulator"
    return (f"`{a['source']}` taken as it is, not trained here ({a['iterations']} PPO iterations × {a['num_worlds']} "
            "worlds in the nominal simulator)")


def _shipped_fit(results: dict) -> str:
    return " (for the shipped (b): at full size, by its own run)" if results.get("shipped") else ""


def _train_count(results: dict) -> str:
    return "none (no policy trained here)" if results.get("shipped") else str(results["config"]["train_per_family"])


def _policies_text(results: dict) -> str:
    """How the policies came to be: (a) and the fine-tunings trained here, or all shipped, trained at full size on a
    GPU elsewhere (their command, commit and policy's hash)."""
    cfg, shipped = results["config"], results.get("shipped")
    if not shipped:
        return (f"(a): {_nominal_text(results)}; (b), (c), (d): (a) fine-tuned {cfg['finetune']} iterations ((d) on "
                f"{cfg['oracle_num_worlds'] or cfg['num_worlds']} worlds).")
    lines = "".join(f"\n- {LABELS.get(n, n)}: `{s['source']}`, {s['iterations']} PPO iterations × {s['num_worlds']} "
                    f"worlds on {s['device']} ({s['machine']}), by `{s['command']}` at commit {s['commit']}; "
                    f"policy.pt sha256 `{s['policy_sha256']}`" for n, s in shipped.items())
    return ("No policy was trained on this machine: (a), (b) and (d) are the ones the package ships, trained at full "
            "size on a GPU ((d) on the real robot of this run's mismatch); this run draws its own motions (seed "
            f"{cfg['seed']}), none of which they trained on:{lines}\n\n")


def _families_text(results: dict) -> str:
    """The held-out families deployed and the rule that chose them, where not all."""
    fam = results.get("heldout_families")
    if not fam:
        return ""
    left = "; ".join(f"{f}: {why}" for f, why in fam["left_out"].items())
    return (f"\n\nHeld-out families deployed: {', '.join(fam['kept'])}, the ones (a) succeeds on in its own simulator "
            f"on every validation motion" + (f" (left out: {left})" if left else "") + ".")


def _write_floor_report(out, floating, results: dict, rollouts: dict, motions, policy_rate_hz: float,
                       animation: bool = True) -> None:
    """Write ``report.md``, ``tracking_heldout.png`` and (``animation``) ``deployed_heldout.usda`` into ``out``."""
    out = Path(out)
    _plot_floor_tracking(rollouts, motions, floating, out / "tracking_heldout.png", policy_rate_hz)
    anim = ""
    if animation:
        i = next((k for k, m in enumerate(motions) if m.family == "step"), 0)
        ref = rollouts["reference"]
        traj = {"reference": np.concatenate([ref.base_ref[i], ref.q_ref[i]], axis=-1)}
        traj.update({n: np.concatenate([d.base[i], d.q[i]], axis=-1) for n, d in rollouts.items()
                     if n != "reference"})
        write_animation(floating, traj, policy_rate_hz, out / "deployed_heldout.usda", spacing=1.5)
        anim = (f"\n`deployed_heldout.usda`: held-out motion `{motions[i].name}` on the real robot's floor, side by side "
                f"along +y: {', '.join(traj)} (a failed rollout holds its last pose).\n")
    cfg, task = results["config"], results["task"]
    held, val = results["real"]["heldout"], results["real"]["validation"]
    extra = "".join(f", {f} (training and validation only)" for f in cfg.get("extra_families", ()))
    text = f"""# Zero-shot skills on the floor, on the "real" robot

Robot `{floating.source.name}` with a free base on a floor; the "real" robot is the MuJoCo C model with the dataset's
mismatch (physics, {1e3 * results['mismatch']['delay']:g} ms delay, torque limits, joint noise) and an IMU with
{task['gyro_noise']:g} rad/s and {task['gravity_noise']:g} noise. The corrections were fitted **on the stand** from the
dataset, with no floor data{_shipped_fit(results)}. Skills: motion-tracking policies (PPO, rsl-rl, asymmetric actor-critic: the actor sees
joint states, the IMU, the reference and its last action) at {policy_rate_hz:g} Hz. Motions per family: train
{_train_count(results)}, validation {cfg['validation_per_family']}, held-out {cfg['heldout_per_family']} (squat,
weight shift, kick, wave{extra}; the held-out set adds stepping in place, a family no policy trained on),
{cfg['duration']:g} s each. {_policies_text(results)} Every
policy is its last iterate; nothing was selected on the real robot or on held-out motions.{_families_text(results)}

## Held-out motions, deployed on the real robot's floor

{_floor_table(results['real']['heldout'], results['sim']['heldout'])}

**Gap closed** (a − x) / (a − d): MPJPE {gap_line(held)}; g-MPJPE {gap_line(held, 'g_mpjpe')} (validation motions:
MPJPE {gap_line(val)}, g-MPJPE {gap_line(val, 'g_mpjpe')}).

## Validation motions, deployed on the real robot's floor

{_floor_table(results['real']['validation'], results['sim']['validation'])}

## Per held-out motion on the real robot: MPJPE [mrad] / g-MPJPE [mm]

| motion | {' | '.join(results['real']['heldout'])} |
|---|{'---|' * len(results['real']['heldout'])}
""" + "\n".join(
        f"| {m.name} | " + " | ".join(
            f"{1e3 * r['motions'][k]['mpjpe']:.1f} / {1e3 * r['motions'][k]['g_mpjpe']:.0f}"
            + ("" if r['motions'][k]['success'] else f" ({r['motions'][k].get('cause') or 'failed'})")
            for r in results['real']['heldout'].values()) + " |" for k, m in enumerate(motions)) + f"""

![tracking](tracking_heldout.png)

`tracking_heldout.png`: reference (dashed) and the real robot under (a)-(d): base height, base tilt and the two most
moving joints, one held-out motion per family.
{anim}
Metrics: success = the motion ran to its end with no fall, no runaway and the base never more than
{task['max_base_error']:g} m from the reference. Failures are counted by kind: a **fall** = the base dropped more than
{task['fall_height']:g} m below its reference height or tilted more than {task['fall_tilt']:g} rad
({np.degrees(task['fall_tilt']):.0f}°) from upright, whichever came first; a **drift** = the base more than
{task['max_base_error']:g} m from the reference's with no fall after it: a drifted robot has failed, but plays on to its
motion's end, and a topple before then counts it as a fall; **diverged** = the simulation ran away. MPJPE = mean
|q − q_ref| of the true joints; g-MPJPE = mean distance of every link's world position from the reference's; base
orientation = mean angle to the reference's; foot slip = mean horizontal speed of the soles
the reference plants; action rate = mean |Δ q_cmd| per policy step. A failed motion's errors count up to its failure;
its cause in the per-motion table: fell_low (base below its reference by the fall height), tilted (both falls),
drifted (base beyond the success radius, no fall after) or diverged. A gap ratio is printed only where the oracle (d)
beats (a): a lower error and no lower success.

Corrections: {', '.join(f'{k} `{v}`' for k, v in results['corrections'].items())}. Wall clock: {results['wall_s']:.0f} s
(fits {results['fit_wall_s']:.0f} s; policies {', '.join(f'{k} {v:.0f} s' for k, v in results['train_wall_s'].items())}).
"""
    (out / "report.md").write_text(text + randomization_text(results))
