"""The zero-shot skill benchmark (``wresdyn deploy``, ``wresdyn deploy --floor``): four skill policies, each deployed on
the "real" robot, on its stand or standing on its floor (the task config's variant,
:class:`~wresdyn.skills.skill_config.SkillTaskConfig`).

1. Motions (:mod:`wresdyn.skills.motions`): training, validation and held-out draws of the task's training families,
   plus a held-out family (the stand's march; on the floor squat, weight shift, kick on one leg and arm waves, with
   stepping in place held out).
2. The corrections, fitted **on the stand** from the dataset (no floor data; on the floor they apply unchanged to the
   same joints and links): the calibrated robot (a hybrid ``wresdyn fit`` run: identified physics + torque residual)
   and the ASAP-style delta-action residual alone (``wresdyn fit --model network --residual delta_action``); both
   fitted here when not given (:mod:`.zero_shot`).
3. Policies (PPO, rsl-rl, :mod:`wresdyn.skills.skill_ppo`; on the floor an asymmetric actor-critic): (a) trained in the
   nominal simulator; (b) (a) fine-tuned in the calibrated one; (c) (a) fine-tuned with the delta-action residual;
   (d) the oracle, (a) fine-tuned on the "real" robot itself (:class:`~wresdyn.skills.plants.RealPlant`, or the same
   robot batched on the GPU, :class:`~wresdyn.skills.real_warp.RealWarpPlant`); asked for by name, the
   domain-randomised baselines (:mod:`wresdyn.skills.randomize`): (e) (a) fine-tuned in the nominal simulator over the
   peers' wide ranges, (f) (a) fine-tuned in the calibrated one over narrow ranges from its identification. (b)-(f) get
   the same number of fine-tuning iterations on the same worlds ((e) fine-tuned rather than trained from scratch: it
   then differs from (b) in the simulator alone).
4. Deployment (:mod:`wresdyn.skills.evaluate`): every policy, and the reference played open loop, on the "real" robot
   (the dataset's mismatch; on the floor its IMU's noise too) over the validation and held-out motions; each policy
   also in the simulator it was trained in. Gap closed = (a − b) / (a − d) on held-out MPJPE (on the floor also on
   g-MPJPE); each deployment is kept in the run folder as it ends and read back on a rerun
   (:mod:`wresdyn.skills.deployment_store`). ``report.md``, ``results.json``, tracking plots and a USD animation of
   the held-out rollouts side by side.

No choice here looks at held-out motions: the task and PPO settings were set on validation motions, and every policy
is its last iterate (no checkpoint selection on the real robot, which a user could not do before deploying).
"""

from __future__ import annotations

import time
from dataclasses import asdict, replace
from pathlib import Path

from ..data.mismatch import Mismatch
from ..data.real_robot import RealRobot
from ..errors import WresdynError
from ..learn.runs import run_physics
from ..robot import load_robot
from ..skills.env import TrackingEnv
from ..skills.deployment_store import DeploymentStore, deploy_all, run_fingerprint
from ..skills.evaluate import gap_closed, gaps_or_why_not
from ..skills.ledger import LEDGER, ledger_table
from ..skills.motion_store import MotionStore, motion_fingerprint
from ..skills.motions import MotionSet, make_motions
from ..skills.plants import RealPlant, sim_plant
from ..skills.real_warp import RealWarpPlant
from ..skills.randomize import Randomization, narrow_ranges
from ..skills.report import write_report
from ..skills.skill_config import FloorTaskConfig, SkillConfig
from ..skills.shipped import install_policy
from ..skills.skill_ppo import finished_skill, load_skill, train_skill
from .deploy_config import DeployConfig, FloorDeployConfig
from .nominal_policy import balanced_families, check_installed, draw_heldout, installed_from, installed_record, \
    nominal_source
from .zero_shot import BASE_POLICIES, POLICIES, RANDOMIZED, fit_corrections, start_benchmark, write_results

__all__ = ["DeployConfig", "FloorDeployConfig", "run_benchmark"]


