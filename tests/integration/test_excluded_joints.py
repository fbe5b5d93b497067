"""Joints excluded from fitting (a mapping file's [exclude], e.g. the SO-101 gripper) count in no metric and no
loss: the dataset's weights, the evaluation's metrics and report, the validation score, the identification loss
and the PPO rewards. Each test perturbs only the excluded joint (nothing changes) and only a fitted joint (the
figure changes)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from wresdyn.data.dataset import Dataset, DatasetError, Trajectory
from wresdyn.evaluation.open_loop import evaluate_split, metrics, pd_gap, summary_line, write_report
from wresdyn.paths import REPO
from wresdyn.sim.rollout import Replays

SO101 = REPO / "scenes" / "so101" / "so101.xml"
SHIPPED = REPO / "data" / "so101"
GRIPPER, PAN = 5, 0
"""Column of the excluded SO-101 gripper and of a fitted joint (shoulder_pan)."""
SAMPLES = 101
"""Samples of each shipped run kept for the replays here (0.2 s at 500 Hz)."""


def _shifted(tr: Trajectory, joint: int, by: float) -> Trajectory:
    """``tr`` with the recorded position of ``joint`` moved by ``by`` [rad] after the start state (the replay
    starts from sample 0 and follows the commands, so only the comparison changes)."""
    q = tr.q.copy()
    q[1:, joint] += by
    return dataclasses.replace(tr, q=q)


def _assert_window_loss_ignores_the_gripper(loss, train, w) -> None:
    """``loss(trajectories, weights)`` of a window at the start of ``train[0]``: unchanged when only the gripper's
    recording moves, changed when a fitted joint's does, or when the gripper moves and nothing is weighted."""
    base = loss(train, w)
    assert base > 0
    assert loss([_shifted(train[0], GRIPPER, 0.3)], w) == pytest.approx(base, rel=1e-6)
    assert loss([_shifted(train[0], PAN, 0.3)], w) > base + 0.05
    assert loss([_shifted(train[0], GRIPPER, 0.3)], None) > base + 0.05


def _tiny(names, excluded, n=2, T=5, seed=0):
    rng = np.random.default_rng(seed)
    trs = [Trajectory(f"t{i}", "heldout", np.arange(T) / 100.0, *rng.normal(size=(4, T, len(names))))
           for i in range(n)]
    return Dataset(list(names), 100.0, trs, "robot.xml", "0" * 64, meta={"excluded_joints": excluded})


@pytest.fixture(scope="module")
def so101():
    from wresdyn.robot.description import load_robot

    return load_robot(SO101)


@pytest.fixture(scope="module")
def shipped(so101):
    """The shipped SO-101 subset imported with its map and split map, each run cut to :data:`SAMPLES`."""
    from wresdyn.data.importers import SplitRule, import_runs, load_split_map
    from wresdyn.data.logs import LogMap

    ds = import_runs([SHIPPED / "logs"], so101, 500.0, LogMap.load(SHIPPED / "map.toml"),
                     SplitRule("train", tuple(load_split_map(SHIPPED / "splits.toml"))))
    cut = [Trajectory(tr.name, tr.split, tr.t[:SAMPLES], tr.q[:SAMPLES], tr.qd[:SAMPLES], tr.qdd[:SAMPLES],
                      tr.q_cmd[:SAMPLES]) for tr in ds.trajectories]
    return dataclasses.replace(ds, trajectories=cut)


def test_dataset_fit_weights_follow_excluded_joints_by_name():
    ds = _tiny(["a", "b", "c"], ["b"])
    assert ds.excluded_joints == ["b"] and ds.fitted_joints == ["a", "c"]
    np.testing.assert_array_equal(ds.fit_weights(), [1.0, 0.0, 1.0])
    assert _tiny(["a", "b"], []).fit_weights().tolist() == [1.0, 1.0]
    no_meta = dataclasses.replace(_tiny(["a", "b"], []), meta={})
    assert no_meta.excluded_joints == [] and no_meta.fit_weights().tolist() == [1.0, 1.0]

    class Robot:  # the fields for_robot reads: the same joints in another order
        joint_names = ["c", "b", "a"]
        source_sha256 = "0" * 64

    np.testing.assert_array_equal(ds.for_robot(Robot()).fit_weights(), [1.0, 0.0, 1.0])
    for bad, text in ((["x"], "not among the joints"), (["a", "b", "c"], "excludes every joint"),
                      ("b", "must be a list")):
        with pytest.raises(DatasetError, match=text) as e:
            _tiny(["a", "b", "c"], bad).validate("here")
        assert "\n" not in str(e.value)


