"""``wresdyn deploy [DATA]``: train tracking skills in the nominal and the corrected simulators and deploy each
zero-shot on the "real" robot (the robot the data was recorded on); see :mod:`wresdyn.experiments.skills`.

Writes ``OUT/report.md`` (the table, gap closed), ``OUT/results.json``, ``OUT/tracking_heldout.png`` and
``OUT/deployed_heldout.usda``; the corrections (``OUT/calibrated``, ``OUT/delta_action``) are fitted on DATA unless
given, and the four policies live in ``OUT/skills/``. Rerunning the same command resumes. Every line printed is also
in ``OUT/deploy.log`` (rsl-rl's tables in each policy's ``train.log``); on a terminal a progress bar per policy shows
the elapsed and remaining time (:mod:`wresdyn.progress`), ``--quiet`` prints nothing. With ``WRESDYN_LOG_CLOCK=1``
each line starts with the seconds since the process started (:mod:`wresdyn.cli.clock`).

The sizes are ``DeployConfig`` (``FloorDeployConfig`` with ``--floor``), the task ``--task.*`` is ``SkillConfig``
(``FloorTaskConfig`` with ``--floor``) and the PPO of every policy ``--ppo.*`` is ``SkillPPOConfig``
(:mod:`wresdyn.skills.skill_config`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal

import tyro

from ..experiments.deploy_config import DeployConfig, FloorDeployConfig
from ..paths import DEFAULT_DATASET
from ..skills.randomization_config import Randomization
from ..skills.skill_config import FloorTaskConfig, SkillConfig, SkillPPOConfig
from .command import FLAT, Command, CommandLineError, list_flags

PPO_FROM_SIZES = ("iterations", "restart_std", "seed", "device")
"""Fields of :class:`SkillPPOConfig` the benchmark sets from the sizes (``iterations``/``finetune``, ``finetune_std``,
``seed``, ``device``): no ``--ppo.*`` flag of their own (the worlds are the sizes' ``num_worlds``, the plants')."""


@dataclass(frozen=True)
class Deploy(Command):
    """``wresdyn deploy``: the corrections' dataset, where the benchmark goes, its sizes (:class:`DeployConfig`, its
    fields as flags), the tracking task (``--task.*``, :class:`SkillConfig`) and the PPO of every policy
    (``--ppo.*``, :class:`SkillPPOConfig`: worlds, iterations, restart noise, seed and device come from the
    sizes)."""

    data: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="DATA")] = str(DEFAULT_DATASET)
    """Dataset the corrections are fitted on; its mismatch is the real robot (default: the shipped one)."""
    out: str = "runs/deploy"
    """Output folder; rerun to resume."""
    calibrated: Annotated[str | None, tyro.conf.arg(metavar="RUN")] = None
    """The calibrated robot: a hybrid `wresdyn fit` run (None: fitted into OUT/calibrated)."""
    delta: Annotated[str | None, tyro.conf.arg(metavar="RUN")] = None
    """A delta-action `wresdyn fit --model network --residual.kind delta_action` run (None: fitted into
    OUT/delta_action)."""
    mismatch: str | None = None
    """Real robot's mismatch (TOML; None: the dataset's)."""
    heldout_ledger: Annotated[str | None, tyro.conf.arg(metavar="JSONL")] = None
    """A ledger besides OUT/heldout_ledger.jsonl (e.g. a benchmark folder's): each scoring of the held-out motions
    appends a line to both, and the report lists every configuration scored (None: OUT's only)."""
    floor: bool = False
    """Skills on the floor: the humanoid keeps its balance with a free base (squat, weight shift, kick, wave;
    stepping held out), corrections still fitted on the stand (see wresdyn.experiments.skills); the sizes
    and the task are then FloorDeployConfig's and FloorTaskConfig's (wresdyn deploy --floor --help)."""
    full: bool = False
    """The full size, for a GPU (DeployConfig.full, FloorDeployConfig.full; the sizes given still apply)."""
    policies: tuple[Literal["a_nominal", "b_calibrated", "c_delta_action", "d_oracle", "e_randomized",
                            "f_calibrated_narrow"], ...] = ()
    """The policies to train and deploy (a_nominal always); empty: a-d, on the floor on the CPU a, b, d (the
    delta-action residual's fit and fine-tuning would take a fifth of the CPU run). The domain-randomised baselines
    (e), (f) need per-world physics: on the floor a GPU."""
    animation: bool = True
    """Write the USD animation."""
    quiet: bool = False
    """Print nothing while deploying (OUT/deploy.log keeps every line; no progress bars)."""
    sizes: Annotated[DeployConfig, FLAT] = field(default_factory=DeployConfig)
    """The benchmark's sizes."""
    task: SkillConfig = field(default_factory=SkillConfig)
    """The tracking task."""
    ppo: SkillPPOConfig = field(default_factory=SkillPPOConfig)
    """PPO of every policy."""
    randomization: Randomization = field(default_factory=Randomization)
    """The domain randomisation of (e) (its wide ranges) and (f) (``unseen``: the range of what the identification
    could not see); its seed is the sizes' ``seed``."""


@dataclass(frozen=True)
class FloorDeploy(Deploy):
    """``wresdyn deploy --floor``: as :class:`Deploy`, with the sizes and the task of the skills on the floor."""

    sizes: Annotated[FloorDeployConfig, FLAT] = field(default_factory=FloorDeployConfig)
    """The benchmark's sizes."""
    task: FloorTaskConfig = field(default_factory=FloorTaskConfig)
    """The tracking task."""


FLOOR_CPU_POLICIES = ("a_nominal", "b_calibrated", "d_oracle")
"""What ``wresdyn deploy --floor`` trains and deploys on the CPU unless told: (a) (shipped), (b) and the oracle."""

COMMAND = Deploy
VARIANTS = (Deploy, FloorDeploy)
"""Every class the command line may be read as (deprecated spellings are rewritten against all of them)."""
VARIANT_FLAGS = ("--floor",)
"""The flags that pick a variant (the CLI reference shows each one's help too)."""
HIDDEN = {SkillPPOConfig: PPO_FROM_SIZES, Randomization: ("seed",)}
"""Config fields without a flag of their own (the benchmark sets them from the sizes)."""


def _last(argv: list[str], name: str) -> bool:
    """Whether the switch ``--name`` is on in ``argv`` (the last of ``--name`` and ``--no-name`` wins)."""
    seen = [a for a in argv if a in (f"--{name}", f"--no-{name}")]
    return bool(seen) and seen[-1] == f"--{name}"


def prepare(argv: list[str]):
    """``(class, default)`` of a deploy command line: ``--floor`` picks :class:`FloorDeploy`, ``--full``
    starts from the full sizes; a flag of the other setting is refused in one line."""
    floor, full = _last(argv, "floor"), _last(argv, "full")
    cls, other = (FloorDeploy, Deploy) if floor else (Deploy, FloorDeploy)
    own, theirs = list_flags(cls, HIDDEN), list_flags(other, HIDDEN)
    for flag in (a.partition("=")[0] for a in argv if a.startswith("--")):
        switch = flag.replace("--no-", "--", 1)  # --no-X: the switch --X's other half
        if flag not in own and switch not in own and (flag in theirs or switch in theirs):
            raise CommandLineError(f"{flag} sets the skills on the floor; it needs --floor" if not floor else
                                   f"{flag} sets the skills on the stand; it has no use with --floor")
    sizes = type(cls().sizes)
    return cls, cls(floor=floor, full=full, sizes=sizes.full() if full else sizes())


def run(args: Deploy) -> int:
    from pathlib import Path

    from ..data.loading import load_data
    from ..data.mismatch import Mismatch

    from dataclasses import replace

    cfg, task, ppo = args.sizes, args.task, args.ppo
    from ..experiments.skills import run_benchmark as bench
    ds, robot = load_data(args.data)
    mismatch = Mismatch.load(args.mismatch) if args.mismatch else None
    from .clock import ClockLog

    # WRESDYN_LOG_CLOCK=1 stamps the lines with the seconds since the process started (a whole seed's time, split)
    log = ClockLog(Path(args.out) / "deploy.log", quiet=args.quiet)
    log(f"wresdyn deploy: skills {'on the floor' if args.floor else 'on the stand'} on {robot.source.name} ({robot.n_dof} joints), corrections from {args.data}, "
          f"real robot {'from ' + args.mismatch if args.mismatch else 'as recorded in the dataset'} -> {args.out}")
    from ..sim.warmup import compile_kernels

    # the skills replay forward; the corrections not given are fitted here (identification, then gradient fits)
    shipped = getattr(cfg, "shipped", False)  # every policy taken as it is: nothing fitted
    policies = args.policies or (FLOOR_CPU_POLICIES if args.floor and (cfg.device == "cpu" or shipped) else ())
    wanted = set(policies or ("b_calibrated", "c_delta_action"))
    fit_cal = not args.calibrated and not shipped and bool(wanted & {"b_calibrated", "f_calibrated_narrow"})
    fit_delta = not args.delta and "c_delta_action" in wanted
    variants = ("forward",) + (("param_grads", "grad") if fit_cal else ()) + (("grad",) if fit_delta else ())
    compile_kernels(robot, ds.rate_hz, tuple(dict.fromkeys(variants)), device=cfg.device, say=log)
    bench(robot, ds, args.out, cfg, data_path=args.data, calibrated=args.calibrated, delta=args.delta,
          mismatch=mismatch, task=task, ppo=ppo, animation=args.animation, ledger=args.heldout_ledger, log=log,
          randomization=replace(args.randomization, seed=cfg.seed), **({"policies": policies} if policies else {}))
    return 0
