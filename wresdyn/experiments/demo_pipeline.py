"""The demo pipeline (``wresdyn demo``): the main job on the embedded defaults, end to end on a 2-core CPU in about
10 minutes.

The whole story at a small size: record → fit → calibrated robot → a skill deployed zero-shot with and without it.

1. robot: load ``scenes/humanoid.usda`` and check Newton against MuJoCo C on a PD replay;
2. data: the shipped dataset ``data/dataset.npz`` (made by ``wresdyn collect``; ``collect`` records a fresh one);
3. learn: the calibrated robot by the gradient fit through the simulation (``wresdyn fit``: identified physics + a
   torque residual) and, for comparison, a torque residual by PPO (``wresdyn train``, the paper's method);
4. evaluate: open-loop replay of the held-out and out-of-distribution trajectories (``wresdyn eval``), and the
   calibrated robot written as USD + Newton actuators (``wresdyn export``);
5. use it: a motion-tracking skill trained by PPO in the nominal simulator, fine-tuned in the calibrated one, and
   fine-tuned on the "real" robot itself (the oracle), each deployed zero-shot on the real robot (``wresdyn deploy``
   at a small size, without its delta-action policy). ``OUT/report.md`` sums it up.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

from ..data.dataset import load_dataset
from ..data.mismatch import Mismatch
from ..data.real_robot import collect as record_dataset
from ..evaluation.evaluate_run import evaluate_run
from ..export.usd import export_run as export_usd
from ..fit.gradfit import GradFitConfig, export_run
from ..fit.hybrid import fit_hybrid
from ..identify.sysid import SysIdConfig
from ..paths import DEFAULT_DATASET, DEFAULT_MISMATCH, DEFAULT_ROBOT
from ..ppo.ppo_config import default_config
from ..ppo.trainer import train
from ..robot.description import load_robot
from ..sim.parity import pd_agreement
from ..skills.skill_config import SkillPPOConfig
from .skills import DeployConfig, run_benchmark

__all__ = ["run_demo"]

QUICK_SECONDS = 2.0
"""Length [s] of each trajectory ``--quick`` keeps (its start: the shipped ones are 4 s)."""


def _head(traj, n: int):
    """The first ``n`` samples of a :class:`~wresdyn.data.dataset.Trajectory` (all of it if shorter)."""
    cut = {f: getattr(traj, f)[:n] for f in ("t", "q", "qd", "qdd", "q_cmd")}
    return dataclasses.replace(traj, **cut, tau=None if traj.tau is None else traj.tau[:n])


def run_demo(out: str | Path = "runs/demo", *, collect: bool = False, ppo_iterations: int = 300,
             skill_iterations: int = 200, quick: bool = False) -> list[str]:
    """Run the demo into ``out``; returns the lines of ``OUT/report.md`` (also printed).

    Args:
        out: Output folder.
        collect: Record a fresh small dataset into ``OUT/data/`` instead of reading the shipped one.
        ppo_iterations: PPO iterations of the residual.
        skill_iterations: PPO iterations of the skill in the nominal simulator, and of each fine-tuning.
        quick: Tiny sizes (the first 2 s of one trajectory per split, two for training; a few iterations each): a
            smoke run of a minute.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    robot = load_robot(DEFAULT_ROBOT)
    a = pd_agreement(robot, 1.0, 0.002, integrator="Euler", solver="featherstone")
    print(f"[1/5] robot: {robot.source.name}, {robot.n_dof} joints, {robot.body_mass.sum():.1f} kg; Newton vs MuJoCo C "
          f"PD replay max |dq| {a.max_abs:.1e} rad", flush=True)

    data_path = DEFAULT_DATASET
    if collect:
        data_path = out / "data" / "dataset.npz"
        if not data_path.is_file():
            mismatch = Mismatch.load(DEFAULT_MISMATCH)
            record_dataset(robot, mismatch, {"train": 4, "validation": 2, "heldout": 2, "ood": 2}, store_tau=False,
                           progress=lambda line: print("      " + line, flush=True)).save(data_path)
    data = load_dataset(data_path, robot=robot)
    if quick:  # the first QUICK_SECONDS of a trajectory per split, two for training: every replay is one of these
        n = int(round(QUICK_SECONDS * data.rate_hz))
        trajs = [t for s, k in (("train", 2), ("validation", 1), ("heldout", 1), ("ood", 1)) for t in data.split(s)[:k]]
        data = dataclasses.replace(data, trajectories=[_head(t, n) for t in trajs])
    splits = ", ".join(f"{s} {len(data.split(s))}" for s in ("train", "validation", "heldout", "ood"))
    print(f"[2/5] data: {data_path} ({splits}"
          f", {data.rate_hz:g} Hz)", flush=True)

    log = lambda line: print("      " + line, flush=True)  # noqa: E731
    gcfg = GradFitConfig()
    scfg = SysIdConfig()
    tcfg = default_config()
    tcfg = dataclasses.replace(tcfg, ppo=dataclasses.replace(tcfg.ppo, iterations=ppo_iterations))
    dcfg = DeployConfig(train_per_family=3, heldout_per_family=1, iterations=skill_iterations,
                        finetune=skill_iterations)
    skill_ppo = SkillPPOConfig()
    if quick:
        gcfg = dataclasses.replace(gcfg, iterations=4, windows=4, horizon_curriculum=(2, 4))
        scfg = dataclasses.replace(scfg, iterations=4, windows=4, identifiability_windows=4)
        tcfg = dataclasses.replace(tcfg, env=dataclasses.replace(tcfg.env, num_worlds=8),
                                   ppo=dataclasses.replace(tcfg.ppo, iterations=2, num_steps_per_env=8))
        dcfg = dataclasses.replace(dcfg, train_per_family=1, iterations=2, finetune=1, num_worlds=8)
        skill_ppo = dataclasses.replace(skill_ppo, torch_threads=1)  # tiny networks: a second thread only waits
    print("[3/5] the calibrated robot: gradient fit through the simulation (identification, then a residual, each "
          "until validation plateaus, `wresdyn fit`) ..." if scfg.iterations is None else
          f"[3/5] the calibrated robot: gradient fit through the simulation ({scfg.iterations} identification + "
          f"{gcfg.iterations} residual iterations, `wresdyn fit`) ...", flush=True)
    fit_dir = out / "fit"
    hybrid = fit_hybrid(robot, data, scfg, gcfg, fit_dir, data_path=data_path, log=log)
    policy, curve, gcfg, id_wall = hybrid.policy, hybrid.curve, hybrid.config, hybrid.identify_wall
    export_run(policy, fit_dir, gcfg, data, data_path, physics=hybrid.physics)
    print(f"      ... and a torque residual by PPO ({tcfg.ppo.iterations} iterations, `wresdyn train`)", flush=True)
    ppo_dir = out / "ppo"
    summary = train(data, robot, tcfg, ppo_dir, resume=True)
    print("[4/5] evaluation (open loop over whole trajectories)", flush=True)
    results = {}
    for name, run_dir in (("calibrated (gradient fit)", fit_dir), ("residual by PPO", ppo_dir)):
        print(f"      {name}:", flush=True)
        results[name] = evaluate_run(str(run_dir), data, robot, data_label=str(data_path))
    exported = export_usd(fit_dir, force=True, data=str(data_path))
    print(f"      the calibrated robot for Newton: {exported}/actuated.usda (`wresdyn export`)", flush=True)
    print("[5/5] skills deployed zero-shot on the real robot (`wresdyn deploy`, small)", flush=True)
    deploy = run_benchmark(robot, data, out / "deploy", dcfg, data_path=data_path, calibrated=fit_dir,
                           ppo=skill_ppo, policies=("a_nominal", "b_calibrated", "d_oracle"), log=log)
    rows = ["| learner | training [s] | held-out mean abs dq [rad] | x | OOD mean abs dq [rad] | x |", "|---|---|---|---|---|---|"]
    walls = {"calibrated (gradient fit)": (curve[-1]["wall"] if curve else 0.0) + id_wall,
             "residual by PPO": summary["wall_s_this_session"]}
    for name, res in results.items():
        h, o = res.get("heldout"), res.get("ood")
        cells = [f"{r['pd_residual']['mean_abs_dq']:.4f} | {r['improvement']:.2f}x" if r else "- | -" for r in (h, o)]
        rows.append(f"| {name} | {walls[name]:.0f} | {cells[0]} | {cells[1]} |")
    pd = next(iter(results.values())).get("heldout", {}).get("pd_only", {}).get("mean_abs_dq", float("nan"))
    real = deploy["real"]["heldout"]
    skill = ["| skill policy, deployed on the real robot | MPJPE [mrad] | foot error [mm] | success |", "|---|---|---|---|"]
    skill += [f"| {n} | {1e3 * r['mean']['mpjpe']:.2f} | {1e3 * r['mean']['foot_error']:.2f} | "
              f"{100 * r['mean']['success']:.0f} % |" for n, r in real.items()]
    gap = deploy["gap_closed"].get("b_calibrated", float("nan"))
    report = ["# wresdyn demo", "", "## Fidelity: open-loop replay", "", f"PD-only held-out mean |Δq|: {pd:.4f} rad.", "",
              *rows, "", "## Zero-shot skills on the real robot (held-out motions)", "", *skill, "",
              f"Gap closed by the calibrated robot, (a − b) / (a − d): {100 * gap:.0f} %.", "",
              "Plots: `fit/eval/fig3_heldout.png`, `ppo/eval/fig3_heldout.png`, `deploy/tracking_heldout.png`; "
              "the calibrated robot: `fit/export/`; the skills' report: `deploy/report.md`. "
              f"Total {time.perf_counter() - t0:.0f} s."]
    (out / "report.md").write_text("\n".join(report) + "\n")
    (out / "results.json").write_text(json.dumps({"fidelity": results, "skills": deploy["real"],
                                                  "gap_closed": deploy["gap_closed"]}, indent=1))
    print("\n".join(report))
    return report
