"""`wresdyn fit` writes a run that `wresdyn eval` reads, and the ablation runs end to end (tiny sizes, resumable)."""

import json

import numpy as np
import pytest

from wresdyn.cli import main
from wresdyn.evaluation.ablation import AblationConfig, cells, run_ablation


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory, humanoid, shipped_mismatch):
    """What `wresdyn collect` records on the shipped real robot, at 0.3 s: 2 train, 1 of each other split."""
    from wresdyn.data.real_robot import collect

    path = tmp_path_factory.mktemp("data") / "tiny.npz"
    collect(humanoid, shipped_mismatch, {"train": 2, "validation": 1, "heldout": 1, "ood": 1}, duration=0.3).save(path)
    return path


@pytest.mark.parametrize("model", ["network", "parametric"])
def test_fit_command_exports_a_run_that_eval_reads(tmp_path, tiny_data, model):
    run = tmp_path / model
    args = ["fit", str(tiny_data), "--out", str(run), "--model", model, "--iterations", "3", "--windows", "2",
            "--curriculum", "2,4", "--solver", "featherstone"]
    assert main(args) == 0
    for name in ("policy.pt", "policy.onnx", "residual.json", "config.json", "checkpoint.pt"):
        assert (run / name).is_file()
    if model == "parametric":
        params = json.loads((run / "parameters.json").read_text())
        assert set(params) == {"kp_scale", "kd_scale", "damping", "friction", "armature"}
    assert main(["eval", str(run), "--splits", "heldout", "--solver", "featherstone"]) == 0
    metrics = json.loads((run / "eval" / "metrics.json").read_text())
    assert "heldout" in json.dumps(metrics) and (run / "eval" / "report.md").is_file()


def test_ablation_cells_and_smoke_run(tmp_path, humanoid, tiny_data):
    from wresdyn.data.dataset import load_dataset

    full = AblationConfig()
    names = [c["name"] for c in cells(full)]
    assert len(names) == 2 * 2 * 2 * 3 + 3  # PPO and gradient: arch x kind x seed; parametric: seeds
    data = load_dataset(tiny_data, robot=humanoid)
    cfg = AblationConfig(learners=("ppo", "gradient", "parametric"), archs=("mlp",), kinds=("torque",), seeds=(0,),
                         ppo_iterations=2, gradient_iterations=2, segments=2, solver="featherstone",
                         ppo_overrides={"ppo.num_envs": 4, "ppo.num_steps_per_env": 4, "env.horizon": 8},
                         gradient_overrides={"windows": 2, "horizon_curriculum": (2,)})
    results = run_ablation(humanoid, data, cfg, tmp_path, log=lambda *_: None)
    assert [r["learner"] for r in results] == ["ppo", "gradient", "parametric"]
    for r in results:
        assert len(r["curve"]) == 2 and r["curve"][-1]["sim_steps"] > r["curve"][0]["sim_steps"] > 0
        assert np.isfinite(r["heldout"]["mean_abs_dq"]) and np.isfinite(r["ood"]["mean_abs_dq"])
    table = (tmp_path / "table.md").read_text()
    assert "| ppo | mlp | torque | 1 |" in table and "| parametric |" in table
    assert (tmp_path / "curves.png").stat().st_size > 0
    # a second run finds every cell done and only rewrites the summary
    mtime = (tmp_path / "gradient-mlp-torque-s0" / "result.json").stat().st_mtime
    run_ablation(humanoid, data, cfg, tmp_path, log=lambda *_: None)
    assert (tmp_path / "gradient-mlp-torque-s0" / "result.json").stat().st_mtime == mtime


def test_parallel_cells_reproduce_the_sequential_run(tmp_path, humanoid, tiny_data):
    """`--jobs`: cells in spawned worker processes (robot and data pickled) give the sequential figures."""
    from wresdyn.data.dataset import load_dataset

    data = load_dataset(tiny_data, robot=humanoid)
    cfg = AblationConfig(learners=("gradient", "parametric"), archs=("mlp",), kinds=("torque",), seeds=(0,),
                         gradient_iterations=3, segments=1, solver="featherstone",
                         gradient_overrides={"windows": 2, "horizon_curriculum": (2,)})
    seq = run_ablation(humanoid, data, cfg, tmp_path / "seq", log=lambda *_: None)
    par = run_ablation(humanoid, data, cfg, tmp_path / "par", log=lambda *_: None, jobs=2)
    assert [r["name"] for r in par] == [r["name"] for r in seq]
    for a, b in zip(seq, par):
        assert b["heldout"]["mean_abs_dq"] == pytest.approx(a["heldout"]["mean_abs_dq"], rel=1e-6)
    assert (tmp_path / "par" / "table.md").is_file()


def test_ablation_config_refuses_bad_cells_at_construction(tmp_path, capsys):
    from wresdyn.errors import WresdynError

    for kw, msg in (({"learners": ("ppo", "bogus")}, "learners = 'bogus' is not one of: ppo, gradient, parametric"),
                    ({"kinds": ("torqu",)}, "ablation kinds = 'torqu' is not one of: torque, delta_action"),
                    ({"solver": "mujuco"}, "ablation solver = 'mujuco' is not one of"),
                    ({"segments": 4, "ppo_iterations": 3}, "ablation ppo_iterations = 3 must be >= 4"),
                    ({"seeds": ()}, "at least one seed"),
                    ({"ppo_overrides": {"ppo.num_env": 4}}, "ablation ppo_overrides: .*num_env"),
                    ({"ppo_overrides": {"ppo.num_envs": 2}}, "num_mini_batches = 4 is more than the 2 worlds"),
                    ({"learners": ("gradient",), "gradient_overrides": {"windowz": 2}},
                     "gradient_overrides: .*windowz")):
        with pytest.raises(WresdynError, match=msg):
            AblationConfig(**kw)
    # the command line refuses the same in one line, before loading anything
    assert main(["ablate", "--out", str(tmp_path / "never"), "--segments", "5", "--ppo-iterations", "2"]) == 2
    assert capsys.readouterr().err.splitlines() == ["wresdyn ablate: error: ablation ppo_iterations = 2 must be >= 5"]
    with pytest.raises(SystemExit) as ex:  # argparse's own refusal, in the same one-line form
        main(["ablate", "--out", str(tmp_path / "never"), "--kinds", "torque,bogus"])
    err = capsys.readouterr().err.splitlines()
    assert ex.value.code == 2 and len(err) == 1 and "--kinds" in err[0] and "torque,delta_action" in err[0]
    assert not (tmp_path / "never").exists()