def _plants(task, real, robot, rate: float, runs: dict, device: str, dr: Randomization | None = None):
    """The plant makers of a task: ``real(worlds, seed)`` (with the IMU's noise on the floor) and
    ``sim(setting, worlds)`` (on the floor with ``ground``; a :data:`~.zero_shot.RANDOMIZED` setting with ``dr``)."""

    def real_plant(worlds: int, seed: int) -> RealPlant:
        return RealPlant(real, worlds, task.decimation, seed=seed, imu_noise=_imu_noise(task))

    def sim(setting: str, worlds: int):
        randomization = None
        if setting in RANDOMIZED:
            setting, cfg = RANDOMIZED[setting], dr or Randomization()
            randomization = cfg
            if setting == "calibrated":
                run = runs.get(setting)
                randomization = (cfg, narrow_ranges(cfg, robot, run_physics(run, robot), run)[0])
        return sim_plant(setting, robot, worlds, rate, task.decimation, runs.get(setting), device, ground=task.floating,
                         randomization=randomization)

    return real_plant, sim


def _own_sim(setting: str, runs: dict) -> str | None:
    """The simulator a policy is deployed in besides the real robot: ``None`` where it has none here (a shipped
    policy whose correction this run does not build)."""
    return None if setting != "real" and runs.get(setting, setting) is None else setting


def _imu_noise(task) -> tuple[float, float]:
    """The real robot's IMU noise (floor), off on the stand."""
    return (task.gyro_noise, task.gravity_noise) if task.floating else (0.0, 0.0)


def _run_of(i: int, name: str, ppo, cfg, runs: dict, meta: dict, out: Path, dr: Randomization | None):
    """What policy ``name`` (the ``i``-th) trains into: its run folder, PPO config, the run it is fine-tuned from
    (``None`` for ``a_nominal``) and the meta its ``config.json`` records."""
    setting = POLICIES[name]
    run_meta = {**meta, "setting": setting, "correction": str(runs.get(RANDOMIZED.get(setting, setting), ""))}
    if setting in RANDOMIZED:
        run_meta["randomization"] = (dr or Randomization()).record(narrow=setting == "calibrated_narrow")
    run_ppo = replace(ppo, iterations=cfg.iterations if i == 0 else cfg.finetune,
                      restart_std=None if i == 0 else cfg.finetune_std)
    return out / "skills" / name, run_ppo, None if i == 0 else out / "skills" / "a_nominal", run_meta


def _reused(i: int, name: str, task, ppo, cfg, runs: dict, meta: dict, out: Path, log, dr=None) -> bool:
    """Whether policy ``name`` has already trained all its iterations with this configuration
    (:func:`~wresdyn.skills.skill_ppo.finished_skill`, which refuses another one): then it is reused as it is, said
    in one line, without building its plant."""
    run_dir, run_ppo, init, run_meta = _run_of(i, name, ppo, cfg, runs, meta, out, dr)
    worlds = cfg.oracle_worlds if POLICIES[name] == "real" else cfg.num_worlds
    if finished_skill(run_ppo, run_dir, asdict(task), worlds, init=init, meta=run_meta) is None:
        return False
    log(f"[3/4] policy {name}: done earlier ({run_ppo.iterations} iterations), reused")
    return True


def _train_policy(i: int, name: str, robot, real, motions, task, ppo, cfg, runs: dict, meta: dict, out: Path,
                  log, dr: Randomization | None = None) -> float:
    """Train policy ``name`` (the ``i``-th of the benchmark: ``a_nominal`` from scratch, the others fine-tuned from it)
    on its plant (``robot``: the one the task acts on, on its stand or with its free base), or reuse it where it has
    already trained (:func:`_reused`); returns the wall-clock time [s]."""
    setting = POLICIES[name]
    t0 = time.perf_counter()
    if _reused(i, name, task, ppo, cfg, runs, meta, out, log, dr):
        return time.perf_counter() - t0
    worlds = cfg.oracle_worlds if setting == "real" else cfg.num_worlds
    real_plant, sim = _plants(task, real, robot, real.rate_hz, runs, cfg.device, dr)
    if setting != "real":
        plant = sim(setting, worlds)
    elif cfg.oracle_plant == "mujoco_warp":  # the same real robot batched on the device, float32
        plant = RealWarpPlant(real, worlds, task.decimation, seed=cfg.seed + 1, imu_noise=_imu_noise(task),
                              device=cfg.device)
    else:
        plant = real_plant(worlds, cfg.seed + 1)
    env = TrackingEnv(plant, motions, task, seed=cfg.seed + i, device=cfg.device)
    run_dir, run_ppo, init, run_meta = _run_of(i, name, ppo, cfg, runs, meta, out, dr)
    train_skill(env, run_ppo, run_dir, log=log, init=init, meta=run_meta)
    wall = time.perf_counter() - t0
    where = "on the floor of the" if task.floating else "in the"
    what = f"robot ({cfg.oracle_plant})" if setting == "real" else "simulator"
    log(f"[3/4] policy {name}: {run_ppo.iterations} PPO iterations x {worlds} worlds {where} {setting} {what} "
        f"({wall:.0f} s)")
    return wall


