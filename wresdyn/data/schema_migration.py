"""Rewrite a schema-1 dataset file as schema 2, optionally giving it a validation split.

Schema 2 adds the validation split, on which every choice (hyper-parameters, early stopping, sweeps) is made;
held-out and OOD are for reporting only (docs/dataset.md). A schema-1 file has no validation trajectories.
With ``validation=K``:

* a dataset recorded by ``wresdyn collect`` on the simulated real robot (its header has the mismatch, the seed
  and the generator meta) gets K validation trajectories recorded exactly as ``collect`` records them: same
  seeds (:data:`~wresdyn.data.real_robot.SPAWN_KEYS`), mismatch, excitation config, duration, rate and torque
  storage. The file's first trajectory is re-recorded alongside and must come out bit for bit: otherwise the
  robot (file or gains) or the libraries differ from the recording's, and the new trajectories would come
  from another robot than the rest of the data;
* any other dataset (real logs) cannot record more: its last K training trajectories become the validation
  split.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .dataset import SCHEMA_VERSION, SPLITS, Dataset, DatasetError, load_dataset, read_header
from .excitation import ExcitationConfig
from .loading import dataset_robot
from .mismatch import Mismatch
from .real_robot import collect

__all__ = ["Migration", "migrate", "recorded_by_collect"]


@dataclass(frozen=True)
class Migration:
    """The result of :func:`migrate`."""

    dataset: Dataset
    """The dataset as schema 2 (not saved yet); ``meta["migration"]`` records what was done."""
    from_version: int
    """Schema version of the file read."""
    how: str
    """How the validation split was made: ``"recorded"``, ``"moved from train"`` or ``"none"``."""
    names: list[str]
    """Names of the validation trajectories added or moved, in file order."""
    robot: object = None
    """The :class:`~wresdyn.robot.description.Robot` the validation trajectories were recorded on (``None`` when
    nothing was recorded)."""


def recorded_by_collect(ds: Dataset) -> bool:
    """True when ``ds`` was recorded by ``wresdyn collect`` on the simulated real robot, so it can record more."""
    return bool(ds.mismatch) and ds.seed is not None and ds.meta.get("generator") == "wresdyn collect"


def migrate(path, validation: int = 0, robot=None, progress=None) -> Migration:
    """Read a schema-1 dataset file and return it as schema 2 with ``validation`` validation trajectories.

    Args:
        path: The schema-1 ``.npz`` file; a file already at :data:`~wresdyn.data.dataset.SCHEMA_VERSION` is refused.
        validation: Number of validation trajectories to record (simulated data) or move from train (real logs).
        robot: Robot to record on (default: the file's ``robot_file``, as :func:`~wresdyn.data.loading.load_data`
            finds it, with the gains config stored in the file, if any); only used when recording.
        progress: Optional ``callable(str)`` receiving progress lines.

    Raises:
        DatasetError: one line naming the file; nothing is written either way.
    """
    path = Path(path)
    version = read_header(path)["schema_version"]
    if version == SCHEMA_VERSION:
        raise DatasetError(f"{path}: already schema version {SCHEMA_VERSION}, nothing to migrate")
    if isinstance(validation, bool) or not isinstance(validation, int) or validation < 0:
        raise DatasetError(f"{path}: the number of validation trajectories must be an integer >= 0, not {validation!r}")
    ds = load_dataset(path)
    if validation == 0:
        how, names, used, ds_new = "none", [], None, ds
    elif recorded_by_collect(ds):
        how = "recorded"
        ds_new, names, used = _record_validation(ds, validation, robot, path, progress)
    else:
        how, used = "moved from train", None
        ds_new, names = _move_from_train(ds, validation, path)
    record = {"from_schema_version": version, "to_schema_version": SCHEMA_VERSION, "validation": how,
              "trajectories": names}
    ds_new = dataclasses.replace(ds_new, meta={**ds_new.meta, "migration": record})
    return Migration(ds_new, version, how, names, used)


def _in_split_order(trajs: list) -> list:
    """Trajectories grouped by split in :data:`SPLITS` order (the order ``collect`` writes), stable within one."""
    return sorted(trajs, key=lambda tr: SPLITS.index(tr.split))


def _move_from_train(ds: Dataset, k: int, path: Path) -> tuple[Dataset, list[str]]:
    train = ds.split("train")
    if k >= len(train):
        raise DatasetError(f"{path}: cannot move {k} of its {len(train)} training trajectories to validation: at "
                           f"least one must stay in train")
    moved = {tr.name for tr in train[-k:]}
    trajs = [dataclasses.replace(tr, split="validation") if tr.name in moved else tr for tr in ds.trajectories]
    trajs = _in_split_order(trajs)
    return dataclasses.replace(ds, trajectories=trajs), [tr.name for tr in trajs if tr.name in moved]


def _record_validation(ds: Dataset, k: int, robot, path: Path, progress):
    meta = ds.meta
    if not isinstance(meta.get("duration_s"), (int, float)) or not isinstance(meta.get("excitation"), dict):
        raise DatasetError(f"{path}: meta lacks the collect parameters (duration_s, excitation) to record more")
    names = {f.name for f in dataclasses.fields(ExcitationConfig)}
    unknown = sorted(set(meta["excitation"]) - names)
    if unknown:
        raise DatasetError(f"{path}: meta excitation config has unknown field(s) {unknown}")
    # JSON turned the config's tuples into lists
    cfg = ExcitationConfig(**{key: tuple(v) if isinstance(v, list) else v for key, v in meta["excitation"].items()})
    mismatch = Mismatch.from_dict(ds.mismatch, where=f"{path}: header mismatch")
    ref = next((tr for s in ("train", "heldout", "ood") for tr in ds.split(s) if tr.name == f"{s}_000"), None)
    if ref is None:
        raise DatasetError(f"{path}: no trajectory train_000, heldout_000 or ood_000 to check the re-recording against")
    robot = robot if robot is not None else dataset_robot(ds.robot_file, gains=ds.gains_config)
    ds = ds.for_robot(robot, str(path))
    ref = next(tr for tr in ds.trajectories if tr.name == ref.name)
    if progress:
        progress(f"recording {k} validation trajectories, and {ref.name} again to check it is reproduced exactly")
    new = collect(robot, mismatch, {ref.split: 1, "validation": k}, float(meta["duration_s"]), ds.rate_hz, ds.seed,
                  cfg, store_tau=ref.tau is not None, progress=progress)
    again = next(tr for tr in new.trajectories if tr.name == ref.name)
    fields = ("t", "q", "qd", "q_cmd") + (("tau",) if ref.tau is not None else ())
    differ = [f for f in fields if not np.array_equal(getattr(again, f), getattr(ref, f))]
    if differ:
        worst = max(_max_abs_diff(getattr(again, f), getattr(ref, f)) for f in differ)
        raise DatasetError(f"{path}: re-recording {ref.name} does not reproduce it ({', '.join(differ)} differ, by up "
                           f"to {worst:.3g}): the robot file, its gains or the library versions are not the "
                           f"recording's, so new trajectories would come from another robot")
    added = new.split("validation")
    params = {**meta.get("trajectory_params", {}), **{tr.name: new.meta["trajectory_params"][tr.name] for tr in added}}
    out = dataclasses.replace(ds, trajectories=_in_split_order(ds.trajectories + added),
                              meta={**meta, "trajectory_params": params})
    return out, [tr.name for tr in added], robot


def _max_abs_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max()) if a.shape == b.shape else float("inf")
