"""Pack what a resume and the report need from the device runs into /root/pack (latest checkpoint per policy only)."""
import re, shutil
from pathlib import Path
dst = Path("/root/pack"); dst.mkdir(exist_ok=True)
for run in sorted(Path("/root").glob("floor_*")) + [Path("/root/peer_out"), Path("/root/res"), Path("/root/unv_fits")]:
    if not run.is_dir():
        continue
    for f in run.rglob("*"):
        if not f.is_file() or "/git/" in str(f) or "tfevents" in f.name or "/wc_" in str(f) or "telemetry.csv" in f.name or f.name == "motions.npz":
            continue
        if "/res/" in str(f) and "/runs/" in str(f) and f.suffix == ".pt" and f.stat().st_size > 2e6:
            continue
        m = re.fullmatch(r"model_(\d+)\.pt", f.name)
        if m:
            its = [int(re.fullmatch(r"model_(\d+)\.pt", g.name).group(1)) for g in f.parent.glob("model_*.pt")]
            if int(m.group(1)) != max(its):
                continue
        out = dst / run.name / f.relative_to(run)
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(f, out)
print(sum(f.stat().st_size for f in dst.rglob("*") if f.is_file()) / 1e6, "MB packed")
