"""What one update of the online identifier (:class:`~wresdyn.adapt.adapter.Adapter`) did: the candidate it
tried, the decision, the errors before and after and the compute it took (:class:`Update`), as the adapter returns
it and ``updates.csv`` (:mod:`wresdyn.adapt.timeline`) logs it. Settings named here are
:class:`~wresdyn.adapt.config.AdaptConfig`'s."""

from dataclasses import dataclass, field

from ..robot.physical import PhysicalParams

__all__ = ["Update"]


@dataclass
class Update:
    """One update of the adapter: what it tried, what it kept, the errors and the compute it took."""

    t: float
    """Robot time of the update [s] (the last sample's)."""
    accepted: bool
    """Whether a candidate became the model: this update's, where it lowered the held-back error; with
    :attr:`AdaptConfig.confirm`, the last update's, where it lowered it again here."""
    open_loop: float
    """Held-back open-loop error of the model after the decision, mean |q_sim − q| [rad]."""
    open_loop_before: float
    """The same for the model before the update [rad]."""
    open_loop_candidate: float
    """The same for the candidate [rad]."""
    open_loop_start: float
    """The same for the warm start (the offline calibration, held fixed) [rad]."""
    one_step: float
    """One-step prediction error of the model after the decision on the held-back samples, mean |q_sim − q| [rad]."""
    one_step_start: float
    """The same for the warm start [rad]."""
    loss: float
    """Training loss of the last step (with the prior)."""
    excited: int
    """Joints the training part excites (their joint fields were adapted)."""
    compute: float
    """Wall-clock time of the update [s]."""
    physics: PhysicalParams = field(repr=False)
    """The model after the decision."""
    reverted: bool = False
    """Whether the model went back to the warm start (:attr:`AdaptConfig.fallback`)."""
    pending: bool = False
    """Whether a winner waits to be confirmed on the next held-back part (:attr:`AdaptConfig.confirm`,
    :attr:`AdaptConfig.confirm_leave`)."""
    jump: float = 0.0
    """The model's held-back error before the update over the median of the recent ones (:attr:`AdaptConfig.detect`;
    0 without it or while the history is short)."""
    tracking: bool = False
    """Whether the update was decided in the tracking mode after a jump (no confirmation)."""
    effort_tried: int = 0
    """Lower effort limits replayed on the last update's held-back part, where a joint's own error jumped
    (:attr:`AdaptConfig.effort_grid`)."""
    effort_set: str = ""
    """``joint=limit`` [N·m] where one of them won and became the model's; empty otherwise."""

    def row(self) -> dict:
        """The scalar fields, for a CSV / JSON log."""
        return {k: v for k, v in self.__dict__.items() if k != "physics"}
