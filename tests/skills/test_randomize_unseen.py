"""(f)'s ranges of the parameters the identification could not see (``Randomization.unseen``): the switch off keeps
the narrow ranges (±2 SE, ±10 % without a finite error); on, an unseen parameter (read from the report) gets (e)'s
range and a seen one keeps its own."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from wresdyn.errors import WresdynError
from wresdyn.learn.runs import RunError, check_resume
from wresdyn.sim.physics import PhysicalParams
from wresdyn.skills.randomize import NARROW_DEFAULT, UNSEEN_FIELDS, Randomization, narrow_ranges, unseen_parameters


def _report(run, humanoid):
    """A tiny ``identify/identifiability.json``: kp of joint 0 seen (SE 0.03), kp of joint 1, friction of joint 2
    and the torso's mass unseen (zero sensitivity, no error), armature of joint 3 at 0 with an absolute error."""
    j = humanoid.joint_names
    params = [{"name": f"kp:{j[0]}", "sensitivity": 0.01, "se": 0.03, "se_pct": 3.0},
              {"name": f"kp:{j[1]}", "sensitivity": 0.0, "se": None, "se_pct": math.inf},
              {"name": f"friction:{j[2]}", "sensitivity": 0.0, "se": None, "se_pct": math.inf},
              {"name": f"armature:{j[3]}", "sensitivity": 0.001, "se": 0.3, "se_pct": None},
              {"name": "body_mass:torso", "sensitivity": 0.0, "se": None, "se_pct": math.inf}]
    (run / "identify").mkdir(parents=True)
    (run / "identify" / "identifiability.json").write_text(json.dumps({"parameters": params}))
    return run


def _centre(humanoid):
    centre = PhysicalParams.nominal(humanoid)
    return dataclasses.replace(centre, friction=np.full(humanoid.n_dof, 1.0))


def test_the_report_marks_unseen_only_what_has_no_finite_error(tmp_path, humanoid):
    report = json.loads((_report(tmp_path, humanoid) / "identify" / "identifiability.json").read_text())
    j = humanoid.joint_names
    assert unseen_parameters(report) == {f"kp:{j[1]}", f"friction:{j[2]}", "body_mass:torso"}


def test_by_default_the_ranges_and_the_record_are_those_from_before(tmp_path, humanoid):
    """Off: an unseen parameter ±10 % like any without an error, the CoM 10 % of (e)'s, and no new field recorded."""
    run, centre, cfg = _report(tmp_path, humanoid), _centre(humanoid), Randomization()
    ranges, source = narrow_ranges(cfg, humanoid, centre, run)
    lo, hi = ranges.scale["kp"]
    assert (lo[0], hi[0]) == pytest.approx((math.exp(-0.06), math.exp(0.06)))
    assert (lo[1], hi[1]) == pytest.approx((1 / (1 + NARROW_DEFAULT), 1 + NARROW_DEFAULT))
    torso = list(humanoid.body_names).index("torso")
    assert ranges.scale["body_mass"][1][torso] == pytest.approx(1 + NARROW_DEFAULT)
    assert np.allclose(ranges.com_offset, NARROW_DEFAULT * np.asarray(cfg.com_offset))
    assert ranges.friction[1][2] == pytest.approx(1 + NARROW_DEFAULT) and "unseen" not in source
    record = cfg.record()
    assert not set(UNSEEN_FIELDS) & set(record) and record == {
        k: v for k, v in dataclasses.asdict(cfg).items() if k not in (*UNSEEN_FIELDS, "effort_from_data")}


def test_wide_gives_the_unseen_the_wide_ranges_and_keeps_the_seen(tmp_path, humanoid):
    run, centre = _report(tmp_path, humanoid), _centre(humanoid)
    cfg = Randomization(unseen="wide")
    ranges, source = narrow_ranges(cfg, humanoid, centre, run)
    lo, hi = ranges.scale["kp"]
    assert (lo[0], hi[0]) == pytest.approx((math.exp(-0.06), math.exp(0.06)))  # seen: 2 SE
    assert (lo[1], hi[1]) == pytest.approx(cfg.kp_scale)  # unseen: (e)'s
    assert hi[2] == pytest.approx(1 + NARROW_DEFAULT)  # not in the report: ±10 %
    assert ranges.scale["armature"][1][3] == pytest.approx(1 + NARROW_DEFAULT)  # an absolute error: seen, ±10 %
    torso = list(humanoid.body_names).index("torso")
    m_lo, m_hi = ranges.scale["body_mass"]
    assert (m_lo[torso], m_hi[torso]) == pytest.approx(cfg.mass_scale)
    others = np.arange(len(m_hi)) != torso
    assert np.allclose(m_hi[others], 1 + NARROW_DEFAULT)
    assert np.allclose(ranges.com_offset, cfg.com_offset)  # the torso's mass unseen: (e)'s whole CoM offset
    width = cfg.friction[1] * float(centre.effort[2])
    assert (ranges.friction[0][2], ranges.friction[1][2]) == pytest.approx((max(1.0 - width, 0.0), 1.0 + width))
    assert "3 unseen" in source


