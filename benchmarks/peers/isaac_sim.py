"""Isaac Sim 6.2's System Identification backend (``isaacsim.robot_setup.sysid`` 3.2.0) on the project's humanoid,
outside Kit: its standalone differentiable Newton path, its own recipe, scored like the other peers.

The backend ships in the ``isaacsim-robot-setup`` wheel (NVIDIA's licence: an optional peer of this benchmark, never
a dependency; install it only into a throwaway folder). Outside Kit three things stand in for what Kit provides:

- its package lives inside a Kit extension folder (``isaacsim/exts/isaacsim.robot_setup.sysid``): that folder and
  its ``pip_prebundle`` go on ``sys.path`` by hand;
- 14 of its modules import ``carb`` (Carbonite) at module level, for logging: ``--kit`` takes it from the
  ``isaacsim-kernel`` wheel's ``isaacsim/kit`` (``kernel/py`` and ``libcarb.so``), whose logging works without a
  running Kit (``carb.settings`` does not; the Newton path does not use it); ``--carb-stub`` writes a logging-only
  stand-in instead, for interpreters the cp312 ``_carb`` cannot load;
- Kit registers Newton's USD schemas at start-up; here ``newton_usd_schemas`` does, before the first stage opens
  (the writeback applies ``NewtonJointAPI``).

Four steps; the peer's interpreter (Python 3.12, the peer's Newton) never imports wresdyn:

    # wresdyn's interpreter: the robot as a USD layer on a stand, the recordings as the peer's CSV, the job
    python benchmarks/peers/isaac_sim.py prepare data/dataset.npz --out OUT --recipe drive_calibration_inair
    # the peer's interpreter: torch, newton, warp, mujoco-warp, usd-core, newton-usd-schemas, pyyaml, the wheels
    python3.12 benchmarks/peers/isaac_sim.py solve OUT --isaac ISAAC_SITE --kit KERNEL/isaacsim/kit
    # wresdyn's interpreter: the peer's USD writeback read by Newton's importer, open-loop |Δq| on every split
    python benchmarks/peers/isaac_sim.py score data/dataset.npz OUT
    # any interpreter: what imports outside Kit and what does not (benchmarks/results/peers/isaac_sim/probe.txt)
    python benchmarks/peers/isaac_sim.py probe --python python3.12 --isaac ISAAC_SITE --kit KERNEL/isaacsim/kit

Choices (each says why):

- **Robot.** ``OUT/robot.usda``, a layer over a copy of the shipped ``scenes/humanoid.usda`` (untouched) that puts
  the robot on a stand in the peer's terms: a fixed joint from the world to the pelvis (the peer loads the USD with
  ``ModelBuilder.add_usd`` as authored; the recordings hang the robot on a stand); the articulation root moved from
  the pelvis body to the robot's Xform (the peer collects joints only below the root's prim, and the shipped file's
  links are the pelvis's siblings: it found 3 of 21 joints); ``physxScene:timeStepsPerSecond`` at the recording
  rate (the peer resamples the telemetry to the scene's step and assumes 60 Hz when none is authored). The peer's
  writeback authors into this layer; ``solve`` exports it as ``OUT/identified.usda``.
- **Telemetry.** One CSV in the peer's compact layout (``time, q1..qN, dq1..dqN, cmd1..cmdN``, joints in the
  robot's order), the training and validation trajectories one after another with a gap, and one explicit chunk per
  trajectory (``train`` / ``validation``): each chunk rolls from its own first recorded state, the peer's multiple
  shooting. The recipe's ``chunking: auto`` would cut the training data 80/20 by time instead; the project's
  validation split is every tool's selection set.
- **Recipe.** The peer's built-in recipe by name, applied with its own ``synthesize_run_spec_from_quickstart``
  (parameters and bounds: its registry defaults, as its quick start does). Only paths, chunks and the device are
  set here, the parameter-confidence report after the solve is off (extra rollouts, not part of the fit), and
  ``--featherstone-substeps`` where the recipe's 4 diverge: the peer's own stability message names
  the count (on the humanoid at 500 Hz: 39; the recipe's second restart row starts uniformly inside the registry
  bounds, drive damping up to 100x the file's, 160 N·m·s/rad on the worst joint).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
EXT = "isaacsim/exts/isaacsim.robot_setup.sysid"
"""The sysid extension's folder inside the unpacked ``isaacsim-robot-setup`` wheel."""
STAND = "stand_joint"
"""Name of the fixed joint the layer adds under the robot's root prim."""
GAP_S = 1.0
"""Time gap between trajectories in the telemetry CSV [s]: chunk bounds never share a sample."""


