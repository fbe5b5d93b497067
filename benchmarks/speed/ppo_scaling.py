"""PPO on one and several GPUs through torchrun: training throughput of the residual and of the floor skill, and the
residual's time to a validation target.

    torchrun --standalone --nproc_per_node 1 benchmarks/speed/ppo_scaling.py --device cuda --json one.json \\
        --cases residual:4096 residual:8192 skill:4096 skill:8192
    torchrun --standalone --nproc_per_node 2 benchmarks/speed/ppo_scaling.py --device cuda --json two.json \\
        --cases residual:8192 skill:8192
    python benchmarks/speed/ppo_scaling.py --table one.json two.json
    torchrun --standalone --nproc_per_node 2 benchmarks/speed/ppo_scaling.py --device cuda --ttf 2.0 --envs 8192 --out DIR

A case is ``LEARNER:ENVS[+OPTION...]`` with ENVS the worlds of all processes together (split as ``wresdyn train``
splits them); an option sets a PPO field (:data:`OPTIONS`): ``+one_sync`` the update with one host synchronisation
(``ppo.one_sync_update``), ``+graph`` each mini-batch's update step replayed from one CUDA graph
(``ppo.graph_update``, :class:`~wresdyn.ppo.graph_update.GraphPPO`, the residual's default on CUDA), ``+packed`` the
same update run eagerly (``ppo.graph_update`` false: :class:`~wresdyn.ppo.packed_update.PackedPPO`), ``+bf16``
rsl-rl's mixed precision, ``+compile`` rsl-rl's ``torch.compile``, ``+mbK`` K mini-batches, ``+epK`` K epochs;
``+pin`` (residual only) each process bound to the CPU cores local to its GPU (``ppo.pin_cpus``,
:func:`wresdyn.ppo.affinity.pin_process`), ``+defer_log`` (residual only) rsl-rl's episode bookkeeping copied to the
host once per iteration instead of a host wait at every rollout step on rank 0 (``ppo.deferred_episode_log``, on by
default on CUDA in training; a residual case without ``+defer_log`` turns it off, as every case ran before);
``+rsl_update`` (residual only) runs rsl-rl's own ``PPO.update`` instead of the residual's update, which is
:class:`~wresdyn.ppo.packed_update.PackedPPO`'s bit for bit with fewer collectives and host waits (on the CPU, or
eagerly with ``+packed``): the baseline of that change in the same run.

- ``residual``: the default residual PPO on the shipped benchmark (:func:`wresdyn.ppo.trainer.runner_cfg`, 24 steps per
  world, 5 epochs x 4 mini-batches), the environment step from a CUDA graph; the training default on CUDA is
  ``residual:N+graph+defer_log``.
- ``skill``: policy (a) of the floor benchmark (``wresdyn deploy --floor --full``'s sizes: 16 training motions per
  family of 4 s; :class:`~wresdyn.skills.env.TrackingEnv` on the nominal simulator with a floor,
  :func:`wresdyn.skills.skill_ppo.runner_cfg` with the default :class:`~wresdyn.skills.skill_config.SkillPPOConfig`).
  An env-step is a policy step (``decimation`` physics steps).

Each case builds its worlds and rsl-rl's runner as training does, runs ``--warmup`` iterations (CUDA graph capture,
allocation), then ``--iterations`` timed ones: training env-steps/s = env-steps of all processes / rank 0's rsl-rl
collect + learn time (the processes meet at every mini-batch, so rank 0's time is the iteration's). ``--table``
prints the rows of several runs side by side with the efficiency of each several-process row: its env-steps/s over
(processes x the one-process row of the same learner, options and worlds per process).

``--ttf RATIO``: :func:`wresdyn.ppo.trainer.train` with validation every ``--check`` iterations, stopping at the first
check at or below the PD-only validation error / RATIO (at most ``--max-iterations``): training wall-clock to the
target (validation checks excluded), as ``benchmarks/speed/time_to_fidelity.py`` measures it.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


OPTIONS = {"one_sync": ("one_sync_update", True), "graph": ("graph_update", True), "packed": ("graph_update", False),
           "bf16": ("mixed_precision", True), "compile": ("compile_mode", "default"), "pin": ("pin_cpus", True),
           "defer_log": ("deferred_episode_log", True)}
"""A case's ``+OPTION``: the PPO config field it sets (``+mbK`` sets ``num_mini_batches`` = K, ``+epK``
``num_learning_epochs`` = K); the skill's config has ``one_sync``, ``mbK`` and ``epK``."""

