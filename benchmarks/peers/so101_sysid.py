"""The SO-101's published models fitted on recorded runs with MuJoCo's own toolbox, replayed in MuJoCo C.

Written on public APIs only: ``mujoco.sysid`` (``Parameter``, ``ParameterDict``, ``TimeSeries``,
``ModelSequences``, ``create_initial_state``, ``sysid_rollout``, ``apply_pgain`` / ``apply_dgain``,
``apply_param_modifiers``, ``build_residual_fn``, ``optimize``), ``mujoco.rollout`` and
``scipy.optimize.least_squares``. Three recipes:

- **playground**: the parameter set of MuJoCo Playground's SO-101 identification (google-deepmind/mujoco_playground
  v1.0.0, ``mujoco_playground/tasks/sysid/so101/README.md``): 24 parameters, per joint of the six ``armature``,
  ``frictionloss``, ``stiffness`` and ``damping``, read here as the position servo's P and D gains (its simulation
  constants, ``robots/so101/sim/constant.py``, list armature, frictionloss and "position servo PD gains identified
  from real teleop data"), fitted by ``mujoco.sysid``'s Gauss-Newton least squares on the joint positions of
  rollouts (the error in radians: ``so101_residual.py``). Playground measures the serial command transport delay from its logs' stamps and shifts the control
  times by it; the SAGE logs carry no such stamps, so here the delay is a 25th parameter fitted with the others:
  each command reaches the servo ``delay`` seconds late (the control series shifted in time, linearly
  interpolated, so finite differences see a change below one sample).
- **lerobot**: LeRobot's SO-101 MuJoCo model (:func:`wresdyn.evaluation.servo_baselines.lerobot_model`: kp 17.8,
  kv 0, damping 0.60, frictionloss 0.052, armature 0.028) with its joint parameters (damping, frictionloss,
  armature) and its actuator's kp fitted per arm joint the same way; no delay (the model has none).
- **bam**: BAM's STS3215 model class (:class:`~wresdyn.evaluation.servo_baselines.BamDrive`): kt, R, armature,
  Coulomb and viscous friction, the firmware's P and the target's maximum velocity, one set for every joint as BAM
  identifies one per servo type, bounds as BAM 1.0.2 sets them. Fitted by ``scipy.optimize.least_squares`` on the
  MuJoCo replay of :func:`bam_native`, a native MuJoCo model with the same law (checked against ``BamDrive`` in
  ``tests/integration/test_peers_so101.py``) so that ``mujoco.rollout`` runs it.

Data: windows of ``horizon`` samples, ``per_run`` evenly spaced per training run, each from its own recorded state;
the residual covers the five arm joints' positions (the gripper is excluded, as the dataset excludes it). The fits
run with contacts off (the arm's collision pairs cost 2.6x the step); scoring replays the fitted model with the
robot file's options, contacts on, through :func:`wresdyn.evaluation.servo_baselines.evaluate_baseline`.
"""

from __future__ import annotations

import copy
import dataclasses
import io
import math
import re
import time
from dataclasses import dataclass, field

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout
from mujoco import sysid
from scipy import optimize as scipy_optimize

from wresdyn.evaluation.servo_baselines import LEROBOT_KP, BamParams

ARM = 5
"""The fitted joints are the first five (shoulder pan to wrist roll); the gripper is replayed, never scored."""

