"""The one simulation layer: N Newton worlds of one robot under PD drives plus a residual, read and written as torch.

Every consumer steps the robot through :class:`Simulator`: data collection's PD-only replay and evaluation
(through :func:`wresdyn.sim.rollout.rollout`), the PPO environment (:class:`wresdyn.ppo.replay_env.ReplayEnv`)
and the gradient fit (``rollout(..., grad=True)``). It owns the Newton model, the solver
(:func:`wresdyn.sim.solvers.make_solver`), the states and the control, the torch views of them, the device
stream, CUDA graphs of the solver steps and, for gradients, one state per step so each step's ``wp.Tape`` stays valid.

- Fast path, :meth:`Simulator.step`: writes the PD target and joint torque into ``control``, advances
  ``substeps`` solver steps in place (on CUDA replayed from a captured graph on the simulator's own stream,
  ordered against torch's current stream).
- Differentiable path, :meth:`Simulator.step_diff`: the same step as a ``torch.autograd.Function``
  (:class:`~wresdyn.sim.tape_step.TapeStep`) whose backward runs the Warp tape, so gradients reach the previous
  state, the PD target and the torque. On CUDA its Warp work runs on torch's current stream when that is a stream
  of its own (the gradient fit's CUDA graph, :meth:`Simulator._tape_stream`), else on Warp's device stream.

Divergence (:class:`DivergenceLimits`, :meth:`Simulator.diverged`) is judged in one place: a non-finite state,
a runaway joint speed, a joint far past its limit, or (when a reference is given) far from the recording.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass

import numpy as np
import torch

from ..errors import SimulationDiverged
from ..robot.ground import base_index
from .devices import require_device, torch_stream_for_warp
from .physics import MODEL_ARRAYS, SERVO_ARRAYS, PhysicalParams
from .solvers import make_solver, resolve_solver
from .tape_step import TapeBuffers, TapeStep, tape_rows
from .world_physics import model_flags, model_values, refresh, write_world_physics

__all__ = ["DivergenceLimits", "Simulator", "SimulationDiverged"]


@dataclass(frozen=True)
class DivergenceLimits:
    """When a simulated world counts as diverged (it is then reset by a learner, frozen by evaluation)."""

    max_qd: float = 100.0
    """Runaway joint speed [rad/s or m/s]."""
    limit_margin: float = 0.5
    """Runaway distance beyond a joint limit [rad or m]."""
    max_error: float = math.inf
    """Runaway distance from the recording, max over joints [rad or m]; inf = not checked."""


def _torch_device(device: str | None) -> torch.device:
    import warp as wp

    return torch.device(str(wp.device_to_torch(wp.get_device(device))))


def _index(idx: np.ndarray, device) -> slice | torch.Tensor:
    """A slice where the indices are contiguous (a view, no gather), else an index tensor."""
    idx = np.asarray(idx, dtype=np.int64)
    if len(idx) and (np.diff(idx) == 1).all():
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return torch.as_tensor(idx, device=device)


class Simulator:
    """``num_worlds`` copies of a fixed- or floating-base robot in Newton, stepped under PD with a residual.

    Args:
        robot: The robot (:class:`wresdyn.robot.Robot`).
        num_worlds: Number of worlds (one robot each).
        dt: Sample period [s]: one :meth:`step` holds its target and torque for ``dt``.
        solver: Solver kind (:data:`wresdyn.sim.solvers.SOLVERS`).
        substeps: Solver steps per sample period.
        device: Warp device (``"cpu"``, ``"cuda:0"``).
        requires_grad: Build a differentiable model (for :meth:`step_diff`).
        param_grads: Gradients also reach the model's physical parameters (identification). The replay solver's
            kernels are the same either way (they read every parameter), so this only gates :meth:`set_physics`.
        graph: Replay the solver steps of :meth:`step` from a CUDA graph (default: on CUDA). Also the default of the
            attribute ``rollout_graph``: a rollout without gradients captured whole as one graph and replayed on later
            calls (:mod:`.rollout_graph`); ``sim.rollout_graph = False`` keeps that loop eager.
        ground: Stand the robots on a floor (:meth:`wresdyn.robot.Robot.build_model`); needs the ``mujoco``
            solver (``auto`` picks it), so no gradients.
        contact: :class:`~wresdyn.robot.ground.ContactSettings` of the floor (default ``ContactSettings()``).
        friction_kappa: Dry-friction law of the replay solver (:func:`~wresdyn.sim.solvers.make_solver`).
        solver_threads: CPU host threads the replay solver splits the worlds over (its ``threads``).
        refresh_graph: Replay mujoco_warp's refresh after :meth:`set_world_physics` from a CUDA graph (default: on
            CUDA; :mod:`wresdyn.sim.world_physics` gives the measured gain); the CPU has no graphs.

    Properties ``q``, ``qd`` are copies of the actuated joint positions [rad] and velocities [rad/s],
    shape (num_worlds, n_dof), float32 on :attr:`device`. A floating base adds ``base_pose`` and ``base_twist``
    (Newton's free-joint convention, :mod:`wresdyn.robot.ground`) and :meth:`set_full_state`.
    """

    def __init__(self, robot, num_worlds: int, dt: float, *, solver: str = "auto", substeps: int = 1,
                 device: str | None = "cpu", requires_grad: bool = False, param_grads: bool = False,
                 graph: bool | None = None, ground: bool = False, contact=None, friction_kappa=None,
                 solver_threads: int = 1, refresh_graph: bool | None = None) -> None:
        import warp as wp

        if num_worlds < 1 or substeps < 1 or not dt > 0:
            raise ValueError(f"need num_worlds >= 1, substeps >= 1 and dt > 0 (got {num_worlds}, {substeps}, {dt})")
        self.robot, self.num_worlds, self.dt, self.substeps = robot, int(num_worlds), float(dt), int(substeps)
        self.dt_sub = self.dt / self.substeps
        self.ground = bool(ground)
        self.solver_kind = resolve_solver(robot, self.dt_sub, solver, self.ground)
        if requires_grad and self.solver_kind == "mujoco":
            raise ValueError(f"{robot.source.name}: SolverMuJoCo is not differentiable; gradients need the replay "
                             "or featherstone solver (add armature so explicit PD is stable)"
                             + ("; a ground needs SolverMuJoCo" if self.ground else ""))
        if getattr(robot, "servo", None) is not None and self.solver_kind != "replay":
            raise ValueError(f"{robot.source.name}: servo drives (drive = \"servo\") run on the replay solver only, "
                             f"not {self.solver_kind}")
        self.requires_grad = bool(requires_grad)
        require_device(device)
        self.model = robot.build_model(self.num_worlds, device, requires_grad=self.requires_grad, ground=self.ground,
                                       contact=contact)
        self.solver = make_solver(self.model, robot, self.dt_sub, self.solver_kind, ground=self.ground,
                                  contact=contact, friction_kappa=friction_kappa, threads=solver_threads)
        if self.solver_kind == "replay":
            self.solver.friction_grad = False  # until set_physics hands it a friction that carries gradients
        self.device = _torch_device(device)
        self._cuda = self.device.type == "cuda"
        self.graph = self.rollout_graph = self._cuda if graph is None else bool(graph) and self._cuda
        self.states = [self.model.state(), self.model.state()]
        self.control = self.model.control()
        w = self.num_worlds
        self.nq, self.nqd = self.model.joint_coord_count // w, self.model.joint_dof_count // w
        """Joint coordinates and DoFs per world (a floating base adds 7 and 6)."""
        self._q = [wp.to_torch(s.joint_q, requires_grad=False).view(w, self.nq) for s in self.states]
        self._qd = [wp.to_torch(s.joint_qd, requires_grad=False).view(w, self.nqd) for s in self.states]
        self._target = wp.to_torch(self.control.joint_target_q, requires_grad=False).view(w, -1)
        self._force = wp.to_torch(self.control.joint_f, requires_grad=False).view(w, self.nqd)
        self.q_index = _index(robot.q_index, self.device)
        self.qd_index = _index(robot.qd_index, self.device)
        f32 = dict(dtype=torch.float32, device=self.device)
        self.lower = torch.as_tensor(robot.lower, **f32)
        self.upper = torch.as_tensor(robot.upper, **f32)
        self._cur, self._graphs, self._rollout_graphs = 0, {}, {}  # buffer index; solver and rollout_graph graphs
        self.refresh_graph, self._refresh_graphs = self._cuda and refresh_graph is not False, {}  # world_physics
        self._side = self._wp_side = None  # CUDA: the solver's stream (see _stream)
        self._wp_streams: dict[int, tuple] = {}  # torch stream handle -> (torch stream, Warp stream): _tape_stream
        self._tape_buffers, self._tape_rows = [], tape_rows(self.model.device)  # step_diff's, per step
        self._needs_fk = self.solver_kind != "replay"  # SolverReplay integrates joint coordinates only
        self.param_grads = bool(param_grads)
        self._physics: dict[str, torch.Tensor] = {}  # field -> tensor carrying gradients (set_physics)

    # ------------------------------------------------------------------------------------------------ physics
    def _model_view(self, field: str, grad: bool = False) -> torch.Tensor:
        """Torch view of a physical field's model array (or its gradient) per world: (W, n) for joint fields
        (DoFs of the actuated joints selected by the caller), (W, nb[, 3[, 3]]) for body fields."""
        import warp as wp

        a = getattr(self.model, MODEL_ARRAYS.get(field) or SERVO_ARRAYS[field])
        t = wp.to_torch(a.grad if grad else a, requires_grad=False)
        return t.view(self.num_worlds, -1, *t.shape[1:]) if field.startswith("body_") else t.view(self.num_worlds, -1)

    def set_physics(self, values, worlds: slice | None = None) -> None:
        """Write physical parameters into every world's model arrays (:mod:`wresdyn.sim.physics`).

        ``values``: a :class:`~wresdyn.sim.physics.PhysicalParams` or a dict of its fields as tensors
        (joint fields (n,), body fields (nb,), (nb, 3), (nb, 3, 3)); ``delay`` is ignored here (it belongs to
        the command path). Tensors that require grad, with ``param_grads``, receive gradients through
        :meth:`step_diff`. An infinite effort is written as 0 (Newton's "unlimited"). ``worlds``: only these
        worlds (e.g. a nominal baseline next to a calibrated model in one batch; no gradients then).
        """
        arrays = MODEL_ARRAYS if getattr(self.robot, "servo", None) is None else {**MODEL_ARRAYS, **SERVO_ARRAYS}
        if isinstance(values, PhysicalParams):
            values.check(self.robot)
            values = {f: torch.as_tensor(getattr(values, f)) for f in arrays}
        self._physics = {}
        w = slice(None) if worlds is None else worlds
        with torch.no_grad():
            for f, v in values.items():
                if f not in arrays:
                    continue
                v32 = model_values(f, v, self.device)
                view = self._model_view(f)
                if f.startswith("body_"):
                    view[w] = v32
                else:
                    view[w, self.qd_index] = v32
                if v.requires_grad and worlds is None:
                    if not (self.param_grads and self.requires_grad):
                        raise RuntimeError("gradients to physical parameters need Simulator(requires_grad=True, "
                                           "param_grads=True)")
                    self._physics[f] = v
        if self.solver_kind == "replay":
            if worlds is None:  # the friction solve of a frictionless world is only differentiated for its gradient
                self.solver.friction_grad = "friction" in self._physics
            return  # every parameter is read live from the arrays just written: nothing to recompile
        self._physics_changed()

    def set_world_physics(self, values: dict[str, torch.Tensor], ids=None) -> None:
        """Write different physical parameters into each world (no gradients): tensors with a leading world axis,
        joint fields (k, n), body fields (k, nb), (k, nb, 3), (k, nb, 3, 3), one row per world of ``ids`` (long (k,);
        ``None``: every world); other fields and worlds keep theirs. In place, the solver told only what changed, CUDA
        graphs kept (:mod:`wresdyn.sim.world_physics`): a redraw on reset, a finite-difference Jacobian."""
        refresh(self, model_flags(write_world_physics(self, values, ids)))

    def _physics_changed(self) -> None:
        """Tell a solver that caches model properties that they changed."""
        from newton import ModelFlags

        self.solver.notify_model_changed(ModelFlags.JOINT_DOF_PROPERTIES | ModelFlags.BODY_INERTIAL_PROPERTIES)
        for graphs in (self._graphs, self._refresh_graphs, self._rollout_graphs):
            graphs.clear()  # captured launches may hold recompiled kernels' predecessors

    # ------------------------------------------------------------------------------------------------ state
    @property
    def q(self) -> torch.Tensor:
        return self._q[self._cur][:, self.q_index].clone()

    @property
    def qd(self) -> torch.Tensor:
        return self._qd[self._cur][:, self.qd_index].clone()

    def set_state(self, ids, q: torch.Tensor, qd: torch.Tensor) -> None:
        """Overwrite the joint state of worlds ``ids`` (long (k,), a slice, or ``None`` for all) with q, qd (k, n)."""
        ids = slice(None) if ids is None else ids
        self._q[self._cur][ids, self.q_index] = q.to(torch.float32)
        self._qd[self._cur][ids, self.qd_index] = qd.to(torch.float32)
        self._refresh_fk()

    def set_state_where(self, mask: torch.Tensor, q: torch.Tensor, qd: torch.Tensor) -> None:
        """Overwrite the joint state of the worlds where ``mask`` (num_worlds,) bool with q, qd (num_worlds, n); the
        others keep theirs. Fixed shapes and no host sync: safe inside a CUDA graph."""
        m = mask[:, None]
        for state, index, x in ((self._q[self._cur], self.q_index, q), (self._qd[self._cur], self.qd_index, qd)):
            if isinstance(index, slice):  # a view: written in place by one kernel, not gathered, selected and copied
                torch.where(m, x.to(torch.float32), state[:, index], out=state[:, index])
            else:
                state[:, index] = torch.where(m, x.to(torch.float32), state[:, index])
        self._refresh_fk()

    def _refresh_fk(self) -> None:
        """Body poses from the joint state just written (solvers that read them; SolverReplay does not)."""
        if self._needs_fk:
            with self._stream():
                self._eval_fk(self.states[self._cur])

    def _base_slices(self) -> tuple[slice, slice]:
        """The free joint's 7 coordinates and 6 DoFs in a world's joint_q / joint_qd."""
        if self.robot.base != "floating":
            raise ValueError(f"{self.robot.source.name}: the base is fixed; load_robot(..., base='floating') for a "
                             "base pose")
        q0, qd0 = base_index(self.robot)
        return slice(q0, q0 + 7), slice(qd0, qd0 + 6)

    @property
    def base_pose(self) -> torch.Tensor:
        """Base pose per world, [x y z qx qy qz qw] (position [m], unit quaternion, world frame), shape
        (num_worlds, 7); a floating base only."""
        return self._q[self._cur][:, self._base_slices()[0]].clone()

    @property
    def base_twist(self) -> torch.Tensor:
        """Base velocity per world in world axes: centre of mass [m/s], angular [rad/s]; (num_worlds, 6); floating."""
        return self._qd[self._cur][:, self._base_slices()[1]].clone()

    def set_full_state(self, ids, base_pose: torch.Tensor, base_twist: torch.Tensor, q: torch.Tensor,
                       qd: torch.Tensor) -> None:
        """Overwrite the whole state of worlds ``ids`` (long (k,), a slice, or ``None`` for all): base pose (k, 7)
        and twist (k, 6) as :attr:`base_pose` / :attr:`base_twist` (the quaternion is normalised), joints q, q̇
        (k, n). A floating base only."""
        pose_index, twist_index = self._base_slices()
        ids = slice(None) if ids is None else ids
        pose = base_pose.to(self.device, torch.float32).clone()
        pose[..., 3:] = pose[..., 3:] / pose[..., 3:].norm(dim=-1, keepdim=True)
        self._q[self._cur][ids, pose_index] = pose
        self._qd[self._cur][ids, twist_index] = base_twist.to(self.device, torch.float32)
        self.set_state(ids, q, qd)

    def _eval_fk(self, state) -> None:
        import newton

        newton.eval_fk(self.model, state.joint_q, state.joint_qd, state)

    # ------------------------------------------------------------------------------------------------ stepping
    @contextlib.contextmanager
    def _stream(self):
        """Run Warp work on this simulator's own CUDA stream, ordered after and before torch's current stream.

        Torch wrote the control on its current stream and reads the state there afterwards; the solver runs on
        a side stream that waits for the first and is waited for by the second. A stream of its own, because
        CUDA graphs cannot be captured on torch's default (legacy) stream.
        """
        if not self._cuda:
            yield
            return
        import warp as wp

        side = self.side_stream()
        cur = torch.cuda.current_stream(self.device)
        if cur == side:  # already on it (a caller capturing a graph of its own on this stream): no cross-stream waits
            with wp.ScopedStream(self._wp_side, sync_enter=False, sync_exit=False):
                yield
            return
        side.wait_stream(cur)
        with wp.ScopedStream(self._wp_side):
            yield
        cur.wait_stream(side)

    def _tape_stream(self):
        """Where :meth:`step_diff`'s Warp work (forward and the tape's backward) runs: on torch's current stream when
        that is a stream of its own (a CUDA graph being captured or warmed up on it: the gradient fit's captured
        iteration), so torch's and Warp's launches are ordered by the stream itself; else on Warp's device stream,
        which torch's legacy default stream synchronises with (the set-up whose CUDA gradients are checked against
        the CPU's)."""
        if not self._cuda:
            return contextlib.nullcontext()
        import warp as wp

        ws = torch_stream_for_warp(self.device, self._wp_streams)
        return contextlib.nullcontext() if ws is None else wp.ScopedStream(ws, sync_enter=False, sync_exit=False)

    def side_stream(self):
        """The simulator's own CUDA stream (torch), created on first use; CUDA only."""
        if self._side is None:
            import warp as wp

            self._side = torch.cuda.Stream(self.device)
            self._wp_side = wp.stream_from_torch(self._side)
            self._wp_streams[self._side.cuda_stream] = (self._side, self._wp_side)  # one Warp stream object for it
        return self._side

    def _advance(self) -> None:
        for _ in range(self.substeps):
            self.solver.step(self.states[self._cur], self.states[1 - self._cur], self.control, None, self.dt_sub)
            self._cur = 1 - self._cur

    def _advance_graph(self) -> None:
        """Replay the solver steps from a CUDA graph captured once per starting buffer (the states ping-pong)."""
        import warp as wp

        start = self._cur
        graph = self._graphs.get(start)
        if graph is None:
            self._advance()  # compiles and allocates outside the capture
            self._cur = start
            with wp.ScopedCapture(device=self.model.device) as cap:  # on Warp's current stream (step's: _wp_side)
                self._advance()
            self._cur = start
            graph = self._graphs[start] = cap.graph
        wp.capture_launch(graph)
        self._cur = start ^ (self.substeps & 1)

    def step(self, target: torch.Tensor, tau: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Advance one sample period holding the PD target [rad] and joint torque [N*m] (N, n); returns (q, q̇)."""
        self._target[:, self.q_index] = target  # joint_target_q has joint_q's (coordinate) layout
        self._force[:, self.qd_index] = 0.0 if tau is None else tau
        with self._stream():
            if self.graph:
                self._advance_graph()
            else:
                self._advance()
        return self.q, self.qd

    def step_diff(self, k: int, q: torch.Tensor, qd: torch.Tensor, target: torch.Tensor,
                  tau: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Differentiable step ``k`` of a rollout from (q, q̇) (N, n): returns (q', q̇') with gradients to q, q̇,
        target and tau. Step ``k`` uses its own state buffers (kept for the backward pass)."""
        if not self.requires_grad:
            raise RuntimeError("step_diff needs Simulator(..., requires_grad=True)")
        if tau is None:
            tau = torch.zeros_like(target)
        with self._tape_stream():  # Warp fills new buffers on the stream whose torch writes to them come next
            TapeBuffers.up_to(self, k)
        names = tuple(self._physics)
        return TapeStep.apply(q, qd, target, tau, self, k, names, *(self._physics[f] for f in names))

    def diverged(self, q: torch.Tensor, qd: torch.Tensor, limits: DivergenceLimits,
                 q_ref: torch.Tensor | None = None, bounds=None) -> torch.Tensor:
        """Worlds past ``limits``: non-finite, runaway speed, far past a joint limit, or far from ``q_ref``. (N, n)
        tensors -> bool (N,). ``bounds``: (lower, upper), the limits widened by the margin, from a loop over steps."""
        lo, hi = bounds or (self.lower - limits.limit_margin, self.upper + limits.limit_margin)
        nonfinite = torch.cat([q, qd], -1).mul(0.0).ne(0.0)  # x * 0 is ±0 for a finite x, NaN for ±inf and NaN
        bad = torch.cat([nonfinite, q < lo, q > hi, qd.abs() > limits.max_qd], -1).any(-1)  # one reduction
        if q_ref is not None and math.isfinite(limits.max_error):
            bad |= ((q - q_ref).abs() > limits.max_error).any(-1)
        return bad

    # ------------------------------------------------------------------------------------------------ gradients
    def _physics_grads(self, names, meta) -> list[torch.Tensor]:
        """Gradients the tape left in the model's fields ``names``, summed over worlds (one robot), each as the
        ``(dtype, device)`` of ``meta``."""
        out = []
        for f, (dtype, device) in zip(names, meta):
            g = self._model_view(f, grad=True)
            g = g.sum(0) if f.startswith("body_") else g[:, self.qd_index].sum(0)
            out.append(g.to(device, dtype))
        return out
