"""One rollout step of the gradient fit's network, forward and backward: the fused MLP path's torch operations against
its Warp tile kernels (``FusedMLPRollout(policy, tiles=True)``, ``GradFitConfig.network_tiles``).

    python benchmarks/speed/tile_mlp_step.py --device cuda:0 --windows 1024
    python benchmarks/speed/tile_mlp_step.py --device cuda:0 --windows 1024 --blocks 16x32x128,8x32x128,32x32x256
    python benchmarks/speed/tile_mlp_step.py --device cpu --windows 1024 --horizon 8 --repeats 3

Workload: the fit's residual network (:class:`wresdyn.learn.residual.ResidualConfig`'s hidden widths, ELU, the
humanoid's 21 joints: observation 84 -> 256 -> 128 -> 64 -> 21) over ``--windows`` rows, ``--horizon`` steps each
run forward (residual and action) and then backward (the gradients of both handed back, the observation's gradient
formed), as in a rollout of that length. On CUDA the H forward and H backward steps are captured in one CUDA graph and
replayed (the fit replays its iterations so; no Python between kernels), timed with CUDA events, and also run eagerly;
on the CPU eagerly, by wall-clock. Printed: µs per step (forward + backward) of each path, and the largest absolute
difference between the paths' residuals, observation gradients and gradients at the layer outputs (float32 rounding:
the kernels sum each GEMM in another order). ``--blocks`` lists the kernels' splits to time
(:class:`~wresdyn.learn.tile_mlp.TileBlock`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

N_DOF = 21  # the project humanoid's joints


def _policy(device):
    import torch

    from wresdyn.learn.residual import EluMLP, MLPResidualPolicy, ResidualConfig

    torch.manual_seed(0)
    mlp = EluMLP(4 * N_DOF, N_DOF, list(ResidualConfig().hidden_dims))
    mlp[-1].weight.data.mul_(10)  # outputs past the clip for some entries: the mask does work
    return MLPResidualPolicy(mlp, torch.randn(4 * N_DOF) * 0.1, torch.rand(4 * N_DOF) + 0.5, torch.rand(N_DOF) + 0.5,
                             "torque").to(device)


def _steps(net, obs, grads, horizon: int):
    """H forward steps then H backward steps, newest first (a rollout's order); what the last backward returns."""
    rs = [net._forward(obs, k, None, True) for k in range(horizon)]
    g_obs = None
    for k in range(horizon - 1, -1, -1):
        g_obs = net._backward(grads[0], grads[1], k, True)
    return rs[0][0], g_obs


def _time(net, obs, grads, horizon: int, repeats: int, cuda: bool) -> tuple[dict, list]:
    """One path's figures: first call, eager and (CUDA) graph-replayed µs per step; and its step-0 outputs."""
    import torch

    fig = {}
    net.begin(horizon, obs.shape[0])
    t = time.perf_counter()
    r, g_obs = _steps(net, obs, grads, horizon)  # the first call loads (and may compile) the kernels
    if cuda:
        torch.cuda.synchronize(obs.device)
    fig["first_call_s"] = time.perf_counter() - t
    outputs = [r, g_obs] + [b[0] for b in net._g]
    t = time.perf_counter()
    for _ in range(repeats):
        _steps(net, obs, grads, horizon)
    if cuda:
        torch.cuda.synchronize(obs.device)
    fig["eager_us_per_step"] = 1e6 * (time.perf_counter() - t) / (repeats * horizon)
    if cuda:
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph):
            _steps(net, obs, grads, horizon)
        graph.replay()
        start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        start.record()
        for _ in range(repeats):
            graph.replay()
        end.record()
        end.synchronize()
        fig["graph_us_per_step"] = 1e3 * start.elapsed_time(end) / (repeats * horizon)
    return fig, [o.clone() for o in outputs]


def run(device: str, windows: int, horizon: int, repeats: int, blocks: list) -> dict:
    """The torch fused path, then the tile path at each :class:`~wresdyn.learn.tile_mlp.TileBlock` of ``blocks``."""
    import torch

    from wresdyn.learn.fused_mlp import FusedMLPRollout

    torch.set_grad_enabled(False)  # as inside the step's autograd node
    g = torch.Generator().manual_seed(1)
    obs = (torch.randn(windows, 4 * N_DOF, generator=g) * 4).to(device)
    grads = [torch.randn(windows, N_DOF, generator=g).to(device) for _ in range(2)]
    cuda = device.startswith("cuda")
    out = {"device": torch.cuda.get_device_name(device) if cuda else "cpu", "windows": windows, "horizon": horizon}
    out["torch"], ref = _time(FusedMLPRollout(_policy(device)), obs, grads, horizon, repeats, cuda)
    labels = ["residual", "obs_grad"] + [f"g{i}" for i in range(len(ref) - 2)]
    out["max_abs"] = {k: float(b.abs().max()) for k, b in zip(labels, ref, strict=True)}
    out["tiles"] = []
    for block in blocks:
        try:
            fig, got = _time(FusedMLPRollout(_policy(device), tiles=True, tile_block=block), obs, grads, horizon,
                             repeats, cuda)
        except RuntimeError as e:  # a split the device refuses (shared memory, a compile): the others still run
            out["tiles"].append({"block": dataclasses.asdict(block), "error": str(e).splitlines()[0]})
            continue
        fig["block"] = dataclasses.asdict(block)
        fig["max_abs_diff"] = {k: float((a - b).abs().max()) for k, a, b in zip(labels, got, ref, strict=True)}
        out["tiles"].append(fig)
    return out


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--windows", type=int, default=1024)
    p.add_argument("--horizon", type=int, default=64, help="steps per timed rollout (the curriculum's longest)")
    p.add_argument("--repeats", type=int, default=20)
    p.add_argument("--blocks", default="",
                   help="comma list of ROWSxCHUNKxTHREADS (windows per block, weight rows read at a time, threads "
                        "per block), each with suffix 'm' for MathDx's GEMMs (a long first compile); default: the "
                        "split the fit runs ($WRESDYN_TILE_BLOCK's or TileBlock's defaults)")
    p.add_argument("--json", default="")
    args = p.parse_args(argv)
    import warp as wp

    from wresdyn.learn.tile_mlp import TileBlock

    wp.config.quiet = True
    blocks = [TileBlock.parse(b) for b in args.blocks.split(",")] if args.blocks else [TileBlock.from_env()]
    out = run(args.device, args.windows, args.horizon, args.repeats, blocks)
    print(f"{out['device']}: {args.windows} windows, H = {args.horizon}")
    rows = [("torch fused", out["torch"])] + [(str(t["block"]), t) for t in out["tiles"]]
    for name, fig in rows:
        if "error" in fig:
            print(f"{name}: failed: {fig['error']}")
            continue
        times = [f"{mode} {fig[f'{mode}_us_per_step']:.1f} µs/step" for mode in ("graph", "eager")
                 if f"{mode}_us_per_step" in fig]
        print(f"{name}: " + ", ".join(times) + f"; first call {fig['first_call_s']:.1f} s")
        if "max_abs_diff" in fig:
            print("  max |tiles - torch|: " + ", ".join(f"{k} {v:.2e} (of {out['max_abs'][k]:.2e})"
                                                       for k, v in fig["max_abs_diff"].items()))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
