"""Pack what a resume and the report need from the floor benchmark's full-size runs (floor_fair_resume.sh) into DST.

    python benchmarks/skills/floor_fair_pack.py DST [ROOT]

From each ``ROOT/floor_*`` folder and ``ROOT/unv_fits`` (ROOT: /root, where the runs' config.json paths point), every
file except: each policy's older checkpoints (only the latest ``model_<it>.pt``), rsl-rl's TensorBoard events and
``git/`` diffs, ``motions.npz`` (drawn again from the seed), ``skills/a_nominal`` (the shipped policy, installed again)
and, once a run has written its ``results.json``, its kept deployments (``deployments/``: tens of MB a run; the
results and the report hold what they gave). Prints the packed size in MB.
"""
import re
import shutil
import sys
from pathlib import Path


def keep(run: Path, f: Path) -> bool:
    rel = f.relative_to(run).as_posix()
    if "/git/" in f"/{rel}" or "tfevents" in f.name or f.name == "motions.npz" or rel.startswith("skills/a_nominal/"):
        return False
    if rel.startswith("deployments/") and (run / "results.json").is_file():
        return False
    m = re.fullmatch(r"model_(\d+)\.pt", f.name)
    if m:
        its = [int(re.fullmatch(r"model_(\d+)\.pt", g.name).group(1)) for g in f.parent.glob("model_*.pt")]
        return int(m.group(1)) == max(its)
    return True


def main(dst: Path, root: Path) -> None:
    runs = sorted(root.glob("floor_*")) + [root / "unv_fits"]
    for run in (r for r in runs if r.is_dir()):
        for f in (f for f in run.rglob("*") if f.is_file() and keep(run, f)):
            out = dst / run.name / f.relative_to(run)
            out.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(f, out)
    print(f"{sum(f.stat().st_size for f in dst.rglob('*') if f.is_file()) / 1e6:.1f} MB packed")


if __name__ == "__main__":
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    main(Path(sys.argv[1]), Path(sys.argv[2] if len(sys.argv) == 3 else "/root"))