PLAYGROUND_FIELDS = ("armature", "frictionloss", "kp", "kv")
"""Playground's per-joint set: joint armature and friction loss, position servo P ("stiffness") and D ("damping")."""
PLAYGROUND_BOUNDS = {"armature": (1e-4, 0.5), "frictionloss": (0.0, 1.0), "kp": (1.0, 2000.0), "kv": (0.0, 20.0)}
"""Box bounds [SI]: wide around the robot file's start (armature 0.028 kg·m², friction 0.052 N·m, kp 998 N·m/rad,
kv 2.7 N·m·s/rad) and Playground's identified armatures (0.11-0.20 kg·m²)."""
DELAY_BOUNDS = (0.0, 0.1)
"""Transport delay [s]: up to five 50 Hz control periods."""
DELAY_START = 0.01
"""Start of the delay [s]: half a 50 Hz control period, off the bound at 0."""
LEROBOT_FIELDS = ("damping", "frictionloss", "armature", "kp")
LEROBOT_BOUNDS = {"damping": (0.0, 10.0), "frictionloss": (0.0, 1.0), "armature": (1e-4, 0.5), "kp": (0.5, 500.0)}
"""Box bounds [SI] around LeRobot's values (0.60, 0.052, 0.028, 17.8)."""
BAM_FIELDS = ("kt", "R", "armature", "friction_base", "friction_viscous", "kp", "max_velocity")
BAM_BOUNDS = {"kt": (0.05, 2.5), "R": (0.1, 10.0), "armature": (1e-5, 0.04), "friction_base": (0.0, 0.2),
              "friction_viscous": (0.0, 1.0), "kp": (1.6, 160.0),
              "max_velocity": (0.1 * 3400 * 2 * math.pi / 4096, 10.0 * 3400 * 2 * math.pi / 4096)}
"""BAM 1.0.2's own bounds (``bam/feetech/actuator.py`` ``STS3215Actuator.initialize``, ``bam/model.py``); its
``error_gain_ratio`` (0.1-10) is carried by the firmware P (16 x 0.1-10)."""


def load_spec(robot_file, rate_hz: float, contact: bool = False) -> mujoco.MjSpec:
    """The robot file as an ``MjSpec`` stepping at ``1 / rate_hz``; ``contact=False`` turns collisions off."""
    spec = mujoco.MjSpec.from_file(str(robot_file))
    spec.option.timestep = 1.0 / rate_hz
    if not contact:
        spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    return spec


def lerobot_spec(spec: mujoco.MjSpec) -> mujoco.MjSpec:
    """``spec`` with LeRobot's actuator gains (kp 17.8 N·m/rad, kv 0) on every position actuator, in place."""
    for a in spec.actuators:
        sysid.apply_pgain(spec, a.name, LEROBOT_KP)
        sysid.apply_dgain(spec, a.name, 0.0)
    return spec


def joint_names(spec: mujoco.MjSpec) -> list[str]:
    return [j.name for j in spec.joints]


def _setter(field_name: str, joint: str):
    """A ``Parameter`` modifier writing one joint's (or its actuator's) field into the spec."""
    if field_name == "kp":
        return lambda s, p: sysid.apply_pgain(s, joint, float(p.value[0]))
    if field_name == "kv":
        return lambda s, p: sysid.apply_dgain(s, joint, float(p.value[0]))
    if field_name == "damping":
        def set_damping(s, p):
            d = np.array(s.joint(joint).damping)
            d[0] = p.value[0]
            s.joint(joint).damping = d
        return set_damping
    return lambda s, p: setattr(s.joint(joint), field_name, float(p.value[0]))


def _start(spec: mujoco.MjSpec, field_name: str, joint: str) -> float:
    if field_name == "kp":
        return float(spec.actuator(joint).gainprm[0])
    if field_name == "kv":
        return float(-spec.actuator(joint).biasprm[2])
    if field_name == "damping":
        return float(spec.joint(joint).damping[0])
    return float(getattr(spec.joint(joint), field_name))


def joint_params(spec: mujoco.MjSpec, joints, fields, bounds, delay: bool = False) -> sysid.ParameterDict:
    """``ParameterDict`` of ``fields`` on each of ``joints`` (named ``{joint}_{field}``), each starting at the spec's
    value (moved off a bound by the peer's ``move_off_bounds``), and ``delay`` [s] when asked."""
    params = sysid.ParameterDict()
    for j in joints:
        for f in fields:
            lo, hi = bounds[f]
            params.add(sysid.Parameter(f"{j}_{f}", _start(spec, f, j), lo, hi, modifier=_setter(f, j)))
    if delay:
        params.add(sysid.Parameter("delay", DELAY_START, *DELAY_BOUNDS))
    params.move_off_bounds()
    return params


