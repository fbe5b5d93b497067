"""One step of :class:`~wresdyn.learn.fused_mlp.FusedMLPRollout` as one plain Warp kernel per layer (its opt-in
``layers``).

On a GPU the fused path's step is ~24 torch kernels, its GEMMs cuBLAS kernels of 5-9 µs each at the fit's shapes
(1024 rows, widths 84 -> 256 -> 128 -> 64 -> 21; ``benchmarks/results/speed/h200_20261201c/``), and the tile
kernels (:mod:`.tile_mlp`) keep a whole block's work on one multiprocessor. :class:`LayerMLP` runs each layer's
forward as one kernel and the gradient at each layer's input as one: a thread computes one output column for
``rows`` windows, reading the weight's column for its output (adjacent threads, adjacent columns: coalesced loads)
and the windows' inputs (the same address across the warp), with everything around the GEMM folded in: the first
layer normalises the raw observation and stores it, a hidden layer stores its pre-activation and its ELU, the last one
the clip, its mask, the scale and the action; backwards, the last layer's kernel forms the gradient at the network's
output from those of the residual and the action, a hidden layer's applies the ELU's backward, the first layer's
divides by the normaliser's std. Eight kernels a step for the fit's four layers, where the torch path runs ~24.

The kernels write the per-step buffers :meth:`FusedMLPRollout.finish` reads (each layer's input, each hidden layer's
pre-activation, the gradients at the layer outputs, the clip's mask) and compute the torch path's operations; each sum
runs over its terms in order from the bias, not in cuBLAS's order, so the values agree to float32 rounding.

A kernel is generated per layer shape and cached per process; it launches on torch's current stream, so a CUDA graph
torch captures includes it.
"""

from __future__ import annotations

import hashlib
import linecache
import os

import torch

from ..sim.devices import torch_stream_for_warp

__all__ = ["ENV_ROWS", "LayerMLP", "ROWS", "UNROLL", "rows_from_env"]

ROWS = 8
"""Windows per thread: each weight value a thread loads serves this many rows."""

ENV_ROWS = "WRESDYN_LAYER_ROWS"
"""The environment variable that sets :class:`LayerMLP`'s windows per thread where none is given (:data:`ROWS` where
unset or empty): the benchmarks and the fit pick it without a config field."""

UNROLL = 4
"""Terms of a sum per pass of its loop, loads issued together."""

_FUNCS = '''
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
def _inside(y: float):
    # clamp's backward passes the gradient where -1 <= y <= 1 (NaN: neither), the torch path's c == y
    if y >= -1.0 and y <= 1.0:
        return wp.uint8(1)
    return wp.uint8(0)


@wp.func
def _given(a: wp.array2d(dtype=float), has: int, i: int, j: int):
    # a gradient autograd did not hand over (None, an empty array here) reads 0
    if has != 0:
        return a[i, j]
    return 0.0


@wp.func
def _out_grad(gr: float, ga: float, s: float, m: wp.uint8):
    # residual_grad's g_r + g_a / scale (a missing one reads 0), then the product's and the clip's backward
    if m != wp.uint8(0):
        return (gr + ga / s) * s
    return 0.0
'''

_A1, _A2, _A3, _U3 = ("wp.array1d(dtype=float)", "wp.array2d(dtype=float)", "wp.array3d(dtype=float)",
                      "wp.array3d(dtype=wp.uint8)")


def _sum_lines(n_terms: int, rows: int, term) -> list[str]:
    """``acc{r} += term(r, "t")`` for t over ``range(n_terms)``, unrolled by :data:`UNROLL` (a remainder after)."""
    lines, whole = [], n_terms - n_terms % UNROLL
    if whole:
        lines.append(f"for t0 in range(0, {whole}, {UNROLL}):")
        for u in range(UNROLL):
            t = f"t0 + {u}"
            lines += [f"    {line}" for line in term(t, u)]
    for t in range(whole, n_terms):
        lines += term(str(t), t)
    return lines


