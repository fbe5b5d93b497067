"""Tiny deploy (stand, floor) and train runs with the checkout in the cwd; prints a digest of every number."""
import hashlib, json, os, sys
from pathlib import Path
sys.path.insert(0, os.getcwd())
import numpy as np
import wresdyn
assert wresdyn.__file__.startswith(os.getcwd()), wresdyn.__file__
out = Path(sys.argv[1]); out.mkdir(parents=True, exist_ok=True)
from wresdyn.cli import main
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.data.real_robot import Mismatch, collect
from wresdyn.paths import DEFAULT_MISMATCH
robot = load_robot(DEFAULT_ROBOT)
ds_path = out / "dataset.npz"
if not ds_path.exists():
    data = collect(robot, Mismatch.load(DEFAULT_MISMATCH), {"train": 2, "validation": 1, "heldout": 1, "ood": 1}, duration=0.2)
    data.save(ds_path)
    from wresdyn.learn.gradfit import build_policy
    from wresdyn.learn.residual import ResidualConfig, export_run_files, obs_stats
    from wresdyn.sim.physics import PhysicalParams
    for kind, physics in (("torque", True), ("delta_action", False)):
        run = out / kind; run.mkdir()
        if physics:
            p = PhysicalParams.nominal(robot); p.kp *= 0.8; p.delay = np.full(robot.n_dof, 0.004); p.save(run / "physics.json")
        mean, std = obs_stats(data.split("train"))
        export_run_files(build_policy(robot, ResidualConfig(kind=kind, fraction=0.1), mean, std), run, data, arch="mlp", learner="gradient")
common = [str(ds_path), "--calibrated", str(out / "torque"), "--delta", str(out / "delta_action"), "--iterations", "2",
          "--finetune", "1", "--envs", "4", "--oracle-envs", "3", "--motions", "1", "--heldout", "1", "--no-animation", "--quiet"]
extra = [a for a in sys.argv[2:] if a != "--digest"]
rc = [] if "--digest" in sys.argv else [main(["deploy", *common, "--finetune-std", "0.6", "--out", str(out / "stand"), *extra]),
      main(["deploy", *common, "--out", str(out / "stand_own_std"), *extra]),
      main(["deploy", *common, "--floor", "--duration", "1.0", "--out", str(out / "floor"), *extra]),
      main(["train", str(ds_path), "--out", str(out / "ppo"), "--iterations", "3", "--num-envs", "4", "--steps-per-env", "8",
            "--save-interval", "1", "--set", "ppo.select_every=1", "--set", "residual.hidden_dims=32,32", "--quiet"])]
print("rc", rc)
import torch
def digest(obj, h):
    if isinstance(obj, torch.Tensor):
        h.update(obj.detach().cpu().contiguous().numpy().tobytes())
    elif isinstance(obj, dict):
        for k in sorted(obj, key=str):
            if k in ("wall_s", "train_wall_s", "fit_wall_s", "wall_s_this_session", "env_steps_per_s", "s_per_iteration",
                     "training_steps_per_s", "collect_s_per_iteration", "learn_s_per_iteration", "collection_steps_per_s",
                     "step_s", "seconds"):
                continue
            v = obj[k]
            if k == "restart_std" and v == 0.0:  # "the initial policy's own": 0.0 before, None now
                v = None
            h.update(str(k).encode()); digest(v, h)
    elif isinstance(obj, (list, tuple)):
        for v in obj: digest(v, h)
    else:
        h.update(repr(obj).encode())
for p in sorted(out.rglob("*")):
    rel = p.relative_to(out)
    if p.suffix == ".pt" and p.name != "policy.pt":
        h = hashlib.sha256(); digest(torch.load(p, map_location="cpu", weights_only=True), h)
        print(rel, h.hexdigest()[:16])
    elif p.name in ("results.json", "train_summary.json"):
        h = hashlib.sha256(); digest(json.loads(p.read_text()), h); print(rel, h.hexdigest()[:16])
    elif p.name == "policy.pt":
        prog = torch.export.load(p) if False else None
        from wresdyn.learn.network_file import load_program
        m = load_program(p)[0]
        h = hashlib.sha256(); digest(dict(m.state_dict), h); print(rel, h.hexdigest()[:16])
    elif p.is_file():
        print(rel, "file")
