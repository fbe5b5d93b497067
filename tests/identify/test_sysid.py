"""Grey-box identification through the differentiable solver (:mod:`wresdyn.identify.sysid`), its CLI and report, and
the hybrid: a residual fitted and evaluated on top of identified physics."""

import dataclasses
import json

import numpy as np
import pytest

from wresdyn.cli import main, parse_command
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.identify.sysid import PhysicsScore, SysIdConfig, identify
from wresdyn.learn.runs import RunError, load_checkpoint
from wresdyn.sim.physics import PhysicalParams

REAL = Mismatch(kp_scale=0.8, kd_scale=1.3, friction=0.03, damping=0.3, delay=0.004, torque_limit_scale=0.5)
"""Uneven enough to matter, no noise: gains, friction, damping, a 2-step delay and saturation."""
SMALL = SysIdConfig(iterations=40, windows=4, horizon_curriculum=(8, 16), select_every=10, effort_grid=(0.3, 1.0),
                    identifiability=False)
"""Without the identifiability report: test_identify_cli_report_and_hybrid_fit and test_identifiability.py check it."""


@pytest.fixture(scope="module")
def recorded(humanoid, record):
    return record(humanoid, REAL, {"train": 2, "validation": 1, "heldout": 1}, seconds=0.3, amplitude=0.3)


def test_identification_reduces_the_validation_error_toward_the_truth(humanoid, recorded, tmp_path):
    params, curve = identify(humanoid, recorded, SMALL, out=tmp_path, log=lambda *_: None)
    score = PhysicsScore(humanoid, recorded.split("heldout"), recorded.rate_hz)
    nominal = score(PhysicalParams.nominal(humanoid))
    fitted = score(params)
    assert fitted < 0.7 * nominal, (fitted, nominal)
    truth = RealRobot(humanoid, REAL).physics()
    # kp starts at the file's value (1.25x the truth): the mean error of the log-ratio shrinks
    before = np.abs(np.log(humanoid.kp / truth.kp)).mean()
    after = np.abs(np.log(params.kp / truth.kp)).mean()
    assert after < before, (after, before)
    assert PhysicalParams.load(tmp_path / "physics.json", humanoid).kp.tolist() == params.kp.tolist()
    assert any("validation" in row for row in curve)


def test_identification_resume_refuses_a_changed_config(humanoid, recorded, tmp_path):
    cfg = dataclasses.replace(SMALL, iterations=4, select_every=2)
    identify(humanoid, recorded, cfg, out=tmp_path, log=lambda *_: None)
    with pytest.raises(RunError, match="lr"):
        identify(humanoid, recorded, dataclasses.replace(cfg, lr=0.5), out=tmp_path, log=lambda *_: None)


def test_refinement_resumes_adam_and_never_selects_worse(humanoid, recorded, tmp_path):
    score = PhysicsScore(humanoid, recorded.split("validation"), recorded.rate_hz)
    adam, _ = identify(humanoid, recorded, SMALL, out=tmp_path, log=lambda *_: None)
    # a finished run refined later: Adam's checkpoint is resumed (refine may change), then L-BFGS on fixed windows
    cfg = dataclasses.replace(SMALL, refine=3, refine_windows=4)
    lines = []
    refined, curve = identify(humanoid, recorded, cfg, out=tmp_path, log=lines.append)
    assert any(s.startswith("resumed from") for s in lines), lines
    rows = [r for r in curve if r.get("stage") == "refine"]
    assert len(rows) == 3 and all("validation" in r for r in rows)
    assert rows[-1]["loss"] <= rows[0]["loss"]  # L-BFGS with a line search does not go up on its fixed windows
    best = min([r["validation"] for r in rows] + [score(adam)])
    assert score(refined) == pytest.approx(best, rel=1e-6)  # the best on validation, Adam's start included
    assert score(refined) < 0.9 * score(adam)  # here 40 Adam steps leave plenty: 0.0103 -> 0.0068 rad
    assert PhysicalParams.load(tmp_path / "physics.json", humanoid).kd.tolist() == refined.kd.tolist()


