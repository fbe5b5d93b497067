"""When a window fit moves on and when it stops: a fixed count of iterations, or convergence on validation.

Both window fits (identification, the gradient fit of a residual) step through a horizon curriculum (short windows
first) with a falling learning rate. Two schedules drive them:

* :class:`FixedSchedule` (``cfg.iterations = N``): exactly N iterations, the horizons in equal parts, the learning
  rate on a cosine from ``cfg.lr`` to ``cfg.lr_final``, validation every ``select_every`` (default N // 10). An old
  run reproduces bit for bit.
* :class:`PlateauSchedule` (``cfg.iterations = None``, the default): each horizon runs until validation stops
  improving, then the next begins; on the last horizon a plateau lowers the learning rate by ``lr_decay`` down to
  ``lr_final``, and a plateau there ends the fit. A plateau is ``patience`` validations in a row without a gain of
  ``min_improvement`` (relative) over the best so far. Stage s of S starts at the cosine's rate at s / S, so the
  rates the stages see are the fixed schedule's. ``max_iterations`` and ``max_seconds`` (training wall-clock) are
  ceilings. Where the starting point is a candidate (the hybrid's zero residual) and ``beat_start_within`` is set, a
  fit none of whose first ``beat_start_within`` checks beat the start stops there, keeping the start. A fixed count
  tuned on one robot under- or over-fits another (a 29-DoF humanoid's validation still fell by 20 % over the last
  tenth of the shipped humanoid's 800 identification iterations); validation says when to move on for any robot.

The log says why each stage ended and why the fit stopped (:attr:`PlateauSchedule.reason`).
"""

from __future__ import annotations

import math

__all__ = ["FixedSchedule", "PlateauSchedule", "make_schedule", "describe_length", "PLATEAU_CHECK_EVERY"]

PLATEAU_CHECK_EVERY = 40
"""Validation cadence of :class:`PlateauSchedule` [iterations] unless ``select_every`` is given: about a second of
validation against 5-10 s of training per check on the shipped humanoid on 2 CPU cores."""


def cosine_lr(cfg, fraction: float) -> float:
    """The learning rate at ``fraction`` (0-1) of the cosine from ``cfg.lr`` to ``cfg.lr_final``."""
    return float(cfg.lr_final + 0.5 * (cfg.lr - cfg.lr_final) * (1.0 + math.cos(math.pi * fraction)))


