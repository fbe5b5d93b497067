"""The project's robot and recordings in ``mujoco.sysid``'s terms (MuJoCo ≥ 3.17, ``pip install "mujoco[sysid]"``).

``mujoco.sysid`` fits anything settable on an ``MjSpec`` by Gauss-Newton with finite-difference Jacobians over
``mujoco.rollout``. This module is the adapter :mod:`peer_sysid` runs it through, written with the peer's public
API only (``Parameter``, ``ParameterDict``, ``body_inertia_param``, ``apply_pgain`` / ``apply_dgain``,
``TimeSeries``, ``ModelSequences``, ``build_residual_fn``, ``optimize``). Its choices:

- **Model.** The nominal robot's ``MjSpec`` (:func:`wresdyn.robot.mujoco_model.mujoco_spec`: the robot file's
  bodies, inertias, joints and PD position actuators with the effort limit as force range), ``implicitfast`` at a
  model step ``dt``: the recording step by default, or the "real" robot's own 1 ms step (``dt=``). The "real" robot
  is that same MuJoCo model perturbed and stepped at 1 ms, so the peer simulates in the truth's own engine: an
  advantage over wresdyn, whose SolverReplay is another simulator.
- **Commands.** Each actuator's ``ctrl`` is the recorded command ``q_cmd``, held for one sample as the real robot
  holds it: at a model step finer than the sample the control series is written at the model step, each command
  repeated (the peer resamples controls to the model step by linear interpolation, here the identity). Every
  actuator carries MuJoCo's native control history (:func:`history_size` entries, linear interpolation) so the
  actuator ``delay`` is a continuous, finite-differenceable model parameter up to :data:`MAX_DELAY`; the history
  at the start of a sequence holds the commands before it (the first command before sample 0: the robot held it
  while settling).
- **Observations.** The joint state: each joint's qpos and qvel (``SignalType.MjStateQPos`` / ``MjStateQVel``)
  against the recorded q and q̇, with the peer's default residual (each column divided by its RMS over the
  sequence). Not ``jointpos`` / ``jointvel`` sensors: ``mujoco.rollout`` returns the sensors computed at the start
  of each step but stamps them with the time at its end, so the peer's residual would compare them with the
  recording one sample late (on a noise-free cartpole, damping then converges 50 % off the truth).
- **Initial state.** ``mjSTATE_FULLPHYSICS`` with the recorded q, q̇ of the sequence's first sample and the history
  above, built with ``mj_initCtrlHistory`` (the peer's ``create_initial_state`` leaves the history empty).
- **Sequences.** :func:`tiled_sequences`: consecutive windows of ``horizon`` samples tiling every training
  trajectory end to end (the peer's ``SystemTrajectory.split`` layout, the short tail kept as a window of its own so
  every sample is used once), each its own sequence from its own recorded start state. :func:`sequences`:
  ``chunks`` evenly spaced windows per trajectory.
- **Parameters** (the set wresdyn identifies): per joint armature, damping, friction loss, kp, kd (``apply_pgain``,
  ``apply_dgain``), effort limit (force range) and delay; per moving link the 10-D pseudo-inertia
  (``body_inertia_param(..., InertiaType.Pseudo)``, its default bounds). Bounds below; every parameter starts at
  the robot file's value, moved off a bound by the peer's own ``move_off_bounds`` as its documentation advises.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

MAX_DELAY = 0.012
"""Largest actuator delay the peer may fit [s] (a few ms of bus latency at most, with room on both mismatches)."""
NSAMPLE = 8
"""Control-history samples per actuator at the 2 ms recording step: :func:`history_size` of it."""
JOINT_FIELDS = ("kp", "kd", "armature", "damping", "friction", "effort", "delay")
"""Per-joint fields the peer fits, named as :class:`~wresdyn.robot.physical.PhysicalParams`' fields."""


def history_size(dt: float) -> int:
    """Control-history entries per actuator at model step ``dt`` [s]: MuJoCo interpolates a delayed control between
    two entries and needs one more, so ``MAX_DELAY / dt + 2``."""
    return int(round(MAX_DELAY / dt)) + 2


