"""The replay solver's dry-friction law as a run option (``friction_kappa`` of the identification, gradient-fit and
replay-environment configs): it reaches the solver through the one simulation layer, a run records it and ``wresdyn
eval`` replays under it, a changed law is refused on resume, and a bad value or a solver without the law is a
one-line error."""

import dataclasses
import json

import numpy as np
import pytest

from wresdyn.cli import main
from wresdyn.errors import WresdynError
from wresdyn.evaluation.evaluate_run import run_friction_kappa
from wresdyn.evaluation.open_loop import evaluate_split
from wresdyn.fit.gradfit_config import GradFitConfig
from wresdyn.identify.sysid import identify
from wresdyn.identify.sysid_config import SysIdConfig
from wresdyn.learn.runs import RunError
from wresdyn.ppo.ppo_config import TrainConfig, config_from_dict
from wresdyn.ppo.replay_env_config import ReplayEnvConfig
from wresdyn.robot.physical import PhysicalParams
from wresdyn.sim import Simulator
from wresdyn.sim.rollout import replay_trajectories
from wresdyn.sim.solver_replay import SolverReplay

KAPPA = 1e4
"""The damper law's rate of the SO-101 runs [1/s]."""
FRICTION = 2.0
"""Dry friction on every joint [N*m], so that the law shows: the humanoid file has none."""
TINY = SysIdConfig(fit=("kp", "friction"), iterations=2, windows=2, horizon_curriculum=(4,), select_every=1,
                   effort_grid=())


@pytest.fixture(scope="module")
def recorded(humanoid, record):
    from wresdyn.data.mismatch import Mismatch

    return record(humanoid, Mismatch(friction=0.5), {"train": 2, "validation": 1, "heldout": 1}, seconds=0.2,
                  amplitude=0.3)


@pytest.fixture(scope="module")
def rough(humanoid):
    return dataclasses.replace(PhysicalParams.nominal(humanoid), friction=np.full(humanoid.n_dof, FRICTION))


def test_the_law_reaches_the_solver(humanoid, recorded, rough):
    trajs = recorded.split("validation")
    soft = replay_trajectories(humanoid, trajs, recorded.rate_hz, physics=rough)["residual"].q[0]
    damper = replay_trajectories(humanoid, trajs, recorded.rate_hz, physics=rough, friction_kappa=KAPPA)
    # the same replay on a simulator whose solver was built by hand with the law
    sim = Simulator(humanoid, 1, 1.0 / recorded.rate_hz)
    sim.solver = SolverReplay(sim.model, friction_kappa=KAPPA)
    sim.solver.friction_grad = False
    by_hand = replay_trajectories(humanoid, trajs, recorded.rate_hz, physics=rough, sim=sim)["residual"].q[0]
    assert np.array_equal(damper["residual"].q[0], by_hand)
    # the soft law creeps below its bound where the damper all but sticks: 0.3 rad of multisine apart by mrad
    assert np.abs(damper["residual"].q[0] - soft).max() > 1e-3


def test_configs_check_the_law():
    for bad in (0.0, -1.0, float("nan"), True, "1e4"):
        with pytest.raises(WresdynError, match="friction_kappa"):
            SysIdConfig(friction_kappa=bad)
    with pytest.raises(WresdynError, match="env.friction_kappa = 0"):
        ReplayEnvConfig(friction_kappa=0)
    for solver in ("featherstone", "mujoco"):
        with pytest.raises(WresdynError, match="replay solver"):
            GradFitConfig(solver=solver, friction_kappa=KAPPA)
    assert SysIdConfig(friction_kappa=float("inf")).friction_kappa == float("inf")  # hard Coulomb friction
    # a PPO run's config.json round trip
    cfg = TrainConfig(env=ReplayEnvConfig(friction_kappa=KAPPA))
    assert config_from_dict(json.loads(json.dumps(dataclasses.asdict(cfg)))) == cfg


