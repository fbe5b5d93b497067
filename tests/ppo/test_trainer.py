"""PPO through rsl-rl at tiny sizes (4 envs, 8 steps, 32-unit nets): runs, checkpoints, resumes, exports; and one
seeded run of 64 envs on the cart-pole whose selected residual beats PD only on validation."""

import dataclasses
import json

import numpy as np
import pytest
import torch

from wresdyn.config_fields import apply_overrides, set_fields
from wresdyn.data.mismatch import Mismatch
from wresdyn.errors import WresdynError
from wresdyn.learn.residual import GRUResidualPolicy, MLPResidualPolicy, ResidualConfig, export_policy
from wresdyn.learn.run_residual import load_policy
from wresdyn.learn.runs import load_checkpoint
from wresdyn.learn.selection import ValidationScore
from wresdyn.ppo.ppo_config import PPOConfig, TrainConfig, config_from_dict, default_config
from wresdyn.ppo.replay_env import ReplayEnvConfig
from wresdyn.ppo.rewards import RewardConfig
from wresdyn.ppo.runner import latest_checkpoint
from wresdyn.ppo.trainer import RunError, train

from conftest import tiny_ppo_config as tiny


def test_config_round_trips_through_json():
    cfg = tiny("gru", kind="delta_action")
    assert config_from_dict(json.loads(json.dumps(dataclasses.asdict(cfg)))) == cfg


def test_overrides_set_any_field_and_refuse_bad_ones(tmp_path):
    import subprocess
    import sys

    cfg = apply_overrides(default_config(), ["ppo.desired_kl=0.05", "residual.hidden_dims=128,64", "env.horizon=500",
                                             "residual.obs_normalization=false", "rewards.joint_pos_bonus=0"])
    assert (cfg.ppo.desired_kl, cfg.residual.hidden_dims, cfg.env.horizon) == (0.05, (128, 64), 500)
    assert cfg.residual.obs_normalization is False and cfg.rewards.joint_pos_bonus == 0.0
    assert cfg.ppo.gamma == default_config().ppo.gamma  # nothing else moved
    # an optional field at its None default parses as its annotation's other type
    assert default_config().ppo.select_every is None
    assert apply_overrides(default_config(), ["ppo.select_every=50"]).ppo.select_every == 50
    for bad, msg in (("ppo.nope=1", "no field 'nope'"), ("net.x=1", "unknown section"), ("env.num_worlds=1.5", "not a int"),
                     ("ppo.select_every=ten", "not a int"),
                     ("ppo.gamma", "SECTION.FIELD=VALUE")):
        with pytest.raises(ValueError, match=msg):
            apply_overrides(default_config(), [bad])
    out = tmp_path / "never"
    res = subprocess.run([sys.executable, "-m", "wresdyn.cli", "train", "data/dataset.npz", "--out", str(out),
                          "--ppo.nope", "1"], capture_output=True, text=True)
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("wresdyn")]
    assert res.returncode == 2 and len(lines) == 1 and "nope" in lines[0] and not out.exists()


