"""rsl-rl's PPO update, bit for bit, with one collective and one host wait per mini-batch.

rsl-rl 5.5's ``PPO.update`` meets the host about five times per mini-batch (the adaptive learning rate's KL tests in
Python, three losses read back for the log) and, across processes, makes three collectives per mini-batch: the KL's
all-reduce, rank 0's new learning rate broadcast (uploaded from the host first, read back after) and the gradients'
all-reduce. Each of these is a point where the processes wait for each other, 20 mini-batches an iteration.

:class:`PackedPPO` computes the same numbers with fewer meeting points:

- the KL is packed into the gradients' all-reduce (one collective; rsl-rl packs the gradients the same way, and the
  KL's sum and division by the process count are the same float32 operations on the same values);
- every rank applies rsl-rl's rule to the all-reduced KL, which is the same value on every rank, instead of
  receiving rank 0's rate: the same rate, rounded to float32 as rsl-rl's broadcast tensor rounds it;
- both KL tests are read back in one copy, started before the gradient clips are launched and waited on after them,
  so the device works on the clips while the host waits;
- the losses are summed on the device in float64 (float32 values summed in the order rsl-rl's Python floats are)
  and read back once, at the end of the update.

The learning rate stays a Python float, so Adam runs exactly as in rsl-rl's update (unlike
:class:`~wresdyn.ppo.update.OneSyncPPO`, which keeps it on the device and rounds Adam's step differently). On one
process and on two the weights, optimiser state, learning rate and losses equal rsl-rl's bit for bit; on more than
two, up to the order in which the all-reduce sums. Only the plain case takes this path (a feed-forward actor and
critic, no RND, no symmetry, the KL of the gradients' dtype); anything else runs rsl-rl's own update.
"""

from __future__ import annotations

import numpy as np
import torch

from wresdyn.ppo.update import PlainPPO

__all__ = ["PackedPPO", "next_learning_rate"]


def next_learning_rate(lr: float, higher: bool, lower: bool) -> float:
    """rsl-rl's adaptive rule on the host: ``lr`` / 1.5 (not below 1e-5) where the KL is above twice its target
    (``higher``), ``lr`` x 1.5 (not above 1e-2) where it is in (0, target / 2) (``lower``), else ``lr``."""
    if higher:
        return max(1e-5, lr / 1.5)
    if lower:
        return min(1e-2, lr * 1.5)
    return lr


class PackedPPO(PlainPPO):
    """rsl-rl's :class:`~rsl_rl.algorithms.PPO` with one collective and one host wait per mini-batch (see the
    module)."""

    def _flags_buffer(self) -> torch.Tensor:
        """A host tensor of 2 booleans (the KL tests) the device copies into without blocking: page-locked on CUDA,
        kept from one update to the next."""
        buf = getattr(self, "_flags", None)
        if buf is None:
            pin = torch.device(self.device).type == "cuda"
            buf = self._flags = torch.zeros(2, dtype=torch.bool, pin_memory=pin)
        return buf

    def update(self) -> dict[str, float]:
        if not self._plain():
            return super().update()
        adaptive = self.desired_kl is not None and self.schedule == "adaptive"
        cuda = torch.device(self.device).type == "cuda"
        flags = self._flags_buffer()
        params = [*self.actor.parameters(), *self.critic.parameters()]
        sums = torch.zeros(3, dtype=torch.float64, device=self.device)  # value, surrogate, entropy
        for batch in self.storage.mini_batch_generator(self.num_mini_batches, self.num_learning_epochs):
            loss, kl, logged = self._losses(batch, with_kl=adaptive)
            self.optimizer.zero_grad()
            loss.backward()
            if self.is_multi_gpu:
                kl = self._reduce(params, kl)
            if adaptive:
                # the same comparisons as rsl-rl's (a float32 tensor against a Python number), copied to the host
                # while the device goes on with the clips
                tests = torch.stack([kl > self.desired_kl * 2.0, (kl < self.desired_kl / 2.0) & (kl > 0.0)])
                flags.copy_(tests, non_blocking=cuda)
                copied = torch.cuda.Event() if cuda else None
                if copied is not None:
                    copied.record()
            torch.nn.utils.clip_grad_norm_(self.actor.parameters(), self.max_grad_norm)
            torch.nn.utils.clip_grad_norm_(self.critic.parameters(), self.max_grad_norm)
            if adaptive:
                if copied is not None:
                    copied.synchronize()  # the one wait of the mini-batch
                higher, lower = flags.numpy().tolist()  # a host buffer: no wait on the device
                self.learning_rate = next_learning_rate(self.learning_rate, higher, lower)
                if self.is_multi_gpu:  # rsl-rl broadcasts the rate as a float32 tensor
                    self.learning_rate = float(np.float32(self.learning_rate))
                for group in self.optimizer.param_groups:
                    group["lr"] = self.learning_rate
            self.optimizer.step()
            sums += logged.double()
        obs = self.storage.observations.flatten(0, 1)
        self.actor.update_normalization(obs)
        self.critic.update_normalization(obs)
        n = self.num_learning_epochs * self.num_mini_batches
        losses = [s / n for s in sums.tolist()]
        self.storage.clear()
        return dict(zip(("value", "surrogate", "entropy"), losses))

    def _reduce(self, params, kl: torch.Tensor | None) -> torch.Tensor | None:
        """Average the gradients of ``params`` (and the mini-batch KL, if given) over the processes in one
        all-reduce, as rsl-rl's bucket does (sum, then divide by the process count); the averaged KL."""
        grads = [p.grad.view(-1) for p in params if p.grad is not None]
        packed_kl = kl is not None and kl.dtype == grads[0].dtype
        packed = torch.cat([*grads, kl.view(1)] if packed_kl else grads)
        torch.distributed.all_reduce(packed, op=torch.distributed.ReduceOp.SUM)
        packed /= self.gpu_world_size
        n = sum(g.numel() for g in grads)
        torch._foreach_copy_(grads, list(torch.split(packed[:n], [g.numel() for g in grads])))
        if kl is None or packed_kl:
            return None if kl is None else packed[n]
        kl = kl.clone()  # a KL of another dtype (mixed precision) reduced on its own, as rsl-rl does
        torch.distributed.all_reduce(kl, op=torch.distributed.ReduceOp.SUM)
        return kl / self.gpu_world_size
