"""The residual of the Playground recipe's fit in radians, on ``mujoco.sysid``'s public ``ModifyResidualFn`` hook.

``mujoco.sysid``'s default residual divides each observed column by its window's root mean square *value*
(``normalize_residual``: ``‖y‖ / √2``, not its spread about the mean). For joint positions that is the distance of
the joint's angle from the zero of its encoder, so a joint that sits near 0 rad in a window weighs up to hundreds
of times more than one held at 1 rad, whatever it does; the fit then trades the scored joints' error for that
column's. Here every arm joint's position error counts in radians, as the scoring metric counts it.
"""

from __future__ import annotations

import numpy as np
from mujoco import sysid

ARM = 5


def radian_residual(params, predicted, measured, model, return_pred_all, state=None, **_):
    """Arm-joint position error [rad] of one window, its first (given) sample left out as ``mujoco.sysid`` does.

    ``state`` is the rollout's full-physics state (time, then qpos), row k after step k + 1 of the window's H − 1;
    the measured series starts at the window's initial state, so row k lines up with measured sample k + 1."""
    del params, predicted, model, return_pred_all
    q_sim = state[:, 1:1 + ARM]
    q_rec = measured.data[1:, :ARM]
    times = measured.times[1:]
    if not np.allclose(state[:, 0], times, atol=1e-9):
        raise ValueError("the rollout's times do not line up with the recording's")
    res = (q_sim - q_rec).ravel()
    return (res, sysid.TimeSeries(times, q_sim, measured.signal_mapping),
            sysid.TimeSeries(times, q_rec, measured.signal_mapping))
