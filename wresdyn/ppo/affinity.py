"""Each training process bound to the CPU cores next to its GPU (``ppo.pin_cpus``).

With two processes on one host the scheduler may run a rank's Python thread on a core of the other GPU's NUMA node,
next to the other rank's busy threads, or move it between cores; the rollout, which launches many small kernels
and waits on the device, then pays for it on the host. :func:`pin_process` gives each rank a fixed set of cores:
those sysfs lists as local to its GPU (``/sys/bus/pci/devices/<bus id>/local_cpulist``), split evenly among the
ranks whose GPUs share that list (on a host of one NUMA node every GPU lists every core), intersected with the cores
the process may use. Without a sysfs entry (no CUDA, a virtual bus) the allowed cores are split evenly by local
rank. This module imports torch only inside :func:`pin_process`.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["parse_cpulist", "sysfs_bus_id", "device_bus_id", "gpu_cpus", "rank_cpus", "pin_process",
           "set_affinity"]

SYSFS_PCI = Path("/sys/bus/pci/devices")
"""Where Linux lists PCI devices by bus id (``0000:00:06.0``)."""


def parse_cpulist(text: str) -> set[int]:
    """The cores of a Linux CPU list (``"0-3,8,10-11"``; empty: none)."""
    cpus: set[int] = set()
    for part in text.strip().split(","):
        part = part.strip()
        if not part:
            continue
        lo, _, hi = part.partition("-")
        cpus.update(range(int(lo), int(hi or lo) + 1))
    return cpus


def sysfs_bus_id(bus_id: str) -> str:
    """A PCI bus id as sysfs names it: lower case, a 4-digit domain (CUDA reports ``00000000:00:06.0``; sysfs has
    ``0000:00:06.0``)."""
    parts = bus_id.strip().lower().split(":")
    if len(parts) != 3:
        raise ValueError(f"not a PCI bus id: {bus_id!r}")
    domain, bus, devfn = parts
    return f"{int(domain, 16):04x}:{bus.zfill(2)}:{devfn}"


def device_bus_id(props) -> str:
    """The PCI bus id of a CUDA device from its properties (``torch.cuda.get_device_properties``): torch gives the
    domain, bus and device numbers as integers (a text ``pci_bus_id`` is taken as it is)."""
    bus = props.pci_bus_id
    if isinstance(bus, str):
        return bus
    return f"{int(getattr(props, 'pci_domain_id', 0)):04x}:{int(bus):02x}:{int(props.pci_device_id):02x}.0"


def gpu_cpus(bus_id: str, root: Path = SYSFS_PCI) -> set[int] | None:
    """The cores sysfs lists as local to the PCI device ``bus_id``; ``None`` without an entry or with an empty one."""
    path = Path(root) / sysfs_bus_id(bus_id) / "local_cpulist"
    try:
        cpus = parse_cpulist(path.read_text())
    except (OSError, ValueError):
        return None
    return cpus or None


def rank_cpus(local_rank: int, local: list[set[int] | None], allowed: set[int]) -> set[int]:
    """The cores of local rank ``local_rank``: ``local[i]`` is the cores local to rank i's GPU (``None``: unknown),
    ``allowed`` the cores the process may use. The ranks whose GPUs list the same cores split them evenly, in
    rank order; a rank with unknown or unusable local cores takes its even share of ``allowed`` by local rank."""
    mine = local[local_rank]
    if mine is not None and mine & allowed:
        share = [r for r, c in enumerate(local) if c == mine]
        return _split(sorted(mine & allowed), len(share), share.index(local_rank))
    return _split(sorted(allowed), len(local), local_rank)


def _split(cores: list[int], parts: int, index: int) -> set[int]:
    """Part ``index`` of ``cores`` cut into ``parts`` contiguous runs of near-equal length (never empty)."""
    if parts <= 1 or len(cores) < parts:
        return set(cores)
    lo, hi = index * len(cores) // parts, (index + 1) * len(cores) // parts
    return set(cores[lo:hi])


def pin_process(local_rank: int, world: int, device: str) -> set[int]:
    """Bind this process (:func:`set_affinity`) to its cores (:func:`rank_cpus`) and return them. On CUDA
    each local rank's GPU is ``cuda:<local rank>`` (one per process, as under torchrun); elsewhere sysfs is not read."""
    allowed = os.sched_getaffinity(0)
    local: list[set[int] | None] = [None] * max(world, local_rank + 1)
    if str(device).startswith("cuda"):
        import torch

        n = torch.cuda.device_count()
        for r in range(min(len(local), n)):
            local[r] = gpu_cpus(device_bus_id(torch.cuda.get_device_properties(r)))
    cpus = rank_cpus(local_rank, local, allowed)
    set_affinity(cpus)
    return cpus


def set_affinity(cpus) -> None:
    """Bind every thread of this process to ``cpus`` (the threads torch, NCCL or Warp started already too: Linux
    binds one thread per call, and a new thread inherits its parent's cores)."""
    tasks = Path("/proc/self/task")
    tids = [int(t) for t in os.listdir(tasks)] if tasks.is_dir() else [0]
    for tid in tids:
        try:
            os.sched_setaffinity(tid, cpus)
        except (ProcessLookupError, PermissionError):  # a thread that ended meanwhile
            pass
    os.sched_setaffinity(0, cpus)
