"""rsl-rl's episode bookkeeping without a host wait per environment step (``ppo.deferred_episode_log``).

rsl-rl's ``Logger.process_env_step`` runs on the rank that writes the logs at every step of the rollout: it finds the
worlds whose episode ended (``nonzero``) and copies their reward sums and lengths to the host, so on CUDA the host
waits for the device at each of the 24 steps of an iteration and cannot launch the next step ahead. Rank 0 does it
and the other ranks do not, so rank 0 is also the slower one at the update's first collective.
:func:`defer_episode_log` keeps the same sums on the device, records each step's ended worlds and their totals there,
and copies them to the host once per iteration, when rsl-rl logs the iteration (outside its collection and learning
times, where its other logging already runs): the reward and length buffers then hold the same numbers in the same
order as rsl-rl's. What is learned does not depend on it (the buffers are only logged). rsl-rl's intrinsic-reward
(RND) bookkeeping is not deferred: with RND the logger keeps its own per-step path.
"""

from __future__ import annotations

import torch

__all__ = ["defer_episode_log", "flush_episode_log"]


def defer_episode_log(logger) -> None:
    """Replace ``logger``'s (an rsl-rl ``Logger``) per-step episode bookkeeping by the deferred one (see the module);
    :func:`flush_episode_log` moves what is pending into its buffers, as its ``log`` now does first."""
    step, log = logger.process_env_step, logger.log
    logger._pending_episodes = []

    def process_env_step(rewards, dones, extras, intrinsic_rewards=None):
        if logger.writer is None or intrinsic_rewards is not None:
            return step(rewards, dones, extras, intrinsic_rewards)
        if "episode" in extras:
            logger.ep_extras.append(extras["episode"])
        elif "log" in extras:
            logger.ep_extras.append(extras["log"])
        logger.cur_reward_sum += rewards
        logger.cur_episode_length += 1
        ended = (dones > 0).view(-1)
        # the totals as rsl-rl reads them (before the ended worlds are zeroed), kept on the device
        logger._pending_episodes.append((ended, logger.cur_reward_sum.clone(), logger.cur_episode_length.clone()))
        logger.cur_reward_sum.masked_fill_(ended, 0)
        logger.cur_episode_length.masked_fill_(ended, 0)

    def logged(*args, **kwargs):
        flush_episode_log(logger)
        return log(*args, **kwargs)

    logger.process_env_step, logger.log = process_env_step, logged


def flush_episode_log(logger) -> None:
    """Move the deferred steps' ended episodes into ``logger.rewbuffer`` and ``lenbuffer`` (one copy to the host),
    step by step and world by world, as rsl-rl's per-step path adds them."""
    pending = getattr(logger, "_pending_episodes", None)
    if not pending:
        return
    ended = torch.stack([e for e, _, _ in pending]).cpu()
    sums = torch.stack([torch.stack([r, n]) for _, r, n in pending]).cpu()  # (steps, 2, worlds)
    pending.clear()
    for mask, (rew, length) in zip(ended, sums):
        if mask.any():
            logger.rewbuffer.extend(rew[mask].numpy().tolist())
            logger.lenbuffer.extend(length[mask].numpy().tolist())
