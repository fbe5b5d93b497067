"""Fair fight 1: ``mujoco.sysid`` against ``wresdyn identify`` on the shipped humanoid, each on its own recipe.

Three legs, each its own call, so a remote machine lent in 10-minute calls can run them one after the other:

    python benchmarks/peers/humanoid.py peer data/dataset.npz --out OUT --threads 16 --max-seconds 540 --resume
    python benchmarks/peers/humanoid.py wresdyn data/dataset.npz --out OUT --device cpu      # or cuda:0
    python benchmarks/peers/humanoid.py report --out OUT

``peer``: ``mujoco.sysid`` (its ``"mujoco"`` backend: projected Gauss-Newton, finite-difference Jacobians over
``mujoco.rollout`` on ``--threads`` threads) through :mod:`peer_adapter`, with

- windows of ``--horizon`` samples tiling every training trajectory end to end (the peer's
  ``SystemTrajectory.split`` layout, every training sample in exactly one window; 0.5 s by default: several PD time
  constants, so delay, damping and inertia show in each window, while the open-loop drift of a window from its
  recorded start stays small, which keeps the Gauss-Newton model of the residual good);
- the model at the "real" robot's own step (the dataset's ``mismatch.substep``, 1 ms; commands held for their
  sample as the real robot holds them);
- fitted in stages as the peer's documentation suggests (declare every parameter once, toggle ``frozen``): stage 1
  the per-joint parameters (kp, kd, armature, damping, friction loss, effort limit, delay), stage 2 the links'
  10-D pseudo-inertias from stage 1's result, joints frozen there;
- the same start as wresdyn: the robot file's values. ``wresdyn identify``'s defaults run no grid search before
  its gradient steps (its ``gain_grid`` and ``delay_grid`` are empty; its ``effort_grid`` runs mid-way, from its own
  iterate, when the effort limit joins its fit: part of its method and of its wall-clock), so neither tool gets a
  searched start;
- run to the optimiser's own termination (its default ``xtol``, ``gtol``, regulariser ceiling; ``max_iters`` set
  out of reach); ``x_scale="jac"``, the scaling its conditioning warning advises. The backend is called as
  ``sysid.optimize(optimizer="mujoco")`` calls it (``mujoco.minimize.least_squares`` on the stacked residual of
  ``build_residual_fn``, the parameters' bounds), at iteration verbosity instead of the full one ``optimize`` forces:
  the same iterates, without the Jacobian ``optimize`` computes once more at the end for confidence intervals (a
  whole iteration's rollouts at each stage's end, which a 10-minute call may not hold) and without every
  iteration's Jacobian kept in memory.

It checkpoints after every Gauss-Newton iteration (``OUT/peer/checkpoint.json``: stage, iteration, the accepted
parameter vector, the peer's seconds so far, the curve) and ``--resume`` continues from there; ``--max-seconds``
ends a call cleanly after the iteration that passes it. A resumed stage restarts the optimiser from the checkpoint's
vector with its regulariser reset (the backend takes no regulariser in), so a resumed run is the same iterates only
while the regulariser of the interrupted run was 0; the iteration count and the curve continue.

``wresdyn``: :func:`wresdyn.identify.sysid.identify` with its defaults (it stops when validation plateaus) on
``--device``, kernels compiled first (counted in its wall-clock), resumable through its own run folder;
``--recipe NAME`` fits a recipe of :data:`recipe_search.RECIPES` instead (chosen there on validation only).

Scoring, the same for both: each candidate is replayed open loop over every whole validation trajectory from its
first recorded state (:func:`wresdyn.evaluation.open_loop.metrics`, mean |Δq| over the fitted joints), each model in
its own simulator; the peer validates every accepted Gauss-Newton iterate, wresdyn every ``select_every`` iterations;
validation time is excluded from both clocks. The curve is the best validation error so far against the tool's
wall-clock; each tool's final model is its best on validation; held-out and OOD are scored on it once.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import hashlib
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parents[1]), str(HERE)]  # this checkout, this folder (peer_adapter, host)
import host  # noqa: E402
import peer_adapter as peer  # noqa: E402
from peer_adapter import SPLITS, param_errors  # noqa: E402
from recipe_search import RECIPES, recipe_config  # noqa: E402

STAGES = (peer.JOINT_FIELDS, ("bodies",))
"""The fields each stage fits: the joints' own, then the links' inertias."""
MAX_ITERS = 1_000_000
"""Out of reach: the optimiser's own criteria end each stage."""
CONVERGED = ("norm(dx) < tol.", "norm(gradient) < tol.", "insufficient reduction.")
"""The backend's stop messages that mean it found no further descent (its others: the iteration ceiling, a failed
factorisation)."""
SUMMARY_KEYS = ("heldout_error", "ood_error", "seconds_to_final", "converged", "samples_used", "machine")


