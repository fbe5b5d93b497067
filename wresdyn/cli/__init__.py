"""``wresdyn`` command line: one subcommand per pipeline stage.

Each subcommand lives in its own module with ``add_arguments(parser)`` and ``run(args) -> int``; modules
are imported only when their command runs, so ``wresdyn --help`` stays fast. Errors the user can fix
(bad files, bad configs, a diverging simulation) print one line ``wresdyn <cmd>: error: ...`` and exit 2.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import sys

COMMANDS: dict[str, tuple[str, str]] = {
    # name: (module, one-line help)
    "inspect": ("wresdyn.cli.inspect", "print a robot's joint table and check it in Newton and MuJoCo"),
    "demo": ("wresdyn.cli.demo", "run the main job on the embedded defaults"),
    "collect": ("wresdyn.cli.collect", "record a dataset on the simulated real robot (or import real logs)"),
    "migrate": ("wresdyn.cli.migrate", "rewrite a schema-1 dataset as schema 2, optionally adding a validation split"),
    "train": ("wresdyn.cli.train", "learn a residual with PPO on a dataset's training split (resumable)"),
    "eval": ("wresdyn.cli.eval", "replay held-out and OOD data open-loop: PD only vs PD + residual, report"),
    "bench": ("wresdyn.cli.bench", "env-steps/s of the replay workload for every solver, same robot and worlds"),
    "identify": ("wresdyn.cli.identify", "identify the simulator's own physics (gains, friction, delay, masses...)"),
    "fit": ("wresdyn.cli.fit", "learn a residual by gradient descent through the differentiable simulation"),
    "adapt": ("wresdyn.cli.adapt", "keep a run's identified physics up to date from a stream of the robot's samples"),
    "view": ("wresdyn.cli.view", "play a run's held-out replay (or a deploy's skills) in the browser, side by side"),
    "export": ("wresdyn.cli.export", "write the calibrated robot: USD layers, Newton actuators and the residual"),
    "deploy": ("wresdyn.cli.deploy", "train tracking skills in nominal and corrected simulators, deploy them on the real robot"),
    "ablate": ("wresdyn.cli.ablate", "PPO vs gradient vs parametric x MLP/GRU x torque/delta action x seeds"),
}


class UserError(Exception):
    """An error caused by the user's input: reported in one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    """argparse, with its errors in the same one line as every other user error (no usage block)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _user_errors():
    from ..errors import SimulationDiverged, WresdynError

    return (UserError, WresdynError, SimulationDiverged, FileNotFoundError)


def build_parser() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    """The ``wresdyn`` parser and each command's own (its module's ``add_arguments``), by command name."""
    parser = _Parser(prog="wresdyn", description=__doc__.splitlines()[0])
    parser.add_argument("--package-path", action="append", default=[], metavar="DIR",
                        help="folder holding ROS packages that a URDF's package://NAME/... mesh URIs name (repeatable, "
                             "or several joined by the path separator); searched before the URDF's own folder tree "
                             "and ROS_PACKAGE_PATH")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    subs = {}
    for name, (module, help_) in COMMANDS.items():
        p = subs[name] = sub.add_parser(name, help=help_, description=help_)
        p.set_defaults(_module=module)
        # argument definitions are cheap; import the module lazily only for its parser hook
        importlib.import_module(module).add_arguments(p)
    return parser, subs


def main(argv: list[str] | None = None) -> int:
    parser, _ = build_parser()
    args = parser.parse_args(argv)
    mod = importlib.import_module(args._module)
    from ..robot.packages import set_package_path

    try:
        set_package_path(args.package_path)
        return int(mod.run(args) or 0)
    except _user_errors() as e:
        print(f"wresdyn {args.command}: error: {e}", file=sys.stderr)
        return 2
    finally:
        set_package_path([])  # the roots belong to this command, not to later calls in the same process


def entry() -> None:
    """The ``wresdyn`` executable: :func:`main`, then exit. The interpreter's last garbage collection would walk every
    object still alive, among them the syntax trees Warp keeps of the generated kernels (1.6 million objects after a
    humanoid fit: about 4 s); they are freed at exit by reference counting all the same, so the collector is told to
    leave the survivors alone (``gc.freeze``)."""
    rc = main()
    gc.freeze()
    sys.exit(rc)
