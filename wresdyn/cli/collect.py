"""``wresdyn collect``: record a dataset on the simulated real robot, or import real logs into one.

Simulated: draws excitations (train / validation / held-out: the paper's ellipsoid foot paths, eq. 2;
out-of-distribution: chirps and kicks), executes them under PD on the MuJoCo "real" robot with the mismatch
config, and writes ``OUT/dataset.npz`` and ``OUT/spectrum.png`` (command spectrum per split). It then replays
the validation, held-out and OOD commands PD-only in Newton and reports the gap (mean |Δq|), also stored in the
dataset's meta.
Logs: ``--logs A.csv B.npz ...`` imports real logs (docs/dataset.md) onto the ``--rate`` grid instead.
"""

from __future__ import annotations

import argparse
from pathlib import Path

DEFAULT_MISMATCH = Path(__file__).resolve().parents[2] / "data" / "mismatch_default.toml"  # wresdyn.paths, no import


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--robot", default=None, help="robot file (default: scenes/humanoid.usda)")
    p.add_argument("--gains", default=None, help="TOML file of PD gains by joint-name pattern")
    p.add_argument("--mismatch", default=str(DEFAULT_MISMATCH),
                   help="mismatch config (TOML) of the real robot, or 'none' for the nominal robot "
                        "(default: data/mismatch_default.toml)")
    p.add_argument("--train", type=int, default=16, help="number of training trajectories")
    p.add_argument("--validation", type=int, default=4,
                   help="number of validation trajectories (same family as train; for every tuning choice)")
    p.add_argument("--heldout", type=int, default=4, help="number of held-out trajectories (same family as train)")
    p.add_argument("--ood", type=int, default=4, help="number of out-of-distribution trajectories (chirp, kick)")
    p.add_argument("--duration", type=float, default=4.0, help="length of each trajectory [s]")
    p.add_argument("--rate", type=float, default=500.0, help="command and recording rate [Hz]")
    p.add_argument("--seed", type=int, default=0, help="master seed (same seed, same data)")
    p.add_argument("--out", default="data", help="output folder (default: data)")
    p.add_argument("--no-tau", action="store_true", help="do not store the measured (diagnostic) torque")
    p.add_argument("--no-gap", action="store_true", help="skip the PD-only Newton replay that measures the gap")
    p.add_argument("--logs", nargs="+", default=None, metavar="LOG",
                   help="import these real logs (.csv/.npz) instead of simulating")
    from ..data.dataset import SPLITS  # numpy only: cheap

    p.add_argument("--split", default="heldout", choices=SPLITS, help="split of imported logs (default: heldout)")


def _say(line: str) -> None:
    print(line, flush=True)


def run(args: argparse.Namespace) -> int:
    from ..data.dataset import SPLITS
    from ..robot.description import DEFAULT_ROBOT, load_robot
    from . import UserError

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"{out}: --out must be a folder")
    if not args.rate > 0:
        raise UserError(f"--rate must be > 0, not {args.rate}")
    robot = load_robot(args.robot or DEFAULT_ROBOT, gains=args.gains)
    robot.check_gains()
    path = out / "dataset.npz"
    if args.logs:
        from ..data.logs import import_logs

        ds = import_logs(args.logs, robot, args.rate, args.split)
        out.mkdir(parents=True, exist_ok=True)
        ds.save(path)
        _say(f"imported {len(ds.trajectories)} log(s) into {path} at {args.rate:g} Hz, split {args.split}")
        return 0

    from ..data.excitation import plot_spectrum
    from ..data.real_robot import Mismatch, collect
    from ..evaluation.evaluate import pd_gap

    counts = {"train": args.train, "validation": args.validation, "heldout": args.heldout, "ood": args.ood}
    if any(n < 0 for n in counts.values()) or sum(counts.values()) == 0:
        raise UserError("--train/--validation/--heldout/--ood must be >= 0 and not all 0")
    if not args.duration * args.rate >= 2:
        raise UserError(f"--duration {args.duration} s at {args.rate:g} Hz gives fewer than 2 samples")
    mismatch = Mismatch() if args.mismatch.lower() == "none" else Mismatch.load(args.mismatch)
    _say(f"collecting {sum(counts.values())} trajectories of {args.duration:g} s at {args.rate:g} Hz on "
         f"{robot.source.name} with mismatch {'none (nominal)' if mismatch.is_nominal() else args.mismatch}, "
         f"seed {args.seed}")
    ds = collect(robot, mismatch, counts, args.duration, args.rate, args.seed, store_tau=not args.no_tau,
                 progress=_say)
    if not args.no_gap:
        gaps = {}
        for split in ("validation", "heldout", "ood"):
            trajs = ds.split(split)
            if trajs:
                _say(f"replaying {len(trajs)} {split} trajectories PD-only in Newton (nominal robot)")
                g = gaps[split] = pd_gap(robot, trajs, args.rate)
                _say(f"  PD-only vs real on {split}: mean |dq| {g['mean']:.4f} +- {g['std']:.4f} rad")
        ds.meta["pd_only_gap"] = gaps
    out.mkdir(parents=True, exist_ok=True)
    ds.save(path)
    plot_spectrum({s: [tr.q_cmd for tr in ds.split(s)] for s in SPLITS}, args.rate, out / "spectrum.png",
                  ds.joint_names)
    _say(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB) and {out / 'spectrum.png'}")
    return 0