class ConfigChanged(SystemExit):
    """A resumed call with other settings than the checkpoint's."""


class _Budget(Exception):
    """``--max-seconds`` ran out (raised from the optimiser's iteration callback, after the checkpoint)."""


def machine(threads: int | None, device: str = "cpu") -> str:
    """CPU model, cores visible / used, and the GPU when ``device`` is CUDA."""
    cpu = host.cpu_model()
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    out = f"{cpu}, {cores} cores visible" + (f", {threads} threads used" if threads else "")
    if device.startswith("cuda"):
        import torch

        out += f", GPU {torch.cuda.get_device_name(torch.device(device))}"
    return out


def load(data: str):
    """``(dataset, robot, truth)``: the recording, the nominal robot and the real robot's true parameters."""
    from wresdyn.data.loading import load_data
    from wresdyn.data.real_robot import Mismatch, RealRobot

    ds, robot = load_data(data, None, None)
    truth = RealRobot(robot, Mismatch.from_dict(ds.mismatch), ds.rate_hz).physics()
    return ds, robot, truth


def real_step(ds) -> float:
    """The real robot's physics step [s] (the mismatch's ``substep``; the sample period when it has none)."""
    return float(ds.mismatch.get("substep") or 0.0) or 1.0 / ds.rate_hz


def file_digest(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def data_digest(path: str) -> str:
    """sha256 (16 hex digits) of what a fit reads from a dataset: every recorded array and the header without its
    ``meta``. ``meta`` is the recorder's provenance (the excitation's drawn design parameters among it), whose last
    digits differ between machines that record bit-identical samples, so the file's own digest does too."""
    h = hashlib.sha256()
    with np.load(path, allow_pickle=False) as z:
        header = json.loads(z["header"].tobytes().decode())
        header.pop("meta", None)
        h.update(json.dumps(header, sort_keys=True).encode())
        for key in sorted(k for k in z.files if k != "header"):
            a = np.ascontiguousarray(z[key])
            h.update(f"{key} {a.dtype.str} {a.shape}".encode())
            h.update(a.tobytes())
    return h.hexdigest()[:16]


DATA_KEYS = ("data", "data_sha256", "data_content_sha256")
"""The checkpoint's data: its path on the machine that wrote it, the file's digest, :func:`data_digest`."""


def same_data(saved: dict, config: dict) -> bool:
    """The data a checkpoint was fitted on: the same file, or the same samples and declarations (a checkpoint written
    before ``data_content_sha256`` existed matches on the file only)."""
    content = saved.get("data_content_sha256")
    return saved["data_sha256"] == config["data_sha256"] or (content is not None and
                                                              content == config["data_content_sha256"])


def open_log(path: Path):
    path.parent.mkdir(parents=True, exist_ok=True)
    f = path.open("a")

    def log(line: str) -> None:
        print(line, flush=True)
        f.write(line + "\n")
        f.flush()

    return log


def write_json(path: Path, obj) -> None:
    """Atomic: a call killed mid-write leaves the previous file."""
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(obj, indent=1))
    tmp.replace(path)


# --- scoring -------------------------------------------------------------------------------------------------------

def best_so_far(points):
    out, best = [], np.inf
    for t, v in points:
        best = min(best, v)
        out.append((float(t), float(best)))
    return out


def time_to(curve, level: float):
    """First time the curve's best validation error is ≤ ``level`` [s], or ``None``."""
    return next((t for t, v in curve if v <= level + 5e-5), None)  # levels are printed to 4 decimals


def peer_scores(model, ds, threads: int, splits=SPLITS) -> dict:
    """Mean |Δq| [rad] of the peer's ``model`` replayed over each whole trajectory of ``splits``."""
    from wresdyn.evaluation.open_loop import metrics

    return {s: metrics(ds.split(s), peer.replay(model, ds.split(s), threads, ds.rate_hz), ds.fit_weights()).mean_abs_dq
            for s in splits}


