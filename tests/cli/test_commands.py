"""Every command's flags: generated from its config (each field a flag, with its docstring and its true default),
every flag of earlier releases still accepted with the same meaning, ``--help`` fast, bad values in one line."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import asdict, fields, replace

import pytest

from wresdyn.adapt.config import AdaptConfig
from wresdyn.cli import build_parser, main
from wresdyn.cli.collect import CollectConfig
from wresdyn.cli.config_flags import config_fields, plain_help
from wresdyn.data.signals import ExcitationConfig
from wresdyn.experiments.ablation_config import AblationConfig
from wresdyn.experiments.deploy_config import DeployConfig, FloorDeployConfig
from wresdyn.learn.ppo_config import default_config
from wresdyn.learn.window_fit_config import GradFitConfig, SysIdConfig
from wresdyn.skills.skill_config import FloorTaskConfig, SkillConfig, SkillPPOConfig

OLD_FLAGS = {
    "inspect": ("--gains", "--floating", "--seconds", "--dt", "--solver"),
    "demo": ("--out", "--collect", "--ppo-iterations", "--skill-iterations", "--quick"),
    "collect": ("--robot", "--gains", "--mismatch", "--train", "--validation", "--heldout", "--ood", "--duration",
                "--rate", "--seed", "--out", "--no-tau", "--no-gap", "--quiet", "--excitation", "--frames",
                "--max-velocity", "--logs", "--map", "--split", "--assign", "--split-map", "--validation-fraction",
                "--heldout-fraction"),
    "migrate": ("--out", "--validation", "--force", "--robot", "--gains", "--no-gap"),
    "train": ("--out", "--robot", "--gains", "--residual", "--arch", "--iterations", "--num-envs", "--steps-per-env",
              "--horizon", "--obs-noise", "--fraction", "--solver", "--device", "--seed", "--save-interval",
              "--physics", "--set", "--no-resume", "--eval", "--quiet"),
    "eval": ("--data", "--robot", "--gains", "--splits", "--out", "--solver", "--device", "--joints", "--compare"),
    "bench": ("--robot", "--gains", "--worlds", "--device", "--steps", "--horizon", "--slow-steps", "--slow-max-worlds",
              "--threads", "--solvers", "--dt", "--min-time", "--json"),
    "identify": ("--out", "--robot", "--gains", "--iterations", "--windows", "--fit", "--delay-grid", "--gain-grid",
                 "--refine", "--solver", "--device", "--seed", "--eval", "--quiet"),
    "fit": ("--out", "--robot", "--gains", "--model", "--residual", "--arch", "--fraction", "--iterations",
            "--identify-iterations", "--gain-grid", "--refine", "--windows", "--horizon", "--curriculum", "--lr",
            "--obs-noise", "--solver", "--device", "--no-cuda-graph", "--seed", "--physics", "--eval", "--quiet"),
    "adapt": ("--out", "--robot", "--rate-hz", "--split", "--track", "--quiet", "--window", "--holdout",
              "--update-every", "--iterations", "--windows", "--horizon", "--fit", "--lr"),
    "view": ("--split", "--index", "--data", "--host", "--port", "--seconds", "--device"),
    "export": ("--out", "--force", "--physics-only", "--data", "--gains"),
    "deploy": ("--out", "--calibrated", "--delta", "--mismatch", "--floor", "--full", "--iterations", "--finetune",
               "--envs", "--oracle-envs", "--oracle-beside", "--motions", "--heldout", "--duration", "--finetune-std",
               "--seed", "--device", "--no-animation", "--quiet"),
    "ablate": ("--data", "--robot", "--out", "--learners", "--archs", "--kinds", "--seeds", "--ppo-iterations",
               "--gradient-iterations", "--segments", "--solver", "--device", "--ppo-envs", "--windows", "--horizon",
               "--jobs", "--delays", "--delays-only", "--delay-learner", "--delay-trajectories"),
}
"""The flags of every command before they were generated from the configs (``wresdyn CMD --help`` at edbe496; a
command added since: its flags when it came)."""

CONFIG_FLAGS = {
    "collect": [(CollectConfig(), "", ())],
    "identify": [(SysIdConfig(), "", ())],
    "adapt": [(AdaptConfig(), "", ())],
    "fit": [(GradFitConfig(), "", ("model",)),
            (SysIdConfig(), "identify.", ("device", "seed", "solver", "friction_kappa"))],
    "train": [(default_config(), "", ())],
    "deploy": [(DeployConfig(), "", ()), (FloorDeployConfig(), "", tuple(f.name for f in fields(DeployConfig))),
               (SkillConfig(), "task.", ()),
               (FloorTaskConfig(), "task.", tuple(f.name for f in fields(SkillConfig))),
               (SkillPPOConfig(), "ppo.", ("iterations", "restart_std", "seed", "device"))],
    "ablate": [(AblationConfig(), "", ("ppo_overrides", "gradient_overrides"))],
}
"""Each command's configs: ``(defaults, flag prefix, fields without a flag)``."""

