"""Saturation probe: joint steps that drive the legs' PD drives into their effort limits on the stand.

A drive's effort limit shows in a recording only while the drive saturates, and hung on a stand the legs swing
free: the paper's ellipsoid excitation never asks the knees for the torque that balance on the floor needs, so their
limits cannot be identified from it (:mod:`wresdyn.identify.unexcited_limits`). The probe asks for it on purpose:
from the foot workspace's home pose, each leg joint in turn steps by δ and back, the step rising in ``rise``
seconds (a minimum-jerk move, faster than the drive can follow), while every other joint holds its home position.
The step is sized so the PD demand kp·δ is ``effort_fraction`` of the robot file's effort limit (drawn per step),
so a derated drive saturates until the joint has covered most of δ, tens of ms. A step stays
``limit_margin`` inside the joint's limits: a joint whose range is too short for the demand steps as far as the
range allows (on the humanoid, the ankles: kp·range is below their file limit).

``across`` (opt-in) makes such range-limited joints saturate anyway. The drive is kp·(q_cmd − q) − kd·q̇ with no
velocity feed-forward, so its kd term opposes the move and a step's demand peaks at about kp·Δ, Δ the commanded
jump, before the joint has moved: the only way to raise the demand within the limits is a larger Δ. A step that
finds no side with room for its demand goes from one end of the range to the other and back instead (home → one end
→ the other → the first → home, each move one ``rise``, holds of a quarter pair between): Δ is the whole range less
the margins, and each pair has two saturating steps. Humanoid numbers (kp 40 N·m/rad, kd 2 N·m·s/rad, file limit 50
N·m on both ankle joints): ankle roll's range ±0.26 rad gives Δ = 0.42 rad with the 0.05 rad margin, kp·Δ = 17 N·m
(0.34 of the file's limit) where one side's 0.21 rad gave 8.5 N·m (0.17): above the mismatches' derating of 0.3 (15
N·m; 0.9 of kp: 15.3 N·m, a thin excess), not above 0.15-0.2 (``limit_margin`` 0.02: 19 N·m); ankle pitch's
−0.87..0.52 rad gives 1.30 rad, kp·Δ = 52 N·m, above even the file's limit, where its longer side's 0.82 rad gave 33
N·m. Holding against a joint limit would saturate for longer but commands outside the limits and leaves the stop's
contact to the replay; the probe does neither. On the second benchmark mismatch
(`benchmarks/results/floor_fair/ankle_probe_cpu/`) it does less than these numbers say. From the robot's neutral
pose ankle pitch steps across and saturates on about twice the samples, but from the foot workspace's home that
`wresdyn collect` probes from (ankle pitch at −0.53 and −0.82 rad) its steps have room and do not change. Ankle roll
steps across and still does not saturate: that mismatch's ankle friction (0.12 of the file's limit, 6 N·m) stalls it
f/kp ≈ 0.16 rad short of every command, so its drive delivers at most about 10 N·m of its 15: within the joint
limits no position step saturates it.

The k-th joint of every IK chain is probed at once (the base is fixed, so the legs do not load each other), the
chain positions in a random order, ``steps`` out-and-back pairs each, each step to a random side that has room.

The probe's command speed exceeds the excitation's ``max_velocity`` by design (a step is the point of it): it is
exempt from that check, and from nothing else (joint limits hold). It is opt-in (``wresdyn collect
--probe-saturation N`` adds N probe trajectories to the training split); without it nothing is drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robot.description import Robot, RobotError
from .signals import Excitation, finite_limits, limit_margin, min_jerk

__all__ = ["PROBE_FAMILY", "SaturationProbe", "saturation_probe"]

PROBE_FAMILY = "saturation_probe"
"""Family name of a probe trajectory (recorded in the dataset's meta)."""


@dataclass(frozen=True)
class SaturationProbe:
    """How the saturation probe steps each leg joint (module docstring)."""

    effort_fraction: tuple[float, float] = (0.6, 0.9)
    """The PD demand of a step, kp·δ, as a fraction of the robot file's effort limit, drawn uniformly per step [-].
    Real drives deliver well below the file's figure (the benchmark mismatches: 0.15-0.3 of it), so the default
    saturates them with steps small enough not to dominate the training loss (above 1 with the 10 ms rise: the
    demand exceeds even the file's limit, a larger and rougher probe)."""
    rise: float = 0.01
    """Duration of one step's minimum-jerk move [s]."""
    steps: int = 4
    """Out-and-back step pairs per joint and trajectory (with 6 probes of 4 s beside 16 other training trajectories,
    every drive the probe saturates does so on more than 1 % of the training samples, the share identification needs
    to call its limit identified, :mod:`wresdyn.identify.unexcited_limits`)."""
    lead: float = 0.1
    """Hold of the home pose before the first step [s]."""
    limit_margin: float = 0.05
    """Steps stay this far inside every joint limit [rad]."""
    across: bool = False
    """A step whose demand no side of the home pose has room for steps across the joint's whole range and back
    instead of as far as one side allows (module docstring: it doubles ankle roll's demand, which friction can still
    hold below the limit). Off: such a step goes as far as its side allows, with the same random draws."""

    def __post_init__(self) -> None:
        lo, hi = self.effort_fraction
        if not 0 < lo <= hi:
            raise RobotError(f"saturation probe: effort_fraction must be 0 < lo <= hi, not {self.effort_fraction}")
        if not (self.rise > 0 and self.steps >= 1 and self.lead >= 0 and self.limit_margin >= 0):
            raise RobotError("saturation probe: rise must be > 0, steps >= 1, lead and limit_margin >= 0")


def saturation_probe(robot: Robot, chains: list[np.ndarray], home: np.ndarray, duration: float, rate_hz: float,
                     rng: np.random.Generator, cfg: SaturationProbe | None = None) -> Excitation:
    """Draw one probe trajectory.

    Args:
        robot: The robot (fixed base): gains ``kp`` [N·m/rad], effort limits [N·m] and joint limits [rad].
        chains: Per IK frame, the joint indices of its chain (:attr:`~wresdyn.data.ik.FootIK.chains`).
        home: Pose held between steps and by every joint not being probed [rad], shape (n_dof,).
        duration: Trajectory length [s].
        rate_hz: Command rate [Hz].
        rng: Random generator (advanced in place).
        cfg: Step sizes and timing.

    Returns:
        The excitation; ``params`` holds, per probed joint, its steps (``t0`` [s], ``delta`` [rad]; ``across``:
        true on a step across the range, ``t0`` and ``delta`` then its first crossing) and ``reach``, the largest
        kp·|δ| over the file's effort limit [-] (below 1: the joint's range is too short to ask for it).

    Raises:
        RobotError: one line: a trajectory too short for the steps, a probed joint without gain or effort limit.
    """
    cfg = cfg or SaturationProbe()
    t = np.arange(int(round(duration * rate_hz))) / rate_hz
    n_slots = max(len(c) for c in chains)
    pair = (duration - cfg.lead) / (n_slots * cfg.steps)
    if pair < 4 * cfg.rise or pair < 4.0 / rate_hz:
        raise RobotError(f"saturation probe: {duration:g} s holds no {cfg.steps} step pairs on each of {n_slots} "
                         f"joints per chain with {cfg.rise:g} s rises; make the trajectories longer")
    lo, hi = finite_limits(robot)
    m = limit_margin(lo, hi, cfg.limit_margin)
    lo, hi = lo + m, hi - m
    home = np.clip(np.asarray(home, dtype=np.float64), lo, hi)
    kp, effort = np.asarray(robot.kp, dtype=np.float64), np.asarray(robot.effort, dtype=np.float64)
    q = np.broadcast_to(home, (len(t), robot.n_dof)).copy()
    order = rng.permutation(n_slots)
    params: dict = {"order": order.tolist(), "joints": {}}
    for slot, k in enumerate(order):
        for chain in chains:
            if k >= len(chain):
                continue
            j = int(chain[k])
            name = robot.joint_names[j]
            if not (np.isfinite(effort[j]) and effort[j] > 0 and kp[j] > 0):
                raise RobotError(f"{robot.source}: saturation probe of {name} needs a gain and an effort limit")
            steps, reach = [], 0.0
            for s in range(cfg.steps):
                want = rng.uniform(*cfg.effort_fraction) * effort[j] / kp[j]
                room = np.array([hi[j] - home[j], home[j] - lo[j]])
                sides = np.flatnonzero(room >= want)
                side = int(rng.choice(sides)) if len(sides) else int(np.argmax(room))
                delta = (1.0 if side == 0 else -1.0) * min(want, room[side])
                t0 = cfg.lead + (slot * cfg.steps + s) * pair
                step = {"t0": float(t0), "delta": float(delta)}
                moves = ((t0, 0.0, delta), (t0 + 0.5 * pair, delta, 0.0))
                if cfg.across and not len(sides):
                    far = -np.sign(delta) * room[1 - side]  # the other end, from the end with more room
                    moves = ((t0, 0.0, delta), (t0 + 0.25 * pair, delta, far), (t0 + 0.5 * pair, far, delta),
                             (t0 + 0.75 * pair, delta, 0.0))
                    delta = far - delta
                    step = {"t0": float(t0 + 0.25 * pair), "delta": float(delta), "across": True}
                for start, a, b in moves:
                    u = np.clip((t - start) / cfg.rise, 0.0, 1.0)
                    q[:, j] = np.where(t >= start, home[j] + a + min_jerk(u) * (b - a), q[:, j])
                steps.append(step)
                reach = max(reach, kp[j] * abs(delta) / effort[j])
            params["joints"][name] = {"steps": steps, "reach": float(reach)}
    speed = float(np.abs(np.diff(q, axis=0)).max() * rate_hz) if len(t) > 1 else 0.0
    params.update(family=PROBE_FAMILY, draws=1, ik_max_error_m=0.0, max_speed=speed)
    return Excitation(family=PROBE_FAMILY, q_cmd=q, params=params)
