"""Each variant's 2-process efficiency per round, from the JSON rows of ppo90/ (run from this folder).

Efficiency = the 2-process launch's ``training_steps_per_s`` over twice the same round's 1-process one, the
definition of ``summary.json``'s ``ppo_residual_2gpu_efficiency``; then each option's throughput against ``+graph``
in the same launch.

    python efficiency.py > efficiency.txt
"""

import json
from pathlib import Path

VARIANTS = ("graph", "graph+defer_log", "graph+pin+defer_log")
ROUNDS = (1, 2, 3)


def rate(launch: str, rnd: int) -> dict[str, float]:
    rows = json.loads(Path("ppo90", f"{launch}_r{rnd}.json").read_text())["rows"]
    return {r["options"]: r["training_steps_per_s"] for r in rows}


def main() -> None:
    one = {r: rate("one", r) for r in ROUNDS}
    two = {r: rate("two", r) for r in ROUNDS}
    print("| variant | round | 1 process: env-steps/s | 2 processes: env-steps/s | efficiency |")
    print("|---|---|---|---|---|")
    for v in VARIANTS:
        for r in ROUNDS:
            eff = two[r][v] / (2 * one[r][v])
            print(f"| +{v} | {r} | {one[r][v] / 1e6:.3f}M | {two[r][v] / 1e6:.3f}M | {eff:.4f} |")
        pooled = sum(two[r][v] for r in ROUNDS) / (2 * sum(one[r][v] for r in ROUNDS))
        print(f"| +{v} | pooled | | | {pooled:.4f} |")
    print()
    print("| variant | round | 1 process: over +graph | 2 processes: over +graph |")
    print("|---|---|---|---|")
    for v in VARIANTS[1:]:
        for r in ROUNDS:
            print(f"| +{v} | {r} | {one[r][v] / one[r]['graph']:.3f} | {two[r][v] / two[r]['graph']:.3f} |")


if __name__ == "__main__":
    main()
