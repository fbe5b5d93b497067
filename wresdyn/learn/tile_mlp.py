"""One step of :class:`~wresdyn.learn.fused_mlp.FusedMLPRollout` as two Warp tile kernels (its opt-in ``tiles``).

On a GPU the fused path's step is still ~24 small torch kernels (normalise, an addmm and an ELU per layer, clamp, the
clip's mask and the scale; in the backward pass the gradients' sum, the mask, a GEMM and an ELU backward per layer),
each ~2-3 µs of launch latency whatever its size. :class:`TileMLP` runs the forward as one kernel and the backward as
one: a block of ``rows`` windows carries its activations through every layer in shared memory (Warp's tile API,
``wp.tile_matmul``: Warp's own tile GEMM, or MathDx's with :attr:`TileBlock.mathdx`). Weights larger than a block's
shared memory (256x128 float32 is 128 KB) are read in chunks of ``chunk`` columns of the reduction dimension; every
tile dimension is padded to a multiple of ``chunk`` (loads out of bounds read zeros, stores out of bounds are
skipped), so the padding adds zeros to each sum.

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
    """Columns of the reduction dimension read from a weight at a time; every tile dimension is padded to a multiple
    of it. 256x32 float32 is 32 KB: the largest shared tiles stay ~130 KB a block (an H200 has ~227 KB)."""
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


def _matmul_lines(x: str, w: str, n_in: int, n_out: int, chunk: int, transpose: bool) -> list[str]:
    """``acc_<w>`` = x @ w.T (``transpose``, w (n_out, n_in)) or x @ w (w (n_in, n_out)), reading w in chunks of the
    reduction dimension n_in."""
    shape, off = ((n_out, chunk), "(0, c * KC)") if transpose else ((chunk, n_out), "(c * KC, 0)")
    wt = f"wp.tile_transpose(wc_{w})" if transpose else f"wc_{w}"
    # one name per product: Warp merges a name assigned in a branch with its value before, which needs one shape
    return [f"acc_{w} = wp.tile_zeros(shape=(TB, {n_out}), dtype=float)",
            f"for c in range({n_in // chunk}):",
            f"    wc_{w} = wp.tile_load({w}, shape={shape}, offset={off}, storage='shared')",
            f"    wp.tile_matmul(wp.tile_view({x}, offset=(0, c * KC), shape=(TB, KC)), {wt}, acc_{w})"]


def _sources(dims: list[int], chunk: int) -> tuple[str, str]:
    """The forward and backward kernels' source for a network of layer widths ``dims`` (input first)."""
    p = [_pad(d, chunk) for d in dims]
    n = len(dims) - 1
    f32 = "wp.array{}d(dtype=float)"
    a1, a2, a3, u3 = f32.format(1), f32.format(2), f32.format(3), "wp.array3d(dtype=wp.uint8)"
    ws = [f"w{i}: {a2}, b{i}: {a1}" for i in range(n)]
    xs, zs, gs = ([f"{c}{i}: {a3}" for i in range(m)] for c, m in (("x", n), ("z", n - 1), ("g", n)))
    fwd = [f"def tile_mlp_forward(obs: {a2}, k: int, mean: {a1}, std: {a1}, scale: {a1}, both: int, "
           + ", ".join(ws + xs + zs) + f", mask: {u3}, out: {a2}, action: {a2}):",
           "r0 = wp.tid() * TB",
           f"o = wp.tile_load(obs, shape=(TB, {p[0]}), offset=(r0, 0))",
           f"mu = wp.tile_broadcast(wp.tile_load(mean, shape=({p[0]},)), shape=(TB, {p[0]}))",
           f"sd = wp.tile_broadcast(wp.tile_load(std, shape=({p[0]},)), shape=(TB, {p[0]}))",
           "x = wp.tile_map(_normalise, o, mu, sd)",
           "wp.tile_store(x0[k], x, offset=(r0, 0))"]
    for i in range(n):
        fwd += _matmul_lines("x", f"w{i}", p[i], p[i + 1], chunk, True)
        fwd.append(f"y = acc_w{i} + wp.tile_broadcast(wp.tile_load(b{i}, shape=({p[i + 1]},)), "
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
           + ", ".join([f"w{i}: {a2}" for i in range(n)] + zs + gs) + f", mask: {u3}, g_obs: {a2}):",
           "r0 = wp.tid() * TB",
           f"s = wp.tile_broadcast(wp.tile_load(scale, shape=({p[n]},)), shape=(TB, {p[n]}))",
           f"gr = wp.tile_load(g_r, shape=(TB, {p[n]}), offset=(r0, 0))",
           f"ga = wp.tile_load(g_a, shape=(TB, {p[n]}), offset=(r0, 0))",
           f"m = wp.tile_load(mask[k], shape=(TB, {p[n]}), offset=(r0, 0))",
           "g = wp.tile_map(_out_grad, gr, ga, s, m)",
           f"wp.tile_store(g{n - 1}[k], g, offset=(r0, 0))"]
    for i in range(n - 1, 0, -1):
        bwd += _matmul_lines("g", f"w{i}", p[i + 1], p[i], chunk, False)
        bwd += [f"zt = wp.tile_load(z{i - 1}[k], shape=(TB, {p[i]}), offset=(r0, 0))",
                f"g = wp.tile_map(_elu_backward, acc_w{i}, zt)",
                f"wp.tile_store(g{i - 1}[k], g, offset=(r0, 0))"]
    # the normalisation's backward: sub passes the gradient through, div divides by std
    bwd += ["if need_obs != 0:"] + ["    " + line for line in _matmul_lines("g", "w0", p[1], p[0], chunk, False)]
    bwd += [f"    sd = wp.tile_broadcast(wp.tile_load(std, shape=({p[0]},)), shape=(TB, {p[0]}))",
            "    wp.tile_store(g_obs, wp.tile_map(wp.div, acc_w0, sd), offset=(r0, 0))"]
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
        self.torch_device = torch.device(device)
        self._bufs = self._policy = None
        self._streams: dict[int, tuple] = {}

    def bind(self, policy=None, linears=(), x=(), z=(), g=(), mask: torch.Tensor | None = None) -> None:
        """The rollout's policy, its linear layers and (H, B, ·) buffers (:meth:`FusedMLPRollout.begin`), viewed for
        Warp once per rollout, not at every step; no ``policy``: let them go."""
        if policy is None:
            self._bufs = self._policy = None
            return
        self._bufs = [_wp(t) for t in x], [_wp(t) for t in z], [_wp(t) for t in g], _wp(mask.view(torch.uint8))
        self._policy = ([_wp(t) for lin in linears for t in (lin.weight, lin.bias)],
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
        """Step ``k``'s residual (into ``out`` where given) and with ``both`` its action residual / scale."""
        x, z, _, mask = self._bufs
        params, _, mean, std, scale = self._policy
        batch = obs.shape[0]
        r = torch.empty(batch, self.dims[-1], device=obs.device, dtype=torch.float32) if out is None else out
        a = torch.empty_like(r) if both else r
        self._launch(self.forward_kernel, batch, [_wp(obs), k, mean, std, scale, int(both), *params, *x, *z, mask,
                                                  _wp(r), _wp(a)])
        r = r.view(r.shape)  # a fresh view as the step's output: autograd marks it, not the tensor handed in
        return (r, a) if both else r

    def backward(self, g_r, g_a, k: int, need_obs: bool) -> torch.Tensor | None:
        """The gradients at step ``k``'s layer outputs into the rollout's buffers, and the observation's gradient when
        ``need_obs``."""
        _, z, g, mask = self._bufs
        _, weights, _, std, scale = self._policy
        batch = g[0].shape[1]
        g_obs = torch.empty(batch, self.dims[0], device=self.torch_device, dtype=torch.float32) if need_obs else None
        grads = [self._empty if t is None else _wp(t) for t in (g_r, g_a)]
        self._launch(self.backward_kernel, batch, [*grads, k, scale, std, int(need_obs), *weights, *z, *g, mask,
                                                   _wp(g_obs) if need_obs else self._empty])
        return g_obs
