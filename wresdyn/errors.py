"""Errors a user can cause and fix: each is reported by the command line in one line with exit code 2."""

from __future__ import annotations

__all__ = ["WresdynError", "RobotError", "SimulationDiverged"]


class WresdynError(ValueError):
    """Base of wresdyn's user-facing errors; the message is one line naming the file or setting at fault."""


class RobotError(WresdynError):
    """A robot file or gains config that wresdyn cannot use; the message is one line naming the file."""


class SimulationDiverged(RuntimeError):
    """The simulated state became non-finite or left any sensible range."""
