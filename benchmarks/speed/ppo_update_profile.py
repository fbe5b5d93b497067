"""Where a residual PPO iteration's time goes: collection against the update, and the update by part.

    python benchmarks/speed/ppo_update_profile.py                                     # CPU, 256 worlds
    python benchmarks/speed/ppo_update_profile.py --device cuda:0 --envs 4096
    python benchmarks/speed/ppo_update_profile.py --device cuda:0 --envs 4096 --set ppo.one_sync_update=true
    torchrun --standalone --nproc_per_node 2 benchmarks/speed/ppo_update_profile.py --device cuda --envs 8192
    torchrun --standalone --nproc_per_node 2 benchmarks/speed/ppo_update_profile.py --device cuda --envs 8192 \\
        --rsl-update

Workload: the shipped benchmark with the default residual PPO (:func:`wresdyn.ppo.trainer.runner_cfg`, 24 steps per
world, 5 epochs x 4 mini-batches, adaptive learning rate), ``--envs`` worlds in total (split over torchrun's
processes, as ``wresdyn train`` splits them), ``--set`` overrides as on ``wresdyn train``; the update is
:class:`~wresdyn.ppo.packed_update.PackedPPO` run eagerly (``ppo.graph_update`` false: the parts' synchronisations
cannot run inside the CUDA graph of the residual's default on CUDA), or rsl-rl's own with ``--rsl-update``.

1. **Split** (``--iterations`` plain iterations after 2 of warm-up): rsl-rl's own collect and learn times.
2. **Breakdown** (as many iterations again, instrumented): every part of ``PPO.update`` timed between device
   synchronisations (self time: a part inside another counts once), and counted per iteration: the host
   synchronisations the update makes (``Tensor.item``, ``tolist``, a tensor's truth value; not counted inside
   Adam's step, which reads its step counts, host tensors, so) and the collectives
   (``all_reduce``, ``broadcast``). The synchronisations around each part slow the instrumented update down; the
   parts' shares, not their sum, are the finding, and the plain learn time of (1) is the total.

Prints the table of rank 0 (every rank profiles its own process) and, with ``--json``, writes it.
"""

from __future__ import annotations

import argparse
import json
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


REST = "rest of the update (losses, Python)"
"""The update's own time outside the wrapped parts."""


class Parts:
    """Self times [s] and call counts of the wrapped callables while ``active``."""

    def __init__(self, sync) -> None:
        self.sync, self.active = sync, False
        self.time: dict[str, float] = {}
        self.calls: dict[str, int] = {}
        self._stack: list[list] = []  # [label, time of the parts inside]
        self._undo: list = []

    def wrap(self, owner, attr: str, label: str, skip_inside: tuple[str, ...] = ()) -> None:
        """Replace ``owner.attr`` by a wrapper that counts and times (between synchronisations) its calls, except
        those made inside a part named in ``skip_inside``."""
        orig = getattr(owner, attr)
        parts = self

        def wrapper(*a, **kw):
            if not parts.active or any(s[0] in skip_inside for s in parts._stack):
                return orig(*a, **kw)
            return parts._timed(label, orig, a, kw)

        setattr(owner, attr, wrapper)
        self._undo.append((owner, attr, orig, attr in getattr(owner, "__dict__", {})))

    def _timed(self, label, fn, a, kw):
        self.calls[label] = self.calls.get(label, 0) + 1
        self.sync()
        self._stack.append([label, 0.0])
        t0 = time.perf_counter()
        try:
            return fn(*a, **kw)
        finally:
            self.sync()
            spent = time.perf_counter() - t0
            inner = self._stack.pop()[1]
            self.time[label] = self.time.get(label, 0.0) + spent - inner
            if self._stack:
                self._stack[-1][1] += spent

    def wrap_generator(self, owner, attr: str, label: str) -> None:
        """Time each item of the generator ``owner.attr(...)`` returns (the mini-batch gathers)."""
        orig = getattr(owner, attr)
        parts = self

        def gen(*a, **kw):
            it = orig(*a, **kw)
            while True:
                try:
                    yield parts._timed(label, next, (it,), {}) if parts.active else next(it)
                except StopIteration:
                    return

        setattr(owner, attr, gen)
        self._undo.append((owner, attr, orig, True))

    def undo(self) -> None:
        for owner, attr, orig, own in reversed(self._undo):
            if own:
                setattr(owner, attr, orig)
            else:
                delattr(owner, attr)
        self._undo.clear()


