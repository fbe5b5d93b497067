"""The phases of fit logs stamped with WRESDYN_LOG_CLOCK=1, one row per log.

    python stamps.py LOG[:RUN] ...

Seconds since the process started, read off the stamped lines: ``start`` (to the first fit line: imports, CUDA,
data), ``kernels`` (the kernel load line's), ``set-up 1`` (stage 1's line to ``start: validation``), ``identif.``
(``effort limits`` to the ``identifiability`` line), ``set-up 2`` (stage 2's line to ``validation at the start``),
``end`` (stage 2's ``selected iteration`` to ``done:``), ``eval`` (``evaluating the run`` to ``evaluation done``),
``whole`` (the shell's clock, the log's last line, else the last stamp); with RUN (the run folder), ``training``
(``wall_s`` of its train_summary.json: both loops' training clocks) and ``other`` (whole less training).
"""
import json
import re
import sys

COLS = ("start", "kernels", "set-up 1", "identif.", "set-up 2", "end", "eval", "whole", "training", "other")


def stamps(path):
    rows = []
    for line in open(path, errors="replace"):
        m = re.match(r"\[\s*([0-9.]+) s\] (.*)", line)
        if m:
            rows.append((float(m[1]), m[2]))
    whole = re.search(r"whole command: ([0-9.]+) s", open(path).read())
    return rows, float(whole[1]) if whole else (rows[-1][0] if rows else float("nan"))


def at(rows, prefix, nth=0):
    hits = [t for t, text in rows if text.startswith(prefix)]
    return hits[nth] if len(hits) > nth else float("nan")


def main():
    print("| log | " + " | ".join(COLS) + " |")
    print("|---|" + "---|" * len(COLS))
    for arg in sys.argv[1:]:
        log, _, run = arg.partition(":")
        rows, whole = stamps(log)
        v = {"start": rows[0][0], "kernels": at(rows, "... done in") - at(rows, "compiling Warp"),
             "set-up 1": at(rows, "start: validation") - at(rows, "stage 1/2"),
             "identif.": at(rows, "identifiability:") - at(rows, "effort limits"),
             "set-up 2": at(rows, "validation at the start") - at(rows, "stage 2/2"),
             "end": at(rows, "done:") - at(rows, "selected iteration", 1),
             "eval": at(rows, "evaluation done") - at(rows, "evaluating the run"), "whole": whole}
        if run:
            v["training"] = json.load(open(f"{run}/train_summary.json"))["wall_s"]
            v["other"] = whole - v["training"]
        name = log.rsplit("/", 1)[-1]
        print(f"| {name} | " + " | ".join(f"{v[c]:.1f}" if c in v else "" for c in COLS) + " |")


if __name__ == "__main__":
    main()
