"""Shipped skill policies: installed into a run folder with their files checked against the manifest's hashes; the
floor's CPU runs that fine-tune the shipped (a) or deploy the shipped (a), (b), (d) (``--shipped``)."""

import hashlib
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


def _run(folder, last=99):
    folder.mkdir(parents=True)
    for name, data in (("config.json", b"{}"), ("train_summary.json", b"{}"), ("policy.pt", b"program"),
                       ("model_50.pt", b"older"), (f"model_{last}.pt", b"latest")):
        (folder / name).write_bytes(data)
    return folder


def test_ship_install_and_check(tmp_path, monkeypatch):
    monkeypatch.setattr(shipped, "SHIPPED", tmp_path / "policies")
    folder = shipped.ship_policy(_run(tmp_path / "run"), "floor_nominal", "wresdyn deploy ...", "H200", "abc")
    # only the last checkpoint travels
    assert sorted(p.name for p in folder.iterdir()) == ["config.json", "model_99.pt", "policy.pt", "shipped.json",
                                                        "train_summary.json"]
    dst = shipped.install_policy("floor_nominal", tmp_path / "out" / "a_nominal")
    assert (dst / "model_99.pt").read_bytes() == b"latest"
    assert not (tmp_path / "out" / "a_nominal.partial").exists()
    assert shipped.install_policy("floor_nominal", dst) == dst  # the same files again: kept
    (folder / "policy.pt").write_bytes(b"tampered")
    with pytest.raises(WresdynError, match="changed since it was shipped"):
        shipped.shipped_folder("floor_nominal")
    with pytest.raises(WresdynError, match="no shipped policy 'stand'.*floor_nominal"):
        shipped.shipped_folder("stand")


def test_install_refuses_another_policy_and_unfinished_runs(tmp_path):
    dst = shipped.install_policy(_run(tmp_path / "a"), tmp_path / "out")
    with pytest.raises(WresdynError, match="holds another policy"):
        shipped.install_policy(_run(tmp_path / "b", last=120), dst)
    unfinished = _run(tmp_path / "c")
    (unfinished / "policy.pt").unlink()
    with pytest.raises(WresdynError, match="not a finished skill run.*policy.pt"):
        shipped.install_policy(unfinished, tmp_path / "out2")



@pytest.fixture(scope="module")
def tiny_nominal(tmp_path_factory, humanoid, floating):
    """A skill run of (a) as the floor benchmark writes it (one PPO iteration on 2 worlds of the nominal simulator's
    floor, 1 s unscreened motions), from the real trainer."""
    from wresdyn.skills.env import TrackingEnv
    from wresdyn.skills.motions import make_motions
    from wresdyn.skills.plants import SimPlant
    from wresdyn.skills.skill_config import FloorTaskConfig, SkillPPOConfig
    from wresdyn.skills.skill_ppo import train_skill

    motions = make_motions(humanoid, {"train": 1}, duration=1.0, rate_hz=500.0, seed=0, floating=floating,
                           screen=False)
    task = FloorTaskConfig()
    env = TrackingEnv(SimPlant(floating, 2, 500.0, task.decimation, ground=True), motions["train"], task)
    run = tmp_path_factory.mktemp("nominal") / "a_nominal"
    meta = {"motions": {"seed": 0, "counts": {"train": 1}, "duration": 1.0, "floor": True, "screened": False},
            "setting": "nominal", "correction": ""}
    train_skill(env, SkillPPOConfig(iterations=1, torch_threads=1), run, meta=meta, log=lambda s: None)
    return run


