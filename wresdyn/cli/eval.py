"""``wresdyn eval RUN``: open-loop replay of held-out and OOD trajectories, PD-only vs PD + the run's residual.

Writes ``metrics.json``, ``report.md``, a Fig. 3-style plot per split and the learning curves (Fig. 4 style,
with ``--compare`` runs overlaid) into ``RUN/eval`` (or ``--out``).
"""

from __future__ import annotations

import argparse

from ..choices import SolverKind, choices


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run folder written by `wresdyn train`")
    p.add_argument("--data", default=None, help="dataset file (default: the one the run was trained on)")
    p.add_argument("--robot", default=None, help="robot file (default: the dataset's)")
    p.add_argument("--gains", default=None,
                   help="gains config (TOML) by joint-name pattern; replaces the one stored in the dataset")
    p.add_argument("--splits", nargs="+", default=["validation", "heldout", "ood"],
                   help="splits to evaluate (default: validation heldout ood; absent splits are skipped)")
    p.add_argument("--out", default=None, help="output folder (default: RUN/eval)")
    p.add_argument("--solver", choices=choices(SolverKind), default=None,
                   help="Newton solver (default: the one the run was trained with)")
    p.add_argument("--device", default="cpu", help="cpu or cuda:0")
    p.add_argument("--joints", type=int, default=6, help="joints in the Fig. 3 plot (largest PD-only error first)")
    p.add_argument("--compare", nargs="*", default=[], metavar="RUN", help="other runs to overlay in the learning curves")



def run(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from ..data.loading import load_data
    from ..evaluation.evaluate_run import evaluate_run
    from . import UserError

    cfg_path = Path(args.run) / "config.json"
    if not cfg_path.is_file():
        raise UserError(f"{args.run}: not a run folder (no config.json)")
    data = args.data or json.loads(cfg_path.read_text()).get("data_path")
    if not data:
        raise UserError(f"{args.run}: the run does not record its dataset; pass --data")
    ds, robot = load_data(data, args.robot, args.gains)
    evaluate_run(args.run, ds, robot, args.splits, args.out, args.solver, args.device, args.joints, args.compare,
                 data_label=str(data))
    return 0
