"""The zero-shot deployment benchmark (``wresdyn deploy``): four skill policies, each deployed on the "real" robot.

1. Motions (:mod:`wresdyn.skills.motions`): training, validation and held-out draws of the training families, plus a
   held-out family.
2. The corrected simulators: the calibrated robot (a hybrid ``wresdyn fit`` run: identified physics + torque residual)
   and the ASAP-style delta-action residual alone (``wresdyn fit --model network --residual delta_action``); both
   fitted here on the dataset when not given (:mod:`.zero_shot`).
3. Policies (PPO, rsl-rl, :mod:`wresdyn.skills.skill_ppo`): (a) trained in the nominal simulator; (b) (a) fine-tuned
   in the calibrated one; (c) (a) fine-tuned with the delta-action residual; (d) the oracle, (a) fine-tuned on the
   "real" robot itself (:class:`~wresdyn.skills.plants.RealPlant`). (b), (c) and (d) get the same number of
   fine-tuning iterations.
4. Deployment (:mod:`wresdyn.skills.evaluate`): every policy, and the reference played open loop, on the "real" robot
   (the dataset's mismatch) over the validation and held-out motions; each policy also in the simulator it was
   trained in. Gap closed = (a − b) / (a − d) on held-out MPJPE. ``report.md``, ``results.json``, tracking plots and
   a USD animation of the held-out rollouts side by side.

No choice here looks at held-out motions: the task and PPO settings were set on validation motions, and every policy
is its last iterate (no checkpoint selection on the real robot, which a user could not do before deploying).
"""

from __future__ import annotations

import time
from dataclasses import asdict, replace
from pathlib import Path

from ..data.real_robot import RealRobot
from ..skills.env import SkillConfig, TrackingEnv
from ..skills.evaluate import deploy_skill, gap_closed, metrics
from ..skills.motions import make_motions
from ..skills.plants import RealPlant, sim_plant
from ..skills.report import write_report
from ..skills.skill_ppo import load_skill, train_skill
from .deploy_config import DeployConfig
from .zero_shot import POLICIES, fit_corrections, start_benchmark, write_results

__all__ = ["DeployConfig", "run_benchmark"]