CARB_STUB = '''"""Logging-only stand-in for Carbonite's Python module, for interpreters the cp312 _carb cannot load."""
import logging

_log = logging.getLogger("carb")
log_error, log_warn, log_info, log_verbose = _log.error, _log.warning, _log.info, _log.debug
'''


def write_carb_stub(folder: str) -> None:
    """``folder/carb/__init__.py``: :data:`CARB_STUB` (the peer's Newton path calls only ``carb.log_*``)."""
    path = Path(folder) / "carb" / "__init__.py"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(CARB_STUB)


def peer_paths(isaac: str, kit: str | None, carb_stub: str | None) -> None:
    """Put the peer's package (inside its Kit extension folder) and Carbonite's Python bindings on ``sys.path``."""
    ext = Path(isaac) / EXT
    if carb_stub:
        write_carb_stub(carb_stub)
    first = [str(carb_stub)] if carb_stub else []
    if kit and not carb_stub:
        import ctypes

        # _carb links libcarb.so by name; loading it first stands in for LD_LIBRARY_PATH, read only at start-up.
        ctypes.CDLL(str(Path(kit) / "libcarb.so"), mode=ctypes.RTLD_GLOBAL)
        first.append(str(Path(kit) / "kernel/py"))
    sys.path[:0] = first + [str(ext), str(ext / "pip_prebundle")]


# --- prepare (wresdyn's interpreter) -----------------------------------------------------------------------------
def write_stage(robot_file: Path, root: str, pelvis: str, rate_hz: float, out: Path) -> Path:
    """``out/robot.usda``: a layer over a copy of ``robot_file`` (so ``out`` travels whole) that puts the robot on
    a stand in the terms the peer reads (see the module's docstring)."""
    import shutil

    from pxr import Sdf, Usd, UsdPhysics

    shutil.copyfile(robot_file, out / robot_file.name)
    path = out / "robot.usda"
    stage = Usd.Stage.CreateNew(str(path))
    stage.GetRootLayer().subLayerPaths.append(robot_file.name)
    src = Usd.Stage.Open(str(robot_file))
    stage.SetDefaultPrim(stage.GetPrimAtPath(root))
    for key in ("upAxis", "metersPerUnit", "kilogramsPerUnit"):
        stage.SetMetadata(key, src.GetMetadata(key))
    joint = UsdPhysics.FixedJoint.Define(stage, Sdf.Path(root).AppendChild(STAND))
    joint.CreateBody1Rel().SetTargets([Sdf.Path(pelvis)])
    # The peer collects joints below the articulation root's prim; the shipped file roots the articulation at the
    # pelvis body with the other links as its siblings, so the root moves up to the robot's Xform.
    UsdPhysics.ArticulationRootAPI.Apply(stage.GetPrimAtPath(root))
    stage.OverridePrim(pelvis).RemoveAPI(UsdPhysics.ArticulationRootAPI)
    # The peer resamples the telemetry to the scene's step and assumes 60 Hz when none is authored.
    for prim in src.Traverse():
        if prim.IsA(UsdPhysics.Scene):
            stage.OverridePrim(prim.GetPath()).CreateAttribute(
                "physxScene:timeStepsPerSecond", Sdf.ValueTypeNames.UInt).Set(int(round(rate_hz)))
    stage.GetRootLayer().Save()
    return path


def write_telemetry(splits: dict, out: Path) -> tuple[Path, list[dict]]:
    """The trajectories of ``splits`` (role -> list of trajectories) as one CSV and the peer's chunk list."""
    rows, chunks, t0 = [], [], 0.0
    for role, trajectories in splits.items():
        for i, tr in enumerate(trajectories):
            t = t0 + (tr.t - tr.t[0])
            rows.append(np.column_stack([t, tr.q, tr.qd, tr.q_cmd]))
            chunks.append({"name": f"{role}_{i}", "role": role, "excitation": "custom", "start": float(t[0]),
                           "end": float(t[-1]), "weight": 1.0})
            t0 = float(t[-1]) + GAP_S
    n = splits[next(iter(splits))][0].q.shape[1]
    header = ",".join(["time"] + [f"{c}{j}" for c in ("q", "dq", "cmd") for j in range(1, n + 1)])
    path = out / "telemetry.csv"
    np.savetxt(path, np.concatenate(rows), delimiter=",", header=header, comments="", fmt="%.9g")
    return path, chunks


