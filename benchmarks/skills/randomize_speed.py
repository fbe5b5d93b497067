"""How much domain randomisation slows a skill's training: PPO iteration time of one plant, at equal size, with

- ``fixed``: the robot file's physics in every world (as the (b) policy's plant: one physics, no redraw);
- ``startup``: (e)'s draws, once at construction (the randomised physics' own cost: dry friction adds constraints);
- ``redraw``: (e)'s draws again on every reset, written in place, the solver's refresh eager (the CPU's path);
- ``redraw_graph``: as ``redraw``, the refresh replayed from a CUDA graph (``Simulator.refresh_graph``, CUDA's default;
  CUDA only);
- ``recapture``: as the redraws were before they wrote in place: each followed by the broad model-changed notice
  and a new capture of the solver's CUDA graphs;

plus the cost of one redraw of a twentieth of the worlds alone, and of the solver's refresh per Newton ``ModelFlags``
member (``redraw``: the eager refresh, where mujoco_warp's ``set_const_0`` dominates).

Before the first timed plant, ``--warmup`` PPO iterations (default 1) of the first mode's plant run untimed: the
process's first iteration compiles or loads every kernel of the step and starts torch's CUDA libraries, which would
otherwise count in the first mode's time only (on one H200 from an empty Warp cache: 47.5 s of ``fixed``'s first
iteration, against 0.64-0.69 s for the next four).

Usage:
    python benchmarks/skills/randomize_speed.py OUT [--device cuda:0] [--worlds 4096] [--iterations 5] [--floor]
        [--warmup 1]

On the CPU the floor's several worlds run in MuJoCo C threads that share world 0's physics (no randomisation): the
CPU run steps the humanoid on its stand in mujoco_warp on Warp's CPU device, the floor plants' solver. Writes
``OUT/randomize_speed.json`` and prints one line per plant.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.skills.env import TrackingEnv
from wresdyn.skills.motions import make_motions
from wresdyn.skills.plants import SimPlant
from wresdyn.skills.randomize import Randomization
from wresdyn.skills.skill_config import SkillConfig, SkillPPOConfig, SkillTaskConfig
from wresdyn.skills.skill_ppo import train_skill

RATE = 500.0
DECIMATION = 10


def plant(robot, worlds: int, device: str, floor: bool, mode: str) -> SimPlant:
    """The plant of ``mode`` (module docstring)."""
    dr = None if mode == "fixed" else Randomization(seed=0, redraw="startup" if mode == "startup" else "reset")
    p = SimPlant(robot, worlds, RATE, DECIMATION, device=device, ground=floor, solver="auto" if floor else "mujoco",
                 randomization=dr)
    p.sim.refresh_graph = mode == "redraw_graph"
    if mode == "recapture":
        draw, sim = p.randomizer.draw, p.sim

        def draw_then_recapture(ids=None):
            out = draw(ids)
            sim._physics_changed()  # JOINT_DOF_PROPERTIES | BODY_INERTIAL_PROPERTIES, graphs dropped
            return out

        p.randomizer.draw = draw_then_recapture
    return p


def sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize(device)


def redraw_seconds(p: SimPlant, device: str, repeats: int = 10) -> float:
    """What one redraw of a twentieth of the worlds (a reset's share) adds to the policy step after it [s]: the mean
    of (redraw + step) less that of a step alone, so a graph captured again at the step is counted."""
    k = max(1, p.num_worlds // 20)
    rng = np.random.default_rng(0)
    hold = p.q.clone()

    def mean(redraw: bool) -> float:
        sync(device)
        t0 = time.perf_counter()
        for _ in range(repeats):
            if redraw:
                ids = torch.as_tensor(np.sort(rng.choice(p.num_worlds, k, replace=False)))
                p._set_delay(ids, p.randomizer.draw(ids))
            p.step(hold)
        sync(device)
        return (time.perf_counter() - t0) / repeats

    mean(False)  # warm: the step's graph captured
    return mean(True) - mean(False)


def refresh_ms(p: SimPlant, device: str, repeats: int = 5) -> dict:
    """Mean wall time [ms] of the solver's refresh after a change of each kind of field, and of all at once."""
    from newton import ModelFlags as F

    from wresdyn.sim.world_physics import refresh

    kinds = {"force": F.JOINT_DOF_FORCE_PROPERTIES, "armature": F.JOINT_DOF_INERTIAL_PROPERTIES,
             "bodies": F.BODY_INERTIAL_PROPERTIES, "shapes": F.SHAPE_PROPERTIES}
    kinds["all"] = sum((int(f) for f in kinds.values()), 0)
    out = {}
    for name, flags in kinds.items():
        refresh(p.sim, int(flags))
        sync(device)
        t0 = time.perf_counter()
        for _ in range(repeats):
            refresh(p.sim, int(flags))
        sync(device)
        out[name] = 1e3 * (time.perf_counter() - t0) / repeats
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--worlds", type=int, default=8)
    ap.add_argument("--iterations", type=int, default=3)
    ap.add_argument("--floor", action="store_true", help="the floor's plants (a GPU: several worlds per device)")
    ap.add_argument("--modes", nargs="+", default=["fixed", "startup", "redraw", "redraw_graph", "recapture"])
    ap.add_argument("--warmup", type=int, default=1, help="untimed PPO iterations first (module docstring; 0: none)")
    a = ap.parse_args()
    torch.set_num_threads(1)
    stand = load_robot(DEFAULT_ROBOT)
    robot = load_robot(stand.source, base="floating") if a.floor else stand
    task = SkillTaskConfig.floor(decimation=DECIMATION) if a.floor else SkillConfig(decimation=DECIMATION)
    motions = make_motions(stand, {"train": 2}, duration=2.0, rate_hz=RATE, seed=0,
                           floating=robot if a.floor else None, screen=False).split("train")
    ppo = SkillPPOConfig(iterations=a.iterations, torch_threads=1)
    a.out.mkdir(parents=True, exist_ok=True)
    rows = {}
    modes = [m for m in a.modes if a.device.startswith("cuda") or m != "redraw_graph"]
    if a.warmup > 0 and modes:
        env = TrackingEnv(plant(robot, a.worlds, a.device, a.floor, modes[0]), motions, task, device=a.device)
        train_skill(env, SkillPPOConfig(iterations=a.warmup, torch_threads=1), a.out / "warmup", log=lambda *_: None)
    for mode in modes:
        p = plant(robot, a.worlds, a.device, a.floor, mode)
        env = TrackingEnv(p, motions, task, device=a.device)
        s = train_skill(env, ppo, a.out / mode, log=lambda *_: None)
        rows[mode] = {"s_per_iteration": s["wall_s_this_session"] / s["iterations_this_session"],
                      "collect_s_per_iteration": s["collect_s_per_iteration"], "episodes": s["episodes"],
                      "redraw_s": None if mode in ("fixed", "startup") else redraw_seconds(p, a.device)}
        r = rows[mode]
        if mode in ("redraw", "redraw_graph"):
            r["refresh_ms"] = refresh_ms(p, a.device)
        k = max(1, a.worlds // 20)
        redraw = "" if r["redraw_s"] is None else f", one redraw {1e3 * r['redraw_s']:.1f} ms ({k} worlds)"
        print(f"{mode:10s} {r['s_per_iteration']:.3f} s/iteration (collect {r['collect_s_per_iteration']:.3f} s), "
              f"{r['episodes']} episodes{redraw}", flush=True)
        if "refresh_ms" in r:
            print("  refresh [ms]: " + ", ".join(f"{k} {v:.1f}" for k, v in r["refresh_ms"].items()), flush=True)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    record = {"command": " ".join(["python", *sys.argv]),
              "commit": commit, "machine": platform.node(), "device": a.device, "worlds": a.worlds,
              "iterations": a.iterations, "warmup_iterations": a.warmup, "num_steps_per_env": ppo.num_steps_per_env,
              "floor": a.floor, "plants": rows}
    (a.out / "randomize_speed.json").write_text(json.dumps(record, indent=2) + "\n")


if __name__ == "__main__":
    main()
