"""A benchmark's drawn motions kept in its run folder (``motions.npz``), so that a resumed run reads them back instead
of drawing and screening them again (minutes on the floor, while the accelerator waits).

The file holds plain arrays (read with ``allow_pickle=False``) and one JSON string: the motions' names, families,
screening reports and drawn parameters, and the *fingerprint* of every input that determines the draw (the robot
file and its hash, the seed, the counts per split, the length and rate, the screening, the families and the motion
generator's constants). A run whose fingerprint differs is refused in one line naming the first differing field:
its policies were trained on the stored motions, and drawing others over them would mix two draws in one run. A
missing file is drawn and written; an unreadable one (a run killed while writing it cannot leave one: it is written
to a temporary file and renamed) is drawn again after a one-line warning and overwritten.

The held-out motions of a run that picks its held-out families once its nominal policy is known are kept beside the
others with the families they were drawn for: a different pick (the policy trained further) draws them again, which
loses nothing (no policy trains on held-out motions).
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np

from ..errors import WresdynError
from ..learn.config_diff import first_difference
from ..paths import REPO, file_sha256
from . import families, feasibility, motions
from .motions import Motion, MotionSet, joint_velocity

__all__ = ["MOTIONS_FILE", "MotionStore", "motion_fingerprint", "save_motions", "read_motions"]

MOTIONS_FILE = "motions.npz"
"""The file's name in a run folder."""
_ARRAYS = ("q", "feet", "base", "planted")
"""The array fields of :class:`~.motions.Motion` kept (``base``, ``planted``: on the floor only); the velocities are
computed again from ``q`` on reading (:func:`~.motions.joint_velocity`, as drawn). Without them and compressed, a
motion of 4 s at 500 Hz takes about 0.1 MB instead of 0.9 MB: a full-size run's 130 motions stay small enough to carry
its folder between machines."""


def _generator() -> dict:
    """The motion generator's constants that change what a seed draws."""
    return {"task_families": {k: [list(f.train), list(f.held_out), list(f.extra)]
                              for k, f in families.TASK_FAMILIES.items()},
            "stance": families.STANCE, "floor_transfer_s": families.FLOOR_TRANSFER_S,
            "floor_across_s": families.FLOOR_ACROSS_S, "floor_swing_s": families.FLOOR_SWING_S,
            "combo_transfer_s": families.COMBO_TRANSFER_S, "slower": motions.SLOWER, "unscreened": motions.UNSCREENED,
            "planted_tol": motions.PLANTED_TOL, "screen_every_s": feasibility.SCREEN_EVERY_S,
            "screen_skip_s": feasibility.SCREEN_SKIP_S}


def _robot_file(source) -> str:
    """The robot file's path, relative to the repository where it lies inside it (the same in every clone)."""
    path = Path(source).resolve()
    try:
        return str(path.relative_to(REPO))
    except ValueError:
        return str(path)


def _plain(x):
    """``x`` as JSON keeps it (tuples as lists, NumPy scalars and arrays as numbers and lists)."""
    def default(v):
        return v.tolist() if isinstance(v, (np.ndarray, np.generic)) else str(v)

    return json.loads(json.dumps(x, default=default))


def motion_fingerprint(robot, counts: dict, duration: float, rate_hz: float, seed: int, *, floor: bool,
                       screen: bool, extra=(), heldout_families: str = "all") -> dict:
    """Every input that determines a benchmark's draw of its motions, as JSON keeps it: ``robot`` the robot on its
    stand (its file and the file's SHA-256, its gains config), ``counts`` the motions per family and split, ``duration``
    [s], ``rate_hz`` [Hz], ``seed``, ``floor`` (placed on the floor), ``screen`` (the floor's feasibility screening),
    ``extra`` families, ``heldout_families`` (``"balanced"``: the held-out ones drawn later) and the generator's
    constants."""
    return _plain({"robot": {"file": _robot_file(robot.source), "sha256": file_sha256(robot.source),
                             "gains": robot.gains},
                   "seed": int(seed), "counts": dict(counts), "duration_s": float(duration), "rate_hz": float(rate_hz),
                   "task": {"floor": bool(floor)}, "screen": bool(screen), "extra": list(extra),
                   "heldout_families": heldout_families, "generator": _generator()})


