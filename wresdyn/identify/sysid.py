"""Grey-box system identification: fit the simulator's own physical parameters through the differentiable solver.

The fitted quantities are the model arrays SolverReplay reads (per joint: PD gains, armature, viscous damping,
dry friction with stiction, effort limit, command delay; per link: mass, centre of mass and inertia through the
log-Cholesky pseudo-inertia), produced by :class:`~wresdyn.sim.physics.PhysicsModel`. As in the gradient fit of a
residual (:mod:`wresdyn.fit.gradfit`), each iteration replays B windows of recorded commands open loop from their
recorded start state and minimises

    L = mean_k [ w_q |q_k − q_r,k|² + w_qd |q̇_k − q̇_r,k|² ] + w_prior |u − u_0|²,

but the gradient goes to the parameters: the Warp tape of every step returns ``∂L/∂(model arrays)``
(:meth:`wresdyn.sim.Simulator.step_diff`), the command delay's through the interpolated PD target
(:func:`wresdyn.sim.bank.delay_commands`). The prior is weak; it only settles what the data cannot tell apart.

A saturating drive has no gradient while the simulated drive does not saturate, so the effort limit starts
from a coarse search: the training loss of a few windows at a geometric grid of fractions of the robot file's
limit (forward only, :mod:`.grid_search`); the gradient refines from the best. ``SysIdConfig.effort_floor`` bounds
both from below (a servo's data-sheet stall torque as the least torque bound). Model selection on the validation
split, as for every learner: every ``select_every`` iterations the current parameters replay the validation
trajectories and the best are returned. Optional L-BFGS (``SysIdConfig.refine``) and Levenberg-Marquardt
(``polish``, :mod:`.refine`) steps follow on fixed training windows, each validated the same way. Held-out and OOD
data are never read. The Adam loop is the gradient fit's (:func:`~wresdyn.learn.window_fit.run_window_fit`).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import torch

from ..errors import WresdynError
from ..learn.adam import Adam
from ..learn.graph_step import StepGraphs, adopt_optimiser, set_lr
from ..learn.runs import RunFolder
from ..learn.selection import ValidationScore
from ..learn.window_fit import joint_weights, run_window_fit, start_window_fit
from ..sim import Simulator, TrajectoryBank
from ..sim.fused import can_fuse
from ..sim.physics import PhysicalParams, PhysicsModel
from .grid_search import GridChoice, grid_search
from .identifiability import identifiability, write_identifiability
from .refine import lbfgs_refine, physics_window_loss, polish
from .shooting import ShootingNodes, chain_loss, draw_chains
from .sysid_config import SysIdConfig
from .unexcited_limits import effort_candidates

__all__ = ["SysIdConfig", "identify", "run_record", "PhysicsScore", "GridChoice", "RESUME_MAY_CHANGE",
           "physics_window_loss", "NonFiniteLoss"]

RESUME_MAY_CHANGE = ("device", "torch_threads", "sim_threads", "refine", "refine_windows", "refine_frozen", "fused",
                     "cuda_graph", "max_iterations", "max_seconds", "identifiability", "identifiability_windows",
                     "polish", "polish_windows", "polish_threshold")
""":class:`SysIdConfig` fields a resumed identification may change: where and how fast it runs (the fused replay's
states are the stepped replay's, the captured step's the eager one's to float32 rounding), the L-BFGS refinement and
the polish, which run after the checkpointed Adam steps, the ceilings of a run until convergence, and the
identifiability report, which reads the selected parameters only."""


class NonFiniteLoss(WresdynError):
    """The identification loss became non-finite where a command-path field (goal acceleration, delay) is fitted."""


def _non_finite(it: int, fields) -> Exception:
    """The error of a non-finite loss at iteration ``it``: with the goal acceleration or the delay among ``fields``,
    a one-line :class:`NonFiniteLoss` naming them (the goal profile's pathwise gradient overflows over long runs, so
    a step can land anywhere); otherwise the simulation diverged."""
    path = [f for f in ("goal_accel", "delay") if f in fields]
    if not path:
        return FloatingPointError(f"identification: non-finite loss at iteration {it} (simulation diverged)")
    how = {"delay": "the delay by --delay-grid", "goal_accel": "goal_accel on validation over a grid of values set "
           "in the gains config"}
    return NonFiniteLoss(f"identification: non-finite loss at iteration {it} while fitting {' and '.join(path)} (the "
                         f"servo goal profile's gradient overflows over long runs): leave {' and '.join(path)} out of "
                         f"--fit and choose {' and '.join(how[f] for f in path)}")


class PhysicsScore(ValidationScore):
    """``score(params) -> mean |Δq| [rad]``: :class:`~wresdyn.learn.selection.ValidationScore` of whole trajectories
    replayed PD-only with the physical parameters ``params`` (and their delay), through one reused simulator."""

    def __call__(self, params: PhysicalParams) -> float:
        self.physics = params
        return super().__call__()


def identify(robot, dataset, cfg: SysIdConfig, out: str | Path | None = None, log=print,
             start: PhysicalParams | None = None, on_search=None):
    """Identify the simulator's physical parameters from ``dataset``'s training split.

    Args:
        robot: The nominal robot (the simulator side).
        dataset: A :class:`~wresdyn.data.dataset.Dataset` (``q``, ``qd``, ``q_cmd`` of train; validation selects).
        cfg: Settings.
        out: Optional run folder (:class:`~wresdyn.learn.runs.RunFolder`): ``config.json``, ``checkpoint.pt``
            (resumed; a changed config is refused), ``physics.json`` (the selected parameters), ``curve.json`` and,
            with ``cfg.identifiability``, ``identifiability.json`` / ``.md`` (:mod:`.identifiability`).
        log: Progress printer.
        start: Values to start from (default the robot file's).
        on_search: Optional ``callable(GridChoice)``, called after each grid search (kp, delay, effort) with what
            it chose.

    Returns:
        ``(params, curve)``: the selected :class:`~wresdyn.sim.physics.PhysicalParams` and the learning curve.
    """
    rng, train, dt = start_window_fit(cfg, dataset)
    learner = IdentifyLearner(robot, dataset, cfg, start, rng, train, dt, log, on_search)
    run = RunFolder(out, dataclasses.asdict(cfg), RESUME_MAY_CHANGE, key="sysid", record=run_record(cfg, dataset))
    curve = run_window_fit(cfg, learner, run, rng, log)
    params = learner.model.values()
    params, validation = effort_candidates(cfg, robot, dataset, train, dt, params, learner.physics_score,
                                           run.best.value, log)
    if cfg.refine:
        params = lbfgs_refine(cfg, robot, learner.bank, dt, params, learner.physics_score, validation,
                              learner.weights, curve, log)
    if cfg.polish:
        params = polish(cfg, robot, learner.bank, dt, params, learner.physics_score, learner.weights, curve, log)
    if run.path is not None:
        params.save(run.path / "physics.json")
        run.write_curve()
        if cfg.identifiability:
            _report_identifiability(robot, dataset, params, cfg, run.path, log)
    return params, curve


def _report_identifiability(robot, dataset, params, cfg, out, log) -> None:
    """Write ``identifiability.json`` and ``.md`` to ``out`` (:mod:`.identifiability`) and log its summary and
    flags."""
    found = identifiability(robot, dataset, params, cfg)
    if found is None:
        log("identifiability: no validation split, no report")
        return
    write_identifiability(out, found)
    log(found.summary())
    for f in found.flags:
        log(f"  {f['kind']}: {', '.join(f['parameters'])}: {f['advice']}")


def run_record(cfg: SysIdConfig, dataset) -> dict:
    """What ``config.json`` of an identification run holds beside the config itself (under ``sysid``), for
    ``wresdyn eval``."""
    return {"learner": "identify", "rate_hz": dataset.rate_hz, "solver": cfg.solver,
            "friction_kappa": cfg.friction_kappa}


class IdentifyLearner:
    """Identification as a :class:`~wresdyn.learn.window_fit.WindowLearner`: the physical parameters
    (:class:`~wresdyn.sim.physics.PhysicsModel`) under Adam, with the grid searches before the first step (kp) and
    where the effort limit joins the fit (delay, effort). With ``cfg.cuda_graph`` on CUDA the Adam step is replayed
    from a CUDA graph per window length (:attr:`graphs`), captured again after every grid search, where the effort
    limit joins the fit, at each horizon stage and after a checkpoint is restored."""

    name, what, parts, checkpoint_keys, map_location, deferred = \
        "identify", "identification", ("loss", "pos", "vel"), ("model", "optim"), "cpu", False

    def __init__(self, robot, dataset, cfg: SysIdConfig, start, rng, train, dt: float, log, on_search) -> None:
        self.robot, self.cfg, self.rng, self.train, self.dt, self.log = robot, cfg, rng, train, dt, log
        self.on_search = on_search
        self.model = self.module = PhysicsModel(robot, start, fit=cfg.fit, dt=dt, effort_floor=cfg.effort_floor,
                                                shared_delay=cfg.shared_delay)
        model = self.model
        groups = [[model.u_kp, model.u_kd, model.u_armature, model.u_noload_speed, model.u_goal_accel],
                  [model.u_damping, model.u_friction, model.u_effort, model.u_delay, model.u_deadband,
                   model.u_startup_torque, model.u_stiction,
                   model.u_backlash, model.u_encoder_offset, model.u_load_friction],
                  [model.u_body_logdiag, model.u_body_off]]
        self.optim = Adam([{"params": [p for p in g if p.requires_grad], "scale": f}
                           for g, f in zip(groups, cfg.lr_scale)], lr=cfg.lr)
        self.effort_from = math.inf  # the iteration where the effort limit joins the fit (never, unless fitted)
        if "effort" in cfg.fit and cfg.iterations is not None:
            self.effort_from = int(round(cfg.effort_after * cfg.iterations))
        validation = dataset.split("validation")
        self.physics_score = PhysicsScore(robot, validation, dataset.rate_hz, cfg.solver, cfg.device,
                                          weights=dataset.fit_weights(), friction_kappa=cfg.friction_kappa
                                          ) if validation else None
        self.sim = Simulator(robot, cfg.windows, dt, solver=cfg.solver, device=cfg.device, requires_grad=True,
                             param_grads=True, friction_kappa=cfg.friction_kappa, solver_threads=cfg.sim_threads)
        fusable = can_fuse(self.sim) and cfg.grad_truncation is None and cfg.shooting == 1
        if cfg.fused is True and not fusable:
            raise ValueError("fused replays PD drives with the replay solver at one substep; this identification's "
                             "robot or solver is not that: set fused to false")
        self.fused = fusable if cfg.fused is None else cfg.fused
        self.graphs = None
        """The Adam step's CUDA graphs (:class:`~wresdyn.learn.graph_step.StepGraphs`), ``None``: eager steps."""
        servo = getattr(robot, "servo", None) is not None  # its command path compares goal profiles on the host
        if cfg.cuda_graph is True and servo and StepGraphs.available(self.sim.device):
            raise ValueError("cuda_graph: a robot with servo drives identifies eagerly; set cuda_graph to false or "
                             "none")
        # None: captured wherever it can be (shooting 1 is the config's check for True)
        if cfg.cuda_graph is not False and not servo and cfg.shooting == 1 and StepGraphs.available(self.sim.device):
            model.to(self.sim.device)  # a parameter on the host would be copied, not captured
            self.graphs, self.deferred = StepGraphs(self.sim, before_capture=self._release), True
            adopt_optimiser(self.optim, self.sim.device, capturable=self._capturable())
        self.bank = TrajectoryBank(train, self.sim.device)
        self.weights = joint_weights(dataset, self.sim.device)  # joints excluded from fitting weigh 0 in the loss
        self.horizons = cfg.horizon_curriculum or (64,)
        self.run = None
        self.nodes = self.pool = None
        if cfg.shooting > 1:  # multiple shooting: chains of windows side by side, free start states
            self.parts = (*self.parts, "defect")
            self.checkpoint_keys = (*self.checkpoint_keys, "nodes", "node_optim")
            self.chain_sim = Simulator(robot, cfg.windows * cfg.shooting, dt, solver=cfg.solver, device=cfg.device,
                                       requires_grad=True, param_grads=True, friction_kappa=cfg.friction_kappa,
                                       solver_threads=cfg.sim_threads)
            self.nodes = ShootingNodes(self.bank, min(self.horizons))
            self.node_optim = torch.optim.SparseAdam(self.nodes.parameters(), lr=cfg.shooting_lr)

    def begin(self, run: RunFolder) -> None:
        self.run = run
        if self.physics_score is not None:
            run.best.take(self.score(), 0, self.model)
            self.log(f"start: validation {run.best.value:.4f} rad")

    def on_stage(self, stage: int, it: int) -> None:
        """Until a plateau, the effort limit joins the fit where the stage holding ``effort_after`` of the
        curriculum begins."""
        if self.cfg.iterations is None and "effort" in self.cfg.fit \
                and stage == int(self.cfg.effort_after * len(self.horizons)) and it < self.effort_from:
            self.effort_from = it
        if self.graphs is not None:  # the last length's graphs are not replayed again: their memory goes
            self.graphs.reset()

    def _search(self, field: str, grid, values, per_joint: bool = False) -> GridChoice | None:
        return grid_search(self.cfg, self.model, self.sim, self.train, self.rng, field, grid, values, self.log,
                            self.weights, per_joint=per_joint)

    def _events(self, it: int) -> bool:
        """The grid searches: kp before the first step, delay and effort where the effort limit joins the fit (the
        delay before the first step with ``delay_grid_first``); whether one ran."""
        cfg, searched = self.cfg, []

        def delay_search():
            if "delay" in cfg.fit:
                searched.append(self._search("delay", cfg.delay_grid, lambda g: np.full(self.robot.n_dof, g * self.dt),
                                             per_joint=cfg.delay_grid_per_joint))
        if it == 0 and cfg.delay_grid_first:
            delay_search()
        if it == 0 and cfg.gain_grid:
            start_kp = self.model.values().kp
            choice = self._search("kp", cfg.gain_grid, lambda g: g * start_kp, per_joint=True)
            if self.physics_score is not None:  # the searched start is a candidate of the selection too
                v = self.score()  # counted in the wall-clock, as the search itself
                self.log(f"after the kp search: validation {v:.4f} rad")
                choice = dataclasses.replace(choice, validation=v)
                self.run.best.consider(v, 0, self.model)
            searched.append(choice)
        if it == self.effort_from:
            if not cfg.delay_grid_first:
                delay_search()
            file_effort = np.asarray(self.robot.effort, dtype=np.float64)
            grid = cfg.effort_grid if cfg.effort_floor is None else \
                tuple(dict.fromkeys(max(g, cfg.effort_floor) for g in cfg.effort_grid))  # raised to the floor, once
            searched.append(self._search("effort", grid,
                                         lambda g: np.where(np.isfinite(file_effort), g * file_effort, np.inf)))
        for choice in searched:
            if choice is not None and self.on_search:
                self.on_search(choice)
        return any(choice is not None for choice in searched)

    def step(self, it: int, h: int, lr: float):
        if self.graphs is not None:
            return self._graphed_step(it, h, lr)
        cfg, model = self.cfg, self.model
        for group in self.optim.param_groups:
            group["lr"] = group["scale"] * lr
        self._events(it)
        delay = model.delay_steps().float().to(self.sim.device)
        if getattr(self.robot, "servo", None) is None:
            self.bank.set_delay(delay)
        else:
            self.bank.set_command_path(delay, model.goal_accel_steps().float().to(self.sim.device))
        if self.nodes is None:
            window = self.bank.sample(self.rng, cfg.windows, h)
            loss, parts = physics_window_loss(cfg, model, self.sim, window, self.weights, fused=self.fused)
        else:
            traj, first = self._chains(h)
            loss, parts = chain_loss(cfg, model, self.chain_sim, self.bank, self.nodes, traj, first, h, self.weights)
            self.node_optim.zero_grad()
        loss = loss + cfg.w_prior * model.prior().to(loss.device)
        if not torch.isfinite(loss):
            raise _non_finite(it, cfg.fit)
        self.optim.zero_grad()
        loss.backward()
        if self.nodes is not None:
            self.node_optim.step()
        if it < self.effort_from and model.u_effort.grad is not None:
            model.u_effort.grad = None  # not yet part of the fit (Adam skips a parameter without gradient)
        torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
        self.optim.step()
        model.project()
        return {"loss": float(loss.detach()), **{k: float(v) for k, v in parts.items()}}, None

    def _graphed_step(self, it: int, h: int, lr: float):
        """:meth:`step` through :attr:`graphs`: the same arithmetic (on CUDA, Adam ``capturable``), the loss parts
        returned on the device (a non-finite loss is found when they are read, :meth:`non_finite`)."""
        for group in self.optim.param_groups:
            set_lr(group, group["scale"] * lr)
        if self._events(it) or it == self.effort_from:  # parameters moved on the host, or the effort gets a gradient
            self.graphs.reset()
        traj, start = self.bank.draw(self.rng, self.cfg.windows, h)
        with_effort = it >= self.effort_from
        return {}, self.graphs(h, lambda traj, start: self._adam_step(traj, start, h, with_effort), traj, start)

    def _adam_step(self, traj, start, h: int, with_effort: bool) -> torch.Tensor:
        """One Adam step on the windows at (trajectory, start) (B,) each; returns (loss, pos, vel) in float64 (the
        values :meth:`step`'s row holds), without reading them."""
        cfg, model = self.cfg, self.model
        self.bank.set_delay(model.delay_steps().float().to(self.sim.device))
        window = self.bank.window(traj, start, h)
        loss, parts = physics_window_loss(cfg, model, self.sim, window, self.weights, fused=self.fused)
        loss = loss + cfg.w_prior * model.prior().to(loss.device)
        self.optim.zero_grad()  # to None: a captured backward allocates the gradients in the graph's pool
        loss.backward()
        if not with_effort and model.u_effort.grad is not None:
            model.u_effort.grad = None
        torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
        self.optim.step()
        model.project()
        return torch.stack([loss.detach().double(), parts["pos"].double(), parts["vel"].double()])

    def _release(self) -> None:
        """Drop the autograd graphs the simulator and the bank keep from the last eager step (the model arrays'
        and the delay's): their gradient accumulators would tie a captured backward to the stream they were made
        on. Both are set again at the start of every step."""
        self.sim._physics = {}
        if torch.is_tensor(self.bank.delay):
            self.bank.delay = self.bank.delay.detach()

    def _capturable(self) -> bool:
        """Whether Adam runs ``capturable`` (the learning rate a device tensor): captured steps on CUDA (on the CPU,
        only the tests' stand-in for a capture, which replays eagerly)."""
        return self.graphs is not None and self.sim.device.type == "cuda"

    def non_finite(self, it: int) -> Exception:
        """The error of a non-finite loss at iteration ``it`` (from 0), read back from a deferred step."""
        return _non_finite(it, self.cfg.fit)

    def _chains(self, h: int):
        """This iteration's chains of ``cfg.shooting`` windows of ``h`` steps: (trajectory, first sample), (B,) each,
        fresh or from the pool of the window length (:attr:`SysIdConfig.shooting_pool`)."""
        cfg, spacing = self.cfg, self.nodes.spacing
        if not cfg.shooting_pool:
            return draw_chains(self.bank, self.rng, cfg.windows, cfg.shooting, h, spacing)
        if self.pool is None or self.pool[0] != h:
            self.pool = (h, draw_chains(self.bank, np.random.default_rng([cfg.seed, h]), cfg.shooting_pool,
                                        cfg.shooting, h, spacing))
        pick = self.rng.integers(0, cfg.shooting_pool, cfg.windows)
        return self.pool[1][0][pick], self.pool[1][1][pick]

    def score(self) -> float | None:
        return None if self.physics_score is None else self.physics_score(self.model.values())

    def state(self) -> dict:
        nodes = {} if self.nodes is None else {"nodes": self.nodes.state_dict(),
                                               "node_optim": self.node_optim.state_dict()}
        return {"model": self.model.state_dict(), "optim": self.optim.state_dict(), **nodes}

    def meta(self) -> dict:
        return {"effort_from": self.effort_from}

    def restore(self, data: dict) -> None:
        self.effort_from = data["meta"].get("effort_from", self.effort_from)
        self.model.load_state_dict(data["model"])
        self.optim.load_state_dict(data["optim"])
        # the loaded optimiser brings the flags of the run that saved it (cuda_graph may change on resume)
        adopt_optimiser(self.optim, self.sim.device, capturable=self._capturable())
        if self.graphs is not None:  # and new state tensors
            self.graphs.reset()
        if self.nodes is not None:
            self.nodes.load_state_dict(data["nodes"])
            self.node_optim.load_state_dict(data["node_optim"])
