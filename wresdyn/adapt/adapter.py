"""Online identification: keep the identified physics true while the robot works.

An :class:`Adapter` starts from an offline calibration (``physics.json`` of ``wresdyn identify`` or a hybrid ``wresdyn
fit``), consumes the robot's stream of samples (t, q, q̇, q_cmd) and keeps the last :attr:`AdaptConfig.window`
seconds. Every :attr:`AdaptConfig.update_every` seconds of robot time it runs a bounded number of identification
steps, the offline loss of :mod:`wresdyn.identify.sysid` (multiple shooting on windows cut from the buffer, through the
differentiable solver, in the physically consistent coordinates of :class:`~wresdyn.sim.physics.PhysicsModel`)

    L = mean_k [ w_q |q_k − q_r,k|² + w_qd |q̇_k − q̇_r,k|² ] + w_prior |u − u_warm|²,

on the window without its latest :attr:`AdaptConfig.holdout` seconds. The prior pulls toward the warm start, and a
joint the training part does not move (RMS velocity under :attr:`AdaptConfig.excited_min`) keeps its joint fields:
what the recent data do not excite stays as the calibration left it. The candidate wins only if the whole
held-back segment, replayed open loop from its first recorded state, is closer to the recording than with the current
model by :attr:`AdaptConfig.min_gain`; with :attr:`AdaptConfig.confirm` a winner becomes the model only if it wins
again on the next update's held-back segment, which it was not fitted on (to leave the warm start, on
:attr:`AdaptConfig.confirm_leave` of them in a row); otherwise the coordinates go back to the current model's.
With :attr:`AdaptConfig.fallback` the model returns to the warm start where that is no worse on the held-back
segment. Accepted updates are published as ``physics.json``-compatible files with their robot time
(:meth:`Adapter.publish`) and, with an export folder, rewrite the exported calibrated robot.

A jump in time of more than 1.5 sample periods starts a new segment: windows never span one, and the held-back part
is the end of the latest segment.
"""

import json
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch

from ..errors import WresdynError
from ..export.usd import check_usd_robot, write_export
from ..identify.sysid import physics_window_loss
from ..learn.adam import Adam
from ..robot.physical import PhysicalParams
from ..sim import Simulator, TrajectoryBank, rollout
from ..sim.fused import can_fuse, fused_rollout
from ..sim.physics import PhysicsModel
from .config import AdaptConfig
from .adapter_update import Update
from .detect import ChangeDetector, command_rate, search_effort

__all__ = ["Adapter", "StreamError", "Update"]

_JOINT_PARAMS = ("kp", "kd", "armature", "damping", "friction", "effort")
"""Joint fields whose coordinates an unexcited joint keeps."""


class StreamError(WresdynError):
    """A sample the adapter cannot take (wrong size, not finite, time not increasing); one line."""