def save_motions(path, motion_set: MotionSet, fingerprint: dict, heldout: dict | None = None) -> None:
    """Write ``motion_set`` with its ``fingerprint`` (and ``heldout``, the record of a later held-out draw) to
    ``path``, atomically: a temporary file beside it, then renamed over it."""
    path = Path(path)
    arrays, index = {}, []
    for split, ms in motion_set.splits.items():
        for m in ms:
            i = len(index)
            index.append({"split": split, "name": m.name, "family": m.family, "screen": m.screen,
                          "params": _plain(m.params), "arrays": [a for a in _ARRAYS if getattr(m, a) is not None]})
            arrays.update({f"{i}_{a}": getattr(m, a) for a in index[-1]["arrays"]})
    meta = {"fingerprint": fingerprint, "heldout": heldout, "rate_hz": motion_set.rate_hz,
            "splits": list(motion_set.splits), "motions": index}
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        np.savez_compressed(f, meta=np.array(json.dumps(meta)), **arrays)
    os.replace(tmp, path)


def read_motions(path) -> tuple[MotionSet, dict]:
    """The motion set stored at ``path`` and the file's record (``fingerprint``, ``heldout``); raises ``OSError``,
    ``ValueError``, ``KeyError`` or ``zipfile.BadZipFile`` where the file is not one :func:`save_motions` wrote."""
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        splits = {s: [] for s in meta["splits"]}
        for i, m in enumerate(meta["motions"]):
            got = {a: z[f"{i}_{a}"] for a in m["arrays"]}
            qd = joint_velocity(got["q"], float(meta["rate_hz"]))
            splits[m["split"]].append(Motion(m["name"], m["family"], got["q"], qd, got["feet"], m["params"],
                                             base=got.get("base"), planted=got.get("planted"), screen=m["screen"]))
    return MotionSet(float(meta["rate_hz"]), splits), meta


class MotionStore:
    """A run folder's ``motions.npz``: :meth:`motions` reads or draws the run's motions, :meth:`heldout` its later
    held-out draw."""

    def __init__(self, folder, fingerprint: dict, log=print):
        self.path = Path(folder) / MOTIONS_FILE
        self.fingerprint = fingerprint
        self.log = log

    def _read(self) -> tuple[MotionSet, dict] | None:
        """The stored set and record; ``None`` where there is none or it cannot be read (warned)."""
        if not self.path.is_file():
            return None
        try:
            return read_motions(self.path)
        except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile) as e:
            self.log(f"warning: {self.path} cannot be read ({type(e).__name__}: {str(e).splitlines()[0][:120]}); "
                     "drawing the motions again")
            return None

    def motions(self, draw, trained=()) -> MotionSet:
        """The stored motions where their fingerprint is this run's; else ``draw()``'s, written. Raises a one-line
        :class:`~wresdyn.errors.WresdynError` where the stored ones were drawn from other inputs (naming the policies
        ``trained`` on them)."""
        stored = self._read()
        if stored is None:
            motion_set = draw()
            save_motions(self.path, motion_set, self.fingerprint)
            return motion_set
        diff = first_difference(stored[1]["fingerprint"], self.fingerprint)
        if diff:
            field, old, new = diff
            on = f" ({', '.join(trained)} trained on them)" if trained else ""
            raise WresdynError(f"{self.path}: the run's motions were drawn with {field} = {json.dumps(old)}, this run "
                               f"asks for {json.dumps(new)}{on}; resume with the same settings or choose another "
                               "folder")
        self.log(f"motions loaded from {self.path}")
        return stored[0]

    def heldout(self, motion_set: MotionSet, kept, draw):
        """The held-out motions of the families ``kept`` and ``draw()``'s note with them: the stored ones where they
        were drawn for ``kept``, else ``draw()``'s (motions, note), written beside ``motion_set``'s other splits."""
        record = {"kept": list(kept)}
        stored = self._read()
        if stored is not None and stored[1]["heldout"] and stored[1]["heldout"]["kept"] == record["kept"]:
            self.log(f"held-out motions loaded from {self.path}")
            return stored[0].split("heldout"), stored[1]["heldout"]["note"]
        held, note = draw()
        splits = {**{s: ms for s, ms in motion_set.splits.items() if s != "heldout"}, "heldout": held}
        save_motions(self.path, MotionSet(motion_set.rate_hz, splits), self.fingerprint, {**record, "note": note})
        return held, note
