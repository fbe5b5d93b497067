"""Different physics per world, written in place: what a domain-randomisation redraw on reset and a finite-difference
Jacobian write into a :class:`~wresdyn.sim.Simulator`'s model.

The values go row by row into the very Warp arrays the solver was built on (same pointers), and the solver is told
only what changed (:func:`model_flags`), so a CUDA graph captured of its steps stays valid and a redraw of a few
worlds costs a few small kernels instead of a new capture:

- ``SolverReplay`` reads every parameter from the model arrays at each launch: nothing to refresh.
- Newton's ``SolverMuJoCo`` on mujoco_warp copies the Newton arrays into its MuJoCo model by kernels that write in
  place, per flag (Newton ``SolverMuJoCo._notify_model_changed``): gains, effort limits and dry friction
  (``JOINT_DOF_FORCE_PROPERTIES``: actuator gain/bias, force range, ``dof_frictionloss``); armature
  (``JOINT_DOF_INERTIAL_PROPERTIES``: ``dof_armature``, then ``set_const_0``); link masses, centres of mass and
  inertias (``BODY_INERTIAL_PROPERTIES``: body mass/ipos/inertia/iquat, then ``set_const_fixed`` for the subtree
  masses and ``set_const_0`` for ``dof_invweight0`` / ``body_invweight0``, which set the constraints' softness);
  shape friction (``SHAPE_PROPERTIES``: ``geom_friction``). Warp keeps the kernels a captured graph launched alive,
  so the graphs are kept.
- Solvers that keep host-side state of the model (Featherstone's mass-matrix flag, the threaded MuJoCo C worlds'
  template) are notified as well and their captured graphs dropped.

On CUDA, ``Simulator.refresh_graph`` (the default there) replays mujoco_warp's refresh from a CUDA graph
(:func:`refresh`): ``set_const_0`` is hundreds of small kernels, whose launches a graph replaces with one. On one
H200 (one run, the host busy with other jobs), the floor humanoid's (e) plant at 4096 worlds (``benchmarks/skills/randomize_speed.py``,
``benchmarks/results/floor_fair/randomize_speed/``) took 1.08 s per PPO iteration with the graph, 1.76 s with the
eager refresh and 4.60 s when every redraw captured the step's graphs again; one redraw of 204 worlds added 9.7, 44.7
and 155.8 ms to the policy step after it. The captured refresh gives the same derived quantities and steps as a solver
built on the drawn model (``tests/skills/test_randomize.py``, run on that GPU). The CPU has no graphs: there the
refresh stays eager.
"""

from __future__ import annotations

import numpy as np
import torch

from .physics import MODEL_ARRAYS, SERVO_ARRAYS

__all__ = ["FIELD_FLAGS", "model_flags", "model_values", "write_world_physics", "refresh"]

FIELD_FLAGS = {"kp": "JOINT_DOF_FORCE_PROPERTIES", "kd": "JOINT_DOF_FORCE_PROPERTIES",
               "damping": "JOINT_DOF_FORCE_PROPERTIES", "friction": "JOINT_DOF_FORCE_PROPERTIES",
               "effort": "JOINT_DOF_FORCE_PROPERTIES", "armature": "JOINT_DOF_INERTIAL_PROPERTIES",
               "body_mass": "BODY_INERTIAL_PROPERTIES", "body_com": "BODY_INERTIAL_PROPERTIES",
               "body_inertia": "BODY_INERTIAL_PROPERTIES"}
"""Newton ``ModelFlags`` member that announces a change of each physical field (servo fields: none, the replay
solver reads them live)."""


def model_flags(fields, shapes: bool = False) -> int:
    """The ``ModelFlags`` of a change of ``fields`` (and of the shapes' friction when ``shapes``)."""
    from newton import ModelFlags

    flags = 0
    for f in fields:
        if f in FIELD_FLAGS:
            flags |= int(getattr(ModelFlags, FIELD_FLAGS[f]))
    return flags | (int(ModelFlags.SHAPE_PROPERTIES) if shapes else 0)


def model_values(field: str, v: torch.Tensor, device) -> torch.Tensor:
    """``field``'s values as the model's arrays hold them: float32 on ``device``, an infinite effort as 0
    (Newton's "unlimited")."""
    v32 = v.detach().to(device, torch.float32)
    return torch.where(torch.isfinite(v32), v32, torch.zeros_like(v32)) if field == "effort" else v32


def _rows(ids, num_worlds: int, device) -> tuple[object, int]:
    """An index of the worlds ``ids`` (``None``: all) and their count."""
    if ids is None:
        return slice(None), num_worlds
    ids = np.asarray(torch.as_tensor(ids).cpu(), dtype=np.int64)
    if len(ids) and ((ids < 0) | (ids >= num_worlds)).any():
        raise ValueError(f"set_world_physics: worlds {ids.tolist()} outside 0..{num_worlds - 1}")
    return torch.as_tensor(ids, device=device), len(ids)


