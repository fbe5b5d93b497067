"""``wresdyn`` command line: one subcommand per pipeline stage.

Each subcommand lives in its own module: a frozen dataclass ``COMMAND`` (its flags, through ``tyro``:
:mod:`wresdyn.cli.command`) and ``run(args) -> int``. Only the module of the command given is imported, and it
imports torch, Warp, Newton or MuJoCo only inside ``run``, so ``wresdyn --help`` and ``wresdyn CMD --help`` stay
fast. Errors the user can fix (bad flags, bad files, bad configs, a diverging simulation) print one line
``wresdyn <cmd>: error: ...`` and exit 2.
"""

from __future__ import annotations

import gc
import importlib
import sys

from .command import CommandLineError, ConfigRefused, hidden_fields, list_flags, parse
from .deprecated import rewrite

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
    "warmup": ("wresdyn.cli.warm", "compile the fit, identify and PPO kernels of the shipped robots (and --robot) ahead"),
}


class UserError(Exception):
    """An error caused by the user's input: reported in one line, exit code 2."""


def _user_errors():
    from ..errors import SimulationDiverged, WresdynError

    return (UserError, WresdynError, SimulationDiverged, FileNotFoundError)


def top_help() -> str:
    """``wresdyn --help``: the commands and their one-line summaries."""
    width = max(map(len, COMMANDS))
    rows = "\n".join(f"  {name:{width}s}  {help_}" for name, (_, help_) in COMMANDS.items())
    return (f"usage: wresdyn [-h] COMMAND ...\n\n{__doc__.splitlines()[0].replace('``', '')}\n\ncommands:\n{rows}\n\n"
            "wresdyn COMMAND --help lists a command's flags.\n")


def command_flags(name: str) -> dict[str, object]:
    """``{flag: annotation}`` of every flag of command ``name`` (of each of its variants: deploy's ``--floor``);
    its module is imported, nothing heavy."""
    module = importlib.import_module(COMMANDS[name][0])
    flags = {}
    for cls in getattr(module, "VARIANTS", (module.COMMAND,)):
        flags |= list_flags(cls, getattr(module, "HIDDEN", None))
    return flags


def _command_at(argv: list[str]) -> int | None:
    """Index of the command's name in ``argv`` (past options given before it and their values)."""
    i = 0
    while i < len(argv):
        if argv[i] == "--package-path":
            i += 2
        elif argv[i].startswith("-"):
            i += 1
        else:
            return i
    return None


def parse_command(argv: list[str]):
    """``(name, module, args)`` of a command line (deprecated spellings rewritten first, with a note on stderr).

    Raises:
        CommandLineError: no such command, or its arguments do not parse (one line).
        ConfigRefused: a config refuses a value given (one line).
        SystemExit: ``--help`` was printed (status 0), or no command given (status 2).
    """
    argv = list(argv)
    i = _command_at(argv)
    if i is None:
        print(top_help(), end="", file=sys.stdout if argv else sys.stderr)
        raise SystemExit(0 if argv and argv[0] in ("-h", "--help") else 2)
    name = argv[i]
    if name not in COMMANDS:
        raise CommandLineError(f"unknown command {name!r}; choose from {', '.join(COMMANDS)}")
    rest = argv[:i] + argv[i + 1:]  # options given before the command (the global --package-path of old) follow it
    module = importlib.import_module(COMMANDS[name][0])
    rest = rewrite(name, command_flags(name), rest, say=lambda line: print(f"wresdyn {name}: {line}", file=sys.stderr))
    prepare = getattr(module, "prepare", None)  # a command whose defaults depend on a flag (deploy --floor)
    cls, default = prepare(rest) if prepare else (module.COMMAND, None)
    args = parse(cls, rest, prog=f"wresdyn {name}", description=COMMANDS[name][1], default=default,
                 registry=hidden_fields(getattr(module, "HIDDEN", None)))
    return name, module, args


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    i = _command_at(argv)
    name = argv[i] if i is not None else ""
    prog = f"wresdyn {name}" if name in COMMANDS else "wresdyn"
    try:
        name, module, args = parse_command(argv)
    except CommandLineError as e:  # as argparse: the usage error ends the process with status 2
        print(f"{prog}: error: {e} (see {prog} --help)", file=sys.stderr)
        raise SystemExit(2) from None
    except ConfigRefused as e:
        print(f"{prog}: error: {e}", file=sys.stderr)
        return 2
    from ..robot.packages import set_package_path

    try:
        set_package_path(args.package_path)
        return int(module.run(args) or 0)
    except _user_errors() as e:
        print(f"wresdyn {name}: error: {e}", file=sys.stderr)
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
