"""What produced a run: package versions, adarl's git commit, Python, CPU, XLA flags and the
numeric settings (x64, matmul precision, platform, …) that a resume must share (`numerics`).

Every trainer writes `environment.json` into a new run folder (`write_environment`) and appends
what each resume ran to its `resumes` (`record_resume`); `adarl report` lists the records and
warns when runs compared were made with different versions of the packages in `COMPARED`, or a
run was resumed with other code (`code_changes`) (docs/run-format.md).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path

from adarl import __version__
from adarl.errors import UsageError
from adarl.files import UnreadableFile, atomic_write_json, read_json
from adarl.runs.layout import ENVIRONMENT_FILE

FORMAT_VERSION = 1
#: Distributions whose versions are recorded (by their installed metadata: nothing is imported).
PACKAGES = ("jax", "jaxlib", "mujoco", "gymnasium", "numpy", "optax")
#: Packages whose versions must agree for runs to be compared without a warning.
COMPARED = ("jax", "mujoco", "gymnasium")
GIT_TIMEOUT_S = 2.0


def environment_record() -> dict:
    """The record `write_environment` stores: a JSON-ready dict."""
    return {
        "format_version": FORMAT_VERSION,
        "adarl": {"version": __version__, **_git_state()},
        "python": {"version": platform.python_version(), "implementation": sys.implementation.name},
        "packages": {name: _version(name) for name in PACKAGES},
        "platform": {"system": platform.system(), "release": platform.release()},
        "cpu": {
            "model": _cpu_model(),
            "machine": platform.machine(),
            "cores": os.cpu_count(),
            "usable_cores": len(os.sched_getaffinity(0))
            if hasattr(os, "sched_getaffinity")
            else os.cpu_count(),
        },
        "xla_flags": os.environ.get("XLA_FLAGS"),
        "numerics": numerics(),
    }


# ----------------------------------------------------------------------------- numerics
#: JAX settings (`jax.config` names) that change a run's numbers: float64 everywhere, the
#: precision of matrix products (on accelerators), the random-number generator and its
#: sharding rule, and op-by-op execution instead of compiled (fused) computations
NUMERIC_CONFIG = (
    "jax_enable_x64",
    "jax_default_matmul_precision",
    "jax_default_prng_impl",
    "jax_threefry_partitionable",
    "jax_disable_jit",
)
#: XLA flags that change where computations run, not their numbers: adarl sets one CPU device
#: per core (`adarl.runtime`), and a seed's numbers do not depend on its device
NEUTRAL_XLA_FLAGS = ("xla_force_host_platform_device_count",)
#: where each numeric setting comes from, for the refusal's hint
NUMERIC_SOURCES = {
    "platform": "JAX_PLATFORMS",
    "xla_flags": "XLA_FLAGS",
    **{name: name.upper() for name in NUMERIC_CONFIG},
}


def numerics() -> dict:
    """The settings of this process that change a run's numbers (docs/reliability.md): each of
    `NUMERIC_CONFIG`, JAX's platform (`jax.default_backend()`: cpu, gpu, tpu) and XLA_FLAGS
    less `NEUTRAL_XLA_FLAGS`, sorted (None when none is left). Imports JAX."""
    import jax

    def plain(value):
        value = getattr(value, "value", value)  # an enum (dtype promotion and the like)
        return value if value is None or isinstance(value, bool | int | float) else str(value)

    flags = sorted(
        flag
        for flag in os.environ.get("XLA_FLAGS", "").split()
        if not flag.lstrip("-").startswith(NEUTRAL_XLA_FLAGS)
    )
    return {
        **{name: plain(getattr(jax.config, name, None)) for name in NUMERIC_CONFIG},
        "platform": jax.default_backend(),
        "xla_flags": " ".join(flags) or None,
    }


def recorded_numerics(record: dict | None) -> dict | None:
    """The numeric settings a run's record says it last trained under: those of its newest
    resume that recorded them, else those it was made with; None for runs made before they
    were recorded (or a record whose `numerics` is not an object)."""
    for part in [*reversed((record or {}).get("resumes", [])), record or {}]:
        found = part.get("numerics")
        if isinstance(found, dict):
            return found
    return None


def check_resume_numerics(run_dir: str | os.PathLike) -> None:
    """A one-line UsageError if this process would resume the run under numeric settings
    (`numerics`) other than those it last trained under, naming each setting, both values and
    the variable that sets it: the resumed steps would differ from an uninterrupted run's
    (issue 55). Runs without a record, or made before settings were recorded, are not checked;
    a damaged record is left to `record_resume`'s warning."""
    try:
        then = recorded_numerics(read_environment(run_dir))
    except UsageError:
        return
    if then is None:
        return
    now = numerics()
    changed = [
        f"{name} {then[name]!r} but this process has {now[name]!r} ({NUMERIC_SOURCES[name]})"
        for name in now
        if name in then and then[name] != now[name]
    ]
    if changed:
        raise UsageError(
            f"run folder {run_dir} was trained with {'; '.join(changed)}; a resume under other "
            "numeric settings would not continue it exactly: set them as the run had them "
            "(environment.json 'numerics'), or start a new run"
        )