def test_refinement_fits_delay_and_effort_only_when_not_frozen(humanoid, recorded, tmp_path):
    adam, _ = identify(humanoid, recorded, SMALL, out=tmp_path, log=lambda *_: None)
    base = dataclasses.replace(SMALL, refine=2, refine_windows=4)
    kept, _ = identify(humanoid, recorded, base, out=tmp_path, log=lambda *_: None)
    assert kept.delay.tolist() == adam.delay.tolist() and kept.effort.tolist() == adam.effort.tolist()
    lines = []
    moved, curve = identify(humanoid, recorded, dataclasses.replace(base, refine_frozen=()), out=tmp_path,
                            log=lines.append)
    assert any(s.startswith("resumed from") for s in lines), lines  # refine_frozen may change on resume
    rows = [r for r in curve if r.get("stage") == "refine"]
    assert rows[-1]["loss"] <= rows[0]["loss"]
    # the delayed commands are re-interpolated at each evaluation, so the delay has a gradient and moves
    assert np.abs(moved.delay - adam.delay).max() > 1e-6
    assert np.abs(moved.effort - adam.effort).max() > 1e-6
    assert (moved.delay >= 0).all() and (moved.effort >= 0.05 * humanoid.effort - 1e-9).all()
    with pytest.raises(ValueError, match="refine_frozen"):
        dataclasses.replace(SMALL, refine_frozen=("nonsense",))
    assert parse_command(["identify", "d.npz", "--refine-frozen"])[2].config.refine_frozen == ()


def test_identify_cli_report_and_hybrid_fit(humanoid, recorded, tmp_path, capsys):
    """`wresdyn identify --eval` writes the parameters, the report against the truth and an evaluation of the
    calibrated model; `wresdyn fit --physics` learns a residual on top and its run replays with that physics."""
    data = tmp_path / "d.npz"
    recorded.save(data)
    run = tmp_path / "id"
    assert main(["identify", str(data), "--out", str(run), "--iterations", "8", "--windows", "2", "--eval",
                 "--identifiability-windows", "4"]) == 0
    report = (run / "identification.md").read_text()
    assert "left_knee" in report and "Within 10 %" in report
    assert "## What the data can identify" in report and (run / "identifiability.json").exists()
    metrics = json.loads((run / "eval" / "metrics.json").read_text())
    assert metrics["splits"]["heldout"]["pd_residual"] is not None  # the calibrated model, PD only
    fit = tmp_path / "fit"
    assert main(["fit", str(data), "--out", str(fit), "--iterations", "4", "--windows", "2", "--curriculum", "4",
                 "--physics", str(run / "physics.json"), "--eval"]) == 0
    assert (fit / "physics.json").exists()
    hybrid = json.loads((fit / "eval" / "metrics.json").read_text())
    # a residual that starts at zero on the calibrated model: the same replay as the calibrated model alone
    assert abs(hybrid["splits"]["heldout"]["pd_residual"]["mean_abs_dq"] - metrics["splits"]["heldout"]["pd_residual"]["mean_abs_dq"]) \
        < 0.3 * metrics["splits"]["heldout"]["pd_residual"]["mean_abs_dq"]
    # PPO on the hybrid (the paper's method on top of the identified model): the run carries the physics too
    ppo = tmp_path / "ppo"
    assert main(["train", str(data), "--out", str(ppo), "--iterations", "2", "--num-envs", "4", "--steps-per-env", "8",
                 "--horizon", "8", "--set", "ppo.num_mini_batches=2", "--physics", str(run / "physics.json"),
                 "--eval"]) == 0
    assert PhysicalParams.load(ppo / "physics.json").kp.tolist() == PhysicalParams.load(run / "physics.json").kp.tolist()
    assert json.loads((ppo / "eval" / "metrics.json").read_text())["info"]["physics"] == "physics.json"
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert main(["fit", str(data), "--out", str(tmp_path / "f2"), "--physics", str(bad)]) == 2
    assert "not a wresdyn physics file" in capsys.readouterr().err


def test_fit_default_is_the_hybrid_and_resumes_both_stages(humanoid, recorded, tmp_path, capsys):
    """`wresdyn fit` without --model identifies the physics (OUT/identify) and fits the residual on top; the run
    carries that physics; a second call finds both stages done."""
    data = tmp_path / "d.npz"
    recorded.save(data)
    out = tmp_path / "hybrid"
    args = ["fit", str(data), "--out", str(out), "--identify-iterations", "6", "--iterations", "4", "--windows", "2",
            "--curriculum", "4", "--identify.identifiability-windows", "2"]
    assert main(args) == 0
    out_text = capsys.readouterr().out
    assert "identification" in out_text
    # the zero-residual start (the identified model alone) is a candidate: the hybrid is never selected worse
    start = float(out_text.split("validation at the start: ")[1].split()[0])
    meta = load_checkpoint(out / "checkpoint.pt", keys=("meta",))["meta"]
    assert meta["best_validation"] <= start + 5e-5  # (printed to 4 decimals)
    identified = PhysicalParams.load(out / "identify" / "physics.json", humanoid)
    assert PhysicalParams.load(out / "physics.json", humanoid).kp.tolist() == identified.kp.tolist()
    assert json.loads((out / "identify" / "config.json").read_text())["learner"] == "identify"
    summary = json.loads((out / "train_summary.json").read_text())
    assert summary["identify_wall_s"] > 0 and summary["config"]["physics"].endswith("physics.json")
    mtime = (out / "identify" / "checkpoint.pt").stat().st_mtime
    assert main(args) == 0  # resumed: nothing left to do in either stage
    assert (out / "identify" / "checkpoint.pt").stat().st_mtime == mtime
    assert "resumed" in capsys.readouterr().out


