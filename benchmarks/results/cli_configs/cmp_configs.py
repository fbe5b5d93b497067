"""Print the configs each command line builds, with the code of the checkout in the current directory."""
import dataclasses, json, os, sys
sys.path.insert(0, os.getcwd())
import wresdyn
assert wresdyn.__file__.startswith(os.getcwd()), wresdyn.__file__
import wresdyn.data.loading as loading, wresdyn.robot.description as description
from wresdyn.cli import main

class Captured(Exception):
    pass

def capture(*a, **k):
    raise Captured(sys._getframe(1).f_locals)

loading.load_data = capture
description.load_robot = capture
D = "data/dataset.npz"
LINES = [
 ["identify", D], ["identify", D, "--out", "runs/identify", "--eval"],
 ["identify", D, "--iterations", "8", "--windows", "2"], ["identify", D, "--gain-grid", "1,0.1,0.03,0.01"],
 ["identify", D, "--delay-grid", "0,10,25,40,55,70"], ["identify", D, "--refine", "8", "--fit", "kp,kd, effort",
 "--solver", "replay", "--device", "cuda:0", "--seed", "3"],
 ["fit", D], ["fit", D, "--out", "runs/fit", "--eval"], ["fit", D, "--model", "network", "--out", "runs/net"],
 ["fit", D, "--model", "network", "--residual", "delta_action"], ["fit", D, "--model", "parametric"],
 ["fit", D, "--no-cuda-graph"], ["fit", D, "--refine", "8"], ["fit", D, "--device", "cuda:0", "--windows", "1024"],
 ["fit", D, "--physics", "runs/identify/physics.json", "--out", "runs/hybrid"],
 ["fit", D, "--identify-iterations", "200", "--iterations", "300", "--gain-grid", "1,0.1"],
 ["fit", D, "--identify-iterations", "6", "--iterations", "4", "--windows", "2", "--curriculum", "4"],
 ["fit", D, "--curriculum", "", "--horizon", "32"], ["fit", D, "--curriculum", "2,4,8", "--horizon", "16"],
 ["fit", D, "--curriculum", "2,,4,8"], ["fit", D, "--arch", "gru", "--fraction", "0.5", "--lr", "0.003",
 "--obs-noise", "0", "--solver", "replay", "--seed", "2", "--model", "network"],
 ["fit", D, "--obs-noise", "0.03"],
 ["train", D], ["train", D, "--out", "runs/ppo", "--eval"], ["train", D, "--device", "cuda:0", "--num-envs", "4096"],
 ["train", D, "--set", "ppo.desired_kl=0.05"], ["train", D, "--fraction", "0.25"],
 ["train", D, "--set", "ppo.gamma=0.95", "--set", "ppo.lam=0.95"],
 ["train", D, "--fraction", "0.5", "--set", "residual.action_gain=0.1", "--obs-noise", "0.1"],
 ["train", D, "--set", "residual.hidden_dims=128,64", "--set", "rewards.sigma_q=0.03", "--set", "rewards.sigma_qd=3"],
 ["train", D, "--set", "residual.init_std=0.5", "--set", "ppo.num_mini_batches=8", "--horizon", "500"],
 ["train", D, "--residual", "delta_action", "--arch", "gru", "--set", "rewards.joint_pos_bonus=0",
  "--set", "residual.obs_normalization=false"],
 ["train", D, "--iterations", "1000", "--save-interval", "250", "--steps-per-env", "12", "--seed", "4",
  "--solver", "featherstone", "--physics", "p.json", "--iterations", "7", "--set", "ppo.iterations=9"],
 ["deploy"], ["deploy", "--floor"], ["deploy", "--floor", "--full"], ["deploy", "--full", "--device", "cuda:0"],
 ["deploy", "--out", "runs/deploy", "--seed", "2"], ["deploy", "--floor", "--out", "x", "--seed", "1"],
 ["deploy", "--iterations", "2", "--finetune", "1", "--envs", "4", "--oracle-envs", "3", "--finetune-std", "0.6",
  "--motions", "1", "--heldout", "1", "--duration", "0.5"],
 ["deploy", "--floor", "--oracle-beside", "--iterations", "2", "--finetune", "1", "--envs", "4", "--oracle-envs", "3",
  "--motions", "1", "--heldout", "1", "--duration", "1.5"],
 ["ablate"], ["ablate", "--jobs", "14", "--ppo-iterations", "500"], ["ablate", "--device", "cuda", "--jobs", "8"],
 ["ablate", "--learners", "gradient,ppo", "--archs", "gru", "--kinds", "torque", "--seeds", "0,5", "--segments", "2",
  "--gradient-iterations", "40", "--solver", "replay", "--ppo-envs", "16", "--windows", "8", "--horizon", "16"],
 ["ablate", "--delays-only", "--delays", "0,0.005,0.01"],
]

def unset(d):
    # select_every, grad_truncation, torch_threads: "use another value" was 0 and is None now
    if isinstance(d, dict):
        return {k: None if k in ("select_every", "grad_truncation", "torch_threads") and d[k] == 0 else unset(v)
                for k, v in d.items()}
    return d

def plain(cfg):
    d = unset(dataclasses.asdict(cfg))
    # the deploy sizes' "use envs" / "(a)'s own" were 0 before and are None now: compare what they mean
    if "oracle_envs" in d:
        d["oracle_envs"] = d["oracle_envs"] or None
        d["finetune_std"] = d["finetune_std"] or None
        d["_class"] = type(cfg).__name__
    return d

for argv in LINES:
    try:
        main(argv)
        raise SystemExit("no capture for " + " ".join(argv))
    except Captured as c:
        loc = c.args[0]
    out = {"cfg": plain(loc["cfg"])}
    if argv[0] == "fit":
        args, cfg = loc["args"], loc["cfg"]
        if "sysid" in loc:
            sysid = loc["sysid"]
        elif args.model == "hybrid" and not cfg.physics:  # the base commit builds it after loading (same code)
            from dataclasses import replace
            from wresdyn.learn.sysid import SysIdConfig
            stage1 = {k: v for k, v in (("iterations", args.identify_iterations), ("windows", args.windows),
                                        ("refine", args.refine)) if v is not None}
            if loc["gain_grid"] is not None:
                stage1["gain_grid"] = loc["gain_grid"]
            sysid = replace(SysIdConfig(), device=cfg.device, seed=cfg.seed, solver=cfg.solver, **stage1)
        else:
            sysid = None
        out["sysid"] = sysid and plain(sysid)
    print(json.dumps({"argv": argv, **out}, sort_keys=True))
