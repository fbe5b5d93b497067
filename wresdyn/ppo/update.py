"""rsl-rl's PPO update with one host synchronisation per update instead of several per mini-batch.

rsl-rl 5.5's ``PPO.update`` waits on the device about five times per mini-batch: the adaptive learning rate compares
the mini-batch's KL divergence with its target in Python (and, across processes, all-reduces the KL, broadcasts the
new rate from rank 0 and reads it back), and the value, surrogate and entropy losses are read back one by one for
the log. With 5 epochs x 4 mini-batches that is ~100 waits per iteration, each of which leaves the GPU idle while the
host launches the next kernels, and across processes each wait meets the other ranks' collectives in lock-step.

:class:`OneSyncPPO` computes the same update with the learning rate kept on the device: the KL test is a ``torch.where``
of rsl-rl's adaptive schedule (divide the rate by 1.5 where the mini-batch's KL exceeds twice the target, multiply it
by 1.5 below half of it, within [1e-5, 1e-2]), Adam takes the rate as a tensor, and across processes every rank
applies the rule to the same all-reduced KL (packed with the gradients into one all-reduce per mini-batch) instead of
receiving it from rank 0. The losses and the final rate are read back once, at the end, where rsl-rl's observation
normalisers (run unchanged) also wait on the device to upload their sample counts.

Only the plain case takes this path (a feed-forward actor and critic, no RND, no symmetry); anything else runs
rsl-rl's own update. Checkpoints are rsl-rl's: the learning rate is saved as a number.
"""

from __future__ import annotations

import torch
from rsl_rl.algorithms import PPO

__all__ = ["DeviceRate", "OneSyncPPO", "PlainPPO", "adapt_learning_rate"]

LR_MIN, LR_MAX, LR_FACTOR = 1e-5, 1e-2, 1.5
"""rsl-rl's adaptive-schedule bounds on the learning rate and its step factor."""


def adapt_learning_rate(lr: torch.Tensor, kl: torch.Tensor, desired_kl: float) -> torch.Tensor:
    """rsl-rl's adaptive learning rate, on the device: ``lr`` / 1.5 (not below 1e-5) where ``kl`` > 2 desired_kl,
    ``lr`` x 1.5 (not above 1e-2) where 0 < ``kl`` < desired_kl / 2, else ``lr``; 0-d tensors."""
    down = torch.clamp(lr / LR_FACTOR, min=LR_MIN)
    up = torch.clamp(lr * LR_FACTOR, max=LR_MAX)
    return torch.where(kl > desired_kl * 2.0, down, torch.where((kl < desired_kl / 2.0) & (kl > 0.0), up, lr))


class PlainPPO(PPO):
    """rsl-rl's :class:`~rsl_rl.algorithms.PPO` with its plain case's mini-batch losses in one method, for the updates
    that change only how the processes and the host meet (:class:`OneSyncPPO`,
    :class:`~wresdyn.ppo.packed_update.PackedPPO`); the same operations in the same order as rsl-rl's update."""

    def _plain(self) -> bool:
        return not (self.actor.is_recurrent or self.critic.is_recurrent or self.rnd or self.symmetry)

    def _actor_distribution(self, observations) -> None:
        """Set the actor's action distribution for ``observations`` as rsl-rl's update does (its forward pass, which
        also draws an action sample the update discards)."""
        self.actor(observations, stochastic_output=True)

    def _losses(self, batch, with_kl: bool) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
        """The mini-batch's loss (a 0-d tensor to back-propagate), its mean KL divergence from the rollout's policy
        (0-d, without gradient; None unless ``with_kl``) and the value, surrogate and entropy losses for the log
        (shape (3,), detached). Normalises ``batch.advantages`` in place where rsl-rl does."""
        if self.normalize_advantage_per_mini_batch:
            with torch.no_grad():
                batch.advantages = (batch.advantages - batch.advantages.mean()) / (batch.advantages.std() + 1e-8)
        with torch.amp.autocast(device_type=torch.device(self.device).type, enabled=self.use_mixed_precision,
                                dtype=torch.bfloat16):
            self._actor_distribution(batch.observations)
            log_prob = self.actor.get_output_log_prob(batch.actions)
            values = self.critic(batch.observations)
            entropy = self.actor.output_entropy
            kl = None
            if with_kl:
                with torch.inference_mode():
                    kl = torch.mean(self.actor.get_kl_divergence(batch.old_distribution_params,
                                                                 self.actor.output_distribution_params))
            ratio = torch.exp(log_prob - torch.squeeze(batch.old_actions_log_prob))
            advantages = torch.squeeze(batch.advantages)
            surrogate = torch.max(-advantages * ratio,
                                  -advantages * torch.clamp(ratio, 1.0 - self.clip_param, 1.0 + self.clip_param))
            surrogate_loss = surrogate.mean()
            if self.use_clipped_value_loss:
                clipped = batch.values + (values - batch.values).clamp(-self.clip_param, self.clip_param)
                value_loss = torch.max((values - batch.returns).pow(2), (clipped - batch.returns).pow(2)).mean()
            else:
                value_loss = (batch.returns - values).pow(2).mean()
            loss = surrogate_loss + self.value_loss_coef * value_loss - self.entropy_coef * entropy.mean()
        logged = torch.stack([value_loss.detach(), surrogate_loss.detach(), entropy.mean().detach()])
        return loss, kl, logged


