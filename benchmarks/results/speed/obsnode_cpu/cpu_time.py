"""Milliseconds of a gradient-fit iteration on the CPU with the observation node off (WRESDYN_OBS_NODE=0), with its
torch operators (1) and with its Warp kernels (warp), interleaved in one process (6 rounds of 8 timed iterations each,
after one untimed) so that a shared machine's load falls on all three alike.

    python benchmarks/results/speed/obsnode_cpu/cpu_time.py WINDOWS plain|fused   # from the repository root
"""

import os
import sys
import time


def main() -> None:
    import torch
    import warp as wp

    from wresdyn.data.dataset import load_dataset
    from wresdyn.fit.gradfit import GradFitConfig, _FitLearner
    from wresdyn.learn.window_fit import start_window_fit
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    wp.config.quiet = True
    torch.set_num_threads(1)
    robot = load_robot(DEFAULT_ROBOT)
    data = load_dataset("data/dataset.npz", robot=robot)
    h, w, fused = 16, int(sys.argv[1]), sys.argv[2] == "fused"
    cfg = GradFitConfig(windows=w, horizon_curriculum=(h,), iterations=1000, fused_network=fused)
    rng, train, dt = start_window_fit(cfg, data)
    learner = _FitLearner(robot, data, cfg, None, rng, train, dt, print)
    times = {m: [] for m in ("0", "1", "warp")}
    i = 0
    for _ in range(6):
        for m, ts in times.items():
            os.environ["WRESDYN_OBS_NODE"] = m  # read at each rollout
            learner.step(i, h, cfg.lr)
            i += 1
            for _ in range(8):
                t = time.perf_counter()
                learner.step(i, h, cfg.lr)
                i += 1
                ts.append(time.perf_counter() - t)
    for m, ts in times.items():
        ts.sort()
        print(f"{'fused' if fused else 'plain'} windows {w} H {h} WRESDYN_OBS_NODE={m}: median "
              f"{1e3 * ts[len(ts) // 2]:.2f} ms/iteration, min {1e3 * ts[0]:.2f}, {len(ts)} iterations interleaved")


if __name__ == "__main__":
    main()