RSL_UPDATE = "rsl_update"
"""The residual case's option for rsl-rl's own ``PPO.update`` (not a config field: the runner config's class)."""


def _parse_case(text: str) -> tuple[str, int, dict]:
    """``LEARNER:ENVS[+OPTION...]`` as (learner, worlds of all processes, PPO config fields to set)."""
    head, *opts = text.split("+")
    learner, _, envs = head.partition(":")
    fields = {}
    for o in opts:
        if o == RSL_UPDATE:
            fields[RSL_UPDATE] = True
        elif o in OPTIONS:
            fields[OPTIONS[o][0]] = OPTIONS[o][1]
        elif o[:2] in ("mb", "ep") and o[2:].isdigit():
            fields["num_mini_batches" if o[:2] == "mb" else "num_learning_epochs"] = int(o[2:])
        else:
            raise SystemExit(f"ppo_scaling.py: case {text!r}: unknown option {o!r} ({', '.join(OPTIONS)}, mbK, epK)")
    if learner not in ("residual", "skill") or not envs.isdigit():
        raise SystemExit(f"ppo_scaling.py: case {text!r} is not residual|skill:ENVS[+OPTION...]")
    if learner == "skill" and RSL_UPDATE in fields:
        raise SystemExit(f"ppo_scaling.py: case {text!r}: the skill's PPO runs rsl-rl's own update already")
    if learner == "skill" and set(fields) & {"mixed_precision", "compile_mode", "graph_update", "pin_cpus",
                                             "deferred_episode_log"}:
        raise SystemExit(f"ppo_scaling.py: case {text!r}: the skill's PPO has no mixed precision, compile, graph, "
                         "pin or defer_log option")
    return learner, int(envs), fields


def _residual(ranks, robot, data, envs: int, device: str, fields: dict, tmp: Path):
    """The residual's worlds and runner, as :func:`wresdyn.ppo.trainer.train` builds them."""
    from wresdyn.ppo.trainer import runner_cfg
    from wresdyn.config_fields import set_fields
    from wresdyn.ppo.ppo_config import default_config
    from wresdyn.ppo.runner import make_runner, seed_processes
    from wresdyn.ppo.replay_env import ReplayEnv
    from wresdyn.learn.residual import obs_stats

    # rsl-rl's per-step episode bookkeeping unless the case says +defer_log, although the deferred one is the
    # default on CUDA: a case keeps meaning what it measured in the rounds recorded before that default
    cfg = set_fields(default_config(), {"env.num_worlds": envs, "ppo.device": device, "ppo.deferred_episode_log": False,
                                        **{f"ppo.{k}": v for k, v in fields.items() if k != RSL_UPDATE}})
    seed_processes(cfg.ppo.seed + ranks.rank, cfg.ppo.torch_threads)
    if cfg.ppo.pin_cpus:  # as wresdyn.ppo.trainer.train does; _throughput gives the cores back after the case
        from wresdyn.ppo.affinity import pin_process

        pin_process(ranks.local_rank, ranks.world, device)
    trajs = data.split("train")
    mean, std = obs_stats(trajs)
    env = ReplayEnv(robot, trajs, data.rate_hz, ranks.num_worlds(envs), cfg.env, cfg.residual, cfg.rewards,
                    device=ranks.device(device), seed=cfg.ppo.seed + ranks.rank, obs_mean=mean, obs_std=std,
                    graph=cfg.ppo.cuda_graph, weights=data.fit_weights())
    rcfg = runner_cfg(cfg)
    rcfg["check_for_nan"] = not env.graph
    if fields.get(RSL_UPDATE):
        rcfg["algorithm"]["class_name"] = "PPO"
    return env, make_runner(env, rcfg, tmp, ranks.main), cfg.ppo.num_steps_per_env


