"""Run folders shared by the learners: field-naming config comparison, weights-only checkpoints, the RunFolder."""

import json

import pytest
import torch

from wresdyn.learn.config_diff import config_diff, describe_diff
from wresdyn.learn.runs import RunError, check_resume, load_checkpoint, read_unset, save_checkpoint


def test_config_diff_names_nested_fields_as_json_reads_them():
    old = {"ppo": {"gamma": 0.9, "seed": 0}, "residual": {"hidden_dims": [64, 32], "kind": "torque"}, "gone": 1}
    new = {"ppo": {"gamma": 0.95, "seed": 0}, "residual": {"hidden_dims": (64, 16), "kind": "torque"}, "added": 2}
    assert config_diff(old, new) == ["ppo.gamma", "residual.hidden_dims[1]", "gone", "added"]
    # equal after the JSON round trip: tuples are lists, 1 == 1.0; but a flag is not a number, and floats are exact
    assert config_diff({"a": (1, 2), "b": 1, "n": float("nan")}, {"a": [1, 2], "b": 1.0, "n": float("nan")}) == []
    assert config_diff({"flag": True}, {"flag": 1}) == ["flag"]
    assert config_diff({"x": 0.1 + 0.2}, {"x": 0.3}) == ["x"]
    assert config_diff({"l": [1, 2]}, {"l": [1, 2, 3]}) == ["l"]  # another length: the list itself
    assert describe_diff({"ppo": {"gamma": 0.9}}, {"ppo": {"gamma": 0.95}}) == "ppo.gamma = 0.9, now 0.95"
    assert describe_diff({"a": 1}, {"b": 1}) == "a = 1, now <missing>; b = <missing>, now 1"
    many = describe_diff({k: 0 for k in "abcde"}, {k: 1 for k in "abcde"})
    assert many.endswith("and 2 more (d, e)")


def test_check_resume_allows_only_the_listed_fields():
    old = {"ppo": {"gamma": 0.9, "iterations": 10}}
    check_resume("runs/x", old, {"ppo": {"gamma": 0.9, "iterations": 20}}, may_change=["ppo.iterations"])
    with pytest.raises(RunError) as err:
        check_resume("runs/x", old, {"ppo": {"gamma": 0.95, "iterations": 20}}, may_change=["ppo.iterations"])
    assert str(err.value) == ("runs/x was trained with ppo.gamma = 0.9, now 0.95; resume with the same configuration "
                              "or choose another folder")


def test_a_field_added_since_the_run_resumes_at_its_none_default_only():
    """A run folder written before a config field existed resumes while the field is at its ``None`` default (the
    behaviour from before it); any other value is refused, naming the field."""
    old = {"env": {"solver": "auto"}, "iterations": 10}
    check_resume("runs/x", old, {"env": {"solver": "auto", "friction_kappa": None}, "iterations": 10})
    with pytest.raises(RunError, match="env.friction_kappa = <missing>, now 10000.0"):
        check_resume("runs/x", old, {"env": {"solver": "auto", "friction_kappa": 1e4}, "iterations": 10})
    with pytest.raises(RunError, match="iterations = 10, now 20"):
        check_resume("runs/x", old, {"env": {"solver": "auto", "friction_kappa": None}, "iterations": 20})


def test_a_run_folder_written_with_0_for_unset_resumes_and_reads_back_as_none():
    """select_every, grad_truncation and torch_threads say "use another value" with None; folders written before saved
    0 for it: they resume with the config that means the same, and another value is still refused."""
    from dataclasses import asdict

    from wresdyn.ppo.ppo_config import config_from_dict, default_config

    new = asdict(default_config())
    old = {**new, "ppo": {**new["ppo"], "select_every": 0}}
    assert new["ppo"]["select_every"] is None and read_unset(old) == new
    check_resume("runs/x", old, new)
    with pytest.raises(RunError, match="ppo.select_every = 3, now null"):
        check_resume("runs/x", {**new, "ppo": {**new["ppo"], "select_every": 3}}, new)
    assert read_unset({"sysid": {"grad_truncation": 0, "refine": 0, "flag": False}}) == {
        "sysid": {"grad_truncation": None, "refine": 0, "flag": False}}
    assert config_from_dict(old) == default_config()


class _Marker:
    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):  # unpickling would create the file
        return (open, (self.path, "w"))


