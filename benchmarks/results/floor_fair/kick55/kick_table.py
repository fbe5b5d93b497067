"""The kick successes of every ``floor_kick_gap.py`` output here, per policy and condition, summed over the runs
that played it (their ``summary`` lines): ``python kick_table.py PREFIX... > table.md``; a PREFIX picks the files
(``f_``, ``c_``, ...), and a run's figure is read from the first file that has it."""

import json
import re
import sys
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).parent
VARIANTS = (("cal_cand1_end", "candidate 1's far end"), ("cal_wide_torso_effort", "torso at (e)'s end, effort x0.9"),
            ("cal_wide_torso", "torso at (e)'s end"),
            ("cal_torso_effort", "torso+effort true"), ("cal_effort", "effort true"), ("cal_torso", "torso true"))
"""The calibrated folders of ``variants.py`` and ``range_ends.py`` and their labels, the longest name first."""


def main(here: Path = HERE, variants: tuple = VARIANTS) -> None:
    """The table of ``here``'s outputs, the calibrated simulator's rows labelled by ``variants``."""
    got = defaultdict(dict)  # (policy, condition) -> {run: [0/1 per kick]}
    for prefix in sys.argv[1:] or [""]:
        for path in sorted(here.glob(f"{prefix}*.txt")):
            text = path.read_text()
            if "\nsummary " not in text:  # still running
                continue
            run = re.search(r"floor_unvp\w*_s\d", text).group(0)
            line = next(x for x in text.splitlines() if x.startswith("summary "))
            cal_line = next(x for x in text.splitlines() if ": 16 validation motions" in x)
            cal = next((label for key, label in variants if key in cal_line), "")
            for key, ok in json.loads(line[len("summary "):]).items():
                policy, cond = key.split(" | ")
                if cond == "calibrated sim" and cal:
                    cond = f"calibrated sim, {cal}"
                got[(policy, cond)].setdefault(run, ok)
    runs = sorted({r for v in got.values() for r in v})
    print("| policy | condition | kicks won | " + " | ".join(runs) + " |")
    print("|---|---|---|" + "---|" * len(runs))
    for (policy, cond), per in got.items():
        won, n = sum(sum(v) for v in per.values()), sum(len(v) for v in per.values())
        cells = [f"{sum(per[r])}/{len(per[r])}" if r in per else "" for r in runs]
        print(f"| {policy} | {cond} | {won}/{n} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