def test_train_checkpoints_and_resumes_after_a_kill(robot, data, tmp_path):
    run = tmp_path / "run"
    s = train(data, robot, tiny(iterations=2), run)
    assert s["iterations_this_session"] == 2 and s["env_steps_this_session"] == 2 * 4 * 8
    assert latest_checkpoint(run).name == "model_1.pt"
    assert list(run.glob("events.out.tfevents.*"))
    # a kill after iteration 0 leaves only model_0.pt; a longer run resumes from it
    (run / "model_1.pt").unlink()
    saved = load_checkpoint(run / "model_0.pt")  # rsl-rl's checkpoint is weights only
    s = train(data, robot, tiny(iterations=3), run)
    assert s["iterations_this_session"] == 2
    assert latest_checkpoint(run).name == "model_2.pt"
    assert saved["iter"] == 0
    # where and how a run goes on may change (a run started on a GPU goes on here), what it learns may not
    saved_cfg = json.loads((run / "config.json").read_text())
    saved_cfg["config"]["ppo"]["device"] = "cuda:3"
    # and a config.json keeping the world count in the PPO config (ppo.num_envs) reads as the environment's num_worlds
    saved_cfg["config"]["ppo"]["num_envs"] = saved_cfg["config"]["env"].pop("num_worlds")
    (run / "config.json").write_text(json.dumps(saved_cfg))
    moved = dataclasses.replace(tiny(iterations=4), ppo=dataclasses.replace(
        tiny(iterations=4).ppo, save_interval=2, torch_threads=2))
    assert train(data, robot, moved, run)["iterations_this_session"] == 1
    assert json.loads((run / "config.json").read_text())["config"]["env"]["num_worlds"] == 4
    # a different configuration is refused rather than silently mixed in, naming what changed
    with pytest.raises(RunError, match=r"rewards\.sigma_q = 0\.1, now 0\.5"):
        train(data, robot, dataclasses.replace(tiny(iterations=3), rewards=dataclasses.replace(
            tiny().rewards, sigma_q=0.5)), run)
    with pytest.raises(RunError):
        train(data, robot, tiny(iterations=3), run, resume=False)
    saved_json = (run / "config.json").read_text()
    other = dataclasses.replace(tiny().ppo, iterations=5, gamma=0.95)  # learns differently
    with pytest.raises(RunError) as err:
        train(data, robot, dataclasses.replace(tiny(), ppo=other), run)
    assert str(err.value) == (f"{run} was trained with ppo.gamma = 0.9, now 0.95; resume with the same configuration "
                              "or choose another folder")
    # so is other data: here one training trajectory fewer
    first = data.split("train")[0].name
    fewer = dataclasses.replace(data, trajectories=[t for t in data.trajectories if t.name != first])
    with pytest.raises(RunError, match=r"trained on other data: dataset\.train = .*resume with the same data"):
        train(fewer, robot, tiny(iterations=5), run)
    assert (run / "config.json").read_text() == saved_json  # a refused resume leaves the folder as it was


def test_recorded_torques_never_reach_training(robot, data, tmp_path):
    """The same recording with every torque NaN trains to exactly the same actor, critic, selection and export:
    PPO reads joint states and commands only. (Dataset.validate refuses NaN; the learners never call it.)"""
    assert all(t.tau is not None and np.isfinite(t.tau).all() for t in data.trajectories)
    nan = dataclasses.replace(data, trajectories=[dataclasses.replace(t, tau=np.full_like(t.q, np.nan))
                                                  for t in data.trajectories])
    runs = {name: tmp_path / name for name in ("finite", "nan")}
    summaries = {name: train(d, robot, tiny(iterations=2), runs[name]) for name, d in (("finite", data), ("nan", nan))}
    def curve(name):  # what was selected on, not when (wall-clock)
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in summaries[name]["validation_curve"]]

    assert curve("nan") == curve("finite")
    for name in ("model_1.pt", "best.pt"):
        a, b = (load_checkpoint(r / name) for r in runs.values())
        for key in ("actor_state_dict", "critic_state_dict") if name == "model_1.pt" else ("actor",):
            assert a[key].keys() == b[key].keys()
            assert all(torch.equal(a[key][k], b[key][k]) for k in a[key]), (name, key)
    v = data.split("validation")[0]
    obs = torch.as_tensor(np.concatenate([v.q, v.qd, v.qdd, v.q_cmd], axis=1), dtype=torch.float32)
    (pa, _), (pb, _) = (load_policy(r) for r in runs.values())
    assert torch.equal(pa(obs), pb(obs)) and torch.isfinite(pa(obs)).all()


