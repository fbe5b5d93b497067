"""Every residual stage on a validated start in the stored logs: its start's validation, its checks' validations, the
first check that beat the start and the iteration selected. Fits until a plateau (``iter N`` lines with no ``/TOTAL``)
are the ones ``beat_start_within`` applies to; fixed counts are listed apart. Identical curves (one fit logged in
several files) are listed once, with how many files hold them.

    python benchmarks/results/speed/fitcut57_cpu/start_rule_curves.py   (from the repository root)
"""
import re
import subprocess

START = re.compile(r"validation at the start: ([0-9.]+) rad")
ITER = re.compile(r"iter\s+(\d+)(/\d+)?\s+H=\s*\d+.*validation ([0-9.]+) rad")
SELECTED = re.compile(r"selected iteration (\d+) by validation \(([0-9.]+) rad\)")

files = subprocess.run(["git", "grep", "-l", "validation at the start", "--", "benchmarks"], capture_output=True,
                       text=True, check=True).stdout.split()
seen: dict[tuple, list[str]] = {}
for f in files:
    lines = open(f, errors="replace").read().splitlines()
    i = 0
    while i < len(lines):
        m = START.search(lines[i])
        i += 1
        if not m:
            continue
        checks, fixed, selected = [], False, None
        while i < len(lines) and not START.search(lines[i]):
            mi, ms = ITER.search(lines[i]), SELECTED.search(lines[i])
            i += 1
            if mi:
                checks.append(float(mi.group(3)))
                fixed = fixed or mi.group(2) is not None
            if ms:
                selected = int(ms.group(1))
                break
        if checks and selected is not None:
            seen.setdefault((float(m.group(1)), tuple(checks), fixed, selected), []).append(f)
for fixed in (False, True):
    print("until a plateau (a check every 40 iterations):" if not fixed else "\nfixed counts (ten checks):")
    for (start, checks, fx, selected), where in sorted(seen.items(), key=lambda kv: kv[1][0]):
        if fx != fixed:
            continue
        first = next((k + 1 for k, v in enumerate(checks) if v < start), None)
        print(f"  {where[0]} ({len(where)} file{'s' if len(where) > 1 else ''}): start {start:.4f} rad, "
              f"{len(checks)} checks, first below the start (4 decimals): {first or 'none'}, selected {selected}")