def instrument(alg, parts: Parts) -> None:
    """Wrap the parts of ``alg.update`` (rsl-rl's PPO or :class:`~wresdyn.ppo.update.OneSyncPPO`)."""
    import torch

    parts.wrap_generator(alg.storage, "mini_batch_generator", "mini-batch gather")
    parts.wrap(alg.actor, "forward", "actor forward")
    parts.wrap(alg.critic, "forward", "critic forward")
    parts.wrap(alg.actor, "get_kl_divergence", "KL")
    parts.wrap(torch.Tensor, "backward", "backward")
    parts.wrap(torch.nn.utils, "clip_grad_norm_", "gradient clip")
    parts.wrap(alg.optimizer, "step", "optimizer step")
    parts.wrap(alg.actor, "update_normalization", "normaliser update")
    parts.wrap(alg.critic, "update_normalization", "normaliser update")
    for name in ("reduce_parameters", "_reduce"):
        if hasattr(alg, name):
            parts.wrap(alg, name, "gradient all-reduce (packing)")
    for name in ("item", "tolist", "__bool__"):
        # Adam reads its step counts, host tensors, with item(): no wait on the device
        parts.wrap(torch.Tensor, name, f"host sync: Tensor.{name}", skip_inside=("optimizer step",))
    if torch.cuda.is_available():  # the packed update waits on an event (its KL tests copied to the host)
        parts.wrap(torch.cuda.Event, "synchronize", "host sync: Event.synchronize")
    if torch.distributed.is_available():
        for name in ("all_reduce", "broadcast"):
            parts.wrap(torch.distributed, name, f"collective: {name}")
    update = alg.update

    def timed_update():
        parts.active = True
        try:
            return parts._timed(REST, update, (), {})
        finally:
            parts.active = False

    alg.update = timed_update


@contextmanager
def iteration_times(runner):
    """rsl-rl's collect and learn time of each iteration run inside, appended to the yielded lists."""
    collect, learn = [], []
    log = runner.logger.log

    def logged(*a, **kw):
        collect.append(kw["collect_time"])
        learn.append(kw["learn_time"])
        return log(*a, **kw)

    runner.logger.log = logged
    try:
        yield collect, learn
    finally:
        runner.logger.log = log