def _skill(ranks, robot, data, envs: int, device: str, fields: dict, tmp: Path, motions_cache: dict,
           per_family: int | None):
    """Policy (a) of the floor benchmark at full size: its worlds and runner, as the benchmark builds them."""
    from wresdyn.experiments.deploy_config import FloorDeployConfig
    from wresdyn.ppo.runner import make_runner, seed_processes
    from wresdyn.robot.description import load_robot
    from wresdyn.skills.env import FloorTaskConfig, TrackingEnv
    from wresdyn.skills.motions import make_motions
    from wresdyn.skills.plants import sim_plant
    from wresdyn.skills.skill_ppo import SkillPPOConfig, rank_share, runner_cfg

    full, task = FloorDeployConfig.full(), FloorTaskConfig()
    cfg = SkillPPOConfig(device=device, seed=full.seed, **fields)
    seed_processes(cfg.seed + ranks.rank, cfg.torch_threads)
    rate = float(data.rate_hz)
    if "train" not in motions_cache:
        floating = load_robot(robot.source, gains=robot.gains, base="floating")
        counts = {"train": per_family or full.train_per_family}
        motions = make_motions(robot, counts, full.duration, rate, full.seed, floating=floating)
        motions_cache.update(train=motions["train"], floating=floating)
    n, dev = rank_share(envs, device)
    plant = sim_plant("nominal", motions_cache["floating"], n, rate, task.decimation, None, dev, ground=True)
    env = TrackingEnv(plant, motions_cache["train"], task, seed=full.seed + ranks.rank, device=dev)
    return env, make_runner(env, runner_cfg(cfg, env.critic_groups), tmp, ranks.main), cfg.num_steps_per_env


def _throughput(ranks, robot, data, case: str, device: str, warmup: int, iterations: int, motions_cache,
                per_family: int | None) -> dict:
    from wresdyn.ppo.affinity import set_affinity

    learner, envs, fields = _parse_case(case)
    cores = os.sched_getaffinity(0)  # a +pin case binds the process: the next case starts unbound again
    try:
        return _timed(ranks, robot, data, case, learner, envs, fields, device, warmup, iterations, motions_cache,
                      per_family)
    finally:
        set_affinity(cores)


def _timed(ranks, robot, data, case, learner, envs, fields, device, warmup, iterations, motions_cache,
           per_family) -> dict:
    import torch

    from wresdyn.progress import into_file

    t_build = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp, into_file(Path(tmp) / "rsl_rl.log"):  # rsl-rl's tables
        if learner == "residual":
            env, runner, steps = _residual(ranks, robot, data, envs, device, fields, Path(tmp))
        else:
            env, runner, steps = _skill(ranks, robot, data, envs, device, fields, Path(tmp), motions_cache,
                                        per_family)
        build = time.perf_counter() - t_build
        times = {"collect": [], "learn": []}
        log = runner.logger.log

        def logged(*a, **kw):
            times["collect"].append(kw["collect_time"])
            times["learn"].append(kw["learn_time"])
            return log(*a, **kw)

        runner.logger.log = logged
        t0 = time.perf_counter()
        runner.learn(warmup)
        warm = time.perf_counter() - t0
        runner.current_learning_iteration += 1
        t0 = time.perf_counter()
        runner.learn(iterations)
        if str(env.device).startswith("cuda"):
            torch.cuda.synchronize(env.device)
        wall = time.perf_counter() - t0
        collect, learn = sum(times["collect"][warmup:]), sum(times["learn"][warmup:])
        row = {"case": case, "learner": learner, "options": "+".join(case.split("+")[1:]), "processes": ranks.world,
               "envs": envs, "envs_per_process": env.num_envs, "device": str(env.device), "iterations": iterations,
               "update": type(runner.alg).__name__, "cores": sorted(os.sched_getaffinity(0)),
               "build_s": build, "warmup_s": warm, "collect_s": collect / iterations, "learn_s": learn / iterations,
               "s_per_iteration": (collect + learn) / iterations,
               "training_steps_per_s": envs * steps * iterations / (collect + learn),
               "wall_steps_per_s": envs * steps * iterations / wall}
        del runner, env
    gc.collect()
    if torch.cuda.is_available():
        torch.cuda.empty_cache()
    return row