def test_load_checkpoint_reads_weights_only_and_names_the_file(tmp_path):
    data = {"w": torch.ones(3), "iter": 4, "opt": {"lr": 1e-3, "betas": (0.9, 0.99)}}
    path = save_checkpoint(data, tmp_path / "c.pt")
    assert load_checkpoint(path, keys=("w", "iter"))["iter"] == 4
    assert not list(tmp_path.glob("*.tmp"))  # written atomically, nothing left beside it
    marker = tmp_path / "ran"
    torch.save({"w": _Marker(marker)}, tmp_path / "evil.pt")
    cases = [("evil.pt", "not a weights-only checkpoint, refused without loading it (it would import io.open)"),
             ("missing.pt", "no such checkpoint"), ("c.pt", "not a checkpoint of this kind of run (no actor)")]
    (tmp_path / "empty.pt").write_bytes(b"")
    (tmp_path / "text.pt").write_text("not a checkpoint\n" * 10)
    torch.save([torch.ones(1)], tmp_path / "list.pt")
    cases += [("empty.pt", "empty or cut short"), ("text.pt", "not a"), ("list.pt", "holds a list, not a dict")]
    for name, msg in cases:
        with pytest.raises(RunError) as err:
            load_checkpoint(tmp_path / name, keys=("actor",) if name == "c.pt" else ())
        assert str(err.value).startswith(f"{tmp_path / name}: ") and msg in str(err.value)
        assert "\n" not in str(err.value)
    assert not marker.exists()
    # what could not be read back is refused when saving, not hours later
    with pytest.raises(TypeError, match="more than tensors and plain containers"):
        save_checkpoint({"w": _Marker(marker)}, tmp_path / "d.pt")
    assert not (tmp_path / "d.pt").exists() and not marker.exists()


def test_run_folder_resumes_its_checkpoint_and_refuses_another_config(tmp_path):
    from wresdyn.learn.runs import RunFolder

    net = torch.nn.Linear(2, 1)
    run = RunFolder(tmp_path / "run", {"lr": 0.1, "device": "cpu"}, may_change=("device",), key="fit",
                    record={"learner": "gradient"})
    assert run.resume(keys=("net",)) is None  # fresh: nothing to load, the record written
    assert json.loads((tmp_path / "run" / "config.json").read_text()) == {"learner": "gradient",
                                                                         "fit": {"lr": 0.1, "device": "cpu"}}
    assert run.best.consider(0.5, 0, net) and not run.best.consider(0.7, 1, net)
    first = net.weight.detach().clone()
    with torch.no_grad():
        net.weight.add_(1.0)  # the snapshot is a copy
    run.curve += [{"iteration": 1, "wall": 0.1, "loss": 2.0}, {"iteration": 2, "wall": 0.25, "loss": 1.0}]
    run.save({"net": net.state_dict()}, rng={"state": 3})
    run.write_curve()
    assert (run.iteration, run.wall) == (2, 0.25)
    assert json.loads((tmp_path / "run" / "curve.json").read_text()) == run.curve

    again = RunFolder(tmp_path / "run", {"lr": 0.1, "device": "cuda:0"}, may_change=("device",), key="fit",
                      record={"learner": "gradient"})
    data = again.resume(keys=("net",))
    assert torch.equal(data["net"]["weight"], net.weight) and again.meta["rng"] == {"state": 3}
    assert (again.iteration, again.wall, again.curve) == (2, 0.25, run.curve)
    assert (again.best.value, again.best.iteration) == (0.5, 0)
    assert torch.equal(again.best.state["weight"], first)
    assert json.loads((tmp_path / "run" / "config.json").read_text())["fit"]["device"] == "cuda:0"

    refused = RunFolder(tmp_path / "run", {"lr": 0.2, "device": "cpu"}, may_change=("device",), key="fit")
    with pytest.raises(RunError, match=r"^\S+ was trained with lr = 0.1, now 0.2; "):
        refused.resume(keys=("net",))
    # a refused resume leaves the record of the run as it was
    assert json.loads((tmp_path / "run" / "config.json").read_text())["fit"]["lr"] == 0.1
    with pytest.raises(RunError, match="no missing"):
        RunFolder(tmp_path / "run", {"lr": 0.1, "device": "cpu"}, key="fit").resume(keys=("missing",))