def _train_beside(source: str, gains, mismatch: dict, rate: float, i: int, name: str, device: str, motions, task,
                  ppo, cfg, runs, meta, out: Path, dr: Randomization | None = None) -> float:
    """:func:`_train_policy` on the floor in a process of its own, its PPO and simulated plant on ``device`` (its lines
    go to its ``train.log`` only)."""
    import torch

    if ppo.torch_threads is not None:
        torch.set_num_threads(ppo.torch_threads)
    floating = load_robot(source, gains=gains, base="floating")
    real = RealRobot(floating, Mismatch.from_dict(mismatch, "the benchmark's mismatch"), rate)
    return _train_policy(i, name, floating, real, motions, task, replace(ppo, device=device),
                         replace(cfg, device=device), runs, meta, out, lambda s: None, dr)


def _train_all(policies, robot, real, motions, task, ppo, cfg, runs, meta, out: Path, mismatch, log, dr=None) -> dict:
    """Train every policy; returns the wall-clock of each [s]. On the floor with PPO on a GPU the oracle's real robot
    (MuJoCo C on the host's cores) trains beside (b) and (c), and with more GPUs the simulated fine-tunings after (b)
    each on one of them: all start as soon as (a), which they are fine-tuned from, is done."""
    wall, beside = {}, {}
    if task.floating:
        oracle_beside = (cfg.device != "cpu" and cfg.oracle_plant == "mujoco" if cfg.oracle_beside is None
                         else cfg.oracle_beside)
        beside = {"d_oracle": cfg.device} if oracle_beside and "d_oracle" in policies[2:] else {}
        beside.update(zip([p for p in policies[2:] if POLICIES[p] != "real"], cfg.beside_devices))
    index = {name: i for i, name in enumerate(policies)}
    pool, jobs = None, {}
    try:
        for name in policies:
            if name in beside or name in wall:  # trained beside, or found done earlier
                continue
            source = installed_from(cfg, name)
            if source:  # trained elsewhere (a shipped policy): (a) fine-tuned from here unless all are shipped
                install_policy(source, out / "skills" / name)
                wall[name] = 0.0
                log(f"[3/4] policy {name}: {source} (not trained here: {out / 'skills' / name})")
            else:
                wall[name] = _train_policy(index[name], name, robot, real, motions, task, ppo, cfg, runs, meta, out,
                                           log, dr)
            if name == "a_nominal":  # a fine-tuning done earlier is not handed to a process of its own
                for other in list(beside):
                    t0 = time.perf_counter()
                    if _reused(index[other], other, task, ppo, cfg, runs, meta, out, log, dr):
                        wall[other] = time.perf_counter() - t0
                        del beside[other]
            if name == "a_nominal" and beside:
                import multiprocessing as mp

                pool = mp.get_context("spawn").Pool(len(beside))
                for other, device in beside.items():
                    jobs[other] = pool.apply_async(_train_beside, (
                        str(robot.source), robot.gains, mismatch.to_dict(), real.rate_hz, index[other], other, device,
                        motions, task, ppo, cfg, runs, meta, out, dr))
                    where = "on the real robot" if other == "d_oracle" else f"on {device}"
                    log(f"[3/4] policy {other}: training {where} beside the others "
                        f"({out / 'skills' / other / 'train.log'})")
        for other, job in jobs.items():
            wall[other] = job.get()
            setting = POLICIES[other]
            worlds, plant = ((cfg.oracle_worlds, "real robot") if setting == "real"
                             else (cfg.num_worlds, f"{setting} simulator"))
            where = "" if setting == "real" else f" on {beside[other]}"
            log(f"[3/4] policy {other}: {cfg.finetune} PPO iterations x {worlds} worlds on the floor of the {plant} "
                f"({wall[other]:.0f} s{where}, beside the others)")
    finally:
        if pool is not None:
            pool.terminate()
    return wall