PARSER, COMMANDS = build_parser()


def _options(command: str) -> dict:
    return {s: a for a in COMMANDS[command]._actions for s in a.option_strings}


def _typed(value) -> str:
    if isinstance(value, tuple):
        return ",".join(map(str, value)) if value else "empty"
    return "none" if value is None else str(value)


def test_every_command_helps_in_full(capsys):
    assert set(COMMANDS) == set(OLD_FLAGS)
    for command in COMMANDS:
        with pytest.raises(SystemExit) as ex:
            main([command, "--help"])
        assert ex.value.code == 0
        assert capsys.readouterr().out.startswith(f"usage: wresdyn {command}")


@pytest.mark.parametrize("command", sorted(CONFIG_FLAGS))
def test_every_config_field_is_a_flag_with_its_docstring_and_true_default(command):
    options = _options(command)
    for defaults, prefix, skip in CONFIG_FLAGS[command]:
        for dotted, _, doc in config_fields(type(defaults)):
            if dotted in skip:
                continue
            head, _, name = (prefix + dotted).rpartition(".")
            flag = "--" + (f"{head}." if head else "") + name.replace("_", "-")
            assert flag in options, f"wresdyn {command}: no {flag}"
            value = defaults
            for part in dotted.split("."):
                value = getattr(value, part)
            assert doc and options[flag].help.startswith(plain_help(doc)), flag
            assert f"(default: {_typed(value)}" in options[flag].help, flag


@pytest.mark.parametrize("command", sorted(OLD_FLAGS))
def test_every_flag_of_earlier_releases_is_still_accepted(command):
    assert not set(OLD_FLAGS[command]) - set(_options(command))


def _config(argv: list[str]):
    args = PARSER.parse_args(argv)
    return sys.modules[args._module].config_from_args(args)


# each line with the fields the code before generated flags built from it (the rest: the defaults)
FIT = GradFitConfig()
SAME = [
    (["collect", "--train", "2", "--validation", "0", "--heldout", "1", "--ood", "3", "--duration", "2.5", "--rate",
      "250", "--seed", "7", "--frames", "a, b", "--max-velocity", "3"],
     CollectConfig(train=2, validation=0, heldout=1, ood=3, duration=2.5, rate=250.0, seed=7,
                   excitation=ExcitationConfig(mode="foot", frames=("a", "b"), max_velocity=3.0,
                                               joint_max_velocity=3.0))),
    (["collect", "--excitation", "joint"], CollectConfig(excitation=ExcitationConfig(mode="joint"))),
    (["identify", "d.npz", "--iterations", "8", "--windows", "2", "--fit", "kp, kd,effort", "--delay-grid", "0,10",
      "--gain-grid", "1,0.1", "--refine", "8", "--solver", "replay", "--device", "cuda:0", "--seed", "3"],
     replace(SysIdConfig(), iterations=8, windows=2, fit=("kp", "kd", "effort"), delay_grid=(0.0, 10.0),
             gain_grid=(1.0, 0.1), refine=8, solver="replay", device="cuda:0", seed=3)),
    (["fit", "d.npz"], FIT),
    (["fit", "d.npz", "--model", "network", "--residual", "delta_action", "--arch", "gru", "--fraction", "0.5"],
     replace(GradFitConfig(), residual=replace(GradFitConfig().residual, kind="delta_action", arch="gru",
                                               fraction=0.5))),
    (["fit", "d.npz", "--model", "parametric", "--no-cuda-graph", "--curriculum", "2,4,8"],
     replace(GradFitConfig(), model="parametric", cuda_graph=False, horizon_curriculum=(2, 4, 8), horizon=8)),
    (["fit", "d.npz", "--curriculum", "", "--horizon", "32", "--lr", "0.003", "--obs-noise", "0", "--windows", "16",
      "--iterations", "5", "--solver", "replay", "--device", "cuda:0", "--seed", "2", "--physics", "p.json"],
     replace(FIT, horizon_curriculum=(), horizon=32, lr=0.003, obs_noise=0.0, windows=16, iterations=5,
             solver="replay", device="cuda:0", seed=2, physics="p.json")),
    (["train", "d.npz", "--residual", "delta_action", "--arch", "gru", "--fraction", "0.25", "--iterations", "7",
      "--num-envs", "64", "--steps-per-env", "12", "--horizon", "500", "--obs-noise", "0.1", "--solver", "replay",
      "--device", "cuda:0", "--seed", "4", "--save-interval", "5", "--physics", "p.json",
      "--set", "ppo.desired_kl=0.05", "--set", "residual.hidden_dims=128,64", "--set", "ppo.iterations=9"],
     replace(default_config(),
             env=replace(default_config().env, num_worlds=64, horizon=500, obs_noise=0.1, solver="replay",
                         physics="p.json"),
             residual=replace(default_config().residual, kind="delta_action", arch="gru", fraction=0.25,
                              hidden_dims=(128, 64)),
             ppo=replace(default_config().ppo, iterations=9, num_steps_per_env=12, device="cuda:0",
                         seed=4, save_interval=5, desired_kl=0.05))),
    (["deploy", "--iterations", "2", "--finetune", "1", "--envs", "4", "--oracle-envs", "3", "--finetune-std", "0.6",
      "--motions", "1", "--heldout", "1", "--duration", "0.5", "--seed", "2", "--device", "cuda:0"],
     DeployConfig(iterations=2, finetune=1, num_worlds=4, oracle_num_worlds=3, finetune_std=0.6, train_per_family=1,
                  heldout_per_family=1, duration=0.5, seed=2, device="cuda:0")),
    (["deploy", "--floor", "--full", "--oracle-beside"], FloorDeployConfig.full(oracle_beside=True)),
    (["ablate", "--learners", "gradient,ppo", "--archs", "gru", "--kinds", "torque", "--seeds", "0,5", "--segments",
      "2", "--ppo-iterations", "9", "--gradient-iterations", "40", "--solver", "replay", "--device", "cuda",
      "--ppo-envs", "16", "--windows", "8", "--horizon", "16"],
     AblationConfig(learners=("gradient", "ppo"), archs=("gru",), kinds=("torque",), seeds=(0, 5), segments=2,
                    ppo_iterations=9, gradient_iterations=40, solver="replay", device="cuda",
                    ppo_overrides={"env.num_worlds": 16}, gradient_overrides={"windows": 8, "horizon": 16})),
]


