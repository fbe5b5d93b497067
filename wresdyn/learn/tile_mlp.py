"""One step of :class:`~wresdyn.learn.fused_mlp.FusedMLPRollout` as two Warp tile kernels (its opt-in ``tiles``).

On a GPU the fused path's step is still ~24 small torch kernels (normalise, an addmm and an ELU per layer, clamp, the
clip's mask and the scale; in the backward pass the gradients' sum, the mask, a GEMM and an ELU backward per layer),
each ~2-3 µs of launch latency whatever its size. :class:`TileMLP` runs the forward as one kernel and the backward as
one: a block of ``rows`` windows carries its activations through every layer in shared memory (Warp's tile API,
``wp.tile_matmul``: Warp's own tile GEMM, or MathDx's with :attr:`TileBlock.mathdx`). Weights larger than a block's
shared memory (256x128 float32 is 128 KB) are read in chunks of ``chunk`` rows of the reduction dimension, as stored
(the forward reads each weight from a transposed copy); every tile dimension is padded to a multiple of ``chunk``
(loads out of bounds read zeros, stores out of bounds are skipped), so the padding adds zeros to each sum. The forward
forms the observation [q, q̇, q̈, q_cmd] (+ noise) from the rollout's tensors (:meth:`TileMLP.forward_state`), and the
backward hands the gradients back to them (:meth:`TileMLP.backward_state`): a rollout runs no kernel of its own for
them.

The kernels write the per-step buffers :meth:`FusedMLPRollout.finish` reads (each layer's input, each hidden layer's
pre-activation, the gradients at the layer outputs, the clip's mask) and compute the same operations as the torch
path; the sums inside the GEMMs run in another order, so the values agree to float32 rounding, not bit for bit.

The kernels are generated per network shape (a layer count the kernel's arguments depend on) and cached per shape;
they launch on torch's current stream, so a CUDA graph torch captures includes them.
"""

from __future__ import annotations

import dataclasses
import linecache
import os
import re

import torch

from ..sim import prebuilt
from ..sim.devices import torch_stream_for_warp

__all__ = ["ENV_BLOCK", "TileBlock", "TileMLP"]

ENV_BLOCK = "WRESDYN_TILE_BLOCK"
"""The environment variable that picks :class:`TileMLP`'s default block (:meth:`TileBlock.from_env`)."""


@dataclasses.dataclass(frozen=True)
class TileBlock:
    """How :class:`TileMLP`'s kernels split the work."""

    rows: int = 8
    """Windows per block (the GEMMs' M). 8 with 256 threads was the fastest of 14 splits on an H200 at 1024 windows
    (one step forward + backward replayed from a CUDA graph: 91 µs against 166 at 16 rows and 128 threads;
    ``benchmarks/results/speed/h200_20261201f/``): fewer rows a block put more of the GPU's multiprocessors to work."""
    chunk: int = 32
    """Rows of the reduction dimension read from a weight (or its transposed copy) at a time; every tile dimension is
    padded to a multiple of it. 256x32 float32 is 32 KB: the largest shared tiles stay ~130 KB a block (an H200 has
    ~227 KB)."""
    threads: int = 256
    """Threads per block."""
    mathdx: bool = False
    """On CUDA, the GEMMs through MathDx (cuBLASDx) rather than Warp's own tile GEMM. Off: on an H200 it is no faster at
    the fit's shapes (172 against 166 µs a step, ``benchmarks/results/speed/h200_20261201e/``), and NVRTC's compile of
    the network's two kernels with MathDx took 124 + 136 s on a 2-core CPU (sm_90), a first run's wait on a fresh
    machine."""

    @classmethod
    def parse(cls, text: str) -> TileBlock:
        """``ROWSxCHUNKxTHREADS`` with an optional ``m`` for :attr:`mathdx` (``16x32x128m``)."""
        match = re.fullmatch(r"\s*(\d+)x(\d+)x(\d+)(m?)\s*", text)
        if match is None or 0 in (rows := int(match[1]), chunk := int(match[2]), threads := int(match[3])):
            raise ValueError(f"{text!r} is not ROWSxCHUNKxTHREADS[m] of positive integers (e.g. 16x32x128m)")
        return cls(rows, chunk, threads, match[4] == "m")

    @classmethod
    def from_env(cls) -> TileBlock:
        """The block ``$WRESDYN_TILE_BLOCK`` names (:meth:`parse`'s format), the defaults where it is unset or empty:
        the benchmarks and the fit pick a split without a config field."""
        given = os.environ.get(ENV_BLOCK, "").strip()
        if not given:
            return cls()
        try:
            return cls.parse(given)
        except ValueError as e:
            raise ValueError(f"{ENV_BLOCK}: {e}") from None