class DeviceRate:
    """A PPO whose learning rate lives on the device while it updates (:class:`OneSyncPPO`,
    :class:`~wresdyn.ppo.graph_update.GraphPPO`): the rate as a tensor in Adam's groups, and checkpoints as rsl-rl's
    own update writes them (the rate a number, Adam's step counts on the host). Mixed into a PPO class."""

    def _device_lr(self) -> torch.Tensor:
        """The learning rate as a 0-d float64 tensor on the device, set in every parameter group (on CUDA Adam then
        runs ``capturable``: its step counts live on the device too, as a tensor rate needs). The tensor is kept
        and filled in place: a tensor made from a number would wait on the device to upload it."""
        lr = getattr(self, "_lr", None)
        if lr is None:
            lr = self._lr = torch.zeros((), dtype=torch.float64, device=self.device)
        lr.fill_(float(self.learning_rate))
        cuda = torch.device(self.device).type == "cuda"
        for group in self.optimizer.param_groups:
            group["lr"] = lr
            if cuda and not group.get("capturable"):
                group["capturable"] = True
                for p in group["params"]:
                    state = self.optimizer.state.get(p, {})
                    if "step" in state:
                        state["step"] = state["step"].to(device=self.device, dtype=torch.float32)
        return lr

    def save(self) -> dict:
        """rsl-rl's checkpoint, with the learning rate as a number and Adam's step counts on the host, as rsl-rl's own
        update saves them."""
        data = super().save()
        opt = data["optimizer_state_dict"]
        for group in opt["param_groups"]:
            group["lr"] = float(group["lr"])
            group["capturable"] = False
        # the per-parameter dicts are the live optimiser's: copied before the step counts move
        opt["state"] = {k: {**v, "step": v["step"].detach().to("cpu", torch.float32)} if torch.is_tensor(v.get("step"))
                        else v for k, v in opt["state"].items()}
        return data

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        out = super().load(loaded_dict, load_cfg, strict)
        self.learning_rate = float(self.learning_rate)
        return out


class OneSyncPPO(DeviceRate, PlainPPO):
    """rsl-rl's :class:`~rsl_rl.algorithms.PPO` whose update waits on the device once (see the module)."""

    def update(self) -> dict[str, float]:
        if not self._plain():
            return super().update()
        adaptive = self.desired_kl is not None and self.schedule == "adaptive"
        lr = self._device_lr()
        params = [p for p in (*self.actor.parameters(), *self.critic.parameters())]
        sums = torch.zeros(3, device=self.device)  # value, surrogate, entropy
        for batch in self.storage.mini_batch_generator(self.num_mini_batches, self.num_learning_epochs):
            loss, kl, logged = self._losses(batch, with_kl=adaptive or self.is_multi_gpu)
            self.optimizer.zero_grad()
            loss.backward()
            if self.is_multi_gpu:
                kl = self._reduce(params, kl)
            if adaptive:
                lr.copy_(adapt_learning_rate(lr, kl, self.desired_kl))
            torch.nn.utils.clip_grad_norm_(self.actor.parameters(), self.max_grad_norm)
            torch.nn.utils.clip_grad_norm_(self.critic.parameters(), self.max_grad_norm)
            self.optimizer.step()
            sums += logged.float()
        obs = self.storage.observations.flatten(0, 1)
        self.actor.update_normalization(obs)
        self.critic.update_normalization(obs)
        n = self.num_learning_epochs * self.num_mini_batches
        *losses, self.learning_rate = torch.cat([(sums / n).to(lr.dtype), lr.view(1)]).tolist()  # the one wait
        self.storage.clear()
        return dict(zip(("value", "surrogate", "entropy"), losses))

    def _reduce(self, params, kl: torch.Tensor) -> torch.Tensor:
        """Average the gradients of ``params`` and the mini-batch KL over the processes in one all-reduce; the
        averaged KL."""
        grads = [p.grad.view(-1) for p in params if p.grad is not None]
        packed = torch.cat([*grads, kl.detach().view(1).to(grads[0].dtype)])
        torch.distributed.all_reduce(packed, op=torch.distributed.ReduceOp.SUM)
        packed /= self.gpu_world_size
        torch._foreach_copy_(grads, list(torch.split(packed[:-1], [g.numel() for g in grads])))
        return packed[-1]
