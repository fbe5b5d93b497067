"""The fit's validation and checkpoints made cheaper without changing a number: a validation score keeps its replay's
set-up (the simulator's physics, the recordings on the device) across checks and scores exactly as a fresh replay,
for fixed physics (the gradient fit) and for physics changing at every check (identification); a checkpoint written
on a thread holds exactly what the written-in-place one does."""

import dataclasses

import numpy as np
import pytest
import torch

from wresdyn.fit.gradfit import GradFitConfig, build_policy
from wresdyn.learn.residual import ResidualConfig, obs_stats
from wresdyn.learn.runs import RunFolder, load_checkpoint
from wresdyn.learn.selection import ValidationScore
from wresdyn.sim.physics import PhysicalParams
from wresdyn.sim.rollout import replay_trajectories


def _error(score, trajectories, runs) -> float:
    rep = runs["residual"] if "residual" in runs else runs["pd"]
    return float(np.concatenate([np.abs(q - t.q) for t, q in zip(trajectories, rep.q)])[:, score.mask].mean())


def _physics(robot, scale: float) -> PhysicalParams:
    p = PhysicalParams.nominal(robot)
    return dataclasses.replace(p, kp=p.kp * scale, damping=p.damping + 0.01 * scale, delay=p.delay + 0.004 * scale)


def test_kept_set_up_scores_as_a_fresh_replay(quadruped, record, shipped_mismatch):
    data = record(quadruped, shipped_mismatch, {"train": 1, "validation": 2}, seconds=0.3, amplitude=0.4)
    val = data.split("validation")
    physics = _physics(quadruped, 0.9)
    score = ValidationScore(quadruped, val, data.rate_hz, physics=physics)
    policy = build_policy(quadruped, ResidualConfig(hidden_dims=(16,)), *obs_stats(data.split("train")))
    for step in range(3):  # the policy changes between checks, the set-up is kept
        with torch.no_grad():
            for w in policy.parameters():
                w.add_(0.05 * torch.randn_like(w))
        got = score(policy)
        fresh = _error(score, val, replay_trajectories(quadruped, val, data.rate_hz, policy.eval(), physics=physics))
        policy.train()
        assert got == fresh, (step, got, fresh)  # bit for bit
    assert score._setup is not None


def test_changing_physics_score_as_fresh_replays(quadruped, record, shipped_mismatch):
    data = record(quadruped, shipped_mismatch, {"train": 1, "validation": 2}, seconds=0.3, amplitude=0.4)
    val = data.split("validation")
    score = ValidationScore(quadruped, val, data.rate_hz)  # identification's use: physics set before each call
    values = []
    for scale in (0.8, 1.2, 1.2, 0.8):  # changed, the same again (the profile kept), changed back
        score.physics = _physics(quadruped, scale)
        got = score()
        fresh = _error(score, val, replay_trajectories(quadruped, val, data.rate_hz, physics=score.physics))
        assert got == fresh, (scale, got, fresh)
        values.append(got)
    assert values[0] != values[1] and values[0] == values[3] and values[1] == values[2]


def test_checkpoint_written_on_a_thread_holds_the_same(quadruped, record, shipped_mismatch, tmp_path):
    data = record(quadruped, shipped_mismatch, {"train": 1}, seconds=0.2, amplitude=0.4)
    policy = build_policy(quadruped, ResidualConfig(hidden_dims=(16,)), *obs_stats(data.split("train")))
    cfg = dataclasses.asdict(GradFitConfig())
    files = {}
    for mode in ("inline", "thread"):
        run = RunFolder(tmp_path / mode, cfg)
        run.curve = [{"iteration": i + 1, "wall": 0.1 * i, "loss": 1.0 / (i + 1)} for i in range(50)]
        run.best.take(0.5, 3, policy)
        state = {"policy": policy.state_dict()}
        run.save(state, background=mode == "thread", rng={"state": 7})
        if mode == "thread":
            with torch.no_grad():  # training goes on while the thread writes: the checkpoint keeps the saved iterate
                for w in policy.parameters():
                    w.add_(1.0)
            run.curve.append({"iteration": 51, "wall": 5.0, "loss": 0.0})
            run.flush()
        files[mode] = load_checkpoint(run.checkpoint, keys=("policy", "best", "meta"))
    a, b = files["inline"], files["thread"]
    assert a["meta"] == b["meta"] and len(b["meta"]["curve"]) == 50
    for part in ("policy", "best"):
        assert a[part].keys() == b[part].keys()
        assert all(torch.equal(a[part][k], b[part][k]) for k in a[part])


def test_a_failed_background_write_is_raised_by_flush(tmp_path):
    run = RunFolder(tmp_path / "run", {"x": 1})
    run.save({"bad": object()}, background=True)  # refused by the weights-only check, on the writer thread
    with pytest.raises(TypeError, match="more than tensors"):
        run.flush()
    run.flush()  # raised once
    assert not run.checkpoint.exists()
