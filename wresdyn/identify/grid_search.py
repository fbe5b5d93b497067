"""Identification's forward grid searches (:func:`wresdyn.identify.sysid.identify`): a field set to the grid point of least
training loss on a few windows, for what the gradient alone cannot reach (a drive that never saturates in simulation
has no gradient with respect to its effort limit; a servo far stiffer in the robot file than on the robot leaves the
loss flat in kp)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..learn.window_fit import squared_error
from ..sim import TrajectoryBank, rollout
from ..sim.bank import servo_goal_accel

__all__ = ["GridChoice", "grid_search"]


@dataclass(frozen=True)
class GridChoice:
    """What one grid search of :func:`~wresdyn.identify.sysid.identify` chose (its ``on_search`` receives one per
    search)."""

    field: str
    """The field searched: ``"kp"`` (``gain_grid``, per joint), ``"delay"`` or ``"effort"`` (all joints at once)."""
    choice: dict[str, float | None]
    """Grid point each joint took, by joint name; ``None`` for a joint excluded from fitting (it keeps its value)."""
    losses: np.ndarray
    """Training loss of each grid point, shape (len(grid),), or per joint (len(grid), n_dof) for a per-joint
    search (mean squared position error [rad²])."""
    validation: float | None = None
    """Validation score of the parameters right after the search [rad] (the kp search, with a validation split)."""


def grid_search(cfg, model, sim, train, rng, field: str, grid, values, log, weights=None,
                per_joint: bool = False) -> GridChoice | None:
    """Set ``field`` to the grid point of least training loss on a few windows (forward only); return what was
    chosen (``None`` for an empty grid).

    ``values(g)`` maps a grid point to the field's values (n,) [SI]; every other field keeps its current value.
    ``weights``: per-joint weights (n,) tensor of the position error (0: excluded from fitting), ``None``: all 1.
    ``per_joint``: each joint takes the grid point of its own least position error (the joints are tried together,
    one rollout per grid point, so their coupling is ignored: a start for the gradient steps, not a fit).
    """
    if not len(grid):
        return None
    h = max(cfg.horizon_curriculum or (64,))
    bank = TrajectoryBank(train, sim.device)
    traj, start = bank.draw(rng, cfg.windows, h)  # the same windows for every grid point
    base = model.values()
    losses = []
    for g in grid:
        p = base.copy()
        setattr(p, field, values(g))
        sim.set_physics(p)
        delay = torch.as_tensor(p.delay / model.dt, dtype=torch.float32, device=sim.device)
        if getattr(model.robot, "servo", None) is None:
            bank.set_delay(delay)
        else:
            bank.set_command_path(delay, servo_goal_accel(model.robot, p, model.dt, sim.device))
        window = bank.window(traj, start, h)
        with torch.no_grad():
            run = rollout(sim, window)
        if per_joint:  # (n,) mean squared position error of each joint
            losses.append(((run.q[:, 1:] - window.q[:, 1:]) ** 2).reshape(-1, run.q.shape[-1]).mean(0).cpu().numpy())
        else:
            losses.append(float(squared_error(run.q[:, 1:], window.q[:, 1:], weights)))
    losses = np.nan_to_num(np.asarray(losses, dtype=np.float64), nan=np.inf)  # a diverged rollout never wins
    if per_joint:
        pick = np.argmin(losses, axis=0)  # (n,) grid index of each joint
        fitted = np.ones(len(pick), bool) if weights is None else weights.detach().cpu().numpy() > 0
        # a joint excluded from fitting keeps its value: its error is no one's to fit
        model.assign(field, np.stack([values(g) for g in grid])[pick, np.arange(len(pick))], keep=~fitted)
        choice = {j: float(grid[k]) if f else None for j, k, f in zip(model.robot.joint_names, pick, fitted)}
        log(f"{field} search, per joint: " + "  ".join(f"{j}:{'excluded' if g is None else f'{g:.3g}'}"
                                                       for j, g in choice.items()))
    else:
        best = grid[int(np.argmin(losses))]
        model.assign(field, values(best))
        choice = dict.fromkeys(model.robot.joint_names, float(best))
        log(f"{field} search: " + "  ".join(f"{g:.3g}:{x:.2e}" for g, x in zip(grid, losses)) + f"  -> {best:.3g}")
    return GridChoice(field, choice, losses)
