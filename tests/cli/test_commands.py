"""Every command is its dataclass on the command line (tyro): each config field a flag with its docstring and its
true default, every spelling of earlier releases rewritten to today's with a one-line note, ``--help`` light, bad
values in one line and exit status 2."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import asdict, replace

import pytest

from wresdyn.adapt.config import AdaptConfig
from wresdyn.cli import COMMANDS, command_flags, main, parse_command
from wresdyn.cli.collect import CollectConfig
from wresdyn.cli.deprecated import RENAMED, rewrite
from wresdyn.data.signals import ExcitationConfig
from wresdyn.experiments.ablation_config import AblationConfig
from wresdyn.experiments.deploy_config import DeployConfig, FloorDeployConfig
from wresdyn.fit.gradfit_config import GradFitConfig
from wresdyn.identify.sysid_config import SysIdConfig
from wresdyn.ppo.ppo_config import default_config
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

POSITIONAL = {"fit": ["d.npz"], "identify": ["d.npz"], "train": ["d.npz"], "eval": ["run"], "export": ["run"],
              "view": ["run"], "adapt": ["run", "log"], "migrate": ["d.npz", "--out", "new.npz"]}
"""What each command needs besides its defaults."""


def _parse(argv: list[str]):
    return parse_command(argv)[2]


def _config(argv: list[str]):
    args = _parse(argv)
    return args.sizes if argv[0] == "deploy" else args.config


def test_every_command_helps(capsys):
    for command in COMMANDS:
        with pytest.raises(SystemExit) as ex:
            main([command, "--help"])
        assert ex.value.code == 0
        out = capsys.readouterr().out
        assert out.startswith(f"usage: wresdyn {command}"), command
        assert "--package-path" in out, command
    with pytest.raises(SystemExit) as ex:
        main(["--help"])
    out = capsys.readouterr().out
    assert ex.value.code == 0 and all(c in out for c in COMMANDS)


DEFAULTS = {
    "collect": CollectConfig(), "identify": SysIdConfig(), "adapt": AdaptConfig(), "fit": GradFitConfig(),
    "train": default_config(), "deploy": DeployConfig(), "ablate": AblationConfig(),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_command_parses_its_defaults(command):
    args = _parse([command, *POSITIONAL.get(command, [])])
    if command in DEFAULTS:
        assert _config([command, *POSITIONAL.get(command, [])]) == DEFAULTS[command]
    assert args.package_path == ()


def test_every_config_field_is_a_flag_but_those_the_command_sets():
    fit = command_flags("fit")
    assert "--horizon-curriculum" in fit and "--residual.kind" in fit and "--identify.iterations" in fit
    assert "--identify.device" not in fit and "--identify.seed" not in fit  # the fit's own
    deploy = command_flags("deploy")
    assert {"--task.action-scale", "--ppo.gamma", "--oracle-beside", "--task.w-fall"} <= set(deploy)
    assert "--ppo.num-envs" not in deploy and "--ppo.seed" not in deploy  # from the sizes
    assert "--ppo-overrides" not in command_flags("ablate")  # a dict: no command-line form


def test_the_help_is_the_docstring_with_the_default(capsys):
    with pytest.raises(SystemExit):
        main(["identify", "--help"])
    out = " ".join(capsys.readouterr().out.replace("│", " ").split())
    assert ("--windows INT Windows B (Newton worlds) per iteration: a batch of recorded windows, one world each, not an "
            "environment's world count") in out and "(default: 32)" in out


@pytest.mark.parametrize("command", sorted(OLD_FLAGS))
def test_every_flag_of_earlier_releases_is_still_read(command):
    flags = command_flags(command)
    for flag in OLD_FLAGS[command]:
        known = flag in flags or flag in RENAMED.get(command, {}) or flag == "--set"
        switch = flag.startswith("--no-") and f"--{flag[5:]}" in flags
        assert known or switch, f"wresdyn {command} {flag}"


@pytest.mark.parametrize("command,old,new", [(c, o, n) for c, table in RENAMED.items() for o, n in table.items()])
def test_each_old_spelling_is_rewritten_with_a_note_naming_the_new_one(command, old, new):
    notes = []
    flags = command_flags(command)
    assert new in flags
    out = rewrite(command, flags, [old, "1"], notes.append)
    assert out[0] == new and len(notes) == 1 and new in notes[0] and "deprecated" in notes[0]


def test_set_comma_lists_none_and_bare_optional_switches_are_rewritten():
    notes = []
    out = rewrite("train", command_flags("train"), ["--set", "ppo.desired_kl=0.05", "--set=residual.hidden_dims=128,64",
                                                    "--env.physics", "p.json"], notes.append)
    assert out == ["--ppo.desired-kl", "0.05", "--residual.hidden-dims", "128", "64", "--env.physics", "p.json"]
    assert len(notes) == 3 and "--ppo.desired-kl 0.05" in notes[0]
    notes.clear()
    out = rewrite("deploy", command_flags("deploy"), ["--oracle-beside", "--finetune-std", "none", "--floor"],
                  notes.append)
    assert out == ["--oracle-beside", "True", "--finetune-std", "None", "--floor"] and len(notes) == 2
    assert rewrite("fit", command_flags("fit"), ["--curriculum", ""], notes.append)[-1] == "--horizon-curriculum"
    assert rewrite("train", command_flags("train"), ["--set", "ppo.one_sync_update=true", "--set",
                                                     "ppo.mixed_precision=false"], notes.append) == [
        "--ppo.one-sync-update", "--ppo.no-mixed-precision"]


def test_switches_of_old_that_became_optional_are_rewritten():
    """``SysIdConfig.cuda_graph``, ``PPOConfig.graph_update`` and ``deferred_episode_log`` were switches and are
    ``bool | None`` now: their negatives and ``--set`` spellings of old still parse, to ``False`` or ``True``."""
    notes = []
    assert rewrite("fit", command_flags("fit"), ["--identify.no-cuda-graph"], notes.append) == [
        "--identify.cuda-graph", "False"]
    assert rewrite("identify", command_flags("identify"), ["--no-cuda-graph"], notes.append) == [
        "--cuda-graph", "False"]
    assert rewrite("train", command_flags("train"), ["--ppo.no-graph-update", "--set", "ppo.graph_update=true"],
                   notes.append) == ["--ppo.graph-update", "False", "--ppo.graph-update=True"]
    assert len(notes) == 4
    assert _config(["fit", "d.npz", "--identify.no-cuda-graph"]).cuda_graph  # the gradient fit's own graph stays
    assert _parse(["fit", "d.npz", "--identify.no-cuda-graph"]).identify.cuda_graph is False
    assert _config(["train", "d.npz"]).ppo.graph_update is None
    assert _config(["train", "d.npz", "--ppo.no-deferred-episode-log"]).ppo.deferred_episode_log is False
    assert _config(["train", "d.npz"]).ppo.deferred_episode_log is None


def test_a_spelling_of_today_is_left_alone():
    notes = []
    argv = ["d.npz", "--horizon-curriculum", "2", "4", "--residual.kind", "torque", "--no-cuda-graph", "--lr=0.01"]
    assert rewrite("fit", command_flags("fit"), argv, notes.append) == argv and not notes


def test_an_old_spelling_prints_one_note_and_runs(capsys):
    assert _config(["fit", "d.npz", "--curriculum", "2,4"]).horizon_curriculum == (2, 4)
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["wresdyn fit: note: --curriculum is deprecated; write --horizon-curriculum",
                   "wresdyn fit: note: comma lists are deprecated; write --horizon-curriculum 2 4"]


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


def test_a_switch_both_deploy_variants_have_is_turned_off_on_the_floor_too():
    args = _parse(["deploy", "--floor", "--no-animation", "--nominal", "None", "--heldout-families", "all"])
    assert not args.animation and args.sizes == FloorDeployConfig(nominal=None, heldout_families="all")


@pytest.mark.parametrize("argv,expected", SAME, ids=[" ".join(a[:3]) for a, _ in SAME])
def test_command_lines_of_earlier_releases_build_the_same_config(argv, expected):
    assert asdict(_config(argv)) == asdict(expected)


def test_the_global_package_path_before_the_command_still_reaches_it(tmp_path):
    args = _parse(["--package-path", str(tmp_path), "fit", "d.npz", "--package-path", "b"])
    assert args.package_path == (str(tmp_path), "b")


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
    assert main(head + ["--task.action-scale", "0.3", "--task.decimation", "5", *own, "--ppo.hidden-dims", "64", "32",
                        "--ppo.gamma", "0.99", "--ppo.torch-threads", "None", "--ppo.init-std", "0.5"]) == 0
    cfg, kw = passed[-1]
    assert cfg == (FloorDeployConfig if floor else DeployConfig)(num_worlds=8)
    task = task_cls(action_scale=0.3, decimation=5, **({"sigma_base": 0.2} if floor else {"fail_error": 0.7}))
    assert kw["task"] == task
    assert kw["ppo"] == SkillPPOConfig(hidden_dims=(64, 32), gamma=0.99, torch_threads=None, init_std=0.5)
    assert main(head) == 0
    assert passed[-1][1]["task"] == task_cls() and passed[-1][1]["ppo"] == SkillPPOConfig()
    # on the floor on the CPU (a), (b) and the oracle unless told; on a GPU and on the stand the benchmark's a-d
    assert passed[-1][1].get("policies") == (("a_nominal", "b_calibrated", "d_oracle") if floor else None)
    assert main(head + ["--device", "cuda:0"]) == 0 and "policies" not in passed[-1][1]
    assert main(head + ["--policies", "a_nominal", "c_delta_action"]) == 0
    assert passed[-1][1]["policies"] == ("a_nominal", "c_delta_action")


def test_the_hybrids_identification_shares_the_fits_device_seed_solver_and_windows():
    args = _parse(["fit", "d.npz", "--identify.iterations", "6", "--identify.gain-grid", "1", "0.5",
                   "--identify.refine", "2", "--windows", "4", "--seed", "3", "--solver", "replay", "--device",
                   "cuda:0"])
    assert args.identify_config == replace(SysIdConfig(), iterations=6, gain_grid=(1.0, 0.5), refine=2, windows=4,
                                           seed=3, solver="replay", device="cuda:0")
    assert _parse(["fit", "d.npz", "--windows", "4", "--identify.windows", "8"]).identify_config.windows == 8


def test_help_and_every_command_import_no_heavy_library():
    code = ("import sys\nfrom wresdyn.cli import COMMANDS, command_flags, main\n"
            "for c in COMMANDS: command_flags(c)\n"
            "try: main(['fit', '--help'])\nexcept SystemExit: pass\n"
            "heavy = [m for m in ('torch', 'warp', 'newton', 'mujoco', 'pxr', 'rsl_rl') if m in sys.modules]\n"
            "assert not heavy, heavy")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-500:]


@pytest.mark.parametrize("argv,message", [
    (["fit", "d.npz", "--iterations", "x"], "wresdyn fit: error: Error parsing --iterations:"),
    (["train", "d.npz", "--residual.kind", "torqu"],
     "wresdyn train: error: invalid choice 'torqu' for argument '--residual.kind'. choose from torque,delta_action"),
    (["deploy", "--floor", "--train-per-family", "1.5"], "wresdyn deploy: error: Error parsing --train-per-family"),
    (["fit", "d.npz", "--bogus", "3"], "wresdyn fit: error: Unrecognized options: --bogus"),
    (["train", "none.npz", "--set", "ppo.gama=0.9"], "wresdyn train: error: Unrecognized options: --set"),
    (["fit"], "wresdyn fit: error: required options: Missing from wresdyn fit: DATA"),
    (["nothing"], "wresdyn: error: unknown command 'nothing'"),
    (["deploy", "--oracle-beside", "True"],
     "wresdyn deploy: error: --oracle-beside sets the skills on the floor; it needs --floor"),
    (["deploy", "--beside-devices", "cuda:1"],
     "wresdyn deploy: error: --beside-devices sets the skills on the floor; it needs --floor"),
    (["deploy", "--task.w-fall", "3"], "wresdyn deploy: error: --task.w-fall sets the skills on the floor; it needs "
                                       "--floor"),
    (["deploy", "--floor", "--task.fail-error", "1"],
     "wresdyn deploy: error: --task.fail-error sets the skills on the stand; it has no use with --floor"),
])
def test_a_malformed_command_line_is_one_line_and_exit_2(argv, message, capsys):
    with pytest.raises(SystemExit) as ex:
        main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert ex.value.code == 2 and err and err[-1].startswith(message), err
    assert not any("Traceback" in line for line in err)


@pytest.mark.parametrize("argv,message", [
    (["collect", "--train", "0", "--validation", "0", "--heldout", "0", "--ood", "0"],
     "wresdyn collect: error: train/validation/heldout/ood are all 0: nothing to record"),
    (["collect", "--excitation.frames", "gripperframe", "--excitation.mode", "joint"], "wresdyn collect: error: "
     "--excitation.frames sets the IK targets of the foot excitation; it has no use with --excitation.mode joint"),
    (["collect", "--excitation.frames"], "wresdyn collect: error: --excitation.frames names no frame"),
    (["collect", "--max-velocity", "0"], "wresdyn collect: error: --max-velocity must be > 0, not 0.0"),
    (["migrate", "d.npz", "--out", "n.npz", "--validation", "-1"],
     "wresdyn migrate: error: --validation must be >= 0, not -1"),
    (["identify", "none.npz", "--windows", "0"], "wresdyn identify: error: windows = 0 must be >= 1"),
    (["train", "none.npz", "--env.num-worlds", "1", "--ppo.num-steps-per-env", "2"],
     "wresdyn train: error: ppo.num_mini_batches = 4 is more than the 2 samples per rollout"),
    (["deploy", "--oracle-num-worlds", "0"], "wresdyn deploy: error: deploy.oracle_num_worlds = 0 must be >= 1"),
    (["deploy", "--floor", "--beside-devices", "cuda:1", "gpu2"],
     "wresdyn deploy: error: floor.beside_devices = 'gpu2' is not a device: cpu, cuda or cuda:N"),
    (["deploy", "--ppo.torch-threads", "0"], "wresdyn deploy: error: ppo.torch_threads = 0 must be >= 1"),
    (["deploy", "--task.sigma-q", "0"], "wresdyn deploy: error: skill.sigma_q = 0.0 must be > 0"),
    (["fit", "none.npz", "--identify.gain-grid", "1", "-0.5"], "wresdyn fit: error: gain_grid[1] = -0.5 must be > 0"),
    (["ablate", "--segments", "5", "--ppo-iterations", "2"],
     "wresdyn ablate: error: ablation ppo_iterations = 2 must be >= 5"),
])
def test_a_value_the_config_refuses_is_one_line_and_exit_2(argv, message, capsys):
    assert main(argv) == 2
    assert capsys.readouterr().err.strip().splitlines() == [message]


def test_an_unknown_export_format_is_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as stop:
        main(["export", str(tmp_path / "run"), "--format", "obj", "--out", str(out)])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "'obj'" in err and "mjcf" in err and "usd" in err, err
    assert not out.exists()
