"""The evaluation in the browser: ``wresdyn view RUN`` plays rollouts side by side in an interactive 3-D page.

A ``wresdyn fit``/``train``/``identify`` run folder shows one recording of a split (held-out by default) three
times, as :func:`~wresdyn.evaluation.open_loop.evaluate_split` replays it for ``wresdyn eval``: the real robot (the
recording, red), the simulator with PD alone (green) and the calibrated robot (the run's physics and residual,
blue). A ``wresdyn deploy`` output folder shows its ``deployed_heldout.usda`` (the skills deployed on the real
robot, :func:`wresdyn.evaluation.animation.write_animation`), from the joint positions stored in it.

The page is Newton's :class:`newton.viewer.ViewerViser` (a `viser <https://viser.studio>`_ server): the robots are
one Newton world each, posed by forward kinematics (:class:`~wresdyn.evaluation.animation.RobotRow`, shared with the USD
animation); viser's own GUI adds a time slider, play/pause and a plot per joint of the rollouts' positions.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data.loading import load_data
from ..errors import WresdynError
from ..robot.description import load_robot
from .animation import RobotRow, sample_frames
from .evaluate_run import load_run_model, run_friction_kappa
from .open_loop import evaluate_split

__all__ = ["ViewerConfig", "Scene", "run_scene", "animation_scene", "load_scene", "serve"]

FIT_COLOURS = {"real": (0.85, 0.15, 0.15), "PD only": (0.15, 0.65, 0.2), "calibrated": (0.15, 0.35, 0.9)}
"""Tint of each robot of a run's scene, as in the Fig. 3 plots of ``wresdyn eval`` (red, green, blue)."""
PALETTE = ((0.85, 0.15, 0.15), (0.15, 0.65, 0.2), (0.15, 0.35, 0.9), (0.9, 0.6, 0.1), (0.6, 0.2, 0.8),
           (0.1, 0.7, 0.7))
"""Tints of the rollouts of a deploy folder's animation, in order (repeating)."""


@dataclass(frozen=True)
class ViewerConfig:
    """Where and how ``wresdyn view`` serves its page."""

    host: str = "127.0.0.1"
    """Address the server binds to: the loopback address keeps the page on this machine; ``0.0.0.0`` shares it
    with the network."""
    port: int = 8080
    """TCP port of the page (viser takes the next free one if it is in use)."""
    seconds: float | None = None
    """Stop serving after this many seconds [s] (tests, scripted screenshots); ``None``: until Ctrl-C."""
    fps: float = 50.0
    """Frame rate the rollouts are resampled to and played at [frames/s]."""
    spacing: float = 0.6
    """Distance between neighbouring robots along the world y axis [m]."""
    plot_joints: int = 4
    """Joints plotted (those whose rollouts differ most first)."""


@dataclass(frozen=True)
class Scene:
    """Rollouts of one robot to play side by side."""

    robot: object
    """The :class:`~wresdyn.robot.description.Robot` (fixed base, or floating: poses start with the base pose)."""
    names: list
    """Rollout names, one robot each, in order along +y."""
    poses: np.ndarray
    """Joint positions per frame [rad or m], shape (n_frames, n_rollouts, width) (width ``n_dof``, or
    ``7 + n_dof`` with the base pose [x y z qx qy qz qw] first)."""
    fps: float
    """Frame rate of ``poses`` [frames/s]."""
    colours: tuple
    """RGB tint in [0, 1] of each rollout's robot."""
    title: str
    """What is shown, one line (the page's heading)."""
    spacing: float | None = None
    """Distance between neighbouring robots along +y [m] the rollouts were written with (an animation's
    ``wresdyn:spacing``); ``None``: :attr:`ViewerConfig.spacing`."""


