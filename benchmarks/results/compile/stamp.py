"""Prefix each line read from stdin with the seconds since this script started (the command's wall-clock)."""
import sys
import time

t0 = time.perf_counter()
for line in sys.stdin:
    sys.stdout.write(f"[{time.perf_counter() - t0:8.1f} s] {line}")
    sys.stdout.flush()