class Adapter:
    """Online identifier warm-started from ``start`` (module docstring).

    Args:
        robot: The robot (the simulator side; fixed base).
        start: The warm start (an offline calibration); also where the prior pulls.
        rate_hz: Sample rate of the stream [Hz].
        cfg: Settings.
        publish: Folder the accepted updates are written to (:meth:`publish`); ``None``: not written.
        export: Export folder of the calibrated robot (:func:`wresdyn.export.usd.write_export`, as ``wresdyn
            export --physics-only`` writes it), written with the warm start here and rewritten with each published
            update; ``None``: none. An MJCF or URDF robot is converted at each write.
    """

    def __init__(self, robot, start: PhysicalParams, rate_hz: float, cfg: AdaptConfig = AdaptConfig(),
                 publish: str | Path | None = None, export: str | Path | None = None) -> None:
        start.check(robot)
        if export is not None:
            check_usd_robot(robot)
        self.robot, self.start, self.cfg, self.rate_hz = robot, start, cfg, float(rate_hz)
        self.dt = 1.0 / self.rate_hz
        if cfg.torch_threads is not None:
            torch.set_num_threads(cfg.torch_threads)
        torch.manual_seed(cfg.seed)
        self.rng = np.random.default_rng(cfg.seed)
        n = robot.n_dof
        self.model = PhysicsModel(robot, start, fit=cfg.fit, dt=self.dt)
        m = self.model
        groups = [[m.u_kp, m.u_kd, m.u_armature], [m.u_damping, m.u_friction, m.u_effort],
                  [m.u_body_logdiag, m.u_body_off]]
        self.optim = Adam([{"params": [p for p in g if p.requires_grad], "lr": cfg.lr * f}
                           for g, f in zip(groups, cfg.lr_scale) if any(p.requires_grad for p in g)], lr=cfg.lr)
        self._lrs = [g["lr"] for g in self.optim.param_groups]
        self.detector = ChangeDetector(cfg.detect_factor, round(cfg.detect_history / cfg.update_every),
                                       cfg.track_for, cfg.detect_confirm, cfg.effort_overall,
                                       cfg.detect_norm == "command") if cfg.detect else None
        """The change detector (:attr:`AdaptConfig.detect`), ``None`` without it."""
        self.sim_grid = None  # the effort grid's replays, made on first use
        self.physics = start
        """The current model (the last accepted update, or the warm start)."""
        self._kept = _copy(m.state_dict())
        self._start_state = _copy(self._kept)
        self._pending = None  # (physics, coordinates, held-back parts won since) of a winner to be confirmed
        self.delay = torch.as_tensor(start.delay / self.dt, dtype=torch.float32)
        self.sim = Simulator(robot, cfg.windows, self.dt, solver=cfg.solver, device=cfg.device, requires_grad=True,
                             param_grads=True)
        self.device = self.sim.device
        self.n_holdout = int(round(cfg.holdout * self.rate_hz))
        self.n_one = max(1, (self.n_holdout - 1) // cfg.one_step_every)
        # param_grads: parameters are read live from the model arrays, so a new model does not recompile the solver
        self.sim_val = Simulator(robot, 4, self.dt, solver=cfg.solver, device=cfg.device, param_grads=True)
        self.sim_one = Simulator(robot, 2 * self.n_one, self.dt, solver=cfg.solver, device=cfg.device,
                                 param_grads=True)
        self.sim_one.set_physics(start, worlds=slice(0, self.n_one))
        self.sim_val.set_physics(start, worlds=slice(0, 1))
        cap = int(np.ceil(cfg.window * self.rate_hz)) + 1
        self._cap = cap
        self._t = np.empty(2 * cap)
        self._x = np.empty((2 * cap, 3, n))  # q [rad], q̇ [rad/s], q_cmd [rad] of each sample
        self._seg = np.empty(2 * cap, dtype=np.int64)
        self._len, self._segment, self._next = 0, 0, None
        self.publish_dir = None if publish is None else Path(publish)
        if self.publish_dir is not None:
            self.publish_dir.mkdir(parents=True, exist_ok=True)
        self.export_dir = None if export is None else Path(export)
        if self.export_dir is not None:
            self._export(start, {"t": None})
        self.updates: list[Update] = []
        self.compute = 0.0
        """Wall-clock time spent in updates so far [s]."""

    # -------------------------------------------------------------------------------------------- the stream
    def push(self, t, q, qd, q_cmd) -> list[Update]:
        """Take samples: ``t`` [s] a scalar or (T,), strictly increasing and after every earlier sample; ``q``
        [rad], ``qd`` [rad/s], ``q_cmd`` [rad], each (n,) or (T, n). Runs the updates that fall due on the way and
        returns them."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        x = [np.asarray(a, dtype=np.float64).reshape(len(t), -1) if np.size(a) == len(t) * self.robot.n_dof
             else None for a in (q, qd, q_cmd)]
        if any(a is None for a in x) or t.ndim != 1:
            raise StreamError(f"a sample needs t and {self.robot.n_dof} values each of q, qd and q_cmd "
                              f"(the robot's joints)")
        if not (np.isfinite(t).all() and all(np.isfinite(a).all() for a in x)):
            raise StreamError(f"a sample at t = {t[0]:.6g} s is not finite")
        prev = self._t[self._len - 1] if self._len else -np.inf
        steps = np.diff(np.concatenate([[prev], t]))
        if (steps <= 0).any():
            k = int(np.flatnonzero(steps <= 0)[0])
            before = prev if k == 0 else t[k - 1]
            raise StreamError(f"time does not increase at t = {t[k]:.6g} s (after {before:.6g} s)")
        if (steps < 0.5 * self.dt).any():
            k = int(np.flatnonzero(steps < 0.5 * self.dt)[0])
            raise StreamError(f"a time step of {steps[k]:.6g} s at t = {t[k]:.6g} s is under half the sample period "
                              f"{self.dt:.6g} s: the stream is not at {self.rate_hz:g} Hz")
        out = []
        xs = np.stack(x, 1)
        for i in range(len(t)):
            self._append(t[i], xs[i], steps[i] > 1.5 * self.dt)
            if self._next is None:
                self._next = t[i] + self.cfg.update_every
            elif t[i] >= self._next - 1e-9:
                self._next += self.cfg.update_every * max(1, np.floor((t[i] - self._next) / self.cfg.update_every) + 1)
                u = self.update()
                if u is not None:
                    out.append(u)
        return out

    def _append(self, t: float, x: np.ndarray, jump: bool) -> None:
        if jump and self._len:
            self._segment += 1
        if self._len == len(self._t):  # full: keep the latest window
            keep = self._cap
            for a in (self._t, self._x, self._seg):
                a[:keep] = a[self._len - keep:self._len]
            self._len = keep
        self._t[self._len], self._x[self._len], self._seg[self._len] = t, x, self._segment
        self._len += 1

    def _buffer(self):
        """The samples of the last :attr:`AdaptConfig.window` seconds: ``(t, x, seg)``."""
        t = self._t[:self._len]
        first = np.searchsorted(t, t[-1] - self.cfg.window, side="left")
        return t[first:], self._x[first:self._len], self._seg[first:self._len]

    # -------------------------------------------------------------------------------------------- an update
    def update(self) -> Update | None:
        """One update on the current buffer (normally called by :meth:`push`); ``None`` when the buffer holds too
        little yet (a held-back part of :attr:`AdaptConfig.holdout` and a training window of
        :attr:`AdaptConfig.horizon` steps)."""
        t0 = time.perf_counter()
        t, x, seg = self._buffer()
        latest = seg == seg[-1]
        if latest.sum() < self.n_holdout + 1:
            return None
        hold = np.flatnonzero(latest)[-(self.n_holdout + 1):]
        before = seg[:hold[0] + 1]  # the training part ends at the held-back part's start state
        det = self.detector
        track = det is not None and det.tracking(float(t[-1]))
        # after a joint's own held-back error jumped, the effort grid picks on the held-back part that showed it
        s0, jumped = hold[0] - self.n_holdout, None if det is None else det.joint_ratios
        select = TrajectoryBank([_traj(x[s0:hold[0] + 1])], self.device, self.delay.to(self.device)) if (
            jumped is not None and (jumped > self.cfg.detect_factor).any() and s0 >= 0
            and seg[s0] == seg[hold[0]]) else None
        train = self._train(x[:hold[0] + 1], before, t[:hold[0] + 1] >= det.since if track else None)
        if not train:
            return None
        holdout = TrajectoryBank([_traj(x[hold])], self.device, self.delay.to(self.device))
        excited = np.sqrt(np.mean(np.concatenate([tr.qd for tr in train]) ** 2, 0)) >= self.cfg.excited_min
        loss = self._steps(train, excited, track)
        fitted_in_tracking = track
        cand = self.model.values() if np.isfinite(loss) else self.physics
        pending = self._pending
        ol, ol_joint = self._open_loop(holdout, cand, None if pending is None else pending[0])
        jump = 0.0
        if det is not None:
            _, jump, _ = det.observe(float(t[-1]), float(t[hold[0]]), ol[1], ol_joint, command_rate(x[hold, 2]))
            track = det.tracking(float(t[-1]))
        leaving = self.physics is self.start  # a winner now would take the model off the warm start
        unconfirmed = track and not self.cfg.track_confirm and (fitted_in_tracking or not self.cfg.detect_jump_confirm)
        confirm = self.cfg.confirm and (not unconfirmed or (leaving and not self.cfg.track_leave))
        # the reference to beat: the current model, or the warm start where that is no worse (the model then goes
        # back to it unless something beats it): without drift, updates that only fit one held-back second's noise
        # do not pile up
        revert = self.cfg.fallback and not leaving and ol[0] <= ol[1]
        ref = ol[0] if revert else ol[1]
        gain = 1.0 - self.cfg.min_gain
        wins = bool(np.isfinite(loss) and ol[2] < gain * ref)
        again = False
        if confirm:  # publish the last update's winner if it wins again here, on data it was not fitted on
            again = pending is not None and ol[3] < gain * ref
            accepted = again and pending[2] + 1 >= (self.cfg.confirm_leave if leaving else 1)
            new = pending if accepted else None
            after = ol[3] if accepted else ref
            wins = wins and ol[2] < gain * after
        else:
            accepted = wins
            new = (cand, self.model.state_dict()) if accepted else None
            after = ol[2] if accepted else ref
        if new is not None:
            self.physics = new[0]
            self._kept = _copy(new[1])
        elif revert:
            self.physics = self.start
            self._kept = _copy(self._start_state)
        if again and not accepted:  # it waits for more wins (confirm_leave); the training goes on from it
            self._pending = (*pending[:2], pending[2] + 1)
            self.model.load_state_dict(pending[1])
        else:
            self._pending = (cand, _copy(self.model.state_dict()), 0) if confirm and wins else None
        challenger = self.cfg.persist > 0 and new is None and np.isfinite(loss) and ol[2] <= self.cfg.persist * after
        if self._pending is None and not challenger:
            self.model.load_state_dict(self._kept)
        tried, set_ = 0, ""
        if select is not None and self.cfg.effort_grid and "effort" in self.cfg.fit:
            tried, set_, err = self._effort_grid(select, holdout, jumped, after)
            if set_:
                accepted, after = True, err
        one = self._one_step(holdout)
        u = Update(float(t[-1]), accepted, after, ol[1], ol[2], ol[0], one[1], one[0], float(loss),
                   int(excited.sum()), 0.0, self.physics, reverted=revert and not accepted,
                   pending=self._pending is not None, jump=jump, tracking=track, effort_tried=tried,
                   effort_set=set_)
        u.compute = time.perf_counter() - t0
        self.compute += u.compute
        self.updates.append(u)
        if accepted or u.reverted:
            self.publish(u)
        return u

    def _train(self, x: np.ndarray, seg: np.ndarray, after: np.ndarray | None) -> list:
        """The segments (``seg`` (T,)) of the samples ``x`` (T, 3, n) longer than a window; with ``after`` (T,) bool,
        those of the samples after the jump where they hold a window, else all."""
        if after is not None:
            picked = self._train(x, seg, None) if not after.any() else self._train(x[after], seg[after], None)
            return picked or self._train(x, seg, None)
        train = [_traj(x[seg == s]) for s in np.unique(seg)]
        return [tr for tr in train if len(tr.q) > self.cfg.horizon]

    def _steps(self, train, excited: np.ndarray, track: bool = False) -> float:
        """``cfg.iterations`` Adam steps on windows of ``train`` (in the tracking mode ``cfg.track_iterations`` at
        ``cfg.track_lr`` times the rate); joints not ``excited`` keep their joint fields. Returns the last loss
        (``nan`` if the simulation diverged)."""
        cfg, model = self.cfg, self.model
        bank = TrajectoryBank(train, self.device, self.delay.to(self.device))
        frozen = torch.as_tensor(~excited)
        last = torch.tensor(float("nan"))
        for g, lr in zip(self.optim.param_groups, self._lrs):
            g["lr"] = lr * (cfg.track_lr if track else 1.0)
        for _ in range(cfg.track_iterations if track else cfg.iterations):
            held = {f: getattr(model, f"u_{f}").detach().clone() for f in _JOINT_PARAMS}
            window = bank.sample(self.rng, cfg.windows, cfg.horizon)
            value, _ = physics_window_loss(cfg, model, self.sim, window,
                                           fused=can_fuse(self.sim) and cfg.grad_truncation is None)
            value = value + cfg.w_prior * model.prior().to(value.device)
            if not torch.isfinite(value):
                return float("nan")
            self.optim.zero_grad()
            value.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
            self.optim.step()
            model.project()
            with torch.no_grad():
                for f, v in held.items():
                    u = getattr(model, f"u_{f}")
                    u.copy_(torch.where(frozen, v, u))
            last = value.detach()  # read once, after the steps: on a GPU each read waits for the device
        return float(last)

    def _open_loop(self, holdout: TrajectoryBank, candidate: PhysicalParams, pending: PhysicalParams | None
                   ) -> tuple[tuple[float, float, float, float], np.ndarray]:
        """Held-back open-loop error [rad] of the warm start, the current model, ``candidate`` and ``pending`` (the
        current model again where ``None``) on ``holdout`` (a bank of the held-back samples); and the current
        model's per joint, (n,) [rad]."""
        self.sim_val.set_physics(self.physics, worlds=slice(1, 2))
        self.sim_val.set_physics(candidate, worlds=slice(2, 3))
        self.sim_val.set_physics(self.physics if pending is None else pending, worlds=slice(3, 4))
        window = holdout.whole().repeat(4)
        with torch.no_grad():
            q = fused_rollout(self.sim_val, window)[0] if can_fuse(self.sim_val) else rollout(self.sim_val, window).q
        err = (q[:, 1:] - window.q[:, 1:]).abs()
        joint = err[1].mean(0).cpu().numpy().astype(np.float64)
        return tuple(float(e) for e in err.mean((1, 2)).cpu().numpy()), joint

    def _effort_grid(self, select: TrajectoryBank, holdout: TrajectoryBank, joint_jump: np.ndarray | None,
                     error: float) -> tuple[int, str, float]:
        """The effort grid (:func:`~wresdyn.adapt.detect.search_effort`) for the joints of ``joint_jump`` (n,) above
        the factor, picked on ``select`` (the last update's held-back part, where their errors jumped), kept on
        ``holdout`` against ``error`` [rad], the model's mean there: the winner becomes the model (its coordinates
        too). Returns (limits tried, ``joint=limit`` of the one kept or ``""``, the
        model's held-back error after)."""
        cfg = self.cfg
        if joint_jump is None:
            return 0, "", error
        if self.sim_grid is None:
            self.sim_grid = Simulator(self.robot, cfg.effort_joints * len(cfg.effort_grid) + 1, self.dt,
                                      solver=cfg.solver, device=cfg.device, param_grads=True)
        tried, won, after = search_effort(self.sim_grid, self.sim_val, select.whole(), holdout.whole(), self.physics,
                                          joint_jump, cfg, error, can_fuse(self.sim_grid))
        self.sim_val.set_physics(self.start, worlds=slice(0, 1))  # world 0 replays the warm start
        if won is None:
            return tried, "", error
        j, limit, self.physics = won
        self.model.load_state_dict(self._kept)
        with torch.no_grad():
            self.model.assign("effort", self.physics.effort)
        self._kept = _copy(self.model.state_dict())
        self._pending = None
        return tried, f"{self.robot.joint_names[j]}={limit:.4g}", after

    def _one_step(self, holdout: TrajectoryBank) -> tuple[float, float]:
        """One-step prediction error [rad] of the warm start and the current model on every
        :attr:`AdaptConfig.one_step_every`-th held-back sample, each step from its recorded state."""
        self.sim_one.set_physics(self.physics, worlds=slice(self.n_one, 2 * self.n_one))
        start = torch.arange(self.n_one, device=self.device) * self.cfg.one_step_every
        window = holdout.window(torch.zeros_like(start), start, 1).repeat(2)
        with torch.no_grad():
            run = rollout(self.sim_one, window)
        err = (run.q[:, 1] - window.q[:, 1]).abs().mean(-1).cpu().numpy()
        return float(err[:self.n_one].mean()), float(err[self.n_one:].mean())

    # -------------------------------------------------------------------------------------------- publishing
    def publish(self, update: Update) -> Path | None:
        """Write ``update``'s physics to the publish folder: ``physics_<t>.json`` (``t`` in ms) and ``physics.json``
        (the latest), each the :meth:`~wresdyn.robot.physical.PhysicalParams.save` format with ``t`` [s] and the
        held-back error added (:meth:`~wresdyn.robot.physical.PhysicalParams.load` reads them); and rewrite the
        export folder, if any. Returns the timestamped file."""
        if self.export_dir is not None:
            self._export(update.physics, {"t": update.t, "open_loop": update.open_loop})
        if self.publish_dir is None:
            return None
        data = {**update.physics.to_json(), "t": update.t, "open_loop": update.open_loop}
        text = json.dumps(data, indent=1)
        path = self.publish_dir / f"physics_{int(round(update.t * 1000)):09d}.json"
        for p in (path, self.publish_dir / "physics.json"):
            tmp = p.with_name(p.name + ".tmp")
            tmp.write_text(text)
            tmp.replace(p)
        return path

    def _export(self, physics: PhysicalParams, when: dict) -> None:
        write_export(self.export_dir, self.robot, physics, self.rate_hz, {"source": "wresdyn adapt", **when})


def _traj(x: np.ndarray):
    """A trajectory for :class:`~wresdyn.sim.bank.TrajectoryBank` from buffered samples (T, 3, n); q̈ is not read
    without a residual policy."""
    q = np.ascontiguousarray(x[:, 0])
    return SimpleNamespace(q=q, qd=np.ascontiguousarray(x[:, 1]), qdd=np.zeros_like(q),
                           q_cmd=np.ascontiguousarray(x[:, 2]))


def _copy(state: dict) -> dict:
    """A detached copy of a module's state dict (the coordinates an update may go back to)."""
    return {k: v.clone() for k, v in state.items()}
