"""A skill run that has trained all its iterations is reused as it is: no environment, no rewrite, its stored summary;
more iterations resume it, another configuration is refused. Tiny sizes on the CPU, rsl-rl's real PPO."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from wresdyn.experiments import skills as bench
from wresdyn.experiments.deploy_config import DeployConfig
from wresdyn.learn.runs import RunError
from wresdyn.paths import REPO
from wresdyn.skills.env import SkillConfig, TrackingEnv
from wresdyn.skills.motions import make_motions
from wresdyn.skills.plants import SimPlant
from wresdyn.skills.skill_config import SkillPPOConfig
from wresdyn.skills.skill_ppo import finished_skill, train_skill

import skill_runs

RATE = skill_runs.RATE
TASK = SkillConfig(decimation=5)
PPO = SkillPPOConfig(iterations=1, num_steps_per_env=4, hidden_dims=(16,), num_mini_batches=1, torch_threads=1)


@pytest.fixture(scope="module")
def motions(humanoid):
    return make_motions(humanoid, {"train": 1, "validation": 1, "heldout": 1}, duration=0.4, rate_hz=RATE, seed=3)


def snapshot(run: Path) -> dict:
    """Every file of a run folder: its bytes and modification time [ns]."""
    return {p.relative_to(run): (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(run.rglob("*")) if p.is_file()}


def test_a_finished_skill_is_reused_untouched_and_extended_on_request(tmp_path, humanoid, motions):
    def env(worlds=2):
        return TrackingEnv(SimPlant(humanoid, worlds, RATE, 5), motions.split("train"), TASK)

    run, lines = tmp_path / "skill", []
    trained = train_skill(env(), PPO, run, log=lambda *_: None)
    assert trained["iterations_this_session"] == 1
    stored = json.loads((run / "train_summary.json").read_text())
    before = snapshot(run)
    assert {"config.json", "model_0.pt", "policy.pt", "train_summary.json"} <= {str(p) for p in before}

    # checked without an environment: the stored summary, nothing written
    assert finished_skill(PPO, run, dataclasses.asdict(TASK), 2) == stored
    # given one, it is not stepped: the stored summary again, one line, the folder byte for byte as it was
    again = env()
    assert train_skill(again, PPO, run, log=lines.append) == stored
    assert again.steps_total == 0
    assert lines == ["skill: done earlier (1 iterations), reused"]
    assert snapshot(run) == before

    # another configuration is refused as before, by both, and nothing is written
    with pytest.raises(RunError, match="num_worlds"):
        finished_skill(PPO, run, dataclasses.asdict(TASK), 3)
    with pytest.raises(RunError, match="num_steps_per_env"):
        train_skill(env(), dataclasses.replace(PPO, num_steps_per_env=5), run, log=lambda *_: None)
    assert snapshot(run) == before

    # more iterations: not finished, so it resumes from its checkpoint and trains the one more
    longer = dataclasses.replace(PPO, iterations=2)
    assert finished_skill(longer, run, dataclasses.asdict(TASK), 2) is None
    lines.clear()
    extended = train_skill(env(), longer, run, log=lines.append)
    assert extended["iterations"] == 2 and extended["iterations_this_session"] == 1
    assert any(line.startswith(f"resuming {run} from model_0.pt at iteration 1") for line in lines), lines
    assert (run / "model_1.pt").is_file()
    assert finished_skill(longer, run, dataclasses.asdict(TASK), 2) == extended

    # an export cut short (no policy.pt) is not finished: the run resumes and writes it again
    (run / "policy.pt").unlink()
    assert finished_skill(longer, run, dataclasses.asdict(TASK), 2) is None
    assert train_skill(env(), longer, run, log=lambda *_: None)["iterations_this_session"] == 0
    assert (run / "policy.pt").is_file()


def test_the_benchmark_reuses_a_finished_policy_without_building_its_plant(tmp_path, humanoid, motions,
                                                                          shipped_mismatch, monkeypatch):
    real = skill_runs.quiet_real(humanoid, shipped_mismatch)
    cfg = DeployConfig(iterations=1, num_worlds=2, seed=0)
    meta = {"motions": {"seed": 0}}
    lines = []

    def train(log):
        return bench._train_policy(0, "a_nominal", humanoid, real, motions.split("train"), TASK, PPO, cfg, {}, meta,
                                   tmp_path, log)

    train(lambda *_: None)
    run = tmp_path / "skills" / "a_nominal"
    before = snapshot(run)

    def no_plant(*args, **kwargs):
        raise AssertionError("a finished policy's plant was built")

    monkeypatch.setattr(bench, "sim_plant", no_plant)
    monkeypatch.setattr(bench, "TrackingEnv", no_plant)
    train(lines.append)
    assert lines == ["[3/4] policy a_nominal: done earlier (1 iterations), reused"]
    assert snapshot(run) == before
    # another configuration is still refused before any plant is built
    with pytest.raises(RunError, match="seed"):
        bench._train_policy(0, "a_nominal", humanoid, real, motions.split("train"), TASK, PPO,
                            dataclasses.replace(cfg, seed=5), {}, {"motions": {"seed": 5}}, tmp_path, lines.append)
    assert snapshot(run) == before


TORCHRUN_SCRIPT = """
import sys
from pathlib import Path