def peer_spec(robot, rate_hz: float, dt: float | None = None):
    """The nominal robot's ``MjSpec`` at model step ``dt`` [s] (default the recording step ``1 / rate_hz``), every
    actuator with a control history."""
    from wresdyn.robot.mujoco_model import mujoco_spec

    dt = 1.0 / rate_hz if dt is None else dt
    substeps(rate_hz, dt)  # refuses a step that does not divide the sample period
    spec = mujoco_spec(robot, dt, "implicitfast")
    for a in spec.actuators:
        a.nsample, a.interp, a.delay = history_size(dt), 1, 0.0
    return spec


def substeps(rate_hz: float, dt: float) -> int:
    """Model steps per recorded sample."""
    n = int(round(1.0 / (rate_hz * dt)))
    if n < 1 or abs(n * dt * rate_hz - 1.0) > 1e-9:
        raise ValueError(f"model step {dt} s does not divide the sample period {1.0 / rate_hz} s")
    return n


def _setter(kind: str, name: str, attr: str | None = None):
    from mujoco import sysid

    if kind == "kp":
        return lambda s, p: sysid.apply_pgain(s, name, p.value[0])
    if kind == "kd":
        return lambda s, p: sysid.apply_dgain(s, name, p.value[0])
    if kind == "effort":
        return lambda s, p: s.actuator(name).forcerange.__setitem__(slice(0, 2), [-p.value[0], p.value[0]])
    if kind == "delay":
        return lambda s, p: setattr(s.actuator(name), "delay", float(p.value[0]))
    if attr == "damping":  # the spec's damping is a polynomial in the speed; its first term is the viscous one
        return lambda s, p: s.joint(name).damping.__setitem__(0, float(p.value[0]))
    return lambda s, p: setattr(s.joint(name), attr, float(p.value[0]))


def peer_parameters(spec, robot, fields=(*JOINT_FIELDS, "bodies")):
    """``mujoco.sysid.ParameterDict`` of ``fields`` (per-joint fields of :data:`JOINT_FIELDS`, ``"bodies"``).

    Bounds: kp, kd and armature 0.2-5x the file's value; damping 0 to 2 kd; friction loss 0 to half the effort
    limit; effort limit 2-100 % of the file's (joints without a limit are left unlimited); delay one model step
    to :data:`MAX_DELAY` (MuJoCo's delayed control is the same for every delay in (0, dt], so a start there has a
    zero delay gradient and the peer never moves it; from one step up the control is interpolated: continuous);
    link inertia: ``body_inertia_param``'s defaults (mass 0.1-10x, principal
    stretch 0.5-2x, shear ±0.5, centre of mass ±0.5 m)."""
    from mujoco import sysid

    model = spec.compile()
    dt = model.opt.timestep
    params = sysid.ParameterDict()
    attr = {"armature": "armature", "damping": "damping", "friction": "frictionloss"}
    for i, j in enumerate(robot.joint_names):
        kp, kd, effort = float(robot.kp[i]), float(robot.kd[i]), float(robot.effort[i])
        box = {"kp": (kp, 0.2 * kp, 5 * kp), "kd": (kd, 0.2 * kd, 5 * kd),
               "armature": (robot.armature[i], 0.2 * robot.armature[i], 5 * robot.armature[i]),
               "damping": (robot.damping[i], 0.0, 2 * kd),
               "friction": (robot.friction[i], 0.0, 0.5 * effort if np.isfinite(effort) else 10.0),
               "effort": (effort, 0.02 * effort, effort), "delay": (dt, dt, MAX_DELAY)}
        for f in JOINT_FIELDS:
            if f not in fields or (f == "effort" and not np.isfinite(effort)):
                continue
            nominal, lo, hi = (float(v) for v in box[f])
            params.add(sysid.Parameter(f"{j}_{f}", nominal, lo, hi, modifier=_setter(f, j, attr.get(f))))
    if "bodies" in fields:
        for b in moving_bodies(model):
            params.add(sysid.body_inertia_param(spec, model, b, inertia_type=sysid.InertiaType.Pseudo,
                                                modifier=_pseudo_inertia(b)))
    params.move_off_bounds()
    return params