def run_scene(run, split: str = "heldout", index: int = 0, data: str | None = None, fps: float = 50.0,
              device: str = "cpu") -> Scene:
    """The scene of a run folder: trajectory ``index`` of ``split`` as recorded, replayed with PD alone and with
    the run's calibrated model (its ``physics.json`` and residual), open loop from the first recorded state."""

    run = Path(run)
    cfg_path = run / "config.json"
    if not cfg_path.is_file():
        raise WresdynError(f"{run}: not a run folder (no config.json) nor a deploy folder (no deployed_heldout.usda)")
    data = data or json.loads(cfg_path.read_text()).get("data_path")
    if not data:
        raise WresdynError(f"{run}: the run does not record its dataset; pass --data")
    ds, robot = load_data(data)
    trajs = ds.split(split)
    if not 0 <= index < len(trajs):
        raise WresdynError(f"{data}: split {split!r} has {len(trajs)} trajectories; no index {index}")
    traj = trajs[index]
    policy, meta, physics, solver, substeps = load_run_model(run, robot, ds.rate_hz)
    summary, runs = evaluate_split(robot, [traj], ds.rate_hz, policy, meta["kind"], solver, substeps, device,
                                   physics=physics, weights=ds.fit_weights(), friction_kappa=run_friction_kappa(run))
    rollouts = {"real": traj.q, "PD only": runs["pd"].q[0]}
    title = f"{split} {traj.name} ({run.name}): mean |dq| to the real robot, PD only " \
            f"{summary['pd_only']['mean_abs_dq']:.4f} rad"
    if "residual" in runs:
        rollouts["calibrated"] = runs["residual"].q[0]
        title += f", calibrated {summary['pd_residual']['mean_abs_dq']:.4f} rad"
    names, poses = sample_frames(robot, rollouts, ds.rate_hz, fps)
    return Scene(robot, names, poses, fps, tuple(FIT_COLOURS[n] for n in names), title)