def prepare(args) -> None:
    from wresdyn.data.loading import load_data

    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    ds, robot = load_data(args.data, None, None)
    robot_file = (REPO / ds.robot_file).resolve()
    stage = write_stage(robot_file, "/humanoid", "/humanoid/pelvis", ds.rate_hz, out)
    n = args.trajectories or None  # smoke runs: the first few of each split
    csv, chunks = write_telemetry({"train": ds.split("train")[:n], "validation": ds.split("validation")[:n]}, out)
    job = {"stage": stage.name, "telemetry": csv.name, "chunks": chunks, "robot_prim_path": "/humanoid",
           "recipe": args.recipe, "device": args.device, "joint_names": list(robot.joint_names),
           "n_links": int(robot.n_bodies), "rate_hz": float(ds.rate_hz), "data": args.data}
    (out / "job.json").write_text(json.dumps(job, indent=1))
    print(f"wrote {stage}, {csv} ({len(chunks)} chunks), {out / 'job.json'}")


# --- solve (the peer's interpreter) ------------------------------------------------------------------------------
def solve(args) -> None:
    peer_paths(args.isaac, args.kit, args.carb_stub)
    # Kit registers Newton's USD schemas at start-up; outside Kit the package does it on import, and it must come
    # before the first stage is opened (USD builds its schema registry then): the writeback applies NewtonJointAPI.
    import newton_usd_schemas  # noqa: F401
    from isaacsim.robot_setup.sysid.execution import run_sysid
    from isaacsim.robot_setup.sysid.preset_loader import load_builtin_parameter_preset
    from isaacsim.robot_setup.sysid.recipes import synthesize_run_spec_from_quickstart
    from isaacsim.robot_setup.sysid.trajectory_segments import TelemetryChunkRunSpec

    out = Path(args.out).resolve()
    job = json.loads((out / "job.json").read_text())
    recipe = load_builtin_parameter_preset(args.recipe or job["recipe"])
    spec, notes = synthesize_run_spec_from_quickstart(
        robot_prim_path=job["robot_prim_path"], telemetry_path=str(out / job["telemetry"]), recipe=recipe,
        stage_path=str(out / job["stage"]), num_joints=len(job["joint_names"]), num_links=job["n_links"])
    spec.telemetry.auto_split = False
    spec.telemetry.chunks = [TelemetryChunkRunSpec.from_dict(c) for c in job["chunks"]]
    spec.simulation.newton.device = args.device or job["device"]
    if args.max_iterations:
        spec.solver.max_iterations = args.max_iterations
    if args.max_rollout_steps:
        spec.solver.max_rollout_steps = args.max_rollout_steps
    if args.featherstone_substeps:
        spec.simulation.newton.featherstone_substeps = args.featherstone_substeps
    spec.outputs.compute_parameter_confidence = False  # extra rollouts after the solve, not part of the fit
    spec.outputs.export_provenance_sidecar = False
    for note in notes:
        print(f"# recipe note: {note}", flush=True)
    (out / "run_spec.json").write_text(json.dumps(spec.to_dict(), indent=1, default=str))
    log = (out / "iterations.jsonl").open("w")
    t0 = time.perf_counter()

    def on_iteration(status) -> None:
        row = {"wall_s": time.perf_counter() - t0, **_plain(status)}
        log.write(json.dumps(row, default=str) + "\n")
        log.flush()
        print(f"# it {row.get('iteration')}: cost {row.get('cost')} ({row['wall_s']:.1f}s)", flush=True)

    async def run():
        # run_sysid's own Newton path, unrolled to keep the stage: its writeback authors the accepted values into
        # the stage's root layer but leaves saving to the caller.
        from pxr import Usd

        from isaacsim.robot_setup.sysid.run_controller import SysIdRunController

        stage = Usd.Stage.Open(spec.stage.input_path)
        controller = SysIdRunController(spec)
        prepared = controller.prepare(stage, trajectory=controller.load_trajectory(), timeline_playing=None)
        result = await run_sysid(spec, prepared_run=prepared, on_iteration=on_iteration,
                                 on_progress=lambda msg, frac: print(f"# {frac:.2f} {msg}", flush=True))
        stage.GetRootLayer().Export(str(out / "identified.usda"))
        return result

    result = asyncio.run(run())
    wall = time.perf_counter() - t0
    summary = {"wall_s": wall, "recipe": args.recipe or job["recipe"], "device": spec.simulation.newton.device,
               "featherstone_substeps": spec.simulation.newton.featherstone_substeps,
               "max_iterations": spec.solver.max_iterations, "max_rollout_steps": spec.solver.max_rollout_steps,
               "result": _plain(result), "versions": versions(args.isaac),
               "carb": "stand-in" if args.carb_stub else args.kit}
    (out / "solve.json").write_text(json.dumps(summary, indent=1, default=str))
    print(f"# solve done in {wall:.1f}s: {out / 'solve.json'}")