def test_the_shipped_nominal_is_the_cpu_default_and_one_that_does_not_fit_is_refused(tmp_path, monkeypatch,
                                                                                     tiny_nominal, humanoid):
    """``auto`` takes the shipped ``floor_nominal`` on the CPU only where the package has it (a GPU run and the full
    size train (a)); a policy trained for another task, network, motion generator or robot is refused in one line
    naming what differs."""
    from wresdyn.experiments import nominal_policy
    from wresdyn.experiments.deploy_config import FloorDeployConfig
    from wresdyn.skills.skill_config import FloorTaskConfig, SkillPPOConfig

    monkeypatch.setattr(shipped, "SHIPPED", tmp_path / "policies")
    monkeypatch.setattr(nominal_policy, "SHIPPED", tmp_path / "policies")
    assert nominal_policy.nominal_source(FloorDeployConfig()) is None  # nothing shipped: trained
    shipped.ship_policy(tiny_nominal, "floor_nominal", "wresdyn deploy --floor ...", "2 CPU cores", "abc")
    assert nominal_policy.nominal_source(FloorDeployConfig()) == "floor_nominal"
    assert nominal_policy.nominal_source(FloorDeployConfig(device="cuda:0")) is None
    assert nominal_policy.nominal_source(FloorDeployConfig(nominal=None)) is None
    assert FloorDeployConfig.full().nominal is None and FloorDeployConfig.full().heldout_families == "all"

    motions = {"seed": 3, "counts": {"train": 5}, "duration": 1.0, "floor": True, "screened": False}
    task, ppo, n = FloorTaskConfig(), SkillPPOConfig(), humanoid.n_dof
    nominal_policy.check_fits("floor_nominal", task, ppo, motions, n)  # another seed and count: the same generator
    nominal_policy.check_fits(str(tiny_nominal), task, ppo, motions, n)  # a run folder
    for args, why in (((FloorTaskConfig(w_fall=3.0), ppo, motions, n), "task w_fall 10.0 against 3.0"),
                      ((task, SkillPPOConfig(hidden_dims=(64,)), motions, n), "network widths [256, 128] against [64]"),
                      ((task, ppo, {**motions, "duration": 4.0, "screened": True}, n),
                       "motions' duration 1.0 against 4.0; motions' screened False against True"),
                      ((task, ppo, motions, n - 1), f"does not take this robot's {6 * n}")):
        with pytest.raises(WresdynError, match="does not fit this run") as err:
            nominal_policy.check_fits("floor_nominal", *args)
        assert why in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_the_floor_cpu_run_fine_tunes_the_shipped_nominal(tmp_path, monkeypatch, tiny_nominal, data, capsys):
    """``wresdyn deploy --floor`` on the CPU takes the shipped ``floor_nominal`` as (a) by default (its files as
    shipped), fine-tunes from it and deploys on the held-out families (a) carries on validation motions; another
    task is refused in one line before anything is drawn or trained."""
    import hashlib
    import json

    from wresdyn.cli import main
    from wresdyn.experiments import nominal_policy

    monkeypatch.setattr(shipped, "SHIPPED", tmp_path / "policies")
    monkeypatch.setattr(nominal_policy, "SHIPPED", tmp_path / "policies")
    shipped.ship_policy(tiny_nominal, "floor_nominal", "wresdyn deploy --floor ...", "2 CPU cores", "abc")
    data_path = tmp_path / "dataset.npz"
    data.save(data_path)
    out = tmp_path / "cpu"
    head = ["deploy", str(data_path), "--floor", "--policies", "a_nominal", "d_oracle", "--finetune", "1",
            "--num-worlds", "2", "--train-per-family", "1", "--validation-per-family", "1", "--heldout-per-family",
            "1", "--duration", "1.0", "--no-screen", "--ppo.torch-threads", "1", "--quiet"]
    assert main(head + ["--out", str(out)]) == 0
    log = (out / "deploy.log").read_text()
    assert "policy a_nominal: floor_nominal (not trained here" in log and "in the nominal simulator" not in log
    digest = lambda p: hashlib.sha256(p.read_bytes()).hexdigest()  # noqa: E731
    for f in ("policy.pt", "config.json", "model_0.pt"):
        assert digest(out / "skills" / "a_nominal" / f) == digest(tiny_nominal / f), f
    res = json.loads((out / "results.json").read_text())
    assert res["config"]["nominal"] == "floor_nominal"
    assert res["nominal"] == {"source": "floor_nominal", "iterations": 1, "num_worlds": 2}
    fam = res["heldout_families"]
    # the stepping family has no validation motion to vouch for it: left out unless every family is
    assert ("step" not in fam["kept"] and "validation" in fam["left_out"]["step"]) or not fam["left_out"]
    held = res["real"]["heldout"]["a_nominal"]["motions"]
    assert sorted({m["motion"].split("_", 1)[1].rsplit("_", 1)[0] for m in held}) == sorted(fam["kept"])
    assert "`floor_nominal` taken as it is" in (out / "report.md").read_text()

    capsys.readouterr()
    other = tmp_path / "other"
    assert main(head + ["--out", str(other), "--task.w-fall", "3"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "does not fit" in err and "w_fall 10.0 against 3.0" in err
    assert not (other / "skills").exists()


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
def tiny_shipped(tmp_path, monkeypatch, tiny_nominal, shipped_mismatch):
    """(a), (b), (d) shipped into a package folder of the test's: the tiny (a), copied as (b) and (d) with their
    settings."""
    monkeypatch.setattr(shipped, "SHIPPED", tmp_path / "policies")
    monkeypatch.setattr(nominal_policy, "SHIPPED", tmp_path / "policies")
    mm = {"mismatch": json.loads(json.dumps(shipped_mismatch.to_dict()))}
    for name, source in nominal_policy.SHIPPED_FLOOR.items():
        folder = tmp_path / "runs" / name
        shutil.copytree(tiny_nominal, folder)
        if name != "a_nominal":
            cfg = json.loads((folder / "config.json").read_text())
            (folder / "config.json").write_text(json.dumps({**cfg, "setting": {"b_calibrated": "calibrated",
                                                                               "d_oracle": "real"}[name]}))
        shipped.ship_policy(folder, source, "wresdyn deploy --floor --full ...", "a GPU", "abc", mm)
    return tmp_path / "runs"


def test_the_shipped_cpu_run_trains_nothing_and_deploys_the_shipped_policies(tmp_path, tiny_shipped, data,
                                                                              shipped_mismatch):
    """``--shipped`` installs (a), (b), (d) as shipped (their files bit for bit), fits no correction, draws no
    training motion, deploys every policy on its own validation and held-out motions and says in the report where
    each was trained (command, commit, hash); the policies' own seed, another policy and another real robot are
    refused before anything is drawn."""
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
