"""Mean |dq| [rad] of identification runs on the real SO-101 splits and their ratios against the robot file's PD model
(the PD-only replay of ``benchmarks/results/so101/``), as the servo rows of ``docs/results/real-data.md`` give them.

    python benchmarks/real/so101_servo_ratios.py RUN [RUN ...]      # each RUN holds eval/metrics.json
                                                                    # (or, as kept in results/, eval_metrics.json)
"""

import json
import sys
from pathlib import Path

PD_RUN = Path(__file__).resolve().parents[1] / "results" / "so101" / "hybrid_gain_grid_eval_metrics.json"


def main() -> None:
    pd = {s: v["pd_only"]["mean_abs_dq"] for s, v in json.loads(PD_RUN.read_text())["splits"].items()}
    for run in sys.argv[1:]:
        path = Path(run) / "eval" / "metrics.json"
        splits = json.loads((path if path.exists() else Path(run) / "eval_metrics.json").read_text())["splits"]
        cells = []
        for s in ("validation", "heldout", "ood"):
            dq = splits[s]["pd_residual"]["mean_abs_dq"]
            cells.append(f"{s} {dq:.4f} ({pd[s] / dq:.2f}x)")
        print(f"{run}: " + "  ".join(cells))


if __name__ == "__main__":
    main()
