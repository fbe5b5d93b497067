"""The packed PPO update with each mini-batch's whole step replayed from one CUDA graph.

:class:`~wresdyn.ppo.packed_update.PackedPPO` launches a mini-batch's step kernel by kernel from Python: on two H200s
the update of 5 epochs x 4 mini-batches spends ~150 ms an iteration, most of it the host issuing small kernels
(``benchmarks/results/speed/h200x2_20261130d/ppo90/profile_two.txt``), and at each mini-batch's all-reduce the two
processes wait for the slower host. :class:`GraphPPO` captures one mini-batch's step (the gather from the rollout,
forward passes and losses, backward, the gradients' and KL's all-reduce, rsl-rl's adaptive learning rate, both
gradient clips, Adam's step, the logged losses' sums) as a CUDA graph once and replays it for every mini-batch: per
mini-batch the host copies the mini-batch's indices into the graph's input and launches the graph. NCCL collectives
are capturable (NCCL >= 2.9, one GPU per process); both processes capture at the same mini-batch and replay the same
number of times.

What a replayed graph needs, and where it comes from:

- inputs at fixed addresses: rsl-rl's rollout storage allocates its tensors once; the advantages (a new tensor every
  rollout) are copied into a kept buffer, each mini-batch's slice of the permutation into a kept index buffer;
- no host decision inside: the learning rate is a device tensor adapted by rsl-rl's rule as a ``torch.where``
  (:func:`~wresdyn.ppo.update.adapt_learning_rate`), Adam runs ``capturable`` (:class:`~wresdyn.ppo.update.DeviceRate`);
  the host reads the losses and the rate once, at the end of the update;
- gradients set to ``None`` before the backward pass (as rsl-rl's ``zero_grad`` does), so the captured backward writes
  them instead of adding to them;
- the observation normalisers' std in one kept tensor: rsl-rl's normaliser assigns a new one at every update.

The graph is captured during the first update, after :data:`WARMUP` of its mini-batches have run the same step
eagerly on a side stream (real steps: the lazy initialisations a capture may not contain), and again whenever a
tensor it reads has been replaced (a checkpoint loaded into the optimiser).

The arithmetic is :class:`PackedPPO`'s except Adam's: on the CPU the step run eagerly (:meth:`GraphPPO.static_update`
with ``capture=False``; no CPU capture exists) equals :class:`PackedPPO` bit for bit, on one process and on two over
gloo (``tests/ppo/test_graph_update.py``). On CUDA, capturable Adam computes its bias corrections and step size on the
device in float32 where :class:`PackedPPO`'s Adam uses Python floats (as :class:`~wresdyn.ppo.update.OneSyncPPO`'s
does), so the weights differ in the last bits after the first step; the CUDA test bounds the difference
(:data:`CUDA_RTOL`). The random numbers of later rollouts differ too: the step draws no action sample, where rsl-rl's
forward pass draws one per mini-batch and discards it. Only the plain case in float32 and
uncompiled takes this path, on CUDA; anything else runs :class:`PackedPPO`'s eager update.
"""

from __future__ import annotations

import torch
from rsl_rl.storage import RolloutStorage

from wresdyn.ppo.packed_update import PackedPPO
from wresdyn.ppo.update import DeviceRate, adapt_learning_rate

__all__ = ["GraphPPO", "WARMUP", "CUDA_RTOL"]

WARMUP = 3
"""Eager mini-batches before the capture (PyTorch's whole-network capture example warms up 3 iterations on a side
stream: cuBLAS handles, autograd's streams and Adam's state are made there, outside the graph)."""

CUDA_RTOL = 1e-4
"""Relative tolerance of the captured update against :class:`PackedPPO` on CUDA, per weight and optimiser state
tensor after two updates (``max |a - b| <= CUDA_RTOL (max |b| + 1e-7)``, ``tests/ppo/test_graph_update.py``):
capturable Adam's float32 step size differs from the Python float one by about an ulp (1.2e-7 relative) per step;
the allowance lets 40 steps of a smooth loss carry that forward several hundredfold. Measured on two H200s over NCCL:
1.0e-5 to 1.8e-5 across the three KL settings, the rate equal on both ranks
(``benchmarks/results/speed/h200x2_20261130f/ppo_two_process/rank*.json``)."""


class _Static:
    """The tensors a captured step reads and writes besides the networks', kept from one update to the next."""

    def __init__(self, storage, mini_batch: int, device) -> None:
        n = storage.num_envs * storage.num_transitions_per_env
        self.advantages = torch.zeros(n, 1, device=device)
        """The rollout's advantages, flattened (storage's own are a new tensor every rollout), shape (T N, 1)."""
        self.index = torch.zeros(mini_batch, dtype=torch.long, device=device)
        """The mini-batch's rows of the flattened rollout, shape (mini-batch,)."""
        self.sums = torch.zeros(3, dtype=torch.float64, device=device)
        """The mini-batches' value, surrogate and entropy losses summed (float64, as :class:`PackedPPO` sums)."""