def _forward_source(l: int, dims: list[int], rows: int) -> str:
    """Layer ``l``'s forward: x_{l+1} = ELU(z_l), z_l = b + x_l W^T (the last layer: the clipped, scaled residual)."""
    n, k_in, n_out = len(dims) - 1, dims[l], dims[l + 1]
    first, last = l == 0, l == n - 1
    args = ["k: int", "batch: int", f"src: {_A2 if first else _A3}", f"wt: {_A2}", f"b: {_A1}"]
    args += [f"mean: {_A1}", f"std: {_A1}", f"x0: {_A3}"] if first else []
    args += [f"scale: {_A1}", "both: int", f"mask: {_U3}", f"out: {_A2}", f"action: {_A2}"] if last else \
        [f"z: {_A3}", f"xn: {_A3}"]
    body = ["g, j = wp.tid()", f"r0 = g * {rows}"]
    body += [f"i{r} = wp.min(r0 + {r}, batch - 1)" for r in range(rows)]
    body += ["bj = b[j]"] + [f"a{r} = bj" for r in range(rows)]

    def term(t: str, u) -> list[str]:
        out = [f"w{u} = wt[{t}, j]"]
        if first:
            out += [f"m{u} = mean[{t}]", f"s{u} = std[{t}]"]
            out += [f"a{r} = a{r} + (src[i{r}, {t}] - m{u}) / s{u} * w{u}" for r in range(rows)]
        else:
            out += [f"a{r} = a{r} + src[k, i{r}, {t}] * w{u}" for r in range(rows)]
        return out

    body += _sum_lines(k_in, rows, term)
    if first:  # the normalised observation, for the first weight's gradient: columns j, j + n_out, ...
        body += [f"for c in range(j, {k_in}, {n_out}):", "    mc = mean[c]", "    sc = std[c]"]
        body += [f"    if r0 + {r} < batch:\n            x0[k, i{r}, c] = (src[i{r}, c] - mc) / sc" for r in range(rows)]
    if last:
        body += ["sj = scale[j]"]
        for r in range(rows):
            body += [f"if r0 + {r} < batch:", f"    mask[k, i{r}, j] = _inside(a{r})",
                     f"    v{r} = wp.clamp(a{r}, -1.0, 1.0) * sj", f"    out[i{r}, j] = v{r}",
                     "    if both != 0:", f"        action[i{r}, j] = v{r} / sj"]
    else:
        for r in range(rows):
            body += [f"if r0 + {r} < batch:", f"    z[k, i{r}, j] = a{r}", f"    xn[k, i{r}, j] = _elu(a{r})"]
    return f"def layer_forward_{l}(" + ", ".join(args) + "):\n" + "\n".join("    " + line for line in body)


