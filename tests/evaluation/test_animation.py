"""The side-by-side USD animation of fixed-base rollouts (:mod:`wresdyn.evaluation.animation`)."""

from __future__ import annotations

import numpy as np
import pytest

from wresdyn.evaluation.animation import write_animation

RATE_HZ = 500.0
SAMPLES = 20


def _body_poses(stage, time):
    """World transforms of every visible shape instance the viewer wrote: {prim path: 4x4 matrix}."""
    from pxr import UsdGeom

    poses = {}
    for prim in stage.Traverse():
        if (prim.GetPath().pathString.startswith("/root/model/shapes/") and prim.GetName().startswith("instance_")
                and UsdGeom.Imageable(prim).ComputeVisibility(time) != UsdGeom.Tokens.invisible):
            m = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time)
            poses[prim.GetPath().pathString] = np.array(m, dtype=np.float64)
    return poses


def test_rollouts_side_by_side(humanoid, tmp_path):
    from pxr import Usd

    ramp = np.zeros((SAMPLES, humanoid.n_dof))
    ramp[:, 0] = np.linspace(0.0, 1.0, SAMPLES)
    failed = ramp.copy()
    failed[10:] = np.nan  # a failed rollout holds its last finite pose (sample 9)
    trajectories = {"zeros": np.zeros((SAMPLES, humanoid.n_dof)), "failed": failed, "short": ramp[:10]}
    out = write_animation(humanoid, trajectories, RATE_HZ, tmp_path / "rollouts.usda", fps=50.0, spacing=1.0)
    assert out == tmp_path / "rollouts.usda" and out.is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["rollouts.usda"]  # no temporary file left

    stage = Usd.Stage.Open(str(out))
    assert stage.GetEndTimeCode() > stage.GetStartTimeCode()  # 20 samples at 500 Hz: frames 0 and 1 at 50 fps
    assert list(stage.GetDefaultPrim().GetAttribute("wresdyn:rollouts").Get()) == list(trajectories)

    start, later = _body_poses(stage, 0.0), _body_poses(stage, stage.GetEndTimeCode())
    # robot i of 3 stands at y = i - 1 [m]: tell the shapes apart by their y at the start
    world = {p: int(round(m[3, 1])) + 1 for p, m in start.items()}
    robots = [[p for p in start if world[p] == i] for i in range(3)]
    assert all(len(r) == len(robots[0]) > 1 for r in robots)
    moved = [max(np.abs(later[p] - start[p]).max() for p in r) for r in robots]
    assert moved[0] < 1e-6  # zeros: still
    assert moved[1] > 1e-3  # the ramp on joint 0 moves the robot
    # the NaN tail and the short trajectory both hold sample 9: the same pose, 1 m apart along y
    offset = np.zeros((4, 4))
    offset[3, 1] = 1.0
    for a, b in zip(sorted(robots[1], key=lambda p: tuple(start[p][3])), sorted(robots[2], key=lambda p:
                                                                                   tuple(start[p][3]))):
        np.testing.assert_allclose(later[b], later[a] + offset, atol=1e-5)


def test_wrong_joint_count_raises_and_writes_nothing(humanoid, tmp_path):
    bad = {"ok": np.zeros((SAMPLES, humanoid.n_dof)), "bad": np.zeros((SAMPLES, humanoid.n_dof - 1))}
    with pytest.raises(ValueError) as err:
        write_animation(humanoid, bad, RATE_HZ, tmp_path / "rollouts.usda")
    assert "\n" not in str(err.value) and "'bad'" in str(err.value)
    assert list(tmp_path.iterdir()) == []
