"""Process-wide XLA settings; they must be in the environment before JAX starts."""

from __future__ import annotations

import functools
import os
import sys

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


# ----------------------------------------------------------------------------- checked up front
# A bad MUJOCO_GL, JAX_PLATFORMS or XLA_FLAGS would stop a command deep inside MuJoCo or XLA (a
# traceback, or XLA's own abort) after its output folder is made: each is checked before a
# command writes anything, in one line, exit code 2 (docs/reliability.md).
#: MUJOCO_GL values MuJoCo accepts by platform, besides glfw and the on/off words (its check:
#: mujoco/rendering/classic/gl_context.py)
_MUJOCO_GL_PLATFORM = {"linux": ("glx", "egl", "osmesa"), "win32": ("wgl",), "darwin": ("cgl",)}
#: the library each software/headless backend loads when MuJoCo is imported, and its package
_MUJOCO_GL_LIBRARY = {"osmesa": ("OSMesa", "libosmesa6"), "egl": ("EGL", "libegl1")}
#: commands that build MuJoCo environments, and those that start JAX (train, and sweeps' workers)
MUJOCO_COMMANDS = ("train", "evaluate", "play", "sweep", "tasks")
JAX_COMMANDS = ("train", "sweep")


def check_process_environment(command: str) -> None:
    """The environment variables `command` depends on, checked before it writes anything."""
    if command in MUJOCO_COMMANDS:
        check_mujoco_gl()
    if command in JAX_COMMANDS:
        check_jax_booleans()
        check_jax_backend()


#: the words JAX reads a boolean environment variable from (its `config.bool_env`)
_JAX_TRUE = ("y", "yes", "t", "true", "on", "1")
_JAX_FALSE = ("n", "no", "f", "false", "off", "0")


def check_jax_booleans() -> None:
    """A one-line UsageError if JAX_ENABLE_X64 (or JAX_DEBUG_NANS) is set to a word JAX cannot
    read as true or false: JAX raises a ValueError with a traceback when it starts."""
    from adarl.errors import UsageError

    for name in ("JAX_ENABLE_X64", "JAX_DEBUG_NANS"):
        value = os.environ.get(name)
        if value is not None and value.lower() not in _JAX_TRUE + _JAX_FALSE:
            raise UsageError(
                f"{name}={value!r} is not a truth value JAX reads; allowed: "
                f"{', '.join(_JAX_TRUE)} or {', '.join(_JAX_FALSE)} (or unset it)"
            )


def check_mujoco_gl() -> None:
    """A one-line UsageError if MUJOCO_GL is set to a value MuJoCo refuses (at import, with a
    traceback, even in a command that renders nothing)."""
    from adarl.errors import UsageError

    value = os.environ.get("MUJOCO_GL")
    if value is None:
        return
    system = next((k for k in _MUJOCO_GL_PLATFORM if sys.platform.startswith(k)), "")
    allowed = (
        ("disable", "disabled", "off", "false", "0", "enable", "enabled", "on", "true", "1")
        + ("glfw", "")
        + _MUJOCO_GL_PLATFORM.get(system, ())
    )
    if value.lower().strip() not in allowed:
        names = [*_MUJOCO_GL_PLATFORM.get(system, ()), "glfw", "disable"]
        raise UsageError(
            f"MUJOCO_GL={value!r} is not a MuJoCo rendering backend; allowed: "
            f"{', '.join(names)} (or unset it)"
        )
    library, package = _MUJOCO_GL_LIBRARY.get(value.lower().strip(), (None, None))
    if library is not None:
        import ctypes.util

        if ctypes.util.find_library(library) is None:  # `import mujoco` would fail, a traceback
            raise UsageError(
                f"MUJOCO_GL={value!r} needs the lib{library} library, which this machine lacks "
                f"(Debian/Ubuntu: {package}); allowed: install it, another backend, or unset it"
            )


def check_jax_backend() -> None:
    """A one-line UsageError if JAX cannot start with this process's JAX_PLATFORMS and
    XLA_FLAGS: adarl's own XLA flags are checked here; other flags and any platform but `cpu`
    are tried once in a child process (XLA aborts the process on a flag it does not know)."""
    from adarl.errors import UsageError

    flags = os.environ.get("XLA_FLAGS", "").split()
    probe = False
    for flag in flags:
        name, _, value = flag.lstrip("-").partition("=")
        if name == "xla_force_host_platform_device_count":
            if not (value.isdigit() and int(value) >= 1):
                raise UsageError(
                    f"XLA_FLAGS has {flag}; allowed: --xla_force_host_platform_device_count=N "
                    "with N >= 1 (or unset XLA_FLAGS: adarl sets one device per core)"
                )
        elif name == "xla_cpu_multi_thread_eigen":
            if value.lower() not in ("true", "false", "1", "0"):
                raise UsageError(
                    f"XLA_FLAGS has {flag}; allowed: --xla_cpu_multi_thread_eigen=true|false"
                )
        else:
            probe = True
    platforms = os.environ.get("JAX_PLATFORMS", "").strip().lower()
    if probe or platforms not in ("", "cpu"):
        why = _jax_start_failure(platforms, os.environ.get("XLA_FLAGS", ""))
        if why:
            raise UsageError(
                f"JAX cannot start with JAX_PLATFORMS={os.environ.get('JAX_PLATFORMS', '')!r} "
                f"XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r} ({why}); fix or unset them "
                "(JAX_PLATFORMS=cpu without XLA_FLAGS always works)"
            )


@functools.cache
def _jax_start_failure(platforms: str, xla_flags: str) -> str | None:
    """Why a child process with this environment cannot list JAX's devices, or None."""
    import subprocess

    try:
        done = subprocess.run(
            [sys.executable, "-c", "import jax; jax.devices()"],
            capture_output=True,
            text=True,
            errors="replace",
            timeout=600,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"could not try it: {type(exc).__name__}"
    if done.returncode == 0:
        return None
    lines = [line.strip() for line in done.stderr.splitlines() if line.strip()]
    for line in lines:  # glog: "E1204 12:54:40.19 17055 file.cc:63] message"
        if line[:1] in "EF" and line[1:5].isdigit() and "] " in line:
            return line.split("] ", 1)[1][:300]
    errors = [line for line in lines if "Error: " in line]
    return (errors or lines or [f"exit code {done.returncode}"])[-1][:300]
