"""`wresdyn fit` writes a run that `wresdyn eval` reads, and the ablation runs end to end (tiny sizes, resumable)."""

import dataclasses
import json

import numpy as np
import pytest

import torch
from onnx.reference import ReferenceEvaluator
from PIL import Image

from wresdyn.cli import main
from wresdyn.data.dataset import load_dataset
from wresdyn.experiments.ablation import AblationConfig, cells, run_ablation
from wresdyn.learn.run_residual import load_policy


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
    # the exported residual, as eval and a deployment load it: the data's joints and rate, a finite torque per joint
    data = load_dataset(tiny_data)
    policy, meta = load_policy(run)
    assert meta["kind"] == "torque" and meta["joint_names"] == data.joint_names and meta["rate_hz"] == data.rate_hz
    t = data.split("heldout")[0]
    obs = np.concatenate([t.q, t.qd, t.qdd, t.q_cmd], axis=1).astype(np.float32)
    with torch.no_grad():
        tau = policy(torch.as_tensor(obs)).numpy()
    assert tau.shape == t.q.shape and np.isfinite(tau).all() and np.abs(tau).max() > 0
    # the ONNX file computes the same residual (ONNX's reference evaluator: no runtime needed)
    (onnx_tau,) = ReferenceEvaluator(str(run / "policy.onnx")).run(None, {"obs": obs})
    np.testing.assert_allclose(onnx_tau, tau, rtol=1e-4, atol=1e-5)  # float32, two graphs of the same ops
    config = json.loads((run / "config.json").read_text())  # what eval replays with
    assert config["gradfit"]["model"] == model and config["gradfit"]["iterations"] == 3
    assert config["config"]["env"]["solver"] == "featherstone" and config["data_path"] == str(tiny_data)
    if model == "parametric":
        params = json.loads((run / "parameters.json").read_text())
        assert set(params) == {"kp_scale", "kd_scale", "damping", "friction", "armature"}
        for per_joint in params.values():  # by joint name, each a physical value (scales and softplus terms > 0)
            assert list(per_joint) == data.joint_names and all(np.isfinite(x) and x > 0 for x in per_joint.values())
    assert main(["eval", str(run), "--splits", "heldout", "--solver", "featherstone"]) == 0
    metrics = json.loads((run / "eval" / "metrics.json").read_text())["splits"]["heldout"]
    pd, res = metrics["pd_only"]["mean_abs_dq"], metrics["pd_residual"]["mean_abs_dq"]
    assert 0 < pd and 0 < res and metrics["improvement"] == pytest.approx(pd / res)
    # the report's table states those figures
    report = (run / "eval" / "report.md").read_text()
    assert f"| heldout | 1 | {pd:.4f}" in report and f"{metrics['improvement']:.1f}×" in report, report


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory, humanoid, tiny_data):
    """The smoke ablation, run sequentially: one PPO, one gradient and one parametric cell at tiny sizes; the
    dataset, the configuration, the output folder and the results."""
    data = load_dataset(tiny_data, robot=humanoid)
    cfg = AblationConfig(learners=("ppo", "gradient", "parametric"), archs=("mlp",), kinds=("torque",), seeds=(0,),
                         ppo_iterations=2, gradient_iterations=2, segments=2, solver="featherstone",
                         ppo_overrides={"env.num_worlds": 4, "ppo.num_steps_per_env": 4, "env.horizon": 8},
                         gradient_overrides={"windows": 2, "horizon_curriculum": (2,)})
    out = tmp_path_factory.mktemp("ablation")
    return data, cfg, out, run_ablation(humanoid, data, cfg, out, log=lambda *_: None)