@pytest.mark.parametrize("argv,expected", SAME, ids=[" ".join(a[:3]) for a, _ in SAME])
def test_command_lines_of_earlier_releases_build_the_same_config(argv, expected):
    assert asdict(_config(argv)) == asdict(expected)


@pytest.mark.parametrize("floor", [False, True], ids=["stand", "floor"])
def test_deploys_task_and_ppo_flags_reach_the_benchmark(floor, monkeypatch, tmp_path):
    """``--task.*`` and ``--ppo.*`` build the task and PPO configs that ``wresdyn deploy`` hands the benchmark (stopped
    there: nothing is loaded, compiled or trained); without them, the benchmark's own defaults."""
    from pathlib import Path
    from types import SimpleNamespace

    import wresdyn.data.loading
    import wresdyn.experiments.skills
    import wresdyn.sim.warmup

    robot = SimpleNamespace(source=Path("humanoid.usda"), n_dof=3)
    monkeypatch.setattr(wresdyn.data.loading, "load_data", lambda path: (SimpleNamespace(rate_hz=500.0), robot))
    monkeypatch.setattr(wresdyn.sim.warmup, "compile_kernels", lambda *a, **k: None)
    passed = []
    monkeypatch.setattr(wresdyn.experiments.skills, "run_benchmark",
                        lambda robot, ds, out, cfg, **kw: passed.append((cfg, kw)))
    head = ["deploy", "d.npz", "--out", str(tmp_path), "--quiet", "--envs", "8"] + (["--floor"] if floor else [])
    task_cls = FloorTaskConfig if floor else SkillConfig
    own = ["--task.sigma-base", "0.2"] if floor else ["--task.fail-error", "0.7"]
    assert main(head + ["--task.action-scale", "0.3", "--task.decimation", "5", *own, "--ppo.hidden-dims", "64,32",
                        "--ppo.gamma", "0.99", "--ppo.torch-threads", "none", "--ppo.init-std", "0.5"]) == 0
    cfg, kw = passed[-1]
    assert cfg == (FloorDeployConfig if floor else DeployConfig)(num_worlds=8)
    task = task_cls(action_scale=0.3, decimation=5, **({"sigma_base": 0.2} if floor else {"fail_error": 0.7}))
    assert kw["task"] == task
    assert kw["ppo"] == SkillPPOConfig(hidden_dims=(64, 32), gamma=0.99, torch_threads=None, init_std=0.5)
    assert main(head) == 0
    assert passed[-1][1]["task"] == task_cls() and passed[-1][1]["ppo"] == SkillPPOConfig()