def playground_params(spec: mujoco.MjSpec) -> sysid.ParameterDict:
    """Playground's 24 (4 per joint of the six) plus the transport delay."""
    return joint_params(spec, joint_names(spec), PLAYGROUND_FIELDS, PLAYGROUND_BOUNDS, delay=True)


def lerobot_params(spec: mujoco.MjSpec) -> sysid.ParameterDict:
    """LeRobot's joint parameters and kp on each arm joint (4 x 5)."""
    return joint_params(spec, joint_names(spec)[:ARM], LEROBOT_FIELDS, LEROBOT_BOUNDS)


def window_starts(n_samples: int, horizon: int, per_run: int) -> np.ndarray:
    """``per_run`` window starts over a run of ``n_samples``, at the middles of ``per_run`` equal parts of the
    possible starts (one window: the run's middle, past the settling hold most runs begin with)."""
    last = n_samples - horizon
    if last < 0:
        return np.zeros(0, dtype=int)
    return np.unique(((np.arange(per_run) + 0.5) / per_run * last).astype(int))


def shift(values: np.ndarray, delay_s: float, dt: float) -> np.ndarray:
    """``values`` (T, n) sampled at ``dt`` as seen ``delay_s`` later: row k is the series at k·dt − delay,
    linearly interpolated, the first row held before the start."""
    t = np.arange(len(values)) * dt
    return np.stack([np.interp(t - delay_s, t, col) for col in values.T], axis=1)


def model_sequences(spec: mujoco.MjSpec, trajectories, horizon: int, per_run: int) -> sysid.ModelSequences:
    """``ModelSequences`` of windows of the training ``trajectories`` (each with ``q``, ``qd``, ``q_cmd`` of shape
    (T, 6)): the commands as every actuator's control, the arm joints' recorded positions as observations
    (``MjStateQPos``), the window's first recorded (q, q̇) as its initial state."""
    model = spec.compile()
    dt = model.opt.timestep
    arm = joint_names(spec)[:ARM]
    obs = [(f"{j}_qpos", sysid.SignalType.MjStateQPos) for j in arm]
    names, states, controls, sensors = [], [], [], []
    for tr in trajectories:
        for s in window_starts(len(tr.q), horizon, per_run):
            times = np.arange(horizon) * dt
            names.append(f"{tr.name}@{s}")
            states.append(sysid.create_initial_state(model, tr.q[s], tr.qd[s]))
            controls.append(sysid.TimeSeries.from_control_names(times, tr.q_cmd[s:s + horizon], model))
            sensors.append(sysid.TimeSeries.from_names(times, tr.q[s:s + horizon, :ARM], model, names=obs))
    return sysid.ModelSequences("so101", spec, names, states, controls, sensors, allow_missing_sensors=True)


