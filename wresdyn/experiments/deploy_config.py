"""The sizes of the zero-shot deployment benchmark (:mod:`.skills`), on the stand (:class:`DeployConfig`) and on the
floor (:class:`FloorDeployConfig`), apart from it so that the command line reads them
without importing torch or Warp."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..choices import check_choice, check_device, check_number

__all__ = ["DeployConfig", "FloorDeployConfig"]


@dataclass(frozen=True)
class _BenchmarkSizes:
    """The sizes both benchmarks share, in their order (the stand's defaults). Each benchmark's config adds its own
    fields after these and ends with its ``seed`` and ``device``, which :meth:`__post_init__` checks too, with the
    benchmark's :attr:`_prefix` in its messages."""

    train_per_family: int = 4
    """Training motions per training family."""
    validation_per_family: int = 1
    """Validation motions per family (the task and PPO settings were chosen on them)."""
    heldout_per_family: int = 2
    """Held-out motions per family (training families and the held-out one)."""
    duration: float = 2.0
    """Length of a motion [s]."""
    num_worlds: int = 64
    """Parallel worlds of each simulated plant a policy trains on (PPO's environments; written here once: the plant
    owns the count and PPO reads it from the environment)."""
    oracle_num_worlds: int | None = None
    """Parallel worlds of the oracle's real robot (``None``: ``num_worlds``, the same budget as the others)."""
    oracle_plant: Literal["mujoco", "mujoco_warp"] = "mujoco"
    """What steps the real robot the oracle trains on: ``mujoco`` (MuJoCo C in the host's threads,
    :class:`~wresdyn.skills.plants.RealPlant`) or ``mujoco_warp`` (the same model batched on ``device``,
    :class:`~wresdyn.skills.real_warp.RealWarpPlant`, float32). Deployment is always on MuJoCo C."""
    finetune_std: float | None = None
    """Action noise the fine-tunings (b), (c), (d) restart from (``None``: (a)'s own; see
    ``SkillPPOConfig.restart_std``)."""
    iterations: int = 300
    """PPO iterations of (a) in the nominal simulator."""
    finetune: int = 300
    """PPO iterations of each fine-tuning: (b), (c), (d)."""

    nominal: str | None = None
    """(a) not trained here but taken as it is: a shipped policy's name (``floor_nominal``, trained at full size on a
    GPU; :mod:`wresdyn.skills.shipped`) or a finished skill run folder. ``None``: (a) is trained."""

    _prefix = "deploy"
    """How the fields are named in a message (not a field: no annotation)."""

    @property
    def oracle_worlds(self) -> int:
        """Parallel worlds of the oracle: ``oracle_num_worlds``, else ``num_worlds``."""
        return self.num_worlds if self.oracle_num_worlds is None else self.oracle_num_worlds

    def __post_init__(self) -> None:
        p = self._prefix
        for k in ("train_per_family", "validation_per_family", "heldout_per_family", "num_worlds", "iterations",
                  "finetune"):
            check_number(getattr(self, k), f"{p}.{k}", integer=True, ge=1)
        if self.oracle_num_worlds is not None:
            check_number(self.oracle_num_worlds, f"{p}.oracle_num_worlds", integer=True, ge=1)
        check_choice(self.oracle_plant, Literal["mujoco", "mujoco_warp"], f"{p}.oracle_plant")
        if self.finetune_std is not None:
            check_number(self.finetune_std, f"{p}.finetune_std", gt=0)
        check_number(self.seed, f"{p}.seed", integer=True, ge=0)
        check_device(self.device, f"{p}.device")
        check_number(self.duration, f"{p}.duration", gt=0)


@dataclass(frozen=True)
class DeployConfig(_BenchmarkSizes):
    """Sizes of the benchmark (the defaults: the CPU configuration, minutes on 2 cores)."""

    seed: int = 0
    """Seed of the motions and of PPO."""
    device: str = "cpu"
    """Device of PPO, the simulated plants and the oracle's ``mujoco_warp`` real robot (the deployments' real robot
    steps on the CPU)."""

    @classmethod
    def full(cls, **kw) -> "DeployConfig":
        """The full size, for one GPU: 4096 worlds, 16 training, 2 validation and 4 held-out motions per family
        (the same PPO iterations); the oracle on 4096 worlds of the real robot in mujoco_warp, as many as the
        others."""
        return cls(**{**dict(train_per_family=16, validation_per_family=2, heldout_per_family=4, num_worlds=4096,
                             oracle_plant="mujoco_warp", finetune_std=0.3), **kw})


@dataclass(frozen=True)
class FloorDeployConfig(_BenchmarkSizes):
    """Sizes of the floor benchmark (the defaults: the CPU configuration, about 20 minutes on 2 cores)."""

    train_per_family: int = 3
    """Training motions per training family."""
    validation_per_family: int = 2
    """Validation motions per family (the task and PPO settings were chosen on them; on the CPU the held-out families
    too, ``heldout_families``)."""
    heldout_per_family: int = 3
    """Held-out motions per family (training families and the held-out one)."""
    duration: float = 4.0
    """Length of a motion [s]."""
    screen: bool = True
    """Keep only floor references the flat soles can carry, each draw slowed or redrawn where they cannot
    (:func:`~wresdyn.skills.motions.make_motion`); ``False``: every draw as drawn (test runs of motions too short to
    carry)."""
    finetune_std: float | None = None
    """Action noise the fine-tunings restart from (``None``: (a)'s own; ``SkillPPOConfig.restart_std``)."""
    iterations: int = 200
    """PPO iterations of (a) in the nominal simulator."""
    finetune: int = 30
    """PPO iterations of each fine-tuning: (b), (c), (d)."""
    nominal: str | None = "auto"
    """(a) not trained here but taken as it is: ``auto``, the shipped ``floor_nominal`` (trained at full size on a GPU,
    :mod:`wresdyn.skills.shipped`) where the package has it and PPO runs on the CPU, else trained; a shipped policy's
    name or a finished skill run folder; ``None``: trained here. One that does not fit the run (task, network,
    joints, motion generator: :func:`~wresdyn.experiments.nominal_policy.check_fits`) is refused in one line."""
    shipped: bool = False
    """Train nothing: deploy the policies the package ships, (a), (b) and the oracle (d), each trained at full size on
    a GPU for the real robot of ``data/mismatch_default.toml``
    (:data:`~wresdyn.experiments.nominal_policy.SHIPPED_FLOOR`; their training commands and hashes in
    ``shipped.json``), on motions this run draws with its own ``seed`` (not the policies' 0): the CPU run that shows
    the benchmark's point. No training motion is drawn and no correction fitted; (b) is not deployed in its
    simulator."""
    heldout_families: Literal["all", "balanced"] = "balanced"
    """Which held-out families are deployed: ``all``, or ``balanced``: the families on whose every validation motion
    (a) succeeds in its own simulator (the stepping family, which has none, left out;
    :func:`~wresdyn.experiments.nominal_policy.balanced_families`), so that a short CPU run deploys on motions a
    policy trained at full size can carry."""
    oracle_beside: bool | None = None
    """Train the oracle in a process of its own beside (b) and (c) (``None``: when PPO runs on a GPU and the oracle's
    real robot is MuJoCo C, which steps on otherwise idle host cores)."""
    extra_families: tuple[Literal["combo"], ...] = ()
    """Motion families the policies also train on, ``train_per_family`` each (validation draws them too, the held-out
    motions never): ``combo``, compositions of the weight shifts' and kicks' keyframes with transfers slow and too
    fast to follow (:mod:`wresdyn.skills.families`)."""
    beside_devices: tuple[str, ...] = ()
    """More devices of the host (``cuda:1,cuda:2``): each simulated fine-tuning after (b) trains in a process of its
    own on the next one, beside (b) on ``device``, so that (b) and (c) take one fine-tuning's wall-clock. Empty:
    one after the other on ``device``."""
    motion_workers: int = 0
    """Processes that draw and screen the floor motions at the start of a run (0: the host's usable cores, at most
    one per 8 motions; 1, no process started, on a host of at most 2 cores). The motions are the same bit for bit
    at any count (each has its own random stream: :func:`~wresdyn.skills.motions.make_motions`)."""
    seed: int = 0
    """Seed of the motions and of PPO."""
    device: str = "cpu"
    """Device of PPO, the simulated plants and the oracle's ``mujoco_warp`` real robot (the deployments' real robot
    steps on the CPU)."""

    _prefix = "floor"

    def __post_init__(self) -> None:
        super().__post_init__()
        check_choice(self.heldout_families, Literal["all", "balanced"], "floor.heldout_families")
        for f in self.extra_families:
            check_choice(f, Literal["combo"], "floor.extra_families")
        for d in self.beside_devices:
            check_device(d, "floor.beside_devices")
        check_number(self.motion_workers, "floor.motion_workers", integer=True, ge=0)

    @classmethod
    def full(cls, **kw) -> "FloorDeployConfig":
        """The full size, for one GPU: 4096 worlds, 16 training, 4 validation and 10 held-out motions per family
        (independent draws, screened: :func:`~wresdyn.skills.motions.make_motions`), 1000 + 300 iterations; the
        oracle on 4096 worlds of the real robot's floor in mujoco_warp, as many as the others; (a) trained, every
        held-out family deployed."""
        return cls(**{**dict(train_per_family=16, validation_per_family=4, heldout_per_family=10, num_worlds=4096,
                             oracle_plant="mujoco_warp", iterations=1000, finetune=300, finetune_std=0.3, nominal=None,
                             heldout_families="all"), **kw})