class _RunsCodeWhenUnpickled:
    """What a tampered checkpoint could hold: unpickling it calls ``open(marker, "w")``, creating the file."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def test_resume_refuses_a_checkpoint_that_is_not_weights_only(robot, data, tmp_path):
    run = tmp_path / "run"
    train(data, robot, tiny(iterations=1), run)
    marker = tmp_path / "code_ran"
    evil = run / "model_7.pt"  # the newest checkpoint, so a resume picks it
    good = load_checkpoint(run / "model_0.pt")
    torch.save({**good, "iter": 7, "infos": _RunsCodeWhenUnpickled(marker)}, evil)
    with pytest.raises(RunError) as err:
        train(data, robot, tiny(iterations=9), run)
    msg = str(err.value)
    assert "\n" not in msg and str(evil) in msg and "not a weights-only checkpoint" in msg and "open" in msg
    assert not marker.exists()
    evil.write_bytes(evil.read_bytes()[:100])  # cut short, as by a full disk
    with pytest.raises(RunError, match="model_7.pt: not a readable checkpoint"):
        train(data, robot, tiny(iterations=9), run)
    torch.save({"actor_state_dict": {}, "critic_state_dict": {}, "optimizer_state_dict": {}, "iter": 7}, evil)
    with pytest.raises(RunError, match="model_7.pt: does not fit this run's networks"):
        train(data, robot, tiny(iterations=9), run)


def test_configs_check_their_values_at_construction():
    with pytest.raises(WresdynError, match=r"^residual\.kind = 'torqu' is not one of: torque, delta_action$"):
        ResidualConfig(kind="torqu")
    with pytest.raises(WresdynError, match="residual.arch = 'lstm' is not one of: mlp, gru"):
        ResidualConfig(arch="lstm")
    for bad, msg in (({"num_steps_per_env": 0}, "ppo.num_steps_per_env = 0 must be >= 1"),
                     ({"gamma": 1.5}, "ppo.gamma = 1.5 must be <= 1"),
                     ({"num_steps_per_env": 2.5}, "ppo.num_steps_per_env = 2.5 is not an integer"),
                     ({"learning_rate": float("nan")}, "ppo.learning_rate = nan is not a number"),
                     ({"device": "gpu"}, "ppo.device = 'gpu' is not a device")):
        with pytest.raises(WresdynError, match=msg):
            PPOConfig(**bad)
    with pytest.raises(WresdynError, match="residual.fraction = 0 must be > 0"):
        ResidualConfig(fraction=0)
    with pytest.raises(WresdynError, match="rewards.sigma_q = 0 must be > 0"):
        RewardConfig(sigma_q=0)
    with pytest.raises(WresdynError, match="env.solver = 'featherstne' is not one of: auto, replay"):
        TrainConfig(env=ReplayEnvConfig(solver="featherstne"))
    with pytest.raises(WresdynError, match="env.num_worlds = 0 must be >= 1"):
        ReplayEnvConfig(num_worlds=0)
    # a GRU is batched by world: 2 worlds cannot make 4 mini-batches, whatever the rollout length
    with pytest.raises(WresdynError, match="num_mini_batches = 4 is more than the 2 worlds"):
        TrainConfig(residual=ResidualConfig(arch="gru"), env=ReplayEnvConfig(num_worlds=2))
    # overrides apply at once, so their order does not matter to checks across fields
    cfg = apply_overrides(default_config(), ["residual.arch=gru", "env.num_worlds=2", "ppo.num_mini_batches=2"])
    assert (cfg.residual.arch, cfg.env.num_worlds, cfg.ppo.num_mini_batches) == ("gru", 2, 2)
    # the world count is the environment's; its name in the PPO config still reads in a run's config.json (and on
    # the command line, through the deprecated spellings: tests/cli)
    old = dataclasses.asdict(default_config())
    old["ppo"]["num_envs"] = old["env"].pop("num_worlds") + 1
    assert config_from_dict(old) == set_fields(default_config(), {"env.num_worlds": 257})
    with pytest.raises(ValueError, match="residual.kind = 'torqu'"):
        apply_overrides(default_config(), ["residual.kind=torqu"])


@pytest.mark.parametrize("argv, words", [
    (["--residual.kind", "bogus"], ["--residual.kind", "'bogus'", "torque"]),
    (["--env.solver", "featherstne"], ["--env.solver", "featherstne"]),
    (["--env.num-worlds", "0"], ["env.num_worlds = 0"]),
], ids=["residual", "solver", "num-worlds"])
def test_cli_refuses_bad_choices_in_one_line(tmp_path, argv, words):
    import subprocess
    import sys

    out = tmp_path / "never"
    res = subprocess.run([sys.executable, "-m", "wresdyn.cli", "train", "data/dataset.npz", "--out", str(out), *argv],
                         capture_output=True, text=True)
    assert res.returncode == 2 and res.stdout == "" and not out.exists()
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("wresdyn train: error: "), res.stderr
    assert all(w in lines[0] for w in words), lines[0]


@pytest.mark.parametrize("kind", ["torque", "delta_action"])
def test_exported_policy_is_the_residual_the_env_applies(robot, data, tmp_path, best_actor, kind):
    """The exported residual on raw [q, q̇, q̈, q_cmd] gives the residual that ReplayEnv.step writes into the
    simulator's control for the actor's deterministic action on the same state: the env's fixed normalisation,
    the actor's running normaliser, clip(action_gain · a, −1, 1) · scale, both residual kinds."""
    import warp as wp

    from wresdyn.sim.residual_kinds import observation

    # a full-size initial output and action gain 5, so some residuals sit on the clip and some inside it
    cfg = tiny(iterations=2, kind=kind)
    cfg = dataclasses.replace(cfg, residual=dataclasses.replace(cfg.residual, output_gain=1.0, action_gain=5.0))
    run = tmp_path / kind
    train(data, robot, cfg, run)
    policy, meta = load_policy(run)
    actor, env = best_actor(run, data, robot, cfg)
    assert actor.obs_normalization and float(actor.obs_normalizer.count) > 0  # trained running statistics
    scale = torch.tensor(meta["scale"])
    num_worlds, qd_index = env.num_envs, torch.as_tensor(robot.qd_index)
    clipped = inside = 0
    for _ in range(4):
        g0 = env.g.clone()
        raw = observation(env.q, env.qd, env.qdd, env.bank.q_cmd[g0])
        with torch.no_grad():
            a = actor(env.get_observations())
            expect = policy(raw)
        env.step(a)
        if kind == "torque":
            applied = wp.to_torch(env.sim.control.joint_f).view(num_worlds, -1)[:, qd_index]
        else:
            applied = wp.to_torch(env.sim.control.joint_target_q).view(num_worlds, -1)[:, qd_index]
            applied = applied - env.bank.target(g0)
        torch.testing.assert_close(applied, expect, rtol=1e-5, atol=1e-6 * float(scale.max()))
        on_clip = (expect.abs() >= scale * (1 - 1e-6))
        clipped, inside = clipped + int(on_clip.sum()), inside + int((~on_clip).sum())
    assert clipped > 0 and inside > 0


