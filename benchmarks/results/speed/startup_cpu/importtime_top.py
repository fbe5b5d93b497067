"""Top-level imports of a ``python -X importtime`` log (stderr), by cumulative seconds, largest first.

    python importtime_top.py IMPORTTIME_STDERR [N]
"""
import re
import sys

rows = []
for line in open(sys.argv[1], errors="replace"):
    m = re.match(r"import time:\s+(\d+) \|\s+(\d+) \|( *)(\S+)", line)
    if m and len(m[3]) == 1:
        rows.append((int(m[2]) / 1e6, m[4]))
rows.sort(reverse=True)
for s, name in rows[:int(sys.argv[2]) if len(sys.argv) > 2 else 25]:
    print(f"{s:6.2f} s  {name}")
print(f"{sum(s for s, _ in rows):6.2f} s  all top-level imports")
