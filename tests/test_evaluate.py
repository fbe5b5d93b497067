"""Open-loop evaluation: PD-only parity with the plain replay, an oracle residual closes the gap, reports."""

import json

import numpy as np
import pytest
import torch
from _tiny_data import DEFAULT_MISMATCH, make_dataset

from wresdyn.evaluation.evaluate import evaluate_split, write_report
from wresdyn.evaluation.plots import plot_fig3
from wresdyn.sim.rollout import replay_trajectories


@pytest.fixture(scope="module")
def data(robot):  # longer than the shared tiny recording, no training split
    return make_dataset(robot, seconds=0.3, counts=(0, 2, 1))


class Oracle(torch.nn.Module):
    """The residual that explains the "real" robot of ``_tiny_data``: gain, damping and friction mismatch
    (friction smoothed with tanh(q̇ / 0.02 rad/s)), from raw [q, q̇, q̈, q_cmd]."""

    def __init__(self, robot, kind):
        super().__init__()
        self.n, self.kind = robot.n_dof, kind
        self.kp, self.kd, self.effort = (torch.tensor(x, dtype=torch.float32) for x in (robot.kp, robot.kd, robot.effort))

    def forward(self, obs):
        m = DEFAULT_MISMATCH
        q, qd, _, cmd = obs.split(self.n, -1)
        tau = ((m["kp_scale"] - 1) * self.kp * (cmd - q) - (m["kd_scale"] - 1) * self.kd * qd
               - m["damping_frac"] * self.effort * qd - m["friction_frac"] * self.effort * torch.tanh(qd / 0.02))
        return tau if self.kind == "torque" else tau / self.kp


def test_pd_only_rollout_is_the_plain_newton_replay(robot, data):
    from wresdyn.sim.rollout import replay

    traj = data.split("heldout")[0]
    for solver in ("replay", "featherstone"):
        out = replay_trajectories(robot, [traj], data.rate_hz, solver=solver)["pd"]
        q, qd = replay(robot, traj.q_cmd[:-1], traj.q[0], traj.qd[0], dt=1.0 / data.rate_hz, solver=solver)
        np.testing.assert_allclose(out.q[0], q, atol=1e-5)
        np.testing.assert_allclose(out.qd[0], qd, atol=1e-4)


@pytest.mark.parametrize("kind", ["torque", "delta_action"])
def test_oracle_residual_closes_most_of_the_gap(robot, data, kind):
    s, runs = evaluate_split(robot, data.split("heldout"), data.rate_hz, Oracle(robot, kind), kind)
    assert s["pd_residual"]["diverged"] == 0
    # the oracle ignores stiction and the real robot's implicit integration: a 3x cut is the bar
    assert s["improvement"] > 3.0, s
    assert len(runs["residual"].q) == 2 and runs["residual"].q[0].shape == data.split("heldout")[0].q.shape


def test_zero_residual_equals_pd_only(robot, data):
    zero = lambda obs: torch.zeros(obs.shape[0], robot.n_dof)  # noqa: E731
    s, _ = evaluate_split(robot, data.split("ood"), data.rate_hz, zero, kind="torque")
    assert s["pd_residual"]["mean_abs_dq"] == pytest.approx(s["pd_only"]["mean_abs_dq"], abs=1e-9)
    assert s["improvement"] == pytest.approx(1.0)


def test_report_files(robot, data, tmp_path):
    results, figs = {}, []
    for split in ("heldout", "ood"):
        s, runs = evaluate_split(robot, data.split(split), data.rate_hz, Oracle(robot, "torque"), kind="torque")
        results[split] = s
        figs.append(plot_fig3(robot, data.split(split)[0], runs, tmp_path / f"fig3_{split}.png", data.rate_hz))
    write_report(tmp_path, robot, results, {"run": "oracle"})
    doc = json.loads((tmp_path / "metrics.json").read_text())
    assert set(doc["splits"]) == {"heldout", "ood"}
    m = doc["splits"]["heldout"]["pd_residual"]
    assert len(m["per_joint_rmse"]) == robot.n_dof and m["mean_abs_dq"] > 0 and m["mean_abs_dqd"] > 0
    report = (tmp_path / "report.md").read_text()
    assert "fig3_heldout.png" in report and "| heldout |" in report
    assert all(f.stat().st_size > 10_000 for f in figs)