def write_world_physics(sim, values: dict, ids=None) -> list[str]:
    """Write ``values`` (field -> tensor with a leading axis of one row per world of ``ids``, ``None``: every world;
    joint fields (k, n), body fields (k, nb[, 3[, 3]])) into ``sim``'s model arrays in place, the inverse masses and
    inertias of the links written alike; an infinite effort is written as 0 (Newton's "unlimited"). Returns the
    fields written (what :func:`refresh` announces)."""
    import warp as wp

    arrays = MODEL_ARRAYS if getattr(sim.robot, "servo", None) is None else {**MODEL_ARRAYS, **SERVO_ARRAYS}
    rows, k = _rows(ids, sim.num_worlds, sim.device)
    for f, v in values.items():
        if f in arrays and v.shape[0] != k:
            raise ValueError(f"set_world_physics: {f} has {v.shape[0]} worlds, the simulator {k}")
    written = []
    with torch.no_grad():
        for f, v in values.items():
            if f not in arrays:
                continue
            v32 = model_values(f, v, sim.device)
            view = sim._model_view(f)
            if f.startswith("body_"):
                view[rows] = v32
            elif torch.is_tensor(rows) and torch.is_tensor(sim.qd_index):  # a (k, n) block, not k pairs
                view[rows[:, None], sim.qd_index[None, :]] = v32
            else:
                view[rows, sim.qd_index] = v32
            written.append(f)
        if any(f in ("body_mass", "body_inertia") for f in written):
            w, model = sim.num_worlds, sim.model
            m, inertia = sim._model_view("body_mass")[rows], sim._model_view("body_inertia")[rows]
            moving = m > 0  # a static body keeps an inverse of 0
            one = torch.where(moving, m, torch.ones_like(m))
            inv_m = wp.to_torch(model.body_inv_mass, requires_grad=False).view(w, -1)
            inv_i = wp.to_torch(model.body_inv_inertia, requires_grad=False).view(w, -1, 3, 3)
            inv_m[rows] = torch.where(moving, 1.0 / one, torch.zeros_like(m))
            eye = torch.eye(3, dtype=inertia.dtype, device=inertia.device)
            safe = torch.where(moving[..., None, None], inertia, eye)
            inv_i[rows] = torch.where(moving[..., None, None], torch.linalg.inv(safe), torch.zeros_like(inertia))
    sim._physics = {}  # no field carries gradients now
    if sim.solver_kind == "replay":
        sim.solver.friction_grad = False
    return written


def refresh(sim, flags: int) -> None:
    """Let ``sim``'s solver refresh what it derives from the model arrays that ``flags`` name, on the simulator's
    stream (after torch's writes, before its next step); the captured graphs are kept where the solver refreshes in
    place (module docstring). With ``sim.refresh_graph`` (CUDA's default), mujoco_warp's refresh of each ``flags``
    runs once eagerly, is captured as a CUDA graph and replayed afterwards: one launch instead of the hundreds of
    small kernels of ``set_const_0`` (one solve per DoF, six per link)."""
    if not flags or sim.solver_kind == "replay":
        return
    from newton import ModelFlags
    from newton.solvers import SolverMuJoCo

    solver = sim.solver
    mujoco_warp = type(solver) is SolverMuJoCo and not solver.use_mujoco_cpu
    captured = mujoco_warp and sim.refresh_graph and sim._cuda
    with sim._stream():
        graph = sim._refresh_graphs.get(flags) if captured else None
        if graph is not None:
            import warp as wp

            wp.capture_launch(graph)
        else:
            solver.notify_model_changed(flags)
            if captured:
                _capture(sim, flags)
    if getattr(solver, "use_mujoco_cpu", False) and flags & ModelFlags.SHAPE_PROPERTIES:
        solver.mj_model.geom_friction[:] = solver.mjw_model.geom_friction.numpy()[0]  # Newton leaves MuJoCo C's
    if type(solver) is not SolverMuJoCo:
        sim._graphs.clear()


def _capture(sim, flags: int) -> None:
    """Capture the solver's refresh of ``flags`` (already run eagerly: the kernels are compiled) on the current
    stream; a refresh that cannot be captured stays eager."""
    import warp as wp

    try:
        with wp.ScopedCapture(device=sim.model.device) as cap:
            sim.solver.notify_model_changed(flags)
    except Exception as e:  # noqa: BLE001 - any failure to capture leaves the eager refresh, which is correct
        import warnings

        warnings.warn(f"the solver's refresh after a redraw could not be captured ({e}); it stays eager",
                      stacklevel=3)
        sim.refresh_graph = False
        return
    sim._refresh_graphs[flags] = cap.graph