_FUNCS = '''
@wp.func
def _normalise(o: float, m: float, s: float):
    # a zero std is only the padding's (the policy's stds are positive): keep it out of the sums
    if s == 0.0:
        return 0.0
    return (o - m) / s


@wp.func
def _rate(v: float, before: float, dt: float):
    # the rollout's q̈ = (q̇ - q̇ before) / dt, as its torch operations
    return (v - before) / dt


@wp.func
def _elu(z: float):
    if z > 0.0:
        return z
    return ALPHA * (wp.exp(z) - 1.0)


@wp.func
def _elu_backward(g: float, z: float):
    # torch's elu_backward at scale 1, input_scale 1: g * alpha * exp(z) where z <= 0
    if z <= 0.0:
        return g * ALPHA * wp.exp(z)
    return g


@wp.func
def _clamp(y: float):
    return wp.clamp(y, -1.0, 1.0)


@wp.func
def _inside(y: float):
    # clamp's backward passes the gradient where -1 <= y <= 1 (NaN: neither), the torch path's c == y
    if y >= -1.0 and y <= 1.0:
        return wp.uint8(1)
    return wp.uint8(0)


@wp.func
def _out_grad(gr: float, ga: float, s: float, m: wp.uint8):
    # residual_grad's g_r + g_a / scale (a missing one loads as zeros), then the product's and the clip's backward
    if m != wp.uint8(0):
        return (gr + ga / s) * s
    return 0.0
'''


