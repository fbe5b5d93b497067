"""The configuration of identification (:class:`SysIdConfig`, run by :func:`wresdyn.identify.sysid.identify`) and
what it can fit (:data:`FIT_FIELDS`), apart from the learner so that the command line reads them without importing
torch or Warp."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..choices import SolverKind, check_number
from ..learn.window_fit_config import WindowFitStop, check_window_fit_config
from ..robot.physical import JOINT_FIELDS, SERVO_FIELDS

__all__ = ["DEFAULT_FIT", "FIT_FIELDS", "SysIdConfig"]


FIT_FIELDS = (*JOINT_FIELDS, *SERVO_FIELDS, "bodies")
"""What can be identified: the per-joint fields, the servo drive's (:data:`~wresdyn.robot.physical.SERVO_FIELDS`,
read on servo joints only) and ``"bodies"`` (every moving link's mass, com, inertia)."""
DEFAULT_FIT = (*JOINT_FIELDS, "bodies")
"""What is identified unless told: :data:`FIT_FIELDS` without the servo fields."""



@dataclass(frozen=True)
class SysIdConfig(WindowFitStop):
    """Identification settings (defaults: a CPU run of a few minutes on the shipped data)."""

    lr_decay: float = 0.3
    """Factor on the learning rate at each plateau of the last horizon, down to ``lr_final``; only with
    ``iterations`` ``None``. 0.3 reaches ``lr_final`` in one step from the last stage's 0.0023: on the shipped data
    validation 0.0016 rad in 91 s of training against 0.0015 rad in 139 s at 0.5 (2 cores shared with other work)."""
    fit: tuple[str, ...] = DEFAULT_FIT
    """Fields to identify (:data:`FIT_FIELDS`, default :data:`DEFAULT_FIT`); the others keep the robot file's
    values."""
    windows: int = 32
    """Windows B (Newton worlds) per iteration: a batch of recorded windows, one world each, not an environment's world
    count (``num_worlds`` of the replay environment and the skills' plants): a different quantity, so another name."""
    horizon_curriculum: tuple[int, ...] = (16, 32, 64, 128)
    """Window lengths [steps], one stage each: short windows first (a far-off start diverges over
    long ones), long windows last (delay, friction and saturation act over tens of steps)."""
    grad_truncation: int | None = None
    """Detach the state every this many steps; ``None`` = full backpropagation (the parameters are few and the
    identified model is stable, unlike a residual network early in training)."""
    fused: bool | None = None
    """Replay each batch of training windows in one solver launch and its adjoint in one plan
    (:func:`wresdyn.sim.fused.fused_rollout`) instead of step by step: the same states, gradients equal to float32
    rounding, far fewer launches and host synchronisations (2.7x per iteration on an H100, 2.3x over a whole
    identification on 2 CPU cores, the same selection). It needs the replay solver at one substep, PD drives (no
    servo), no ``grad_truncation`` and independent windows (``shooting`` 1); ``None`` fuses where those hold and steps
    elsewhere, ``True`` refuses a setting that cannot fuse, ``False`` always steps. The grid searches and the refinement
    step either way."""
    cuda_graph: bool | None = None
    """On CUDA, replay each Adam step from a CUDA graph captured per window length at its second call
    (:class:`~wresdyn.learn.graph_step.StepGraphs`, as the gradient fit's ``cuda_graph``), the physical model then
    held on the device: at 32 windows the step is the host launching small kernels, one graph launch instead. Adam
    runs ``capturable`` (its float32 step size on the device: the iterates differ from the eager step's in the last
    bits) and the loss is read back only at log and validation times. It needs a robot without servo drives and
    ``shooting`` 1; ``None`` captures where those hold and steps eagerly elsewhere, ``True`` refuses a setting that
    cannot capture, ``False`` always steps eagerly. On by default on CUDA because an H200 ran it: the default fit's
    identification gave the eager run's 1880 iterations and validation (0.001557 rad) and the whole command took
    42.1 s without ``--eval`` against 66.0 s with it eagerly
    (``benchmarks/results/speed/h200x2_20261130f/sweep``). The grid searches and the refinement run eagerly
    either way; on the CPU no graph exists and every setting steps eagerly, bit for bit the same."""
    lr: float = 0.01
    """Adam learning rate in the coordinates of :class:`~wresdyn.sim.physics.PhysicsModel` (log scales and
    reference units, all O(0.1-1))."""
    lr_final: float = 0.001
    """Learning rate at the last iteration (cosine decay)."""
    w_q: float = 1.0
    """Weight of the joint position error [1/rad²]."""
    w_qd: float = 0.01
    """Weight of the joint velocity error [s²/rad²]."""
    w_prior: float = 1e-5
    """Weight of the squared distance of the coordinates from the start."""
    effort_grid: tuple[float, ...] = tuple(round(float(x), 4) for x in np.geomspace(0.05, 1.0, 9))
    """Fractions of the robot file's effort limits tried when the effort limit joins the fit (forward only, on
    training windows); empty = continue from the file's limits."""
    delay_grid: tuple[float, ...] = ()
    """Command delays [steps] tried (one for every joint) when the effort limit joins the fit, before it (before the
    first step with ``delay_grid_first``). Off by
    default: on the shipped data (true delay 3 steps) the grid 0-8 picked 0 there, the gains, damping and
    friction having already absorbed the delay, and the final error did not change (0.0057 vs 0.0055 rad
    held-out)."""
    delay_grid_first: bool = False
    """Run ``delay_grid`` before the first Adam step (before ``gain_grid``) instead of where the effort limit joins
    the fit, where the first horizon stage has already put the delay's phase lag into the damping, kd and armature.
    From the file's values the search is biased the other way: on the humanoid fight's data (true delay 2 and 3
    samples) the loss fell monotonically to the grid's end, 8 samples, the file's stiffer, unlimited drives asking for
    any lag; Adam then brought the delay back. Only with a ``delay_grid``."""
    delay_grid_per_joint: bool = False
    """Each joint takes the ``delay_grid`` point of its own least training position error (the joints tried together,
    one rollout per grid point, as ``gain_grid``) instead of the one point of least total error."""
    shared_delay: bool = False
    """One command delay for every joint, fitted through all of them (:class:`~wresdyn.sim.physics.PhysicsModel`'s
    ``shared_delay``), in the Adam steps and the refinement: for a command path whose latency is the bus's, the same
    on every joint, where a joint that barely moves, or whose armature or damping is off, would otherwise bend its
    own delay to its other errors. Only when the delay is fitted."""
    gain_grid: tuple[float, ...] = ()
    """Factors on the start's position gain kp tried before the first step, each joint taking the factor of its own
    least training error (forward only, every joint at one factor per rollout); empty = start from the file's kp.
    Off by default. Where the file's kp is so stiff that the drive saturates on every move (the SO-101's servo
    model: kp 998 N·m/rad against 3.35 N·m), the loss barely depends on kp and Adam cannot walk down to a soft
    servo's: ``benchmarks/real/so101_real.sh`` uses it."""
    effort_floor: float | None = None
    """Least effort limit the fit may reach, as a fraction of the robot file's (gains config's) limit, 0-1: the grid
    of ``effort_grid`` is raised to it and every step projected above it; ``None`` = down to 0.05 of it. Where the
    file's limit is a servo's data-sheet stall torque, 1 keeps the fit from lowering the torque bound to flatten the
    motor's torque-speed line, which shares it (:mod:`wresdyn.robot.servo`). Only when the effort limit is fitted."""
    effort_after: float = 0.4
    """Fraction of the iterations after which the effort limit joins the fit (until a plateau: at the start of the
    horizon stage that holds this fraction of the curriculum, the second of four by default). Before, the drives keep the
    file's limits: a low limit started from the file's other values mimics the friction and delay not yet
    identified (a local minimum where saturation stands in for friction)."""
    lr_scale: tuple[float, float, float] = (1.0, 5.0, 0.5)
    """Learning-rate factors of the gain/armature log scales, the linear fields (damping, friction, effort,
    delay: their coordinates run to a few units) and the link pseudo-inertia factors."""
    grad_clip: float = 1.0
    """Global gradient-norm clip."""
    solver: SolverKind = "auto"
    """Newton solver; must be differentiable (SolverReplay)."""
    friction_kappa: float | None = None
    """Dry-friction law of the replay solver, ``None`` (the soft default) or a damper-law rate [1/s]: as
    ``ReplayEnvConfig.friction_kappa`` (:mod:`wresdyn.ppo.replay_env_config`)."""
    device: str = "cpu"
    """Warp / torch device."""
    torch_threads: int | None = 1
    """CPU threads for torch (``None``: torch's default); see :class:`wresdyn.fit.gradfit.GradFitConfig`."""
    sim_threads: int = 1
    """CPU threads the replay solver splits the windows over (``SolverReplay(threads=)``; the same results bit for
    bit). On an idle 2-core machine 2 took the default identification from 27 to 17 s of training; 1 by default, so
    that parallel jobs (``ablate --jobs``, the tests' workers) do not contend for the cores."""
    seed: int = 0
    """Seed of the window sampler."""
    select_every: int | None = None
    """Validate every this many iterations (``None``: ten times in a fixed count of ``iterations``, every
    :data:`~wresdyn.learn.schedule.PLATEAU_CHECK_EVERY` until a plateau)."""
    refine: int = 0
    """L-BFGS steps after Adam (0: off), each up to 20 evaluations with a strong-Wolfe line search, on
    ``refine_windows`` fixed training windows of the longest horizon, from the parameters selected so far; every
    step is validated and the best kept. The fields of ``fit`` except those of ``refine_frozen``."""
    polish: int = 0
    """Levenberg-Marquardt iterations at the very end (0: off; :func:`wresdyn.identify.refine.polish`): Gauss-Newton
    steps on ``polish_windows`` fixed training windows of the longest horizon, with a Jacobian by forward differences
    (every fitted coordinate perturbed in its own worlds of one batched replay), in the directions whose data curvature
    exceeds ``polish_threshold`` times ``w_prior`` only, so the prior no longer biases what the data determine and still
    holds what they do not; every step validated and the best kept. The fields of ``fit`` but the effort limit, the
    delay and the servo goal acceleration. On ``mujoco.sysid``'s known-truth cases (noise-free, in the truth's model
    class) it brings the default fit within the peer's tolerance (``benchmarks/results/peers/known_truth``)."""
    polish_windows: int = 16
    """Fixed training windows of the polish (its Jacobian replays this many times the fitted coordinates' count)."""
    polish_threshold: float = 1.0
    """A direction of the coordinates counts as determined by the data where the curvature of the data loss along it
    exceeds this multiple of the prior's (``w_prior``, in the prior's own metric): at 1 the prior would pull it less
    than half way to the start. With ``w_prior`` 0, every direction the data see (above 1e-12 of the largest)."""
    refine_windows: int = 64
    """Fixed training windows of the refinement."""
    refine_frozen: tuple[str, ...] = ("effort", "delay")
    """Fields of ``fit`` the refinement keeps at the values selected so far. By default the effort limit and the
    delay: the two the Adam stages reach through grid searches, whose loss is flat (an unsaturated drive) or kinked
    (the delay's interpolation between samples) where a quasi-Newton model of the curvature is least trustworthy.
    Empty: the refinement fits every field of ``fit``, the delay through commands re-delayed at every evaluation and
    the effort limit above ``effort_floor``."""
    share_effort_ratio: bool = True
    """After the selection, give the effort limits the training data never reaches the ratio to the file's limit that
    the saturating joints share, bounded below by the torque the data demands
    (:func:`~wresdyn.identify.unexcited_limits.limit_unexcited_efforts`); kept only if validation is not worse. Only
    when the effort limit is fitted."""
    effort_reset: bool = False
    """After the selection (and ``share_effort_ratio``), the selected parameters with every fitted effort limit put
    back at the robot file's are replayed on validation and kept if better: a candidate of the selection, for a file
    whose limit is a measured figure (a servo's data-sheet stall torque) that training windows trade against the other
    fields. Only when the effort limit is fitted and there is a validation split."""
    effort_line_points: int = 0
    """After the selection (and ``share_effort_ratio``, ``effort_reset``), a per-joint line search on the effort
    limits the training data never reach but that stand above the saturating joints' shared derating
    (:func:`~wresdyn.identify.unexcited_limits.search_unexcited_efforts`): each replayed on the whole training
    trajectories at this many limits from its own down to the derating, the lowest within ``effort_line_tolerance``
    of the least error taken; 0 = off. For a drive whose saturation the fit explained away with its other fields,
    which the demanded-torque bound then keeps high. Only when the effort limit is fitted."""
    effort_line_tolerance: float = 0.02
    """How much worse than the line's least a searched limit may leave its joint's own training replay error, and the
    searched limits together the validation error, as a fraction (0.02: 2 %); only with ``effort_line_points``."""
    saturated_min: float = 0.01
    """Fraction of training samples on which a drive must saturate for its effort limit to count as identified."""
    shooting: int = 1
    """Consecutive windows per training sample (multiple shooting with state continuity, :mod:`wresdyn.identify.shooting`): each of
    the ``windows`` samples is a chain of this many windows of the curriculum's length from one run, simulated side by
    side, the later ones from free start states stitched by the defect penalty ``w_defect``; 1 = independent windows
    from their recorded start. Above 1 every horizon must be a multiple of the shortest (the nodes' spacing)."""
    w_defect: float = 1.0
    """Weight of the shooting defects (what a window's end misses the next one's free start by, with ``w_q`` and
    ``w_qd``) against the data term; only with ``shooting`` > 1."""
    shooting_lr: float = 1e-3
    """Adam learning rate of the free start states [rad, rad/s per step]; only with ``shooting`` > 1."""
    shooting_pool: int = 0
    """With ``shooting`` > 1: draw this many chains once per window length (seeded by ``seed`` and the length) and
    each iteration's ``windows`` among them, so that every free start state is visited many times and can move to
    where the chain is continuous; 0 = fresh chains anywhere every iteration (on the SO-101's 1.2 M training samples
    a node is then drawn about once in a run: the free states stay the recorded ones)."""
    identifiability: bool = True
    """After the selection, write what the data can identify (``identifiability.json`` and ``.md`` in the run
    folder, :mod:`wresdyn.identify.identifiability`): per-parameter standard errors and correlations from the
    Gauss-Newton information of the validation loss, and the parameters the recordings never excite, each with
    advice on the recording that would. One batched replay of every parameter's perturbation; needs a validation
    split. On the shipped data a few seconds against the identification's minute or two."""
    identifiability_windows: int = 16
    """Validation windows (of the curriculum's longest length) the identifiability report replays."""

    def __post_init__(self) -> None:
        check_window_fit_config(self)
        bad = sorted(set(self.fit) - set(FIT_FIELDS))
        if bad:
            raise ValueError(f"fit: unknown field(s) {bad}; choose from {list(FIT_FIELDS)}")
        check_number(self.w_prior, "w_prior", ge=0)
        for i, f in enumerate(self.effort_grid):
            check_number(f, f"effort_grid[{i}]", gt=0)
        for i, f in enumerate(self.gain_grid):
            check_number(f, f"gain_grid[{i}]", gt=0)
        if self.gain_grid and "kp" not in self.fit:
            raise ValueError("gain_grid searches kp, which is not among the fitted fields (fit)")
        if self.effort_floor is not None:
            check_number(self.effort_floor, "effort_floor", ge=0, le=1)
            if "effort" not in self.fit:
                raise ValueError("effort_floor bounds the effort limit, which is not among the fitted fields (fit)")
        if (self.delay_grid_first or self.delay_grid_per_joint) and not self.delay_grid:
            raise ValueError("delay_grid_first and delay_grid_per_joint set how delay_grid is searched: give a "
                             "delay_grid")
        if (self.delay_grid_first or self.delay_grid_per_joint or self.shared_delay) and "delay" not in self.fit:
            raise ValueError("delay_grid_first, delay_grid_per_joint and shared_delay act on the delay, which is not "
                             "among the fitted fields (fit)")
        if self.effort_reset and "effort" not in self.fit:
            raise ValueError("effort_reset puts the effort limit back, which is not among the fitted fields (fit)")
        check_number(self.effort_line_points, "effort_line_points", integer=True, ge=0)
        check_number(self.effort_line_tolerance, "effort_line_tolerance", ge=0)
        if self.effort_line_points and "effort" not in self.fit:
            raise ValueError("effort_line_points searches the effort limit, which is not among the fitted fields (fit)")
        check_number(self.effort_after, "effort_after", ge=0)
        for i, f in enumerate(self.lr_scale):
            check_number(f, f"lr_scale[{i}]", gt=0)
        check_number(self.refine, "refine", integer=True, ge=0)
        check_number(self.refine_windows, "refine_windows", integer=True, ge=1)
        check_number(self.polish, "polish", integer=True, ge=0)
        check_number(self.polish_windows, "polish_windows", integer=True, ge=1)
        check_number(self.polish_threshold, "polish_threshold", ge=0)
        bad = sorted(set(self.refine_frozen) - set(FIT_FIELDS))
        if bad:
            raise ValueError(f"refine_frozen: unknown field(s) {bad}; choose from {list(FIT_FIELDS)}")
        check_number(self.saturated_min, "saturated_min", gt=0, le=1)
        check_number(self.shooting, "shooting", integer=True, ge=1)
        check_number(self.identifiability_windows, "identifiability_windows", integer=True, ge=1)
        if self.cuda_graph is True and self.shooting > 1:
            raise ValueError("cuda_graph captures independent windows: set shooting to 1 or cuda_graph to false")
        if self.fused is True and (self.grad_truncation is not None or self.shooting > 1):
            raise ValueError("fused replays whole windows without truncation or shooting: set grad_truncation to "
                             "none and shooting to 1, or fused to false")
        check_number(self.w_defect, "w_defect", ge=0)
        check_number(self.shooting_lr, "shooting_lr", gt=0)
        check_number(self.shooting_pool, "shooting_pool", integer=True, ge=0)
        spacing = min(self.horizon_curriculum or (64,))
        if self.shooting > 1 and any(h % spacing for h in self.horizon_curriculum):
            raise ValueError(f"shooting: every horizon of horizon_curriculum {list(self.horizon_curriculum)} must be a "
                             f"multiple of the shortest ({spacing}), the shooting nodes' spacing")
