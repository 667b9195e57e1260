"""Shared test settings: the CLI's XLA flags (`adarl.runtime`: one thread per computation, one
CPU device per core), a persistent compilation cache shared by the tests and the CLI
subprocesses they start, a headless matplotlib backend, a bound on the memory maps that
compiled XLA executables hold in this long-lived process, and what lets pytest-xdist run the
tests in parallel (`python -m pytest -n auto`, README; `--dist loadfile` in pyproject.toml runs
each test file whole in one worker, so a module fixture such as a trained run is made once)."""

import fcntl
import gc
import os
import sys
import tempfile

import pytest

from adarl.runtime import configure_xla

configure_xla()
# One cache per pytest-xdist worker: JAX writes a cache entry without a lock, so a worker could
# read an entry that another is still writing.
WORKER = os.environ.get("PYTEST_XDIST_WORKER", "")
os.environ.setdefault(
    "JAX_COMPILATION_CACHE_DIR",
    os.path.join(tempfile.gettempdir(), "-".join(filter(None, ["adarl-test-jax-cache", WORKER]))),
)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
os.environ.setdefault("MPLBACKEND", "Agg")

# Every XLA:CPU executable holds its own memory maps, and JAX keeps the executables of every
# function and shape a test compiled. The suite compiles thousands in one process: past the
# kernel's vm.max_map_count (65,530) XLA crashes (SIGSEGV or SIGABRT) in the next compilation.
MAPS_BEFORE_CLEARING = 20_000


def memory_maps() -> int:
    """This process's number of memory maps (0 where /proc is not available)."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return 0


@pytest.fixture(autouse=True)
def bounded_executables():
    yield
    if "jax" in sys.modules and memory_maps() > MAPS_BEFORE_CLEARING:
        sys.modules["jax"].clear_caches()
        gc.collect()


@pytest.fixture
def local_ray_turn():
    """Tests that start a local Ray instance take turns: under pytest-xdist two workers could
    otherwise start two instances on the machine at once."""
    with open(os.path.join(tempfile.gettempdir(), "adarl-test-local-ray.lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        yield