def _pseudo_inertia(body: str):
    """The peer's own pseudo-inertia writer (``apply_body_inertia``), then the inertial frame's orientation set to
    the identity: the writer leaves ``iquat`` NaN beside ``fullinertia``, which MuJoCo 3.17's compiler rejects
    ("mass and inertia of moving bodies must be larger than mjMINVAL"); with a defined ``iquat`` it takes the
    full inertia (checked by a round trip in ``tests/integration/test_peer_sysid.py``)."""
    from mujoco import sysid

    def modifier(spec, param):
        sysid.apply_body_inertia(spec, body, param)
        spec.body(body).iquat = [1.0, 0.0, 0.0, 0.0]

    return modifier


def spec_joints(model) -> list[str]:
    """Joint names in MuJoCo's order."""
    return [model.joint(j).name for j in range(model.njnt)]


def moving_bodies(model) -> list[str]:
    """Names of the bodies that move (not welded to the world)."""
    return [model.body(b).name for b in range(1, model.nbody) if model.body_weldid[b] != 0]


def initial_state(model, q, qd, history) -> np.ndarray:
    """``mjSTATE_FULLPHYSICS`` at time 0: joint state ``q``, ``qd`` (n,), each actuator's control history set to
    ``history`` (nsample, n), the commands of the model steps before (oldest first)."""
    import mujoco

    d = mujoco.MjData(model)
    d.qpos[:], d.qvel[:] = q, qd
    for i in range(model.nu):
        mujoco.mj_initCtrlHistory(model, d, i, None, np.ascontiguousarray(history[:, i:i + 1]))
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS.value
    state = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, d, state, spec)
    return state