def _backward_source(l: int, dims: list[int], rows: int) -> str:
    """The gradient at layer ``l``'s input from the one at its output: (g W) through the ELU below it, or through the
    normaliser (the observation's gradient) for the first layer; the last layer's kernel forms the gradient at the
    network's output from the residual's and the action's and stores it."""
    n, n_in, k_out = len(dims) - 1, dims[l], dims[l + 1]
    first, last = l == 0, l == n - 1
    args = ["k: int", "batch: int", f"w: {_A2}"]
    args += [f"g_r: {_A2}", f"g_a: {_A2}", "has_r: int", "has_a: int", f"scale: {_A1}", f"mask: {_U3}",
             f"g_last: {_A3}"] if last else [f"g_out: {_A3}"]
    args += [f"std: {_A1}", "need_obs: int", f"g_obs: {_A2}"] if first else [f"z: {_A3}", f"g_in: {_A3}"]
    body = ["g, i = wp.tid()", f"r0 = g * {rows}"]
    body += [f"i{r} = wp.min(r0 + {r}, batch - 1)" for r in range(rows)]
    body += [f"a{r} = float(0.0)" for r in range(rows)]

    def grad_at(r: int, t: str) -> str:
        return (f"_out_grad(_given(g_r, has_r, i{r}, {t}), _given(g_a, has_a, i{r}, {t}), scale[{t}], "
                f"mask[k, i{r}, {t}])") if last else f"g_out[k, i{r}, {t}]"

    def term(t: str, u) -> list[str]:
        return [f"w{u} = w[{t}, i]"] + [f"a{r} = a{r} + {grad_at(r, t)} * w{u}" for r in range(rows)]

    body += _sum_lines(k_out, rows, term)
    if last:  # the gradient at the output, for the last weight's: columns i, i + n_in, ...
        body += [f"for c in range(i, {k_out}, {n_in}):"]
        body += [f"    if r0 + {r} < batch:\n            g_last[k, i{r}, c] = {grad_at(r, 'c')}" for r in range(rows)]
    for r in range(rows):
        body.append(f"if r0 + {r} < batch:")
        if first:
            body.append(f"    if need_obs != 0:\n            g_obs[i{r}, i] = a{r} / std[i]")
        else:
            body.append(f"    g_in[k, i{r}, i] = _elu_backward(a{r}, z[k, i{r}, i])")
    return f"def layer_backward_{l}(" + ", ".join(args) + "):\n" + "\n".join("    " + line for line in body)


def rows_from_env() -> int:
    """``$WRESDYN_LAYER_ROWS`` as a positive integer, :data:`ROWS` where unset or empty."""
    given = os.environ.get(ENV_ROWS, "").strip()
    if not given:
        return ROWS
    if not given.isdigit() or int(given) == 0:
        raise ValueError(f"{ENV_ROWS}: {given!r} is not a positive integer")
    return int(given)


_KERNELS: dict[tuple, tuple] = {}


def _kernels(dims: tuple[int, ...], alpha: float, rows: int) -> tuple[list, list]:
    """(forward, backward) kernels per layer for this shape, built once per process (Warp caches their binaries)."""
    key = (dims, alpha, rows)
    if key not in _KERNELS:
        import warp as wp

        n = len(dims) - 1
        head = "\n\n\n@wp.kernel(enable_backward=False)\n"
        src = _FUNCS + "".join(head + _forward_source(l, list(dims), rows) for l in range(n)) \
            + "".join(head + _backward_source(l, list(dims), rows) for l in range(n)) + "\n"
        # Warp reads a kernel's source back through inspect: register the generated text under its own file name
        name = f"<wresdyn.layer_mlp {'-'.join(map(str, dims))} a{alpha} r{rows} u{UNROLL}>"
        linecache.cache[name] = (len(src), None, src.splitlines(True), name)
        # one Warp module for the shape's kernels (the name its functions and kernels register under): one compile
        scope = {"wp": wp, "ALPHA": float(alpha), "__name__": "wresdyn_layer_mlp_" + hashlib.sha1(name.encode()).hexdigest()[:12]}
        exec(compile(src, name, "exec"), scope)  # noqa: S102 (source built above from integers only)
        _KERNELS[key] = ([scope[f"layer_forward_{l}"] for l in range(n)],
                         [scope[f"layer_backward_{l}"] for l in range(n)])
    return _KERNELS[key]


def _wp(t: torch.Tensor):
    import warp as wp

    # requires_grad=False: Warp would otherwise attach (and allocate) the tensor's .grad
    return wp.from_torch(t, requires_grad=False)