class FixedSchedule:
    """``cfg.iterations`` iterations: horizons in equal parts of training, cosine learning rate."""

    def __init__(self, cfg, horizons) -> None:
        self.cfg, self.horizons = cfg, tuple(horizons)
        self.total = cfg.iterations
        """Iterations of the whole schedule (the progress bar's length)."""
        self.check_every = max(1, cfg.select_every or cfg.iterations // 10)
        self.log_every = max(1, cfg.iterations // 20)
        self.reason = ""
        """Why the fit stopped, once it has."""

    def at(self, it: int) -> tuple[int, int, float]:
        """(stage, window length [steps], learning rate) of iteration ``it`` (from 0)."""
        n = self.cfg.iterations
        stage = min(it * len(self.horizons) // n, len(self.horizons) - 1)
        return stage, self.horizons[stage], cosine_lr(self.cfg, it / n)

    def validate_now(self, it: int) -> bool:
        return (it + 1) % self.check_every == 0 or it + 1 == self.cfg.iterations

    def log_now(self, it: int) -> bool:
        return (it + 1) % self.log_every == 0

    def observe(self, value: float | None, it: int, wall: float, start: float | None = None) -> str:
        """Take the validation ``value`` [rad] scored after iteration ``it`` (from 1); the message to log, if any.
        ``start``: the starting point's validation [rad] while it is still the best candidate, else ``None``."""
        return ""

    def finished(self, it: int, wall: float) -> bool:
        """Whether the fit is over before iteration ``it`` (from 0), at training wall-clock ``wall`` [s]."""
        if it >= self.cfg.iterations:
            self.reason = f"{self.cfg.iterations} iterations done"
            return True
        return False

    def state(self) -> dict:
        return {}

    def restore(self, state: dict) -> None:
        pass


class PlateauSchedule:
    """Each horizon until validation plateaus, then lower learning rates on the last until ``lr_final`` plateaus
    (module docstring). Needs a validation split: without one, each stage runs ``patience`` checks."""

    def __init__(self, cfg, horizons) -> None:
        self.cfg, self.horizons = cfg, tuple(horizons)
        self.total = cfg.max_iterations
        self.check_every = max(1, cfg.select_every or PLATEAU_CHECK_EVERY)
        self.log_every = self.check_every
        self.stage = 0
        """Index of the current horizon."""
        self.lr = self._stage_lr(0)
        """The current learning rate."""
        self.best = math.inf
        """The best validation seen [rad]."""
        self.stale = 0
        """Validations in a row without a gain of ``min_improvement`` on :attr:`best`."""
        self.checks = 0
        """Validations taken."""
        self.done = False
        self.reason = ""

    def _stage_lr(self, stage: int) -> float:
        return cosine_lr(self.cfg, stage / len(self.horizons))

    def at(self, it: int) -> tuple[int, int, float]:
        return self.stage, self.horizons[self.stage], self.lr

    def validate_now(self, it: int) -> bool:
        return (it + 1) % self.check_every == 0

    def log_now(self, it: int) -> bool:
        return self.validate_now(it)

    def observe(self, value: float | None, it: int, wall: float, start: float | None = None) -> str:
        cfg = self.cfg
        self.checks += 1
        within = cfg.beat_start_within
        if start is not None and within is not None and self.checks >= within:
            # every check so far scored at or above the start, which stays selected unless a later one beats it
            self.done = True
            self.reason = (f"stopped at iteration {it}: none of {self.checks} validation checks beat the start's "
                           f"{start:.4f} rad (beat_start_within {within})")
            return ""
        if value is not None and value < self.best * (1.0 - cfg.min_improvement):
            self.best, self.stale = value, 0
            return ""
        if value is not None and value < self.best:
            self.best = value
        self.stale += 1
        if self.stale < cfg.patience:
            return ""
        self.stale = 0
        why = (f"no {cfg.min_improvement:.0%} gain on {self.best:.4f} rad over {cfg.patience} checks"
               if value is not None else f"{cfg.patience} checks (no validation split)")
        h = self.horizons[self.stage]
        if self.stage + 1 < len(self.horizons):
            self.stage += 1
            self.lr = self._stage_lr(self.stage)
            return f"H={h} plateaued ({why}): H={self.horizons[self.stage]} from iteration {it + 1}"
        if self.lr > cfg.lr_final * (1.0 + 1e-9):
            was, self.lr = self.lr, max(cfg.lr_final, self.lr * cfg.lr_decay)
            return f"H={h} at lr {was:.2g} plateaued ({why}): lr {self.lr:.2g} from iteration {it + 1}"
        self.done = True
        self.reason = f"converged at iteration {it}: H={h} at the final lr {self.lr:.2g} plateaued ({why})"
        return ""

    def finished(self, it: int, wall: float) -> bool:
        cfg = self.cfg
        if self.done:
            return True
        if it >= cfg.max_iterations:
            self.reason = (f"stopped at the ceiling of {cfg.max_iterations} iterations (max_iterations) before "
                           "validation plateaued")
            return True
        if cfg.max_seconds is not None and wall >= cfg.max_seconds:
            self.reason = (f"stopped at the wall-clock ceiling of {cfg.max_seconds:g} s (max_seconds) at iteration {it} "
                           "before validation plateaued")
            return True
        return False

    def state(self) -> dict:
        return {"stage": self.stage, "lr": self.lr, "best": self.best, "stale": self.stale, "done": self.done,
                "reason": self.reason, "checks": self.checks}

    def restore(self, state: dict) -> None:
        self.stage, self.lr, self.best, self.stale = state["stage"], state["lr"], state["best"], state["stale"]
        self.done, self.reason = state["done"], state["reason"]
        self.checks = state.get("checks", 0)  # a checkpoint from before the count: its checks count from here


def make_schedule(cfg, horizons) -> FixedSchedule | PlateauSchedule:
    """:class:`FixedSchedule` for an explicit ``cfg.iterations``, :class:`PlateauSchedule` for ``None``."""
    return FixedSchedule(cfg, horizons) if cfg.iterations is not None else PlateauSchedule(cfg, horizons)


def describe_length(cfg) -> str:
    """How long a fit of ``cfg`` runs, for its first log line."""
    if cfg.iterations is not None:
        return f"{cfg.iterations} iterations"
    cap = f"at most {cfg.max_iterations} iterations" + (f" or {cfg.max_seconds:g} s" if cfg.max_seconds else "")
    return f"until validation plateaus ({cap})"