def _plain(v):
    """JSON-able copy of the peer's status and result objects, without their rollouts (whole trajectories)."""
    if hasattr(v, "__dataclass_fields__"):
        v = {k: getattr(v, k) for k in v.__dataclass_fields__}
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items() if "rollout" not in str(k)}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if hasattr(v, "tolist"):
        return v.tolist()
    return v if isinstance(v, (str, int, float, bool, type(None))) else str(v)


def versions(isaac: str) -> dict:
    import glob
    import tomllib
    from importlib import metadata

    found = {"python": sys.version.split()[0]}
    for info in glob.glob(str(Path(isaac) / "isaacsim_robot_setup-*.dist-info")):
        found["isaacsim-robot-setup wheel"] = Path(info).name.removesuffix(".dist-info").split("-")[1]
    toml = Path(isaac) / EXT / "config/extension.toml"
    if toml.exists():
        found["isaacsim.robot_setup.sysid extension"] = tomllib.loads(toml.read_text())["package"]["version"]
    for name in ("newton", "warp-lang", "mujoco", "mujoco-warp", "torch",
                 "usd-core", "numpy"):
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    return found


# --- score (wresdyn's interpreter) --------------------------------------------------------------------------------
def write_score_stage(out: Path, layer: str) -> Path:
    """``out/score_<layer>``: ``layer`` with the stand joint deactivated, so wresdyn's loader (which puts the robot on
    its own stand) reads the peer's written values on the shipped file's topology."""
    from pxr import Usd

    path = out / f"score_{layer}"
    stage = Usd.Stage.CreateNew(str(path))
    stage.GetRootLayer().subLayerPaths.append(layer)
    src = Usd.Stage.Open(str(out / layer))
    stage.SetDefaultPrim(stage.GetPrimAtPath(src.GetDefaultPrim().GetPath()))
    for key in ("upAxis", "metersPerUnit", "kilogramsPerUnit"):
        stage.SetMetadata(key, src.GetMetadata(key))
    stage.OverridePrim(src.GetDefaultPrim().GetPath().AppendChild(STAND)).SetActive(False)
    stage.GetRootLayer().Save()
    return path