def write_environment(run_dir: str | os.PathLike, extra: dict | None = None) -> None:
    """Write `environment_record()` (plus `extra`, e.g. a fork's record) to
    RUN_DIR/environment.json (atomically)."""
    atomic_write_json(Path(run_dir) / ENVIRONMENT_FILE, {**environment_record(), **(extra or {})})


def record_resume(run_dir: str | os.PathLike, step: int) -> None:
    """Append what resumes the run at `step` (adarl's version and commit, the package versions)
    to RUN_DIR/environment.json's `resumes` list (atomically). A run without the file, made
    before it existed, is left as it was; so is a damaged one, with a warning (training goes on:
    the file is metadata, and `adarl report` names it)."""
    try:
        record = read_environment(run_dir)
    except UsageError as exc:
        print(f"adarl: warning: {exc}; this resume is not recorded in it", file=sys.stderr)
        return
    if record is None:
        return
    now = environment_record()
    entry = {"step": int(step), "adarl": now["adarl"], "packages": now["packages"]}
    entry["numerics"] = now["numerics"]
    resumes = [*record.get("resumes", []), entry]
    atomic_write_json(Path(run_dir) / ENVIRONMENT_FILE, {**record, "resumes": resumes})


def code_changes(record: dict | None) -> list[str]:
    """Each change of adarl's code (version, commit) or of a `COMPARED` package's version at a
    resume, as `adarl 0.1.0 (89e02c6ce3f2) → 0.1.0 (e9f6ba3d2f70) from step 1,050,000`; empty
    without a record or when every resume ran what created the run. An unknown commit on either
    side (not a git checkout) is not a change."""
    if not record:
        return []

    def state(part: dict) -> dict[str, str | None]:
        adarl, packages = part.get("adarl") or {}, part.get("packages") or {}
        code = _code_text(adarl) if adarl.get("git_commit") else None
        return {"adarl": code, **{name: packages.get(name) for name in COMPARED}}

    changes, before = [], state(record)
    for resume in record.get("resumes", []):
        after = state(resume)
        changed = [
            f"{name} {before[name]} → {after[name]}"
            for name in before
            if before[name] and after[name] and before[name] != after[name]
        ]
        if changed:
            changes.append(f"{', '.join(changed)} from step {resume['step']:,}")
        before = {name: after[name] or before[name] for name in before}
    return changes


#: the parts of a record that are objects (`summary` reads their keys)
RECORD_OBJECTS = ("adarl", "python", "packages", "cpu")


