"""``wresdyn view RUN``: the evaluation in the browser, an interactive 3-D page of rollouts side by side.

A run folder (``wresdyn fit``/``train``/``identify``) shows a held-out recording as the real robot, PD only and the
calibrated robot, with a time slider and joint plots; a ``wresdyn deploy`` folder shows its deployed skills. See
:mod:`wresdyn.evaluation.viewer`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import tyro

from .command import Command


@dataclass(frozen=True)
class View(Command):
    """``wresdyn view``: what to play, and where to serve it."""

    run: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="RUN")]
    """Run folder (`wresdyn fit`, `train`, `identify`), `wresdyn deploy` folder, or a USD animation it wrote."""
    split: str = "heldout"
    """Split of the run's dataset to play."""
    index: int = 0
    """Trajectory of the split to play (0: the first)."""
    data: str | None = None
    """Dataset file (default: the one the run was trained on)."""
    host: str = "127.0.0.1"
    """Address to serve on (127.0.0.1: this machine only; 0.0.0.0 shares the page)."""
    port: int = 8080
    """Port to serve on (or the next free one)."""
    seconds: float | None = None
    """Stop serving after this many seconds (None: serve until Ctrl-C)."""
    device: str = "cpu"
    """cpu or cuda:0, for the replays."""


COMMAND = View


def run(args: View) -> int:
    from ..evaluation.viewer import ViewerConfig, load_scene, serve

    cfg = ViewerConfig(host=args.host, port=args.port, seconds=args.seconds)
    scene = load_scene(args.run, args.split, args.index, args.data, cfg.fps, args.device)
    serve(scene, cfg, say=lambda line: print(line, flush=True))
    return 0