def test_gru_trains_and_exported_policy_loads(robot, data, tmp_path):
    run = tmp_path / "gru"
    train(data, robot, tiny("gru", iterations=1, kind="delta_action"), run)
    policy, meta = load_policy(run)
    assert meta["kind"] == "delta_action" and policy.residual_kind() == "delta_action"
    obs = torch.zeros(3, 4 * robot.n_dof)
    out = policy(obs)
    assert out.shape == (3, robot.n_dof)
    # the residual stays within its authority, fraction * effort / kp
    assert (out.abs() <= torch.tensor(meta["scale"]) + 1e-6).all()


def _policies(n=3, hidden=32):
    torch.manual_seed(0)
    mean, std, scale = np.linspace(-1, 1, 4 * n), np.linspace(0.5, 2, 4 * n), np.arange(1.0, n + 1)

    def mlp(inp):
        return torch.nn.Sequential(torch.nn.Linear(inp, hidden), torch.nn.ELU(), torch.nn.Linear(hidden, n))

    return [MLPResidualPolicy(mlp(4 * n), mean, std, scale, "torque"),
            GRUResidualPolicy(torch.nn.GRU(4 * n, hidden), mlp(hidden), mean, std, scale, "delta_action")]


@pytest.mark.parametrize("which", [0, 1], ids=["mlp", "gru"])
def test_export_loads_back_with_the_same_outputs(tmp_path, which):
    import onnxruntime as ort

    policy = _policies()[which].eval()
    obs = [torch.randn(5, 12), torch.randn(5, 12)]
    policy.reset()
    expect = [policy(o).detach() for o in obs]  # two steps: the GRU carries its state
    from wresdyn.learn.network_file import load_residual

    export_policy(policy, tmp_path / "p.pt", tmp_path / "p.onnx")
    loaded = load_residual(tmp_path / "p.pt")
    for batch in (obs, [o[:1] for o in obs]):  # the batch axis is dynamic, down to one robot
        loaded.reset()
        for o, e in zip(batch, expect):
            torch.testing.assert_close(loaded(o), e[:len(o)], rtol=0, atol=1e-6)
    assert loaded.residual_kind() == loaded.kind == policy.kind
    torch.testing.assert_close(loaded.scale, policy.scale)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.onnx", "p.pt"]  # the ONNX holds its weights
    sess = ort.InferenceSession(str(tmp_path / "p.onnx"))
    h = np.zeros((1, 5, 32), np.float32)
    for o, e in zip(obs, expect):
        feeds = {"obs": o.numpy()}
        if which == 1:
            feeds["h_in"] = h
        out = sess.run(None, feeds)
        if which == 1:
            h = out[1]
        np.testing.assert_allclose(out[0], e.numpy(), atol=1e-5)