def command_history(q_cmd: np.ndarray, start: int, nsample: int = NSAMPLE, n_sub: int = 1) -> np.ndarray:
    """The commands of the ``nsample`` model steps before sample ``start`` (oldest first), each sample's command held
    for its ``n_sub`` model steps; before sample 0 the first command. Shape (nsample, n)."""
    steps = np.arange(start * n_sub - nsample, start * n_sub)
    return q_cmd[np.clip(steps // n_sub, 0, None)]


def _history(model, q_cmd, start: int, n_sub: int) -> np.ndarray:
    return command_history(q_cmd, start, int(model.actuator_history[0, 0]) if model.nu else 0, n_sub)


def tiles(length: int, horizon: int | None) -> list[tuple[int, int]]:
    """``(start, stop)`` sample ranges of consecutive windows of ``horizon`` samples covering ``range(length)`` end to
    end, each sample in exactly one (the last window shorter when ``horizon`` does not divide ``length``; a tail of a
    single sample, which carries no residual, joins the window before). ``None``: one window."""
    if horizon is None or horizon >= length:
        return [(0, length)]
    starts = list(range(0, length, horizon))
    if length - starts[-1] < 2 and len(starts) > 1:
        starts.pop()
    return [(s, e) for s, e in zip(starts, starts[1:] + [length])]


def _sequence(model, t, s: int, e: int, rate_hz: float, n_sub: int, observed):
    """One sequence: samples ``s:e`` of trajectory ``t`` from its recorded state at ``s``, the controls at the model
    step (each command held ``n_sub`` steps)."""
    from mujoco import sysid

    h = e - s
    state = initial_state(model, t.q[s], t.qd[s], _history(model, t.q_cmd, s, n_sub))
    ctrl_times = np.arange(h * n_sub) * model.opt.timestep
    control = sysid.TimeSeries.from_control_names(ctrl_times, np.repeat(t.q_cmd[s:e], n_sub, axis=0), model)
    sensors = sysid.TimeSeries.from_names(np.arange(h) / rate_hz, np.hstack([t.q[s:e], t.qd[s:e]]), model,
                                          names=observed)
    return f"{t.name}@{s}", state, control, sensors


def _observed(model):
    from mujoco import sysid

    return [(f"{j}_qpos", sysid.SignalType.MjStateQPos) for j in spec_joints(model)] + \
        [(f"{j}_qvel", sysid.SignalType.MjStateQVel) for j in spec_joints(model)]


def tiled_sequences(spec, trajectories, rate_hz: float, horizon: int | None):
    """``mujoco.sysid.ModelSequences`` of the training ``trajectories`` cut into :func:`tiles` of ``horizon``
    samples, each from its recorded start state, at the spec's model step. The peer compares a window's samples
    after its first (the start state) with the rollout resampled at their times."""
    from mujoco import sysid

    model = spec.compile()
    n_sub = substeps(rate_hz, model.opt.timestep)
    observed = _observed(model)
    seqs = [_sequence(model, t, s, e, rate_hz, n_sub, observed)
            for t in trajectories for s, e in tiles(len(t.q), horizon)]
    names, states, controls, sensors = (list(c) for c in zip(*seqs))
    return sysid.ModelSequences("robot", spec, names, states, controls, sensors, allow_missing_sensors=True)


def sequences(spec, trajectories, rate_hz: float, horizon: int | None = None, chunks: int = 1):
    """``mujoco.sysid.ModelSequences`` of the training ``trajectories``: ``chunks`` evenly spaced windows of
    ``horizon`` samples per trajectory (``None``: each whole trajectory), each from its recorded start state."""
    from mujoco import sysid

    model = spec.compile()
    n_sub = substeps(rate_hz, model.opt.timestep)
    observed = _observed(model)
    seqs = []
    for t in trajectories:
        h = len(t.q) if horizon is None else min(horizon, len(t.q))
        starts = np.linspace(0, len(t.q) - h, chunks).round().astype(int) if horizon is not None else [0]
        seqs += [_sequence(model, t, int(s), int(s) + h, rate_hz, n_sub, observed) for s in starts]
    names, states, controls, sensors = (list(c) for c in zip(*seqs))
    return sysid.ModelSequences("robot", spec, names, states, controls, sensors, allow_missing_sensors=True)


@dataclass
class Replays:
    """Whole-trajectory replays in the form :func:`wresdyn.evaluation.open_loop.metrics` reads."""

    q: list
    qd: list
    diverged_at: list


def replay(model, trajectories, threads: int = 2, rate_hz: float | None = None) -> Replays:
    """Replay each whole trajectory open loop in MuJoCo (``mujoco.rollout``) from its first recorded state, command
    k held during sample k (its model steps; ``rate_hz`` the recording rate, default one step a sample). A replay
    that turns non-finite holds its last finite state from there (as the project's evaluation does)."""
    import mujoco
    import mujoco.rollout as mj_rollout

    trajectories = list(trajectories)
    out = Replays([], [], [])
    datas = [mujoco.MjData(model) for _ in range(threads)]
    n = model.nq
    n_sub = 1 if rate_hz is None else substeps(rate_hz, model.opt.timestep)
    for t in trajectories:  # one call each: lengths may differ
        s0 = initial_state(model, t.q[0], t.qd[0], _history(model, t.q_cmd, 0, n_sub))
        state, _ = mj_rollout.rollout(model, datas, s0[None], np.repeat(t.q_cmd[:-1], n_sub, axis=0)[None])
        state = state[0, n_sub - 1::n_sub]  # the state at each following sample
        q = np.vstack([t.q[:1], state[:, 1:1 + n]])
        qd = np.vstack([t.qd[:1], state[:, 1 + n:1 + 2 * n]])
        bad = ~(np.isfinite(q).all(1) & np.isfinite(qd).all(1))
        at = int(np.argmax(bad)) if bad.any() else -1
        if at >= 0:
            q[at:], qd[at:] = q[at - 1], 0.0
        out.q.append(q)
        out.qd.append(qd)
        out.diverged_at.append(at)
    return out


def with_params(spec, params):
    """``spec`` compiled with every joint field of ``params`` (a :class:`~wresdyn.robot.physical.PhysicalParams`,
    e.g. the real robot's truth) written into it and its link inertias written into the compiled model's fields, as
    the real robot writes its own (a perturbed inertia may break the triangle inequality the compiler enforces):
    the best the peer's model class can do."""
    from scipy.spatial.transform import Rotation

    for i, j in enumerate(params.joint_names):
        a, jt = spec.actuator(j), spec.joint(j)
        a.gainprm[0], a.biasprm[1], a.biasprm[2] = params.kp[i], -params.kp[i], -params.kd[i]
        if np.isfinite(params.effort[i]):
            a.forcerange = [-params.effort[i], params.effort[i]]
        a.delay = float(params.delay[i])
        jt.armature, jt.frictionloss = float(params.armature[i]), float(params.friction[i])
        jt.damping[0] = float(params.damping[i])
    model = spec.compile()
    for b, m in enumerate(params.body_mass):
        if m <= 0:
            continue
        w, v = np.linalg.eigh(0.5 * (params.body_inertia[b] + params.body_inertia[b].T))
        if np.linalg.det(v) < 0:
            v[:, 0] = -v[:, 0]
        model.body_mass[b + 1], model.body_ipos[b + 1], model.body_inertia[b + 1] = m, params.body_com[b], w
        model.body_iquat[b + 1] = Rotation.from_matrix(v).as_quat(scalar_first=True)
    return model


def physical_params(model, robot):
    """The compiled peer model's parameters as :class:`~wresdyn.robot.physical.PhysicalParams` (inertias rotated
    from MuJoCo's principal frame into the body frame, as :meth:`~wresdyn.data.real_robot.RealRobot.physics`)."""
    from scipy.spatial.transform import Rotation

    from wresdyn.robot.physical import PhysicalParams

    n = robot.n_dof
    rot = Rotation.from_quat(model.body_iquat[1:], scalar_first=True).as_matrix()
    inertia = rot @ (model.body_inertia[1:, :, None] * np.eye(3)) @ rot.transpose(0, 2, 1)
    effort = np.where(np.isfinite(robot.effort), model.actuator_forcerange[:n, 1], np.inf)
    return PhysicalParams(list(robot.joint_names), list(robot.body_names), model.actuator_gainprm[:n, 0].copy(),
                          -model.actuator_biasprm[:n, 2].copy(), model.dof_armature[:n].copy(),
                          model.dof_damping[:n].copy(), model.dof_frictionloss[:n].copy(), effort,
                          model.actuator_delay[:n].copy(), model.body_mass[1:].copy(), model.body_ipos[1:].copy(),
                          inertia)


def cached_build(size: int):
    """A ``build_model`` for ``build_residual_fn`` (the peer's documented hook; its default is
    ``apply_param_modifiers``) that keeps the last ``size`` compiled models by parameter vector. The peer's
    ``residual`` calls ``model_residual`` once per sequence, and each call compiles a model for every column of the
    finite-difference batch: without the cache one Jacobian compiles (parameters + 1) x sequences models, each
    compiling the spec once more per link in the pseudo-inertia writer (33 ms for this humanoid)."""
    from mujoco import sysid

    cache = {}

    def build(params, spec):
        key = params.as_vector().tobytes()
        if key not in cache:
            if len(cache) >= size:
                cache.clear()
            cache[key] = sysid.apply_param_modifiers(params, spec)
        return cache[key]

    return build


class _Budget(Exception):
    """The wall-clock budget ran out (raised from the optimiser's iteration callback)."""


@dataclass
class PeerRun:
    """One ``mujoco.sysid.optimize`` run: every single (not finite-difference) residual evaluation, in order."""

    spec: object
    """The peer's ``MjSpec`` (its modifiers write into it)."""
    params: object
    """The ``ParameterDict`` (its values: the last evaluation's)."""
    evaluations: list
    """``(seconds since the start, x, cost ½|r|²)`` of each single residual evaluation."""
    iterations: int
    """Gauss-Newton iterations completed."""
    stopped: str
    """Why it stopped: ``"converged"`` (the optimiser's own criteria or ``max_iters``) or ``"budget"``."""

    def best(self):
        """``(seconds, x, cost)`` of the lowest-cost evaluation: what the peer returns."""
        return min(self.evaluations, key=lambda e: e[2])

    def model(self, x):
        """The compiled model at ``x``."""
        from mujoco import sysid

        self.params.update_from_vector(np.asarray(x).ravel())
        return sysid.apply_param_modifiers(self.params, self.spec)


def identify_peer(robot, trajectories, rate_hz: float, fields=(*JOINT_FIELDS, "bodies"), horizon: int | None = 250,
                  chunks: int = 2, max_iters: int = 200, budget_s: float | None = None, threads: int = 2,
                  x_scale="jac", log=print) -> PeerRun:
    """Run ``mujoco.sysid.optimize`` (the ``"mujoco"`` backend: projected Gauss-Newton, batched finite-difference
    Jacobians) on ``trajectories`` (see :func:`sequences`) until its own termination, ``max_iters`` or the
    wall-clock ``budget_s`` (checked after each iteration). ``x_scale="jac"``: the column-norm scaling the peer's
    conditioning check advises; ``threads``: the peer's ``n_threads`` (MjData scratch objects of the rollout)."""
    import time

    from mujoco import sysid

    t0 = time.perf_counter()
    spec = peer_spec(robot, rate_hz)
    params = peer_parameters(spec, robot, fields)
    ms = sequences(spec, trajectories, rate_hz, horizon, chunks)
    residual_fn = sysid.build_residual_fn(models_sequences=[ms], n_threads=threads,
                                           build_model=cached_build(2 * (params.size + 1)))
    evaluations, iters = [], [0]

    def timed(x, p, **kw):
        out = residual_fn(x, p, **kw)
        if x.ndim == 1 or x.shape[1] == 1:
            r = np.concatenate(out[0]).ravel()
            evaluations.append((time.perf_counter() - t0, np.array(x, dtype=np.float64).ravel(), 0.5 * float(r @ r)))
        return out

    def on_iteration(trace):
        iters[0] = len(trace)
        # the "mujoco" backend keeps every iteration's Jacobian and residual in its trace (optimize() runs it at
        # full verbosity); only the last is read, so the earlier ones are dropped
        if len(trace) > 1:
            trace[-2] = dataclasses.replace(trace[-2], jacobian=None, residual=None)
        e = min(evaluations, key=lambda e: e[2])
        log(f"peer  iteration {len(trace):3d}  cost {trace[-1].objective:.4e}  best {e[2]:.4e}  "
            f"{time.perf_counter() - t0:.0f}s")
        if budget_s is not None and time.perf_counter() - t0 > budget_s:
            raise _Budget

    log(f"peer: {params.size} parameters, {len(ms.measured_rollout)} sequences, "
        f"{sum(len(s.sensordata) for s in ms.measured_rollout)} samples; setup {time.perf_counter() - t0:.1f}s")
    stopped = "converged"
    try:
        sysid.optimize(initial_params=params, residual_fn=timed, optimizer="mujoco", verbose=False,
                       max_iters=max_iters, x_scale=x_scale, iter_callback=on_iteration)
    except _Budget:
        stopped = "budget"
    return PeerRun(spec, params, evaluations, iters[0], stopped)


SPLITS = ("validation", "heldout", "ood")
"""The splits every fight scores, after selection on validation."""


def param_errors(ident, truth, train) -> dict:
    """Identifiable (joint, field) pairs within 10 % of the truth, median |ratio − 1| per field, and the links'
    median relative mass error and centre-of-mass error [m]."""
    from wresdyn.evaluation.identification import excitation_coverage, identification_table

    rows = identification_table(ident, truth, excitation_coverage(train, truth))
    counted = [r for r in rows if r["identifiable"] and np.isfinite(r["ratio"])]
    out = {"within_10pct": sum(abs(r["ratio"] - 1) <= 0.1 for r in counted), "identifiable": len(counted)}
    for f in JOINT_FIELDS:
        rs = [abs(r["ratio"] - 1) for r in counted if r["field"] == f]
        out[f"median_err_{f}"] = float(np.median(rs)) if rs else float("nan")
    moving = truth.body_mass > 0
    moving[0] = False  # the stand holds the root
    out["median_err_mass"] = float(np.median(np.abs(ident.body_mass[moving] / truth.body_mass[moving] - 1)))
    out["median_err_com_m"] = float(np.median(np.linalg.norm(ident.body_com[moving] - truth.body_com[moving], axis=1)))
    return out