def truth_in_peer(robot, ds, truth, threads: int = 2) -> dict:
    """Errors of the real robot's true parameters in the peer's model at the real step: the floor of the peer."""
    return peer_scores(peer.with_params(peer.peer_spec(robot, ds.rate_hz, real_step(ds)), truth), ds, threads)


# --- the peer leg --------------------------------------------------------------------------------------------------

class Problem:
    """The peer's problem on one dataset: its spec, every parameter of ``stages`` (field groups, see :data:`STAGES`)
    declared once, stage switching by ``frozen``."""

    def __init__(self, robot, ds, dt: float, stages=STAGES):
        self.robot, self.ds, self.dt = robot, ds, dt
        self.spec = peer.peer_spec(robot, ds.rate_hz, dt)
        self.params = peer.peer_parameters(self.spec, robot, tuple(f for st in stages for f in st))
        field = {f"{j}_{f}": f for j in robot.joint_names for f in peer.JOINT_FIELDS}
        self.stage_of = {k: next(i for i, st in enumerate(stages) if field.get(k, "bodies") in st)
                         for k in self.params.keys()}

    def enter(self, stage: int, x_joints=None) -> np.ndarray:
        """Unfreeze ``stage``'s parameters and return their vector. Entering the second stage writes the first's
        result ``x_joints`` into the spec, where it stays while frozen (a frozen parameter's modifier is not
        called)."""
        if stage == 1:
            self._freeze(0)
            self.params.update_from_vector(np.asarray(x_joints, dtype=np.float64))
            for k in self.params.keys():
                if self.stage_of[k] == 0:
                    self.params[k].apply_modifier(self.spec)
        self._freeze(stage)
        return self.params.as_vector().copy()

    def _freeze(self, stage: int) -> None:
        for k in self.params.keys():
            self.params[k].frozen = self.stage_of[k] != stage

    def model(self, x):
        """The compiled model at the current stage's vector ``x``."""
        from mujoco import sysid

        self.params.update_from_vector(np.asarray(x, dtype=np.float64).ravel())
        return sysid.apply_param_modifiers(self.params, self.spec)


def peer_model(robot, ds, dt: float, stages, stage: int, x, x_joints=None):
    """The peer's compiled model at ``x`` of ``stage`` (the second: on top of ``x_joints``), from a fresh problem."""
    prob = Problem(robot, ds, dt, stages)
    prob.enter(stage, x_joints)
    return prob.model(x)


class Clock:
    """The peer's seconds: those of earlier calls plus this call's, less the paused spans (validation, checkpoints)."""

    def __init__(self, before: float, start: float | None = None):
        self.before, self.paused_s = before, 0.0
        self.start = time.perf_counter() if start is None else start

    def now(self) -> float:
        return self.before + time.perf_counter() - self.start - self.paused_s

    @contextlib.contextmanager
    def paused(self):
        t = time.perf_counter()
        try:
            yield
        finally:
            self.paused_s += time.perf_counter() - t


class _Output:
    """The backend's printed lines (it prints through ``output=``) into the log; keeps its stop message."""

    def __init__(self, log):
        self.log, self.buf, self.stop = log, "", None

    def write(self, text: str) -> None:
        self.buf += text
        while "\n" in self.buf:
            line, self.buf = self.buf.split("\n", 1)
            if line.startswith("Terminated after"):
                self.stop = line.split(": ", 1)[1].split(" y:", 1)[0].strip()
            if line.strip():
                self.log(f"  mujoco.minimize: {line}")

    def flush(self) -> None:
        pass


def peer_config(args, ds) -> dict:
    import mujoco

    return {"data": args.data, "data_sha256": file_digest(args.data), "data_content_sha256": data_digest(args.data),
            "horizon": args.horizon, "dt": real_step(ds),
            "threads": args.threads, "stages": [s.split(",") for s in args.stages], "max_iters": args.max_iters,
            "x_scale": "jac",
            "mujoco": mujoco.__version__}


def check_resume(saved: dict, config: dict, path: Path) -> None:
    """Refuse a resume whose settings differ from the checkpoint's, in one line. The data's path is not a setting:
    a checkpoint carried to another machine finds its data elsewhere (:func:`same_data` names the data)."""
    diff = [f"{k}={saved.get(k)!r} there, {config[k]!r} here" for k in config
            if k not in DATA_KEYS and saved.get(k) != config[k]]
    if not same_data(saved, config):
        there = ", ".join(f"{k}={saved.get(k)!r}" for k in DATA_KEYS)
        diff.insert(0, f"data: {config['data']} is not the data there ({there})")
    if diff:
        raise ConfigChanged(f"error: {path} was written with other settings ({'; '.join(diff)}): "
                            "use the same settings or another --out")