def test_the_hybrids_identification_shares_the_fits_device_seed_solver_and_windows():
    from wresdyn.cli.fit import identify_config_from_args

    args = PARSER.parse_args(["fit", "d.npz", "--identify-iterations", "6", "--gain-grid", "1,0.5", "--refine", "2",
                              "--windows", "4", "--seed", "3", "--solver", "replay", "--device", "cuda:0"])
    sysid = identify_config_from_args(args, _config(["fit", "d.npz", "--windows", "4", "--seed", "3", "--solver",
                                                     "replay", "--device", "cuda:0"]))
    assert sysid == replace(SysIdConfig(), iterations=6, gain_grid=(1.0, 0.5), refine=2, windows=4, seed=3,
                            solver="replay", device="cuda:0")
    args = PARSER.parse_args(["fit", "d.npz", "--windows", "4", "--identify.windows", "8"])
    assert identify_config_from_args(args, _config(["fit", "d.npz", "--windows", "4"])).windows == 8


def test_help_and_every_parser_import_no_heavy_library():
    code = ("import sys\nfrom wresdyn.cli import build_parser, main\nbuild_parser()\n"
            "try: main(['fit', '--help'])\nexcept SystemExit: pass\n"
            "heavy = [m for m in ('torch', 'warp', 'newton', 'mujoco', 'pxr', 'rsl_rl') if m in sys.modules]\n"
            "assert not heavy, heavy")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-500:]


@pytest.mark.parametrize("argv,message", [
    (["fit", "d.npz", "--iterations", "x"], "argument --iterations: invalid int value: 'x'"),
    (["train", "d.npz", "--residual", "torqu"], "argument --residual.kind/--residual: invalid choice: 'torqu'"),
    (["deploy", "--floor", "--motions", "1.5"], "argument --train-per-family/--motions: invalid int value: '1.5'"),
])
def test_a_malformed_flag_is_one_line_and_exit_2(argv, message, capsys):
    with pytest.raises(SystemExit) as ex:
        main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert ex.value.code == 2 and len(err) == 1 and message in err[0], err


@pytest.mark.parametrize("argv,message", [
    (["collect", "--train", "0", "--validation", "0", "--heldout", "0", "--ood", "0"],
     "wresdyn collect: error: train/validation/heldout/ood are all 0: nothing to record"),
    (["collect", "--frames", "gripperframe", "--excitation", "joint"], "wresdyn collect: error: --frames sets the IK "
     "targets of the foot excitation; it has no use with --excitation joint"),
    (["identify", "none.npz", "--windows", "0"], "wresdyn identify: error: windows = 0 must be >= 1"),
    (["train", "none.npz", "--set", "ppo.num_envs=1", "--set", "ppo.num_steps_per_env=2"],
     "wresdyn train: error: ppo.num_mini_batches = 4 is more than the 2 samples per rollout"),
    (["train", "none.npz", "--set", "ppo.gama=0.9"],
     "wresdyn train: error: --set 'ppo.gama=0.9': no field 'ppo.gama' (sections: env, ppo, residual, rewards)"),
    (["deploy", "--oracle-envs", "0"], "wresdyn deploy: error: deploy.oracle_num_worlds = 0 must be >= 1"),
    (["deploy", "--oracle-beside"], "wresdyn deploy: error: --oracle-beside sets the benchmark on the floor; it needs "
                                    "--floor"),
    (["deploy", "--beside-devices", "cuda:1"],
     "wresdyn deploy: error: --beside-devices sets the benchmark on the floor; it needs --floor"),
    (["deploy", "--floor", "--beside-devices", "cuda:1,gpu2"],
     "wresdyn deploy: error: floor.beside_devices = 'gpu2' is not a device: cpu, cuda or cuda:N"),
    (["deploy", "--task.w-fall", "3"],
     "wresdyn deploy: error: --task.w-fall sets the task on the floor; it needs --floor"),
    (["deploy", "--floor", "--task.fail-error", "1"],
     "wresdyn deploy: error: --task.fail-error sets the task on the stand; it has no use with --floor"),
    (["deploy", "--ppo.torch-threads", "0"], "wresdyn deploy: error: ppo.torch_threads = 0 must be >= 1"),
    (["deploy", "--task.sigma-q", "0"], "wresdyn deploy: error: skill.sigma_q = 0.0 must be > 0"),
    (["fit", "none.npz", "--gain-grid", "1,-0.5"], "wresdyn fit: error: gain_grid[1] = -0.5 must be > 0"),
])
def test_a_value_the_config_refuses_is_one_line_and_exit_2(argv, message, capsys):
    assert main(argv) == 2
    assert capsys.readouterr().err.strip().splitlines() == [message]
