"""XLA settings applied before JAX starts."""

import os

from adarl.runtime import with_xla_flags, xla_flags


def test_xla_flags_give_one_cpu_device_per_core():
    assert xla_flags(3) == [
        "--xla_cpu_multi_thread_eigen=false",
        "--xla_force_host_platform_device_count=3",
    ]
    cores = os.cpu_count() or 1
    assert xla_flags() == xla_flags(0) == xla_flags(cores)


def test_with_xla_flags_replaces_ours_and_keeps_the_users():
    existing = "--xla_dump_to=/tmp/d --xla_force_host_platform_device_count=8 " + (
        "--xla_cpu_multi_thread_eigen=true"
    )
    flags = with_xla_flags(existing, 1).split()
    assert flags[0] == "--xla_dump_to=/tmp/d"
    assert "--xla_force_host_platform_device_count=1" in flags
    assert "--xla_cpu_multi_thread_eigen=false" in flags
    assert len(flags) == 3


def test_available_cores_follow_the_affinity_and_the_machine_elsewhere(monkeypatch):
    from adarl import runtime

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 3, 5}, raising=False)
    assert runtime.available_cores() == 3
    monkeypatch.delattr(os, "sched_getaffinity")
    monkeypatch.setattr(os, "cpu_count", lambda: 7)
    assert runtime.available_cores() == 7