def run_peer(args) -> dict:
    """The peer leg: returns the checkpoint state (``done`` once both stages ended on their own criteria)."""
    from absl import logging as absl_logging

    from mujoco import minimize, sysid

    absl_logging.set_verbosity(absl_logging.ERROR)  # the peer warns once per sequence that it has no sensors
    call_start = time.perf_counter()
    out = Path(args.out) / "peer"
    ckpt = out / "checkpoint.json"
    ds, robot, truth = load(args.data)
    config = peer_config(args, ds)
    setup_start = time.perf_counter()  # the data and the imports are common to both tools: not the peer's setup
    if ckpt.exists():
        state = json.loads(ckpt.read_text())
        if not args.resume:
            raise ConfigChanged(f"error: {ckpt} exists: pass --resume to continue it, or another --out")
        check_resume(state["config"], config, ckpt)
    else:
        state = {"config": config, "stage": 0, "stage_iteration": 0, "iteration": 0, "seconds": 0.0, "x": None,
                 "x_joints": None, "returned": [], "curve": [], "best": None, "stops": [], "calls": [],
                 "done": False}
    log = open_log(out / "log.txt")
    if state["done"]:
        log("peer: already done")
        return state
    resumed = bool(state["curve"])
    clock = Clock(state["seconds"], setup_start)  # the setup counts once: in the first call
    train = ds.split("train")
    stages = config["stages"]
    if not 1 <= len(stages) <= 2:
        raise SystemExit("error: --stages takes one or two field groups")
    prob = Problem(robot, ds, config["dt"], stages)
    ms = peer.tiled_sequences(prob.spec, train, ds.rate_hz, args.horizon)
    residual_fn = sysid.build_residual_fn(models_sequences=[ms], n_threads=args.threads,
                                           build_model=peer.cached_build(2 * (prob.params.size + 1)))
    n_res = sum(len(s.sensordata) - 1 for s in ms.measured_rollout)  # a window's first sample is its start
    if resumed:
        clock = Clock(state["seconds"])
    where = f"resumed at stage {state['stage'] + 1} iteration {state['stage_iteration']}" if resumed else "fresh"
    log(f"# peer on {args.data}: {len(train)} training trajectories, {len(ms.measured_rollout)} windows of "
        f"<= {args.horizon} samples, {sum(len(s.sensordata) for s in ms.measured_rollout)} samples "
        f"({n_res} in the residual); model step {config['dt'] * 1e3:g} ms; {machine(args.threads)}; "
        f"{where}; "
        f"setup {time.perf_counter() - setup_start:.1f}s; load average {os.getloadavg()[0]:.2f}")
    state["calls"].append({"machine": machine(args.threads), "threads": args.threads, "start_seconds": clock.now()})

    def validate(stage, x) -> float:
        return peer_scores(peer_model(robot, ds, config["dt"], stages, stage, x, state["x_joints"]), ds, args.threads,
                           ("validation",))["validation"]

    def record(stage, x, cost) -> None:
        t = clock.now()
        with clock.paused():
            v = validate(stage, x)
            state["curve"].append({"seconds": t, "validation": v, "stage": stage + 1, "iteration": state["iteration"],
                                   "cost": cost})
            if state["best"] is None or v < state["best"]["validation"]:
                state["best"] = {"validation": v, "stage": stage, "x": [float(a) for a in x],
                                 "x_joints": state["x_joints"], "seconds": t, "iteration": state["iteration"]}
            state["x"], state["seconds"] = [float(a) for a in x], t  # validation excluded
            write_json(ckpt, state)
        log(f"peer  stage {stage + 1}  iteration {state['stage_iteration']:3d} ({state['iteration']} in all)  "
            f"cost {cost:.4e}  validation {v:.4f}  best {state['best']['validation']:.4f}  {t:.1f}s")

    try:
        while state["stage"] < len(stages):
            stage = state["stage"]
            x0 = prob.enter(stage, state["x_joints"])
            if state["x"] is not None:  # resumed within the stage
                x0 = np.asarray(state["x"], dtype=np.float64)
            prob.params.update_from_vector(x0)
            last = {"x": x0, "cost": np.nan}  # the last single (not finite-difference) evaluation

            def residual(x):
                x = np.asarray(x, dtype=np.float64)
                r = np.concatenate(residual_fn(x, prob.params)[0])
                if x.ndim == 1 or x.shape[1] == 1:
                    last["x"], last["cost"] = x.ravel().copy(), 0.5 * float(r.ravel() @ r.ravel())
                return r

            if not state["curve"]:  # the start, once
                residual(x0[:, None])
                record(stage, x0, last["cost"])

            def on_iteration(trace, stage=stage):
                # called after each accepted step, whose point was the last single evaluation (the Armijo loop's
                # accepted candidate); the closing entry (no step: reduction 0) repeats the last recorded point
                if trace[-1].reduction == 0:
                    return
                state["iteration"] += 1
                state["stage_iteration"] += 1
                record(stage, last["x"], last["cost"])
                if args.max_seconds is not None and time.perf_counter() - call_start > args.max_seconds:
                    raise _Budget

            output = _Output(log)
            lo, hi = prob.params.get_bounds()
            x_end, _ = minimize.least_squares(x0, residual, bounds=(lo, hi), max_iter=config["max_iters"] -
                                              state["stage_iteration"], x_scale="jac", verbose=minimize.Verbosity.ITER,
                                              output=output, iter_callback=on_iteration)
            result = argparse.Namespace(x=x_end)
            stop = output.stop or "unknown"
            state["stops"].append({"stage": stage + 1, "stop": stop, "iterations": state["stage_iteration"],
                                   "seconds": clock.now()})
            log(f"peer  stage {stage + 1} ended on its own: {stop} after {state['stage_iteration']} iterations, "
                f"{clock.now():.1f}s")
            state["returned"].append([float(a) for a in result.x])  # what the backend returns: its last iterate
            if stage == 0:
                state["x_joints"] = state["returned"][0]
            state["stage"], state["stage_iteration"], state["x"] = stage + 1, 0, None
            state["seconds"] = clock.now()
            write_json(ckpt, state)
            if state["stage"] < len(stages) and args.max_seconds is not None and \
                    time.perf_counter() - call_start > args.max_seconds:
                raise _Budget
    except _Budget:
        log(f"peer: paused at --max-seconds {args.max_seconds:g} (stage {state['stage'] + 1}, iteration "
            f"{state['stage_iteration']}, {state['seconds']:.1f} peer seconds); rerun with --resume")
        return state
    state["done"] = True
    write_json(ckpt, state)
    final_peer(args, state, ds, robot, truth, log)
    return state