def test_metrics_ignore_an_excluded_joint():
    ds = _tiny(["a", "b", "c"], ["b"])
    trs = ds.trajectories
    rng = np.random.default_rng(1)
    rep = Replays([tr.q + rng.normal(0, 0.1, tr.q.shape) for tr in trs],
                  [tr.qd + rng.normal(0, 0.1, tr.qd.shape) for tr in trs], [-1, -1])
    w = ds.fit_weights()
    base = metrics(trs, rep, w)
    moved = Replays([q + np.array([0.0, 5.0, 0.0]) for q in rep.q], [qd + np.array([0.0, 5.0, 0.0]) for qd in rep.qd],
                    rep.diverged_at)
    same = metrics(trs, moved, w)
    for f in ("mean_abs_dq", "std_abs_dq", "rmse_dq", "max_abs_dq", "mean_abs_dqd", "rmse_dqd"):
        assert getattr(same, f) == getattr(base, f), f
    assert base.n_joints == 2 and same.per_joint_rmse[1] > 4.0  # the per-joint table still shows it
    assert metrics(trs, moved).mean_abs_dq > base.mean_abs_dq + 1.0  # without weights it counts
    fitted = Replays([q + np.array([0.5, 0.0, 0.0]) for q in rep.q], rep.qd, rep.diverged_at)
    assert metrics(trs, fitted, w).mean_abs_dq > base.mean_abs_dq + 0.1
    with pytest.raises(ValueError, match="exclude every joint"):
        metrics(trs, rep, np.zeros(3))
    with pytest.raises(ValueError, match="3 finite numbers"):
        metrics(trs, rep, np.ones(2))


def test_shipped_so101_evaluation_ignores_the_gripper(so101, shipped, tmp_path):
    assert shipped.excluded_joints == ["gripper"] and so101.joint_names[GRIPPER] == "gripper"
    w = shipped.fit_weights()
    held = shipped.split("heldout")
    base, _ = evaluate_split(so101, held, shipped.rate_hz, weights=w)
    pd = base["pd_only"]
    assert base["excluded_joints"] == ["gripper"] and pd["n_joints"] == 5 and pd["mean_abs_dq"] > 0
    grip, _ = evaluate_split(so101, [_shifted(held[0], GRIPPER, 0.3)], shipped.rate_hz, weights=w)
    assert grip["pd_only"]["mean_abs_dq"] == pd["mean_abs_dq"] and grip["pd_only"]["max_abs_dq"] == pd["max_abs_dq"]
    assert grip["pd_only"]["per_joint_rmse"][GRIPPER] > pd["per_joint_rmse"][GRIPPER] + 0.2
    pan, _ = evaluate_split(so101, [_shifted(held[0], PAN, 0.3)], shipped.rate_hz, weights=w)
    assert pan["pd_only"]["mean_abs_dq"] > pd["mean_abs_dq"] + 0.03
    unweighted, _ = evaluate_split(so101, [_shifted(held[0], GRIPPER, 0.3)], shipped.rate_hz)
    assert unweighted["pd_only"]["mean_abs_dq"] > pd["mean_abs_dq"] + 0.03 and unweighted["excluded_joints"] == []
    # the gap collect reports, the terminal line and the report say which joints were left out
    gap = pd_gap(so101, held, shipped.rate_hz, weights=w)
    assert gap["mean"] == pytest.approx(pd["mean_abs_dq"]) and gap["excluded_joints"] == ["gripper"]
    assert pd_gap(so101, [_shifted(held[0], GRIPPER, 0.3)], shipped.rate_hz, weights=w)["mean"] == gap["mean"]
    assert "over 5 fitted joints; excluded: gripper" in summary_line("heldout", base)
    report = write_report(tmp_path, so101, {"heldout": base}).read_text()
    assert "excluded from fitting and from these figures: gripper" in report and "| gripper (excluded) |" in report


def test_validation_score_ignores_the_gripper(so101, shipped):
    from wresdyn.learn.selection import ValidationScore

    val = shipped.split("validation")
    w = shipped.fit_weights()
    base = ValidationScore(so101, val, shipped.rate_hz, weights=w)()
    assert base > 0
    assert ValidationScore(so101, [_shifted(val[0], GRIPPER, 0.3)], shipped.rate_hz, weights=w)() == base
    assert ValidationScore(so101, [_shifted(val[0], PAN, 0.3)], shipped.rate_hz, weights=w)() > base + 0.03
    assert ValidationScore(so101, [_shifted(val[0], GRIPPER, 0.3)], shipped.rate_hz)() > base + 0.03


def test_identification_loss_ignores_the_gripper(so101, shipped):
    from wresdyn.identify.sysid import SysIdConfig, physics_window_loss
    from wresdyn.sim import Simulator, TrajectoryBank
    from wresdyn.sim.physics import PhysicsModel

    cfg = SysIdConfig()
    train = shipped.split("train")
    sim = Simulator(so101, 1, 1.0 / shipped.rate_hz, requires_grad=True, param_grads=True)
    model = PhysicsModel(so101, dt=1.0 / shipped.rate_hz)
    w = torch.as_tensor(shipped.fit_weights(), dtype=torch.float32)

    def loss(trs, weights):
        window = TrajectoryBank(trs, sim.device).window(torch.tensor([0]), torch.tensor([0]), 16)
        value, _ = physics_window_loss(cfg, model, sim, window, weights)
        return float(value.detach())

    _assert_window_loss_ignores_the_gripper(loss, train, w)


