"""The configuration of the gradient fit of a residual (:class:`GradFitConfig`, run by
:func:`wresdyn.fit.gradfit.fit`), apart from the learner so that the command line reads it without importing torch or
Warp."""

from __future__ import annotations

from dataclasses import dataclass

from ..choices import ModelKind, SolverKind, check_choice, check_number
from ..errors import WresdynError
from ..learn.residual_config import ResidualConfig
from ..learn.window_fit_config import WindowFitStop, check_window_fit_config

__all__ = ["GradFitConfig"]


@dataclass(frozen=True)
class GradFitConfig(WindowFitStop):
    """Gradient fit settings (defaults: a small CPU run on the shipped data)."""

    patience: int = 2
    """Validation checks in a row without a ``min_improvement`` gain that end a stage; only with ``iterations``
    ``None``. Two: on the shipped humanoid's identified model the residual's validation stays within 1 % over its six
    horizons either way (3: 1040 iterations, 60 s; 2: 680 iterations, 34 s)."""

    beat_start_within: int | None = 12
    """Validation checks within which the residual must beat its start where the start is a candidate (the hybrid:
    the identified model alone), else the fit stops and keeps the start; ``None`` = the whole schedule runs. Twelve,
    chosen on the validation curves of every fit until a plateau in ``benchmarks/results``
    (``speed/fitcut57_cpu/start_rule.md``): the residual beat its start at the latest at check 12 (the UR5, 480
    iterations) or not in 17-20 checks (the shipped humanoid, the G1, Panda and Solo12 of the robot zoo); twelve is also
    the fewest checks in which the six horizons can each plateau at ``patience`` 2."""

    residual: ResidualConfig = ResidualConfig(fraction=0.25)
    """Residual kind (torque / delta action), network (MLP / GRU) and authority: 0.25 of each effort limit,
    chosen on validation (0.0282 rad against 0.0294 at 0.5, both with ``obs_noise`` 0.1;
    ``benchmarks/results/validation_protocol/fit_sweep_summary.md``)."""
    model: ModelKind = "network"
    """``"network"`` (``residual``'s MLP or GRU) or ``"parametric"`` (per-joint gain scales, damping, friction,
    armature: :class:`wresdyn.learn.parametric.ParametricResidual`, a torque residual)."""
    horizon: int = 64
    """Window length H [steps] (at 500 Hz, 64 steps = 128 ms) when there is no curriculum."""
    horizon_curriculum: tuple[int, ...] = (2, 4, 8, 16, 32, 64)
    """Window lengths stepped through in equal parts of training; empty = always ``horizon``. Doubling
    matters: a residual fitted on 4-step windows can make the 16-step closed loop unstable, and training
    does not recover from there."""
    grad_truncation: int | None = 16
    """Truncated backpropagation: gradients flow through at most this many steps [steps] (the state is
    detached every ``grad_truncation`` steps; the rollout and its loss still span the whole window). Through
    stiff PD dynamics, longer gradient paths explode; ``None`` = never truncate."""
    windows: int = 32
    """Parallel windows B (Newton worlds) per iteration: a batch of recorded windows, one world each, not an
    environment's world count (``num_worlds`` of the replay environment and the skills' plants): a different
    quantity, so another name."""
    lr: float = 1e-3
    """Adam learning rate at the start."""
    lr_final: float = 1e-4
    """Learning rate at the last iteration (cosine decay from ``lr``)."""
    w_q: float = 1.0
    """Weight of the joint position error [1/rad²]."""
    w_qd: float = 0.01
    """Weight of the joint velocity error [s²/rad²]."""
    w_torque: float = 0.5e-5
    """Weight of |τ_res|² [1/(N·m)²] (Table I joint torque)."""
    w_action_rate: float = 0.5e-4
    """Weight of |a_k − a_{k−1}|² in normalised action units (Table I action rate)."""
    grad_clip: float = 1.0
    """Global gradient-norm clip."""
    obs_noise: float = 0.1
    """Gaussian noise added to the policy's observation during training, in units of each channel's
    normalising std (the simulation itself is not perturbed). A regulariser: with 16 training recordings the
    network otherwise fits the training windows' states too closely. Chosen on validation among 0, 0.03, 0.1
    and 0.3 (0.0316, 0.0301, 0.0294, 0.0302 rad at authority 0.5); 0 = off. Not applied to the parametric
    model."""
    solver: SolverKind = "auto"
    """Newton solver (:data:`wresdyn.sim.solvers.SOLVERS`); must be differentiable."""
    friction_kappa: float | None = None
    """Dry-friction law of the replay solver, ``None`` (the soft default) or a damper-law rate [1/s]: as
    ``ReplayEnvConfig.friction_kappa`` (:mod:`wresdyn.ppo.replay_env_config`)."""
    device: str = "cpu"
    """Warp / torch device."""
    torch_threads: int | None = 1
    """CPU threads for torch (``None``: torch's default). One is fastest for these small networks, and an unpinned fit
    ran 12x slower on a loaded 2-core machine (threads contending with the simulation and each other)."""
    sim_threads: int = 1
    """CPU threads the replay solver splits the windows over (the same results; see
    :class:`~wresdyn.identify.sysid.SysIdConfig`). The fit launches one step at a time, so small batches gain nothing: at
    the default 32 windows 2 threads took the residual stage on an idle 2-core machine from 26 to 30 s."""
    seed: int = 0
    """Seed of the window sampler and network initialisation."""
    select_every: int | None = None
    """Evaluate on the validation split every this many iterations and return the best residual (model
    selection on validation); ``None`` = ten times in a fixed count of ``iterations``, every
    :data:`~wresdyn.learn.schedule.PLATEAU_CHECK_EVERY` until a plateau."""
    cuda_graph: bool = True
    """On CUDA, replay each iteration (the rollout with the residual in the loop, the loss, the backward pass
    through torch and each step's Warp tape, gradient clipping, Adam) from a CUDA graph captured once per window
    length, with no host synchronisation inside (:class:`GradFitIteration`). The CPU runs the same code eagerly; off,
    CUDA does too. May change on resume."""
    fused_network: bool | None = None
    """Run the MLP residual of the training rollouts in fewer torch kernels per step
    (:class:`~wresdyn.learn.fused_mlp.FusedMLPRollout`: the parameters' gradients formed once per iteration, the clip's
    mask kept from the forward pass) and Adam as torch's fused kernel. The same fit to float32 rounding, not bit for
    bit (the gradients' sums run in another order). ``None`` (the default): on CUDA where the residual is an MLP
    network the fused path runs (the GPU iteration is launch-bound: ``benchmarks/speed/gradfit_2000.py``), off on the
    CPU, whose results stay those of the plain path bit for bit (:meth:`network_paths`). MLP networks only. May change
    on resume."""
    network_tiles: bool | None = None
    """With ``fused_network``: each rollout step's network forward as one Warp tile kernel and its backward as one
    (:mod:`wresdyn.learn.tile_mlp`) instead of ~24 small torch kernels, and the rollout one autograd node
    (:mod:`wresdyn.sim.tape_chain`). The same fit to float32 rounding (the GEMMs' sums in another order); the kernels'
    split is ``$WRESDYN_TILE_BLOCK``'s where set (:meth:`TileBlock.from_env`). ``None`` (the default): on CUDA with
    the fused path, off on the CPU. May change on resume."""
    physics: str = ""
    """Where the physical parameters the residual is learned on came from (``physics.json`` of ``wresdyn
    identify``; the hybrid's ``identify/``), recorded in the run's config and compared on resume; "" = the robot
    file's. :func:`fit` takes the parameters themselves (``physics``)."""

    def __post_init__(self) -> None:
        check_choice(self.model, ModelKind, "model")
        check_window_fit_config(self)
        check_number(self.horizon, "horizon", integer=True, ge=1)
        for name in ("w_torque", "w_action_rate", "obs_noise"):
            check_number(getattr(self, name), name, ge=0)
        mlp = self.model == "network" and self.residual.arch == "mlp"
        if (self.fused_network or self.network_tiles) and not mlp:
            raise WresdynError("fused_network runs the MLP network only (model 'network', residual.arch 'mlp')")
        if self.network_tiles and self.fused_network is False:
            raise WresdynError("network_tiles runs the fused network's steps: set fused_network too")

    def network_paths(self, fusable: bool = True) -> tuple[bool, bool]:
        """``(fused_network, network_tiles)`` as the fit runs them on :attr:`device`: a value given is kept (tiles
        given on imply the fused path); ``None`` is on for CUDA where the residual is an MLP network the fused path
        can run (``fusable``: :func:`wresdyn.learn.fused_mlp.fusable` of the built residual), else off."""
        auto = str(self.device).startswith("cuda") and self.model == "network" and self.residual.arch == "mlp" \
            and fusable
        fused = (auto or bool(self.network_tiles)) if self.fused_network is None else self.fused_network
        tiles = (auto and fused) if self.network_tiles is None else self.network_tiles
        return fused, tiles
