"""Identification recipes for fight 1's wresdyn leg (:data:`RECIPES`) and their search on validation only.

    python benchmarks/peers/recipe_search.py DATA --recipe NAME --out DIR [--from RUN]

fits :func:`wresdyn.identify.sysid.identify` with recipe ``NAME`` on ``DATA`` (run folder ``DIR/run``) and writes
``DIR/result.json``: the selected parameters' mean |Δq| on the validation split (the fight's own score,
:func:`wresdyn.evaluation.open_loop.evaluate_split`), the fit's seconds and the config. It never replays held-out or
OOD: a recipe is chosen on these figures, then scored once through ``humanoid.py wresdyn --recipe NAME``.

``--from RUN`` copies a finished run folder of the same Adam settings first, so that a recipe differing only in what
runs after the Adam steps (``refine``, which a resumed identification may change) continues from its checkpoint
instead of repeating the same Adam iterates; its seconds are then the earlier run's plus this call's.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parents[1])]  # this checkout

RECIPES = {
    "default": {},
    "refine": {"refine": 20},
    "h256_refine": {"horizon_curriculum": (16, 32, 64, 128, 256), "refine": 20},
    "refine_all": {"refine": 20, "refine_frozen": ()},
    "refine_all_delay_first": {"refine": 20, "refine_frozen": (), "delay_grid": tuple(range(9)),
                               "delay_grid_first": True},
    "refine_all_shared_delay": {"refine": 20, "refine_frozen": (), "delay_grid": tuple(range(9)),
                                "delay_grid_first": True, "shared_delay": True},
    "refine_all_shared_delay_nogrid": {"refine": 20, "refine_frozen": (), "shared_delay": True},
    "refine_all_shared_delay_polish": {"refine": 20, "refine_frozen": (), "delay_grid": tuple(range(9)),
                                       "delay_grid_first": True, "shared_delay": True, "polish": 20},
    "refine_all_shared_delay_polish_all": {"refine": 20, "refine_frozen": (), "delay_grid": tuple(range(9)),
                                           "delay_grid_first": True, "shared_delay": True, "polish": 20,
                                           "polish_threshold": 0.0},
}
"""Recipe name -> :class:`~wresdyn.identify.sysid_config.SysIdConfig` fields over its defaults. ``refine``: L-BFGS
steps on fixed training windows of the longest horizon after the Adam selection, each validated, the best kept;
``h256_refine``: that after a fifth horizon stage of 256 samples (0.5 s at 500 Hz, the peer's window);
``refine_all``: ``refine`` fitting the delay and the effort limits too; ``refine_all_delay_first``: that with one
delay of 0-8 samples for every joint chosen by a grid before the first Adam step (from the file's values the grid's
end, 8, on both mismatches: a start, not a measurement); ``refine_all_shared_delay``: that with the delay tied across
joints through the Adam steps and the refinement; ``refine_all_shared_delay_nogrid``: the tied delay from the file's
(0) without the grid; ``refine_all_shared_delay_polish``: ``refine_all_shared_delay`` followed by up to 20
Levenberg-Marquardt steps in the directions the data determine (``SysIdConfig.polish``);
``refine_all_shared_delay_polish_all``: that in every direction the data see (``polish_threshold`` 0, the prior's pull
ignored). What each scored on validation, and the one chosen:
``benchmarks/results/peers/humanoid/recipe_search/MANIFEST.md``."""


def recipe_config(name: str, device: str = "cpu"):
    """The :class:`~wresdyn.identify.sysid_config.SysIdConfig` of recipe ``name`` on ``device``."""
    from wresdyn.identify.sysid_config import SysIdConfig

    if name not in RECIPES:
        raise SystemExit(f"error: unknown recipe {name!r}; choose from {sorted(RECIPES)}")
    return SysIdConfig(device=device, **RECIPES[name])


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data")
    p.add_argument("--recipe", required=True, choices=sorted(RECIPES))
    p.add_argument("--out", required=True)
    p.add_argument("--from", dest="start", default=None, help="a finished run folder to continue (see above)")
    args = p.parse_args(argv)

    from wresdyn.data.loading import load_data
    from wresdyn.evaluation.open_loop import evaluate_split
    from wresdyn.identify.sysid import identify
    from wresdyn.sim.warmup import compile_kernels

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    logf = (out / "log.txt").open("a")

    def log(line: str) -> None:
        print(line, flush=True)
        logf.write(line + "\n")
        logf.flush()

    before = 0.0
    if args.start:
        shutil.copytree(args.start, out / "run", dirs_exist_ok=True)
        before = json.loads((Path(args.start).parent / "result.json").read_text())["fit_s"]
    cfg = recipe_config(args.recipe)
    ds, robot = load_data(args.data, None, None)
    log(f"# recipe {args.recipe} {RECIPES[args.recipe]} on {args.data}; load average {os.getloadavg()[0]:.2f}"
        + (f"; continuing {args.start} ({before:.1f} s)" if args.start else ""))
    t0 = time.perf_counter()
    compile_kernels(robot, ds.rate_hz, ("forward", "param_grads"), solver=cfg.solver, device=cfg.device, say=log)
    setup = time.perf_counter() - t0
    params, curve = identify(robot, ds, cfg, out=out / "run", log=log)
    fit = time.perf_counter() - t0 - setup
    s, _ = evaluate_split(robot, ds.split("validation"), ds.rate_hz, physics=params, weights=ds.fit_weights(),
                          device=cfg.device)
    v = s["pd_residual"]["mean_abs_dq"]
    result = {"recipe": args.recipe, "fields": RECIPES[args.recipe], "data": args.data, "validation": v,
              "setup_s": setup, "fit_s": before + fit, "this_call_fit_s": fit, "iterations": len(curve),
              "continued_from": args.start, "load_end": os.getloadavg()[0], "config": dataclasses.asdict(cfg)}
    (out / "result.json").write_text(json.dumps(result, indent=1))
    log(f"# recipe {args.recipe}: validation {v:.6f} rad, fit {before + fit:.1f} s (setup {setup:.1f} s)")


if __name__ == "__main__":
    main()