def peer_result(state, ds, robot, truth, threads: int, out: Path) -> dict:
    """The peer's selection (best on validation) and its own return (its last iterate; unfinished: the current one)
    scored on every split, its parameters against the truth (``out/physics.json``), the truth in its model class,
    and the fight's fields."""
    config = state["config"]
    dt, stages = config["dt"], config["stages"]
    best = state["best"]
    model = peer_model(robot, ds, dt, stages, best["stage"], best["x"], best["x_joints"])
    if state["x"] is not None:  # inside a stage
        own = peer_model(robot, ds, dt, stages, state["stage"], state["x"], state["x_joints"])
    else:  # at a stage's end
        own = peer_model(robot, ds, dt, stages, len(state["returned"]) - 1, state["returned"][-1], state["x_joints"])
    params = peer.physical_params(model, robot)
    out.mkdir(parents=True, exist_ok=True)
    params.save(out / "physics.json")
    stops = state["stops"]
    reason = "; ".join(f"stage {s['stage']}: {s['stop']}" for s in stops)
    if not state["done"]:
        reason = (reason + "; " if reason else "") + (
            f"not terminated: paused at stage {state['stage'] + 1}, iteration {state['stage_iteration']} "
            f"({state['iteration']} in all)")
    train = ds.split("train")
    return {
        "scores": peer_scores(model, ds, threads), "own_return_scores": peer_scores(own, ds, threads),
        "truth_in_peer_model": truth_in_peer(robot, ds, truth, threads),
        "param_errors": param_errors(params, truth, train),
        "curve": best_so_far([(c["seconds"], c["validation"]) for c in state["curve"]]),
        "seconds_to_final": best["seconds"], "total_s": stops[-1]["seconds"] if state["done"] else state["seconds"],
        "iterations": state["iteration"], "stops": stops,
        "converged": {"value": state["done"] and all(s["stop"] in CONVERGED for s in stops), "reason": reason},
        "samples_used": sum(len(t.q) for t in train),
        "residual_samples": sum(len(t.q) - len(peer.tiles(len(t.q), config["horizon"])) for t in train),
        # every machine its calls ran on, in order: a run resumed elsewhere is not the last machine's alone
        "machine": " / ".join(dict.fromkeys(c["machine"] for c in state["calls"])), "calls": state["calls"],
        "config": config,
    }


