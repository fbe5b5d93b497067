"""The zero-shot benchmark on the floor (``wresdyn deploy --floor``): four skills that must keep the humanoid's
balance, each deployed on the "real" robot standing on its floor.

1. Motions (:mod:`wresdyn.skills.floor_motions`): squat, weight shift, kick on one leg, arm waves; stepping in place
   held out.
2. Corrections fitted **on the stand** from the dataset (no floor data): the calibrated robot (a hybrid ``wresdyn
   fit`` run: identified physics + torque residual) and the ASAP-style delta action alone, as
   :mod:`.zero_shot` fits them; on the floor they apply unchanged to the same joints and links.
3. Policies (PPO, rsl-rl, asymmetric actor-critic, :mod:`wresdyn.skills.floor_env`): (a) trained in the nominal
   simulator on the floor; (b) (a) fine-tuned in the calibrated robot on the floor; (c) (a) fine-tuned with the delta
   action; (d) the oracle, (a) fine-tuned on the real robot itself. (b), (c), (d) get the same fine-tuning
   iterations.
4. Deployment (:mod:`wresdyn.skills.floor_evaluate`) of every policy, and of the reference played open loop, on the
   real robot (the mismatch's physics, delay, torque limits, joint and IMU noise) over validation and held-out
   motions. Gap closed = (a − b) / (a − d) on held-out MPJPE and on g-MPJPE.

No choice looks at held-out motions; every policy is its last iterate.
"""

from __future__ import annotations

import time
from dataclasses import asdict, replace
from pathlib import Path

from ..data.mismatch import Mismatch
from ..data.real_robot import RealRobot
from ..robot import load_robot
from ..skills.evaluate import gap_closed
from ..skills.floor_env import FloorTaskConfig, FloorTrackingEnv
from ..skills.floor_evaluate import deploy_floor, floor_metrics
from ..skills.floor_motions import make_floor_motions
from ..skills.floor_report import write_floor_report
from ..skills.plants import RealPlant, sim_plant
from ..skills.skill_ppo import load_skill, train_skill
from .deploy_config import FloorDeployConfig
from .zero_shot import POLICIES, fit_corrections, start_benchmark, write_results

__all__ = ["FloorDeployConfig", "run_floor_benchmark"]


def _train_policy(i: int, name: str, floating, real, motions, task, ppo, cfg: FloorDeployConfig, runs: dict,
                  meta: dict, out: Path, log) -> float:
    """Train policy ``name`` (the ``i``-th of the benchmark: ``a_nominal`` from scratch, the others fine-tuned from it)
    on the floor of its plant; returns the wall-clock time [s]."""
    setting = POLICIES[name]
    t0 = time.perf_counter()
    envs = cfg.oracle_worlds if setting == "real" else cfg.envs
    if setting == "real":
        plant = RealPlant(real, envs, task.decimation, seed=cfg.seed + 1, imu_noise=(task.gyro_noise, task.gravity_noise))
    else:
        plant = sim_plant(setting, floating, envs, real.rate_hz, task.decimation, runs.get(setting), cfg.device,
                          ground=True)
    env = FloorTrackingEnv(plant, motions, task, seed=cfg.seed + i, device=cfg.device)
    run_meta = {**meta, "setting": setting, "correction": str(runs.get(setting, ""))}
    it = cfg.iterations if i == 0 else cfg.finetune
    train_skill(env, replace(ppo, iterations=it, num_envs=envs, restart_std=None if i == 0 else cfg.finetune_std),
                out / "skills" / name, log=log, init=None if i == 0 else out / "skills" / "a_nominal", meta=run_meta)
    wall = time.perf_counter() - t0
    log(f"[3/4] policy {name}: {it} PPO iterations x {envs} worlds on the floor of the {setting} "
        f"{'robot' if setting == 'real' else 'simulator'} ({wall:.0f} s)")
    return wall


