"""Several seeds of the floor benchmark side by side: held-out and validation success, MPJPE and g-MPJPE per
policy and seed, their mean, success per motion family, and the gap closed on g-MPJPE and MPJPE, from each run's
``results.json`` (``wresdyn deploy --floor``).

    python benchmarks/skills/floor_seeds_summary.py RUN0/results.json RUN1/results.json ...
"""

import json
import sys

import numpy as np


def main(paths: list[str]) -> None:
    runs = [json.load(open(p)) for p in paths]
    policies = ["reference"] + list(runs[0]["policies"])
    seeds = [r["config"]["seed"] for r in runs]
    cfg = runs[0]["config"]
    # results.json written before the world count was named num_worlds call it envs
    worlds, oracle = cfg.get("num_worlds", cfg.get("envs")), cfg.get("oracle_num_worlds", cfg.get("oracle_envs"))
    print(f"{len(runs)} seeds {seeds}: {cfg['iterations']} + {cfg['finetune']} PPO iterations, {worlds} worlds "
          f"(oracle {oracle}), held-out {len(runs[0]['real']['heldout']['reference']['motions'])} motions")
    for split in ("heldout", "validation"):
        print(f"\n## {split} motions on the real robot's floor (per seed, then the mean)\n")
        print("| policy | success per seed | success mean | falls | MPJPE [mrad] mean | g-MPJPE [mm] mean |")
        print("|---|---|---|---|---|---|")
        for p in policies:
            m = [r["real"][split][p]["mean"] for r in runs]
            n = len(runs[0]["real"][split][p]["motions"])
            ok = [round(x["success"] * n) for x in m]
            print(f"| {p} | {', '.join(f'{k}/{n}' for k in ok)} | {100 * np.mean([x['success'] for x in m]):.0f} % | "
                  f"{sum(x['falls'] for x in m)} | {1e3 * np.mean([x['mpjpe'] for x in m]):.1f} "
                  f"(±{1e3 * np.std([x['mpjpe'] for x in m]):.1f}) | {1e3 * np.mean([x['g_mpjpe'] for x in m]):.0f} "
                  f"(±{1e3 * np.std([x['g_mpjpe'] for x in m]):.0f}) |")
    for split in ("heldout", "validation"):  # validation: where a choice is made
        print(f"\n## {'held-out' if split == 'heldout' else split} success per motion family (sum over seeds)\n")
        fams = sorted({m["motion"].rsplit("_", 1)[0] for m in runs[0]["real"][split]["reference"]["motions"]})
        print("| policy | " + " | ".join(f.removeprefix(f"{split}_") for f in fams) + " |")
        print("|---|" + "---|" * len(fams))
        for p in policies:
            cells = []
            for f in fams:
                hits = [m["success"] for r in runs for m in r["real"][split][p]["motions"]
                        if m["motion"].rsplit("_", 1)[0] == f]
                cells.append(f"{round(sum(hits))}/{len(hits)}")
            print(f"| {p} | " + " | ".join(cells) + " |")
    print("\n## gap closed (a − x) / (a − d) on held-out motions, per seed\n")
    for key in ("gap_closed_g_mpjpe", "gap_closed_mpjpe"):
        for p in runs[0][key]:
            v = [r[key][p] for r in runs]
            print(f"{key} {p}: {', '.join(f'{100 * x:.0f} %' for x in v)}")
    print("\nb never below a (held-out success), per seed:",
          [r["real"]["heldout"]["b_calibrated"]["mean"]["success"] >= r["real"]["heldout"]["a_nominal"]["mean"]["success"]
           for r in runs])


if __name__ == "__main__":
    main(sys.argv[1:])