def run_benchmark(robot, dataset, out, cfg: DeployConfig | FloorDeployConfig | None = None, *, data_path=None,
                  calibrated=None, delta=None, mismatch=None, task=None, ppo=None, animation: bool = True,
                  policies=BASE_POLICIES, randomization: Randomization | None = None, ledger=None,
                  log=print) -> dict:
    """Run the benchmark into ``out`` (resumable: finished fits and policies are reused, PPO resumes).

    Args:
        robot: The nominal robot on its stand (fixed base); on the floor its floating twin is loaded from the same
            file.
        dataset: The stand recordings the corrections are fitted on (:class:`~wresdyn.data.dataset.Dataset`).
        out: Output folder.
        cfg: Sizes: :class:`DeployConfig` on the stand, :class:`FloorDeployConfig` on the floor (default: the
            task's).
        data_path: Where ``dataset`` was read from (recorded in the fitted runs).
        calibrated, delta: Existing run folders of the two corrections (default: fitted into ``out``).
        mismatch: The "real" robot's :class:`~wresdyn.data.mismatch.Mismatch` (default: the dataset's).
        task: The task, :class:`~wresdyn.skills.skill_config.SkillTaskConfig`'s ``stand()`` or ``floor()`` (default:
            the one of ``cfg``'s kind, the stand's without ``cfg``).
        ppo: :class:`~wresdyn.skills.skill_config.SkillPPOConfig` (its size fields are set from ``cfg``).
        policies: Which of :data:`~.zero_shot.POLICIES` to train and deploy (``a_nominal`` always; without
            ``c_delta_action`` no delta-action residual is fitted; the gap closed needs ``d_oracle``; default
            :data:`~.zero_shot.BASE_POLICIES`, the domain-randomised ``e_randomized`` and ``f_calibrated_narrow`` by
            name).
        randomization: The ranges of (e) and the seed of (e)'s and (f)'s draws
            (:class:`~wresdyn.skills.randomize.Randomization`; default its own, seeded with ``cfg.seed``).
        ledger: A second held-out ledger (``.jsonl``, e.g. a benchmark folder's) besides ``out``'s own
            (:mod:`~wresdyn.skills.ledger`): each scoring of the held-out motions appends a line to both, and the
            report lists every configuration either holds.

    Returns:
        The results written to ``results.json``.
    """
    t_start = time.perf_counter()
    out = Path(out)
    task = task or (FloorTaskConfig() if isinstance(cfg, FloorDeployConfig) else SkillConfig())
    cfg = cfg or (FloorDeployConfig() if task.floating else DeployConfig())
    floor = task.floating
    if floor and cfg.device == "cpu" and any(POLICIES.get(p) in RANDOMIZED for p in policies):
        raise WresdynError("the randomised policies on the floor need per-world physics, which the floor's threaded "
                           "CPU worlds do not have: run them with --device cuda")
    policies, ppo, mismatch, counts = start_benchmark(out, cfg, ppo, mismatch, dataset, policies)
    plant_robot = load_robot(robot.source, gains=robot.gains, base="floating") if floor else robot
    rate = float(dataset.rate_hz)
    meta = {"motions": {"seed": cfg.seed, "counts": counts, "duration": cfg.duration}}
    if floor:
        meta["motions"]["floor"] = True
        meta["motions"]["screened"] = cfg.screen  # other draws: a run trained on the others is not resumed
        if cfg.extra_families:  # a run without them keeps the meta of the runs before the option
            meta["motions"]["extra"] = list(cfg.extra_families)
    cfg = replace(cfg, nominal=nominal_source(cfg))  # before anything is fitted: a misfit is refused at once
    check_installed(cfg, policies, mismatch, task, ppo, meta["motions"], robot.n_dof)
    t0 = time.perf_counter()
    balanced = floor and cfg.heldout_families == "balanced"  # held-out motions drawn once the families are chosen
    store = None
    if floor:  # drawn once per run folder: a resumed run reads them back (refused where drawn from other inputs)
        store = MotionStore(out, motion_fingerprint(robot, counts, cfg.duration, rate, cfg.seed, floor=True,
                                                    screen=cfg.screen, extra=cfg.extra_families,
                                                    heldout_families=cfg.heldout_families), log)
        motions = store.motions(lambda: make_motions(
            robot, {k: n for k, n in counts.items() if not (balanced and k == "heldout")}, cfg.duration, rate,
            cfg.seed, floating=plant_robot, extra=cfg.extra_families, screen=cfg.screen, workers=cfg.motion_workers),
            trained=sorted(p.name for p in (out / "skills").glob("*") if p.is_dir()))
    else:
        motions = make_motions(robot, counts, cfg.duration, rate, cfg.seed)
    log(f"[1/4] {'floor ' if floor else ''}motions: "
        + ", ".join(f"{s} {len(motions.split(s))}" for s in motions.splits)
        + (" (held-out: once (a) is known)" if balanced else "")
        + f" of {cfg.duration:g} s at {rate:g} Hz (policy at {rate / task.decimation:g} Hz)" + _screened(motions)
        + f" ({time.perf_counter() - t0:.0f} s)")
    t0 = time.perf_counter()
    calibrated, delta = fit_corrections(dataset, data_path, robot, out, calibrated, delta, cfg.device, log,
                                         need_delta="c_delta_action" in policies,
                                         need_calibrated=any(POLICIES[p] in ("calibrated", "calibrated_narrow")
                                                             and not installed_from(cfg, p) for p in policies))
    fit_s = time.perf_counter() - t0
    log(f"[2/4] corrections{' fitted on the stand' if floor else ''}: calibrated {calibrated}, delta action {delta} "
        f"({fit_s:.0f} s)" if calibrated or delta else "[2/4] corrections: none fitted (none trains a policy here)")
    real = RealRobot(plant_robot, mismatch, rate)
    runs = {"calibrated": calibrated, "delta_action": delta}
    dr = randomization or Randomization(seed=cfg.seed)
    wall = _train_all(policies, plant_robot, real, motions.split("train"), task, ppo, cfg, runs, meta, out, mismatch,
                      log, dr)
    results = {"config": asdict(cfg), "task": asdict(task), "ppo": asdict(ppo), "mismatch": mismatch.to_dict(),
               "policies": policies, "corrections": {k: str(v) for k, v in runs.items() if v is not None},
               "train_wall_s": wall, "fit_wall_s": fit_s, "real": {}, "sim": {}}
    if any(POLICIES[p] in RANDOMIZED for p in policies):
        results["randomization"] = dr.record()
        if "f_calibrated_narrow" in policies:
            results["randomization"]["narrow"] = narrow_ranges(dr, plant_robot, run_physics(calibrated, plant_robot),
                                                               calibrated)[1]
    real_plant, sim = _plants(task, real, plant_robot, rate, runs, cfg.device, dr)
    results.update(installed_record(cfg, out))
    in_sim = {}  # deployments in a policy's own simulator done before the loop below
    if balanced:
        motions, results["heldout_families"], in_sim = _heldout_families(out, robot, plant_robot, cfg, motions, sim,
                                                                          task, log, store)
    # each deployment kept as it ends, so that a run killed here resumes from the ones done
    deployed = DeploymentStore(out, {
        "task": asdict(task), "real": {"mismatch": mismatch.to_dict(), "rate_hz": rate, "seed": cfg.seed + 100},
        "sim": {"device": cfg.device}, "motions": store.fingerprint if store else motion_fingerprint(
            robot, counts, cfg.duration, rate, cfg.seed, floor=False, screen=False)}, log)
    own = {n: _own_sim(POLICIES.get(n, "nominal"), runs) for n in ("reference", *policies)}
    t0 = time.perf_counter()  # the deployment's wall-clock, for the log: one of a run's fixed costs
    results["real"], results["sim"], rollouts = deploy_all(
        deployed, own, out / "skills", motions,
        lambda worlds: real_plant(worlds, cfg.seed + 100), sim, task, robot, in_sim, lambda setting: {
            "setting": setting, "correction": run_fingerprint(runs.get(RANDOMIZED.get(setting, setting))),
            "randomization": dr.record(narrow=setting == "calibrated_narrow") if setting in RANDOMIZED
            else None})
    deploy_s = time.perf_counter() - t0
    _gaps(results, floor)
    ledgers = [out / LEDGER] + ([Path(ledger)] if ledger else [])
    deployed.record(ledgers, {"benchmark": asdict(cfg), "task": asdict(task), "ppo": asdict(ppo),
                              "mismatch": mismatch.to_dict()}, cfg.seed,
                    {n: r["mean"] for n, r in results["real"]["heldout"].items()}, len(motions.split("heldout")))
    held = results["real"]["heldout"]
    n_held = len(motions.split("heldout"))
    if floor:
        log(f"[4/4] deployed on the real robot's floor ({n_held} held-out motions; {deploy_s:.0f} s): " + "; ".join(
            f"{n} success {100 * r['mean']['success']:.0f} % ({r['mean']['falls']} falls), MPJPE "
            f"{1e3 * r['mean'].get('mpjpe', float('nan')):.1f} mrad, "
            f"g-MPJPE {1e3 * r['mean'].get('g_mpjpe', float('nan')):.0f} mm"
            for n, r in held.items()) + _gap_log(held, results["gap_closed_mpjpe"], " (MPJPE)"))
    else:
        log(f"[4/4] deployed on the real robot ({n_held} held-out motions; {deploy_s:.0f} s), MPJPE: " + ", ".join(
            f"{n} {1e3 * r['mean']['mpjpe']:.1f} mrad" for n, r in held.items())
            + _gap_log(held, results["gap_closed"]))
    results["wall_s"] = time.perf_counter() - t_start
    write_report(out, plant_robot, results, rollouts, motions.split("heldout"), rate / task.decimation,
                 animation=animation)
    write_results(out, results)
    with open(out / "report.md", "a") as f:  # what else was ever scored on these held-out motions
        f.write("\n## Held-out ledger\n\n" + "\n".join(ledger_table(p) for p in ledgers))
    log(f"wrote {out / 'report.md'} and {out / 'results.json'}")
    return results