def _train_beside(source: str, gains, mismatch: dict, rate: float, i: int, name: str, device: str, motions, task,
                  ppo, cfg, runs, meta, out: Path) -> float:
    """:func:`_train_policy` in a process of its own, its PPO and simulated plant on ``device`` (its lines go to its
    ``train.log`` only)."""
    import torch

    if ppo.torch_threads is not None:
        torch.set_num_threads(ppo.torch_threads)
    floating = load_robot(source, gains=gains, base="floating")
    real = RealRobot(floating, Mismatch.from_dict(mismatch, "the benchmark's mismatch"), rate)
    return _train_policy(i, name, floating, real, motions, task, replace(ppo, device=device),
                         replace(cfg, device=device), runs, meta, out, lambda s: None)


def run_floor_benchmark(robot, dataset, out, cfg: FloorDeployConfig = FloorDeployConfig(), *, data_path=None,
                        calibrated=None, delta=None, mismatch=None, task=None, ppo=None, animation: bool = True,
                        policies=tuple(POLICIES), log=print) -> dict:
    """Run the floor benchmark into ``out`` (resumable: finished fits and policies are reused, PPO resumes).

    Args:
        robot: The nominal robot on its stand (fixed base); its floating twin is loaded from the same file.
        dataset: The stand recordings the corrections are fitted on.
        cfg: Sizes. task: :class:`~wresdyn.skills.skill_config.FloorTaskConfig`;
            ppo: :class:`~wresdyn.skills.skill_config.SkillPPOConfig` (its size fields are set from ``cfg``).
        calibrated, delta: Existing run folders of the two corrections (default: fitted into ``out``).
        mismatch: The real robot's :class:`~wresdyn.data.mismatch.Mismatch` (default: the dataset's).
        policies: Which of :data:`~.zero_shot.POLICIES` to train and deploy (``a_nominal`` always).

    Returns:
        The results written to ``results.json``.
    """
    t_start = time.perf_counter()
    out = Path(out)
    task = task or FloorTaskConfig()
    policies, ppo, mismatch, counts = start_benchmark(out, cfg, ppo, mismatch, dataset, policies)
    floating = load_robot(robot.source, gains=robot.gains, base="floating")
    rate = float(dataset.rate_hz)
    motions = make_floor_motions(robot, floating, counts, cfg.duration, rate, cfg.seed, extra=cfg.extra_families)
    log("[1/4] floor motions: " + ", ".join(f"{s} {len(motions[s])}" for s in counts)
        + f" of {cfg.duration:g} s at {rate:g} Hz (policy at {rate / task.decimation:g} Hz)")
    t0 = time.perf_counter()
    calibrated, delta = fit_corrections(dataset, data_path, robot, out, calibrated, delta, cfg.device, log,
                                         need_delta="c_delta_action" in policies)
    fit_s = time.perf_counter() - t0
    log(f"[2/4] corrections fitted on the stand: calibrated {calibrated}, delta action {delta} ({fit_s:.0f} s)")
    real = RealRobot(floating, mismatch, rate)
    imu = (task.gyro_noise, task.gravity_noise)
    runs = {"calibrated": calibrated, "delta_action": delta}
    meta = {"motions": {"seed": cfg.seed, "counts": counts, "duration": cfg.duration, "floor": True}}
    if cfg.extra_families:  # a run without them keeps the meta of the runs before the option
        meta["motions"]["extra"] = list(cfg.extra_families)
    wall = {}
    # With PPO on a GPU the oracle's real robot (MuJoCo C on the host's cores) trains beside (b) and (c), and with
    # more GPUs the simulated fine-tunings after (b) each on one of them: all start as soon as (a), which they are
    # fine-tuned from, is done.
    oracle_beside = cfg.device != "cpu" if cfg.oracle_beside is None else cfg.oracle_beside
    beside = {"d_oracle": cfg.device} if oracle_beside and "d_oracle" in policies[2:] else {}
    simulated = [p for p in policies[2:] if POLICIES[p] != "real"]
    beside.update(zip(simulated, cfg.beside_devices))
    index = {name: i for i, name in enumerate(policies)}
    pool, jobs = None, {}
    try:
        for name in policies:
            if name in beside:
                continue
            wall[name] = _train_policy(index[name], name, floating, real, motions["train"], task, ppo, cfg, runs, meta,
                                       out, log)
            if name == "a_nominal" and beside:
                import multiprocessing as mp

                pool = mp.get_context("spawn").Pool(len(beside))
                for other, device in beside.items():
                    jobs[other] = pool.apply_async(_train_beside, (
                        str(robot.source), robot.gains, mismatch.to_dict(), rate, index[other], other, device,
                        motions["train"], task, ppo, cfg, runs, meta, out))
                    where = "on the real robot" if other == "d_oracle" else f"on {device}"
                    log(f"[3/4] policy {other}: training {where} beside the others "
                        f"({out / 'skills' / other / 'train.log'})")
        for other, job in jobs.items():
            wall[other] = job.get()
            setting = POLICIES[other]
            envs, plant = (cfg.oracle_worlds, "real robot") if setting == "real" else (cfg.envs, f"{setting} simulator")
            where = "" if setting == "real" else f" on {beside[other]}"
            log(f"[3/4] policy {other}: {cfg.finetune} PPO iterations x {envs} worlds on the floor of the {plant} "
                f"({wall[other]:.0f} s{where}, beside the others)")
    finally:
        if pool is not None:
            pool.terminate()
    results = {"config": asdict(cfg), "task": asdict(task), "ppo": asdict(ppo), "mismatch": mismatch.to_dict(),
               "policies": policies, "corrections": {k: str(v) for k, v in runs.items() if v is not None},
               "train_wall_s": wall, "fit_wall_s": fit_s, "real": {}, "sim": {}}
    rollouts = {}
    for split in ("validation", "heldout"):
        mot = motions[split]
        results["real"][split], results["sim"][split] = {}, {}
        for name in ("reference", *policies):
            policy = None if name == "reference" else load_skill(out / "skills" / name)
            plant = RealPlant(real, len(mot), task.decimation, seed=cfg.seed + 100, imu_noise=imu)
            dep = deploy_floor(policy, plant, mot, task)
            results["real"][split][name] = floor_metrics(dep)
            if split == "heldout":
                rollouts[name] = dep
            setting = POLICIES.get(name, "nominal")
            if setting != "real":
                plant = sim_plant(setting, floating, len(mot), rate, task.decimation, runs.get(setting), cfg.device,
                                  ground=True)
                results["sim"][split][name] = floor_metrics(deploy_floor(policy, plant, mot, task))["mean"]
    for split, suffix in (("heldout", ""), ("validation", "_validation")):
        for metric in ("mpjpe", "g_mpjpe"):
            mean = {n: r["mean"].get(metric, float("nan")) for n, r in results["real"][split].items()}
            results[f"gap_closed{suffix}_{metric}"] = {
                k: gap_closed(mean["a_nominal"], mean[k], mean["d_oracle"])
                for k in ("b_calibrated", "c_delta_action") if k in mean and "d_oracle" in mean}
    held = results["real"]["heldout"]
    log("[4/4] deployed on the real robot's floor (" + f"{len(motions['heldout'])} held-out motions): " + "; ".join(
        f"{n} success {100 * r['mean']['success']:.0f} % ({r['mean']['falls']} falls), MPJPE "
        f"{1e3 * r['mean'].get('mpjpe', float('nan')):.1f} mrad, g-MPJPE {1e3 * r['mean'].get('g_mpjpe', float('nan')):.0f} mm"
        for n, r in held.items()) + "".join(
        f"; gap closed by {k[0]} {100 * v:.0f} % (MPJPE)" for k, v in results["gap_closed_mpjpe"].items()))
    results["wall_s"] = time.perf_counter() - t_start
    write_floor_report(out, floating, results, rollouts, motions["heldout"], rate / task.decimation,
                       animation=animation)
    write_results(out, results)
    log(f"wrote {out / 'report.md'} and {out / 'results.json'}")
    return results
