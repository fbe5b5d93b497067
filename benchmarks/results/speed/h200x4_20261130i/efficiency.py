"""Each variant's 2- and 4-process efficiency per round, from the JSON rows of ppo90/ (run from this folder).

Efficiency = the 2- (4-) process launch's ``training_steps_per_s`` over twice (four times) the same round's 1-process
one, the definition of ``summary.json``'s ``ppo_residual_2gpu_efficiency`` and ``ppo_residual_4gpu_efficiency``; then
``+defer_log``'s throughput against ``+graph`` in the same launch.

    python efficiency.py > efficiency.txt
"""

import json
from pathlib import Path

VARIANTS = ("graph", "graph+defer_log")
ROUNDS = (1, 2, 3)
LAUNCHES = (("two", 2), ("four", 4))


def rate(launch: str, rnd: int) -> dict[str, float]:
    rows = json.loads(Path("ppo90", f"{launch}_r{rnd}.json").read_text())["rows"]
    return {r["options"]: r["training_steps_per_s"] for r in rows}


def main() -> None:
    runs = {launch: {r: rate(launch, r) for r in ROUNDS} for launch in ("one", "two", "four")}
    one = runs["one"]
    print("| variant | round | 1 process: env-steps/s | 2 processes: env-steps/s | efficiency | "
          "4 processes: env-steps/s | efficiency |")
    print("|---|---|---|---|---|---|---|")
    for v in VARIANTS:
        for r in ROUNDS:
            cells = [f"{one[r][v] / 1e6:.3f}M"]
            for launch, n in LAUNCHES:
                got = runs[launch][r][v]
                cells += [f"{got / 1e6:.3f}M", f"{got / (n * one[r][v]):.4f}"]
            print(f"| +{v} | {r} | " + " | ".join(cells) + " |")
        pooled = [sum(runs[launch][r][v] for r in ROUNDS) / (n * sum(one[r][v] for r in ROUNDS))
                  for launch, n in LAUNCHES]
        print(f"| +{v} | pooled | | | {pooled[0]:.4f} | | {pooled[1]:.4f} |")
    print()
    print("| variant | round | 1 process: over +graph | 2 processes: over +graph | 4 processes: over +graph |")
    print("|---|---|---|---|---|")
    for v in VARIANTS[1:]:
        for r in ROUNDS:
            ratios = [runs[launch][r][v] / runs[launch][r]["graph"] for launch in ("one", "two", "four")]
            print(f"| +{v} | {r} | " + " | ".join(f"{x:.3f}" for x in ratios) + " |")


if __name__ == "__main__":
    main()
