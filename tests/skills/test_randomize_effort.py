"""(f)'s effort limits from the data (``Randomization.effort_from_data``): a limit the training data barely saturate is
drawn uniformly from the torque the data demand of it up to its range's upper end; the others keep their ranges, the
default is what it was, and a report without the demand is refused."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

from wresdyn.errors import WresdynError
from wresdyn.learn.runs import RunError, check_resume
from wresdyn.sim.physics import PhysicalParams
from wresdyn.skills.plants import SimPlant
from wresdyn.skills.randomize import NARROW_DEFAULT, Randomization, narrow_ranges

RATE = 500.0


def _report(run, humanoid, demand: bool = True):
    """A tiny ``identify/identifiability.json``: joint 0 never saturated (demand half its limit), joint 1 saturated on
    5 % of the samples, joint 2 on 0.5 % (its demand above the limit), joint 3 not in it; kp of joint 0 with an
    error."""
    j, eff = humanoid.joint_names, PhysicalParams.nominal(humanoid).effort
    report = {"parameters": [{"name": f"kp:{j[0]}", "sensitivity": 0.01, "se": 0.03, "se_pct": 3.0}]}
    if demand:
        report |= {"demanded_effort_nm": {j[0]: 0.5 * eff[0], j[1]: 0.9 * eff[1], j[2]: 1.2 * eff[2]},
                   "effort_saturated": {j[0]: 0.0, j[1]: 0.05, j[2]: 0.005}, "effort_saturated_min": 0.01}
    (run / "identify").mkdir(parents=True)
    (run / "identify" / "identifiability.json").write_text(json.dumps(report))
    return run


def test_the_barely_saturated_limits_draw_from_the_data_demand_up(tmp_path, humanoid):
    run, centre = _report(tmp_path, humanoid), PhysicalParams.nominal(humanoid)
    off, _ = narrow_ranges(Randomization(), humanoid, centre, run)
    on, source = narrow_ranges(Randomization(effort_from_data=True), humanoid, centre, run)
    lo, hi = on.scale["effort"]
    assert (lo[0], hi[0]) == pytest.approx((0.5, 1 + NARROW_DEFAULT))  # never saturated: from the demand
    assert lo[2] == pytest.approx(1.0)  # saturated on 0.5 %: its demand is above the limit, the identified value stays
    assert list(np.flatnonzero(on.effort_uniform)) == [0, 2]
    keep = np.ones(humanoid.n_dof, dtype=bool)
    keep[[0, 2]] = False  # saturated on 5 %, or not in the report: the range they had
    assert np.array_equal(lo[keep], off.scale["effort"][0][keep]) and np.array_equal(hi, off.scale["effort"][1])
    assert "2 joints" in source and off.effort_uniform is None


def test_the_draw_is_uniform_there_and_every_other_draw_unchanged(tmp_path, humanoid):
    """Two plants of one seed, the option off and on: the same random stream, so each world's effort factor of joint 0
    is lo + u (hi - lo) where the other plant's is lo (hi / lo)^u; every other joint and field is drawn the same."""
    torch.set_num_threads(1)
    run, centre = _report(tmp_path, humanoid), PhysicalParams.nominal(humanoid)
    plants = []
    for cfg in (Randomization(seed=2), Randomization(seed=2, effort_from_data=True)):
        plants.append(SimPlant(humanoid, 8, RATE, 5, randomization=(cfg, narrow_ranges(cfg, humanoid, centre, run)[0])))
    logs, unis = (p.randomizer.values for p in plants)
    x_log = (logs["effort"][:, 0] / centre.effort[0]).double().numpy()
    x_uni = (unis["effort"][:, 0] / centre.effort[0]).double().numpy()
    lo_off, hi = 1 / (1 + NARROW_DEFAULT), 1 + NARROW_DEFAULT
    u = np.log(x_log / lo_off) / np.log(hi / lo_off)
    assert np.allclose(x_uni, 0.5 + u * (hi - 0.5), atol=1e-5)
    assert (x_uni >= 0.5 - 1e-6).all() and (x_uni <= hi + 1e-6).all() and x_uni.min() < lo_off
    for f in logs:
        same = logs[f] if f != "effort" else logs[f][:, [1, 3, 4]]
        other = unis[f] if f != "effort" else unis[f][:, [1, 3, 4]]
        assert torch.equal(same, other), f
    assert np.array_equal(plants[0].randomizer.delay, plants[1].randomizer.delay)


def test_off_the_ranges_and_the_record_are_those_from_before(tmp_path, humanoid):
    """A report with the demand and one without give the default the same ranges; the record has no new field, the
    option on records it for (f) alone, and a change is refused on resume."""
    centre = PhysicalParams.nominal(humanoid)
    new, new_source = narrow_ranges(Randomization(), humanoid, centre, _report(tmp_path / "new", humanoid))
    old, old_source = narrow_ranges(Randomization(), humanoid, centre, _report(tmp_path / "old", humanoid, False))
    for f in new.scale:
        assert all(np.array_equal(a, b) for a, b in zip(new.scale[f], old.scale[f])), f
    assert new.effort_uniform is None and new_source.replace("new", "old") == old_source
    assert "effort_from_data" not in Randomization().record()
    on = Randomization(effort_from_data=True)
    assert on.record()["effort_from_data"] is True and "effort_from_data" not in on.record(narrow=False)
    recorded = {"randomization": json.loads(json.dumps(Randomization().record()))}
    check_resume(tmp_path, recorded, {"randomization": Randomization().record()})
    with pytest.raises(RunError, match="effort_from_data"):
        check_resume(tmp_path, recorded, {"randomization": on.record()})
    assert dataclasses.asdict(Randomization())["effort_from_data"] is False


@pytest.mark.parametrize("demand, match", [(False, "no `demanded_effort_nm`"), (None, "no identifiability report")])
def test_a_report_without_the_demand_is_refused_in_one_line(tmp_path, humanoid, demand, match):
    run = tmp_path if demand is None else _report(tmp_path, humanoid, demand)
    centre = PhysicalParams.nominal(humanoid)
    narrow_ranges(Randomization(), humanoid, centre, run)  # off: an old report still loads
    with pytest.raises(WresdynError, match=match) as e:
        narrow_ranges(Randomization(effort_from_data=True), humanoid, centre, run)
    assert "\n" not in str(e.value) and "effort-from-data" in str(e.value)


def test_the_deploy_command_line_sets_it():
    from wresdyn.cli import parse_command

    _, _, args = parse_command(["deploy", "--floor", "--randomization.effort-from-data"])
    assert args.randomization.effort_from_data is True
    _, _, args = parse_command(["deploy", "--floor"])
    assert args.randomization.effort_from_data is False