class GraphPPO(DeviceRate, PackedPPO):
    """:class:`~wresdyn.ppo.packed_update.PackedPPO` whose mini-batch step is one CUDA graph replay (see the module).

    Example: ``rsl_runner_cfg(..., graph_update=True)`` names this class as the runner's algorithm; on CUDA its update
    captures at the first call, ``static_update(capture=False)`` runs the same step eagerly (the CPU's tests)."""

    def _graphable(self) -> bool:
        return (self._plain() and not self.use_mixed_precision and self.actor is self._raw_actor
                and self.critic is self._raw_critic and getattr(self.actor, "distribution", None) is not None)

    def _actor_distribution(self, observations) -> None:
        """On the captured path, the actor's distribution from its network's output without the action sample
        rsl-rl's forward pass draws and the update discards: CUDA's generator refused that draw inside the capture
        (the stream is capturing) on an H200, and the loss does not depend on the sample. Run eagerly, rsl-rl's."""
        if not getattr(self, "_capturing_path", False):
            return super()._actor_distribution(observations)
        actor = self.actor
        actor.distribution.update(actor.mlp(actor.get_latent(observations)))

    def update(self) -> dict[str, float]:
        if torch.device(self.device).type != "cuda" or not self._graphable():
            return super().update()
        return self.static_update(capture=True)

    def static_update(self, capture: bool) -> dict[str, float]:
        """The update through the step on kept tensors: replayed from a CUDA graph (``capture``; CUDA only) or run
        eagerly. The same mini-batches as rsl-rl's generator (one permutation drawn the same way for all epochs)."""
        adaptive = self.desired_kl is not None and self.schedule == "adaptive"
        st = self.storage
        mini_batch = st.num_envs * st.num_transitions_per_env // self.num_mini_batches
        lr = self._device_lr()
        self._capturing_path = capture
        self._pin_normalisers()
        static = getattr(self, "_static", None)
        if (static is None or static.index.numel() != mini_batch
                or static.advantages.shape[0] != st.num_envs * st.num_transitions_per_env):
            static = self._static = _Static(st, mini_batch, self.device)
            self._graph, self._warm = None, 0
        static.advantages.copy_(st.advantages.flatten(0, 1))
        static.sums.zero_()
        if capture and getattr(self, "_graph", None) is not None and self._graph_inputs != self._inputs():
            self._graph, self._warm = None, 0  # a tensor the graph reads was replaced: captured again
        indices = torch.randperm(self.num_mini_batches * mini_batch, requires_grad=False, device=self.device)
        for _ in range(self.num_learning_epochs):
            for i in range(self.num_mini_batches):
                static.index.copy_(indices[i * mini_batch:(i + 1) * mini_batch])
                if not capture:
                    self._step(adaptive, lr, static)
                else:
                    self._replay(adaptive, lr, static)
        obs = st.observations.flatten(0, 1)
        self.actor.update_normalization(obs)
        self.critic.update_normalization(obs)
        self._pin_normalisers()
        n = self.num_learning_epochs * self.num_mini_batches
        # PackedPPO divides the float64 sums by n on the host: the same IEEE division
        *losses, self.learning_rate = torch.cat([static.sums / n, lr.view(1)]).tolist()  # the update's one wait
        st.clear()
        return dict(zip(("value", "surrogate", "entropy"), losses))

    def _step(self, adaptive: bool, lr: torch.Tensor, static: _Static) -> None:
        """One mini-batch's step on the kept tensors, in :class:`PackedPPO`'s order of operations."""
        st, idx = self.storage, static.index
        batch = RolloutStorage.Batch(
            observations=st.observations.flatten(0, 1)[idx], actions=st.actions.flatten(0, 1)[idx],
            values=st.values.flatten(0, 1)[idx], advantages=static.advantages[idx],
            returns=st.returns.flatten(0, 1)[idx], old_actions_log_prob=st.actions_log_prob.flatten(0, 1)[idx],
            old_distribution_params=tuple(p.flatten(0, 1)[idx] for p in st.distribution_params))
        loss, kl, logged = self._losses(batch, with_kl=adaptive)
        self.optimizer.zero_grad()  # to None: a captured backward then writes the gradients, never adds to them
        loss.backward()
        if self.is_multi_gpu:
            kl = self._reduce([*self.actor.parameters(), *self.critic.parameters()], kl)
        if adaptive:
            new = adapt_learning_rate(lr, kl, self.desired_kl)
            # rsl-rl broadcasts the rate as a float32 tensor across processes: the same rounding
            lr.copy_(new.float() if self.is_multi_gpu else new)
        torch.nn.utils.clip_grad_norm_(self.actor.parameters(), self.max_grad_norm)
        torch.nn.utils.clip_grad_norm_(self.critic.parameters(), self.max_grad_norm)
        self.optimizer.step()
        static.sums += logged.double()

    def _replay(self, adaptive: bool, lr: torch.Tensor, static: _Static) -> None:
        """The mini-batch's step on CUDA: eager on a side stream for the first :data:`WARMUP`, then captured once
        (a capture runs nothing, so the captured mini-batch is replayed too) and replayed."""
        graph = getattr(self, "_graph", None)
        if graph is None:
            def step():
                self._step(adaptive, lr, static)

            warm = getattr(self, "_warm", 0)
            if warm == 0:
                self._release_actor_graph(static)
            if warm < WARMUP:
                self._warm = warm + 1
                return self._on_side_stream(step)
            self._release_actor_graph(static)
            graph = self._graph = self._capture(step)
            self._graph_inputs = self._inputs()
        graph.replay()

    def _release_actor_graph(self, static: _Static) -> None:
        """Replace the actor's kept distribution by one made without gradient. The kept one's autograd graph keeps
        the parameters' gradient accumulators alive, and an accumulator stays on the stream it was made on: made by
        an eager update on the default stream, the captured backward would end by recording an event on the legacy
        stream while the capture runs, which CUDA refuses (``cudaErrorStreamCaptureImplicit`` on an H200). Released
        before the first warm-up and before the capture, they are made again on the side stream."""
        with torch.no_grad():
            self._actor_distribution(self.storage.observations.flatten(0, 1)[static.index])

    def _side_stream(self) -> "torch.cuda.Stream":
        """The one side stream of the warm-ups and the capture (made at the first call). One stream for both keeps
        the step's gradient accumulators on the capturing stream, so the captured backward waits on no event
        recorded outside the capture (the gradient fit's graphed step does the same on its simulator's stream)."""
        side = getattr(self, "_side", None)
        if side is None:
            side = self._side = torch.cuda.Stream(device=self.device)
        return side

    def _on_side_stream(self, step) -> None:
        """Run ``step`` on the side stream, ordered after and before the current stream's work (PyTorch's warm-up
        for a capture: autograd's and Adam's lazily made state then never comes from inside a graph)."""
        side = self._side_stream()
        side.wait_stream(torch.cuda.current_stream(self.device))
        with torch.cuda.stream(side):
            step()
        torch.cuda.current_stream(self.device).wait_stream(side)

    def _capture(self, step) -> "torch.cuda.CUDAGraph":
        """``step`` captured as a CUDA graph on the side stream (not run)."""
        side = self._side_stream()
        side.wait_stream(torch.cuda.current_stream(self.device))
        graph = torch.cuda.CUDAGraph()
        # thread-local: the NCCL watchdog's thread may query the events of earlier collectives meanwhile, which a
        # global capture would count as an unsafe call and abort on
        with torch.cuda.graph(graph, stream=side, capture_error_mode="thread_local"):
            step()
        torch.cuda.current_stream(self.device).wait_stream(side)
        return graph

    def _inputs(self) -> tuple[int, ...]:
        """The addresses of every tensor a captured step reads or writes besides its own intermediates: the
        networks' parameters and buffers, Adam's state, the rollout storage, the kept tensors."""
        st, static = self.storage, self._static
        tensors = [*self.actor.state_dict().values(), *self.critic.state_dict().values(), self._lr,
                   static.advantages, static.index, static.sums, st.actions, st.values, st.returns,
                   st.actions_log_prob, *st.distribution_params, *st.observations.values()]
        tensors += [t for s in self.optimizer.state.values() for t in s.values() if torch.is_tensor(t)]
        return tuple(t.data_ptr() for t in tensors)

    def _pin_normalisers(self) -> None:
        """Keep each observation normaliser's std in one tensor: rsl-rl's ``update`` assigns a new one, which a
        graph captured before would not read. The values are copied; the arithmetic is unchanged."""
        pinned = self.__dict__.setdefault("_pinned_std", {})
        for name, model in (("actor", self.actor), ("critic", self.critic)):
            norm = getattr(model, "obs_normalizer", None)
            std = getattr(norm, "_std", None)
            if not torch.is_tensor(std):
                continue
            kept = pinned.get(name)
            if kept is None or kept.shape != std.shape or kept.device != std.device:
                kept = pinned[name] = std.detach().clone()
            elif kept is not std:
                kept.copy_(std)
            norm._std = kept