def _pad(d: int, chunk: int) -> int:
    return -(-d // chunk) * chunk


def _matmul_lines(x: str, w: str, n_in: int, n_out: int, chunk: int) -> list[str]:
    """``acc_<w>`` = x @ w, w (n_in, n_out), reading w in chunks of ``chunk`` rows (the reduction dimension n_in).

    w is read as stored, never through a transposed view: the scalar GEMM's threads read adjacent columns of a chunk,
    adjacent shared-memory banks, where through a transposed view of an (n_out, chunk) chunk they read addresses a
    multiple of 32 floats apart, one bank, one at a time."""
    # one name per product: Warp merges a name assigned in a branch with its value before, which needs one shape
    return [f"acc_{w} = wp.tile_zeros(shape=(TB, {n_out}), dtype=float)",
            f"for c in range({n_in // chunk}):",
            f"    wc_{w} = wp.tile_load({w}, shape=({chunk}, {n_out}), offset=(c * KC, 0), storage='shared')",
            f"    wp.tile_matmul(wp.tile_view({x}, offset=(0, c * KC), shape=(TB, KC)), wc_{w}, acc_{w})"]


def _sources(dims: list[int], chunk: int) -> tuple[str, str]:
    """The forward and backward kernels' source for a network of layer widths ``dims`` (input first)."""
    p = [_pad(d, chunk) for d in dims]
    n = len(dims) - 1
    f32 = "wp.array{}d(dtype=float)"
    a1, a2, a3, u3 = f32.format(1), f32.format(2), f32.format(3), "wp.array3d(dtype=wp.uint8)"
    ws = [f"wt{i}: {a2}, b{i}: {a1}" for i in range(n)]  # each weight transposed, (in, out)
    xs, zs, gs = ([f"{c}{i}: {a3}" for i in range(m)] for c, m in (("x", n), ("z", n - 1), ("g", n)))
    nj = dims[0] // 4  # the observation's four pieces [q, q̇, q̈, q_cmd], a joint each
    fwd = [f"def tile_mlp_forward(s_q: {a2}, s_qd: {a2}, s_prev: {a2}, s_rate: {a2}, first: int, s_cmd: {a2}, "
           f"noise: {a3}, has_noise: int, dt: float, k: int, mean: {a1}, std: {a1}, scale: {a1}, both: int, "
           + ", ".join(ws + xs + zs) + f", mask: {u3}, out: {a2}, action: {a2}):",
           "r0 = wp.tid() * TB",
           f"x = wp.tile_zeros(shape=(TB, {p[0]}), dtype=float, storage='shared')",
           f"o0 = wp.tile_load(s_q, shape=(TB, {nj}), offset=(r0, 0))",
           f"o1 = wp.tile_load(s_qd, shape=(TB, {nj}), offset=(r0, 0))",
           f"o2 = wp.tile_load(s_rate, shape=(TB, {nj}), offset=(r0, 0))",  # the first step's recorded q̈
           "if first == 0:",  # later steps: the rollout's (q̇ - q̇ before) / dt
           f"    o2 = wp.tile_map(_rate, o1, wp.tile_load(s_prev, shape=(TB, {nj}), offset=(r0, 0)), "
           f"wp.tile_full(shape=(TB, {nj}), value=dt, dtype=float))",
           f"o3 = wp.tile_load(s_cmd, shape=(TB, {nj}), offset=(r0, 0))"]
    for i in range(4):
        fwd += ["if has_noise != 0:",
                f"    o{i} = wp.tile_map(wp.add, o{i}, "
                f"wp.tile_load(noise[k], shape=(TB, {nj}), offset=(r0, {i * nj})))",
                f"mu = wp.tile_broadcast(wp.tile_load(mean, shape=({nj},), offset=({i * nj},)), shape=(TB, {nj}))",
                f"sd = wp.tile_broadcast(wp.tile_load(std, shape=({nj},), offset=({i * nj},)), shape=(TB, {nj}))",
                f"wp.tile_assign(x, wp.tile_map(_normalise, o{i}, mu, sd), offset=(0, {i * nj}))"]
    fwd.append("wp.tile_store(x0[k], x, offset=(r0, 0))")
    for i in range(n):
        fwd += _matmul_lines("x", f"wt{i}", p[i], p[i + 1], chunk)
        fwd.append(f"y = acc_wt{i} + wp.tile_broadcast(wp.tile_load(b{i}, shape=({p[i + 1]},)), "
                   f"shape=(TB, {p[i + 1]}))")
        if i < n - 1:
            fwd += [f"wp.tile_store(z{i}[k], y, offset=(r0, 0))", "x = wp.tile_map(_elu, y)",
                    f"wp.tile_store(x{i + 1}[k], x, offset=(r0, 0))"]
    fwd += ["wp.tile_store(mask[k], wp.tile_map(_inside, y), offset=(r0, 0))",
            f"s = wp.tile_broadcast(wp.tile_load(scale, shape=({p[n]},)), shape=(TB, {p[n]}))",
            "r = wp.tile_map(wp.mul, wp.tile_map(_clamp, y), s)",
            "wp.tile_store(out, r, offset=(r0, 0))",
            "if both != 0:",
            "    wp.tile_store(action, wp.tile_map(wp.div, r, s), offset=(r0, 0))"]
    bwd = [f"def tile_mlp_backward(g_r: {a2}, g_a: {a2}, k: int, scale: {a1}, std: {a1}, need_obs: int, "
           + ", ".join([f"w{i}: {a2}" for i in range(n)] + zs + gs)
           + f", mask: {u3}, combine: int, add: int, dt: float, " + ", ".join(f"o{i}: {a2}" for i in range(4))
           + "):",
           "r0 = wp.tid() * TB",
           f"s = wp.tile_broadcast(wp.tile_load(scale, shape=({p[n]},)), shape=(TB, {p[n]}))",
           f"gr = wp.tile_load(g_r, shape=(TB, {p[n]}), offset=(r0, 0))",
           f"ga = wp.tile_load(g_a, shape=(TB, {p[n]}), offset=(r0, 0))",
           f"m = wp.tile_load(mask[k], shape=(TB, {p[n]}), offset=(r0, 0))",
           "g = wp.tile_map(_out_grad, gr, ga, s, m)",
           f"wp.tile_store(g{n - 1}[k], g, offset=(r0, 0))"]
    for i in range(n - 1, 0, -1):
        bwd += _matmul_lines("g", f"w{i}", p[i + 1], p[i], chunk)
        bwd += [f"zt = wp.tile_load(z{i - 1}[k], shape=(TB, {p[i]}), offset=(r0, 0))",
                f"g = wp.tile_map(_elu_backward, acc_w{i}, zt)",
                f"wp.tile_store(g{i - 1}[k], g, offset=(r0, 0))"]
    # the normalisation's backward: sub passes the gradient through, div divides by std
    bwd += ["if need_obs != 0:"] + ["    " + line for line in _matmul_lines("g", "w0", p[1], p[0], chunk)]
    bwd += [f"    sd = wp.tile_broadcast(wp.tile_load(std, shape=({p[0]},)), shape=(TB, {p[0]}))",
            "    go = wp.tile_map(wp.div, acc_w0, sd)"]
    bwd += [f"    gp{i} = wp.tile_view(go, offset=(0, {i * nj}), shape=(TB, {nj}))" for i in range(4)]
    # combine: the gradients of the state the pieces came from (q, q̇, the q̇ before; q̈ = (q̇ - q̇ before) / dt); add
    # (with combine): added to what o0, o1, o2 hold (each block its own rows), not stored over it
    load = [f"wp.tile_load(o{i}, shape=(TB, {nj}), offset=(r0, 0))" for i in range(3)]
    bwd += ["    if add != 0:",
            f"        wp.tile_store(o0, wp.tile_map(wp.add, gp0, {load[0]}), offset=(r0, 0))",
            f"        h2d = wp.tile_map(wp.div, gp2, wp.tile_full(shape=(TB, {nj}), value=dt, dtype=float))",
            f"        wp.tile_store(o1, wp.tile_map(wp.add, wp.tile_map(wp.add, gp1, h2d), {load[1]}), offset=(r0, 0))",
            f"        wp.tile_store(o2, wp.tile_map(wp.sub, {load[2]}, h2d), offset=(r0, 0))",
            "    else:", "        wp.tile_store(o0, gp0, offset=(r0, 0))", "        if combine != 0:",
            f"            g2d = wp.tile_map(wp.div, gp2, wp.tile_full(shape=(TB, {nj}), value=dt, dtype=float))",
            "            wp.tile_store(o1, wp.tile_map(wp.add, gp1, g2d), offset=(r0, 0))",
            "            wp.tile_store(o2, wp.tile_map(wp.neg, g2d), offset=(r0, 0))", "        else:"]
    bwd += [f"            wp.tile_store(o{i}, gp{i}, offset=(r0, 0))" for i in (1, 2, 3)]
    body = lambda lines: "\n".join([lines[0]] + ["    " + line for line in lines[1:]])  # noqa: E731
    return body(fwd), body(bwd)


_KERNELS: dict[tuple, tuple] = {}


def _kernels(dims: tuple[int, ...], alpha: float, rows: int, chunk: int, mathdx: bool):
    """(forward, backward) Warp kernels for this shape, built once per process (Warp caches their binaries)."""
    key = (dims, alpha, rows, chunk, mathdx)
    if key not in _KERNELS:
        import warp as wp

        fwd, bwd = _sources(list(dims), chunk)
        head = "\n\n\n@wp.kernel(module='unique', enable_backward=False, module_options=OPTIONS)\n"
        src = _FUNCS + head + fwd + head + bwd + "\n"
        # Warp reads a kernel's source back through inspect: register the generated text under its own file name
        name = f"<wresdyn.tile_mlp {'-'.join(map(str, dims))} a{alpha} tb{rows} kc{chunk} dx{int(mathdx)}>"
        linecache.cache[name] = (len(src), None, src.splitlines(True), name)
        # max_unroll 0: an unrolled chunk loop would hold every chunk of a weight in shared memory at once
        options = {"max_unroll": 0, "enable_mathdx_gemm": mathdx}
        scope = {"wp": wp, "TB": rows, "KC": chunk, "ALPHA": float(alpha), "OPTIONS": options}
        exec(compile(src, name, "exec"), scope)  # noqa: S102 (source built above from integers only)
        _KERNELS[key] = scope["tile_mlp_forward"], scope["tile_mlp_backward"]
    return _KERNELS[key]


def _wp(t: torch.Tensor):
    import warp as wp

    # requires_grad=False: Warp would otherwise attach (and allocate) the tensor's .grad
    return wp.from_torch(t, requires_grad=False)


class TileMLP:
    """The forward and backward of one rollout step of an ELU MLP residual (float32) of layer widths ``dims`` (input
    first) as one Warp kernel each, split as ``block`` says (:meth:`TileBlock.from_env` where ``None``). Modules the
    prebuilt kernels (:mod:`wresdyn.sim.prebuilt`) hold exactly are copied into Warp's cache, not compiled."""

    def __init__(self, dims: list[int], alpha: float, device: torch.device, block: TileBlock | None = None) -> None:
        import warp as wp

        wp.init()
        prebuilt.enable()  # a MathDx module compiled ahead (benchmarks/speed/prebuild_tiles.py) skips minutes of NVRTC
        block = block or TileBlock.from_env()
        self.dims, self.rows, self.threads = list(dims), block.rows, block.threads
        self.forward_kernel, self.backward_kernel = _kernels(tuple(dims), float(alpha), block.rows, block.chunk,
                                                             block.mathdx)
        self.device = wp.device_from_torch(device)
        self._empty = _wp(torch.zeros(0, dims[-1], device=device))
        self._empty3 = _wp(torch.zeros(0, 0, 0, device=device))
        self.torch_device = torch.device(device)
        self._bufs = self._policy = self._wt = None
        self._streams: dict[int, tuple] = {}

    def bind(self, policy=None, linears=(), x=(), z=(), g=(), mask: torch.Tensor | None = None) -> None:
        """The rollout's policy, its linear layers and (H, B, ·) buffers (:meth:`FusedMLPRollout.begin`), viewed for
        Warp once per rollout, not at every step; no ``policy``: let them go."""
        if policy is None:
            self._bufs = self._policy = self._wt = None
            return
        self._bufs = [_wp(t) for t in x], [_wp(t) for t in z], [_wp(t) for t in g], _wp(mask.view(torch.uint8))
        # the forward reads each weight transposed (_matmul_lines): copied here, once per rollout (a captured
        # iteration copies the weights Adam left)
        self._wt = [lin.weight.detach().t().contiguous() for lin in linears]
        self._policy = ([_wp(t) for wt, lin in zip(self._wt, linears) for t in (wt, lin.bias)],
                        [_wp(lin.weight) for lin in linears],
                        *(_wp(t) for t in (policy.obs_mean, policy.obs_std, policy.scale)))

    def _launch(self, kernel, batch: int, args: list) -> None:
        import warp as wp

        wp.launch_tiled(kernel, dim=[-(-batch // self.rows)], inputs=args, block_dim=self.threads, device=self.device,
                        stream=self._stream())

    def _stream(self):
        """Torch's current stream as a Warp stream, so that a CUDA graph torch captures holds the launches (``None``
        on the CPU and on torch's default stream, as :class:`~wresdyn.sim.Simulator` runs its steps)."""
        return torch_stream_for_warp(self.device.ordinal, self._streams) if self.device.is_cuda else None

    def forward(self, obs: torch.Tensor, k: int, out: torch.Tensor | None, both: bool):
        """Step ``k``'s residual (into ``out`` where given) and with ``both`` its action residual / scale, of the raw
        observation ``obs`` (N, 4n)."""
        q, qd, rate, cmd = self._pieces(obs)
        return self.forward_state(q, qd, None, rate, cmd, None, 1.0, k, out, both)

    def forward_state(self, q, qd, before, rate, cmd, noise, dt: float, k: int, out: torch.Tensor | None, both: bool):
        """:meth:`forward` of the observation [q, q̇, q̈, q_cmd] (+ ``noise[k]``) the kernel forms from the rollout's
        tensors: q, q̇ (N, n), the q̇ before (``None``: the window's first step, whose q̈ is ``rate``, else
        q̈ = (q̇ - before) / ``dt``), the command (N, n) and the scaled noise (H, N, 4n) or ``None``."""
        x, z, _, mask = self._bufs
        params, _, mean, std, scale = self._policy
        batch, first = q.shape[0], before is None
        r = torch.empty(batch, self.dims[-1], device=q.device, dtype=torch.float32) if out is None else out
        a = torch.empty_like(r) if both else r
        pieces = [_wp(q), _wp(qd), self._empty if first else _wp(before), _wp(rate) if first else self._empty,
                  int(first), _wp(cmd), self._empty3 if noise is None else _wp(noise), int(noise is not None)]
        self._launch(self.forward_kernel, batch, [*pieces, float(dt), k, mean, std, scale, int(both), *params, *x, *z,
                                                  mask, _wp(r), _wp(a)])
        r = r.view(r.shape)  # a fresh view as the step's output: autograd marks it, not the tensor handed in
        return (r, a) if both else r

    def _pieces(self, t: torch.Tensor) -> list[torch.Tensor]:
        n = self.dims[0] // 4
        return [t[:, i * n:(i + 1) * n] for i in range(4)]

    def backward(self, g_r, g_a, k: int, need_obs: bool) -> torch.Tensor | None:
        """The gradients at step ``k``'s layer outputs into the rollout's buffers, and the observation's gradient when
        ``need_obs``."""
        g_obs = torch.empty(self._batch(), self.dims[0], device=self.torch_device, dtype=torch.float32) \
            if need_obs else None
        self._backward(g_r, g_a, k, need_obs, False, 1.0, self._pieces(g_obs) if need_obs else [None] * 4)
        return g_obs

    def backward_state(self, g_r, g_a, k: int, need: bool, dt: float):
        """:meth:`backward` of :meth:`forward_state`: the gradients of q, q̇ and the q̇ before, (N, n) each (``None``
        without ``need``)."""
        outs = [torch.empty(self._batch(), self.dims[0] // 4, device=self.torch_device, dtype=torch.float32)
                for _ in range(3)] if need else [None] * 3
        self._backward(g_r, g_a, k, need, True, dt, outs + [None])
        return tuple(outs)

    def backward_state_into(self, g_r, g_a, k: int, need: bool, dt: float, q_grad, qd_grad, before_grad) -> None:
        """:meth:`backward_state` adding the gradients of q, q̇ and the q̇ before into ``q_grad``, ``qd_grad`` and
        ``before_grad`` (N, n) each (``before_grad`` ``None`` at the window's first step), where the state's gradient
        is summed in place (:mod:`wresdyn.sim.tape_chain`); nothing is added without ``need``."""
        if need and before_grad is None:
            raise ValueError("the window's first step forms q̈ from the recording: its q̇ before has no gradient")
        self._backward(g_r, g_a, k, need, True, dt, [q_grad, qd_grad, before_grad, None], add=True)

    def _batch(self) -> int:
        return self._bufs[2][0].shape[1]

    def _backward(self, g_r, g_a, k: int, need: bool, combine: bool, dt: float, outs: list, add: bool = False) -> None:
        _, z, g, mask = self._bufs
        _, weights, _, std, scale = self._policy
        grads = [self._empty if t is None else _wp(t) for t in (g_r, g_a)]
        self._launch(self.backward_kernel, self._batch(), [*grads, k, scale, std, int(need), *weights, *z, *g, mask,
                                                           int(combine), int(add), float(dt),
                                                           *(self._empty if t is None else _wp(t) for t in outs)])
