"""The floor benchmark's CPU run that trains nothing (``wresdyn deploy --floor --shipped``): the package's shipped (a),
(b) and (d) checked against their hashes and deployed on the run's own motions, with what it refuses."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from wresdyn.cli import main
from wresdyn.data.mismatch import Mismatch
from wresdyn.errors import WresdynError
from wresdyn.experiments import nominal_policy
from wresdyn.experiments.deploy_config import FloorDeployConfig
from wresdyn.skills import shipped
from wresdyn.skills.skill_config import FloorTaskConfig, SkillPPOConfig


def test_the_shipped_floor_policies_are_intact_and_fit_the_floor_task(humanoid, shipped_mismatch):
    """Every file of (a), (b), (d) has the sha256 its manifest records; each fits the default floor task and robot in
    the setting it names; (b) and (d) were fine-tuned for the default mismatch, the one the manifest keeps."""
    motions = {"seed": 1, "duration": 4.0, "floor": True, "screened": True}
    for name, source in nominal_policy.SHIPPED_FLOOR.items():
        folder = shipped.shipped_folder(source)  # raises where a file's hash differs
        record = json.loads((folder / "shipped.json").read_text())
        assert set(record["sha256"]) == {p.name for p in folder.iterdir() if p.name != "shipped.json"}
        assert record["command"].count("--full") == 1 and "cuda" in record["command"], record["command"]
        nominal_policy.check_fits(source, FloorTaskConfig(), SkillPPOConfig(), motions, humanoid.n_dof,
                                  setting={"a_nominal": "nominal", "b_calibrated": "calibrated",
                                           "d_oracle": "real"}[name])
        if name != "a_nominal":
            assert record["mismatch"] == json.loads(json.dumps(shipped_mismatch.to_dict()))
            assert json.loads((folder / "config.json").read_text())["ppo"]["iterations"] == 300


@pytest.fixture()
def tiny_shipped(tmp_path, monkeypatch, floating, shipped_mismatch):
    """(a), (b), (d) shipped into a package folder of the test's: one PPO iteration of (a) on 2 worlds of the nominal
    simulator's floor (1 s unscreened motions), copied as (b) and (d) with their settings."""
    from wresdyn.skills.env import TrackingEnv
    from wresdyn.skills.motions import make_motions
    from wresdyn.skills.plants import SimPlant
    from wresdyn.skills.skill_ppo import train_skill
    from wresdyn.robot.description import load_robot

    robot = load_robot(floating.source)
    motions = make_motions(robot, {"train": 1}, duration=1.0, rate_hz=500.0, seed=0, floating=floating, screen=False)
    task = FloorTaskConfig()
    env = TrackingEnv(SimPlant(floating, 2, 500.0, task.decimation, ground=True), motions["train"], task)
    run = tmp_path / "runs" / "a_nominal"
    meta = {"motions": {"seed": 0, "counts": {"train": 1}, "duration": 1.0, "floor": True, "screened": False},
            "setting": "nominal", "correction": ""}
    train_skill(env, SkillPPOConfig(iterations=1, torch_threads=1), run, meta=meta, log=lambda s: None)
    monkeypatch.setattr(shipped, "SHIPPED", tmp_path / "policies")
    monkeypatch.setattr(nominal_policy, "SHIPPED", tmp_path / "policies")
    mm = {"mismatch": json.loads(json.dumps(shipped_mismatch.to_dict()))}
    for name, source in nominal_policy.SHIPPED_FLOOR.items():
        folder = run.with_name(name)
        if name != "a_nominal":
            shutil.copytree(run, folder)
            cfg = json.loads((folder / "config.json").read_text())
            (folder / "config.json").write_text(json.dumps({**cfg, "setting": {"b_calibrated": "calibrated",
                                                                               "d_oracle": "real"}[name]}))
        shipped.ship_policy(folder, source, "wresdyn deploy --floor --full ...", "a GPU", "abc", mm)
    return run.parent


def test_the_shipped_cpu_run_trains_nothing_and_deploys_the_shipped_policies(tmp_path, tiny_shipped, data,
                                                                              shipped_mismatch):
    """``--shipped`` installs (a), (b), (d) as shipped (their files bit for bit), fits no correction, draws no
    training motion, deploys every policy on its own validation and held-out motions and says in the report where
    each was trained (command, commit, hash); the policies' own seed, another policy and another real robot are
    refused before anything is drawn."""
    import hashlib

    data_path = tmp_path / "dataset.npz"
    data.save(data_path)
    head = ["deploy", str(data_path), "--floor", "--shipped", "--validation-per-family", "1", "--heldout-per-family",
            "1", "--duration", "1.0", "--no-screen", "--no-animation", "--quiet"]
    out = tmp_path / "cpu"
    assert main(head + ["--seed", "1", "--out", str(out)]) == 0
    log = (out / "deploy.log").read_text()
    assert "PPO iterations" not in log and "fitting" not in log
    digest = lambda p: hashlib.sha256(p.read_bytes()).hexdigest()  # noqa: E731
    for name in nominal_policy.SHIPPED_FLOOR:
        assert f"policy {name}: {nominal_policy.SHIPPED_FLOOR[name]} (not trained here" in log
        for f in ("policy.pt", "model_0.pt"):
            assert digest(out / "skills" / name / f) == digest(tiny_shipped / name / f), (name, f)
    assert not (out / "calibrated").exists() and not (out / "delta_action").exists()
    res = json.loads((out / "results.json").read_text())
    assert set(res["shipped"]) == {"a_nominal", "b_calibrated", "d_oracle"}
    assert res["shipped"]["d_oracle"]["policy_sha256"] == digest(tiny_shipped / "d_oracle" / "policy.pt")
    for split in ("validation", "heldout"):
        assert set(res["real"][split]) == {"reference", "a_nominal", "b_calibrated", "d_oracle"}
        assert set(res["sim"][split]) <= {"reference", "a_nominal"}  # (b)'s simulator is not built here
    assert len(res["real"]["validation"]["a_nominal"]["motions"]) == 4  # one per training family, no training split
    report = (out / "report.md").read_text()
    assert "No policy was trained on this machine" in report and "`wresdyn deploy --floor --full ...`" in report
    (line,) = (out / "heldout_ledger.jsonl").read_text().splitlines()
    assert set(json.loads(line)["figures"]) == set(res["real"]["heldout"])

    cfg, task, ppo = FloorDeployConfig(shipped=True, seed=1), FloorTaskConfig(), SkillPPOConfig()
    uneven = Mismatch.load(Path(__file__).parents[2] / "data" / "mismatch_uneven.toml")
    for args, why in (((["a_nominal"], shipped_mismatch), "--seed 0 draws the shipped policies' own"),
                      ((["a_nominal", "c_delta_action"], shipped_mismatch), "deploys a_nominal"),
                      ((["a_nominal", "d_oracle"], uneven), "deploys on that one only")):
        with pytest.raises(WresdynError, match=why):
            nominal_policy.check_installed(replace(cfg, seed=0) if "seed" in why else cfg, *args, task, ppo, {}, 21)
    with pytest.raises(WresdynError, match="changed since it was shipped"):
        (shipped.SHIPPED / "floor_oracle" / "policy.pt").write_bytes(b"tampered")
        shipped.shipped_folder("floor_oracle")
