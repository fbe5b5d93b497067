"""The fixed phases of stamped fit logs (WRESDYN_LOG_CLOCK=1), one row per log, and the mean of each group.

    python phases.py LOG[:RUN] ...

Columns, seconds: ``to line 1`` (the first fit line: imports, data; on this branch with torch._dynamo's import),
``kernels`` (the kernel load), ``set-up 1`` (stage 1's line to ``start: validation``: the identification's set-up and
its first validation; on main with torch._dynamo's import), ``line 1 + set-up 1`` (the two together, the same work on
both trees), ``to iter 1`` (``first iteration of identify``), ``identif.`` (``effort limits`` to ``identifiability``),
``set-up 2`` (stage 2's line to ``validation at the start``), ``end`` (stage 2's selection to ``done:``), ``eval``
(``evaluating the run`` to ``evaluation done``), ``whole`` (the shell's clock on the last line), with RUN
``training`` (train_summary.json's ``wall_s``) and ``other`` (whole less training). A group is the logs whose name
differs only in its last digit.
"""
import json
import re
import statistics
import sys

COLS = ("to line 1", "kernels", "set-up 1", "line 1 + set-up 1", "to iter 1", "identif.", "set-up 2", "end", "eval",
        "whole", "training", "other")


def read(path):
    text = open(path, errors="replace").read()
    rows = [(float(m[1]), m[2]) for m in re.finditer(r"^\[\s*([0-9.]+) s\] (.*)$", text, re.M)]
    whole = re.search(r"whole command: ([0-9.]+) s", text)
    return rows, float(whole[1]) if whole else float("nan")


def at(rows, prefix):
    return next((t for t, s in rows if s.startswith(prefix)), float("nan"))


def phases(log, run):
    rows, whole = read(log)
    line1 = at(rows, "gradient fit of a")
    v = {"to line 1": line1, "kernels": at(rows, "... done in") - at(rows, "compiling Warp"),
         "set-up 1": at(rows, "start: validation") - at(rows, "stage 1/2"),
         "to iter 1": at(rows, "first iteration of identify"),
         "identif.": at(rows, "identifiability:") - at(rows, "effort limits"),
         "set-up 2": at(rows, "validation at the start") - at(rows, "stage 2/2"),
         "end": at(rows, "done:") - [t for t, s in rows if s.startswith("selected iteration")][-1],
         "eval": at(rows, "evaluation done") - at(rows, "evaluating the run"), "whole": whole}
    v["line 1 + set-up 1"] = v["to line 1"] + v["set-up 1"]
    if run:
        v["training"] = json.load(open(f"{run}/train_summary.json"))["wall_s"]
        v["other"] = whole - v["training"]
    return v


def main():
    print("| log | " + " | ".join(COLS) + " |")
    print("|---|" + "---|" * len(COLS))
    groups = {}
    for arg in sys.argv[1:]:
        log, _, run = arg.partition(":")
        v = phases(log, run)
        name = log.rsplit("/", 1)[-1]
        groups.setdefault(re.sub(r"\d*\.log$", "", name), []).append(v)
        print(f"| {name} | " + " | ".join(f"{v.get(c, float('nan')):.1f}" for c in COLS) + " |")
    for g, vs in groups.items():
        if len(vs) > 1:
            print(f"| **{g} mean of {len(vs)}** | " + " | ".join(
                f"{statistics.mean(x.get(c, float('nan')) for x in vs):.2f}" for c in COLS) + " |")


if __name__ == "__main__":
    main()
