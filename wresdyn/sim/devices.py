"""Whether a device named on the command line is one this machine's Warp and torch can both use, and which Warp
stream runs beside torch's current one."""

from __future__ import annotations

import torch

from ..errors import WresdynError


def require_device(device: str | None) -> None:
    """Refuse, in one line, a CUDA device that this machine's Warp or torch cannot use (no GPU, a CPU build of
    torch, an index past the last GPU), before any model is built on it."""
    if device is None or not str(device).startswith("cuda"):
        return
    import warp as wp

    index = int(str(device).partition(":")[2] or 0)
    n_warp = wp.get_cuda_device_count()
    n_torch = torch.cuda.device_count() if torch.cuda.is_available() else 0
    if index >= min(n_warp, n_torch):
        raise WresdynError(f"device {device!r} is not available here: Warp {wp.config.version} sees {n_warp} CUDA "
                           f"device(s), torch {torch.__version__} sees {n_torch}; use --device cpu, or on a GPU "
                           "machine a CUDA build of torch (the README's set-up)")


def torch_stream_for_warp(device, streams: dict):
    """Torch's current stream on CUDA ``device`` as a Warp stream where it is a stream of its own (a CUDA graph being
    captured or warmed up on it), so that torch's and Warp's launches are ordered by the stream itself; ``None`` on
    torch's legacy default stream, which Warp's device stream synchronises with. ``streams`` (torch stream handle ->
    (torch stream, Warp stream)) keeps one Warp object per stream, and the torch stream alive beside it."""
    import warp as wp

    cur = torch.cuda.current_stream(device)
    if cur == torch.cuda.default_stream(device):
        return None
    if cur.cuda_stream not in streams:
        streams[cur.cuda_stream] = (cur, wp.stream_from_torch(cur))
    return streams[cur.cuda_stream][1]
