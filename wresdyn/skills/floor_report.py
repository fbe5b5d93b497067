"""``report.md`` of the floor benchmark: the table, tracking plots (joints, base height and tilt) and the USD
animation of the four deployed rollouts side by side on the floor."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..evaluation.animation import write_animation
from .report import LABELS, gaps_text, one_per_family, plot_rollouts

__all__ = ["write_floor_report", "floor_table", "plot_floor_tracking"]


def floor_table(split: dict, sim: dict | None = None) -> str:
    """Markdown table of one split's floor deployments (``{policy: floor_metrics(...)}``), optionally with each
    policy's MPJPE in the simulator it trained in."""
    head = ("| policy | success | falls | MPJPE [mrad] | g-MPJPE [mm] | base orientation [mrad] | foot slip [mm/s] "
            "| action rate [mrad/step] |")
    head += " MPJPE in its training sim [mrad] |" if sim else ""
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    nan = float("nan")
    for name, r in split.items():
        m = r["mean"]
        n = len(r["motions"])
        row = (f"| {LABELS.get(name, name)} | {100 * m['success']:.0f} % ({n - m['failures']}/{n}) | {m['falls']} | "
               f"{1e3 * m.get('mpjpe', nan):.1f} | {1e3 * m.get('g_mpjpe', nan):.0f} | "
               f"{1e3 * m.get('orientation_error', nan):.0f} | {1e3 * m.get('foot_slip', nan):.0f} | "
               f"{1e3 * m.get('action_rate', nan):.1f} |")
        if sim:
            s = sim.get(name)
            row += f" {1e3 * s.get('mpjpe', nan):.1f} |" if s else " – (trained on the real robot) |"
        rows.append(row)
    return "\n".join(rows)


def _tilt(quat: np.ndarray) -> np.ndarray:
    x, y = quat[..., 0], quat[..., 1]
    return np.arccos(np.clip(1.0 - 2.0 * (x * x + y * y), -1.0, 1.0))


def plot_floor_tracking(rollouts: dict, motions, robot, path, rate_hz: float, max_motions: int = 5,
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


def write_floor_report(out, floating, results: dict, rollouts: dict, motions, policy_rate_hz: float,
                       animation: bool = True) -> None:
    """Write ``report.md``, ``tracking_heldout.png`` and (``animation``) ``deployed_heldout.usda`` into ``out``."""
    out = Path(out)
    plot_floor_tracking(rollouts, motions, floating, out / "tracking_heldout.png", policy_rate_hz)
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
    extra = "".join(f", {f} (training and validation only)" for f in cfg.get("extra_families", ()))
    text = f"""# Zero-shot skills on the floor, on the "real" robot

Robot `{floating.source.name}` with a free base on a floor; the "real" robot is the MuJoCo C model with the dataset's
mismatch (physics, {1e3 * results['mismatch']['delay']:g} ms delay, torque limits, joint noise) and an IMU with
{task['gyro_noise']:g} rad/s and {task['gravity_noise']:g} noise. The corrections were fitted **on the stand** from the
dataset, with no floor data. Skills: motion-tracking policies (PPO, rsl-rl, asymmetric actor-critic: the actor sees
joint states, the IMU, the reference and its last action) at {policy_rate_hz:g} Hz. Motions per family: train
{cfg['train_per_family']}, validation {cfg['validation_per_family']}, held-out {cfg['heldout_per_family']} (squat,
weight shift, kick, wave{extra}; the held-out set adds stepping in place, a family no policy trained on),
{cfg['duration']:g} s each. (a): {cfg['iterations']} PPO iterations × {cfg['envs']} worlds in the nominal simulator;
(b), (c), (d): (a) fine-tuned {cfg['finetune']} iterations ((d) on {cfg['oracle_envs'] or cfg['envs']} worlds). Every
policy is its last iterate; nothing was selected on the real robot or on held-out motions.

## Held-out motions, deployed on the real robot's floor

{floor_table(results['real']['heldout'], results['sim']['heldout'])}

**Gap closed** (a − x) / (a − d): MPJPE {gaps_text(results['gap_closed_mpjpe'])}; g-MPJPE
{gaps_text(results['gap_closed_g_mpjpe'])} (validation motions: MPJPE {gaps_text(results['gap_closed_validation_mpjpe'])},
g-MPJPE {gaps_text(results['gap_closed_validation_g_mpjpe'])}).

## Validation motions, deployed on the real robot's floor

{floor_table(results['real']['validation'], results['sim']['validation'])}

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
Metrics: success = the motion ran to its end with no fall (base more than {task['fall_height']:g} m below its
reference or tilted past {task['fall_tilt']:g} rad) and the base never more than {task['max_base_error']:g} m from the
reference; MPJPE = mean |q − q_ref| of the true joints; g-MPJPE = mean distance of every link's world position from
the reference's; base orientation = mean angle to the reference's; foot slip = mean horizontal speed of the soles
the reference plants; action rate = mean |Δ q_cmd| per policy step. A failed motion's errors count up to its failure;
its cause in the per-motion table: fell_low (base below its reference by the fall height), tilted, drifted (base
beyond the success radius) or diverged.

Corrections: {', '.join(f'{k} `{v}`' for k, v in results['corrections'].items())}. Wall clock: {results['wall_s']:.0f} s
(fits {results['fit_wall_s']:.0f} s; policies {', '.join(f'{k} {v:.0f} s' for k, v in results['train_wall_s'].items())}).
"""
    (out / "report.md").write_text(text)
