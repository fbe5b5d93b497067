"""A benchmark's deployments kept in its run folder (``wresdyn/skills/deployment_store.py``): read back bit for bit
where their fingerprint matches, deployed again where the policy or a setting changed or the file is unreadable, and
the held-out ledger still holds one line per scoring."""

from __future__ import annotations

import json
import shutil
from dataclasses import fields

import numpy as np
import pytest

from wresdyn.skills import deployment_store as ds
from wresdyn.skills.deployment_store import DeploymentStore, read_deployment, save_deployment
from wresdyn.skills.env import FAILURE_CAUSES
from wresdyn.skills.evaluate import Deployment, metrics
from wresdyn.skills.ledger import read_ledger
from wresdyn.skills.motions import Motion

from skill_runs import fit_run

COMMON = {"task": {"decimation": 5}, "motions": {"seed": 0}, "real": {"seed": 100}, "sim": {"device": "cpu"}}


def floor_deployment(seed: int = 0) -> Deployment:
    """A floor deployment of 3 motions (one fell at step 3, one drifted at step 4), 6 policy steps, 4 joints and 5
    links, as :func:`~wresdyn.skills.evaluate.deploy` shapes it."""
    rng = np.random.default_rng(seed)
    m, k, n, nb = 3, 6, 4, 5
    q, q_ref = rng.normal(size=(m, k + 1, n)), rng.normal(size=(m, k + 1, n))
    base, base_ref = rng.normal(size=(m, k + 1, 7)), rng.normal(size=(m, k + 1, 7))
    bodies, bodies_ref = rng.normal(size=(m, k + 1, nb, 3)), rng.normal(size=(m, k + 1, nb, 3))
    cmd = rng.normal(size=(m, k, n))
    for a in (q, base, bodies):
        a[0, 4:] = np.nan  # failed at step 3: nothing recorded after it
    cmd[0, 3:] = np.nan
    return Deployment(q, q_ref, cmd, np.array([3, 4, -1]), ["m0", "m1", "m2"], 0.02, floating=True, base=base,
                      bodies=bodies, base_ref=base_ref, bodies_ref=bodies_ref,
                      planted=rng.random((m, k + 1, 2)) > 0.5, feet=np.array([3, 4]),
                      fell=np.array([True, False, False]),
                      cause=np.array([FAILURE_CAUSES[0], "drifted", ""], dtype=object), fell_at=np.array([3, -1, -1]),
                      base_error_max=rng.random(m))


def motion(name: str, seed: int = 0) -> Motion:
    q = np.random.default_rng(seed).normal(size=(10, 4))
    return Motion(name, "squat", q, np.zeros_like(q), np.zeros((10, 2, 3)), {})