def _time_to_target(ranks, robot, data, args) -> dict:
    from wresdyn.ppo.trainer import train
    from wresdyn.config_fields import set_fields
    from wresdyn.ppo.ppo_config import default_config
    from wresdyn.learn.selection import ValidationScore

    pd_only = ValidationScore(robot, data.split("validation"), data.rate_hz, device=ranks.device(args.device),
                              weights=data.fit_weights())()
    target = pd_only / args.ttf
    opts = "+".join(o for o in (["one_sync"] if args.one_sync else []) + args.ttf_options.split("+") if o)
    case = f"residual:{args.envs}" + (f"+{opts}" if opts else "")
    fields = {f"ppo.{k}": v for k, v in _parse_case(case)[2].items()}
    cfg = set_fields(default_config(), {"env.num_worlds": args.envs, "ppo.device": args.device,
                                        "ppo.iterations": args.max_iterations, "ppo.select_every": args.check,
                                        "ppo.save_interval": 10**6, **fields})
    out = Path(args.out) / f"ttf_{ranks.world}x{args.envs // ranks.world}_{opts or 'rsl_rl'}"
    s = train(data, robot, cfg, out, resume=False, stop_below=target, log=lambda *_: None)
    curve = s["validation_curve"]
    if not ranks.main:  # rank 0 alone scores on validation
        return {"case": "ttf", "processes": ranks.world}
    hit = next((r for r in curve if r["validation"] <= target), None)
    return {"case": f"ttf {case}", "processes": ranks.world,
            "envs": args.envs, "pd_only": pd_only, "target": target, "ratio": args.ttf,
            "reached_at_iteration": hit["iteration"] if hit else None, "wall_s": hit["wall_s"] if hit else None,
            "iterations_run": s["iterations_this_session"], "best_validation": min(r["validation"] for r in curve),
            "training_steps_per_s": s["training_steps_per_s"], "s_per_iteration": s["s_per_iteration"],
            "curve": [(r["iteration"], round(r["validation"], 5), round(r.get("wall_s", 0.0), 2)) for r in curve]}


def _rate(x: float) -> str:
    """env-steps/s, 3 significant figures: ``1.09M``, ``668k``, ``412``."""
    for unit, scale in (("M", 1e6), ("k", 1e3)):
        if x >= scale:
            return f"{x / scale:.3g}{unit}"
    return f"{x:.3g}"