def _heldout_families(out: Path, robot, floating, cfg, motions, sim, task, log, store: MotionStore):
    """The held-out motions of the families (a) carries in its own simulator on every validation motion
    (:func:`~.nominal_policy.balanced_families`), drawn now (or read back from ``store`` where drawn for the same
    families): the motion set with them, the record of the rule for ``results.json``, and (a)'s validation deployment
    in the nominal simulator (reused by the deployment)."""
    t0 = time.perf_counter()
    val = motions.split("validation")
    kept, left, res = balanced_families(load_skill(out / "skills" / "a_nominal"), sim("nominal", len(val)), val, task)
    held, unvouched = store.heldout(motions, kept, lambda: draw_heldout(robot, floating, cfg, motions.rate_hz, kept))
    left = {**left, **unvouched} if kept else {}
    record = {"rule": "balanced", "kept": list(dict.fromkeys(m.family for m in held)), "left_out": left}
    log(f"[4/4] held-out families (a) carries on every validation motion in its simulator: "
        f"{', '.join(record['kept'])}" + ("" if kept else " (it carries none: every family)")
        + "".join(f"; left out {f}: {why}" for f, why in left.items())
        + f"; {len(held)} held-out motions" + _screened(MotionSet(motions.rate_hz, {"heldout": held}))
        + f" ({time.perf_counter() - t0:.0f} s)")
    return MotionSet(motions.rate_hz, {**motions.splits, "heldout": held}), record, {("validation", "a_nominal"): res}


