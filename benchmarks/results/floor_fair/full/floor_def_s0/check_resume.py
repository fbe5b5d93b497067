"""Whether ``wresdyn deploy --floor --full ... --out OUT`` resumes this folder copied to OUT, checked with the code's
own pieces on the CPU (no training): the fits are reused, (a) is installed from the shipped policy, and (b)'s saved
``config.json`` passes the resume check against the record (b) would be trained with.

Usage (repository root): python benchmarks/results/floor_fair/full/floor_def_s0/check_resume.py FOLDER OUT
"""

import json
import sys
from dataclasses import asdict, replace
from pathlib import Path

from wresdyn.cli import parse_command
from wresdyn.errors import WresdynError
from wresdyn.learn.runs import check_resume
from wresdyn.ppo.runner import latest_checkpoint
from wresdyn.skills.shipped import shipped_folder
from wresdyn.skills.skill_ppo import RESUME_MAY_CHANGE, upgrade_record

folder, out = Path(sys.argv[1]), sys.argv[2]
argv = ["deploy", "--floor", "--full", "--device", "cuda:0", "--mismatch", "data/mismatch_default.toml", "--seed", "0",
        "--nominal", "floor_nominal", "--out", out, "--quiet"]
_, _, args = parse_command(argv)
cfg, task = args.sizes, args.task
ppo = replace(args.ppo, seed=cfg.seed, device=cfg.device)  # as start_benchmark resolves it
counts = {"train": cfg.train_per_family, "validation": cfg.validation_per_family, "heldout": cfg.heldout_per_family}
motions = {"seed": cfg.seed, "counts": counts, "duration": cfg.duration, "floor": True, "screened": cfg.screen}
if cfg.extra_families:
    motions["extra"] = list(cfg.extra_families)
# experiments/skills.py _train_policy: (b) is policy 1, fine-tuned from (a) in the calibrated simulator
b_ppo = replace(ppo, iterations=cfg.finetune, restart_std=cfg.finetune_std)
record = {"ppo": asdict(b_ppo), "task": asdict(task), "num_worlds": cfg.num_worlds,
          "init": str((Path(out) / "skills" / "a_nominal").resolve()), "motions": motions, "setting": "calibrated",
          "correction": str(Path(out) / "calibrated")}
for fit in ("calibrated", "delta_action"):
    print(f"{fit}/policy.pt present (fit_corrections reuses it): {(folder / fit / 'policy.pt').is_file()}")
print(f"skills/a_nominal absent, installed from {shipped_folder('floor_nominal')}: "
      f"{not (folder / 'skills' / 'a_nominal').exists()}")
ckpt = latest_checkpoint(folder / "skills" / "b_calibrated")
print(f"(b) resumes from {ckpt.name}")
saved = upgrade_record(json.loads((folder / "skills" / "b_calibrated" / "config.json").read_text()))
try:
    check_resume(folder / "skills" / "b_calibrated", saved, record, RESUME_MAY_CHANGE)
    print(f"(b)'s config check with --out {out}: passes")
except WresdynError as e:
    print(f"(b)'s config check with --out {out}: refused: {e}")