def table(paths) -> None:
    """Print the rows of the JSON files ``paths`` with each several-process row's scaling efficiency."""
    rows = [r for p in paths for r in json.loads(Path(p).read_text())["rows"]]
    base = {(r["learner"], r["options"], r["envs_per_process"]): r for r in rows
            if r.get("processes") == 1 and "learner" in r}
    if base or any("learner" in r for r in rows):
        print("| case | processes | worlds per process | s / iteration | collect / learn [s] | training env-steps/s | "
              "efficiency |")
        print("|---|---|---|---|---|---|---|")
    for r in rows:
        if "learner" not in r:
            continue
        one = base.get((r["learner"], r["options"], r["envs_per_process"]))
        eff = (f"{100 * r['training_steps_per_s'] / (r['processes'] * one['training_steps_per_s']):.0f} %"
               if one is not None and r["processes"] > 1 else "")
        print(f"| {r['case']} | {r['processes']} | {r['envs_per_process']} | {r['s_per_iteration']:.4f} | "
              f"{r['collect_s']:.4f} / {r['learn_s']:.4f} | {_rate(r['training_steps_per_s'])} | {eff} |")
    ttf = [r for r in rows if r["case"].startswith("ttf")]
    if ttf:
        if any("learner" in r for r in rows):
            print()
        print("| time to target | processes | target [rad] | reached at iteration | training wall-clock [s] | "
              "best validation | training env-steps/s |")
        print("|---|---|---|---|---|---|---|")
        for r in ttf:
            wall = f"{r['wall_s']:.1f}" if r["wall_s"] is not None else f"not reached in {r['iterations_run']}"
            print(f"| {r['case']} | {r['processes']} | {r['target']:.4f} (PD-only / {r['ratio']:g}) | "
                  f"{r['reached_at_iteration']} | {wall} | {r['best_validation']:.4f} | "
                  f"{_rate(r['training_steps_per_s'])} |")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu", help="cpu, or cuda (cuda:<LOCAL_RANK> per process under torchrun)")
    p.add_argument("--data", default=str(ROOT / "data" / "dataset.npz"))
    p.add_argument("--cases", nargs="*", default=[], help="LEARNER:ENVS[+OPTION...], LEARNER residual or skill")
    p.add_argument("--warmup", type=int, default=2, help="untimed iterations of each case")
    p.add_argument("--iterations", type=int, default=20, help="timed iterations of each residual case")
    p.add_argument("--skill-iterations", type=int, default=8, help="timed iterations of each skill case")
    p.add_argument("--skill-motions", type=int, default=None,
                   help="training motions per family of the skill (default: the full benchmark's; fewer for checks)")
    p.add_argument("--ttf", type=float, default=None, help="time to PD-only validation error / TTF instead")
    p.add_argument("--envs", type=int, default=4096, help="--ttf: worlds of all processes")
    p.add_argument("--one-sync", action="store_true", help="--ttf: with ppo.one_sync_update")
    p.add_argument("--ttf-options", default="", help="--ttf: a case's options, e.g. one_sync+mb2")
    p.add_argument("--check", type=int, default=25, help="--ttf: validation every this many iterations")
    p.add_argument("--max-iterations", type=int, default=400, help="--ttf: iterations at most")
    p.add_argument("--out", default=None, help="--ttf: folder of the runs")
    p.add_argument("--json", default=None, help="write the rows here (rank 0)")
    p.add_argument("--table", nargs="*", default=None, help="print the rows of these JSON files and exit")
    args = p.parse_args()
    if args.table is not None:
        return table(args.table)

    import torch
    import warp as wp

    from wresdyn.data.dataset import load_dataset
    from wresdyn.ppo.runner import Ranks
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    wp.config.quiet = True
    torch.set_num_threads(1)
    ranks = Ranks.from_env()
    robot = load_robot(DEFAULT_ROBOT)
    data = load_dataset(args.data, robot=robot)
    rows, motions_cache = [], {}
    if args.ttf is not None and not args.out:
        raise SystemExit("ppo_scaling.py: --ttf needs --out")
    for case in args.cases:  # every case's runner joins the process group of the first
        it = args.skill_iterations if case.startswith("skill") else args.iterations
        try:
            row = _throughput(ranks, robot, data, case, args.device, args.warmup, it, motions_cache, args.skill_motions)
        except Exception as e:  # one process: the other cases still run (across processes a rank left alone hangs)
            if ranks.world > 1:
                raise
            print(f"{case}: FAILED {type(e).__name__}: {str(e)[:300]}", flush=True)
            continue
        rows.append(row)
        if ranks.main:
            print(f"{case} x {ranks.world} process(es): {row['s_per_iteration']:.4f} s/it (collect {row['collect_s']:.4f}"
                  f" + learn {row['learn_s']:.4f}), {_rate(row['training_steps_per_s'])} training env-steps/s; "
                  f"built in {row['build_s']:.0f} s, warm-up {row['warmup_s']:.0f} s", flush=True)
    if args.ttf is not None:  # last: a finished run tears the process group down
        rows.append(_time_to_target(ranks, robot, data, args))
    ranks.close()
    if ranks.main:
        name = torch.cuda.get_device_name(0) if args.device.startswith("cuda") else "cpu"
        for r in rows:
            if r["case"].startswith("ttf"):
                print(f"{r['case']} x {r['processes']}: target {r['target']:.4f} rad reached at iteration "
                      f"{r['reached_at_iteration']} after {r['wall_s']} s of training; curve {r['curve']}", flush=True)
        if args.json:
            Path(args.json).write_text(json.dumps({"device": name, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