def _screened(motions) -> str:
    """What the floor's feasibility screening did to the motion set, for the log (empty where it did not run)."""
    done = [m.screen for ms in motions.splits.values() for m in ms if m.screen]
    slowed = sum("slowed" in s for s in done)
    return f"; screened {len(done)}: {len(done) - slowed} as drawn, {slowed} slowed" if done else ""


def _gap_log(held: dict, gaps: dict, what: str = "") -> str:
    """The log's gap ratios, under the report's rule: none where no policy succeeded or the oracle does not beat (a)
    (:func:`~wresdyn.skills.evaluate.gaps_or_why_not`), then the reason."""
    _, why = gaps_or_why_not(held)
    if why:
        return f"; no gap ratio: {why}"
    return "".join(f"; gap closed by {k[0]} {100 * v:.0f} %{what}" for k, v in gaps.items())


def _gaps(results: dict, floor: bool) -> None:
    """The gaps closed by (b) and (c) on the real robot, into ``results``: on held-out MPJPE ``gap_closed`` and on
    validation ``gap_closed_validation``; on the floor ``gap_closed[_validation]_{mpjpe,g_mpjpe}``."""
    for split, suffix in (("heldout", ""), ("validation", "_validation")):
        for metric in ("mpjpe", "g_mpjpe") if floor else ("mpjpe",):
            mean = {n: r["mean"].get(metric, float("nan")) if floor else r["mean"][metric]
                    for n, r in results["real"][split].items()}
            results[f"gap_closed{suffix}_{metric}" if floor else f"gap_closed{suffix}"] = {
                k: gap_closed(mean["a_nominal"], mean[k], mean["d_oracle"])
                for k in ("b_calibrated", "c_delta_action", "e_randomized", "f_calibrated_narrow")
                if k in mean and "d_oracle" in mean}
