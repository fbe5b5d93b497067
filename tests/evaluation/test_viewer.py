"""``wresdyn view``: the scenes it plays (a run's replays, a deploy's animation) and, opt-in, the page itself drawn
by headless Chromium (:mod:`wresdyn.evaluation.viewer`).

The run is real and tiny: the SO-101 arm recorded by ``wresdyn collect`` (1 s per trajectory) and fitted by
``wresdyn fit`` for 2 iterations; the browser test serves it with ``wresdyn view --seconds`` on the loopback address
and takes a screenshot.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from wresdyn.cli import main
from wresdyn.paths import REPO

SO101 = REPO / "scenes" / "so101" / "so101.xml"


@pytest.fixture(scope="module")
def fit_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("view")
    assert main(["collect", "--robot", str(SO101), "--train", "1", "--validation", "1", "--heldout", "1", "--ood",
                 "0", "--duration", "1.0", "--no-gap", "--out", str(tmp / "d")]) == 0
    assert main(["fit", str(tmp / "d" / "dataset.npz"), "--model", "network", "--iterations", "2", "--windows", "2",
                 "--curriculum", "2", "--out", str(tmp / "fit")]) == 0
    return tmp / "fit"


def test_run_scene_is_the_recording_and_the_eval_replays(fit_run):
    from wresdyn.data.dataset import load_dataset
    from wresdyn.evaluation.viewer import load_scene

    scene = load_scene(fit_run, fps=50.0)
    ds = load_dataset(fit_run.parent / "d" / "dataset.npz")
    real = ds.split("heldout")[0].q
    assert scene.names == ["real", "PD only", "calibrated"]
    # 1 s at 500 Hz: 500 samples, frames at 50 fps pick every 10th
    assert scene.poses.shape == (50, 3, 6) and scene.fps == 50.0
    np.testing.assert_array_equal(scene.poses[:, 0], real[::10])
    # the replays start from the first recorded state and part from the recording (the real robot's mismatch)
    np.testing.assert_allclose(scene.poses[0, 1:], np.broadcast_to(real[0], (2, 6)), atol=1e-6)
    assert np.abs(scene.poses[:, 1] - scene.poses[:, 0]).mean() > 0.01
    assert "heldout heldout_000" in scene.title and "PD only" in scene.title
    with pytest.raises(Exception, match="no index 3"):
        load_scene(fit_run, index=3)


def test_animation_scene_reads_back_the_frames_it_was_written_with(tmp_path):
    from wresdyn.evaluation.viewer import load_scene
    from wresdyn.robot.description import load_robot
    from wresdyn.evaluation.animation import sample_frames, write_animation

    robot = load_robot(SO101)
    ramp = np.zeros((30, robot.n_dof))
    ramp[:, 1] = np.linspace(0.0, 0.5, 30)
    rollouts = {"reference": ramp, "nominal": 0.5 * ramp}
    (tmp_path / "deploy").mkdir()
    write_animation(robot, rollouts, 50.0, tmp_path / "deploy" / "deployed_heldout.usda", fps=25.0)
    scene = load_scene(tmp_path / "deploy")  # a deploy folder: its deployed_heldout.usda
    names, poses = sample_frames(robot, rollouts, 50.0, 25.0)
    assert scene.names == names == ["reference", "nominal"] and scene.fps == 25.0
    np.testing.assert_array_equal(scene.poses, poses)
    assert scene.poses.shape == (15, 2, robot.n_dof) and scene.spacing == 1.0  # write_animation's default
    assert scene.robot.joint_names == robot.joint_names and scene.robot.base == "fixed"


def test_not_a_run_is_one_line(tmp_path, capsys):
    assert main(["view", str(tmp_path), "--seconds", "1"]) == 2
    assert "not a run folder" in capsys.readouterr().err


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _chromium() -> str | None:
    return next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)


@pytest.mark.browser
def test_page_draws_the_three_robots(fit_run, tmp_path):
    """The page as a user sees it: served on 127.0.0.1 for a bounded time, opened by headless Chromium (software
    WebGL), the screenshot holds the tinted robots (red real, green PD only, blue calibrated) in the 3-D view."""
    from matplotlib.image import imread

    browser = _chromium()
    if browser is None:
        pytest.fail("--run-browser needs Chromium on PATH (Debian: apt-get install chromium)")
    port = _free_port()
    server = subprocess.Popen([sys.executable, "-m", "wresdyn", "view", str(fit_run), "--host", "127.0.0.1",
                               "--port", str(port), "--seconds", "30"], stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, cwd=REPO)
    try:
        lines, deadline = [], time.monotonic() + 50
        while time.monotonic() < deadline:
            line = server.stdout.readline()
            lines.append(line)
            if line.startswith("serving http://127.0.0.1:"):
                break
            assert line or server.poll() is None, "".join(lines)
        else:
            pytest.fail("the viewer did not say it serves:\n" + "".join(lines))
        url = line.split()[1]
        shot = tmp_path / "viewer.png"
        subprocess.run([browser, "--headless", "--no-sandbox", "--enable-unsafe-swiftshader",
                        "--use-angle=swiftshader", "--hide-scrollbars", f"--screenshot={shot}",
                        "--window-size=1400,900", "--virtual-time-budget=25000", url],
                       check=True, timeout=90, capture_output=True)
        assert server.wait(timeout=40) == 0  # --seconds: it stops by itself
    finally:
        if server.poll() is None:
            server.kill()
    if os.environ.get("WRESDYN_VIEWER_SHOT"):  # regenerates docs/viewer.png (docs/viewer.md says how)
        shutil.copyfile(shot, os.environ["WRESDYN_VIEWER_SHOT"])
    rgb = imread(shot)[..., :3]
    assert rgb.shape == (900, 1400, 3)
    # the 3-D view, clear of the notice (top left), the axes (bottom left) and the GUI panel (right)
    scene = rgb[170:820, :1040]
    ink = np.abs(scene - scene[0, 0]).max(axis=-1) > 0.1
    # the robots cover a few percent of the view (3.5 % measured); a blank or uniform page has none
    assert 0.01 < ink.mean() < 0.5
    r, g, b = (scene[..., c] for c in range(3))
    # each robot's tint: red (real), green (PD only), blue (calibrated) dominates some pixels; columns order them
    # along +y, left to right as the page says
    cols = [np.nonzero((mask & ink).any(axis=0))[0] for mask in (r > g + 0.15, g > r + 0.15, b > r + 0.15)]
    assert all(len(c) > 10 for c in cols), [len(c) for c in cols]
    assert np.median(cols[0]) < np.median(cols[1]) < np.median(cols[2])