def animation_scene(path) -> Scene:
    """The scene of a USD animation written by :func:`~wresdyn.evaluation.animation.write_animation` (e.g. a deploy
    folder's ``deployed_heldout.usda``), from the joint positions and robot file stored on its default prim."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    root = stage.GetDefaultPrim()
    attr = root.GetAttribute("wresdyn:poses") if root else None
    if not attr or not attr.HasValue():
        raise WresdynError(f"{path}: holds no wresdyn:poses (written by an older wresdyn); rerun the deploy to view it")
    shape = tuple(root.GetAttribute("wresdyn:posesShape").Get())
    gains = root.GetAttribute("wresdyn:gains")
    robot = load_robot(root.GetAttribute("wresdyn:robotFile").Get(),
                       gains=json.loads(gains.Get()) if gains and gains.HasValue() else None,
                       base=str(root.GetAttribute("wresdyn:base").Get()))
    poses = np.asarray(attr.Get(), dtype=np.float64).reshape(shape)
    names = list(root.GetAttribute("wresdyn:rollouts").Get())
    colours = tuple(PALETTE[i % len(PALETTE)] for i in range(len(names)))
    spacing = root.GetAttribute("wresdyn:spacing")
    return Scene(robot, names, poses, float(stage.GetTimeCodesPerSecond()), colours,
                 f"{Path(path).name}: {', '.join(names)}", float(spacing.Get()) if spacing else None)


def load_scene(path, split: str = "heldout", index: int = 0, data: str | None = None, fps: float = 50.0,
               device: str = "cpu") -> Scene:
    """The scene of ``path``: a deploy folder (it holds ``deployed_heldout.usda``), a USD animation, or a run
    folder (:func:`run_scene`)."""
    path = Path(path)
    if path.is_dir() and (path / "deployed_heldout.usda").is_file():
        return animation_scene(path / "deployed_heldout.usda")
    if path.is_file() and path.suffix.lower() in (".usd", ".usda", ".usdc"):
        return animation_scene(path)
    return run_scene(path, split, index, data, fps, device)


def _tint(model, colours) -> None:
    """Blend every shape's colour with its world's tint, so the robots tell apart at a glance."""
    if model.shape_color is None:
        return
    import warp as wp

    base = model.shape_color.numpy()
    world = model.shape_world.numpy()
    tint = np.array([colours[w] if w >= 0 else (0.5, 0.5, 0.5) for w in world], dtype=np.float32)
    model.shape_color = wp.array(0.35 * base + 0.65 * tint, dtype=wp.vec3, device=model.device)


def _aim_camera(viewer, row, spacing: float) -> None:
    """Look at the row of robots from +x (so +y runs left to right), a little above, far enough to see all of them,
    the row shifted left of the GUI panel on the right (z-up scenes; a y-up one keeps the viewer's default view)."""
    if int(row.model.up_axis) != 2:
        return
    body = row.state.body_q.numpy()[:, :3]
    body = body[: max(1, len(body) // row.num_worlds)]  # world 0's bodies, the row's offsets not applied
    lo, hi = body.min(axis=0), body.max(axis=0)
    centre = 0.5 * (lo + hi)
    width = (row.num_worlds - 1) * spacing + float(hi[1] - lo[1])
    extent = max(float(np.max(hi - lo)), width, 0.2)
    distance, height = 1.5 * extent, 0.4 * extent
    pos = centre + np.array([distance, 0.15 * extent, height])
    viewer.set_camera(pos, pitch=-float(np.degrees(np.arctan2(height, distance))), yaw=180.0)


def serve(scene: Scene, cfg: ViewerConfig = ViewerConfig(), say=print) -> None:
    """Serve ``scene`` at ``http://cfg.host:cfg.port`` until Ctrl-C or ``cfg.seconds`` have passed; ``say`` gets
    the page's address once the scene is drawn."""
    try:
        from viser import uplot
    except ImportError:
        raise WresdynError("the viewer needs viser: pip install 'wresdyn[view]' (or pip install viser)") from None
    import newton

    n_frames, num_worlds, width = scene.poses.shape
    spacing = scene.spacing if scene.spacing is not None else cfg.spacing
    row = RobotRow(scene.robot, num_worlds)
    _tint(row.model, scene.colours)
    viewer = newton.viewer.ViewerViser(host=cfg.host, port=cfg.port, label="wresdyn", verbose=False)
    try:
        row.attach(viewer, spacing)
        viewer.begin_frame(0.0)
        viewer.log_state(row.pose(scene.poses[0]))
        viewer.end_frame()
        _aim_camera(viewer, row, spacing)
        gui = viewer.server.gui
        duration = (n_frames - 1) / scene.fps
        with gui.add_folder("wresdyn", order=-2):  # above the viewer's own folders
            gui.add_markdown(f"**{scene.title}**  \n" + ", ".join(
                f"<span style='color:rgb{tuple(int(255 * c) for c in col)}'>{name}</span>"
                for name, col in zip(scene.names, scene.colours)) + " (left to right along +y)")
            slider = gui.add_slider("time [s]", min=0.0, max=max(duration, 1.0 / scene.fps), step=1.0 / scene.fps,
                                    initial_value=0.0)
            play = gui.add_checkbox("play", initial_value=True)
            speed = gui.add_slider("speed", min=0.1, max=2.0, step=0.1, initial_value=1.0)
        joints = _plot_joints(scene, cfg.plot_joints)
        t = np.arange(n_frames) / scene.fps
        offset = width - scene.robot.n_dof
        with gui.add_folder("joint positions [rad]", order=-1):
            for j in joints:
                gui.add_uplot(
                    data=(t, *(scene.poses[:, i, offset + j] for i in range(num_worlds))),
                    series=(uplot.Series(label="t [s]"), *(
                        uplot.Series(label=name, stroke="#%02x%02x%02x" % tuple(int(255 * c) for c in col), width=1.5)
                        for name, col in zip(scene.names, scene.colours))),
                    title=scene.robot.joint_names[j], scales={"x": uplot.Scale(time=False)}, aspect=2.0)
        say(f"wresdyn view: {scene.title}\nserving http://{cfg.host}:{viewer.server.get_port()} "
            + (f"for {cfg.seconds:g} s" if cfg.seconds is not None else "(Ctrl-C to stop)"))
        _loop(viewer, row, scene, slider, play, speed, cfg)
    finally:
        viewer.close()


def _plot_joints(scene: Scene, count: int) -> list[int]:
    """The ``count`` joints whose rollouts part most from the first one (largest mean |Δq|), in joint order."""
    offset = scene.poses.shape[2] - scene.robot.n_dof
    q = scene.poses[:, :, offset:]
    spread = np.abs(q - q[:, :1]).mean(axis=(0, 1))
    return sorted(np.argsort(-spread, kind="stable")[:max(0, count)].tolist())


def _loop(viewer, row, scene: Scene, slider, play, speed, cfg: ViewerConfig) -> None:
    """Advance the slider while playing (looping at the end) and draw the frame under it when it moves."""
    n_frames = scene.poses.shape[0]
    start = last = time.monotonic()
    shown = 0
    try:
        while viewer.is_running() and (cfg.seconds is None or time.monotonic() - start < cfg.seconds):
            now = time.monotonic()
            if play.value and n_frames > 1:
                t = slider.value + (now - last) * speed.value
                slider.value = t % ((n_frames - 1) / scene.fps)
            last = now
            frame = min(int(round(slider.value * scene.fps)), n_frames - 1)
            if frame != shown:
                viewer.begin_frame(frame / scene.fps)
                viewer.log_state(row.pose(scene.poses[frame]))
                viewer.end_frame()
                shown = frame
            time.sleep(1.0 / cfg.fps)
    except KeyboardInterrupt:
        pass
