"""What the USD export changes or drops of the identified model: the ``notes`` of its ``export.json``.

Newton's joints carry a constant dry friction ``newton:friction`` (``SolverMuJoCo`` makes it MuJoCo's frictionloss,
a soft constraint, the replay's default law) and no velocity-dependent bound; the servo drive
(:mod:`wresdyn.export.servo_actuator`) carries the startup torque but no friction. So a run identified under the
damper friction law exports its amplitudes as that friction, and a servo joint's stiction (the static friction above
the dry one at rest, :func:`wresdyn.robot.servo.friction_bound`) and its load friction (the share of the drive torque
added to it) are dropped, as the MJCF export drops them.
"""

from __future__ import annotations

__all__ = ["usd_notes"]


def usd_notes(robot, physics, friction_kappa: float | None) -> list[str]:
    """One line per change: the damper law's friction (``friction_kappa`` [1/s], ``None``: the default law) and each
    servo joint's dropped stiction [N m] and load friction [-] (``physics``:
    :class:`~wresdyn.sim.physics.PhysicalParams` on ``robot``)."""
    notes = []
    if friction_kappa is not None:
        notes.append(f"friction: identified under the damper law -clamp(kappa H_ii v, -mu, mu), kappa = "
                     f"{friction_kappa:g} /s; exported as Newton's joint friction newton:friction mu (SolverMuJoCo's "
                     "frictionloss, a soft constraint: the replay's default law), which holds a joint at rest where "
                     "the damper lets it creep")
    servo = getattr(robot, "servo", None)
    for i, name in enumerate(robot.joint_names):
        if servo is not None and servo.mask[i] and physics.stiction[i] > 0:
            notes.append(f"{name}: servo stiction {float(physics.stiction[i]):.4g} N m dropped (neither Newton's "
                         f"joints nor the servo drive bound friction by speed): the joint's friction is the sliding "
                         f"friction {float(physics.friction[i]):.4g} N m at rest too")
        if servo is not None and servo.mask[i] and physics.load_friction[i] > 0:
            notes.append(f"{name}: servo load friction {float(physics.load_friction[i]):.4g} x |drive torque| dropped "
                         f"(Newton's joint friction is constant)")
    return notes
