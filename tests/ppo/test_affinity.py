"""Binding a training process to its GPU's cores (:mod:`wresdyn.ppo.affinity`): the sysfs lists, the bus ids, the
split among ranks; on the CPU."""

import os

import pytest

from wresdyn.ppo.affinity import (device_bus_id, gpu_cpus, parse_cpulist, pin_process, rank_cpus, set_affinity,
                                  sysfs_bus_id)


def test_cpulist_parsing():
    assert parse_cpulist("0-3,8,10-11\n") == {0, 1, 2, 3, 8, 10, 11}
    assert parse_cpulist("5") == {5}
    assert parse_cpulist("\n") == set()
    with pytest.raises(ValueError):
        parse_cpulist("a-b")


def test_bus_ids_in_sysfs_form():
    assert sysfs_bus_id("00000000:00:06.0") == "0000:00:06.0"  # CUDA's 8-digit domain
    assert sysfs_bus_id("0000:1B:00.0") == "0000:1b:00.0"
    with pytest.raises(ValueError):
        sysfs_bus_id("1b:00.0")

    class Props:  # torch's device properties: the numbers as integers
        pci_domain_id, pci_bus_id, pci_device_id = 0, 0x1B, 0

    assert device_bus_id(Props()) == "0000:1b:00.0"


def test_gpu_cpus_read_from_sysfs(tmp_path):
    (tmp_path / "0000:1b:00.0").mkdir()
    (tmp_path / "0000:1b:00.0" / "local_cpulist").write_text("0-7,16-23\n")
    (tmp_path / "0000:2c:00.0").mkdir()
    (tmp_path / "0000:2c:00.0" / "local_cpulist").write_text("\n")
    assert gpu_cpus("00000000:1B:00.0", tmp_path) == set(range(8)) | set(range(16, 24))
    assert gpu_cpus("0000:2c:00.0", tmp_path) is None  # empty: unknown
    assert gpu_cpus("0000:3d:00.0", tmp_path) is None  # no entry


def test_rank_cores_split():
    allowed = set(range(8))
    # two NUMA nodes, one GPU on each: each rank its node's cores
    assert rank_cpus(0, [{0, 1, 2, 3}, {4, 5, 6, 7}], allowed) == {0, 1, 2, 3}
    assert rank_cpus(1, [{0, 1, 2, 3}, {4, 5, 6, 7}], allowed) == {4, 5, 6, 7}
    # one node listing every core for both GPUs (a VM): split between the two ranks
    assert rank_cpus(0, [allowed, allowed], allowed) == {0, 1, 2, 3}
    assert rank_cpus(1, [allowed, allowed], allowed) == {4, 5, 6, 7}
    # no sysfs entry: an even split of the allowed cores by local rank
    assert rank_cpus(1, [None, None], {2, 3, 5, 7}) == {5, 7}
    assert rank_cpus(0, [None, None, None], allowed) == {0, 1}
    assert rank_cpus(2, [None, None, None], allowed) == {5, 6, 7}
    # the local cores intersected with the allowed ones; none of them allowed: the fallback
    assert rank_cpus(0, [{0, 1, 2, 3}, {4, 5, 6, 7}], {2, 3, 4, 5}) == {2, 3}
    assert rank_cpus(0, [{8, 9}, {10, 11}], {2, 3, 4, 5}) == {2, 3}
    # fewer cores than ranks: every rank keeps them all rather than none
    assert rank_cpus(1, [None, None], {0}) == {0}
    assert rank_cpus(0, [None], allowed) == allowed


def test_pin_process_on_the_cpu_and_back():
    before = os.sched_getaffinity(0)
    try:
        assert pin_process(0, 1, "cpu") == before  # one process: all its cores
        two = pin_process(1, 2, "cpu")
        assert two and two <= before and os.sched_getaffinity(0) == two
        assert len(before) == 1 or len(two) == len(before) - len(before) // 2
    finally:
        set_affinity(before)
    assert os.sched_getaffinity(0) == before