def final_peer(args, state, ds, robot, truth, log) -> None:
    """:func:`peer_result` of the finished run: ``OUT/peer/final.json``."""
    final = peer_result(state, ds, robot, truth, args.threads, Path(args.out) / "peer")
    write_json(Path(args.out) / "peer" / "final.json", final)
    log(f"peer: done; best validation {state['best']['validation']:.4f} at {state['best']['seconds']:.1f}s; " +
        " / ".join(f"{s} {v:.4f}" for s, v in final["scores"].items()))


# --- the wresdyn leg -----------------------------------------------------------------------------------------------

def identify_wresdyn(robot, ds, out: Path, device: str, log, iterations: int | None = None,
                     recipe: str = "default") -> dict:
    """``wresdyn identify`` (``recipe`` of :data:`recipe_search.RECIPES`, its defaults by default; ``iterations`` a
    fixed count instead of its plateau stopping) on ``device``, kernels compiled first and counted: the identified
    parameters, the best-validation curve ``[(s, rad)]``, the final scores per split, setup / total seconds."""
    from wresdyn.evaluation.open_loop import evaluate_split
    from wresdyn.identify.sysid import identify
    from wresdyn.sim.warmup import compile_kernels

    cfg = recipe_config(recipe, device)
    if iterations is not None:
        cfg = dataclasses.replace(cfg, iterations=iterations)
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    compile_kernels(robot, ds.rate_hz, ("forward", "param_grads"), solver=cfg.solver, device=cfg.device, say=log)
    setup = time.perf_counter() - t0
    params, curve = identify(robot, ds, cfg, out=out, log=log)
    total = time.perf_counter() - t0
    points = [(setup + r["wall"], r["validation"]) for r in curve if r.get("validation") is not None]
    final = {}
    for split in SPLITS:
        s, _ = evaluate_split(robot, ds.split(split), ds.rate_hz, physics=params, weights=ds.fit_weights(),
                              device=device)
        final[split] = s["pd_residual"]["mean_abs_dq"]
    return {"params": params, "curve": best_so_far(points), "scores": final, "setup_s": setup, "total_s": total,
            "train_s": points[-1][0] if points else total, "load_start": load0, "load_end": os.getloadavg()[0],
            "config": dataclasses.asdict(cfg)}


def leg_tag(tag: str | None, recipe: str, device: str) -> str:
    """The name of a wresdyn leg's outputs: ``tag`` if given, else the recipe's for a recipe other than the defaults,
    else ``cpu`` or ``cuda``."""
    return tag or (recipe if recipe != "default" else "cuda" if device.startswith("cuda") else "cpu")


def run_wresdyn(args) -> dict:
    """The wresdyn leg: :func:`identify_wresdyn` with ``args.recipe`` (its defaults unless told) on ``args.device``,
    ``OUT/wresdyn_TAG.json`` (resumable through its run folder ``OUT/wresdyn_TAG/``, TAG :func:`leg_tag`)."""
    tag = leg_tag(args.tag, args.recipe, args.device)
    out = Path(args.out) / f"wresdyn_{tag}"
    log_ = open_log(out / "log.txt")
    lines = []

    def log(line: str) -> None:
        lines.append(line)
        log_(line)

    ds, robot, truth = load(args.data)
    threads = None if args.device.startswith("cuda") else 1  # its default torch_threads
    log(f"# wresdyn identify on {args.data}, device {args.device}, recipe {args.recipe} {RECIPES[args.recipe]}; "
        f"{machine(threads, args.device)}; load average {os.getloadavg()[0]:.2f}")
    w = identify_wresdyn(robot, ds, out, args.device, log, recipe=args.recipe)
    best = w["curve"]
    reason = next((ln.split(": ", 1)[1] for ln in reversed(lines)
                   if ": converged at iteration" in ln or ": stopped at the" in ln), "unknown")
    result = {k: v for k, v in w.items() if k != "params"} | {
        "seconds_to_final": time_to(best, best[-1][1]) if best else w["total_s"],
        "converged": {"value": reason.startswith("converged"), "reason": reason},
        "samples_used": sum(len(t.q) for t in ds.split("train")),
        "param_errors": param_errors(w["params"], truth, ds.split("train")),
        "machine": machine(threads, args.device), "device": args.device, "recipe": args.recipe,
    }
    w["params"].save(out / "physics.json")
    write_json(Path(args.out) / f"wresdyn_{tag}.json", result)
    log(f"# wresdyn done in {w['total_s']:.0f}s: " + " / ".join(f"{s} {v:.4f}" for s, v in w["scores"].items()))
    return result


