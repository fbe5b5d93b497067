"""The ensembles' validation against their members' and the recipe's three-seed mean: the choice of this folder
(run from benchmarks/results/so101_servo/). Reads every run's eval_metrics.json as scored.

    python ensemble/compare.py
"""

import json
from pathlib import Path

CANDIDATES = {
    "ensemble/gru_delta_mean3": ("the recipe's three GRU delta-action residuals averaged per step on its servo model",
                                 ["hybrid/gru_delta", "hybrid/gru_delta_seed1", "hybrid/gru_delta_seed2"]),
    "ensemble/servo_mean3": ("the three kappa 1e5 servo models' parameters averaged, alone",
                             ["effort/k1e5_reset", "k1e5/reset_seed1", "k1e5/reset_seed2"]),
}
PD_RUN = Path(__file__).resolve().parents[2] / "so101" / "hybrid_gain_grid_eval_metrics.json"
"""The robot file's PD model, what ``benchmarks/real/so101_servo_ratios.py`` gives the ratios against."""
RECIPE = ["hybrid/gru_delta", "hybrid/gru_delta_seed1", "hybrid/gru_delta_seed2"]
"""The reported recipe's seeds: seed 0 is the row of record, the mean over three the figure it was chosen on."""


def validation(run: str) -> float:
    return json.loads(Path(run, "eval_metrics.json").read_text())["splits"]["validation"]["pd_residual"]["mean_abs_dq"]


def main() -> None:
    pd = json.loads(PD_RUN.read_text())["splits"]["validation"]["pd_only"]["mean_abs_dq"]
    seed0, mean = validation(RECIPE[0]), sum(map(validation, RECIPE)) / len(RECIPE)
    print(f"the reported recipe: seed 0 {seed0:.5f}, mean of three seeds {mean:.5f} rad (validation)")
    for run, (what, members) in CANDIDATES.items():
        v = [validation(m) for m in members]
        ratio = pd / validation(run)
        print(f"{run}: {what}\n  validation {validation(run):.5f} rad ({ratio:.2f}x the file's PD model);"
              f" members {' / '.join(f'{x:.5f}' for x in v)}"
              f" (mean {sum(v) / len(v):.5f}, best {min(v):.5f})\n"
              f"  against the recipe's seed 0: {validation(run) / seed0 - 1:+.1%}, its three-seed mean:"
              f" {validation(run) / mean - 1:+.1%}: {'better' if validation(run) < mean else 'not better'}")


if __name__ == "__main__":
    main()
