"""The string choices of wresdyn's configs, as ``Literal`` types, and the checks every config runs on itself.

One place for each set of allowed values: the config dataclasses annotate their fields with these types and
check them in ``__post_init__`` (so a bad value fails where the config is built, whoever builds it: the command
line, ``--set``, a script, an ablation cell, a ``config.json`` read back), and the command line takes its
``choices=`` from :func:`choices` of the same type. This module imports nothing heavy, so ``wresdyn --help``
stays fast.
"""

from __future__ import annotations

import math
import re
from typing import Literal, get_args

from .errors import WresdynError

__all__ = ["ResidualKind", "Arch", "SolverKind", "ModelKind", "FitModel", "Learner", "ExcitationMode", "DetectNorm",
           "choices", "check_choice", "check_number", "check_friction_kappa", "check_device"]

ResidualKind = Literal["torque", "delta_action"]
"""Joint torque added to τ_pd (the paper, eq. 1) or offset added to the PD target (ASAP)."""
Arch = Literal["mlp", "gru"]
"""Residual network: MLP with ELU, or GRU followed by the MLP (paper Fig. 4)."""
SolverKind = Literal["auto", "replay", "featherstone", "mujoco"]
"""Replay solvers of :func:`wresdyn.sim.solvers.make_solver` (its ``SOLVERS``)."""
ModelKind = Literal["network", "parametric"]
"""What the gradient fit learns: a residual network or the parametric baseline."""
FitModel = Literal["hybrid", "network", "parametric"]
"""What ``wresdyn fit`` builds: identified physics + residual network (the default), a residual network on the
robot file's physics (or on ``--physics``), or the residual-torque parametric baseline."""
Learner = Literal["ppo", "gradient", "parametric"]
"""Learners of the ablation."""
ExcitationMode = Literal["auto", "foot", "joint"]
"""Excitation of ``wresdyn collect``: foot IK targets, joint space, or foot when the robot has all the frames."""
DetectNorm = Literal["none", "command"]
"""What the online identifier's change detector divides a held-back error by (:attr:`wresdyn.adapt.config.AdaptConfig.
detect_norm`)."""


def choices(literal) -> tuple[str, ...]:
    """The allowed values of a ``Literal`` type, e.g. for argparse's ``choices=``."""
    return tuple(get_args(literal))


def check_choice(value, literal, name: str):
    """``value`` if it is one of ``literal``'s values, else a one-line :class:`WresdynError` naming ``name``
    and listing the allowed values."""
    allowed = choices(literal)
    if not isinstance(value, str) or value not in allowed:
        raise WresdynError(f"{name} = {value!r} is not one of: {', '.join(allowed)}")
    return value


def check_number(value, name: str, *, integer: bool = False, gt: float | None = None, ge: float | None = None,
                 le: float | None = None):
    """``value`` if it is a finite number (an ``int`` when ``integer``) within the bounds, else a one-line
    :class:`WresdynError` naming ``name``. ``bool`` is not a number here: ``True`` for a count is a mistake."""
    kind = "an integer" if integer else "a number"
    ok = isinstance(value, int) if integer else isinstance(value, (int, float))
    if isinstance(value, bool) or not ok or not math.isfinite(value):
        raise WresdynError(f"{name} = {value!r} is not {kind}")
    for bound, fails, word in ((gt, lambda b: value <= b, ">"), (ge, lambda b: value < b, ">="),
                               (le, lambda b: value > b, "<=")):
        if bound is not None and fails(bound):
            raise WresdynError(f"{name} = {value!r} must be {word} {bound:g}")
    return value


def check_friction_kappa(value, name: str, solver: str = "auto"):
    """``value`` if it is ``None`` (the replay solver's soft dry friction) or a damper-law rate [1/s] > 0
    (``inf``: hard Coulomb friction) with a ``solver`` that can be the replay solver, else a one-line
    :class:`WresdynError` naming ``name``."""
    if value is None:
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise WresdynError(f"{name} = {value!r} must be a rate > 0 [1/s] (inf: hard Coulomb) or none (the soft law)")
    if solver not in ("auto", "replay"):
        raise WresdynError(f"{name} = {value!r} is a law of the replay solver; solver {solver!r} has its own friction")
    return value


_DEVICE = re.compile(r"cpu|cuda(:\d+)?")


def check_device(value, name: str):
    """``value`` if it names a device the way torch and Warp both read it (``cpu``, ``cuda``, ``cuda:N``)."""
    if not isinstance(value, str) or not _DEVICE.fullmatch(value):
        raise WresdynError(f"{name} = {value!r} is not a device: cpu, cuda or cuda:N")
    return value