@pytest.mark.slow  # the same example runs in tests/integration/test_examples.py, which checks its report too
def test_example_smoke_run(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    res = subprocess.run([sys.executable, "examples/train_residual_ppo.py", "--test", "--out", str(tmp_path / "ex")],
                         capture_output=True, text=True, cwd=root, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "heldout: mean |dq| PD only" in res.stdout
    assert (tmp_path / "ex" / "policy.onnx").is_file() and (tmp_path / "ex" / "eval" / "metrics.json").is_file()


def test_the_selected_residual_beats_pd_only(cartpole, record, tmp_path):
    # the cart-pole on a real robot with dry friction and softer gains: PD alone misses the validation replay by
    # about 0.0125 rad. The reward's kernel is narrowed to that scale (the default 0.1 rad² is flat there). Seeded:
    # on the CPU the validation error falls below 0.8x PD's from iteration 7 on, to 0.58x at iteration 10. A claim
    # about the training and its selection only: this tiny run's residual does not carry over to other commands (on
    # one held-out trajectory it missed by 9x PD's error)
    data = record(cartpole, Mismatch(friction=0.1, kp_scale=0.6), {"train": 2, "validation": 1}, seconds=0.1,
                  amplitude=0.4)
    cfg = TrainConfig(env=ReplayEnvConfig(horizon=48, num_worlds=64), rewards=RewardConfig(sigma_q=1e-3),
                      residual=ResidualConfig(hidden_dims=(32, 32), critic_hidden_dims=(32, 32), init_std=0.5),
                      ppo=PPOConfig(num_steps_per_env=48, iterations=12, save_interval=12,
                                    num_mini_batches=2, num_learning_epochs=4, learning_rate=3e-4, desired_kl=0.01,
                                    select_every=1))
    summary = train(data, cartpole, cfg, tmp_path / "run")
    val = np.array([row["validation"] for row in summary["validation_curve"]])
    score = ValidationScore(cartpole, data.split("validation"), data.rate_hz)
    pd = score()
    assert summary["selected_validation"] == val.min() < 0.7 * pd, (val / pd).round(3)
    # a stretch of iterations below PD, not one lucky iterate that the selection on these replays picked
    assert (val < 0.9 * pd).sum() >= 3, (val / pd).round(3)
    policy, meta = load_policy(tmp_path / "run")  # the export is the selected residual
    assert score(policy, meta["kind"]) == pytest.approx(val.min(), rel=1e-5)
