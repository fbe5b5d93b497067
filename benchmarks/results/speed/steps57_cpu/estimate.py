"""ESTIMATE (not measured): the H200 seconds the fewer kernels per window step would save over the gradient fit's 2000
iterations, from the CPU counts in before/ and after/ (torch operators that are a kernel on CUDA, plus Warp memsets),
at ~2 µs a kernel (the fused H = 64 profile's chain, ../h200_20261201b/) and the fixed schedule's iterations per window
length (2000 iterations, six lengths 2-64 in equal parts: 334, 333, 333, 334, 333, 333; 41 976 window steps).

    python benchmarks/results/speed/steps57_cpu/estimate.py > benchmarks/results/speed/steps57_cpu/estimate.txt
"""

import re
from pathlib import Path

HERE = Path(__file__).resolve().parent
ITERATIONS = {2: 334, 4: 333, 8: 333, 16: 334, 32: 333, 64: 333}
US_PER_KERNEL = 2.0


def kernels(path: Path) -> tuple[int, int]:
    """(torch operators that are a kernel on CUDA, Warp memsets) of one iteration."""
    first, second = path.read_text().splitlines()[:2]
    return (int(re.search(r"per step; (\d+) \(", first)[1]), int(re.search(r"array.zero_\): (\d+) in", second)[1]))


def main() -> None:
    steps = sum(h * n for h, n in ITERATIONS.items())
    for fused in (False, True):
        tag = "_fused" if fused else ""
        saved = 0
        print(f"fused_network {fused}")
        print("| H | torch kernels a step, before -> after | Warp memsets a step, before -> after | fewer a step |")
        print("|---|---|---|---|")
        for h, n in ITERATIONS.items():
            (tb, mb), (ta, ma) = (kernels(HERE / d / f"ops_h{h}{tag}.txt") for d in ("before", "after"))
            saved += n * ((tb + mb) - (ta + ma))
            print(f"| {h} | {tb / h:.2f} -> {ta / h:.2f} | {mb / h:.2f} -> {ma / h:.2f} | "
                  f"{((tb + mb) - (ta + ma)) / h:.2f} |")
        print(f"schedule: {saved} kernels fewer in 2000 iterations ({steps} window steps, {saved / steps:.2f} a step); "
              f"ESTIMATE at {US_PER_KERNEL:.0f} us a kernel: {saved * US_PER_KERNEL * 1e-6:.2f} s fewer "
              f"({saved / steps * 41958 * US_PER_KERNEL * 1e-6:.2f} s with 41958 window steps)\n")


if __name__ == "__main__":
    main()
