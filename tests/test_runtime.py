"""XLA settings applied before JAX starts."""

import os

import pytest

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


# ----------------------------------------------------------------------------- issue 38, class 5
def test_mujoco_gl_is_checked_as_mujoco_would(monkeypatch):
    import ctypes.util

    import pytest

    from adarl.errors import UsageError
    from adarl.runtime import check_mujoco_gl

    monkeypatch.setattr(ctypes.util, "find_library", lambda name: f"lib{name}.so.1")
    for ok in ("egl", "OSMesa", " glfw ", "disable", "0", ""):
        monkeypatch.setenv("MUJOCO_GL", ok)
        check_mujoco_gl()
    monkeypatch.delenv("MUJOCO_GL")
    check_mujoco_gl()
    for bad in ("garbage", "wgl", "egl,osmesa"):  # wgl: Windows only
        monkeypatch.setenv("MUJOCO_GL", bad)
        with pytest.raises(UsageError, match=f"MUJOCO_GL={bad!r} is not a MuJoCo rendering"):
            check_mujoco_gl()


def test_adarls_own_xla_flags_are_checked_without_starting_jax(monkeypatch):
    import pytest

    from adarl import runtime
    from adarl.errors import UsageError

    def no_probe(*args):
        raise AssertionError("started a child process")

    monkeypatch.setattr(runtime, "_jax_start_failure", no_probe)
    monkeypatch.delenv("JAX_PLATFORMS", raising=False)
    for flags, needle in [
        ("--xla_force_host_platform_device_count=0", "with N >= 1"),
        ("--xla_force_host_platform_device_count=abc", "with N >= 1"),
        ("--xla_force_host_platform_device_count=-2", "with N >= 1"),
        ("--xla_cpu_multi_thread_eigen=maybe", "=true|false"),
    ]:
        monkeypatch.setenv("XLA_FLAGS", flags)
        with pytest.raises(UsageError, match=f"XLA_FLAGS has {flags}; allowed.*{needle}"):
            runtime.check_jax_backend()
    monkeypatch.setenv("XLA_FLAGS", " ".join(runtime.xla_flags(4)))
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    runtime.check_jax_backend()  # adarl's own settings: nothing to try


def test_a_backend_jax_cannot_start_is_one_line_before_the_run_folder(
    tmp_path, capsys, monkeypatch
):
    from adarl.cli.main import main

    out = tmp_path / "run"
    argv = ["train", "--algo", "sac", "--preset", "smoke", "--total-steps", "200", "--out",
            str(out), "--no-progress"]  # fmt: skip
    for name, value, needle in [
        ("JAX_PLATFORMS", "tpu", "Unable to initialize backend 'tpu'"),
        ("XLA_FLAGS", "--xla_no_such_flag=1", "Unknown flag in XLA_FLAGS: --xla_no_such_flag=1"),
    ]:
        with monkeypatch.context() as m:
            m.setenv(name, value)
            assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and needle in err and "JAX cannot start" in err, err
        assert not out.exists()


@pytest.mark.parametrize("name", ["JAX_ENABLE_X64", "JAX_DEBUG_NANS"])
def test_a_jax_boolean_jax_cannot_read_is_one_line_before_anything_is_written(name, monkeypatch, tmp_path):  # fmt: skip
    # issue 61 §6: JAX_ENABLE_X64=maybe was a ValueError traceback from inside JAX
    import subprocess
    import sys

    from adarl.errors import UsageError
    from adarl.runtime import check_process_environment

    monkeypatch.setenv(name, "maybe")
    with pytest.raises(UsageError, match=f"{name}='maybe' is not a truth value JAX reads"):
        check_process_environment("train")
    for word in ("0", "False", "on"):
        monkeypatch.setenv(name, word)
        check_process_environment("train")  # JAX's own words pass
    env = {**os.environ, name: "maybe"}
    out = tmp_path / "run"
    done = subprocess.run(
        [sys.executable, "-m", "adarl.cli.main", "train", "--algo", "sac", "--task", "hopper",
         "--total-steps", "500", "--out", str(out)],
        env=env, capture_output=True, text=True,
    )  # fmt: skip
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not out.exists()


@pytest.mark.parametrize(("backend", "library"), [("osmesa", "OSMesa"), ("egl", "EGL")])
def test_a_backend_whose_library_is_missing_is_one_line(backend, library, monkeypatch):
    # issue 61 §6: MUJOCO_GL=osmesa without libOSMesa was an ImportError traceback at `import
    # mujoco`, in every command that builds an env
    import ctypes.util

    from adarl.errors import UsageError
    from adarl.runtime import check_mujoco_gl

    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None if name == library else "x")
    monkeypatch.setenv("MUJOCO_GL", backend)
    with pytest.raises(UsageError, match=f"MUJOCO_GL='{backend}' needs the lib{library} library"):
        check_mujoco_gl()
    monkeypatch.setenv("MUJOCO_GL", "glfw")  # loads nothing at import
    check_mujoco_gl()