def test_run_folder_without_a_path_keeps_everything_in_memory(tmp_path, monkeypatch):
    from wresdyn.learn.runs import RunFolder

    monkeypatch.chdir(tmp_path)
    run = RunFolder(None, {"lr": 0.1})
    assert run.resume() is None and run.checkpoint is None
    run.curve.append({"iteration": 1, "wall": 0.5})
    run.save({"w": torch.ones(1)})
    run.write_curve()
    assert run.iteration == 1 and not list(tmp_path.iterdir())


def _skill_record(**ppo) -> dict:
    """The ``config.json`` of a skill run (:func:`wresdyn.skills.skill_ppo.train_skill`), with ``ppo`` fields set."""
    from dataclasses import asdict, replace

    from wresdyn.skills.skill_config import SkillConfig, SkillPPOConfig

    return {"ppo": asdict(replace(SkillPPOConfig(), **ppo)), "task": asdict(SkillConfig()), "init": None,
            "setting": "nominal"}


def test_runner_folder_checks_its_record_and_writes_it_once_fit(tmp_path):
    """A runner keeping its own checkpoints (rsl-rl's PPO): ``config.json`` is the record a resume is checked against,
    refused in one line naming the fields, and written only by a run found fit to continue."""
    from wresdyn.learn.runs import RunnerFolder
    from wresdyn.skills.skill_ppo import RESUME_MAY_CHANGE

    path = tmp_path / "skill"
    first = RunnerFolder(path, _skill_record(), RESUME_MAY_CHANGE)
    assert first.check(None) is None  # a fresh run: nothing to check
    first.write_config()
    first.write_summary({"iterations": 3})
    saved = (path / "config.json").read_text()
    assert json.loads(saved) == json.loads(json.dumps(_skill_record()))
    assert json.loads((path / "train_summary.json").read_text()) == {"iterations": 3}
    ckpt = path / "model_2.pt"
    # extended, or moved to another device, it goes on
    assert RunnerFolder(path, _skill_record(iterations=9, device="cuda:0"), RESUME_MAY_CHANGE).check(ckpt) == \
        json.loads(saved)
    refused = RunnerFolder(path, _skill_record(gamma=0.9, iterations=9), RESUME_MAY_CHANGE)
    with pytest.raises(RunError) as err:
        refused.check(ckpt)
    assert str(err.value) == (f"{path} was trained with ppo.gamma = 0.97, now 0.9; resume with the same "
                              "configuration or choose another folder")
    assert (path / "config.json").read_text() == saved
    # the compared part of a record under a key (the residual's PPO: the config beside the data's identity)
    nested = RunnerFolder(tmp_path / "ppo", {"config": {"lr": 0.1}, "dataset": {"rate_hz": 500.0}}, key="config",
                          writer="`wresdyn train`")
    nested.write_config()
    assert list(json.loads((tmp_path / "ppo" / "config.json").read_text())) == ["config", "dataset"]
    with pytest.raises(RunError, match=r"lr = 0.1, now 0.2"):
        RunnerFolder(tmp_path / "ppo", {"config": {"lr": 0.2}, "dataset": {}}, key="config").check(ckpt)
    (tmp_path / "ppo" / "config.json").write_text("[1]")
    with pytest.raises(RunError, match=r"config.json: not a run configuration written by `wresdyn train`$"):
        nested.check(ckpt)
    with pytest.raises(RunError, match="holds checkpoints but no config.json"):
        RunnerFolder(tmp_path / "none", _skill_record()).check(ckpt)


def test_a_skill_run_written_with_0_for_unset_resumes():
    """The skills' PPO wrote 0.0 for "the initial policy's own noise" (``restart_std``) and 0 for "torch's default
    threads" (``torch_threads``), both ``None`` now: such a folder resumes, and another value is still refused."""
    from wresdyn.learn.runs import RunnerFolder

    old = _skill_record()
    old["ppo"].update(restart_std=0.0, torch_threads=0)  # what SkillPPOConfig(restart_std=0.0, torch_threads=0) saved
    new = _skill_record(restart_std=None, torch_threads=None)
    check_resume("runs/x", old, new)
    assert read_unset(old) == read_unset(new)
    with pytest.raises(RunError, match=r"ppo.restart_std = 0.5, now null"):
        check_resume("runs/x", _skill_record(restart_std=0.5), new)
    assert RunnerFolder("runs/x", new).config["ppo"]["restart_std"] is None
