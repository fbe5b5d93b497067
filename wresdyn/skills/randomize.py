"""Domain randomisation of a simulated plant: the physics of every world drawn around a centre, redrawn per episode.

Two baselines users run instead of (or on top of) calibration: (e) the nominal simulator with the wide ranges the
peers' humanoid tasks randomise (:class:`Randomization`, each range with its source) and (f) the calibrated simulator
with narrow ranges around the identified values, their widths from the identification's standard errors
(:func:`narrow_ranges`).

A draw writes the drawn worlds' rows into the Newton model of :class:`~wresdyn.skills.plants.SimPlant`'s simulator,
in place (:func:`wresdyn.sim.world_physics.write_world_physics`, the per-world path identifiability uses, then one
notice to the solver of what changed, so a CUDA graph captured of its steps stays valid): PD gains
(``joint_target_ke/kd``, what every solver reads), dry friction, armature, effort limits, link masses with their
inertias scaled alike (uniform density: the inverse mass and inertia follow), the centre of mass of one link, and
on the floor the friction of the robot's collision shapes (``shape_material_mu``). The command delay is the plant's
own delay line, per world. Draws are uniform in each range (log-uniform for scale factors, so ×0.8 and ×1.25 are
equally likely), seeded: the same seed gives the same draws.

When: ``redraw="reset"`` draws again for every world an episode resets (IsaacLab's ``mode="reset"``), ``"startup"``
once at construction (IsaacLab's and mjlab's ``mode="startup"``, their choice for masses and materials).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..errors import WresdynError
from ..sim.world_physics import model_flags, refresh, write_world_physics
from .randomization_config import UNSEEN_FIELDS, Randomization

__all__ = ["Randomization", "Ranges", "Randomizer", "wide_ranges", "narrow_ranges", "unseen_parameters",
           "NARROW_SIGMAS", "NARROW_FLOOR", "NARROW_DEFAULT", "UNSEEN_FIELDS"]

SCALED = ("kp", "kd", "armature", "effort", "body_mass")
"""Fields drawn as a factor on the centre value (log-uniform)."""




@dataclass
class Ranges:
    """Per-parameter ranges of one plant: ``scale[field] = (lo, hi)`` factors on the centre value ((n,) joint fields,
    (nb,) ``body_mass``), the rest absolute."""

    scale: dict
    """Factor ranges of :data:`SCALED` fields, each ``(lo, hi)`` arrays."""
    friction: tuple[np.ndarray, np.ndarray]
    """Dry friction range [N·m], (n,) each."""
    delay: tuple[np.ndarray, np.ndarray]
    """Command delay range [s], (n,) each."""
    com_offset: np.ndarray
    """Half-range of the CoM offset of ``com_body`` [m], (3,)."""
    com_body: str
    floor_friction: tuple[float, float]
    """Robot-floor friction range [-]."""
    effort_uniform: np.ndarray | None = None
    """Per joint, whether its effort factor is drawn uniformly instead of log-uniformly, (n,) bool (``None``: none):
    a range bounded from below by the data (:attr:`Randomization.effort_from_data`)."""


def _pair(r, n) -> tuple[np.ndarray, np.ndarray]:
    return np.full(n, float(r[0])), np.full(n, float(r[1]))


def wide_ranges(cfg: Randomization, robot, centre) -> Ranges:
    """(e)'s ranges: ``cfg``'s, around ``centre`` (:class:`~wresdyn.sim.physics.PhysicalParams`)."""
    n, nb = robot.n_dof, len(centre.body_mass)
    eff = np.asarray(centre.effort, dtype=np.float64)
    eff = np.where(np.isfinite(eff), eff, 0.0)
    scale = {"kp": _pair(cfg.kp_scale, n), "kd": _pair(cfg.kd_scale, n), "armature": _pair(cfg.armature_scale, n),
             "effort": _pair(cfg.effort_scale, n), "body_mass": _pair(cfg.mass_scale, nb)}
    return Ranges(scale, (cfg.friction[0] * eff, cfg.friction[1] * eff), _pair(cfg.delay, n),
                  np.asarray(cfg.com_offset, dtype=np.float64), cfg.com_body, tuple(cfg.floor_friction))


NARROW_SIGMAS = 2.0
"""(f): a factor range exp(±NARROW_SIGMAS · SE) around the identified value (SE of its log, the identifiability
report's relative standard error): the 95 % band of a log-normal estimate."""
NARROW_FLOOR = 0.02
"""(f): the least half-width of a factor range (the report's errors are lower bounds)."""
NARROW_DEFAULT = 0.10
"""(f): the half-width of a parameter the report does not cover (not fitted, no finite error, no report): ±10 %."""


def unseen_parameters(report: dict) -> set[str]:
    """The names the identifiability ``report`` (``identifiability.json``) marks unseen: zero sensitivity or no finite
    error (the data carry no trace of them). A finite error without a relative one (``se_pct`` ``None``: a value of 0
    in absolute units) is seen."""
    return {p["name"] for p in report["parameters"]
            if p.get("sensitivity") == 0 or p.get("se") is None or not math.isfinite(p["se"])}


def _where(mask, unseen: tuple, seen: tuple) -> tuple[np.ndarray, np.ndarray]:
    """The range ``(lo, hi)`` taken from ``unseen`` where ``mask`` holds, from ``seen`` elsewhere."""
    return np.where(mask, unseen[0], seen[0]), np.where(mask, unseen[1], seen[1])


def narrow_ranges(cfg: Randomization, robot, centre, run) -> tuple[Ranges, str]:
    """(f)'s ranges around the identified ``centre``: each identified parameter's factor range
    exp(±:data:`NARROW_SIGMAS` · SE) from ``run``'s ``identify/identifiability.json`` (or ``identifiability.json``),
    at least ±:data:`NARROW_FLOOR` and never wider than (e)'s; a parameter without a finite error
    ±:data:`NARROW_DEFAULT`. Dry friction and delay the same way around their identified values; the CoM offsets
    :data:`NARROW_DEFAULT` of (e)'s (the report does not cover them); the floor friction (e)'s (the stand's data say
    nothing of the floor). With ``cfg.unseen="wide"`` a parameter the report marks unseen (:func:`unseen_parameters`)
    gets (e)'s range instead, an unseen link's mass ``cfg.unseen_mass_add_kg`` and an unseen effort limit
    ``cfg.unseen_effort_scale`` where set, and the CoM offset is
    (e)'s (or ``cfg.unseen_com_offset``) when ``com_body``'s mass is unseen. With ``cfg.effort_from_data`` the effort
    limits the training data barely saturate are drawn uniformly from the data's demand up (:func:`_effort_from_data`).
    Returns the ranges and one line saying where the widths came from."""
    wide = wide_ranges(cfg, robot, centre)
    run = Path(run)
    path = next((p for p in (run / "identify" / "identifiability.json", run / "identifiability.json")
                 if p.is_file()), None)
    se, unseen = {}, set()
    if path is not None:
        report = json.loads(path.read_text())
        for p in report["parameters"]:
            if p.get("se") is not None and p.get("se_pct") is not None and math.isfinite(p["se"]):
                se[p["name"]] = float(p["se"])
        if cfg.unseen == "wide":
            unseen = unseen_parameters(report)
    names = {"body_mass": list(robot.body_names)}
    scale, half, is_unseen = {}, {}, {}
    for f in (*SCALED, "friction", "delay"):
        labels = names.get(f, list(robot.joint_names))
        h = np.array([NARROW_SIGMAS * se[f"{f}:{x}"] if f"{f}:{x}" in se else math.log1p(NARROW_DEFAULT)
                      for x in labels])
        half[f] = np.maximum(h, math.log1p(NARROW_FLOOR))
        is_unseen[f] = np.array([f"{f}:{x}" in unseen for x in labels], dtype=bool)
    for f in SCALED:  # never wider than (e)
        lo, hi = wide.scale[f]
        scale[f] = _where(is_unseen[f], (lo, hi), (np.maximum(np.exp(-half[f]), lo), np.minimum(np.exp(half[f]), hi)))
    if cfg.unseen_mass_add_kg is not None and is_unseen["body_mass"].any():
        m = np.asarray(centre.body_mass, dtype=np.float64)
        # a light link keeps a tenth of its mass: IsaacLab adds to the base only
        lo, hi = (np.maximum(m + a, 0.1 * m) / np.where(m > 0, m, 1.0) for a in cfg.unseen_mass_add_kg)
        scale["body_mass"] = _where(is_unseen["body_mass"], (lo, hi), scale["body_mass"])
    if cfg.unseen_effort_scale is not None and is_unseen["effort"].any():
        scale["effort"] = _where(is_unseen["effort"], _pair(cfg.unseen_effort_scale, robot.n_dof), scale["effort"])
    fr, de = np.asarray(centre.friction, float), np.asarray(centre.delay, float)
    friction = (fr * np.exp(-half["friction"]), np.minimum(fr * np.exp(half["friction"]), wide.friction[1] + fr))
    delay = (de * np.exp(-half["delay"]), np.minimum(de * np.exp(half["delay"]), de + wide.delay[1][0]))
    # the unseen: (e)'s width either side of the identified value, as the data bound neither side
    friction = _where(is_unseen["friction"], (np.maximum(fr - wide.friction[1], 0.0), fr + wide.friction[1]), friction)
    delay = _where(is_unseen["delay"], (np.maximum(de - wide.delay[1], 0.0), de + wide.delay[1]), delay)
    com = NARROW_DEFAULT * wide.com_offset
    com_unseen = f"body_mass:{wide.com_body}" in unseen
    if com_unseen:
        com = np.asarray(cfg.unseen_com_offset if cfg.unseen_com_offset is not None else wide.com_offset, float)
    source = (f"widths from {path} ({len(se)} parameters with a finite error, ±{NARROW_SIGMAS:g} SE, at least "
              f"±{100 * NARROW_FLOOR:g} %, others ±{100 * NARROW_DEFAULT:g} %)" if path is not None else
              f"no identifiability report in {run}: ±{100 * NARROW_DEFAULT:g} % of every identified value")
    uniform = None
    if cfg.effort_from_data:
        uniform = _effort_from_data(scale["effort"], robot, centre, run, None if path is None else report)
        source += (f"; the effort limits of {int(uniform.sum())} joints saturated on too few training samples from "
                   "the data's demand up")
    if cfg.unseen == "wide":
        source += (f"; {len(unseen)} unseen in the report with (e)'s ranges"
                   + (f", an unseen link's mass {cfg.unseen_mass_add_kg} kg" if cfg.unseen_mass_add_kg else "")
                   + (f", {int(is_unseen['effort'].sum())} unseen effort limits ×{cfg.unseen_effort_scale}"
                      if cfg.unseen_effort_scale else "")
                   + (f", {wide.com_body}'s CoM ±{tuple(float(x) for x in com)} m" if com_unseen else ""))
    return Ranges(scale, friction, delay, com, wide.com_body, wide.floor_friction, uniform), source


def _effort_from_data(effort: tuple, robot, centre, run, report: dict | None) -> np.ndarray:
    """:attr:`Randomization.effort_from_data`: the factor range ``effort`` (lo, hi) set in place, for each joint the
    ``report``'s training data saturate on fewer than its ``effort_saturated_min`` of the samples, to (demanded /
    identified, hi), never above 1 (the identified value stays inside); returns those joints, (n,) bool."""
    missing = "no identifiability report" if report is None else next(
        (f"no `{k}` in its identifiability report (written before it: recompute the report)"
         for k in ("demanded_effort_nm", "effort_saturated", "effort_saturated_min") if k not in report), None)
    if missing:
        raise WresdynError(f"randomization.effort-from-data: {run} has {missing}")
    demanded, share = report["demanded_effort_nm"], report["effort_saturated"]
    identified = np.asarray(centre.effort, dtype=np.float64)
    lo = effort[0]
    uniform = np.zeros(robot.n_dof, dtype=bool)
    for j, name in enumerate(robot.joint_names):
        if (name in demanded and share[name] < report["effort_saturated_min"] and demanded[name] > 0
                and np.isfinite(identified[j]) and identified[j] > 0):
            lo[j], uniform[j] = min(demanded[name] / identified[j], 1.0), True
    return uniform


class Randomizer:
    """Draws :class:`Ranges` around ``centre`` for the worlds of a :class:`~wresdyn.sim.Simulator` and writes them
    into its model; :meth:`draw` returns each world's command delay [s] (k, n) for the plant's delay line.

    Args:
        sim: The simulator (its ``robot``, ``num_worlds``, ``ground``).
        centre: :class:`~wresdyn.sim.physics.PhysicalParams` the draws are centred on (the robot file's or the
            identified ones).
        ranges: The ranges (:func:`wide_ranges`, :func:`narrow_ranges`).
        seed: Seed of the draws.
    """

    def __init__(self, sim, centre, ranges: Ranges, seed: int = 0) -> None:
        if type(sim.solver).__name__ == "SolverMuJoCoThreads":
            raise WresdynError("domain randomisation needs per-world physics; the floor's threaded MuJoCo C worlds "
                               "share world 0's: run the floor's plants on a GPU (mujoco_warp) or with one world")
        self.sim, self.ranges = sim, ranges
        self.rng = np.random.default_rng(seed)
        robot = sim.robot
        f32 = dict(dtype=torch.float32, device=sim.device)
        self.centre = {f: torch.as_tensor(np.asarray(getattr(centre, f), dtype=np.float64), **f32)
                       for f in ("kp", "kd", "armature", "friction", "effort", "body_mass", "body_com",
                                 "body_inertia")}
        self.centre["effort"] = torch.where(torch.isfinite(self.centre["effort"]), self.centre["effort"],
                                            torch.zeros_like(self.centre["effort"]))  # 0: Newton's "unlimited"
        if ranges.com_body not in robot.body_names:
            raise WresdynError(f"randomisation: no link {ranges.com_body!r} in {robot.source.name}")
        self.com_body = list(robot.body_names).index(ranges.com_body)
        w = sim.num_worlds
        self.values = {f: v.expand(w, *v.shape).clone() for f, v in self.centre.items()}
        """Each world's physics as drawn: joint fields (W, n), body fields (W, nb[, 3[, 3]])."""
        self.delay = np.zeros((w, robot.n_dof))
        """Each world's command delay [s] (W, n)."""
        self.floor_friction = np.zeros(w)
        """Each world's robot-floor friction [-] (W,) (floor only)."""
        self._shapes = None
        if sim.ground:
            import warp as wp

            per_world = np.asarray(sim.model.shape_world.numpy())
            self._mu = wp.to_torch(sim.model.shape_material_mu, requires_grad=False)
            # MuJoCo takes the larger of two geoms' friction: the shared floor at the range's low end lets each
            # world's robot shapes set its own robot-floor friction
            self._mu[torch.as_tensor(np.flatnonzero(per_world < 0), device=self._mu.device)] = \
                float(ranges.floor_friction[0])
            self._shapes = torch.as_tensor(np.flatnonzero(per_world >= 0), device=self._mu.device)
            self._shape_world = torch.as_tensor(per_world[per_world >= 0], device=self._mu.device)

    def _uniform(self, lo, hi, k: int, log=False) -> np.ndarray:
        """``k`` draws in (lo, hi), log-uniform where ``log`` (a bool, or one per entry)."""
        lo, hi = np.broadcast_to(lo, np.shape(hi)), np.asarray(hi)
        u = self.rng.random((k, *hi.shape))
        if log is True:
            return np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo)))
        if log is False:
            return lo + u * (hi - lo)
        return np.where(log, np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo))), lo + u * (hi - lo))

    def draw(self, ids=None) -> np.ndarray:
        """Draw new physics for worlds ``ids`` (long (k,), ``None``: all) and write theirs into the model (in place);
        returns the drawn worlds' command delays [s] (k, n)."""
        w = self.sim.num_worlds
        ids = np.arange(w) if ids is None else np.asarray(torch.as_tensor(ids).cpu(), dtype=np.int64)
        k = len(ids)
        if k == 0:
            return np.zeros((0, self.sim.robot.n_dof))
        r, dev = self.ranges, self.sim.device
        t = lambda a: torch.as_tensor(a, dtype=torch.float32, device=dev)  # noqa: E731
        idx = torch.as_tensor(ids, device=dev)
        # the draws in one fixed order (the seed's stream): gains, armature, effort, friction, masses, CoM, delay, floor
        for f in ("kp", "kd", "armature", "effort"):
            log = True if f != "effort" or r.effort_uniform is None else ~r.effort_uniform
            self.values[f][idx] = self.centre[f] * t(self._uniform(*r.scale[f], k, log=log))
        self.values["friction"][idx] = t(self._uniform(*r.friction, k))
        s = t(self._uniform(*r.scale["body_mass"], k, log=True))
        self.values["body_mass"][idx] = self.centre["body_mass"] * s
        self.values["body_inertia"][idx] = self.centre["body_inertia"] * s[..., None, None]
        com = self.centre["body_com"].expand(k, *self.centre["body_com"].shape).clone()
        com[:, self.com_body] += t(self._uniform(-r.com_offset, r.com_offset, k))
        self.values["body_com"][idx] = com
        lo, hi = r.delay  # one quantile for every joint of a world: one command bus
        self.delay[ids] = lo + self.rng.random((k, 1)) * (hi - lo)
        # only the drawn worlds' rows, in place: the solver's captured graph stays valid (wresdyn.sim.world_physics)
        written = write_world_physics(self.sim, {f: v[idx] for f, v in self.values.items()}, ids)
        if self._shapes is not None:
            self.floor_friction[ids] = self._uniform(*r.floor_friction, k)
            self._mu[self._shapes] = t(self.floor_friction)[self._shape_world]
        refresh(self.sim, model_flags(written, shapes=self._shapes is not None))
        return self.delay[ids]