def main() -> None:
    import tempfile

    import torch
    import warp as wp

    from wresdyn.data.dataset import load_dataset
    from wresdyn.ppo.trainer import runner_cfg
    from wresdyn.config_fields import apply_overrides, set_fields
    from wresdyn.ppo.ppo_config import default_config
    from wresdyn.ppo.runner import Ranks, make_runner, seed_processes
    from wresdyn.ppo.replay_env import ReplayEnv
    from wresdyn.learn.residual import obs_stats
    from wresdyn.progress import into_file
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--data", default=str(ROOT / "data" / "dataset.npz"))
    p.add_argument("--envs", type=int, default=256, help="worlds in total (split over torchrun's processes)")
    p.add_argument("--iterations", type=int, default=5, help="iterations of each phase")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE")
    p.add_argument("--rsl-update", action="store_true",
                   help="rsl-rl's own PPO.update instead of the packed update (the same, bit for bit)")
    p.add_argument("--json", default=None)
    args = p.parse_args()
    wp.config.quiet = True
    ranks = Ranks.from_env()
    cfg = apply_overrides(set_fields(default_config(), {"env.num_worlds": args.envs, "ppo.device": args.device,
                                                        "ppo.save_interval": 10**6, "ppo.graph_update": False}),
                          args.set)
    seed_processes(cfg.ppo.seed + ranks.rank, cfg.ppo.torch_threads)
    robot = load_robot(DEFAULT_ROBOT)
    data = load_dataset(args.data, robot=robot)
    trajs = data.split("train")
    mean, std = obs_stats(trajs)
    device = ranks.device(cfg.ppo.device)
    env = ReplayEnv(robot, trajs, data.rate_hz, ranks.num_worlds(cfg.env.num_worlds), cfg.env, cfg.residual, cfg.rewards,
                    device=device, seed=cfg.ppo.seed + ranks.rank, obs_mean=mean, obs_std=std,
                    graph=cfg.ppo.cuda_graph, weights=data.fit_weights())
    sync = (lambda: torch.cuda.synchronize(device)) if str(device).startswith("cuda") else (lambda: None)
    with tempfile.TemporaryDirectory() as tmp, into_file(Path(tmp) / "rsl_rl.log"):
        rcfg = runner_cfg(cfg)
        rcfg["check_for_nan"] = not env.graph
        if args.rsl_update:
            rcfg["algorithm"]["class_name"] = "PPO"
        runner = make_runner(env, rcfg, Path(tmp), main=ranks.main)  # rank 0 logs as in a run
        runner.learn(2)
        with iteration_times(runner) as (collect, learn):
            runner.learn(args.iterations)
        parts = Parts(sync)
        instrument(runner.alg, parts)
        runner.learn(args.iterations)
        parts.undo()
    n = args.iterations
    row = {"device": str(device), "gpu": torch.cuda.get_device_name(device) if str(device).startswith("cuda") else "cpu",
           "processes": ranks.world, "envs_per_process": env.num_envs, "update": type(runner.alg).__name__,
           "one_sync_update": cfg.ppo.one_sync_update,
           "mixed_precision": cfg.ppo.mixed_precision, "compile_mode": cfg.ppo.compile_mode,
           "mini_batches": cfg.ppo.num_mini_batches, "epochs": cfg.ppo.num_learning_epochs,
           "collect_s": sum(collect) / n, "learn_s": sum(learn) / n,
           "training_steps_per_s": ranks.world * env.num_envs * cfg.ppo.num_steps_per_env * n / (sum(collect) + sum(learn)),
           "parts_s": {k: v / n for k, v in parts.time.items()},
           "calls_per_iteration": {k: v / n for k, v in parts.calls.items()}}
    if ranks.main:
        _print(row)
        if args.json:
            Path(args.json).write_text(json.dumps(row, indent=1))
    ranks.close()


def _print(row: dict) -> None:
    print(f"\n{row['gpu']} ({row['device']}), {row['processes']} process(es) x {row['envs_per_process']} worlds; "
          f"{row['epochs']} epochs x {row['mini_batches']} mini-batches; update {row['update']}, "
          f"mixed precision {row['mixed_precision']}, compile {row['compile_mode'] or 'off'}")
    print(f"plain iterations: collect {row['collect_s']:.4f} s + learn {row['learn_s']:.4f} s per iteration, "
          f"{row['training_steps_per_s'] / 1e3:.1f}k training env-steps/s (all processes)")
    total = sum(row["parts_s"].values())
    print(f"instrumented update: {total * 1e3:.1f} ms per iteration (synchronised around every part)")
    print("| part | self ms / iteration | share | calls / iteration |")
    print("|---|---|---|---|")
    labels = sorted(set(row["parts_s"]) | set(row["calls_per_iteration"]), key=lambda k: -row["parts_s"].get(k, 0.0))
    for k in labels:
        t = row["parts_s"].get(k, 0.0)
        share = f"{100 * t / total:.0f} %" if total else ""
        print(f"| {k} | {t * 1e3:.2f} | {share} | {row['calls_per_iteration'].get(k, 0):g} |")


if __name__ == "__main__":
    main()
