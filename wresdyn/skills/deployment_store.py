"""A benchmark's deployments kept in its run folder (``deployments/<split>/<where>_<name>.npz``), so that a run killed
while it deploys its policies reads back on its rerun what it had deployed instead of deploying it again.

Each file holds one :class:`~.evaluate.Deployment` (every policy, and the reference, on the ``real`` plant or in the
``sim`` it was trained in, over one split's motions) as plain arrays (read with ``allow_pickle=False``) and one JSON
string: its scalars and the *fingerprint* of every input that determines the rollouts: the policy's ``policy.pt``
(SHA-256) and its last checkpoint's iteration, the motion set's fingerprint (:func:`~.motion_store.motion_fingerprint`)
and a digest of the split's motions themselves (a held-out draw picked once the nominal policy is known changes them
under the same set fingerprint), the task config, and the plant: the real robot's mismatch, rate and seed, or the
simulator's setting, the SHA-256 of the correction it is built from, its randomisation and its device. The metrics are
computed again from the arrays read back, so they equal those of the deployment as run, bit for bit.

A deployment whose stored fingerprint equals this run's is read back (one line, "reused"); one whose fingerprint
differs (the policy trained further, other motions or plant settings) is deployed again and overwritten (one line
naming the first field that differs); an unreadable file (a run killed while writing cannot leave one: written to a
temporary file and renamed) is deployed again after a one-line warning. :data:`VERSION` is part of the fingerprint:
a change to what :func:`~.evaluate.deploy` records bumps it, so that no rollout of the older code is read back.

The held-out ledger (:mod:`.ledger`) keeps its rule, every scoring listed once: :meth:`DeploymentStore.record` appends
a line where this run deployed a held-out motion on the real robot, and where it read every one back, only to the
ledgers that do not already hold the same scoring (a run killed after deploying and before recording is listed then).
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from dataclasses import fields
from pathlib import Path

import numpy as np

from ..learn.config_diff import first_difference
from ..paths import file_sha256
from ..ppo.runner import latest_checkpoint
from .evaluate import Deployment, deploy, metrics
from .ledger import config_hash, read_ledger, record_heldout
from .motion_store import _plain
from .skill_ppo import load_skill

__all__ = ["DEPLOYMENTS", "VERSION", "DeploymentStore", "save_deployment", "read_deployment", "policy_fingerprint",
           "run_fingerprint", "motions_digest", "deploy_all"]

DEPLOYMENTS = "deployments"
"""The folder of the stored deployments in a run folder."""
VERSION = 1
"""The rollouts' format and meaning: bumped where :func:`~.evaluate.deploy` records something else."""
_SCALARS = ("names", "policy_dt", "floating")
"""The fields of :class:`~.evaluate.Deployment` kept in the JSON string; the others are arrays (or ``None``)."""