def test_wide_with_the_sourced_mass_and_com_ranges(tmp_path, humanoid):
    run, centre = _report(tmp_path, humanoid), _centre(humanoid)
    cfg = Randomization(unseen="wide", unseen_mass_add_kg=(-5.0, 5.0), unseen_com_offset=(0.05, 0.05, 0.01))
    ranges, source = narrow_ranges(cfg, humanoid, centre, run)
    torso = list(humanoid.body_names).index("torso")
    m = float(centre.body_mass[torso])
    lo, hi = ranges.scale["body_mass"][0][torso], ranges.scale["body_mass"][1][torso]
    assert (lo, hi) == pytest.approx((max(m - 5.0, 0.1 * m) / m, (m + 5.0) / m))
    assert np.allclose(ranges.com_offset, (0.05, 0.05, 0.01))
    record = cfg.record()
    assert record["unseen"] == "wide" and record["unseen_mass_add_kg"] == (-5.0, 5.0)


def test_a_changed_unseen_setting_is_refused_on_resume_and_the_default_resumes(tmp_path):
    old = {"randomization": json.loads(json.dumps(Randomization().record()))}
    check_resume(tmp_path, old, {"randomization": Randomization().record()})
    with pytest.raises(RunError, match="unseen"):
        check_resume(tmp_path, old, {"randomization": Randomization(unseen="wide").record()})


@pytest.mark.parametrize("kw, match", [
    ({"unseen": "maybe"}, "'narrow' or 'wide'"),
    ({"unseen_mass_add_kg": (-5.0, 5.0)}, "only with"),
    ({"unseen": "wide", "unseen_mass_add_kg": (5.0, -5.0)}, "lo < hi"),
    ({"unseen": "wide", "unseen_com_offset": (0.05, -0.05, 0.01)}, ">= 0"),
])
def test_bad_values_are_refused_in_one_line(kw, match):
    with pytest.raises(WresdynError, match=match) as e:
        Randomization(**kw)
    assert "\n" not in str(e.value)


def test_the_deploy_command_line_sets_it_and_refuses_a_bad_value(capsys):
    from wresdyn.cli import main, parse_command

    _, _, args = parse_command(["deploy", "--floor", "--randomization.unseen", "wide",
                                "--randomization.unseen-mass-add-kg", "-5", "5"])
    assert args.randomization.unseen == "wide" and args.randomization.unseen_mass_add_kg == (-5.0, 5.0)
    assert main(["deploy", "--floor", "--randomization.unseen-mass-add-kg", "-5", "5"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "only with --randomization.unseen wide" in err


def test_only_f_records_the_switch_so_a_kept_e_resumes(tmp_path):
    """(e) never reads the unseen fields: a policy (e) trained before them (a committed floor run's) resumes under
    ``unseen="wide"``, while (f)'s record carries the switch."""
    from pathlib import Path

    from wresdyn.experiments.deploy_config import FloorDeployConfig
    from wresdyn.experiments.skills import _run_of
    from wresdyn.skills.skill_config import SkillPPOConfig

    kept = Path(__file__).parents[2] / "benchmarks/results/floor_fair/full/floor_unvp55_s0/skills/e_randomized"
    saved = json.loads((kept / "config.json").read_text())["randomization"]
    wide = Randomization(unseen="wide", unseen_mass_add_kg=(-5.0, 5.0))
    runs = {"calibrated": tmp_path / "cal"}
    meta = {}
    for name in ("e_randomized", "f_calibrated_narrow"):
        meta[name] = _run_of(1, name, SkillPPOConfig(), FloorDeployConfig(), runs, {}, tmp_path, wide)[3]
    e = json.loads(json.dumps(meta["e_randomized"]["randomization"]))
    check_resume(kept, {"randomization": saved}, {"randomization": e})
    assert meta["f_calibrated_narrow"]["randomization"]["unseen"] == "wide"
