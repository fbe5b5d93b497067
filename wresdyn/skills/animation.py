"""USD animations of rollouts (on the stand or on the floor), side by side: one robot per rollout, in one file.

Each rollout is a joint-position trajectory sampled at ``rate_hz``; every one is played on its own copy of the robot
(one Newton world each), the copies placed ``spacing`` metres apart along the world y axis by the viewer's own world
offsets (:meth:`newton.viewer.ViewerUSD.set_world_offsets`), and the bodies' poses are written by
:class:`newton.viewer.ViewerUSD` through forward kinematics, at the animation's frame rate. Open the file in any USD
viewer (``usdview``, Omniverse, Blender) to compare the rollouts.
"""

from __future__ import annotations

import math
import os
import uuid
from pathlib import Path

import numpy as np

from ..choices import check_number
from ..errors import WresdynError
from ..robot.description import Robot

__all__ = ["write_animation"]

_USD_SUFFIXES = (".usd", ".usda", ".usdc")
"""File extensions a USD layer can be written to (the extension picks the format)."""


def write_animation(robot: Robot, trajectories: dict[str, np.ndarray], rate_hz: float, path, fps: float = 50.0,
                    spacing: float = 1.0) -> Path:
    """Write a USD animation of rollouts side by side: on the stand (a fixed base), or on a floor (a floating base:
    each row is the base pose [x y z qx qy qz qw] followed by the joint positions, and the floor is drawn).

    One robot per entry of ``trajectories``, in the given order, placed ``spacing`` metres apart along the world y
    axis: rollout ``i`` of ``n`` is offset by ``(i - (n - 1) / 2) * spacing`` [m] (the row is centred on the origin;
    Newton's :meth:`~newton.viewer.ViewerUSD.set_world_offsets`). Frame ``f`` (time ``f / fps`` [s]) shows the
    sample nearest in time, ``round(f * rate_hz / fps)``; a trajectory shorter than the longest holds its last
    pose, and a row with a non-finite value (a failed rollout) holds the last finite pose (the neutral pose
    :attr:`Robot.q0` if none came before). The names of the rollouts, in order, are the string array
    ``wresdyn:rollouts`` on the stage's default prim (``/root``), the spacing [m] its ``wresdyn:spacing``.

    The file is written to a temporary file next to ``path`` and renamed into place: nothing half-written is
    left on error.

    Args:
        robot: The robot, fixed or floating base.
        trajectories: Rollout name -> joint positions [rad or m], shape (T, n_dof) in ``robot.joint_names`` order
            (a floating base: (T, 7 + n_dof), the base pose first),
            sample ``k`` at time ``k / rate_hz`` [s]; ``T >= 1`` may differ between rollouts.
        rate_hz: Sample rate of the trajectories [Hz].
        path: USD file to write (``.usd``, ``.usda`` or ``.usdc``); its folder is created if missing.
        fps: Frame rate of the animation [frames/s].
        spacing: Distance between neighbouring robots along the world y axis [m].

    Returns:
        The path written.

    Raises:
        WresdynError: (a :class:`ValueError`, one line) no rollouts, a trajectory of the wrong shape, a non-positive rate or frame rate, or a file name that is not a USD layer.
    """
    path = Path(path)
    floating = robot.base == "floating"
    width = robot.n_dof + (7 if floating else 0)
    check_number(rate_hz, "rate_hz", gt=0.0)
    check_number(fps, "fps", gt=0.0)
    check_number(spacing, "spacing")
    if path.suffix.lower() not in _USD_SUFFIXES:
        raise WresdynError(f"{path}: an animation is a USD file; name it .usd, .usda or .usdc")
    if not isinstance(trajectories, dict) or not trajectories:
        raise WresdynError("write_animation needs at least one trajectory (a dict name -> joint positions)")
    names = [str(name) for name in trajectories]
    held = []
    for name, q in trajectories.items():
        q = np.asarray(q, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != width or q.shape[0] < 1:
            raise WresdynError(f"trajectory {name!r} has shape {q.shape}; {robot.source.name} needs (T >= 1, "
                               f"{width}) {'base poses and ' if floating else ''}joint positions")
        neutral = np.concatenate([[0, 0, 0, 0, 0, 0, 1.0], robot.q0]) if floating else robot.q0
        held.append(_hold_finite(q, neutral))

    n_samples = max(len(q) for q in held)
    n_frames = int(math.floor((n_samples - 1) / rate_hz * fps + 1e-6)) + 1
    frames = np.arange(n_frames)
    poses = np.stack([q[np.minimum(np.rint(frames * rate_hz / fps).astype(int), len(q) - 1)] for q in held],
                     axis=1)  # (n_frames, n_worlds, n_dof)

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{uuid.uuid4().hex[:12]}.tmp{path.suffix}")
    try:
        _write(robot, poses, names, tmp, fps, spacing)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    from pxr import Sdf

    layer = Sdf.Layer.Find(str(path.resolve()))
    if layer is not None:  # a stage of this process still holds the file's former content
        layer.Reload(force=True)
    return path


def _hold_finite(q: np.ndarray, neutral: np.ndarray) -> np.ndarray:
    """``q`` with every row holding a non-finite value replaced by the last finite row before it (``neutral``
    before the first), shape (T, n_dof) [rad or m]."""
    out = q.copy()
    last = np.asarray(neutral, dtype=np.float64)
    for k in range(len(out)):
        if np.isfinite(out[k]).all():
            last = out[k]
        else:
            out[k] = last
    return out


def _write(robot: Robot, poses: np.ndarray, names: list[str], out: Path, fps: float, spacing: float) -> None:
    """Play ``poses`` (joint positions [rad or m], shape (n_frames, n_worlds, n_dof), frame ``f`` at ``f / fps``
    [s]) on ``n_worlds`` copies of the robot and save the animation to ``out``."""
    import newton
    from pxr import Sdf

    n_frames, n_worlds, _ = poses.shape
    floating = robot.base == "floating"
    model = robot.build_model(n_worlds, device="cpu", ground=floating)
    state = model.state()
    q = model.joint_q.numpy().reshape(n_worlds, -1).copy()  # per-world joint_q: default coordinates of every joint
    viewer = newton.viewer.ViewerUSD(output_path=str(out), fps=fps, num_frames=None)
    viewer.set_model(model)
    viewer.set_world_offsets((0.0, float(spacing), 0.0))
    flags = model.shape_flags.numpy()
    visual = (flags & int(newton.ShapeFlags.VISIBLE)) != 0
    visual &= (flags & int(newton.ShapeFlags.SITE)) == 0
    if not visual.any():  # a robot of collision shapes only (and sites): draw those, else nothing but sites shows
        viewer.show_collision = True
    root = viewer.stage.GetDefaultPrim()
    root.CreateAttribute("wresdyn:rollouts", Sdf.ValueTypeNames.StringArray, custom=True).Set(names)
    root.CreateAttribute("wresdyn:spacing", Sdf.ValueTypeNames.Double, custom=True).Set(float(spacing))
    for f in range(n_frames):
        if floating:
            from ..robot.ground import base_index

            b = base_index(robot)[0]
            q[:, b:b + 7], q[:, robot.q_index] = poses[f][:, :7], poses[f][:, 7:]
        else:
            q[:, robot.q_index] = poses[f]
        state.joint_q.assign(q.reshape(-1).astype(np.float32))
        newton.eval_fk(model, state.joint_q, state.joint_qd, state)
        viewer.begin_frame(f / fps)
        viewer.log_state(state)
        viewer.end_frame()
    viewer.close()
