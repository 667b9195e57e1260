"""Process-wide XLA settings; they must be in the environment before JAX starts."""

from __future__ import annotations

import os

XLA_FLAG_NAMES = ("xla_cpu_multi_thread_eigen", "xla_force_host_platform_device_count")


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity on Linux, else the machine's)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def xla_flags(cpus: int | None = None) -> list[str]:
    """XLA flags for a process allowed `cpus` cores (default: all of this machine's).

    Each computation runs on one thread (measured faster for these small networks), and the
    host gets one CPU device per core: XLA runs one computation at a time per device, so the
    trainer puts its lanes of seeds on different devices to update them concurrently
    (`adarl.train.sac_learner`)."""
    cpus = max(1, cpus or os.cpu_count() or 1)
    return ["--xla_cpu_multi_thread_eigen=false", f"--xla_force_host_platform_device_count={cpus}"]


def with_xla_flags(existing: str, cpus: int | None = None) -> str:
    """`existing` XLA_FLAGS with our thread and device flags replaced (other flags are kept)."""
    kept = [f for f in existing.split() if not f.lstrip("-").startswith(XLA_FLAG_NAMES)]
    return " ".join(kept + xla_flags(cpus))


def configure_xla(cpus: int | None = None) -> None:
    """Set XLA_FLAGS for this process unless the user has set them (call before importing JAX)."""
    os.environ.setdefault("XLA_FLAGS", " ".join(xla_flags(cpus)))
