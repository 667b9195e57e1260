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
from pathlib import Path

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


# The device backend's longest tests: each trains or steps MJX on a CPU, where one compile takes
# a minute or more (seconds a test, measured 2026-12-07 in the suite beside the campaign, 2 workers,
# cold compile cache; together 1,655 s of the suite's 3,250). They leave the default run, which
# must stay under 15 minutes on two cores, and run with `pytest -m mjx` (not timed
# alone) and on an accelerator. The default run keeps a device resume
# (test_device_learner's killed-and-resumed run), the host parity of Hopper under four physics,
# the float32 check and the accelerator script's budget.
MJX_LONG = {
    "train/test_device_learner.py::test_a_sigkilled_device_run_resumes_to_the_uninterrupted_runs_bits",  # 245
    "train/test_device_ring.py::test_killed_and_resumed_run_equals_an_uninterrupted_one",  # 184
    "train/test_device_ring.py::test_ant_and_humanoid_under_paper_run_the_host_envs_gravity_and_wind",  # 241, both
    "train/test_device_precision.py::test_returns_and_ranks_are_the_same_under_a_gpus_matmuls",  # 93
    "train/test_device_learner.py::test_the_device_evaluation_is_each_seeds_deterministic_policy_from_its_own_resets",  # 88
    "device/test_humanoid.py::test_humanoid_stays_within_the_measured_difference_from_pgs",  # 82
    "train/test_device_ring.py::test_walker2d_under_uniform_draws_each_seeds_own_models_as_the_host_env_does",  # 82
    "train/test_device_ring.py::test_chunk_k_plus_1_is_dispatched_before_chunk_ks_episodes_are_read",  # 79
    "train/test_device_sparse.py::test_sac_sparse_trains_on_the_device_and_its_policy_files_compute_its_network",  # 76
    "algos/test_sac_device.py::test_every_episode_starts_from_its_own_reset_from_the_pool_or_past_it",  # 74
    "train/test_device_ring.py::test_episodes_csv_records_the_host_envs_parameters",  # 67
    "device/test_ant.py::test_ant_stays_within_the_measured_difference_free_running",  # 42
    "device/test_walker2d.py::test_walker2d_matches_the_host_task_under_four_physics",  # 39
    "device/test_hopper.py::test_hopper_with_the_line_search_capped_at_4_matches_the_host_task",  # 38
    "device/test_walker2d.py::test_walker2d_with_the_line_search_capped_at_4_still_matches_the_host_task",  # 36
    # second round (the suite at 17 min beside the campaign without the above)
    "device/test_humanoid.py::test_humanoid_one_step_difference_from_the_same_state",  # 78
    "train/test_device_ring.py::test_every_episode_runs_the_model_the_host_env_compiles_for_it",  # 65
    "device/test_ant.py::test_ant_one_step_difference_from_the_same_state",  # 42
}


@pytest.hookimpl(tryfirst=True)  # before `-m` deselects: the marker must be there by then
def pytest_collection_modifyitems(config, items):
    """Mark MJX_LONG's tests `mjx` (the default run leaves them out: pyproject.toml's addopts);
    a name in MJX_LONG that its collected file lacks (a renamed test, which would silently rejoin
    the default run) is a usage error."""
    root = Path(__file__).parent
    found, files = set(), set()
    for item in items:
        path = Path(item.fspath).relative_to(root).as_posix()
        files.add(path)
        name = f"{path}::{item.originalname or item.name}"
        if name in MJX_LONG:
            item.add_marker(pytest.mark.mjx)
            found.add(name)
    missing = sorted(n for n in MJX_LONG - found if n.split("::")[0] in files)
    if missing:
        raise pytest.UsageError(f"tests/conftest.py MJX_LONG names no collected test: {missing}")