class LayerMLP:
    """The forward and backward of one rollout step of an ELU MLP residual (float32) of layer widths ``dims`` (input
    first), one Warp kernel per layer each way, each thread ``rows`` windows of one output column (where ``None``,
    :func:`rows_from_env`'s)."""

    def __init__(self, dims: list[int], alpha: float, device: torch.device, rows: int | None = None) -> None:
        import warp as wp

        wp.init()
        self.dims, self.rows = list(dims), rows or rows_from_env()
        self.forward_kernels, self.backward_kernels = _kernels(tuple(dims), float(alpha), self.rows)
        self.device = wp.device_from_torch(device)
        self.torch_device = torch.device(device)
        self._empty2 = _wp(torch.zeros(0, dims[-1], device=device))
        self._bufs = self._policy = None
        self._streams: dict[int, tuple] = {}

    def bind(self, policy=None, linears=(), x=(), z=(), g=(), mask: torch.Tensor | None = None) -> None:
        """The rollout's policy, its linear layers and (H, B, ·) buffers (:meth:`FusedMLPRollout.begin`), viewed for
        Warp once per rollout; the weights' transposes (the forward kernels' coalesced reads) copied here, once per
        rollout. No ``policy``: let them go."""
        if policy is None:
            self._bufs = self._policy = self._wt = None
            return
        self._bufs = [_wp(t) for t in x], [_wp(t) for t in z], [_wp(t) for t in g], _wp(mask.view(torch.uint8))
        self._wt = [lin.weight.detach().t().contiguous() for lin in linears]
        self._policy = ([_wp(t) for t in self._wt], [_wp(lin.bias.detach()) for lin in linears],
                        [_wp(lin.weight.detach()) for lin in linears],
                        *(_wp(t) for t in (policy.obs_mean, policy.obs_std, policy.scale)))

    def _launch(self, kernel, batch: int, width: int, args: list) -> None:
        import warp as wp

        wp.launch(kernel, dim=(-(-batch // self.rows), width), inputs=args, device=self.device,
                  stream=self._stream())

    def _stream(self):
        """Torch's current stream as a Warp stream, so that a CUDA graph torch captures holds the launches (``None``
        on the CPU and on torch's default stream)."""
        return torch_stream_for_warp(self.device.ordinal, self._streams) if self.device.is_cuda else None

    def forward(self, obs: torch.Tensor, k: int, out: torch.Tensor | None, both: bool):
        """Step ``k``'s residual (into ``out`` where given) and with ``both`` its action residual / scale."""
        x, z, _, mask = self._bufs
        wts, biases, _, mean, std, scale = self._policy
        batch, n = obs.shape[0], len(self.dims) - 1
        r = torch.empty(batch, self.dims[-1], device=obs.device, dtype=torch.float32) if out is None else out
        a = torch.empty_like(r) if both else r
        for l in range(n):
            args = [k, batch, _wp(obs) if l == 0 else x[l], wts[l], biases[l]]
            args += [mean, std, x[0]] if l == 0 else []
            args += [scale, int(both), mask, _wp(r), _wp(a)] if l == n - 1 else [z[l], x[l + 1]]
            self._launch(self.forward_kernels[l], batch, self.dims[l + 1], args)
        r = r.view(r.shape)  # a fresh view as the step's output: autograd marks it, not the tensor handed in
        return (r, a) if both else r

    def backward(self, g_r, g_a, k: int, need_obs: bool) -> torch.Tensor | None:
        """The gradients at step ``k``'s layer outputs into the rollout's buffers, and the observation's gradient when
        ``need_obs``."""
        _, z, g, mask = self._bufs
        _, _, weights, _, std, scale = self._policy
        n, batch = len(self.dims) - 1, g[0].shape[1]
        g_obs = torch.empty(batch, self.dims[0], device=self.torch_device, dtype=torch.float32) if need_obs else None
        for l in range(n - 1, -1, -1):
            if l == 0 and n > 1 and not need_obs:
                break  # the last kernel's only output would be the observation's gradient
            args = [k, batch, weights[l]]
            if l == n - 1:
                grads = [self._empty2 if t is None else _wp(t) for t in (g_r, g_a)]
                args += [*grads, int(g_r is not None), int(g_a is not None), scale, mask, g[n - 1]]
            else:
                args.append(g[l])
            args += [std, int(need_obs), _wp(g_obs) if need_obs else self._empty2] if l == 0 else [z[l - 1], g[l - 1]]
            self._launch(self.backward_kernels[l], batch, self.dims[l], args)
        return g_obs
