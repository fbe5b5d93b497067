"""``wresdyn ablate``: PPO vs gradient vs parametric × MLP/GRU × torque/delta action × seeds, on one dataset.

Writes ``OUT/table.md`` (held-out and OOD mean |Δq|, mean ± std over seeds, wall-clock, simulated steps),
``OUT/results.json`` and ``OUT/curves.png`` (held-out error against wall-clock and against simulated steps).
Each cell checkpoints; running the same command again resumes. ``--delays 0 0.005 0.01`` adds the delay sweep:
for each actuator delay the data are recorded again with the default mismatch (delay replaced) and MLP vs GRU
are compared in ``OUT/delay_<ms>ms/``, summarised in ``OUT/delay_sweep.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated

from ..choices import Learner
from ..experiments.ablation_config import AblationConfig
from .command import FLAT, Command


@dataclass(frozen=True)
class Ablate(Command):
    """``wresdyn ablate``: the dataset, where the table goes, the grid (:class:`AblationConfig`, its fields as
    flags; device cuda spreads the cells over every GPU of the host, --jobs at a time) and the delay sweep."""

    data: str | None = None
    """Dataset (.npz; default: data/dataset.npz)."""
    robot: str | None = None
    """Robot file (default: scenes/humanoid.usda)."""
    out: str = "runs/ablation"
    """Output folder."""
    ppo_envs: int | None = None
    """Override PPO's number of parallel envs."""
    windows: int | None = None
    """Override the gradient fit's parallel windows."""
    horizon: int | None = None
    """Override the gradient fit's window length [steps]."""
    jobs: int = 1
    """Cells run in parallel worker processes, one core (or a share of a GPU) each."""
    delays: tuple[float, ...] = ()
    """Delay sweep [s], e.g. 0 0.005 0.01."""
    delays_only: bool = False
    """Run only the delay sweep, not the main grid."""
    delay_learner: Learner = "gradient"
    """Learner of the delay sweep."""
    delay_trajectories: tuple[int, int, int, int] = (16, 4, 4, 4)
    """Train, validation, heldout, ood trajectories recorded per delay."""
    grid: Annotated[AblationConfig, FLAT] = field(default_factory=AblationConfig)
    """The grid."""

    @property
    def config(self) -> AblationConfig:
        """The grid with ``--ppo-envs``, ``--windows`` and ``--horizon`` as its PPO and gradient overrides."""
        grad = {k: v for k, v in {"windows": self.windows, "horizon": self.horizon}.items() if v is not None}
        return replace(self.grid, ppo_overrides={"env.num_worlds": self.ppo_envs} if self.ppo_envs is not None else {},
                       gradient_overrides=grad)


COMMAND = Ablate


def run(args: Ablate) -> int:
    import dataclasses

    from ..data.dataset import load_dataset
    from ..experiments.ablation import run_ablation
    from ..paths import DEFAULT_DATASET
    from ..robot.description import DEFAULT_ROBOT, load_robot

    # the config checks itself before the robot and data load: a bad flag fails at once
    cfg = args.config
    robot = load_robot(args.robot or DEFAULT_ROBOT)
    data_path = Path(args.data) if args.data else DEFAULT_DATASET
    dataset = load_dataset(data_path, robot=robot)
    out = Path(args.out)
    from ..sim.warmup import compile_kernels

    # once, before the cells (Warp's disk cache then serves every cell's process); "cuda" spreads cells over GPUs
    compile_kernels(robot, dataset.rate_hz, ("forward", "grad", "param_grads"),
                    device="cuda:0" if cfg.device == "cuda" else cfg.device)
    if not args.delays_only:
        run_ablation(robot, dataset, cfg, out, jobs=args.jobs)
        print((out / "table.md").read_text())
    if args.delays:
        _delay_sweep(robot, dataset, dataclasses.replace(cfg, learners=(args.delay_learner,), archs=("mlp", "gru"),
                                                         kinds=("torque",)), args, out)
    return 0


def _delay_sweep(robot, dataset, cfg, args, out: Path) -> None:
    import dataclasses

    import numpy as np

    from ..data.dataset import load_dataset
    from ..data.mismatch import Mismatch
    from ..data.real_robot import collect
    from ..experiments.ablation import cells, run_cells, write_summary

    base = Mismatch.from_dict(dataset.mismatch) if dataset.mismatch else Mismatch()
    n_train, n_val, n_held, n_ood = args.delay_trajectories
    grid = cells(cfg)
    folders, tasks = {}, []
    for delay in args.delays:
        folder = out / f"delay_{1e3 * delay:g}ms"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / "dataset.npz"
        if not path.is_file():
            mismatch = dataclasses.replace(base, delay=delay)
            print(f"recording data with actuator delay {1e3 * delay:g} ms")
            collect(robot, mismatch, {"train": n_train, "validation": n_val, "heldout": n_held, "ood": n_ood}, seed=dataset.seed or 0,
                    store_tau=False).save(path)
        data = load_dataset(path, robot=robot)
        folders[delay] = (folder, len(tasks))
        tasks += [(c, robot, data, cfg, folder / c["name"]) for c in grid]
    results = run_cells(tasks, args.jobs)  # every delay's cells in one pool
    rows = ["| delay [ms] | PD-only held-out [rad] | MLP held-out [rad] | GRU held-out [rad] | GRU / MLP |",
            "|---|---|---|---|---|"]
    for delay, (folder, first) in folders.items():
        res = results[first : first + len(grid)]
        write_summary(res, cfg, folder)
        by_arch = {a: np.mean([r["heldout"]["mean_abs_dq"] for r in res if r["arch"] == a]) for a in ("mlp", "gru")}
        pd = res[0]["heldout_pd_only"]["mean_abs_dq"]
        rows.append(f"| {1e3 * delay:g} | {pd:.4f} | {by_arch['mlp']:.4f} | {by_arch['gru']:.4f} | "
                    f"{by_arch['gru'] / by_arch['mlp']:.2f} |")
    text = "\n".join(rows) + f"\n\nLearner: {cfg.learners[0]}, torque residual, seeds {list(cfg.seeds)}.\n"
    (out / "delay_sweep.md").write_text(text)
    print(text)