def test_rewards_ignore_an_excluded_joint():
    from wresdyn.ppo.rewards import RewardConfig, reward_terms

    g = torch.Generator().manual_seed(0)
    n, w = 4, torch.tensor([1.0, 1.0, 0.0, 1.0])
    q_r, qd_r = torch.randn(8, n, generator=g), torch.randn(8, n, generator=g)
    q, qd = q_r + 0.05 * torch.randn(8, n, generator=g), qd_r + 0.5 * torch.randn(8, n, generator=g)
    q[:2] = q_r[:2]  # some worlds match exactly: the bonus fires
    rest = [torch.randn(8, n, generator=g) for _ in range(5)]  # qdd, tau, a, a_prev, a_prev2
    cfg = RewardConfig()

    def terms(q, qd, weights):
        return reward_terms(cfg, q, qd, rest[0], q_r, qd_r, rest[1], *rest[2:], weights=weights)

    base = terms(q, qd, w)
    off = torch.zeros(n)
    off[2] = 0.4
    moved = terms(q + off, qd + 10 * off, w)
    for k in ("joint_pos_mimic", "joint_vel_mimic", "joint_pos_bonus"):  # the terms that compare with the recording
        torch.testing.assert_close(moved[k], base[k], rtol=0, atol=0, msg=k)
    assert not torch.equal(moved["joint_vel"], base["joint_vel"])  # regularisers keep every joint (documented)
    assert (base["joint_pos_bonus"][:2] == cfg.joint_pos_bonus).all()  # a w-weighted mean: 1 when all fitted match
    unweighted = terms(q + off, qd + 10 * off, None)
    assert (unweighted["joint_pos_mimic"] < base["joint_pos_mimic"]).all()
    assert (unweighted["joint_pos_bonus"][:2] < cfg.joint_pos_bonus).all()
    fitted = torch.zeros(n)
    fitted[0] = 0.4
    assert (terms(q + fitted, qd, w)["joint_pos_mimic"] < base["joint_pos_mimic"]).all()
    assert torch.equal(terms(q, qd, torch.ones(n))["joint_pos_mimic"], terms(q, qd, None)["joint_pos_mimic"])


def test_gradient_fit_loss_ignores_the_gripper(so101, shipped):
    from wresdyn.fit.gradfit import GradFitConfig, build_policy, window_loss
    from wresdyn.learn.residual import obs_stats
    from wresdyn.sim import Simulator, TrajectoryBank, rollout

    cfg = GradFitConfig()
    train = shipped.split("train")
    sim = Simulator(so101, 1, 1.0 / shipped.rate_hz, requires_grad=True)
    policy = build_policy(so101, cfg.residual, *obs_stats(train))
    w = torch.as_tensor(shipped.fit_weights(), dtype=torch.float32)

    def loss(trs, weights):
        window = TrajectoryBank(trs, sim.device).window(torch.tensor([0]), torch.tensor([0]), 16)
        run = rollout(sim, window, policy, grad=True)
        value, _ = window_loss(cfg, run.q[:, 1:], run.qd[:, 1:], run.actions, window.q[:, 1:], window.qd[:, 1:],
                               policy.scale, weights)
        return float(value.detach())

    _assert_window_loss_ignores_the_gripper(loss, train, w)


def test_ppo_environment_ignores_the_gripper(so101, shipped):
    from wresdyn.ppo.replay_env import ReplayEnv, ReplayEnvConfig

    train = shipped.split("train")

    def step(joint, weights):
        """One zero-residual step after the recording's ``joint`` is moved by 0.3 rad (the start states, drawn at
        construction with the same seed, are the same in every call)."""
        env = ReplayEnv(so101, train, shipped.rate_hz, 4, ReplayEnvConfig(horizon=50), seed=0, weights=weights)
        if joint is not None:
            env.bank.q[:, joint] += 0.3
        _, reward, _, extras = env.step(torch.zeros(4, so101.n_dof))
        return reward, float(extras["log"]["Error/mean_abs_dq"])

    w = shipped.fit_weights()
    r0, e0 = step(None, w)
    r1, e1 = step(GRIPPER, w)
    torch.testing.assert_close(r1, r0, rtol=0, atol=0)
    assert e1 == e0
    r2, e2 = step(PAN, w)
    assert (r2 < r0).all() and e2 > e0 + 0.05
    r3, _ = step(GRIPPER, None)
    assert (r3 < r0).all()