def read_environment(run_dir: str | os.PathLike) -> dict | None:
    """A run's record, or None if it has none (runs made before it was written). One that is
    not a JSON object of `environment_record()`'s shape is a one-line UsageError naming it."""
    path = Path(run_dir) / ENVIRONMENT_FILE
    if not path.is_file():
        return None
    try:
        record = read_json(path)
    except UnreadableFile as exc:
        raise UsageError(f"{exc}; delete it or restore it") from None
    if not isinstance(record, dict):
        raise UsageError(f"{path} is not a JSON object; delete it or restore it")
    for key in RECORD_OBJECTS:
        if record.get(key) is not None and not isinstance(record[key], dict):
            raise UsageError(
                f"{path} field {key!r} is {record[key]!r}; allowed: an object "
                "(as adarl writes it); delete the file or restore it"
            )
    resumes = record.get("resumes", [])
    if not isinstance(resumes, list) or not all(
        isinstance(r, dict) and isinstance(r.get("step"), int) for r in resumes
    ):
        raise UsageError(
            f"{path} field 'resumes' is {resumes!r}; allowed: a list of objects with an integer "
            "step (as adarl writes it); delete the file or restore it"
        )
    return record


def summary(record: dict | None) -> dict[str, str]:
    """One flat row for a table: adarl (+ commit), python, each package, cpu, cores, XLA_FLAGS;
    "unknown" throughout for a run without a record."""
    if record is None:
        return dict.fromkeys(("adarl", "python", *PACKAGES, "cpu", "cores", "XLA_FLAGS"), "unknown")
    adarl, cpu = record.get("adarl") or {}, record.get("cpu") or {}
    version = _code_text(adarl)
    packages = record.get("packages") or {}
    return {
        "adarl": version,
        "python": str((record.get("python") or {}).get("version") or "unknown"),
        **{name: str(packages.get(name) or "unknown") for name in PACKAGES},
        "cpu": str(cpu.get("model") or "unknown"),
        "cores": str(cpu.get("cores") or "unknown"),
        "XLA_FLAGS": str(record.get("xla_flags") or "—"),
    }


def mismatches(records: dict[str, dict | None]) -> list[str]:
    """One line per package of `COMPARED` whose version differs between runs ({name: record});
    runs without a record are left out of the comparison."""
    lines = []
    for package in COMPARED:
        by_version: dict[str, list[str]] = {}
        for name, record in records.items():
            version = ((record or {}).get("packages") or {}).get(package)
            if version:
                by_version.setdefault(str(version), []).append(name)
        if len(by_version) > 1:
            groups = "; ".join(f"{v} ({', '.join(names)})" for v, names in by_version.items())
            lines.append(f"runs were made with different {package} versions: {groups}")
    return lines


def _code_text(adarl: dict) -> str:
    """adarl's version with its commit, as `0.1.0 (89e02c6ce3f2)` (`+dirty` with uncommitted
    changes); the version alone outside a git checkout."""
    text = str(adarl.get("version") or "unknown")
    if adarl.get("git_commit"):
        text += f" ({adarl['git_commit'][:12]}{'+dirty' if adarl.get('git_dirty') else ''})"
    return text


def _version(distribution: str) -> str | None:
    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return None


def _git_state() -> dict:
    """adarl's commit and whether the checkout has uncommitted changes, when adarl is imported
    from a git checkout (an editable install); None for both otherwise or if git fails."""
    root = Path(__file__).resolve().parents[2]
    state = {"git_commit": None, "git_dirty": None}
    if not (root / ".git").exists():
        return state
    commit = _git(root, "rev-parse", "HEAD")
    if commit:
        state["git_commit"] = commit
        status = _git(root, "status", "--porcelain", "--untracked-files=no")
        state["git_dirty"] = None if status is None else bool(status)
    return state


def _git(root: Path, *args: str) -> str | None:
    try:
        out = subprocess.run(
            ["git", "--no-optional-locks", "-C", str(root), *args],  # read-only
            capture_output=True,
            text=True,
            timeout=GIT_TIMEOUT_S,
            check=True,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip()


def _cpu_model() -> str | None:
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.partition(":")[2].strip()
    except OSError:
        pass
    return platform.processor() or None
