"""Multiple shooting with state continuity for identification: chains of consecutive windows of one run.

With ``SysIdConfig.shooting = K > 1`` each of the B training samples of an iteration is a chain of K consecutive
windows of H steps of one recorded run (K H steps in all), simulated side by side as B K worlds. The first window
starts from the recorded state, window k > 0 from a free start state ``s_k`` (q, q̇), a variable of the fit kept per
node of a grid over every training run (one node every ``G`` samples, ``G`` the shortest window of the curriculum,
initialised to the recorded state there), and the loss adds the defects, what the previous window's end misses the
next one's start by::

    L = mean_{b, k, t} [ w_q |q − q_r|² + w_qd |q̇ − q̇_r|² ]
        + w_defect mean_{b, k > 0} [ w_q |q_{k−1}(H) − s_k^q|² + w_qd |q̇_{k−1}(H) − s_k^q̇|² ]

Where every defect is zero the chain is the single window of K H steps from the chain's recorded start, step for
step, and its first term that window's loss (``tests/identify/test_shooting.py``). Adam (sparse: a node moves only
when it was drawn) descends the free states at ``shooting_lr``; the physical parameters take the rest of the
identification's optimiser. What the servo carries across windows lives in the state and the command path: the goal
profile runs over each whole run before it is cut into windows (:class:`~wresdyn.sim.bank.TrajectoryBank`), and
the dead band's side is the joint's position itself.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from ..learn.window_fit import squared_error
from ..sim import rollout

__all__ = ["ShootingNodes", "chain_loss"]


class ShootingNodes(torch.nn.Module):
    """The free start states of multiple shooting: (q, q̇) at every ``spacing``-th sample of each training run.

    Args:
        bank: The training runs (:class:`~wresdyn.sim.bank.TrajectoryBank`).
        spacing: Samples between nodes G [steps]; chains start and cut at multiples of it.
    """

    def __init__(self, bank, spacing: int) -> None:
        super().__init__()
        self.spacing = int(spacing)
        lengths = bank.length.cpu().numpy()
        counts = (lengths - 1) // self.spacing + 1  # nodes at samples 0, G, 2G, ... < T
        self.base = np.concatenate([[0], np.cumsum(counts)[:-1]])
        rows = np.concatenate([s + self.spacing * np.arange(c) for s, c in zip(bank.start.cpu().numpy(), counts)])
        rows = torch.as_tensor(rows, device=bank.device)
        init = torch.cat([bank.q[rows], bank.qd[rows]], -1).float().cpu()
        self.n = bank.q.shape[1]
        self.states = torch.nn.Embedding(len(init), 2 * self.n, sparse=True, _weight=init.clone())
        """Free start states [rad, rad/s], (nodes, 2n): q then q̇."""

    def index(self, traj: np.ndarray, sample: np.ndarray) -> np.ndarray:
        """Node of sample ``sample`` (a multiple of :attr:`spacing`) of training run ``traj`` (arrays of one shape)."""
        return self.base[traj] + sample // self.spacing

    def forward(self, nodes: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(q, q̇) of ``nodes`` (...,) long: each (..., n)."""
        s = self.states(nodes)
        return s[..., :self.n], s[..., self.n:]


def draw_chains(bank, rng: np.random.Generator, b: int, segments: int, steps: int, spacing: int):
    """``b`` chains of ``segments`` windows of ``steps`` steps: (trajectory (b,), first sample (b,)), the first
    sample a multiple of ``spacing``, uniform over the runs long enough and the starts that fit."""
    span = segments * steps
    lengths = bank.length.cpu().numpy()
    eligible = np.flatnonzero(lengths > span)
    if len(eligible) == 0:
        raise ValueError(f"every training trajectory is shorter than the {span + 1} samples a chain of {segments} "
                         f"windows of {steps} steps needs")
    traj = eligible[rng.integers(0, len(eligible), b)]
    first = spacing * rng.integers(0, (lengths[traj] - 1 - span) // spacing + 1, b)
    return traj, first


def chain_loss(cfg, model, sim, bank, nodes: ShootingNodes, traj: np.ndarray, first: np.ndarray, steps: int,
               weights=None):
    """The multiple-shooting loss of the module docstring for chains of ``cfg.shooting`` windows of ``steps`` steps
    from sample ``first`` (b,) of training runs ``traj`` (b,), on ``sim`` (b K worlds, chain-major: world
    ``i K + k`` is window k of chain i). Returns ``(loss, parts)``: parts ``pos``, ``vel`` (the data term's) and
    ``defect`` (its weighted sum, before ``w_defect``), floats."""
    k_seg = cfg.shooting
    k = np.arange(k_seg)
    t = np.repeat(traj, k_seg)
    s = (first[:, None] + steps * k[None]).reshape(-1)
    dev = sim.device
    window = bank.window(torch.as_tensor(t, device=dev), torch.as_tensor(s, device=dev), steps)
    later = torch.as_tensor(np.tile(k > 0, len(traj)), device=dev)[:, None]
    node_q, node_qd = nodes(torch.as_tensor(nodes.index(t, s)))
    node_q, node_qd = node_q.to(dev), node_qd.to(dev)
    q0 = torch.where(later, node_q, window.q[:, 0])
    qd0 = torch.where(later, node_qd, window.qd[:, 0])
    window = dataclasses.replace(window, q=torch.cat([q0[:, None], window.q[:, 1:]], 1),
                                 qd=torch.cat([qd0[:, None], window.qd[:, 1:]], 1))
    sim.set_physics(model())
    run = rollout(sim, window, grad=True, truncation=cfg.grad_truncation or 0)
    pos = squared_error(run.q[:, 1:], window.q[:, 1:], weights)
    vel = squared_error(run.qd[:, 1:], window.qd[:, 1:], weights)
    n = run.q.shape[-1]
    end_q = run.q[:, -1].reshape(len(traj), k_seg, n)[:, :-1]
    end_qd = run.qd[:, -1].reshape(len(traj), k_seg, n)[:, :-1]
    start_q = q0.reshape(len(traj), k_seg, n)[:, 1:]
    start_qd = qd0.reshape(len(traj), k_seg, n)[:, 1:]
    defect = cfg.w_q * squared_error(end_q, start_q, weights) + cfg.w_qd * squared_error(end_qd, start_qd, weights)
    loss = cfg.w_q * pos + cfg.w_qd * vel + cfg.w_defect * defect
    return loss, {"pos": float(pos.detach()), "vel": float(vel.detach()), "defect": float(defect.detach())}