# --- the report ----------------------------------------------------------------------------------------------------

def report(args) -> dict:
    """``OUT/summary.json``, ``OUT/curves.json``, ``OUT/curves.png`` and a Markdown table on stdout from the legs'
    outputs (a leg not run is left out; an unfinished peer refuses)."""
    out = Path(args.out)
    tools = {}
    if (out / "peer" / "final.json").exists():
        tools["mujoco.sysid"] = json.loads((out / "peer" / "final.json").read_text())
    elif (out / "peer" / "checkpoint.json").exists():
        if not args.partial:
            raise SystemExit(f"error: the peer leg in {out / 'peer'} has not finished: run it again with --resume, "
                             "or report its best so far with --partial")
        state = json.loads((out / "peer" / "checkpoint.json").read_text())
        data = args.data or state["config"]["data"]  # the checkpoint's path is the machine's that wrote it
        here = {"data_sha256": file_digest(data), "data_content_sha256": data_digest(data)}
        if not same_data(state["config"], here):
            there = {k: state["config"].get(k) for k in DATA_KEYS[1:]}
            raise SystemExit(f"error: {data} is not the data {out / 'peer'} was fitted on ({here} here, {there} there)")
        ds, robot, truth = load(data)
        tools["mujoco.sysid"] = peer_result(state, ds, robot, truth, os.cpu_count() or 1, out / "peer" / "partial")
    for leg in sorted(out.glob("wresdyn_*.json")):
        tools[leg.stem] = json.loads(leg.read_text())
    if not tools:
        raise SystemExit(f"error: no leg output in {out}")
    summary = {name: {"heldout_error": r["scores"]["heldout"], "ood_error": r["scores"]["ood"],
                      "seconds_to_final": r["seconds_to_final"], "converged": r["converged"],
                      "samples_used": r["samples_used"], "machine": r["machine"]} for name, r in tools.items()}
    extra = {name: {k: v for k, v in r.items() if k not in ("curve",)} for name, r in tools.items()}
    if "mujoco.sysid" in tools:
        p = tools["mujoco.sysid"]
        level = p["curve"][-1][1]
        extra["peer_final_validation"] = level
        for name, w in tools.items():
            tag = name.removeprefix("wresdyn_")
            if name != "mujoco.sysid":
                t_w = time_to(w["curve"], level)
                extra[f"ratio_{tag}"] = {
                    "wresdyn_seconds_to_peer_final": t_w,
                    "over_peer_seconds_to_final": None if t_w is None else t_w / p["seconds_to_final"],
                    "over_peer_total": None if t_w is None else t_w / p["total_s"]}
    summary["extra"] = extra
    write_json(out / "summary.json", summary)
    write_json(out / "curves.json", {name: r["curve"] for name, r in tools.items()})
    plot(out / "curves.png", tools, args.title or out.name)
    table(tools, extra)
    return summary