def test_a_solver_without_the_law_is_refused(humanoid):
    with pytest.raises(WresdynError, match="friction_kappa is a law of the replay solver, not of mujoco"):
        Simulator(humanoid, 1, 0.002, solver="mujoco", friction_kappa=KAPPA)


def test_bad_values_on_the_command_line(tmp_path, capsys):
    for flags, msg in ((["--friction-kappa", "0"], "friction_kappa = 0.0 must be a rate > 0"),
                       (["--friction-kappa", "1e4", "--solver", "mujoco"], "solver 'mujoco' has its own friction")):
        assert main(["identify", str(tmp_path / "none.npz"), *flags]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and msg in err, err
    assert not any(tmp_path.iterdir())


def test_identify_records_the_law_eval_replays_under_it_resume_refuses_another(humanoid, recorded, rough, tmp_path,
                                                                               capsys):
    cfg = dataclasses.replace(TINY, friction_kappa=KAPPA)
    identify(humanoid, recorded, cfg, out=tmp_path, log=lambda *_: None)
    from wresdyn.fit.hybrid import save_identify_config

    save_identify_config(tmp_path, cfg, recorded.rate_hz)
    assert run_friction_kappa(tmp_path) == KAPPA
    with pytest.raises(RunError, match="friction_kappa = 10000.0, now null"):
        identify(humanoid, recorded, TINY, out=tmp_path, log=lambda *_: None)
    # evaluated under the run's law: the same figures as evaluate_split's with that law, not the soft law's
    rough.save(tmp_path / "physics.json")
    data = tmp_path / "data.npz"
    recorded.save(data)
    assert main(["eval", str(tmp_path), "--data", str(data), "--splits", "heldout", "--out", str(tmp_path / "ev")]) == 0
    got = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert got["info"]["friction_kappa"] == KAPPA
    trajs = recorded.split("heldout")
    want, _ = evaluate_split(humanoid, trajs, recorded.rate_hz, physics=rough, friction_kappa=KAPPA)
    soft, _ = evaluate_split(humanoid, trajs, recorded.rate_hz, physics=rough)
    mean = got["splits"]["heldout"]["pd_residual"]["mean_abs_dq"]
    assert mean == want["pd_residual"]["mean_abs_dq"] != soft["pd_residual"]["mean_abs_dq"]


def test_fit_carries_the_law_to_both_stages_and_refuses_another_on_resume(recorded, tmp_path, capsys):
    data, run = tmp_path / "d.npz", tmp_path / "fit"
    recorded.save(data)
    args = ["fit", str(data), "--out", str(run), "--iterations", "2", "--windows", "2", "--horizon-curriculum", "4",
            "--identify.iterations", "2", "--identify.horizon-curriculum", "8", "--quiet"]
    assert main([*args, "--friction-kappa", "1e4"]) == 0
    assert run_friction_kappa(run) == KAPPA  # the residual's run, as wresdyn eval reads it
    assert run_friction_kappa(run / "identify") == KAPPA  # the hybrid's identification ran under it too
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "friction_kappa = 10000.0, now null" in err, err
    # Newton's joints have no damper friction law: the USD export writes the amplitudes as joint friction and says so
    assert main(["export", str(run), "--out", str(tmp_path / "exp")]) == 0
    record = json.loads((tmp_path / "exp" / "export.json").read_text())
    assert record["friction_kappa"] == KAPPA and any("damper" in n for n in record["notes"]), record


def test_train_flag_reaches_the_replay_environment(humanoid, recorded):
    from wresdyn.cli import parse_command
    from wresdyn.ppo.replay_env import ReplayEnv

    cfg = parse_command(["train", "d.npz", "--env.friction-kappa", "inf"])[2].config
    assert cfg.env.friction_kappa == float("inf")
    env = ReplayEnv(humanoid, recorded.split("train"), recorded.rate_hz, 2, cfg.env)
    assert isinstance(env.sim.solver, SolverReplay) and env.sim.solver.friction_kappa == float("inf")