def test_fit_passes_refine_to_its_identification(humanoid, recorded, tmp_path, capsys):
    data = tmp_path / "d.npz"
    recorded.save(data)
    out = tmp_path / "hybrid"
    # the refinement on 2 windows and no identifiability report: the flag's way through is the property here
    assert main(["fit", str(data), "--out", str(out), "--identify-iterations", "4", "--refine", "1", "--iterations",
                 "2", "--windows", "2", "--curriculum", "4", "--identify.refine-windows", "2",
                 "--identify.no-identifiability"]) == 0
    assert "refine   1/1" in capsys.readouterr().out
    curve = json.loads((out / "identify" / "curve.json").read_text())
    assert [r.get("stage") for r in curve][-1] == "refine"


def test_fit_passes_the_gain_grid_to_its_identification(humanoid, recorded, tmp_path, capsys):
    data = tmp_path / "d.npz"
    recorded.save(data)
    out = tmp_path / "hybrid"
    assert main(["fit", str(data), "--out", str(out), "--identify-iterations", "2", "--gain-grid", "1,0.5",
                 "--iterations", "2", "--windows", "2", "--curriculum", "4", "--identify.no-identifiability"]) == 0
    assert "kp search, per joint:" in capsys.readouterr().out
    assert main(["fit", str(data), "--out", str(tmp_path / "bad"), "--gain-grid", "1,-0.5"]) == 2
    assert "gain_grid" in capsys.readouterr().err and not (tmp_path / "bad").exists()


def test_identify_refuses_a_malformed_delay_grid(tmp_path, capsys):
    with pytest.raises(SystemExit) as ex:  # the command line's refusal, in the same one-line form
        main(["identify", str(tmp_path / "none.npz"), "--delay-grid", "0", "ten"])
    err = capsys.readouterr().err
    assert ex.value.code == 2 and "--delay-grid" in err and len(err.strip().splitlines()) == 1


def test_gain_grid_starts_each_joint_at_its_own_kp(humanoid, record):
    # arms' servos 10x softer than the file says, legs and waist as the file says
    soft_arms = Mismatch(joint=({"match": "*_shoulder_*", "kp_scale": 0.1}, {"match": "*_elbow", "kp_scale": 0.1}))
    data = record(humanoid, soft_arms, {"train": 2, "validation": 1}, seconds=0.3, amplitude=0.3)
    data.meta["excluded_joints"] = ["right_elbow"]  # out of the fit: keeps the file's kp, whatever its error says
    cfg = dataclasses.replace(SMALL, iterations=2, gain_grid=(1.0, 0.1), effort_grid=())
    searches = []
    params, _ = identify(humanoid, data, cfg, log=lambda *_: None, on_search=searches.append)
    (kp,) = searches  # effort_grid is off and the delay not searched: the kp search alone
    assert kp.field == "kp" and kp.losses.shape == (2, humanoid.n_dof)
    picks = dict(kp.choice)
    assert picks.pop("right_elbow") is None
    arms = [j for j in humanoid.joint_names if ("shoulder" in j or "elbow" in j) and j != "right_elbow"]
    assert sum(picks[j] == 0.1 for j in arms) >= 0.75 * len(arms), picks
    legs = [j for j in humanoid.joint_names if j not in arms and j != "right_elbow"]
    assert sum(picks[j] == 1.0 for j in legs) >= 0.75 * len(legs), picks
    # the searched start is a selection candidate: what is returned is never worse on validation
    score = PhysicsScore(humanoid, data.split("validation"), data.rate_hz, weights=data.fit_weights())
    assert score(params) <= kp.validation + 5e-5
    # the selected model starts from there (two small Adam steps later): far closer to the arms' truth than the file
    truth = RealRobot(humanoid, soft_arms).physics()
    arm = np.isin(humanoid.joint_names, arms)
    elbow = humanoid.joint_names.index("right_elbow")
    assert params.kp[elbow] == pytest.approx(humanoid.kp[elbow], rel=0.05)  # two small Adam steps at most
    assert np.abs(np.log(params.kp / truth.kp))[arm].mean() < 0.5 * np.abs(np.log(humanoid.kp / truth.kp))[arm].mean()


def test_identify_refuses_a_malformed_gain_grid(tmp_path, capsys):
    with pytest.raises(SystemExit) as ex:
        main(["identify", str(tmp_path / "none.npz"), "--gain-grid", "1", "soft"])
    err = capsys.readouterr().err
    assert ex.value.code == 2 and "--gain-grid" in err and len(err.strip().splitlines()) == 1
    with pytest.raises(ValueError, match="gain_grid"):
        SysIdConfig(fit=("kd",), gain_grid=(1.0, 0.1))


