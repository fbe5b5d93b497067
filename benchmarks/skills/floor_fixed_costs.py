"""Time a floor seed's two fixed parts on this host and print digests two trees compare: the motions' draw and
screening (``make_motions``, serial: the per-motion cost a pool divides) and the deployment of the shipped policies
(``deploy_all``: the reference, (a), (b) and (d) on the real robot's floor, (a) in its nominal simulator, on the
validation and held-out motions), e.g. ``python benchmarks/skills/floor_fixed_costs.py --per-family 1``.

Prints one JSON line: the wall-clock and the process's CPU time of each part [s] (on a shared host the CPU time
varies less), the SHA-256 of the motion set
(``motion_pool.py``'s digest: arrays, names, screen reports, parameters) and of every deployment's metrics (the
per-motion and mean figures of ``results.json``, as JSON), which must be equal before and after a change that claims
to keep every bit."""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from motion_pool import digest  # noqa: E402

from wresdyn.data.mismatch import Mismatch  # noqa: E402
from wresdyn.data.real_robot import RealRobot  # noqa: E402
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot  # noqa: E402
from wresdyn.skills.deployment_store import DeploymentStore, deploy_all  # noqa: E402
from wresdyn.skills.motions import make_motions  # noqa: E402
from wresdyn.skills.plants import RealPlant, sim_plant  # noqa: E402
from wresdyn.skills.shipped import install_policy  # noqa: E402
from wresdyn.skills.skill_config import FloorTaskConfig  # noqa: E402

SHIPPED = {"a_nominal": "floor_nominal", "b_calibrated": "floor_calibrated", "d_oracle": "floor_oracle"}
"""The policies deployed, as the CPU run ``wresdyn deploy --floor --shipped`` takes them."""
OWN_SIM = {"reference": "nominal", "a_nominal": "nominal", "b_calibrated": None, "d_oracle": "real"}
"""Where each is deployed besides the real robot (the shipped run has no calibrated fit to build (b)'s simulator)."""


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--per-family", type=int, default=1, help="validation and held-out motions per family")
    p.add_argument("--rate", type=float, default=500.0, help="sample rate [Hz] (the shipped dataset's)")
    p.add_argument("--mismatch", default="data/mismatch_default.toml")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--motions-only", action="store_true", help="draw and time the motions only")
    p.add_argument("--full", action="store_true",
                   help="the full-size run's motion set instead: 16 training, 4 validation and 10 held-out motions a "
                        "family (FloorDeployConfig.full), as `wresdyn deploy --floor --full` draws it")
    p.add_argument("--workers", type=int, default=1, help="motion processes (make_motions workers)")
    a = p.parse_args()
    stand = load_robot(DEFAULT_ROBOT)
    floating = load_robot(stand.source, base="floating")
    counts = ({"train": 16, "validation": 4, "heldout": 10} if a.full
              else {"validation": a.per_family, "heldout": a.per_family})
    t0, c0 = time.perf_counter(), time.process_time()
    motions = make_motions(stand, counts, 4.0, a.rate, a.seed, floating=floating, workers=a.workers)
    out = {"motions": sum(len(m) for m in motions.splits.values()), "motions_s": round(time.perf_counter() - t0, 2),
           "motions_cpu_s": round(time.process_time() - c0, 2), "motions_sha256": digest(motions)}
    if not a.motions_only:
        task = FloorTaskConfig()
        real = RealRobot(floating, Mismatch.load(a.mismatch), a.rate)
        with tempfile.TemporaryDirectory() as tmp:
            for name, source in SHIPPED.items():
                install_policy(source, Path(tmp) / "skills" / name)
            store = DeploymentStore(tmp, {"task": {}, "real": {}, "sim": {}, "motions": {}}, lambda s: None)
            t0, c0 = time.perf_counter(), time.process_time()
            res_real, res_sim, _ = deploy_all(
                store, OWN_SIM, Path(tmp) / "skills", motions,
                lambda worlds: RealPlant(real, worlds, task.decimation, seed=a.seed + 100,
                                         imu_noise=(task.gyro_noise, task.gravity_noise)),
                lambda setting, worlds: sim_plant(setting, floating, worlds, a.rate, task.decimation, None, "cpu",
                                                  ground=True), task, stand, {}, lambda setting: {})
            out["deploy_s"] = round(time.perf_counter() - t0, 2)
            out["deploy_cpu_s"] = round(time.process_time() - c0, 2)
        figures = json.dumps({"real": res_real, "sim": res_sim}, sort_keys=True, default=str)
        out["deploy_sha256"] = hashlib.sha256(figures.encode()).hexdigest()
        out["heldout_success"] = {n: r["mean"]["success"] for n, r in res_real["heldout"].items()}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
