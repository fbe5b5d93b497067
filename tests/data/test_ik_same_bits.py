"""The foot IK gives the same bits as its first, plainer loop (kept here as the reference): the floor motions, the
excitation and the datasets recorded from it depend on every bit of its solutions."""

import numpy as np
import pytest

from wresdyn.data.ik import FootIK
from wresdyn.skills.families import stance


def _reference_solve(ik: FootIK, pos, rot, q_init):
    """The IK's damped least-squares loop as first written: every iterate's error computed at the top of the loop,
    the last one once more after it."""
    pin, cfg = ik._pin, ik.config
    q = np.array(q_init, dtype=np.float64)
    q[ik.dofs] = np.clip(q[ik.dofs], ik.lower[ik.dofs], ik.upper[ik.dofs])
    rows = np.arange(3) if ik.position_only else np.arange(6) if pos is not None else np.arange(3, 6)
    w = np.array([1.0, 1.0, 1.0, cfg.rot_weight, cfg.rot_weight, cfg.rot_weight])
    nf = len(ik.frame_ids)
    for _ in range(cfg.max_iters):
        err = ik._error(q, pos, rot)
        if (np.linalg.norm(err[:, :3], axis=1) < cfg.pos_tol).all() and (
                np.linalg.norm(err[:, 3:], axis=1) < cfg.rot_tol).all():
            break
        pin.computeJointJacobians(ik.model, ik.data, q)
        m = len(rows)
        jac = np.zeros((m * nf, len(ik.dofs)))
        for i, fid in enumerate(ik.frame_ids):
            j = pin.getFrameJacobian(ik.model, ik.data, fid, pin.LOCAL_WORLD_ALIGNED)
            jac[m * i: m * i + m] = (w[:, None] * j[:, ik.dofs])[rows]
        e = (w * err)[:, rows].ravel()
        lam = cfg.damping * float(e @ e) + cfg.damping_floor
        dq = jac.T @ np.linalg.solve(jac @ jac.T + lam * np.eye(m * nf), e)
        q[ik.dofs] = np.clip(q[ik.dofs] + dq, ik.lower[ik.dofs], ik.upper[ik.dofs])
    err = ik._error(q, pos, rot)
    return q, np.stack([np.linalg.norm(err[:, :3], axis=1), np.linalg.norm(err[:, 3:], axis=1)], axis=1)


@pytest.mark.parametrize("position_only", [None, True])
def test_solutions_are_the_reference_loops_bit_for_bit(humanoid, position_only):
    ik = FootIK(humanoid, position_only=position_only)
    q0 = stance(humanoid)
    home, rot = ik.forward(q0)
    rng = np.random.default_rng(0)
    r = None if ik.position_only else rot
    targets = [(home + d, r, q0) for d in np.cumsum(rng.normal(0, 0.004, (40, 2, 3)), 0)]
    # far targets run out of iterations at the joint limits; orientation-only targets use the rotation rows alone
    targets += [(home + rng.normal(0, 0.2, (2, 3)), r, q0) for _ in range(3)]
    if not ik.position_only:
        targets += [(None, rot, q0 + rng.normal(0, 0.1, q0.shape)) for _ in range(3)]
    q = q0
    for pos, target_rot, start in targets:
        start = q if start is q0 and pos is not None else start  # a path: warm-started as solve_path does
        got, want = ik.solve(pos, target_rot, start), _reference_solve(ik, pos, target_rot, start)
        for a, b in zip(got, want):
            assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)
        q = got[0]
