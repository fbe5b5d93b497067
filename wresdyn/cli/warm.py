"""``wresdyn warmup``: compile the kernels of the fit, identification and PPO paths into Warp's cache, no training.

A robot's first run waits for its kernels to compile (on a GPU the adjoint most of all): run this once on a new
machine, or in a container's build, and the first ``wresdyn fit``, ``identify``, ``train`` or ``eval`` only loads
them. It compiles for the shipped robots (the humanoid; the SO-101 with its file's actuators and with
``scenes/so101/servo.toml``'s servo drives) and for ``--robot`` if given, on ``--device``; a second call finds
everything in the cache and returns within seconds. The cache is Warp's (``$WARP_CACHE_PATH``, else
``~/.cache/warp``); the generated kernel sources go to ``$WRESDYN_KERNEL_DIR`` (else ``~/.cache/wresdyn/kernels``).
What is compiled: :func:`wresdyn.sim.warmup.warm_up`.
"""

from __future__ import annotations

from dataclasses import dataclass

from .command import Command

SHIPPED = (("scenes/humanoid.usda", None), ("scenes/so101/so101.xml", None),
           ("scenes/so101/so101.xml", "scenes/so101/servo.toml"))
"""The shipped robots it compiles for: (robot file, gains config or None) relative to the repository; the SO-101 twice,
its file's position actuators and the STS3215 servo drives, which generate code of their own."""


@dataclass(frozen=True)
class Warmup(Command):
    """``wresdyn warmup``: the robots and the device to compile for."""

    robot: str | None = None
    """Robot file to compile for as well (.usda/.urdf/.xml), e.g. the one your data were recorded on."""
    gains: str | None = None
    """Gains config (TOML) of --robot: servo drives compile kernels of their own."""
    device: str = "cpu"
    """Warp device: cpu or cuda:0 (one GPU compiles for every GPU of its architecture)."""
    shipped: bool = True
    """Also compile for the shipped robots (--no-shipped: only --robot)."""
    export: str | None = None
    """Folder to copy the compiled modules to, with an index (Warp version, device architecture, module hashes): ship
    it, or point WRESDYN_PREBUILT_KERNELS at it, and a fresh machine of that architecture and Warp version copies
    them into its cache instead of compiling (only on an exact match)."""


COMMAND = Warmup


def run(args: Warmup) -> int:
    from ..choices import check_device
    from ..paths import REPO
    from . import UserError

    check_device(args.device, "--device")
    targets = [(str(REPO / path), None if gains is None else str(REPO / gains)) for path, gains in SHIPPED]
    if not args.shipped:
        targets = []
    if args.robot is not None:
        targets.append((args.robot, args.gains))
    elif args.gains is not None:
        raise UserError("--gains applies to --robot: give the robot file too")
    if not targets:
        raise UserError("nothing to compile: --no-shipped needs --robot")
    import warp as wp

    # before Newton initialises Warp: no banner, the warm-up's own lines say what happens
    wp.config.quiet = True
    wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
    from ..sim.warmup import warm_up

    warm_up(targets, device=args.device, export=args.export)
    return 0