def delayed_rollout(*, models, datas, control_signal, initial_states, param_dicts, rollout_signal_mapping,
                    rollout_state_mapping, ctrl_mapping):
    """``mujoco.sysid``'s rollout with each control series shifted by its parameter set's ``delay`` (a
    ``CustomRolloutFn``: one parameter set per finite-difference column, its sequences consecutive)."""
    per = len(control_signal) // len(param_dicts)
    shifted = []
    for i, ts in enumerate(control_signal):
        d = float(param_dicts[i // per]["delay"].value[0])
        dt = float(ts.times[1] - ts.times[0])
        shifted.append(sysid.TimeSeries(ts.times, shift(ts.data, d, dt), ts.signal_mapping))
    return sysid.sysid_rollout(models, datas, shifted, initial_states, rollout_signal_mapping,
                               rollout_state_mapping, ctrl_mapping)


class CachedBuild:
    """``build_model`` for ``build_residual_fn``: ``mujoco.sysid`` rebuilds the model once per sequence and
    finite-difference column; the same parameter values compile once (the spec is written in full each time)."""

    def __init__(self, size: int = 256):
        self.size = size
        self.cache: dict = {}
        self.compiles = 0

    def __call__(self, params: sysid.ParameterDict, spec: mujoco.MjSpec) -> mujoco.MjModel:
        key = (id(spec), params.as_vector().tobytes())
        if key not in self.cache:
            if len(self.cache) >= self.size:
                self.cache.clear()
            self.cache[key] = sysid.apply_param_modifiers(params, spec)
            self.compiles += 1
        return self.cache[key]


def build(params: sysid.ParameterDict, spec: mujoco.MjSpec) -> mujoco.MjModel:
    """The model of ``spec`` with ``params`` written into it (a copy: ``spec`` is left as it was)."""
    return sysid.apply_param_modifiers(params, spec.copy())


def replay_q(model: mujoco.MjModel, trajectories, delay_s: float = 0.0, controls=None, threads: int = 1):
    """Whole-run replays with ``mujoco.rollout`` from each run's first recorded state, command k held for step k
    (``controls``: per run (T, nu) in place of the recorded commands), shifted by ``delay_s``: list of q (T, nq)."""
    datas = [mujoco.MjData(model) for _ in range(threads)]
    size = mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    out = []
    for i, tr in enumerate(trajectories):
        u = tr.q_cmd if controls is None else controls[i]
        if delay_s:
            u = shift(u, delay_s, model.opt.timestep)
        d = datas[0]
        mujoco.mj_resetData(model, d)
        d.qpos[:], d.qvel[:] = tr.q[0], tr.qd[0]
        x0 = np.empty((1, size))
        mujoco.mj_getState(model, d, x0[0], mujoco.mjtState.mjSTATE_FULLPHYSICS)
        state, _ = mj_rollout.rollout(model, datas, x0, u[None, :-1])
        q = np.vstack([tr.q[:1], state[0, :, 1:1 + model.nq]])
        out.append(q)
    return out


def mean_abs_dq(trajectories, qs) -> float:
    """Mean |Δq| over the arm joints and every sample of every run [rad] (the scoring metric's numerator; a
    non-finite replay counts as 1 rad so a diverged candidate never looks good)."""
    errs = [np.nan_to_num(np.abs(q[:, :ARM] - tr.q[:, :ARM]), nan=1.0) for tr, q in zip(trajectories, qs)]
    return float(np.concatenate([e.ravel() for e in errs]).mean())


@dataclass
class FitRecord:
    """One fit to its optimiser's termination."""

    method: str
    values: dict
    """Fitted parameter values, name -> list."""
    seconds: float
    """Wall-clock of the fit [s], the validation curve's replays excluded."""
    iterations: int
    status: str
    """The optimiser's own termination message."""
    converged: bool
    samples: int
    """Recorded training samples in the residual (windows x horizon)."""
    curve: list = field(default_factory=list)
    """Per iteration: {iteration, seconds (fit time so far), objective, validation [rad]}."""


def fit_sysid(params: sysid.ParameterDict, ms: sysid.ModelSequences, val_fn, *, delay: bool, max_iters: int,
              threads: int, log=print, modify_residual=None) -> tuple[sysid.ParameterDict, FitRecord]:
    """``mujoco.sysid.optimize`` (the ``"mujoco"`` backend: projected Gauss-Newton with finite-difference Jacobians
    over ``mujoco.rollout``, ``x_scale="jac"``) to its own termination or ``max_iters``; ``val_fn(params) ->`` mean
    |Δq| on validation, evaluated at every iteration's candidate (its time not counted). The record keeps every
    candidate's values (``curve``) so the iterate of lowest validation error can be rebuilt; ``modify_residual``
    replaces ``mujoco.sysid``'s default residual."""
    builder = CachedBuild()
    residual_fn = sysid.build_residual_fn(models_sequences=[ms], build_model=builder, n_threads=threads,
                                          custom_rollout=delayed_rollout if delay else None,
                                          modify_residual=modify_residual)
    curve, paused = [], [0.0]
    t0 = time.perf_counter()

    def on_iteration(trace):
        t_pause = time.perf_counter()
        p = params.copy()
        p.update_from_vector(np.asarray(trace[-1].candidate).ravel())
        v = val_fn(p)
        elapsed = t_pause - t0 - paused[0]
        values = {k: q.value.tolist() for k, q in p.items()}
        curve.append({"iteration": len(trace) - 1, "seconds": round(elapsed, 2),
                      "objective": float(trace[-1].objective), "validation": v, "values": values})
        log(f"  iter {len(trace) - 1:3d}  objective {float(trace[-1].objective):.6g}  validation {v:.5f} rad  "
            f"{elapsed:.0f} s", flush=True)
        paused[0] += time.perf_counter() - t_pause

    out = io.StringIO()
    opt, _ = sysid.optimize(params, residual_fn, optimizer="mujoco", verbose=False, max_iters=max_iters,
                            x_scale="jac", iter_callback=on_iteration, output=out)
    seconds = time.perf_counter() - t0 - paused[0]
    text = out.getvalue()
    m = re.search(r"Terminated after (\d+) iterations: .*", text)
    status = m.group(0).strip() if m else text.strip().splitlines()[-1] if text.strip() else "unknown"
    iters = int(m.group(1)) if m else len(curve)
    converged = bool(m) and "maximum iterations" not in status
    final_v = val_fn(opt)
    values = {k: p.value.tolist() for k, p in opt.items()}
    curve.append({"iteration": iters, "seconds": round(seconds, 2), "objective": None, "validation": final_v,
                  "final": True, "values": values})
    rec = FitRecord("mujoco.sysid.optimize (mujoco backend)", values, seconds, iters, status, converged,
                    sum(len(s.times) for s in ms.sensordata), curve)
    return opt, rec


# ---- BAM's model class as a native MuJoCo model ----

def bam_native(base: mujoco.MjModel, p: BamParams) -> mujoco.MjModel:
    """``base`` (the robot, position actuators) turned into BAM's servo law, a copy.

    BAM: τ = kt/R · vin · clip(kp · error_gain · (target − q), ±max_pwm) − kt²/R · q̇ with the friction model's
    Coulomb (frictionloss) and viscous (damping) terms. Here: a position actuator of gain K = kt/R · vin · kp ·
    error_gain on the target, force-limited to ±kt/R · vin · max_pwm (the duty clip), and the back-EMF term
    kt²/R added to the joint damping (outside the clip, as in BAM), integrated explicitly as BamDrive applies it;
    the target's rate limit is on the controls (:func:`bam_targets`). The one difference left: the viscous friction
    is explicit here and implicit in BamDrive's model (the test bounds the effect)."""
    m = copy.deepcopy(base)
    k = p.kt / p.R * p.vin * p.kp * p.error_gain
    limit = p.kt / p.R * p.vin * p.max_pwm
    m.actuator_gainprm[:, :] = 0.0
    m.actuator_gainprm[:, 0] = k
    m.actuator_biasprm[:, :] = 0.0
    m.actuator_biasprm[:, 1] = -k
    m.actuator_ctrllimited[:] = 0
    m.actuator_forcelimited[:] = 1
    m.actuator_forcerange[:, 0], m.actuator_forcerange[:, 1] = -limit, limit
    m.dof_armature[:] = p.armature
    m.dof_frictionloss[:] = p.friction_base
    m.dof_damping[:] = p.friction_viscous + p.kt**2 / p.R
    # BamDrive's back-EMF is an explicit torque: Euler's implicit joint damping would change it by h·b/M, 4 % here
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    return m


def bam_targets(q_cmd: np.ndarray, q0: np.ndarray, max_velocity: float, dt: float) -> np.ndarray:
    """The firmware's target, moving at most ``max_velocity`` [rad/s] toward the command from ``q0``: shape of
    ``q_cmd`` ((T, n) or (B, T, n) with ``q0`` (n,) or (B, n)), target k computed at step k as ``BamDrive`` does."""
    step = max_velocity * dt
    out = np.empty_like(q_cmd)
    target = np.array(q0, dtype=np.float64)
    for k in range(q_cmd.shape[-2]):
        target = np.clip(q_cmd[..., k, :], target - step, target + step)
        out[..., k, :] = target
    return out


def bam_params(x: np.ndarray, template: BamParams) -> BamParams:
    return dataclasses.replace(template, **{f: float(v) for f, v in zip(BAM_FIELDS, x)})


class BamWindows:
    """The training windows for the BAM fit: initial states, commands and recorded arm positions, batched."""

    def __init__(self, base: mujoco.MjModel, trajectories, horizon: int, per_run: int):
        self.base = base
        size = mujoco.mj_stateSize(base, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        d = mujoco.MjData(base)
        x0, u, q, q0 = [], [], [], []
        for tr in trajectories:
            for s in window_starts(len(tr.q), horizon, per_run):
                mujoco.mj_resetData(base, d)
                d.qpos[:], d.qvel[:] = tr.q[s], tr.qd[s]
                st = np.empty(size)
                mujoco.mj_getState(base, d, st, mujoco.mjtState.mjSTATE_FULLPHYSICS)
                x0.append(st)
                u.append(tr.q_cmd[s:s + horizon])
                q.append(tr.q[s:s + horizon, :ARM])
                q0.append(tr.q[s])
        self.x0, self.u, self.q, self.q0 = np.array(x0), np.array(u), np.array(q), np.array(q0)

    @property
    def samples(self) -> int:
        return int(self.q.shape[0] * self.q.shape[1])

    def residual(self, p: BamParams, datas) -> np.ndarray:
        """Arm-joint position error [rad] of the native BAM model over every window, flat."""
        m = bam_native(self.base, p)
        targets = bam_targets(self.u, self.q0, p.max_velocity, m.opt.timestep)
        state, _ = mj_rollout.rollout(m, datas, self.x0, targets[:, :-1])
        qs = state[:, :, 1:1 + ARM]
        r = qs - self.q[:, 1:]
        return np.nan_to_num(r, nan=1.0, posinf=1.0, neginf=-1.0).ravel()


def fit_bam(windows: BamWindows, start: BamParams, val_fn, *, max_nfev: int, threads: int, log=print):
    """BAM's parameters by ``scipy.optimize.least_squares`` (trust-region reflective, 2-point finite differences,
    ``x_scale="jac"``, BAM's bounds) on the arm-joint position error of the native replay; ``val_fn(params)`` at
    every evaluation that lowers the cost (its time not counted)."""
    datas = [mujoco.MjData(windows.base) for _ in range(threads)]
    lo = np.array([BAM_BOUNDS[f][0] for f in BAM_FIELDS])
    hi = np.array([BAM_BOUNDS[f][1] for f in BAM_FIELDS])
    x0 = np.clip(np.array([getattr(start, f) for f in BAM_FIELDS]), lo, hi)
    curve, paused, best, n_eval = [], [0.0], [np.inf], [0]
    t0 = time.perf_counter()

    def fun(x):
        r = windows.residual(bam_params(x, start), datas)
        n_eval[0] += 1
        cost = 0.5 * float(r @ r)
        if cost < best[0]:
            best[0] = cost
            t_pause = time.perf_counter()
            v = val_fn(bam_params(x, start))
            elapsed = t_pause - t0 - paused[0]
            curve.append({"evaluation": n_eval[0], "seconds": round(elapsed, 2), "objective": cost, "validation": v})
            log(f"  eval {n_eval[0]:3d}  cost {cost:.6g}  validation {v:.5f} rad  {elapsed:.0f} s", flush=True)
            paused[0] += time.perf_counter() - t_pause
        return r

    res = scipy_optimize.least_squares(fun, x0, bounds=(lo, hi), x_scale="jac", diff_step=1e-4, max_nfev=max_nfev)
    seconds = time.perf_counter() - t0 - paused[0]
    fitted = bam_params(res.x, start)
    curve.append({"evaluation": n_eval[0], "seconds": round(seconds, 2), "objective": float(res.cost),
                  "validation": val_fn(fitted), "final": True})
    rec = FitRecord("scipy.optimize.least_squares (trf) on the MuJoCo replay", dataclasses.asdict(fitted), seconds,
                    int(res.nfev), f"status {res.status}: {res.message}", res.status > 0, windows.samples, curve)
    return fitted, rec