def run_benchmark(robot, dataset, out, cfg: DeployConfig = DeployConfig(), *, data_path=None, calibrated=None,
                  delta=None, mismatch=None, task=None, ppo=None, animation: bool = True, policies=tuple(POLICIES),
                  log=print) -> dict:
    """Run the benchmark into ``out`` (resumable: finished fits and policies are reused, PPO resumes).

    Args:
        robot: The nominal robot (fixed base).
        dataset: The recordings the corrections are fitted on (:class:`~wresdyn.data.dataset.Dataset`).
        out: Output folder.
        cfg: Sizes.
        data_path: Where ``dataset`` was read from (recorded in the fitted runs).
        calibrated, delta: Existing run folders of the two corrections (default: fitted into ``out``).
        mismatch: The "real" robot's :class:`~wresdyn.data.mismatch.Mismatch` (default: the dataset's).
        task: :class:`~wresdyn.skills.skill_config.SkillConfig`;
            ppo: :class:`~wresdyn.skills.skill_config.SkillPPOConfig` (its size fields are set from ``cfg``).
        policies: Which of :data:`~.zero_shot.POLICIES` to train and deploy (``a_nominal`` always; without
            ``c_delta_action`` no delta-action residual is fitted; the gap closed needs ``d_oracle``).

    Returns:
        The results written to ``results.json``.
    """
    t_start = time.perf_counter()
    out = Path(out)
    task = task or SkillConfig()
    policies, ppo, mismatch, counts = start_benchmark(out, cfg, ppo, mismatch, dataset, policies)
    rate = float(dataset.rate_hz)
    motions = make_motions(robot, counts, cfg.duration, rate, cfg.seed)
    log("[1/4] motions: " + ", ".join(f"{s} {len(motions.split(s))}" for s in counts)
        + f" of {cfg.duration:g} s at {rate:g} Hz (policy at {rate / task.decimation:g} Hz)")
    t0 = time.perf_counter()
    calibrated, delta = fit_corrections(dataset, data_path, robot, out, calibrated, delta, cfg.device, log,
                                         need_delta="c_delta_action" in policies)
    fit_s = time.perf_counter() - t0
    log(f"[2/4] corrections: calibrated {calibrated}, delta action {delta} ({fit_s:.0f} s)")
    real = RealRobot(robot, mismatch, rate)
    runs = {"calibrated": calibrated, "delta_action": delta}
    meta = {"motions": {"seed": cfg.seed, "counts": counts, "duration": cfg.duration}}
    wall = {}
    for i, name in enumerate(policies):
        setting = POLICIES[name]
        t0 = time.perf_counter()
        envs = cfg.oracle_worlds if setting == "real" else cfg.envs
        if setting == "real":
            plant = RealPlant(real, envs, task.decimation, seed=cfg.seed + 1)
        else:
            plant = sim_plant(setting, robot, envs, rate, task.decimation, runs.get(setting), cfg.device)
        env = TrackingEnv(plant, motions.split("train"), task, seed=cfg.seed + i, device=cfg.device)
        run_meta = {**meta, "setting": setting, "correction": str(runs.get(setting, ""))}
        it = cfg.iterations if i == 0 else cfg.finetune
        train_skill(env, replace(ppo, iterations=it, num_envs=envs, restart_std=None if i == 0 else cfg.finetune_std),
                    out / "skills" / name, log=log,
                    init=None if i == 0 else out / "skills" / "a_nominal", meta=run_meta)
        wall[name] = time.perf_counter() - t0
        log(f"[3/4] policy {name}: {it} PPO iterations x {envs} worlds in the {setting} "
            f"{'robot' if setting == 'real' else 'simulator'} ({wall[name]:.0f} s)")
    results = {"config": asdict(cfg), "task": asdict(task), "ppo": asdict(ppo), "mismatch": mismatch.to_dict(),
               "policies": policies, "corrections": {k: str(v) for k, v in runs.items() if v is not None}, "train_wall_s": wall, "fit_wall_s": fit_s,
               "real": {}, "sim": {}}
    rollouts = {}
    for split in ("validation", "heldout"):
        mot = motions.split(split)
        results["real"][split], results["sim"][split] = {}, {}
        for name in ("reference", *policies):
            policy = None if name == "reference" else load_skill(out / "skills" / name)
            dep = deploy_skill(policy, RealPlant(real, len(mot), task.decimation, seed=cfg.seed + 100), mot, task)
            results["real"][split][name] = metrics(dep, robot)
            if split == "heldout":
                rollouts[name] = dep
            setting = POLICIES.get(name, "nominal")
            if setting != "real":
                plant = sim_plant(setting, robot, len(mot), rate, task.decimation, runs.get(setting), cfg.device)
                results["sim"][split][name] = metrics(deploy_skill(policy, plant, mot, task), robot)["mean"]
    for split, key in (("heldout", "gap_closed"), ("validation", "gap_closed_validation")):
        mean = {n: r["mean"]["mpjpe"] for n, r in results["real"][split].items()}
        results[key] = {k: gap_closed(mean["a_nominal"], mean[k], mean["d_oracle"])
                        for k in ("b_calibrated", "c_delta_action") if k in mean and "d_oracle" in mean}
    mean = {n: r["mean"]["mpjpe"] for n, r in results["real"]["heldout"].items()}
    log(f"[4/4] deployed on the real robot ({len(motions.split('heldout'))} held-out motions), MPJPE: " + ", ".join(
        f"{n} {1e3 * v:.1f} mrad" for n, v in mean.items()) + "".join(
        f"; gap closed by {k[0]} {100 * v:.0f} %" for k, v in results["gap_closed"].items()))
    results["wall_s"] = time.perf_counter() - t_start
    write_report(out, robot, results, rollouts, motions.split("heldout"), rate / task.decimation, animation=animation)
    write_results(out, results)
    log(f"wrote {out / 'report.md'} and {out / 'results.json'}")
    return results

