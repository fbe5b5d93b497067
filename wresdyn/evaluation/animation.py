"""USD animations of rollouts (on the stand or on the floor), side by side: one robot per rollout, in one file.

Each rollout is a joint-position trajectory sampled at ``rate_hz``; every one is played on its own copy of the robot
(one Newton world each), the copies placed ``spacing`` metres apart along the world y axis by the viewer's own world
offsets (:meth:`newton.viewer.ViewerUSD.set_world_offsets`), and the bodies' poses are written by
:class:`newton.viewer.ViewerUSD` through forward kinematics, at the animation's frame rate. Open the file in any USD
viewer (``usdview``, Omniverse, Blender) to compare the rollouts.
"""

from __future__ import annotations

import json
import math
import os
import uuid
from pathlib import Path

import numpy as np

from ..choices import check_number
from ..errors import WresdynError
from ..robot.description import Robot
from ..robot.ground import base_index

__all__ = ["RobotRow", "sample_frames", "write_animation"]

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
    ``wresdyn:rollouts`` on the stage's default prim (``/root``), the spacing [m] its ``wresdyn:spacing``; the
    frames themselves its ``wresdyn:poses`` (flattened, shape ``wresdyn:posesShape`` = (n_frames, n_rollouts,
    width)), with ``wresdyn:robotFile``, ``wresdyn:base`` and ``wresdyn:gains`` (JSON) to rebuild the robot from
    (:func:`wresdyn.evaluation.viewer.animation_rollouts` reads them back).

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
    check_number(spacing, "spacing")
    if path.suffix.lower() not in _USD_SUFFIXES:
        raise WresdynError(f"{path}: an animation is a USD file; name it .usd, .usda or .usdc")
    names, poses = sample_frames(robot, trajectories, rate_hz, fps)

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


def sample_frames(robot: Robot, trajectories: dict[str, np.ndarray], rate_hz: float, fps: float
                  ) -> tuple[list[str], np.ndarray]:
    """The rollouts' poses at a viewer's frame rate: frame ``f`` (time ``f / fps`` [s]) holds the sample nearest in
    time, ``round(f * rate_hz / fps)``, a shorter trajectory its last sample, a non-finite row the last finite one
    (:func:`write_animation` states the rules; ``trajectories`` and ``rate_hz`` as there).

    Returns:
        ``(names, poses)``: the rollouts' names in order and their poses, shape (n_frames, n_rollouts, width)
        [rad or m] (width: ``n_dof``, or ``7 + n_dof`` for a floating base).
    """
    floating = robot.base == "floating"
    width = robot.n_dof + (7 if floating else 0)
    check_number(rate_hz, "rate_hz", gt=0.0)
    check_number(fps, "fps", gt=0.0)
    if not isinstance(trajectories, dict) or not trajectories:
        raise WresdynError("an animation needs at least one trajectory (a dict name -> joint positions)")
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
    poses = np.stack([q[np.minimum(np.rint(frames * rate_hz / fps).astype(int), len(q) - 1)] for q in held], axis=1)
    return [str(name) for name in trajectories], poses


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
    """Play ``poses`` (joint positions [rad or m], shape (n_frames, num_worlds, n_dof), frame ``f`` at ``f / fps``
    [s]) on ``num_worlds`` copies of the robot and save the animation to ``out``."""
    import newton
    from pxr import Sdf

    n_frames, num_worlds, _ = poses.shape
    row = RobotRow(robot, num_worlds)
    viewer = newton.viewer.ViewerUSD(output_path=str(out), fps=fps, num_frames=None)
    row.attach(viewer, spacing)
    root = viewer.stage.GetDefaultPrim()
    root.CreateAttribute("wresdyn:rollouts", Sdf.ValueTypeNames.StringArray, custom=True).Set(names)
    root.CreateAttribute("wresdyn:spacing", Sdf.ValueTypeNames.Double, custom=True).Set(float(spacing))
    # the frames as joint positions too, so `wresdyn view` replays them on the robot file in the browser
    root.CreateAttribute("wresdyn:robotFile", Sdf.ValueTypeNames.String, custom=True).Set(str(robot.source))
    root.CreateAttribute("wresdyn:base", Sdf.ValueTypeNames.Token, custom=True).Set(robot.base)
    if robot.gains is not None:
        root.CreateAttribute("wresdyn:gains", Sdf.ValueTypeNames.String, custom=True).Set(json.dumps(robot.gains))
    root.CreateAttribute("wresdyn:poses", Sdf.ValueTypeNames.DoubleArray, custom=True).Set(
        poses.reshape(-1).tolist())
    root.CreateAttribute("wresdyn:posesShape", Sdf.ValueTypeNames.IntArray, custom=True).Set(list(poses.shape))
    for f in range(n_frames):
        viewer.begin_frame(f / fps)
        viewer.log_state(row.pose(poses[f]))
        viewer.end_frame()
    viewer.close()


class RobotRow:
    """``num_worlds`` copies of ``robot`` (one Newton world each, on the CPU), posed by joint positions through
    forward kinematics (``newton.eval_fk``), for a Newton viewer to draw side by side: the USD animation here and
    the browser viewer (:mod:`wresdyn.evaluation.viewer`) share it.

    A floating base gets a ground plane; ``pose`` then takes the base pose [x y z qx qy qz qw] before the joints.
    """

    def __init__(self, robot: Robot, num_worlds: int) -> None:
        self.robot, self.num_worlds = robot, int(num_worlds)
        self.floating = robot.base == "floating"
        self.model = robot.build_model(self.num_worlds, device="cpu", ground=self.floating)
        self.state = self.model.state()
        # per-world joint_q: the default coordinates of every joint, the robot's own written over them per pose
        self._q = self.model.joint_q.numpy().reshape(self.num_worlds, -1).copy()

    def attach(self, viewer, spacing: float) -> None:
        """Give ``viewer`` the model, the worlds ``spacing`` [m] apart along +y (centred on the origin), and the
        shapes to draw: the visual ones, or the collision shapes of a robot that has no visual shape but sites."""
        import newton

        viewer.set_model(self.model)
        viewer.set_world_offsets((0.0, float(spacing), 0.0))
        flags = self.model.shape_flags.numpy()
        visual = (flags & int(newton.ShapeFlags.VISIBLE)) != 0
        visual &= (flags & int(newton.ShapeFlags.SITE)) == 0
        if not visual.any():
            viewer.show_collision = True

    def pose(self, rows: np.ndarray):
        """The state (body poses filled by forward kinematics) of world ``i`` at ``rows[i]``: joint positions
        [rad or m] in ``robot.joint_names`` order, shape (num_worlds, n_dof) (floating base: (num_worlds, 7 + n_dof),
        the base pose first)."""
        import newton

        rows = np.asarray(rows, dtype=np.float64)
        if self.floating:
            b = base_index(self.robot)[0]
            self._q[:, b:b + 7], self._q[:, self.robot.q_index] = rows[:, :7], rows[:, 7:]
        else:
            self._q[:, self.robot.q_index] = rows
        self.state.joint_q.assign(self._q.reshape(-1).astype(np.float32))
        newton.eval_fk(self.model, self.state.joint_q, self.state.joint_qd, self.state)
        return self.state
