"""(f)'s range of the effort limits the identification could not see (``Randomization.unseen_effort_scale``): with
``unseen="wide"`` an unseen limit gets the set factor range instead of (e)'s ``effort_scale``; the seen limits, (e)
and every run recorded before the field are unchanged."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from wresdyn.errors import WresdynError
from wresdyn.learn.runs import RunError, check_resume
from wresdyn.sim.physics import PhysicalParams
from wresdyn.skills.plants import SimPlant
from wresdyn.skills.randomize import NARROW_DEFAULT, Randomization, narrow_ranges, wide_ranges

TWIST = (0.8, 1.2)
C_FLAGS = ["--randomization.unseen", "wide", "--randomization.unseen-mass-add-kg", "-5", "5",
           "--randomization.unseen-com-offset", "0.05", "0.05", "0.01"]
KEPT = Path(__file__).parents[2] / "benchmarks/results/floor_fair/full/floor_unvpc_s0/skills"


def _report(run, humanoid):
    """A tiny ``identify/identifiability.json``: joint 0's effort limit seen (SE 0.02), joint 1's unseen (zero
    sensitivity, no error), joint 2's kp unseen."""
    j = humanoid.joint_names
    params = [{"name": f"effort:{j[0]}", "sensitivity": 0.01, "se": 0.02, "se_pct": 2.0},
              {"name": f"effort:{j[1]}", "sensitivity": 0.0, "se": None, "se_pct": math.inf},
              {"name": f"kp:{j[2]}", "sensitivity": 0.0, "se": None, "se_pct": math.inf}]
    (run / "identify").mkdir(parents=True)
    (run / "identify" / "identifiability.json").write_text(json.dumps({"parameters": params}))
    return run


def test_the_unseen_limits_get_the_set_range_and_the_rest_keep_theirs(tmp_path, humanoid):
    run, centre = _report(tmp_path, humanoid), PhysicalParams.nominal(humanoid)
    before, _ = narrow_ranges(Randomization(unseen="wide"), humanoid, centre, run)
    cfg = Randomization(unseen="wide", unseen_effort_scale=TWIST)
    after, source = narrow_ranges(cfg, humanoid, centre, run)
    lo, hi = after.scale["effort"]
    assert (lo[1], hi[1]) == pytest.approx(TWIST)  # unseen: the set range
    assert (before.scale["effort"][0][1], before.scale["effort"][1][1]) == pytest.approx(cfg.effort_scale)
    assert (lo[0], hi[0]) == pytest.approx((math.exp(-0.04), math.exp(0.04)))  # seen: 2 SE
    assert hi[3] == pytest.approx(1 + NARROW_DEFAULT)  # not in the report: ±10 %
    others = np.arange(humanoid.n_dof) != 1
    assert np.array_equal(lo[others], before.scale["effort"][0][others])
    assert np.array_equal(hi[others], before.scale["effort"][1][others])
    for f in after.scale:  # every other field as without it: kp's unseen joint keeps (e)'s kp range
        if f != "effort":
            assert all(np.array_equal(a, b) for a, b in zip(after.scale[f], before.scale[f])), f
    assert "1 unseen effort limits ×(0.8, 1.2)" in source
    wide = wide_ranges(cfg, humanoid, centre)  # (e) untouched
    assert np.allclose(wide.scale["effort"][0], cfg.effort_scale[0]) and np.allclose(wide.scale["effort"][1], 1.1)