def test_ablation_cells_and_smoke_run(humanoid, smoke_run):
    full = AblationConfig()
    names = [c["name"] for c in cells(full)]
    assert len(names) == 2 * 2 * 2 * 3 + 3  # PPO and gradient: arch x kind x seed; parametric: seeds
    data, cfg, out, results = smoke_run
    assert [r["learner"] for r in results] == ["ppo", "gradient", "parametric"]
    for r in results:
        assert len(r["curve"]) == 2 and r["curve"][-1]["sim_steps"] > r["curve"][0]["sim_steps"] > 0
        assert np.isfinite(r["heldout"]["mean_abs_dq"]) and np.isfinite(r["ood"]["mean_abs_dq"])
    table = (out / "table.md").read_text()
    for r in results:  # one row per learner, stating its held-out error (one seed: no ± part)
        assert f"| {r['learner']} | {r['arch']} | {r['kind']} | 1 | {r['heldout']['mean_abs_dq']:.4f} |" in table, table
    # the curves: a line per learner in matplotlib's first three colours, on both panels of a wide figure
    img = np.asarray(Image.open(out / "curves.png").convert("RGB")).astype(int)
    assert img.shape[1] > 2 * img.shape[0]
    for colour in ((0x1F, 0x77, 0xB4), (0xFF, 0x7F, 0x0E), (0x2C, 0xA0, 0x2C)):
        assert (np.abs(img - colour).sum(axis=-1) < 30).sum() > 50, colour
    # a second run finds every cell done and only rewrites the summary
    mtime = (out / "gradient-mlp-torque-s0" / "result.json").stat().st_mtime
    run_ablation(humanoid, data, cfg, out, log=lambda *_: None)
    assert (out / "gradient-mlp-torque-s0" / "result.json").stat().st_mtime == mtime


def test_parallel_cells_reproduce_the_sequential_run(tmp_path, humanoid, smoke_run):
    """`--jobs`: cells in spawned worker processes (robot and data pickled) give the sequential figures: the smoke
    run's gradient and parametric cells (a cell depends on nothing but itself and the configuration's sizes)."""
    data, cfg, out, results = smoke_run
    par = run_ablation(humanoid, data, dataclasses.replace(cfg, learners=("gradient", "parametric")), tmp_path,
                       log=lambda *_: None, jobs=2)
    seq = [r for r in results if r["learner"] != "ppo"]
    assert [r["name"] for r in par] == [r["name"] for r in seq] == ["gradient-mlp-torque-s0", "parametric-s0"]
    for a, b in zip(seq, par):
        assert b["heldout"]["mean_abs_dq"] == pytest.approx(a["heldout"]["mean_abs_dq"], rel=1e-6)
    # the same table but for the wall-clock column (the 8th) and the PPO row the parallel run has not
    lines = [[row for row in (d / "table.md").read_text().splitlines() if not row.startswith("| ppo |")]
             for d in (out, tmp_path)]
    assert sum(row.startswith("|") for row in lines[1]) == 4  # header, rule, two cells
    seq_table, par_table = ([row.split("|")[:8] + row.split("|")[9:] for row in rows] for rows in lines)
    assert par_table == seq_table


def test_ablation_config_refuses_bad_cells_at_construction(tmp_path, capsys):
    from wresdyn.errors import WresdynError

    for kw, msg in (({"learners": ("ppo", "bogus")}, "learners = 'bogus' is not one of: ppo, gradient, parametric"),
                    ({"kinds": ("torqu",)}, "ablation kinds = 'torqu' is not one of: torque, delta_action"),
                    ({"solver": "mujuco"}, "ablation solver = 'mujuco' is not one of"),
                    ({"segments": 4, "ppo_iterations": 3}, "ablation ppo_iterations = 3 must be >= 4"),
                    ({"seeds": ()}, "at least one seed"),
                    ({"ppo_overrides": {"ppo.num_env": 4}}, "ablation ppo_overrides: .*num_env"),
                    ({"ppo_overrides": {"env.num_worlds": 2}}, "num_mini_batches = 4 is more than the 2 worlds"),
                    ({"learners": ("gradient",), "gradient_overrides": {"windowz": 2}},
                     "gradient_overrides: .*windowz")):
        with pytest.raises(WresdynError, match=msg):
            AblationConfig(**kw)
    # the command line refuses the same in one line, before loading anything
    assert main(["ablate", "--out", str(tmp_path / "never"), "--segments", "5", "--ppo-iterations", "2"]) == 2
    assert capsys.readouterr().err.splitlines() == ["wresdyn ablate: error: ablation ppo_iterations = 2 must be >= 5"]
    with pytest.raises(SystemExit) as ex:  # the command line's own refusal, in the same one-line form
        main(["ablate", "--out", str(tmp_path / "never"), "--kinds", "torque", "bogus"])
    err = capsys.readouterr().err.splitlines()
    assert ex.value.code == 2 and len(err) == 1 and "--kinds" in err[0] and "torque,delta_action" in err[0]
    assert not (tmp_path / "never").exists()
