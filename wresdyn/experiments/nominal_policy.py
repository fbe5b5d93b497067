"""The floor benchmark's CPU run (:mod:`.skills`): (a) taken as it is from a policy trained at full size elsewhere (the
shipped ``floor_nominal``, :mod:`wresdyn.skills.shipped`) instead of trained, checked to fit the run, and the held-out
families such a run deploys on, chosen on validation motions. With ``shipped`` (:data:`SHIPPED_FLOOR`) (b) and the
oracle (d) are taken as they are too, and the run only draws its own motions and deploys.

Fitting the run means: the same task (every field of the task config: rewards, limits and the observation built from
them), the same network widths (a fine-tuning loads the checkpoint's weights), the robot's number of joints in the
actor's observation and action, and the same motion generator (length, screening, extra families). The motion seed
and counts may differ: every floor motion has its own random stream (:func:`~wresdyn.skills.motions.make_motions`),
so another seed or count draws other motions of the same families, never the held-out ones of the policy's seed as
training ones.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from ..errors import WresdynError
from ..skills.evaluate import deploy, metrics
from ..skills.motions import TASK_FAMILIES, make_motions
from ..skills.shipped import SHIPPED, shipped_folder
from ..skills.skill_ppo import load_skill
from .zero_shot import POLICIES as POLICY_SETTING

__all__ = ["SHIPPED_NOMINAL", "SHIPPED_FLOOR", "nominal_source", "installed_from", "check_fits", "check_installed",
           "installed_record", "balanced_families", "draw_heldout"]

SHIPPED_NOMINAL = "floor_nominal"
"""The shipped (a) of the floor benchmark that ``nominal="auto"`` takes on the CPU."""
SHIPPED_FLOOR = {"a_nominal": SHIPPED_NOMINAL, "b_calibrated": "floor_calibrated", "d_oracle": "floor_oracle"}
"""The policies a ``shipped`` floor run takes from the package: (a), and (b) and (d) fine-tuned from it at full size on
a GPU for the real robot of ``data/mismatch_default.toml`` (each ``shipped.json`` keeps that mismatch)."""
_MOTION_KEYS = ("duration", "floor", "screened", "extra")
"""What of a run's ``motions`` record a policy taken as it is must share with the run (not the seed nor counts)."""


def nominal_source(cfg) -> str | None:
    """Where (a) comes from: ``cfg.nominal`` (a shipped name or a run folder; ``None``: trained here), with ``auto``
    resolved to :data:`SHIPPED_NOMINAL` where the package ships it and PPO runs on the CPU, else ``None``."""
    if getattr(cfg, "shipped", False):
        return SHIPPED_NOMINAL
    if cfg.nominal != "auto":
        return cfg.nominal
    has = (SHIPPED / SHIPPED_NOMINAL / "shipped.json").is_file()
    return SHIPPED_NOMINAL if has and cfg.device == "cpu" else None


def installed_from(cfg, name: str) -> str | None:
    """Where the policy ``name`` is taken from as it is (a shipped name or a run folder), ``None`` where it is trained
    here: (a) from ``cfg.nominal`` (resolved by :func:`nominal_source`), with ``shipped`` (b) and (d) too."""
    if getattr(cfg, "shipped", False):
        return SHIPPED_FLOOR.get(name)
    return cfg.nominal if name == "a_nominal" else None


def _folder(source: str) -> Path:
    return Path(source) if Path(source).is_dir() else shipped_folder(source)


def check_installed(cfg, policies, mismatch, task, ppo, motions_meta: dict, n_dof: int) -> None:
    """Refuse in one line a run whose policies taken as they are do not fit it (:func:`check_fits`); with ``shipped``
    also policies the package does not ship, a real robot other than the one the shipped oracle was trained on, and
    the shipped policies' own motion seed, whose validation and held-out motions are the full-size run's."""
    if getattr(cfg, "shipped", False):
        other = [p for p in policies if p not in SHIPPED_FLOOR]
        if other:
            raise WresdynError(f"--shipped deploys {', '.join(SHIPPED_FLOOR)} only (not {', '.join(other)})")
        record = json.loads((shipped_folder(SHIPPED_FLOOR["d_oracle"]) / "shipped.json").read_text())
        if json.loads(json.dumps(mismatch.to_dict())) != record["mismatch"]:
            raise WresdynError("the shipped oracle was trained on the real robot of data/mismatch_default.toml; "
                               "--shipped deploys on that one only (--mismatch data/mismatch_default.toml)")
        trained = json.loads((shipped_folder(SHIPPED_FLOOR["d_oracle"]) / "config.json").read_text())["motions"]
        if cfg.seed == trained["seed"]:
            raise WresdynError(f"--seed {cfg.seed} draws the shipped policies' own validation and held-out motions "
                               "(their full-size run's); give the CPU run another seed")
    for name in policies:
        source = installed_from(cfg, name)
        if source:
            check_fits(source, task, ppo, motions_meta, n_dof, setting=POLICY_SETTING[name])