def test_a_deployment_reads_back_bit_for_bit_and_scores_the_same(tmp_path):
    dep = floor_deployment()
    save_deployment(tmp_path / "d.npz", dep, {"x": 1})
    back, fingerprint = read_deployment(tmp_path / "d.npz")
    assert fingerprint == {"x": 1}
    for f in fields(Deployment):
        a, b = getattr(dep, f.name), getattr(back, f.name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and a.shape == b.shape, f.name
            assert (a.tobytes() == b.tobytes()) if a.dtype != object else list(a) == list(b), f.name
        else:
            assert a == b, f.name
    assert json.dumps(metrics(back)) == json.dumps(metrics(dep))  # NaN-free means, NaN per-motion figures alike
    assert not list(tmp_path.glob("*.tmp"))


def _store(tmp_path, lines):
    return DeploymentStore(tmp_path, COMMON, lines.append)


def test_a_matching_deployment_is_reused_and_a_changed_input_deployed_again(tmp_path, monkeypatch):
    calls, lines = [], []
    monkeypatch.setattr(ds, "load_skill", lambda run_dir: f"policy of {run_dir.name}")

    def run(seed):
        def go(policy):
            calls.append(policy)
            return floor_deployment(seed)
        return go

    skill = tmp_path / "skills" / "a_nominal"
    skill.mkdir(parents=True)
    (skill / "policy.pt").write_bytes(b"weights 1")
    (skill / "model_4.pt").write_bytes(b"checkpoint")
    mot = [motion("m0"), motion("m1", 1)]
    first = _store(tmp_path, lines).deploy("heldout", "real", "a_nominal", skill, mot, run(0))
    assert calls == ["policy of a_nominal"] and lines == []
    path = tmp_path / "deployments" / "heldout" / "real_a_nominal.npz"
    assert read_deployment(path)[1]["policy"] == {"policy_sha256": ds.file_sha256(skill / "policy.pt"), "iteration": 4}

    store = _store(tmp_path, lines)
    again = store.deploy("heldout", "real", "a_nominal", skill, mot, run(1))
    assert len(calls) == 1 and "reused" in lines[-1] and store.deployed == set()
    assert again.q.tobytes() == first.q.tobytes()

    # another policy file, another motion, another plant setting: each deployed again and overwritten
    (skill / "policy.pt").write_bytes(b"weights 2")
    changed = [("policy.policy_sha256", lambda: store.deploy("heldout", "real", "a_nominal", skill, mot, run(2))),
               ("motions.digest", lambda: store.deploy("heldout", "real", "a_nominal", skill, mot[:1], run(3))),
               ("plant.seed", lambda: DeploymentStore(tmp_path, {**COMMON, "real": {"seed": 7}}, lines.append).deploy(
                   "heldout", "real", "a_nominal", skill, mot[:1], run(4)))]
    for i, (field, deploy) in enumerate(changed):
        got = deploy()
        assert len(calls) == 2 + i and f"with {field} = " in lines[-1] and "deployed again" in lines[-1], lines[-1]
        assert got.q.tobytes() == floor_deployment(2 + i).q.tobytes()
        assert read_deployment(path)[0].q.tobytes() == got.q.tobytes()
    assert store.deployed == {("heldout", "real")}


def test_a_skill_is_loaded_once_for_every_deployment_of_the_same_file(tmp_path, monkeypatch):
    loads, used = [], []
    monkeypatch.setattr(ds, "load_skill", lambda run_dir: loads.append(run_dir) or object())
    skill = tmp_path / "skills" / "a_nominal"
    skill.mkdir(parents=True)
    (skill / "policy.pt").write_bytes(b"weights 1")
    store = _store(tmp_path, [])

    def run(policy):
        used.append(policy)
        return floor_deployment()

    for split in ("validation", "heldout"):
        for where in ("real", "sim"):
            store.deploy(split, where, "a_nominal", skill, [motion(split)], run)
    assert len(loads) == 1 and len(used) == 4 and all(p is used[0] for p in used)
    (skill / "policy.pt").write_bytes(b"weights 2")  # another file under the same folder: loaded again
    store.deploy("heldout", "real", "a_nominal", skill, [motion("heldout")], run)
    assert len(loads) == 2 and used[-1] is not used[0]


def test_an_unreadable_deployment_is_deployed_again_with_a_warning(tmp_path):
    lines, calls = [], []
    path = tmp_path / "deployments" / "validation" / "sim_reference.npz"
    path.parent.mkdir(parents=True)
    path.write_bytes(b"cut short")
    dep = _store(tmp_path, lines).deploy("validation", "sim", "reference", None, [motion("m0")],
                                         lambda p: calls.append(p) or floor_deployment())
    assert calls == [None] and lines[0].startswith(f"warning: {path} cannot be read")
    assert read_deployment(path)[0].q.tobytes() == dep.q.tobytes()


def test_the_ledger_gets_one_line_per_scoring(tmp_path):
    """A session that deployed on held-out motions is recorded; one that read them all back is recorded only in a
    ledger that lacks that scoring (a run killed between its last deployment and the ledger)."""
    config, figures = {"benchmark": {"seed": 0, "iterations": 2}}, {"a_nominal": {"mpjpe": 0.1, "success": 1.0}}
    own, shared = tmp_path / "own.jsonl", tmp_path / "shared.jsonl"
    deployed = _store(tmp_path, [])
    deployed.deployed.add(("heldout", "real"))
    assert deployed.record([own], config, 0, figures, 3) == [own]
    assert deployed.record([own], config, 0, figures, 3) == [own]  # a second scoring run: listed again
    lines = []
    reread = _store(tmp_path, lines)
    assert reread.record([own, shared], config, 0, figures, 3) == [shared]
    assert reread.record([own, shared], config, 0, figures, 3) == [] and "in the ledger already" in lines[-1]
    assert (len(read_ledger(own)), len(read_ledger(shared))) == (2, 1)
    # other figures, seed or configuration are another scoring
    assert reread.record([own], config, 0, {"a_nominal": {"mpjpe": 0.2, "success": 1.0}}, 3) == [own]
    assert reread.record([own], config, 1, figures, 3) == [own]
    assert reread.record([own], {"benchmark": {"seed": 0, "iterations": 3}}, 0, figures, 3) == [own]
    assert len(read_ledger(own)) == 5


def _numbers(out) -> str:
    """``results.json`` without the wall-clock times, as text."""
    res = json.loads((out / "results.json").read_text())
    for k in ("wall_s", "fit_wall_s", "train_wall_s"):
        res.pop(k)
    return json.dumps(res, sort_keys=True)


@pytest.mark.slow  # ~2 min on 2 cores: the stand benchmark at the smallest size, three times
def test_a_rerun_benchmark_reads_back_its_deployments_and_scores_the_same(tmp_path, humanoid, data):
    """Run the stand benchmark, rerun it (every deployment read back: the same results.json, no ledger line), then
    give (b) (a)'s policy file: (b) is deployed again and scores on the real robot exactly as (a), a new scoring."""
    from wresdyn.experiments.deploy_config import DeployConfig
    from wresdyn.experiments.skills import run_benchmark
    from wresdyn.skills.skill_config import SkillPPOConfig

    cal = fit_run(tmp_path, humanoid, data, "torque", physics=True)
    cfg = DeployConfig(train_per_family=1, validation_per_family=1, heldout_per_family=1, duration=0.4,
                       num_worlds=4, oracle_num_worlds=2, iterations=2, finetune=1)
    ppo = SkillPPOConfig(num_steps_per_env=4, hidden_dims=(16,), num_mini_batches=1, torch_threads=1)
    out, policies = tmp_path / "deploy", ("a_nominal", "b_calibrated", "d_oracle")

    def bench():
        lines = []
        run_benchmark(humanoid, data, out, cfg, calibrated=cal, ppo=ppo, animation=False, policies=policies,
                      log=lines.append)
        return _numbers(out), [x for x in lines if "deployed earlier" in x]

    first, none = bench()
    assert none == []
    stored = sorted(p.relative_to(out / "deployments").as_posix() for p in (out / "deployments").rglob("*.npz"))
    # every policy and the reference on the real robot; all but the oracle in their own simulator
    assert stored == sorted(f"{s}/{w}_{n}.npz" for s in ("heldout", "validation") for w in ("real", "sim")
                            for n in ("reference", *policies) if not (w == "sim" and n == "d_oracle"))
    again, reused = bench()
    assert again == first
    assert len(reused) == len(stored) and all(x.endswith(".npz)") and "reused" in x for x in reused)
    assert len(read_ledger(out / "heldout_ledger.jsonl")) == 1

    shutil.copy2(out / "skills" / "a_nominal" / "policy.pt", out / "skills" / "b_calibrated" / "policy.pt")
    changed, lines = bench()
    res = json.loads(changed)
    assert sum("reused" in x for x in lines) == len(stored) - 4  # (b)'s four deployments ran again
    assert all("b_calibrated" in x and "policy.policy_sha256" in x for x in lines if "deployed again" in x)
    for split in ("validation", "heldout"):
        assert res["real"][split]["b_calibrated"] == res["real"][split]["a_nominal"]
        assert res["real"][split]["b_calibrated"] != json.loads(first)["real"][split]["b_calibrated"]
    assert len(read_ledger(out / "heldout_ledger.jsonl")) == 2


@pytest.mark.slow  # ~2 min on 2 cores: the floor benchmark at the smallest size, twice
def test_a_rerun_floor_benchmark_reads_back_its_deployments_and_scores_the_same(tmp_path, humanoid, data):
    """The floor's rollouts (base, links, failure causes) read back give the same results.json; the balanced held-out
    families' pick (a's validation deployment in its simulator, run again) keeps the same held-out motions."""
    from wresdyn.experiments.deploy_config import FloorDeployConfig
    from wresdyn.experiments.skills import run_benchmark
    from wresdyn.skills.skill_config import SkillPPOConfig

    cal = fit_run(tmp_path, humanoid, data, "torque", physics=True)
    cfg = FloorDeployConfig(iterations=1, finetune=1, num_worlds=2, train_per_family=1, validation_per_family=1,
                            heldout_per_family=1, duration=0.5, device="cpu", nominal=None, screen=False,
                            heldout_families="balanced")
    out, runs = tmp_path / "floor", []
    for _ in range(2):
        lines = []
        run_benchmark(humanoid, data, out, cfg, calibrated=cal, ppo=SkillPPOConfig(torch_threads=1),
                      policies=("a_nominal", "d_oracle"), animation=False, log=lines.append)
        runs.append((_numbers(out), [x for x in lines if "deployed earlier" in x]))
    (first, none), (again, reused) = runs
    stored = list((out / "deployments").rglob("*.npz"))
    assert none == [] and len(stored) == 2 * (3 + 2) - 1  # (a)'s validation run in its simulator is the pick's
    assert again == first and len(reused) == len(stored) and all("reused" in x for x in reused)
    assert "falls" in json.loads(first)["real"]["heldout"]["a_nominal"]["mean"]  # the floor's metrics
    assert len(read_ledger(out / "heldout_ledger.jsonl")) == 1