def score(args) -> None:
    """Open-loop mean |Δq| of the peer's written-back robot on every split, in wresdyn's simulator, next to the
    robot file's own values (the peer's starting point), and its parameters against the truth."""
    from peer_adapter import SPLITS, param_errors  # this folder: the script's own, first on sys.path

    from wresdyn.data.loading import load_data
    from wresdyn.data.real_robot import Mismatch, RealRobot
    from wresdyn.evaluation.open_loop import evaluate_splits
    from wresdyn.robot.description import load_robot
    from wresdyn.robot.physical import PhysicalParams

    out = Path(args.out).resolve()
    ds, robot = load_data(args.data, None, None)
    truth = RealRobot(robot, Mismatch.from_dict(ds.mismatch), ds.rate_hz).physics()
    models = {"robot file": PhysicalParams.nominal(robot)}
    for layer in ("robot.usda", "identified.usda"):
        if (out / layer).exists():
            peer_robot = load_robot(write_score_stage(out, layer))
            if list(peer_robot.joint_names) != list(robot.joint_names):
                raise SystemExit(f"{layer}: joints {peer_robot.joint_names} != {robot.joint_names}")
            models[f"isaac {layer}"] = PhysicalParams.nominal(peer_robot)
    rows = {}
    print("| model | validation | held-out | OOD | (joint, field) within 10 % of the truth |")
    print("|---|---|---|---|---|")
    for name, physics in models.items():
        res = evaluate_splits(robot, {s: ds.split(s) for s in SPLITS}, ds.rate_hz, physics=physics,
                              weights=ds.fit_weights())
        rows[name] = {"mean_abs_dq": {s: res[s][0]["pd_residual"]["mean_abs_dq"] for s in SPLITS},
                      "param_errors": param_errors(physics, truth, ds.split("train"))}
        print(f"| {name} | " + " | ".join(f"{rows[name]['mean_abs_dq'][s]:.4f}" for s in SPLITS)
              + f" | {rows[name]['param_errors']['within_10pct']} / {rows[name]['param_errors']['identifiable']} |",
              flush=True)
    solve = json.loads((out / "solve.json").read_text()) if (out / "solve.json").exists() else {}
    (out / "score.json").write_text(json.dumps({"data": args.data, "models": rows, "solve": {
        k: solve.get(k) for k in ("wall_s", "recipe", "device", "featherstone_substeps", "max_iterations",
                                  "versions")}}, indent=1))


# --- probe (any interpreter) ------------------------------------------------------------------------------------
PROBE_MODULES = (
    "isaacsim.robot_setup.sysid",                            # package root: documented to import nothing heavy
    "isaacsim.robot_setup.sysid.execution",                  # run_sysid
    "isaacsim.robot_setup.sysid.run_spec",
    "isaacsim.robot_setup.sysid.recipes",
    "isaacsim.robot_setup.sysid.ingest",
    "isaacsim.robot_setup.sysid.check_report",
    "isaacsim.robot_setup.sysid.run_controller",
    "isaacsim.robot_setup.sysid.optimizers.cma_es",
    "isaacsim.robot_setup.sysid.optimizers.gradient_descent",
    "isaacsim.robot_setup.sysid.newton_sysid_bridge",        # standalone Newton MuJoCo
    "isaacsim.robot_setup.sysid.newton_diff_sysid_bridge",   # differentiable Newton Featherstone
    "isaacsim.robot_setup.sysid.isaac_sim_sysid_bridge",     # Kit-hosted PhysX / Newton
)
KIT_ROOTS = ("carb", "omni", "isaacsim.core", "usdrt")
"""Modules only a Kit installation provides."""


def module_level_kit_imports(isaac: str) -> dict[str, list[str]]:
    """Per module of the peer's package, the Kit-only modules it imports at module level (import time)."""
    import ast

    pkg = Path(isaac) / EXT / "isaacsim/robot_setup/sysid"
    found = {}
    for path in sorted(pkg.rglob("*.py")):
        if "tests" in path.relative_to(pkg).parts:
            continue
        names = []
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            mods = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module else [])
            names += [m for m in mods if any(m == r or m.startswith(r + ".") for r in KIT_ROOTS)]
        if names:
            found[str(path.relative_to(pkg))] = sorted(set(names))
    return found


