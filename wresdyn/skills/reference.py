"""The reference a tracking environment plays, at the policy rate: motions (:mod:`.motions`) as padded tensors, where
each world starts in them, and the quaternion geometry of a floating base's reference and its IMU.

The quaternions are Newton's ``[qx qy qz qw]``; the IMU is ideal (a plant with one of its own, the real robot's, adds
its noise: :meth:`~.plants.RealPlant.imu`).
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["motion_tensors", "start_points", "quat_rotate_inv", "base_frame_imu", "quat_angle", "tilt", "plant_dt"]


def motion_tensors(motions, decimation: int, ahead: int, device) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
    """Motions at the policy rate, padded by ``ahead`` steps (positions with their last sample, velocities with
    zeros), and the policy steps of each motion (M,) long.

    Every motion gives joints ``q`` (M, W, n) [rad] and ``qd`` (M, W, n) [rad/s]; motions on the floor (with a
    ``base``) also the base pose ``base`` (M, W, 7), its displacement per sample period ``base_v`` (M, W, 3) [m] and
    the planted soles ``planted`` (M, W, 2) bool.
    """
    k = [(len(m.q) - 1) // decimation for m in motions]
    width = max(k) + 1 + ahead
    n = motions[0].q.shape[1]
    floor = motions[0].base is not None
    out = {"q": np.empty((len(motions), width, n)), "qd": np.zeros((len(motions), width, n))}
    if floor:
        out.update(base=np.empty((len(motions), width, 7)), base_v=np.zeros((len(motions), width, 3)),
                   planted=np.ones((len(motions), width, 2)))
    for i, m in enumerate(motions):
        src = {"q": m.q, "qd": m.qd}
        if floor:
            src.update(base=m.base, base_v=np.gradient(m.base[:, :3], axis=0), planted=m.planted)  # per sample period
        for key, x in src.items():
            sub = x[::decimation][:k[i] + 1]
            out[key][i, :len(sub)] = sub
            out[key][i, len(sub):] = 0.0 if key in ("qd", "base_v") else sub[-1]
    f = dict(dtype=torch.float32, device=device)
    ref = {key: torch.as_tensor(v, **f) for key, v in out.items()}
    if floor:
        ref["planted"] = ref["planted"] > 0.5
    return ref, torch.as_tensor(k, dtype=torch.long, device=device)


def start_points(ids: torch.Tensor, ref_len: torch.Tensor, random_start: bool, gen: torch.Generator, device
                 ) -> tuple[torch.Tensor, torch.Tensor]:
    """Motion and policy step each reset world of ``ids`` starts from: drawn at random (``random_start``, from
    ``gen`` on ``device``: a motion, then a step below its length ``ref_len``) or in turn, each motion from its
    start."""
    if random_start:
        m = torch.randint(len(ref_len), (len(ids),), generator=gen, device=device)
        t = (torch.rand(len(ids), generator=gen, device=device) * ref_len[m]).long()
    else:
        m, t = ids % len(ref_len), torch.zeros_like(ids)
    return m, t


def quat_rotate_inv(quat_xyzw: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate world vectors ``v`` (N, 3) into the frame of unit quaternions ``quat_xyzw`` (N, 4)."""
    xyz, w = quat_xyzw[:, :3], quat_xyzw[:, 3:4]
    t = 2.0 * torch.cross(xyz, v, dim=-1)
    return v - w * t + torch.cross(xyz, t, dim=-1)


def base_frame_imu(base_pose: torch.Tensor, base_twist: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """An ideal IMU on the base: angular velocity [rad/s] and the unit gravity direction (z down), in base axes."""
    down = torch.zeros_like(base_pose[:, :3])
    down[:, 2] = -1.0
    quat = base_pose[:, 3:]
    return quat_rotate_inv(quat, base_twist[:, 3:]), quat_rotate_inv(quat, down)


def quat_angle(qa: torch.Tensor, qb: torch.Tensor) -> torch.Tensor:
    """Rotation angle between unit quaternions (N, 4) [rad]."""
    return 2.0 * torch.acos((qa * qb).sum(-1).abs().clamp(max=1.0))


def tilt(quat: torch.Tensor) -> torch.Tensor:
    """Angle between the base's up axis and the world's [rad]."""
    x, y = quat[:, 0], quat[:, 1]
    return torch.acos((1.0 - 2.0 * (x * x + y * y)).clamp(-1.0, 1.0))


def plant_dt(plant) -> float:
    """The sample period of a plant [s]."""
    dt = getattr(plant, "dt", None)
    if dt is not None:
        return float(dt)
    return 1.0 / float(plant.real.rate_hz)