def test_the_unseen_limit_is_drawn_log_uniform_in_it_and_the_other_draws_unchanged(tmp_path, humanoid):
    """Two plants of one seed, without and with the field: the same random stream, so joint 1's effort factor is the
    same quantile of the other range; every other draw is the same."""
    torch.set_num_threads(1)
    run, centre = _report(tmp_path, humanoid), PhysicalParams.nominal(humanoid)
    plants = []
    for cfg in (Randomization(seed=3, unseen="wide"), Randomization(seed=3, unseen="wide", unseen_effort_scale=TWIST)):
        ranges = narrow_ranges(cfg, humanoid, centre, run)[0]
        plants.append(SimPlant(humanoid, 8, 500.0, 5, randomization=(cfg, ranges)))
    old, new = (p.randomizer.values for p in plants)
    x_old = (old["effort"][:, 1] / centre.effort[1]).double().numpy()
    x_new = (new["effort"][:, 1] / centre.effort[1]).double().numpy()
    u = np.log(x_old / 0.9) / np.log(1.1 / 0.9)
    assert np.allclose(x_new, 0.8 * (1.2 / 0.8) ** u, rtol=1e-5)
    assert (x_new >= 0.8 - 1e-6).all() and (x_new <= 1.2 + 1e-6).all() and x_new.min() < 0.9
    for f in old:
        keep = [j for j in range(humanoid.n_dof) if j != 1]
        a, b = (old[f], new[f]) if f != "effort" else (old[f][:, keep], new[f][:, keep])
        assert torch.equal(a, b), f


@pytest.mark.parametrize("kw, match", [
    ({"unseen_effort_scale": TWIST}, "only with"),
    ({"unseen": "wide", "unseen_effort_scale": (1.2, 0.8)}, "0 < lo < hi"),
    ({"unseen": "wide", "unseen_effort_scale": (0.0, 1.2)}, "0 < lo < hi"),
    ({"unseen": "wide", "unseen_effort_scale": (0.8, math.inf)}, "0 < lo < hi"),
    ({"unseen": "wide", "unseen_effort_scale": (0.8, 1.0, 1.2)}, "0 < lo < hi"),
])
def test_bad_values_are_refused_in_one_line(kw, match):
    with pytest.raises(WresdynError, match=match) as e:
        Randomization(**kw)
    assert "\n" not in str(e.value)


def test_the_record_omits_it_unless_set_for_f(tmp_path):
    """Narrow, (e) and unset: no new field; set, (f) records it and a change is refused on resume."""
    assert "unseen_effort_scale" not in Randomization().record()
    assert "unseen_effort_scale" not in Randomization(unseen="wide").record()
    on = Randomization(unseen="wide", unseen_effort_scale=TWIST)
    assert on.record()["unseen_effort_scale"] == TWIST and "unseen_effort_scale" not in on.record(narrow=False)
    assert on.record(narrow=False) == Randomization().record(narrow=False)
    recorded = {"randomization": json.loads(json.dumps(Randomization(unseen="wide").record()))}
    check_resume(tmp_path, recorded, {"randomization": Randomization(unseen="wide").record()})
    with pytest.raises(RunError, match="unseen_effort_scale"):
        check_resume(tmp_path, recorded, {"randomization": on.record()})


def test_c_flags_reproduce_the_recorded_f_and_the_kept_e_resumes_under_d(tmp_path):
    """The command line with C's flags records what C's committed (f) recorded (before the field existed), and the
    kept (e) of C's base resumes with the field set, as batch D keeps it."""
    from wresdyn.cli import parse_command
    from wresdyn.experiments.deploy_config import FloorDeployConfig
    from wresdyn.experiments.skills import _run_of
    from wresdyn.skills.skill_config import SkillPPOConfig

    _, _, args = parse_command(["deploy", "--floor", *C_FLAGS])
    saved = json.loads((KEPT / "f_calibrated_narrow" / "config.json").read_text())["randomization"]
    assert json.loads(json.dumps(args.randomization.record())) == saved
    check_resume(KEPT / "f_calibrated_narrow", {"randomization": saved}, {"randomization": args.randomization.record()})
    _, _, args = parse_command(["deploy", "--floor", *C_FLAGS, "--randomization.unseen-effort-scale", "0.8", "1.2"])
    assert args.randomization.unseen_effort_scale == TWIST
    kept_e = json.loads((KEPT / "e_randomized" / "config.json").read_text())["randomization"]
    meta = _run_of(1, "e_randomized", SkillPPOConfig(), FloorDeployConfig(), {"calibrated": tmp_path / "cal"}, {},
                   tmp_path, args.randomization)[3]
    check_resume(KEPT / "e_randomized", {"randomization": kept_e},
                 {"randomization": json.loads(json.dumps(meta["randomization"]))})