def probe(args) -> None:
    """Import each of :data:`PROBE_MODULES` in a fresh ``args.python``, with and without Carbonite, and print what
    fails (the last line of each traceback)."""
    import glob

    meta = glob.glob(str(Path(args.isaac) / "isaacsim_robot_setup-*.dist-info/METADATA"))
    print(f"$ {' '.join(sys.argv)}")
    if meta:
        head = [ln for ln in Path(meta[0]).read_text().splitlines()
                if ln.split(":")[0] in ("Name", "Version", "License", "Requires-Python", "Requires-Dist")]
        print("## wheel METADATA\n" + "\n".join(head))
    ext = Path(args.isaac) / EXT
    print(f"## extension.toml [dependencies] (Kit extensions)\n"
          + "\n".join(ln for ln in (ext / "config/extension.toml").read_text().split("[dependencies]")[1]
                      .split("[[")[0].strip().splitlines()))
    print("## module-level imports of Kit-only modules (import time), per module")
    for mod, names in module_level_kit_imports(args.isaac).items():
        print(f"{mod}: {', '.join(names)}")
    version = subprocess.run([args.python, "-c", "import sys; print(sys.version.split()[0])"], capture_output=True,
                             text=True).stdout.strip()
    setups = {"the wheel as installed (site folder only)": [str(args.isaac)],
              "+ the extension folder and its pip_prebundle on sys.path": [str(ext), str(ext / "pip_prebundle")]}
    if args.kit:
        setups["+ carb from isaacsim-kernel (kit/kernel/py, libcarb.so on LD_LIBRARY_PATH)"] = [
            str(Path(args.kit) / "kernel/py"), str(ext), str(ext / "pip_prebundle")]
    if args.carb_stub:
        write_carb_stub(args.carb_stub)
        setups["+ a logging-only carb stand-in"] = [str(args.carb_stub), str(ext), str(ext / "pip_prebundle")]
    for label, path in setups.items():
        print(f"## {args.python} (Python {version}): {label}")
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(path + [os.environ.get("PYTHONPATH", "")]))
        if args.kit:
            env["LD_LIBRARY_PATH"] = os.pathsep.join([str(args.kit), os.environ.get("LD_LIBRARY_PATH", "")])
        for mod in PROBE_MODULES:
            r = subprocess.run([args.python, "-c", f"import {mod}"], capture_output=True, text=True, env=env)
            last = (r.stderr.strip().splitlines() or ["?"])[-1]
            print(f"import {mod}: {'ok' if r.returncode == 0 else last}")
        if "carb" in label:
            code = ("import carb; carb.log_warn('carb logging outside Kit'); import carb.settings; "
                    "carb.settings.get_settings()")
            r = subprocess.run([args.python, "-c", code], capture_output=True, text=True, env=env)
            out = (r.stdout + r.stderr).strip().splitlines()
            print(f"carb.log_warn then carb.settings.get_settings(): {out[0] if out else ''} | "
                  f"{'ok' if r.returncode == 0 else out[-1]}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("prepare", help="robot layer, telemetry CSV and job (wresdyn's interpreter)")
    a.add_argument("data")
    a.add_argument("--out", required=True)
    a.add_argument("--recipe", default="drive_calibration_inair", help="the peer's built-in recipe")
    a.add_argument("--device", default="cuda:0", help="the peer's Newton device")
    a.add_argument("--trajectories", type=int, default=0, help="first N trajectories of each split (smoke runs)")
    a.set_defaults(fn=prepare)
    s = sub.add_parser("solve", help="the peer's solve (its interpreter)")
    s.add_argument("out")
    s.add_argument("--isaac", required=True, help="folder the isaacsim-robot-setup wheel was installed into")
    s.add_argument("--kit", default=None, help="the isaacsim-kernel wheel's isaacsim/kit folder (for carb)")
    s.add_argument("--carb-stub", default=None, help="folder to write a logging-only carb stand-in into, used first")
    s.add_argument("--recipe", default=None, help="override the prepared recipe")
    s.add_argument("--device", default=None, help="override the prepared device")
    s.add_argument("--max-iterations", type=int, default=None, help="override the recipe's (smoke runs only)")
    s.add_argument("--max-rollout-steps", type=int, default=None, help="override the recipe's (smoke runs only)")
    s.add_argument("--featherstone-substeps", type=int, default=None,
                   help="override the recipe's (its stability message names the count a robot needs)")
    s.set_defaults(fn=solve)
    c = sub.add_parser("score", help="open-loop |Δq| of the peer's writeback (wresdyn's interpreter)")
    c.add_argument("data")
    c.add_argument("out")
    c.set_defaults(fn=score)
    r = sub.add_parser("probe", help="what imports outside Kit, with which interpreter")
    r.add_argument("--python", default=sys.executable, help="interpreter to probe")
    r.add_argument("--isaac", required=True, help="folder the isaacsim-robot-setup wheel was installed into")
    r.add_argument("--kit", default=None, help="the isaacsim-kernel wheel's isaacsim/kit folder (for carb)")
    r.add_argument("--carb-stub", default=None, help="folder to write a logging-only carb stand-in into")
    r.set_defaults(fn=probe)
    args = p.parse_args()
    args.fn(args)


if __name__ == "__main__":
    main()
