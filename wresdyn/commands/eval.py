"""``wresdyn eval RUN``: open-loop replay of held-out and OOD trajectories, PD-only vs PD + the run's residual.

Writes ``metrics.json``, ``report.md``, a Fig. 3-style plot per split and the learning curves (Fig. 4 style,
with ``--compare`` runs overlaid) into ``RUN/eval`` (or ``--out``).
"""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run folder written by `wresdyn train`")
    p.add_argument("--data", default=None, help="dataset file (default: the one the run was trained on)")
    p.add_argument("--robot", default=None, help="robot file (default: the dataset's)")
    p.add_argument("--splits", nargs="+", default=["heldout", "ood"], help="splits to evaluate (default: heldout ood)")
    p.add_argument("--out", default=None, help="output folder (default: RUN/eval)")
    p.add_argument("--solver", default=None, help="Newton solver (default: the one the run was trained with)")
    p.add_argument("--device", default="cpu", help="cpu or cuda:0")
    p.add_argument("--joints", type=int, default=6, help="joints in the Fig. 3 plot (largest PD-only error first)")
    p.add_argument("--compare", nargs="*", default=[], metavar="RUN", help="other runs to overlay in the learning curves")


def evaluate_run(run: str, ds, robot, splits=("heldout", "ood"), out: str | None = None, solver: str | None = None,
                 device: str = "cpu", joints: int = 6, compare=(), data_label: str = "") -> dict:
    """Evaluate the exported residual of ``run`` on ``splits`` of ``ds`` and write the report; returns the
    per-split summaries."""
    import json
    from pathlib import Path

    import torch

    from ..cli import UserError
    from ..evaluate import evaluate_split, plot_fig3, plot_learning_curves, write_report
    from ..ppo import RunError, config_from_dict, load_policy

    torch.set_num_threads(1)
    run_dir = Path(run)
    try:
        policy, meta = load_policy(run_dir)
    except RunError as e:
        raise UserError(str(e)) from None
    cfg = config_from_dict(json.loads((run_dir / "config.json").read_text())["config"])
    if list(meta["joint_names"]) != list(robot.joint_names):
        raise UserError(f"{run_dir}: trained on joints {meta['joint_names'][:3]}..., not this robot's")
    if abs(meta["rate_hz"] - ds.rate_hz) > 1e-9:
        raise UserError(f"{run_dir}: trained at {meta['rate_hz']:g} Hz, the data is at {ds.rate_hz:g} Hz")
    solver = solver or cfg.env.solver
    out_dir = Path(out) if out else run_dir / "eval"
    results = {}
    for split in splits:
        trajs = ds.split(split)
        if not trajs:
            print(f"{split}: no trajectories, skipped")
            continue
        summary, runs = evaluate_split(robot, trajs, ds.rate_hz, policy, meta["kind"], solver, cfg.env.substeps, device)
        results[split] = summary
        plot_fig3(robot, trajs[0], runs, out_dir / f"fig3_{split}.png", ds.rate_hz, joints,
                  title=f"{split}: {trajs[0].name} (red: real, green: PD only, blue: PD + residual)")
        pd, res = summary["pd_only"], summary["pd_residual"]
        print(f"{split:8s} {len(trajs)} traj  mean |dq| PD only {pd['mean_abs_dq']:.4f} ± {pd['std_abs_dq']:.4f} rad  "
              f"PD + residual {res['mean_abs_dq']:.4f} ± {res['std_abs_dq']:.4f} rad  ({summary['improvement']:.2f}x)  "
              f"vel {pd['mean_abs_dqd']:.3f} -> {res['mean_abs_dqd']:.3f} rad/s", flush=True)
    curves = {run_dir.name: run_dir, **{Path(c).name: Path(c) for c in compare}}
    plot_learning_curves(curves, out_dir / "fig4_learning_curves.png")
    write_report(out_dir, robot, results, {"run": str(run_dir), "residual": meta["kind"], "arch": meta["arch"],
                                           "solver": solver, "dataset": data_label, "robot": str(robot.source)})
    print(f"wrote {out_dir / 'metrics.json'} and {out_dir / 'report.md'}")
    return results


def run(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from ..cli import UserError
    from .train import load_data

    cfg_path = Path(args.run) / "config.json"
    if not cfg_path.is_file():
        raise UserError(f"{args.run}: not a run folder (no config.json)")
    data = args.data or json.loads(cfg_path.read_text()).get("data_path")
    if not data:
        raise UserError(f"{args.run}: the run does not record its dataset; pass --data")
    ds, robot = load_data(data, args.robot)
    evaluate_run(args.run, ds, robot, args.splits, args.out, args.solver, args.device, args.joints, args.compare,
                 data_label=str(data))
    return 0
