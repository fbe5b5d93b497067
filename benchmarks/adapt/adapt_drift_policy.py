"""A deployed skill as the drift benchmark's motion (``adapt_drift.py --motion policy --policy SKILL_RUN``).

A stand tracking policy trained by ``wresdyn deploy`` (a ``skills/<name>/`` folder: ``policy.pt``, ``config.json``)
runs closed loop on the drifting "real" robot with the skills' own deployment code
(:func:`wresdyn.skills.evaluate.deploy` on a :class:`wresdyn.skills.plants.RealPlant`, one world), tracking one
long reference (the skill motions in turn). :class:`DriftingPlant` sits between the two: before every policy step it
calls the benchmark's hook with the step's first sample (the drift changes the plant's MuJoCo model there, as
``RealRobot.record``'s ``on_sample`` does at every sample), and it keeps the log a robot would write at the recording
rate: the sensed joint state at every sample and the PD target the policy commanded, held for the policy period.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

NEVER = 1e9
"""A failure rule that never fires [rad] (the task's must be a finite number)."""


@dataclass
class PolicyRun:
    """The drifting robot under the policy: its log at the recording rate and the policy's tracking."""

    q: np.ndarray
    """Sensed joint positions [rad] (T, n), sample k at t = k / rate."""
    qd: np.ndarray
    """Sensed joint velocities [rad/s] (T, n)."""
    q_cmd: np.ndarray
    """The policy's PD target held from sample k to k + 1 [rad] (T, n)."""
    tracking: np.ndarray
    """The policy's tracking error: mean over joints of |q_true - q_ref| at the end of each policy step [rad] (K,)."""
    step_t: np.ndarray
    """Robot time at the end of each policy step [s] (K,)."""
    joint_error: np.ndarray
    """Each joint's |q_true - q_ref| at the end of each policy step [rad] (K, n)."""
    worst: np.ndarray
    """The largest joint's |q_true - q_ref| at the end of each policy step [rad] (K,)."""
    fail_error: float
    """The skill task's failure rule [rad]: an episode would have ended where ``worst`` exceeds it."""


class DriftingPlant:
    """A one-world :class:`~wresdyn.skills.plants.RealPlant` that calls ``hook(k, model)`` before each step (``k``:
    the step's first sample) and logs every sample of the stream; every other attribute is the plant's."""

    def __init__(self, plant, hook, rng: np.random.Generator) -> None:
        if plant.num_worlds != 1:
            raise ValueError(f"one robot drifts: the plant has {plant.num_worlds} worlds")
        self.plant, self.hook, self.rng = plant, hook, rng
        self.k = 0
        """Samples logged so far."""
        self.resets = 0
        self.q, self.qd, self.cmd = [], [], []
        self._sensed = None  # what the plant's sensors reported at the end of the last step (the next step's first)

    def __getattr__(self, name):
        return getattr(self.plant, name)

    def reset(self, ids, q, qd) -> None:
        self.resets += 1
        self.plant.reset(ids, q, qd)

    def step(self, cmd):
        p = self.plant
        self.hook(self.k, p.real.model)
        q, qd, bad = p.step(cmd)
        # the samples inside the step pass the sensors here; its first is what the plant reported after the last step
        qs, qds = p.real.sense(p.q_samples[0], p.qd_samples[0], self.rng)
        if self._sensed is not None:
            qs[0], qds[0] = self._sensed
        self._sensed = (q[0].double().numpy(), qd[0].double().numpy())
        self.q.append(qs)
        self.qd.append(qds)
        self.cmd.append(np.repeat(np.asarray(cmd[0].detach().cpu(), np.float64)[None], p.decimation, 0))
        self.k += p.decimation
        return q, qd, bad


def skill_task(skill_dir):
    """The tracking task a skill run was trained on (its ``config.json``'s ``task``), a
    :class:`~wresdyn.skills.env.SkillConfig`."""
    from wresdyn.skills.env import SkillConfig

    task = json.loads((Path(skill_dir) / "config.json").read_text())["task"]
    return SkillConfig(**{f.name: task[f.name] for f in fields(SkillConfig) if f.name in task})


def policy_stream(skill_dir, real, hook, ref_q: np.ndarray, ref_feet: np.ndarray, rate: float, seed: int
                  ) -> PolicyRun:
    """Run the skill of ``skill_dir`` closed loop on ``real`` (a :class:`~wresdyn.data.real_robot.RealRobot`, on its
    stand) over the reference ``ref_q`` [rad] (T, n) (soles ``ref_feet`` [m] (T, n_feet, 3)), from rest in its first
    sample; ``hook(k, model)`` before every policy step. ``seed``: the sensor noise. The log holds (T - 1) // decimation
    policy steps of samples; the task's failure rule does not stop the run (only a robot that runs away does)."""
    import torch

    from wresdyn.skills.evaluate import deploy
    from wresdyn.skills.motions import Motion
    from wresdyn.skills.plants import RealPlant
    from wresdyn.skills.skill_ppo import load_skill

    task = skill_task(skill_dir)
    policy = load_skill(skill_dir)
    motion = Motion("drift_reference", "cycle", ref_q, np.gradient(ref_q, 1.0 / rate, axis=0), ref_feet)
    plant = DriftingPlant(RealPlant(real, 1, task.decimation, seed=seed, threads=1), hook,
                          np.random.default_rng([seed, 1]))
    # a robot at work does not stop where a training episode would end: the run goes on past the task's failure
    # rule (a joint fail_error from its reference); where it would have fired is reported (PolicyRun.worst)
    with torch.no_grad():
        dep = deploy(policy, plant, [motion], replace(task, fail_error=NEVER))
    if dep.failed_at[0] >= 0:
        raise SystemExit(f"{skill_dir}: the real robot ran away {dep.failed_at[0] * task.decimation / rate:.2f} s "
                         "into the run")
    err = np.abs(dep.q[0, 1:] - dep.q_ref[0, 1:])
    cat = np.concatenate
    return PolicyRun(cat(plant.q), cat(plant.qd), cat(plant.cmd), err.mean(-1),
                     np.arange(1, len(err) + 1) * task.decimation / rate, err, err.max(-1), task.fail_error)


def policy_tracking(run, phase, path, log, joint_names, motions) -> dict:
    """The policy's own tracking error (mean |q_true - q_ref| over joints and policy steps [rad]) per second
    (written to ``path``) and per phase, and where a joint crossed the task's failure rule: per joint (of
    ``joint_names``) and per motion (``motions``: the reference motion of each policy step's end, (K,))."""
    sec = np.floor(run.step_t - 1e-9).astype(int)  # a step ending at t lies in the second before t
    per = {int(s): float(run.tracking[sec == s].mean()) for s in np.unique(sec)}
    with open(path, "w") as f:
        f.write("t,phase,mpjpe\n" + "".join(f"{s},{phase(s)},{v:.6f}\n" for s, v in per.items()))
    out = {}
    for ph in ("none", "ramp", "friction", "payload", "derate"):
        sel = [v for s, v in per.items() if phase(s) == ph]
        if sel:
            out[ph] = float(np.mean(sel))
    log("policy tracking error (mean |q - q_ref| [rad]): " + "  ".join(f"{k} {v:.5f}" for k, v in out.items()))
    over = run.worst > run.fail_error
    fails = sorted({int(s) for s in sec[over]})
    worst = {ph: float(run.worst[[phase(s) == ph for s in sec]].max()) for ph in out}
    log(f"a joint more than {run.fail_error:g} rad from its reference (the task's failure rule) in "
        f"{int(over.sum())} policy steps, in the seconds {fails or 'none'}; worst per phase: " + "  ".join(
            f"{ph} {v:.3f}" for ph, v in worst.items()))
    by_joint = {joint_names[j]: int(c) for j, c in enumerate((run.joint_error > run.fail_error).sum(0)) if c}
    names, counts = np.unique(motions[over], return_counts=True)
    by_motion = {str(m): int(c) for m, c in zip(names, counts)}
    log(f"  by joint: {by_joint}; by motion: {by_motion}")
    return {"mpjpe_phases": out, "fail_error": run.fail_error, "failure_steps": int(over.sum()),
            "failure_joint_steps": by_joint, "failure_motion_steps": by_motion,
            "failure_seconds": fails, "worst_phases": worst}
