"""How close the oracle's mujoco_warp real robot (RealWarpPlant) stays to the MuJoCo C one (RealPlant) that policies
are deployed on: every held-out floor motion played open loop on both, sensor noise off; per motion the largest and
mean joint difference and the largest base-position difference over the motion, and the time per policy step.

    python benchmarks/skills/real_warp_parity.py [--duration 4] [--device cpu|cuda:0] [--worlds N]

``--worlds N`` also times N worlds of each plant (a standing robot held still) for a few policy steps.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np
import torch

from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.paths import DEFAULT_MISMATCH
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.robot.ground import standing_state
from wresdyn.skills.motions import make_motions
from wresdyn.skills.plants import RealPlant
from wresdyn.skills.real_warp import RealWarpPlant

DEC = 5
"""Recording periods per policy step (the floor task's)."""


def parity(real, robot, floating, duration: float, device: str) -> None:
    motions = make_motions(robot, {"heldout": 1}, duration=duration, rate_hz=real.rate_hz, seed=3,
                           floating=floating)["heldout"]
    m_n = len(motions)
    warp, mjc = RealWarpPlant(real, m_n, DEC, device=device), RealPlant(real, m_n, DEC)
    ids, q0 = torch.arange(m_n), torch.as_tensor(np.stack([m.q[0] for m in motions]))
    base = torch.as_tensor(np.stack([m.base[0] for m in motions]))
    for p in (warp, mjc):
        p.reset_full(ids, base, torch.zeros(m_n, 6), q0, 0 * q0)
    dq, db, t_warp, t_mjc = [], [], [], []
    for k in range(min(len(m.q) for m in motions) // DEC - 1):
        cmd = torch.as_tensor(np.stack([m.q[DEC * (k + 1)] for m in motions]))
        t0 = time.perf_counter()
        qw, _, bad_w = warp.step(cmd)
        qw = qw.cpu()
        t1 = time.perf_counter()
        qc, _, bad_c = mjc.step(cmd)
        t_warp.append(t1 - t0)
        t_mjc.append(time.perf_counter() - t1)
        dq.append((qw - qc).abs().max(-1).values.numpy())
        db.append((warp.base_pose.cpu() - mjc.base_pose)[:, :3].abs().max(-1).values.numpy())
        assert not (bad_w.any() or bad_c.any()), f"step {k}: a plant diverged"
    dq, db = np.array(dq), np.array(db)
    print(f"{len(dq)} policy steps of {DEC / real.rate_hz * 1e3:g} ms ({real.n_sub * DEC} physics substeps each), "
          f"mujoco_warp on {warp.device}, overflow flags {int(warp.data.overflow.numpy().max())}")
    print(f"{'motion':<24} {'max |dq| rad':>13} {'mean |dq| rad':>14} {'max |dbase| m':>14} {'final z m':>10}")
    z = mjc.base_pose[:, 2].numpy()
    for i, m in enumerate(motions):
        print(f"{m.name:<24} {dq[:, i].max():13.2e} {dq[:, i].mean():14.2e} {db[:, i].max():14.2e} {z[i]:10.3f}")
    first = np.argmax(dq.max(1) > 1e-3) if (dq.max(1) > 1e-3).any() else None
    print(f"first step over 1e-3 rad: {first}; all motions over the first second: max |dq| "
          f"{dq[:int(1.0 * real.rate_hz / DEC)].max():.2e} rad")
    print(f"time per policy step ({m_n} worlds): mujoco_warp {np.median(t_warp[1:]) * 1e3:.1f} ms, "
          f"MuJoCo C {np.median(t_mjc[1:]) * 1e3:.1f} ms (medians; first warp step {t_warp[0]:.1f} s)")


def timing(real, floating, worlds: int, device: str, steps: int = 5) -> None:
    st = standing_state(floating)
    tile = lambda a: torch.as_tensor(np.tile(a, (worlds, 1)))  # noqa: E731
    for name, plant in (("mujoco_warp", RealWarpPlant(real, worlds, DEC, device=device)),
                        ("MuJoCo C", RealPlant(real, worlds, DEC))):
        plant.reset_full(torch.arange(worlds), tile(st.base_pose), tile(st.base_twist), tile(st.q), tile(st.qd))
        plant.step(tile(st.q))  # compiles / captures
        t0 = time.perf_counter()
        for _ in range(steps):
            q, _, _ = plant.step(tile(st.q))
        q.cpu()
        print(f"{name}: {worlds} worlds, {(time.perf_counter() - t0) / steps * 1e3:.1f} ms per policy step")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=4.0, help="length of each held-out motion [s]")
    ap.add_argument("--device", default="cpu", help="mujoco_warp's device")
    ap.add_argument("--worlds", type=int, default=0, help="also time this many worlds of each plant")
    args = ap.parse_args()
    torch.set_num_threads(1)
    robot = load_robot(DEFAULT_ROBOT)
    floating = load_robot(robot.source, base="floating")
    quiet = dataclasses.replace(Mismatch.load(DEFAULT_MISMATCH), position_noise=0.0, velocity_noise=0.0,
                                encoder_resolution=0.0, velocity_resolution=0.0)
    real = RealRobot(floating, quiet, 500.0)
    parity(real, robot, floating, args.duration, args.device)
    if args.worlds:
        timing(real, floating, args.worlds, args.device)


if __name__ == "__main__":
    main()
