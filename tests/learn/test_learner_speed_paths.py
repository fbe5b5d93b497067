"""The learners' speed paths at tiny sizes: PPO across processes (torchrun, rsl-rl's multi-GPU PPO, here over gloo on
the CPU: the residual and the floor skills), stopping at a validation target (time to fidelity), ablation cells spread over GPUs, and (CUDA only) the
graph-replayed environment step and gradient-fit iteration against the eager ones."""

import dataclasses
import json
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from wresdyn.cli import main
from wresdyn.config_fields import set_fields
from wresdyn.experiments.ablation import cell_devices
from wresdyn.fit.gradfit import GradFitConfig, fit
from wresdyn.learn.residual import ResidualConfig
from wresdyn.ppo.ppo_config import default_config
from wresdyn.ppo.replay_env import ReplayEnv, ReplayEnvConfig
from wresdyn.ppo.trainer import train

TORCHRUN = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2", "-m", "wresdyn.cli",
            "train", "data/dataset.npz", "--num-envs", "16", "--steps-per-env", "8", "--device", "cpu",
            "--save-interval", "1", "--set", "ppo.select_every=1"]


def _torchrun(*argv):
    env = dict(os.environ, OMP_NUM_THREADS="1")
    return subprocess.run([*TORCHRUN, *argv], capture_output=True, text=True, env=env, timeout=600)


def _failure(res) -> str:
    """What a failed torchrun says: the ranks' own lines (errors, tracebacks, aborts), then the launcher's summary."""
    own = [ln for ln in res.stderr.splitlines() if not ln.lstrip().startswith(("E1", "W1", "I1"))
           and any(k in ln for k in ("Error", "error", "Traceback", "terminate", "Abort", "abort", "File "))]
    return "\n".join(own[:60]) + "\n--- launcher:\n" + res.stderr[-1500:]


def test_torchrun_trains_on_two_processes_resumes_and_refuses_a_changed_config(tmp_path, monkeypatch, capsys):
    run = tmp_path / "run"
    res = _torchrun("--out", str(run), "--iterations", "2")
    assert res.returncode == 0, _failure(res)
    # rsl-rl's multi-GPU PPO ran: rank 1 took rank 0's parameters, gradients are averaged across the two
    assert "Synchronizing parameters for rank 1" in res.stdout
    s = json.loads((run / "train_summary.json").read_text())
    assert s["processes"] == 2 and s["iterations_this_session"] == 2
    assert s["env_steps_this_session"] == 2 * 16 * 8  # 8 worlds per process, both counted
    assert sorted(p.name for p in run.glob("model_*.pt")) == ["model_0.pt", "model_1.pt"]
    assert (run / "policy.pt").is_file() and (run / "best.pt").is_file()
    # a killed run resumes from its checkpoint on every rank
    (run / "model_1.pt").unlink()
    res = _torchrun("--out", str(run), "--iterations", "3")
    assert res.returncode == 0, _failure(res)
    assert json.loads((run / "train_summary.json").read_text())["iterations_this_session"] == 2
    assert (run / "model_2.pt").is_file()
    # a changed configuration is refused in one line by each rank (here in this process, in the environment torchrun
    # gives it) before the process group forms, and nothing of the run is rewritten
    saved = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    for rank in (0, 1):
        for name in ("RANK", "LOCAL_RANK"):
            monkeypatch.setenv(name, str(rank))
        monkeypatch.setenv("WORLD_SIZE", "2")
        capsys.readouterr()
        assert main([*TORCHRUN[TORCHRUN.index("train"):], "--out", str(run), "--iterations", "4",
                     "--set", "ppo.gamma=0.95"]) == 2
        errors = [ln for ln in capsys.readouterr().err.splitlines() if ": error:" in ln]
        assert len(errors) == 1 and "ppo.gamma" in errors[0], (rank, errors)
    now = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    assert now["train.log"].startswith(saved.pop("train.log"))  # the refused commands' lines appended to its log
    assert {k: v for k, v in now.items() if k != "train.log"} == saved