def installed_record(cfg, out: Path) -> dict:
    """What ``results.json`` keeps of the policies taken as they are: ``nominal`` ((a): source, iterations, worlds)
    and with ``shipped`` ``shipped`` (each one's source, training command, commit, machine and policy's sha256)."""
    rec = {}
    if cfg.nominal:
        a_cfg = json.loads((out / "skills" / "a_nominal" / "config.json").read_text())
        rec["nominal"] = {"source": str(cfg.nominal), "iterations": a_cfg["ppo"]["iterations"],
                          "num_worlds": a_cfg["num_worlds"]}
    if getattr(cfg, "shipped", False):
        rec["shipped"] = {}
        for name, source in SHIPPED_FLOOR.items():
            have = json.loads((shipped_folder(source) / "shipped.json").read_text())
            run = json.loads((out / "skills" / name / "config.json").read_text())
            rec["shipped"][name] = {"source": source, "iterations": run["ppo"]["iterations"],
                                    "num_worlds": run["num_worlds"], "device": run["ppo"]["device"],
                                    **{k: have[k] for k in ("command", "commit", "machine")},
                                    "policy_sha256": have["sha256"]["policy.pt"]}
    return rec


def check_fits(source: str, task, ppo, motions_meta: dict, n_dof: int, setting: str = "nominal") -> None:
    """Refuse in one line a policy ``source`` (a shipped name or a skill run folder) that does not fit the run:
    another ``task`` (its config dataclass), ``ppo.hidden_dims``, motion generator (``motions_meta``: the run's
    ``motions`` record), number of joints ``n_dof`` (the actor's observation: 6 per joint, the floor's 6 IMU values
    more, :meth:`~wresdyn.skills.env.TrackingEnv.get_observations`; its action: one per joint) or plant it was
    trained on (``setting``, :data:`~.zero_shot.POLICIES`)."""
    folder = _folder(source)
    have = json.loads((folder / "config.json").read_text())
    why = []
    want_task = json.loads(json.dumps(asdict(task)))  # as config.json keeps it (tuples as lists)
    if have.get("task") != want_task:
        old = have.get("task") or {}
        keys = sorted(k for k in set(old) | set(want_task) if old.get(k) != want_task.get(k))
        why.append("task " + ", ".join(f"{k} {old.get(k)} against {want_task.get(k)}" for k in keys[:3])
                   + (" ..." if len(keys) > 3 else ""))
    widths = list(have.get("ppo", {}).get("hidden_dims", []))
    if widths != list(ppo.hidden_dims):
        why.append(f"network widths {widths} against {list(ppo.hidden_dims)}")
    old_m = have.get("motions", {})
    for k in _MOTION_KEYS:
        if old_m.get(k) != motions_meta.get(k):
            why.append(f"motions' {k} {old_m.get(k)} against {motions_meta.get(k)}")
    if have.get("setting") != setting:
        why.append(f"trained in the {have.get('setting')} setting, not the {setting} one")
    n_obs = 6 * n_dof + (6 if task.floating else 0)
    try:
        with torch.no_grad():
            act = load_skill(folder)(torch.zeros(2, n_obs))
        if tuple(act.shape) != (2, n_dof):
            raise ValueError(f"{tuple(act.shape[1:])} actions")
    except Exception as e:  # torch.export's guard or the shape check: the layout is another robot's
        why.append(f"its policy does not take this robot's {n_obs} observations to {n_dof} actions "
                   f"({str(e).splitlines()[0][:80] if str(e) else type(e).__name__})")
    if why:
        raise WresdynError(f"(a) from {source} does not fit this run: {'; '.join(why)} (train (a) here with "
                           "--nominal None, or give the run's own settings)")


def balanced_families(policy, plant, validation: list, task) -> tuple[list[str], dict[str, str], dict]:
    """The rule that picks the families of the CPU run's held-out motions, decided on validation motions only: a
    family is kept when ``policy`` (the full-size (a)) succeeds on every one of its ``validation`` motions in the
    simulator it was trained in (``plant``, one world per motion), i.e. its motions are within the reach of a policy
    trained at full size, so that what the real robot does to them is the simulators' gap; the held-out family, which
    has no validation motion, is left out. Returns the kept families, the reason of each one left out, and the
    deployment's :func:`~wresdyn.skills.evaluate.metrics`."""
    res = metrics(deploy(policy, plant, validation, task))
    fams = list(dict.fromkeys(m.family for m in validation))
    kept, left = [], {}
    for f in fams:
        ok = [p["success"] for p, m in zip(res["motions"], validation) if m.family == f]
        if all(ok):
            kept.append(f)
        else:
            left[f] = f"(a) failed {len(ok) - int(np.sum(ok))} of {len(ok)} validation motions in its simulator"
    return kept, left, res


def draw_heldout(robot, floating, cfg, rate_hz: float, kept: list[str]) -> tuple[list, dict[str, str]]:
    """The held-out motions of the families ``kept`` (``cfg.heldout_per_family`` each, from the held-out stream of
    :func:`~wresdyn.skills.motions.make_motions`: the same draws as in a set of every family) and the reason of each
    held-out family left out that no validation motion vouches for; every family's where none is kept (a run that
    deploys nothing shows nothing)."""
    per = {"heldout": cfg.heldout_per_family}
    kw = dict(floating=floating, screen=cfg.screen, workers=cfg.motion_workers)
    if not kept:
        return make_motions(robot, per, cfg.duration, rate_hz, cfg.seed, **kw)["heldout"], {}
    held = make_motions(robot, per, cfg.duration, rate_hz, cfg.seed, families=kept, held_out=(), **kw)["heldout"]
    return held, {f: "no validation motion (the held-out family)" for f in TASK_FAMILIES["floor"].held_out}
