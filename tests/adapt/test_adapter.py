"""The online identifier (:mod:`wresdyn.adapt`): an update is kept only when it lowers the held-back error, published
as a physics file with its time; the stream's bad input is refused in one line, by the adapter and by ``wresdyn
adapt``."""

import json

import numpy as np
import pytest

from wresdyn.adapt.adapter import Adapter, StreamError
from wresdyn.adapt.config import ADAPT_FIT, AdaptConfig
from wresdyn.adapt.stream import dataset_blocks, text_blocks
from wresdyn.cli import main
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.sim.physics import SERVO_FIELDS, PhysicalParams

REAL = Mismatch(kp_scale=0.8, kd_scale=1.3, friction=0.03, damping=0.3, torque_limit_scale=0.5)
"""The real robot of these tests: gains, friction, damping and saturation off the file's, no delay, no noise."""
TINY = AdaptConfig(window=1.2, holdout=0.3, update_every=0.4, iterations=3, windows=4, horizon=16, one_step_every=10,
                   confirm=False)
"""A few updates on 1.6 s of stream; each candidate is decided on its own held-back part."""


@pytest.fixture(scope="module")
def stream(humanoid, record):
    return record(humanoid, REAL, {"train": 1}, seconds=1.6, amplitude=0.3)


def _run(adapter, ds):
    return [u for block in dataset_blocks(ds) for u in adapter.push(*block)]


def test_an_update_that_lowers_the_held_back_error_is_accepted_and_published(humanoid, stream, tmp_path):
    # the robot file's physics is far from the real robot's: a few steps toward it lower the held-back error
    start = PhysicalParams.nominal(humanoid)
    adapter = Adapter(humanoid, start, stream.rate_hz, TINY.__class__(**{**TINY.__dict__, "lr": 0.02}),
                      publish=tmp_path)
    updates = _run(adapter, stream)
    assert len(updates) >= 2
    first = updates[0]
    assert first.accepted and first.open_loop_candidate < first.open_loop_before
    assert first.open_loop == first.open_loop_candidate < first.open_loop_start
    last = [u for u in updates if u.accepted][-1]
    assert last.open_loop < 0.9 * last.open_loop_start, (last.open_loop, last.open_loop_start)
    published = PhysicalParams.load(tmp_path / "physics.json", humanoid)
    assert published.friction.tolist() == adapter.physics.friction.tolist()
    assert json.loads((tmp_path / "physics.json").read_text())["t"] == pytest.approx(last.t)
    assert len(list(tmp_path.glob("physics_*.json"))) == sum(u.accepted or u.reverted for u in updates)


def test_a_field_in_fit_is_adapted_and_the_others_keep_the_warm_start(humanoid, stream):
    # friction alone: the real robot's friction is off the file's, so the accepted updates move it toward the truth
    start, truth = PhysicalParams.nominal(humanoid), RealRobot(humanoid, REAL).physics()
    cfg = TINY.__class__(**{**TINY.__dict__, "lr": 0.02, "fit": ("friction",)})
    adapter = Adapter(humanoid, start, stream.rate_hz, cfg)
    updates = _run(adapter, stream)
    assert any(u.accepted for u in updates)
    moved = np.abs(adapter.physics.friction - start.friction)
    assert moved.max() > 0.1 * np.abs(truth.friction - start.friction).max(), moved
    assert np.abs(adapter.physics.friction - truth.friction).mean() < np.abs(start.friction - truth.friction).mean()
    for f in ("kp", "kd", "armature", "damping", "effort", "delay", "body_mass"):  # to rounding of their coordinates
        np.testing.assert_allclose(getattr(adapter.physics, f), getattr(start, f), rtol=1e-12, err_msg=f)


def test_fit_accepts_exactly_the_fields_the_adapter_steps(humanoid):
    # every field AdaptConfig accepts is one the adapter's optimiser steps, and every field it steps is one asked for
    adapter = Adapter(humanoid, PhysicalParams.nominal(humanoid), 500.0, TINY)
    assert TINY.fit == ADAPT_FIT
    stepped = {id(p) for g in adapter.optim.param_groups for p in g["params"]}
    fitted = {id(p) for p in adapter.model.parameters() if p.requires_grad}
    assert stepped == fitted
    for name in ("u_delay", *(f"u_{f}" for f in SERVO_FIELDS)):
        assert id(getattr(adapter.model, name)) not in stepped, name
    # the delay and the servo drive's fields are not adapted: asking for one is refused in one line naming the rest
    for field in ("delay", *SERVO_FIELDS):
        with pytest.raises(ValueError) as e:
            AdaptConfig(fit=("kp", field))
        message = str(e.value)
        assert "\n" not in message and f"[{field!r}] cannot be adapted" in message
        assert message.endswith(f"choose from {list(ADAPT_FIT)}"), message