@pytest.mark.slow  # an option off by default; tests/ppo/test_update.py checks it against rsl-rl's update in one process
def test_torchrun_one_sync_update_trains_as_rsl_rls(tmp_path):
    """Across two processes the one-sync update (gradients and KL in one all-reduce, the learning rate adapted on
    every rank) ends where rsl-rl's (KL all-reduced, rate broadcast from rank 0) does, up to float rounding."""
    weights = {}
    for one_sync in (False, True):
        run = tmp_path / f"one_sync_{one_sync}"
        res = _torchrun("--out", str(run), "--iterations", "2", "--set", f"ppo.one_sync_update={one_sync}",
                        "--set", "ppo.desired_kl=0.001")
        assert res.returncode == 0, _failure(res)
        weights[one_sync] = torch.load(run / "model_1.pt", weights_only=True)
    a, b = weights[False], weights[True]
    for key in ("actor_state_dict", "critic_state_dict"):
        for name, t in a[key].items():
            torch.testing.assert_close(b[key][name], t, rtol=1e-4, atol=1e-5, msg=f"{key} {name}")
    lr = [w["optimizer_state_dict"]["param_groups"][0]["lr"] for w in (a, b)]
    # the rate moved, the same way on both; rsl-rl broadcasts it as a float32 tensor, so its rate is rounded to float32
    assert lr[1] == pytest.approx(lr[0], rel=1e-6) and lr[0] != 1e-3