def test_fused_identification_follows_the_stepped_one(humanoid, recorded):
    cfg = dataclasses.replace(SMALL, iterations=20, select_every=10)
    stepped, c_step = identify(humanoid, recorded, dataclasses.replace(cfg, fused=False), log=lambda *_: None)
    fused, c_fused = identify(humanoid, recorded, dataclasses.replace(cfg, fused=True), log=lambda *_: None)
    # the default (fused=None) fuses where it can, as here (the replay solver, PD drives, whole windows)
    _, c_default = identify(humanoid, recorded, cfg, log=lambda *_: None)
    strip = lambda curve: [{k: v for k, v in c.items() if k != "wall"} for c in curve]  # noqa: E731
    assert cfg.fused is None and strip(c_default) == strip(c_fused)
    losses = [(a["loss"], b["loss"]) for a, b in zip(c_step, c_fused) if "loss" in a]
    assert len(losses) == 20
    # the same states; the adjoints sum over worlds in another order (float32 rounding), which Adam carries on:
    # measured 1e-6 relative on the loss, <= 6e-7 on the fields, 2.5e-5 on the delay (its gradient comes through
    # the shifted targets)
    for a, b in losses:
        assert abs(a - b) <= 1e-5 * abs(a), (a, b)
    for field, rtol in (("kp", 1e-5), ("kd", 1e-5), ("damping", 1e-5), ("friction", 1e-5), ("effort", 1e-5),
                        ("delay", 2e-4)):
        x, y = getattr(stepped, field), getattr(fused, field)
        assert np.allclose(x, y, rtol=rtol, atol=1e-12), field
    with pytest.raises(ValueError, match="fused replays whole windows"):
        dataclasses.replace(cfg, fused=True, grad_truncation=8)
    dataclasses.replace(cfg, grad_truncation=8, shooting=1)  # the default steps there instead


def test_solver_threads_split_the_windows_with_the_same_results(humanoid, recorded):
    """``sim_threads`` runs the replay solver's worlds on several host threads: every world's arithmetic and the order
    of the sums over worlds stay the same, so the identification is the same bit for bit, fused and stepped."""
    cfg = dataclasses.replace(SMALL, iterations=10, select_every=5)
    strip = lambda curve: [{k: v for k, v in c.items() if k != "wall"} for c in curve]  # noqa: E731
    for fused in (True, False):
        runs = [identify(humanoid, recorded, dataclasses.replace(cfg, fused=fused, sim_threads=t), log=lambda *_: None)
                for t in (1, 2)]
        (one, c_one), (two, c_two) = runs
        assert strip(c_one) == strip(c_two), fused
        for field in ("kp", "kd", "armature", "damping", "friction", "effort"):
            assert np.array_equal(getattr(one, field), getattr(two, field)), (fused, field)
    with pytest.raises(ValueError, match="sim_threads"):
        dataclasses.replace(cfg, sim_threads=0)


def test_delay_grid_first_searches_before_adam_and_shared_delay_stays_one(humanoid, recorded):
    # the effort limit would join the fit after the last of the 2 steps: the delay grid runs only if it runs first
    cfg = dataclasses.replace(SMALL, iterations=2, effort_after=1.0, delay_grid=(0.0, 2.0, 4.0), delay_grid_first=True,
                              shared_delay=True)
    searches = []
    params, _ = identify(humanoid, recorded, cfg, log=lambda *_: None, on_search=searches.append)
    (delay,) = searches
    assert delay.field == "delay" and delay.losses.shape == (3,)
    later = []
    identify(humanoid, recorded, dataclasses.replace(cfg, delay_grid_first=False), log=lambda *_: None,
             on_search=later.append)
    assert later == []
    assert np.ptp(params.delay) < 1e-12  # one delay for every joint, through the Adam steps
    per_joint = dataclasses.replace(cfg, shared_delay=False, delay_grid_per_joint=True)
    searches.clear()
    identify(humanoid, recorded, per_joint, log=lambda *_: None, on_search=searches.append)
    assert searches[0].losses.shape == (3, humanoid.n_dof)
    with pytest.raises(ValueError, match="delay_grid"):
        SysIdConfig(delay_grid_first=True)
    with pytest.raises(ValueError, match="shared_delay"):
        SysIdConfig(fit=("kp",), shared_delay=True)


def test_polish_settings_are_checked():
    with pytest.raises(ValueError, match="polish"):
        SysIdConfig(polish=-1)
    with pytest.raises(ValueError, match="polish_windows"):
        SysIdConfig(polish_windows=0)
    with pytest.raises(ValueError, match="polish_threshold"):
        SysIdConfig(polish_threshold=-1.0)