import torch

from wresdyn.ppo.runner import Ranks
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.skills.env import SkillConfig, TrackingEnv
from wresdyn.skills.motions import make_motions
from wresdyn.skills.plants import SimPlant
from wresdyn.skills.skill_ppo import SkillPPOConfig, rank_share, train_skill

torch.set_num_threads(1)
run, rank = Path(sys.argv[1]), Ranks.from_env().rank
robot = load_robot(DEFAULT_ROBOT)
motions = make_motions(robot, {"train": 1}, duration=0.4, rate_hz=500.0, seed=3)
for iterations in map(int, sys.argv[2:]):
    cfg = SkillPPOConfig(iterations=iterations, num_steps_per_env=4, hidden_dims=(16,), num_mini_batches=1,
                         num_learning_epochs=1, torch_threads=1)
    n, device = rank_share(4, cfg.device)
    env = TrackingEnv(SimPlant(robot, n, 500.0, 5), motions["train"], SkillConfig(decimation=5), seed=rank)
    lines = []
    s = train_skill(env, cfg, run, log=lines.append)
    reused = any("reused" in line for line in lines)
    with open(run.with_name(f"rank{rank}.txt"), "a") as f:  # a file each: the ranks' printed lines interleave
        f.write(f"{iterations} {s['iterations_this_session']} {'reused' if reused else 'trained'}\\n")
Ranks.from_env().close()
"""


@pytest.mark.slow  # two torchrun launches of two processes (about 70 s on 2 cores); run with --run-slow
def test_under_torchrun_every_rank_reuses_a_finished_skill_alike(tmp_path):
    """Two processes over gloo: a skill trained, asked again in the same launch (its process group up) and in a fresh
    one (none started): every rank reuses it; more iterations then resume it on every rank."""
    script, run = tmp_path / "skill.py", tmp_path / "skill"
    script.write_text(TORCHRUN_SCRIPT)
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2", str(script),
           str(run)]
    env = dict(os.environ, OMP_NUM_THREADS="1",
               PYTHONPATH=os.pathsep.join(filter(None, (str(REPO), os.environ.get("PYTHONPATH")))))

    def launch(*iterations):
        res = subprocess.run([*cmd, *map(str, iterations)], capture_output=True, text=True, env=env, timeout=600)
        assert res.returncode == 0, res.stderr[-3000:]
        said = [(tmp_path / f"rank{rank}.txt").read_text().splitlines() for rank in (0, 1)]
        for rank in (0, 1):
            (tmp_path / f"rank{rank}.txt").unlink()
        return said

    # each rank: (iterations asked, iterations this session, trained or reused)
    assert launch(1, 1) == [["1 1 trained", "1 1 reused"]] * 2
    before = snapshot(run)
    assert launch(1, 2) == [["1 1 reused", "2 1 trained"]] * 2
    after = snapshot(run)
    assert after[Path("model_0.pt")] == before[Path("model_0.pt")] and Path("model_1.pt") in after
