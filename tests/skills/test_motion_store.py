"""A floor benchmark's drawn motions kept in its run folder (``wresdyn/skills/motion_store.py``): a resumed run reads
back exactly what it drew, refuses motions drawn from other inputs, and draws again over an unreadable file."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from wresdyn.data.mismatch import Mismatch
from wresdyn.errors import WresdynError
from wresdyn.experiments import skills
from wresdyn.experiments.deploy_config import FloorDeployConfig
from wresdyn.experiments.nominal_policy import draw_heldout
from wresdyn.skills.motion_store import MOTIONS_FILE, MotionStore, read_motions
from wresdyn.skills.skill_config import SkillPPOConfig

RATE = 100.0
# the smallest floor draw the screening still slows and redraws in (4 s: shorter motions leave no time to slow)
CFG = FloorDeployConfig(train_per_family=1, validation_per_family=1, heldout_per_family=1, duration=4.0,
                        nominal=None)


class _Stop(Exception):
    """Raised where the benchmark would fit its corrections: the motions are all these tests need."""


def _start(humanoid, out, cfg=CFG, draw_fails: bool = False) -> tuple:
    """Run the benchmark into ``out`` up to its motions; returns the motion set it got and its log lines."""
    got, lines = [], []

    class Recording(MotionStore):
        def motions(self, draw, trained=()):
            got.append(super().motions(draw, trained))
            return got[-1]

    def stop(*args, **kw):
        raise _Stop

    def no_draw(*args, **kw):
        raise AssertionError("the motions were drawn again")

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(skills, "MotionStore", Recording)
        mp.setattr(skills, "fit_corrections", stop)
        if draw_fails:
            mp.setattr(skills, "make_motions", no_draw)
        with pytest.raises(_Stop):
            skills.run_benchmark(humanoid, SimpleNamespace(rate_hz=RATE), out, cfg, mismatch=Mismatch(),
                                 ppo=SkillPPOConfig(torch_threads=1), log=lines.append)
    return got[0], lines


@pytest.fixture(scope="module")
def drawn(humanoid, tmp_path_factory):
    """A run's first start (it draws and writes the file) and a resumed start (it reads it back)."""
    out = tmp_path_factory.mktemp("floor_run")
    first, first_log = _start(humanoid, out)
    again, again_log = _start(humanoid, out, draw_fails=True)
    return out, first, first_log, again, again_log


def _assert_same(a, b) -> None:
    """Every field of two motion sets equal, arrays bit for bit (dtype and shape too)."""
    assert a.rate_hz == b.rate_hz and list(a.splits) == list(b.splits)
    for split in a.splits:
        assert len(a[split]) == len(b[split])
        for x, y in zip(a[split], b[split]):
            assert (x.name, x.family, x.screen) == (y.name, y.family, y.screen)
            assert x.params == y.params
            assert [type(v) for v in x.params.values()] == [type(v) for v in y.params.values()]
            for f in ("q", "qd", "feet", "base", "planted"):
                u, v = getattr(x, f), getattr(y, f)
                assert u.dtype == v.dtype and u.shape == v.shape and u.tobytes() == v.tobytes(), (x.name, f)


def test_a_resumed_floor_run_reads_back_the_motions_it_drew_bit_for_bit(drawn):
    out, first, first_log, again, again_log = drawn
    assert (out / MOTIONS_FILE).is_file()
    assert not any("motions loaded" in ln for ln in first_log)
    assert f"motions loaded from {out / MOTIONS_FILE}" in again_log
    assert sorted(first.splits) == ["train", "validation"]  # balanced: the held-out ones are drawn later
    _assert_same(first, again)
    # the screening report the log prints, with at least one motion the screening changed (else the test is weak)
    assert skills._screened(first) == skills._screened(again)
    assert any(m.screen != "ok" for ms in first.splits.values() for m in ms), skills._screened(first)
    assert [ln for ln in first_log if ln.startswith("[1/4]")][0].split(" (")[0] == \
        [ln for ln in again_log if ln.startswith("[1/4]")][0].split(" (")[0]


@pytest.mark.parametrize("change, field", [({"seed": 1}, "seed"), ({"train_per_family": 2}, "counts.train"),
                                           ({"screen": False}, "screen")])
def test_motions_drawn_from_other_inputs_are_refused_naming_the_field(humanoid, drawn, change, field):
    out = drawn[0]
    (out / "skills" / "a_nominal").mkdir(parents=True, exist_ok=True)  # a policy trained on the stored motions
    before = (out / MOTIONS_FILE).read_bytes()
    with pytest.raises(WresdynError) as e:
        _start(humanoid, out, replace(CFG, **change), draw_fails=True)
    msg = str(e.value)
    assert "\n" not in msg and str(out / MOTIONS_FILE) in msg and f"drawn with {field} = " in msg, msg
    assert "(a_nominal trained on them)" in msg, msg
    assert (out / MOTIONS_FILE).read_bytes() == before  # never drawn over


def test_an_unreadable_file_is_drawn_again_with_a_warning_and_overwritten(drawn, tmp_path):
    out, first = drawn[0], drawn[1]
    fingerprint = read_motions(out / MOTIONS_FILE)[1]["fingerprint"]
    whole = (out / MOTIONS_FILE).read_bytes()
    for bad in (b"not an npz", whole[: len(whole) // 2]):  # garbage; a file cut short
        (tmp_path / MOTIONS_FILE).write_bytes(bad)
        lines, calls = [], []
        store = MotionStore(tmp_path, fingerprint, lines.append)
        got = store.motions(lambda: calls.append(1) or first)
        assert calls == [1] and got is first
        assert len(lines) == 1 and lines[0].startswith("warning: ") and "drawing the motions again" in lines[0]
        _assert_same(read_motions(tmp_path / MOTIONS_FILE)[0], first)  # overwritten with the drawn ones
        assert not list(tmp_path.glob("*.tmp"))


def test_the_later_held_out_draw_is_kept_for_its_families(humanoid, floating, drawn, tmp_path):
    out, first = drawn[0], drawn[1]
    fingerprint = read_motions(out / MOTIONS_FILE)[1]["fingerprint"]
    (tmp_path / MOTIONS_FILE).write_bytes((out / MOTIONS_FILE).read_bytes())
    store = MotionStore(tmp_path, fingerprint, lambda s: None)
    calls = []

    def draw():
        calls.append(1)
        return draw_heldout(humanoid, floating, CFG, RATE, ["squat"])

    held, note = store.heldout(first, ["squat"], draw)
    lines = []
    again, note_again = MotionStore(tmp_path, fingerprint, lines.append).heldout(first, ["squat"], draw)
    assert calls == [1] and lines == [f"held-out motions loaded from {tmp_path / MOTIONS_FILE}"]
    assert note_again == note and note  # the stepping family's reason kept with them
    _assert_same(skills.MotionSet(RATE, {"heldout": held}), skills.MotionSet(RATE, {"heldout": again}))
    # the other splits stay as they were, and a resumed run still reads them
    _assert_same(MotionStore(tmp_path, fingerprint, lambda s: None).motions(lambda: None),
                 skills.MotionSet(RATE, {**first.splits, "heldout": held}))
    # (a) carrying other families after more training: those are drawn
    store.heldout(first, [], lambda: (calls.append(2) or held, {}))
    assert calls == [1, 2]