def plot(path: Path, tools: dict, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for i, (name, r) in enumerate(n for n in tools.items() if n[0] != "mujoco.sysid"):
        c = np.asarray(r["curve"])  # past ten legs the colour cycle repeats: those dotted
        if len(c):
            ax.step(np.maximum(c[:, 0], 1e-1), c[:, 1], where="post", label=name, color=f"C{i % 10}", ls="-:"[i >= 10])
    if "mujoco.sysid" in tools:  # black and drawn last, so that no leg's colour or line hides the peer's
        c = np.asarray(tools["mujoco.sysid"]["curve"])
        ax.step(np.maximum(c[:, 0], 1e-1), c[:, 1], where="post", label="mujoco.sysid", color="k", lw=2)
    ax.set(xscale="log", yscale="log", xlabel="wall-clock [s] (validation excluded)",
           ylabel="best validation mean |Δq| [rad]", title=title)
    ax.grid(True, which="both", alpha=0.3)
    # beside the axes: inside, seven legs' names hid the peer's long flat tail
    ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def table(tools: dict, extra: dict) -> None:
    names = list(tools)
    print("| | " + " | ".join(names) + " |")
    print("|---" * (len(names) + 1) + "|")
    for split in SPLITS:
        row = " | ".join(f"{tools[n]['scores'][split]:.4f}" for n in names)
        print(f"| {split} mean \\|Δq\\| [rad] | {row} |")
    for key in ("seconds_to_final", "total_s"):
        print(f"| {key} | " + " | ".join(f"{tools[n][key]:.1f}" for n in names) + " |")
    print("| converged | " + " | ".join(f"{tools[n]['converged']['value']} ({tools[n]['converged']['reason']})"
                                       for n in names) + " |")
    fields = ("within_10pct", *(f"median_err_{f}" for f in peer.JOINT_FIELDS), "median_err_mass", "median_err_com_m")
    for f in fields:
        vals = [tools[n]["param_errors"][f] for n in names]
        fmt = (lambda v, n: f"{v} / {tools[n]['param_errors']['identifiable']}") if f == "within_10pct" else \
            (lambda v, n: f"{v:.3f}")
        print(f"| {f} | " + " | ".join(fmt(v, n) for v, n in zip(vals, names)) + " |")
    if "mujoco.sysid" in tools:
        p = tools["mujoco.sysid"]
        for key, what in (("own_return_scores", "mujoco.sysid's own return (its last iterate)"),
                          ("truth_in_peer_model", "the truth in the peer's model (its floor)")):
            print(f"{what}, validation / held-out / OOD [rad]: " + " / ".join(f"{p[key][s]:.4f}" for s in SPLITS))
    for tag in (k.removeprefix("ratio_") for k in extra if k.startswith("ratio_")):
        print(f"wresdyn ({tag}) to the peer's final validation {extra['peer_final_validation']:.4f} rad: "
              f"{extra[f'ratio_{tag}']}")


def build_parser() -> argparse.ArgumentParser:
    """The command line: one subcommand per leg."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="leg", required=True)
    a = sub.add_parser("peer", help="mujoco.sysid, staged, to its own termination (resumable)")
    a.add_argument("data", help="dataset recorded on the simulated real robot (.npz)")
    a.add_argument("--out", required=True, help="output folder (one per dataset)")
    a.add_argument("--horizon", type=int, default=250, help="window length [samples] (default 250: 0.5 s)")
    a.add_argument("--threads", type=int, default=os.cpu_count(), help="mujoco.rollout threads (default: all)")
    a.add_argument("--max-seconds", type=float, default=None, help="end this call after the iteration passing it")
    a.add_argument("--resume", action="store_true", help="continue OUT/peer/checkpoint.json")
    a.add_argument("--stages", nargs="+", default=[",".join(st) for st in STAGES],
                   help="field groups fitted one after the other, comma-separated (default: the joints' fields, then "
                        "'bodies')")
    a.add_argument("--max-iters", type=int, default=MAX_ITERS,
                   help="Gauss-Newton iterations per stage at most (default out of reach)")
    b = sub.add_parser("wresdyn", help="wresdyn identify with its defaults (or --recipe's settings)")
    b.add_argument("data")
    b.add_argument("--out", required=True)
    b.add_argument("--device", default="cpu", help="cpu or cuda:0")
    b.add_argument("--tag", default=None,
                   help="names the leg's outputs OUT/wresdyn_TAG{,.json} (default: --recipe's name; with the "
                        "defaults cpu or cuda), so that one device on two machines keeps two legs")
    b.add_argument("--recipe", default="default", choices=sorted(RECIPES),
                   help="identification settings of recipe_search.RECIPES (default: SysIdConfig's defaults); names "
                        "the outputs OUT/wresdyn_RECIPE unless --tag")
    c = sub.add_parser("report", help="summary.json, curves.json / .png and the tables from the legs' outputs")
    c.add_argument("--out", required=True)
    c.add_argument("--title", default=None)
    c.add_argument("--data", default=None,
                   help="the dataset an unfinished peer is scored on (default: the path its checkpoint recorded)")
    c.add_argument("--partial", action="store_true",
                   help="an unfinished peer leg enters with its best so far, marked not converged")
    return p


def main(argv=None) -> None:
    args = build_parser().parse_args(argv)
    {"peer": run_peer, "wresdyn": run_wresdyn, "report": report}[args.leg](args)


if __name__ == "__main__":
    main()
