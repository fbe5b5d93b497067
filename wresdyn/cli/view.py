"""``wresdyn view RUN``: the evaluation in the browser, an interactive 3-D page of rollouts side by side.

A run folder (``wresdyn fit``/``train``/``identify``) shows a held-out recording as the real robot, PD only and the
calibrated robot, with a time slider and joint plots; a ``wresdyn deploy`` folder shows its deployed skills. See
:mod:`wresdyn.evaluation.viewer`.
"""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run folder (`wresdyn fit`, `train`, `identify`), `wresdyn deploy` folder, or a USD "
                               "animation it wrote")
    p.add_argument("--split", default="heldout", help="split of the run's dataset to play (default: heldout)")
    p.add_argument("--index", type=int, default=0, help="trajectory of the split to play (default: 0, the first)")
    p.add_argument("--data", default=None, help="dataset file (default: the one the run was trained on)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to serve on (default: 127.0.0.1, this machine only; 0.0.0.0 shares the page)")
    p.add_argument("--port", type=int, default=8080, help="port to serve on (default: 8080, or the next free one)")
    p.add_argument("--seconds", type=float, default=None,
                   help="stop serving after this many seconds (default: serve until Ctrl-C)")
    p.add_argument("--device", default="cpu", help="cpu or cuda:0, for the replays")


def run(args: argparse.Namespace) -> int:
    from ..evaluation.viewer import ViewerConfig, load_scene, serve

    cfg = ViewerConfig(host=args.host, port=args.port, seconds=args.seconds)
    scene = load_scene(args.run, args.split, args.index, args.data, cfg.fps, args.device)
    serve(scene, cfg, say=lambda line: print(line, flush=True))
    return 0