def save_deployment(path, dep: Deployment, fingerprint: dict) -> None:
    """Write ``dep`` with its ``fingerprint`` to ``path`` (its folder made), atomically: a temporary file beside it,
    then renamed over it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {f.name: getattr(dep, f.name) for f in fields(Deployment)
              if f.name not in _SCALARS and getattr(dep, f.name) is not None}
    if "cause" in arrays:  # an object array of strings: kept as a plain unicode one
        arrays["cause"] = np.asarray([str(c) for c in arrays["cause"]], dtype=str)
    meta = {"fingerprint": fingerprint, "names": [str(n) for n in dep.names], "policy_dt": float(dep.policy_dt),
            "floating": bool(dep.floating)}
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        np.savez_compressed(f, meta=np.array(json.dumps(meta)), **arrays)
    os.replace(tmp, path)


def read_deployment(path) -> tuple[Deployment, dict]:
    """The deployment stored at ``path`` and its fingerprint; raises ``OSError``, ``ValueError``, ``KeyError``,
    ``TypeError`` or ``zipfile.BadZipFile`` where the file is not one :func:`save_deployment` wrote."""
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        got = {k: z[k] for k in z.files if k != "meta"}
    if "cause" in got:  # as :func:`~.evaluate.deploy` makes it
        got["cause"] = np.array([str(c) for c in got["cause"]], dtype=object)
    dep = Deployment(names=list(meta["names"]), policy_dt=float(meta["policy_dt"]), floating=bool(meta["floating"]),
                     **got)
    return dep, meta["fingerprint"]


def policy_fingerprint(run_dir) -> dict | None:
    """What a skill run folder deploys: its ``policy.pt``'s SHA-256 and its last checkpoint's iteration (``None``:
    the reference, no policy)."""
    if run_dir is None:
        return None
    run_dir = Path(run_dir)
    ckpt = latest_checkpoint(run_dir)
    return {"policy_sha256": file_sha256(run_dir / "policy.pt"),
            "iteration": int(ckpt.stem.split("_")[1]) if ckpt is not None else None}


def run_fingerprint(run) -> dict | None:
    """The SHA-256 of the files a simulator is built from in a fit run folder (``physics.json``, the residual's
    ``policy.pt``: :func:`~.plants.sim_plant`), ``None`` without a run."""
    if run is None:
        return None
    return {f: file_sha256(Path(run) / f) for f in ("physics.json", "policy.pt") if (Path(run) / f).is_file()}


def motions_digest(motions) -> str:
    """SHA-256 (hex) of a list of :class:`~.motions.Motion`: names, families and trajectories, in order."""
    h = hashlib.sha256()
    for m in motions:
        h.update(json.dumps([m.name, m.family]).encode())
        for a in (m.q, m.base):
            if a is not None:
                h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()


class DeploymentStore:
    """A run folder's ``deployments/``: :meth:`deploy` reads a deployment back or runs it, :meth:`record` appends
    the held-out scoring to the ledgers under their rule.

    Args:
        folder: The run folder.
        common: The fingerprint's fields every deployment shares (JSON values): ``task``, ``motions`` (the set's
            fingerprint), and ``real`` and ``sim``, each plant's settings.
        log: Printer of the one-line notes.
    """

    def __init__(self, folder, common: dict, log=print):
        self.folder = Path(folder) / DEPLOYMENTS
        self.common = common
        self.log = log
        self.deployed = set()
        """``(split, where)`` of the deployments this session ran (not read back)."""
        self._policies: dict[tuple[Path, str], object] = {}
        """The skills loaded by :meth:`deploy`, by run folder and ``policy.pt``'s SHA-256: each is deployed on two
        splits and two plants, and loading one (a ``torch.export`` program) takes a few tenths of a second; an
        inference-only program, the same for every deployment."""

    def path(self, split: str, where: str, name: str) -> Path:
        """Where deployment ``name`` of ``split`` on ``where`` (``real`` or ``sim``) is kept."""
        return self.folder / split / f"{where}_{name}.npz"

    def fingerprint(self, split: str, where: str, name: str, run_dir, motions, plant: dict | None = None) -> dict:
        """Every input of one deployment, as JSON keeps it; ``plant``: what only this one's plant has (the sim's
        setting and correction)."""
        return _plain({"version": VERSION, "split": split, "where": where, "name": name,
                       "policy": policy_fingerprint(run_dir), "task": self.common["task"],
                       "motions": {"set": self.common["motions"], "digest": motions_digest(motions)},
                       "plant": {**self.common[where], **(plant or {})}})

    def _read(self, path: Path):
        if not path.is_file():
            return None
        try:
            return read_deployment(path)
        except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile) as e:
            self.log(f"warning: {path} cannot be read ({type(e).__name__}: {str(e).splitlines()[0][:120]}); "
                     "deploying again")
            return None

    def deploy(self, split: str, where: str, name: str, run_dir, motions, run, plant: dict | None = None):
        """The deployment of the skill in ``run_dir`` (``None``: the reference) on ``motions``: read back where stored
        with this fingerprint, else ``run(policy)``'s (``policy``: the loaded skill, ``None`` for the reference),
        written."""
        path = self.path(split, where, name)
        want = self.fingerprint(split, where, name, run_dir, motions, plant)
        stored = self._read(path)
        if stored is not None:
            diff = first_difference(stored[1], want)
            if diff is None:
                self.log(f"[4/4] {name} on the {where} plant, {split}: deployed earlier, reused ({path})")
                return stored[0]
            self.log(f"[4/4] {name} on the {where} plant, {split}: deployed earlier with {diff[0]} = "
                     f"{json.dumps(diff[1])[:80]}, now {json.dumps(diff[2])[:80]}: deployed again")
        policy = None
        if run_dir is not None:
            key = (Path(run_dir), want["policy"]["policy_sha256"])
            if key not in self._policies:
                self._policies[key] = load_skill(run_dir)
            policy = self._policies[key]
        dep = run(policy)
        save_deployment(path, dep, want)
        self.deployed.add((split, where))
        return dep

    def record(self, ledgers, config: dict, seed: int, figures: dict, n_motions: int) -> list[Path]:
        """Append the held-out scoring to ``ledgers`` (:func:`~.ledger.record_heldout`): to every one where this
        session deployed on held-out motions on the real robot, else to those without this scoring (the same
        configuration, seed, motion count and figures); returns the ledgers written."""
        ledgers = list(dict.fromkeys(Path(p) for p in ledgers))
        if ("heldout", "real") not in self.deployed:
            line = (config_hash(config), int(seed), int(n_motions), _text(figures))
            ledgers = [p for p in ledgers if not any(
                (e["config_hash"], e["seed"], e["heldout_motions"], _text(e["figures"])) == line
                for e in read_ledger(p))]
            if not ledgers:
                self.log("[4/4] held-out deployments all read back: their scoring is in the ledger already")
        if ledgers:
            record_heldout(ledgers, config, seed, figures, n_motions)
        return ledgers


def deploy_all(store: DeploymentStore, settings: dict, skills, motions, real_plant, sim, task, robot, in_sim: dict,
               sim_plant) -> tuple[dict, dict, dict]:
    """Deploy the reference and every policy on the validation and held-out motions on the real robot, and each
    (but the oracle) in the simulator it trained in, each read back from ``store`` where it was deployed earlier.

    Args:
        store: The run folder's deployments.
        settings: Per policy name (and ``reference``) the simulator it trained in (``"real"``, ``None``: none).
        skills: The folder of the skill run folders (one per policy name).
        motions: The :class:`~.motions.MotionSet` with ``validation`` and ``heldout`` splits.
        real_plant, sim: Plant makers: ``real_plant(worlds)``, ``sim(setting, worlds)``.
        task: The task config.
        robot: The robot on its stand (the stand's metrics' forward kinematics).
        in_sim: ``{(split, name): metrics}`` of simulator deployments done before (kept as they are).
        sim_plant: ``sim_plant(setting)``: the fingerprint fields of a setting's simulator.

    Returns:
        ``metrics`` per split and name on the real robot, their means in the simulators, and the held-out
        deployments on the real robot per name (the report's rollouts).
    """
    real, in_sims, rollouts = {}, {}, {}
    for split in ("validation", "heldout"):
        mot = motions.split(split)
        real[split], in_sims[split] = {}, {}
        for name, setting in settings.items():
            run_dir = None if name == "reference" else Path(skills) / name
            dep = store.deploy(split, "real", name, run_dir, mot, lambda p: deploy(p, real_plant(len(mot)), mot, task))
            real[split][name] = metrics(dep, robot)
            if split == "heldout":
                rollouts[name] = dep
            if (split, name) in in_sim:
                in_sims[split][name] = in_sim[split, name]["mean"]
            elif setting not in ("real", None):
                dep = store.deploy(split, "sim", name, run_dir, mot,
                                   lambda p: deploy(p, sim(setting, len(mot)), mot, task), sim_plant(setting))
                in_sims[split][name] = metrics(dep, robot)["mean"]
    return real, in_sims, rollouts


def _text(figures: dict) -> str:
    """``figures`` as the ledger writes them (equal text for equal figures, NaN included)."""
    return json.dumps(json.loads(json.dumps(figures, sort_keys=True, default=str)), sort_keys=True)