def test_an_update_that_raises_the_held_back_error_is_rejected(humanoid, stream, tmp_path):
    # the truth itself as the warm start, and steps far too large: every candidate is worse and none is kept
    truth = RealRobot(humanoid, REAL).physics()
    adapter = Adapter(humanoid, truth, stream.rate_hz, TINY.__class__(**{**TINY.__dict__, "lr": 1.0}),
                      publish=tmp_path)
    updates = _run(adapter, stream)
    assert updates and not any(u.accepted for u in updates)
    for u in updates:
        assert u.open_loop_candidate > u.open_loop_before == u.open_loop == u.open_loop_start
    assert adapter.physics is truth
    assert not list(tmp_path.glob("physics*.json"))


def test_with_confirmation_a_winner_becomes_the_model_one_update_later(humanoid, stream, tmp_path):
    start = PhysicalParams.nominal(humanoid)
    cfg = TINY.__class__(**{**TINY.__dict__, "lr": 0.02, "confirm": True, "update_every": 0.2, "confirm_leave": 1})
    adapter = Adapter(humanoid, start, stream.rate_hz, cfg, publish=tmp_path)
    updates = _run(adapter, stream)
    assert not updates[0].accepted and updates[0].pending  # the first winner waits
    accepted = [i for i, u in enumerate(updates) if u.accepted]
    assert accepted, [(u.pending, u.open_loop_candidate, u.open_loop_before) for u in updates]
    for i in accepted:  # only the last update's winner is published, and only where it wins again
        assert i > 0 and updates[i - 1].pending
        assert updates[i].open_loop < (1 - cfg.min_gain) * updates[i].open_loop_before
    assert len(list(tmp_path.glob("physics_*.json"))) == sum(u.accepted or u.reverted for u in updates)


def test_with_persist_a_candidate_that_loses_goes_on_from_where_it_is(humanoid, stream):
    # the truth as the warm start and steps far too large: every candidate loses. Without persist each update starts
    # again from the model; with it the next update trains on from the last candidate, unless that candidate's
    # held-back error is above persist times the model's
    truth = RealRobot(humanoid, REAL).physics()

    def candidates(persist):
        cfg = TINY.__class__(**{**TINY.__dict__, "lr": 1.0, "persist": persist})
        updates = _run(Adapter(humanoid, truth, stream.rate_hz, cfg), stream)
        assert not any(u.accepted for u in updates)
        return [u.open_loop_candidate for u in updates]

    back, on, reset = candidates(0.0), candidates(1e9), candidates(1.0)
    assert len(back) >= 3
    assert on[0] == back[0] and on[1:] != back[1:]
    assert reset == back


def test_to_leave_the_warm_start_a_winner_must_win_confirm_leave_times_in_a_row(humanoid, stream, tmp_path):
    # the robot file's physics is far from the real robot's: the first winner goes on winning; it waits for two
    # more held-back parts before it becomes the model, and the training goes on from it meanwhile
    start = PhysicalParams.nominal(humanoid)
    cfg = TINY.__class__(**{**TINY.__dict__, "lr": 0.02, "confirm": True, "update_every": 0.2, "confirm_leave": 2,
                            "detect": False})
    adapter = Adapter(humanoid, start, stream.rate_hz, cfg, publish=tmp_path)
    updates = _run(adapter, stream)
    first = next((i for i, u in enumerate(updates) if u.accepted), None)
    assert first is not None, [(u.pending, u.open_loop_candidate, u.open_loop_before) for u in updates]
    assert first >= 2 and updates[first - 1].pending and updates[first - 2].pending
    # it won on each held-back part it waited on, against the warm start (the model meanwhile)
    for u in updates[first - 1:first + 1]:
        assert u.open_loop_before == u.open_loop_start
    assert updates[first].open_loop < (1 - cfg.min_gain) * updates[first].open_loop_before
    # once the model has left the warm start, a winner needs one held-back part (as with confirm_leave = 1)
    later = [i for i, u in enumerate(updates) if u.accepted and i > first]
    assert all(updates[i - 1].pending for i in later)


