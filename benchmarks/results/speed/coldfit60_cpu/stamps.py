"""The phases of stamped fit logs (``WRESDYN_LOG_CLOCK=1``), as in the GPU accounting: each loop's seconds between
its stamps, its training wall-clock (the run's curve, validations excluded) and the rest (validations, checkpoints,
logging), for each (log, run folder) pair given.

    python stamps.py LOG RUN [LOG RUN ...]
"""
import json
import re
import sys

MARKS = [("first line", r"gradient fit of a"), ("kernels done", r"\.\.\. done in"), ("stage 1", r"stage 1/2"),
         ("id start", r"start: validation"), ("id end", r"identification: .*(done|converged)"),
         ("stage 2", r"stage 2/2"), ("fit start", r"validation at the start"),
         ("fit end", r"gradient fit: .*(done|converged)"), ("done", r"^done:"), ("eval done", r"evaluation done")]


def stamps(log):
    out = {}
    for line in open(log):
        m = re.match(r"\[\s*([\d.]+) s\] (.*)", line)
        if m:
            for name, pat in MARKS:
                if name not in out and re.search(pat, m.group(2)):
                    out[name] = float(m.group(1))
        m = re.match(r"whole command: ([\d.]+) s", line)
        if m:
            out["whole"] = float(m.group(1))
    return out


args = sys.argv[1:]
for log, run in zip(args[::2], args[1::2]):
    s = stamps(log)
    id_wall = json.load(open(f"{run}/identify/curve.json"))[-1]["wall"]
    fit_wall = json.load(open(f"{run}/curve.json"))[-1]["wall"]
    id_loop, fit_loop = s["id end"] - s["id start"], s["fit end"] - s["fit start"]
    print(f"{log}: start+imports {s['first line']:.1f}, kernels {s['kernels done'] - s['first line']:.1f}, "
          f"stage-1 set-up {s['id start'] - s['stage 1']:.1f}, identification loop {id_loop:.1f} "
          f"(training {id_wall:.1f}, rest {id_loop - id_wall:.1f}), after it to stage 2 {s['stage 2'] - s['id end']:.1f}, "
          f"stage-2 set-up {s['fit start'] - s['stage 2']:.1f}, residual loop {fit_loop:.1f} (training {fit_wall:.1f}, "
          f"rest {fit_loop - fit_wall:.1f}), export {s['done'] - s['fit end']:.1f}, "
          f"evaluation {s['eval done'] - s['done']:.1f}, whole {s.get('whole', float('nan')):.1f} s")