@pytest.mark.parametrize("rank", [0, 1])
def test_train_refuses_worlds_that_do_not_split_on_every_rank(tmp_path, monkeypatch, capsys, rank):
    """Each rank of a torchrun launch (its environment as torchrun sets it: the torchrun tests above) refuses a world
    count that does not split, in one line, before anything is loaded or written."""
    for name, value in (("WORLD_SIZE", "2"), ("RANK", str(rank)), ("LOCAL_RANK", str(rank))):
        monkeypatch.setenv(name, value)
    argv = ["train", "data/dataset.npz", "--out", str(tmp_path / "odd"), "--ppo.iterations", "1", "--ppo.device", "cpu"]
    assert main([*argv, "--env.num-worlds", "15"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("wresdyn train: error:") and "does not split over 2 processes" in err[0]
    assert not (tmp_path / "odd").exists()


SKILL_SCRIPT = """
import sys
from pathlib import Path

import torch

from wresdyn.ppo.runner import Ranks
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.skills.env import SkillTaskConfig, TrackingEnv
from wresdyn.skills.motions import make_motions
from wresdyn.skills.plants import SimPlant
from wresdyn.skills.skill_ppo import SkillPPOConfig, rank_share, train_skill

torch.set_num_threads(1)
out, envs = Path(sys.argv[1]), int(sys.argv[2])
robot = load_robot(DEFAULT_ROBOT)
floating = load_robot(robot.source, base="floating")
motions = make_motions(robot, {"train": 1}, duration=1.0, rate_hz=500.0, seed=3, floating=floating, screen=False)


def skills(session, iterations):
    cfg = SkillPPOConfig(iterations=iterations, num_steps_per_env=4, hidden_dims=(32, 32),
                         num_mini_batches=1, num_learning_epochs=1, save_interval=1, torch_threads=1)
    n, device = rank_share(envs, cfg.device)
    for run in (out, out.with_name(out.name + "_second")):  # the second skill joins the first one's process group
        env = TrackingEnv(SimPlant(floating, n, 500.0, 5, ground=True), motions["train"],
                          SkillTaskConfig.floor(decimation=5), seed=Ranks.from_env().rank, device=device)
        s = train_skill(env, cfg, run, log=lambda *_: None)
        print("SUMMARY", session, s["processes"], s["env_steps_this_session"], s["iterations_this_session"], flush=True)


skills("first", 2)
torch.distributed.barrier()  # every rank done with the run before rank 0 takes its last checkpoint away
if Ranks.from_env().main:
    print("CHECKPOINTS", *sorted(p.name for p in out.glob("model_*.pt")), flush=True)
    (out / "model_1.pt").unlink()  # killed after iteration 0: every rank resumes from model_0.pt
torch.distributed.barrier()
skills("resumed", 3)
Ranks.from_env().close()
"""


def test_torchrun_trains_a_floor_skill_on_two_processes_and_resumes(tmp_path):
    """The floor benchmark's skill PPO data-parallel as the residual's: each process its share of the worlds, rank 0
    writes the run, every rank resumes from the same checkpoint, and a second skill of the same processes joins their
    process group. One launch: the resume reads the checkpoints from disk in the ranks' next runners; a resume in a
    fresh launch (its process group started by the resumed runner) is the residual's torchrun test above, through the
    same runner and ``resume_runner``."""
    script = tmp_path / "skill.py"
    script.write_text(SKILL_SCRIPT)
    run = tmp_path / "skill"
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2", str(script), str(run)]
    # the checkout first, then the caller's path (a machine that installs its wheels off the default path lists them)
    path = os.pathsep.join(filter(None, (os.getcwd(), os.environ.get("PYTHONPATH"))))
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=path)
    res = subprocess.run([*cmd, "4"], capture_output=True, text=True, env=env, timeout=600)
    assert res.returncode == 0, _failure(res)
    assert "Synchronizing parameters for rank 1" in res.stdout
    # both ranks ran 2 iterations of 2 worlds x 4 steps, and count both ranks' env-steps; then a second skill
    assert res.stdout.count("SUMMARY first 2 32 2") == 4, res.stdout[-2000:]
    assert "CHECKPOINTS model_0.pt model_1.pt\n" in res.stdout
    assert (tmp_path / "skill_second" / "policy.pt").is_file()
    # the resumed session: 2 iterations from model_0.pt on every rank, the finished second skill 1 from its model_1.pt
    assert res.stdout.count("SUMMARY resumed 2 32 2") == 2 and (run / "model_2.pt").is_file(), res.stdout[-2000:]
    assert res.stdout.count("SUMMARY resumed 2 16 1") == 2
    s = json.loads((run / "train_summary.json").read_text())
    assert s["processes"] == 2 and s["collect_s_per_iteration"] > 0 and s["learn_s_per_iteration"] > 0
    assert (run / "policy.pt").is_file()


def test_learners_stop_at_the_validation_target(robot, data, tmp_path):
    # a target every residual meets: each learner stops at its first validation check
    cfg = set_fields(default_config(), {"env.num_worlds": 4, "ppo.num_steps_per_env": 8, "ppo.iterations": 10,
                                        "ppo.select_every": 2, "ppo.save_interval": 2})
    s = train(data, robot, cfg, tmp_path / "ppo", stop_below=10.0)
    assert s["stopped_at_target"] == 2 and s["iterations_this_session"] == 2
    assert [r["iteration"] for r in s["validation_curve"]] == [2] and s["validation_curve"][0]["wall_s"] > 0
    assert (tmp_path / "ppo" / "policy.pt").is_file()
    # an unreachable one runs the whole schedule
    s = train(data, robot, set_fields(cfg, {"ppo.iterations": 4}), tmp_path / "ppo_all", stop_below=0.0)
    assert s["stopped_at_target"] is None and s["iterations_this_session"] == 4
    gc = GradFitConfig(windows=2, horizon=4, horizon_curriculum=(), iterations=10, select_every=3)
    _, curve = fit(robot, data, gc, log=lambda *_: None, stop_below=10.0)
    assert curve[-1]["iteration"] == 3 and "validation" in curve[-1]


def test_ablation_cells_spread_round_robin_over_gpus():
    assert cell_devices("cuda", 5, gpus=2) == ["cuda:0", "cuda:1", "cuda:0", "cuda:1", "cuda:0"]
    assert cell_devices("cuda:1", 2) == ["cuda:1", "cuda:1"] and cell_devices("cpu", 1) == ["cpu"]
    with pytest.raises(ValueError, match="torch sees none"):
        cell_devices("cuda", 2, gpus=0)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need a GPU")
@pytest.mark.parametrize("excluded", [0, 3])
def test_graph_replayed_step_equals_the_eager_step(robot, data, excluded):
    weights = np.ones(robot.n_dof)
    weights[:excluded] = 0.0  # joints excluded from fitting: the weighted rewards and errors in the graph too
    envs = {g: ReplayEnv(robot, data.split("train"), data.rate_hz, 64, ReplayEnvConfig(horizon=400), device="cuda:0",
                         seed=1, graph=g, weights=weights) for g in (True, False)}
    a, b = envs[True], envs[False]
    # the same episodes in both (no episode ends within the steps below)
    for name in ("g", "q", "qd", "qdd"):
        getattr(a, name).copy_(getattr(b, name))
    a.end.fill_(10**9)
    b.end.fill_(10**9)
    a.sim.set_state(None, b.q, b.qd)
    gen = torch.Generator(device="cuda:0").manual_seed(0)
    for _ in range(6):  # two eager warm-ups, two captures, replays of both
        act = 0.5 * torch.randn(64, robot.n_dof, device="cuda:0", generator=gen)
        oa, ra, da, ea = a.step(act)
        ob, rb, db, eb = b.step(act)
        torch.testing.assert_close(a.q, b.q, atol=1e-5, rtol=0)
        torch.testing.assert_close(oa["critic"], ob["critic"], atol=1e-3, rtol=1e-4)
        torch.testing.assert_close(ra, rb, atol=1e-4, rtol=1e-4)
        torch.testing.assert_close(ea["log"]["Error/mean_abs_dq"], eb["log"]["Error/mean_abs_dq"], atol=1e-6, rtol=1e-4)
        assert torch.equal(da, db) and not da.any()
    assert len(a._graphs) == 2 and not b._graphs


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need a GPU")
@pytest.mark.parametrize("arch", ["mlp", "gru"])
def test_graph_replayed_fit_iteration_equals_the_eager_one(robot, data, tmp_path, arch):
    # two window lengths: each warms up eagerly, is captured, then replayed; observation noise on (a fixed buffer)
    cfg = GradFitConfig(residual=ResidualConfig(fraction=0.25, arch=arch, hidden_dims=(64, 64)), windows=64,
                        horizon_curriculum=(4, 8), iterations=12, select_every=6, device="cuda:0")
    runs = {g: fit(robot, data, dataclasses.replace(cfg, cuda_graph=g), log=lambda *_: None) for g in (True, False)}
    (pa, ca), (pb, cb) = runs[True], runs[False]
    assert len(ca) == len(cb) == 12
    np.testing.assert_allclose([r["loss"] for r in ca], [r["loss"] for r in cb], rtol=1e-3)
    np.testing.assert_allclose([r["validation"] for r in ca if "validation" in r],
                               [r["validation"] for r in cb if "validation" in r], atol=1e-5)
    for (name, a), b in zip(pa.state_dict().items(), pb.state_dict().values()):
        torch.testing.assert_close(a, b, atol=1e-4, rtol=1e-3, msg=name)
    # an eager checkpoint resumed with graphs (Adam's state moved to where capturable wants it) continues alike
    fit(robot, data, dataclasses.replace(cfg, cuda_graph=False), out=tmp_path, until=6, log=lambda *_: None)
    _, cc = fit(robot, data, cfg, out=tmp_path, log=lambda *_: None)
    np.testing.assert_allclose([r["loss"] for r in cc], [r["loss"] for r in ca], rtol=1e-3)