def test_the_model_goes_back_to_the_warm_start_where_that_is_better(humanoid, stream, tmp_path):
    # the truth as the warm start, the current model set far from it: on the first held-back part the warm start
    # wins, so the model goes back to it (published) unless the candidate beats the truth by the margin, which a few
    # small steps from the far model cannot
    truth = RealRobot(humanoid, REAL).physics()
    cfg = TINY.__class__(**{**TINY.__dict__, "lr": 0.001, "fallback": True})
    adapter = Adapter(humanoid, truth, stream.rate_hz, cfg, publish=tmp_path)
    adapter.physics = PhysicalParams.nominal(humanoid)
    u = _run(adapter, stream)[0]
    assert u.reverted and not u.accepted and adapter.physics is truth
    assert u.open_loop == u.open_loop_start < u.open_loop_before
    assert PhysicalParams.load(tmp_path / "physics.json", humanoid).kp.tolist() == truth.kp.tolist()
    off = Adapter(humanoid, truth, stream.rate_hz, cfg.__class__(**{**cfg.__dict__, "fallback": False}))
    off.physics = PhysicalParams.nominal(humanoid)
    assert not _run(off, stream)[0].reverted and off.physics is not truth


def test_each_update_rewrites_the_exported_robot(humanoid, stream, tmp_path):
    from wresdyn.export.usd import write_export
    from wresdyn.robot.description import load_robot

    start = PhysicalParams.nominal(humanoid)
    export = tmp_path / "calibrated"
    adapter = Adapter(humanoid, start, stream.rate_hz, TINY.__class__(**{**TINY.__dict__, "lr": 0.02}),
                      export=export)
    assert json.loads((export / "export.json").read_text())["t"] is None  # the warm start, before any update
    updates = _run(adapter, stream)
    last = [u for u in updates if u.accepted or u.reverted][-1]
    assert json.loads((export / "export.json").read_text())["t"] == pytest.approx(last.t)
    want = adapter.physics
    assert not np.allclose(want.friction, start.friction)  # the updates moved it
    assert PhysicalParams.load(export / "physics.json", humanoid).friction.tolist() == want.friction.tolist()
    cal = load_robot(export / "robot.usda")  # Newton's USD importer reads the layer the adapter rewrote
    for f in ("kp", "kd", "armature", "damping", "friction", "effort"):
        np.testing.assert_allclose(getattr(cal, f), getattr(want, f), rtol=1e-5, err_msg=f)
    np.testing.assert_allclose(cal.body_mass, want.body_mass, rtol=1e-6)
    np.testing.assert_allclose(cal.body_inertia, want.body_inertia, atol=1e-6 * np.abs(want.body_inertia).max())
    # a write that fails half way (a file to copy in is missing) leaves the last export as it was, no temp folder
    before = {p.name: p.read_bytes() for p in export.iterdir() if p.is_file()}
    with pytest.raises(FileNotFoundError):
        write_export(export, humanoid, start, stream.rate_hz, {}, files={"residual.pt2": tmp_path / "missing.pt"})
    assert {p.name: p.read_bytes() for p in export.iterdir() if p.is_file()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calibrated"]


def test_an_export_needs_a_usd_robot_or_its_converter(cartpole, tmp_path, monkeypatch):
    """A URDF robot exports through its conversion to USD: without the converter the adapter stops before it starts."""
    from wresdyn.export.usd import ExportError

    monkeypatch.setenv("WRESDYN_USD_CONVERTER_PYTHON", str(tmp_path / "no-python"))
    with pytest.raises(ExportError, match="to USD needs urdf-usd-converter"):
        Adapter(cartpole, PhysicalParams.nominal(cartpole), 500.0, TINY, export=tmp_path / "calibrated")
    assert not (tmp_path / "calibrated").exists()


def test_the_adapter_refuses_bad_samples(humanoid):
    adapter = Adapter(humanoid, PhysicalParams.nominal(humanoid), 500.0, TINY)
    n = humanoid.n_dof
    z = np.zeros(n)
    adapter.push(0.0, z, z, z)
    with pytest.raises(StreamError, match="does not increase"):
        adapter.push(0.0, z, z, z)
    with pytest.raises(StreamError, match="not finite"):
        adapter.push(0.002, np.full(n, np.nan), z, z)
    with pytest.raises(StreamError, match=f"{n} values"):
        adapter.push(0.002, z[:-1], z[:-1], z[:-1])
    with pytest.raises(StreamError, match="under half the sample period"):
        adapter.push(0.0005, z, z, z)


def test_text_stream_parses_and_names_the_bad_line(humanoid):
    n = humanoid.n_dof
    good = " ".join(["0.0"] + ["0.1"] * 3 * n)
    (t, q, qd, q_cmd), = text_blocks(["# header", "", good], n, block=8)
    assert t.tolist() == [0.0] and q.shape == qd.shape == q_cmd.shape == (1, n)
    with pytest.raises(StreamError, match="x:2: 3 numbers"):
        list(text_blocks([good, "0.002 1 2"], n, where="x"))


def _write_lines(path, rows):
    path.write_text("\n".join(" ".join(f"{v:.9g}" for v in r) for r in rows) + "\n")


@pytest.mark.parametrize("case, message", [
    ("missing_run", "no such run folder"),
    ("no_physics", "no physics.json"),
    ("wrong_dof", "62 numbers, expected 64"),
    ("nan", "not finite"),
    ("unsorted", "does not increase"),
    ("other_robot", "joint"),
])
def test_cli_bad_input_is_one_line_and_exit_2(humanoid, stream, tmp_path, capsys, case, message):
    from wresdyn.robot.description import DEFAULT_ROBOT

    run = tmp_path / "run"
    run.mkdir()
    PhysicalParams.nominal(humanoid).save(run / "physics.json")
    tr = stream.trajectories[0]
    rows = np.column_stack([tr.t, tr.q, tr.qd, tr.q_cmd])[:50]
    if case == "wrong_dof":
        rows = rows[:, :-2]
    elif case == "nan":
        rows[10, 3] = np.nan
    elif case == "unsorted":
        rows[[10, 11]] = rows[[11, 10]]
    log = tmp_path / "log.txt"
    _write_lines(log, rows)
    if case == "missing_run":
        run = tmp_path / "nowhere"
    elif case == "no_physics":
        (run / "physics.json").unlink()
    elif case == "other_robot":
        d = json.loads((run / "physics.json").read_text())
        d["joint_names"] = d["joint_names"][:-1]
        (run / "physics.json").write_text(json.dumps(d))
    code = main(["adapt", str(run), str(log), "--robot", str(DEFAULT_ROBOT), "--out", str(tmp_path / "out"),
                 "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("wresdyn adapt: error:") and message in err, err


def test_cli_replays_a_dataset_and_writes_every_update(humanoid, stream, tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    PhysicalParams.nominal(humanoid).save(run / "physics.json")
    stream.save(tmp_path / "data.npz")
    out = tmp_path / "out"
    code = main(["adapt", str(run), str(tmp_path / "data.npz"), "--out", str(out), "--window", "1.2",
                 "--holdout", "0.3", "--update-every", "0.4", "--iterations", "2", "--windows", "4", "--horizon", "16",
                 "--lr", "0.02", "--confirm-leave", "1", "--track", "friction:*knee", "--export",
                 str(tmp_path / "calibrated")])
    printed = capsys.readouterr().out
    assert code == 0
    summary = json.loads((out / "updates.json").read_text())
    rows = (out / "updates.csv").read_text().splitlines()
    assert summary["n_updates"] == len(summary["updates"]) == len(rows) - 1 >= 2
    assert "friction[left_knee]" in rows[0] and printed.count("friction[left_knee]") == summary["n_updates"]
    assert (out / "adapt.png").is_file()
    assert len(list((out / "physics").glob("physics_*.json"))) == summary["accepted"] + summary["reverted"]
    assert summary["accepted"] >= 1
    published = json.loads((out / "physics" / "physics.json").read_text())
    assert json.loads((tmp_path / "calibrated" / "export.json").read_text())["t"] == published["t"]
    assert (tmp_path / "calibrated" / "robot.usda").is_file()


def test_cli_export_of_a_robot_without_its_converter_is_one_line_and_writes_nothing(cartpole, tmp_path, capsys,
                                                                                     monkeypatch):
    monkeypatch.setenv("WRESDYN_USD_CONVERTER_PYTHON", str(tmp_path / "no-python"))
    run = tmp_path / "run"
    run.mkdir()
    PhysicalParams.nominal(cartpole).save(run / "physics.json")
    n = cartpole.n_dof
    log = tmp_path / "log.txt"
    _write_lines(log, np.column_stack([np.arange(10) / 500.0, np.zeros((10, 3 * n))]))
    code = main(["adapt", str(run), str(log), "--robot", "newton:cartpole.urdf", "--out", str(tmp_path / "out"),
                 "--export", str(tmp_path / "calibrated"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "USD" in err, err
    assert not (tmp_path / "out").exists() and not (tmp_path / "calibrated").exists()
