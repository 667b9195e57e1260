"""Run-folder I/O shared by every trainer: atomic writes, append-only CSV logs that a resumed run
truncates back to the last checkpoint, TensorBoard scalars, and checkpoints that survive SIGKILL.
Also the run folder's safety: its lock (one writer at a time), checkpoint checksums and the
fallback to an older intact checkpoint, one-line file-system errors, the divergence watch.

The layout of a run folder is documented in docs/run-format.md; what is checked, in
docs/reliability.md.
"""

from __future__ import annotations

import csv
import fcntl
import hashlib
import io
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from adarl import __version__
from adarl.errors import ON_DIVERGENCE, Diverged, UsageError
from adarl.files import (  # noqa: F401  (re-exported: the run folder's writers)
    _fsync_dir,
    _json_default,
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_text,
    fs_errors,
)

RUN_FORMAT_VERSION = 1
CHECKPOINT_DIR = "checkpoints"
# checkpoints taken just before a truncation (fork points): kept, never rotated or resumed from
PRE_TRUNCATION_DIR = "checkpoints/pre_truncation"
LOCK_FILE = ".lock"  # holds the PID of the process writing the run (flock, see RunLock)
DAMAGED_PREFIX = "damaged_"  # a checkpoint that failed to load is renamed damaged_step_<n>


def check_writable_dir(path: str | os.PathLike, what: str = "--out") -> None:
    """A one-line UsageError unless `path` is a writable folder or can be created as one
    (writes nothing)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UsageError(f"{what} {path} is a file; give a folder")
    _check_creatable(path, path, what)


def check_writable_file(path: str | os.PathLike, what: str = "--out") -> None:
    """A one-line UsageError unless `path` can be written as a file (writes nothing)."""
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"{what} {path} is a folder; give a file name")
    _check_creatable(path, path.parent, what)


def _check_creatable(path: Path, folder: Path, what: str) -> None:
    """`folder` (to hold `path`) exists and is writable, or its nearest existing ancestor is."""
    probe = folder
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise UsageError(f"{what} {path} cannot be written: {probe} is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise UsageError(f"{what} {path} cannot be written: {probe} is not writable")


def check_memory(nbytes: int, what: str) -> None:
    """A one-line UsageError if `what` needs more bytes than the machine's physical memory."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # not knowable here: do not guess
        return
    if nbytes > total:
        raise UsageError(
            f"{what} need {nbytes / 2**30:.1f} GiB but this machine has {total / 2**30:.1f} GiB "
            "of memory; lower --buffer-size or train fewer seeds per run"
        )


def check_new_run_dir(run_dir: str | os.PathLike) -> None:
    """A new run's folder: writable and absent or empty (a lock file aside: a run killed before
    writing anything leaves one), else a one-line UsageError."""
    run_dir = Path(run_dir)
    check_writable_dir(run_dir)
    holder = lock_holder(run_dir)
    if holder:
        raise UsageError(
            f"run folder {run_dir} is being written by another adarl process (pid {holder}); "
            "choose another --out"
        )
    refuse_non_empty(run_dir)


def refuse_non_empty(run_dir: Path) -> None:
    """A one-line UsageError if `run_dir` holds anything but its lock file."""
    if run_dir.exists() and any(p.name != LOCK_FILE for p in run_dir.iterdir()):
        raise UsageError(
            f"run folder {run_dir} already exists and is not empty; "
            f"resume it with --resume {run_dir} or choose another --out"
        )


def check_resume_dir(run_dir: str | os.PathLike) -> None:
    """A run folder to resume: it exists, holds config.yaml and can be written."""
    run_dir = Path(run_dir)
    if not (run_dir / "config.yaml").exists():
        raise UsageError(f"{run_dir} is not a run folder (no config.yaml)")
    if not os.access(run_dir, os.W_OK | os.X_OK):
        raise UsageError(f"run folder {run_dir} is not writable")


# ----------------------------------------------------------------------------- the run lock
def lock_holder(run_dir: str | os.PathLike) -> str | None:
    """The PID (as written, or "?") of the process holding `run_dir`'s lock, or None."""
    try:
        with open(Path(run_dir) / LOCK_FILE, encoding="utf-8") as handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                return handle.read().strip() or "?"
            return None  # closing the file drops the shared lock just taken
    except OSError:
        return None


class RunLock:
    """An exclusive `flock` on RUN_DIR/.lock: one process writes a run folder at a time.

    Use as `with RunLock(run_dir) as lock:` around a trainer and call `lock.acquire(new)` after
    validating the input and before the first write. The kernel drops the lock when the process
    ends, however it ends, so a killed run never leaves a stale lock. The file holds the PID of
    the holder, which the one-line error of a second writer names (exit code 2).
    """

    def __init__(self, run_dir: str | os.PathLike):
        self.run_dir = Path(run_dir)
        self._handle = None

    def acquire(self, new: bool) -> None:
        """Take the lock (creating the folder of a `new` run); a UsageError if another process
        holds it or, for a new run, if the folder filled up meanwhile."""
        path = self.run_dir / LOCK_FILE
        with fs_errors(path):
            if new:
                self.run_dir.mkdir(parents=True, exist_ok=True)
            handle = open(path, "a+", encoding="utf-8")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            pid = handle.read().strip() or "?"
            handle.close()
            raise UsageError(
                f"run folder {self.run_dir} is being written by another adarl process "
                f"(pid {pid}); wait for it to end or stop it"
            ) from None
        self._handle = handle
        if new:  # it may have filled up since the check before the lock
            try:
                refuse_non_empty(self.run_dir)
            except UsageError:
                self.release()
                raise
        with fs_errors(path):
            handle.seek(0)
            handle.truncate()
            handle.write(f"{os.getpid()}\n")
            handle.flush()

    def release(self) -> None:
        if self._handle is not None:
            self._handle.close()  # closing the file drops the lock
            self._handle = None

    def __enter__(self) -> RunLock:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def write_environment(run_dir: str | os.PathLike, extra: dict | None = None) -> None:
    """Record what produced a new run (versions, commit, CPU, XLA flags; `extra` added) in
    environment.json; see adarl.train.provenance."""
    from adarl.train.provenance import write_environment

    write_environment(run_dir, extra)


# ----------------------------------------------------------------------------- CSV logs
class CsvLog:
    """Append-only CSV with a fixed header.

    Rows are flushed after each `write`; `offset()` is the file size, which a checkpoint records
    so that a resumed run can `truncate` away rows written after that checkpoint (and any half
    line a kill left behind).
    """

    def __init__(self, path: str | os.PathLike, columns: list[str]):
        self.path = Path(path)
        self.columns = list(columns)
        new = not self.path.exists() or self.path.stat().st_size == 0
        if not new:  # appending (a resumed run): keep the file's own column order
            with open(self.path, encoding="utf-8", newline="") as f:
                existing = next(csv.reader(f), [])
            if sorted(existing) != sorted(self.columns):
                raise UsageError(f"{self.path} has columns {existing}, expected {self.columns}")
            self.columns = existing
        with fs_errors(self.path):
            self._file = open(self.path, "a", newline="", encoding="utf-8")
            self._writer = csv.DictWriter(self._file, fieldnames=self.columns, extrasaction="raise")
            if new:
                self._writer.writeheader()
                self._file.flush()

    def write(self, rows: dict | list[dict]) -> None:
        if isinstance(rows, dict):
            rows = [rows]
        with fs_errors(self.path):
            for row in rows:
                self._writer.writerow({k: _fmt(v) for k, v in row.items()})
            self._file.flush()

    def offset(self) -> int:
        with fs_errors(self.path):
            self._file.flush()
            return self._file.tell()

    def close(self) -> None:
        try:
            self._file.close()
        except OSError:  # a failed write already raised; rows not flushed then are lost anyway
            pass

    @staticmethod
    def truncate(path: str | os.PathLike, offset: int) -> None:
        """Cut `path` back to `offset` bytes (the size recorded in a checkpoint)."""
        path = Path(path)
        if path.exists() and path.stat().st_size > offset:
            with fs_errors(path), open(path, "r+b") as f:
                f.truncate(offset)


def _fmt(v):
    if isinstance(v, float | np.floating):
        return f"{float(v):.6g}"
    if isinstance(v, np.integer):
        return int(v)
    return v


def read_csv(path: str | os.PathLike) -> list[dict]:
    """Read a run CSV, ignoring a trailing half-written line."""
    text = Path(path).read_text(encoding="utf-8")
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    return list(csv.DictReader(io.StringIO(text)))


# ----------------------------------------------------------------------------- TensorBoard
def _summary_writer():
    """tensorboardX's SummaryWriter, imported without torch. tensorboardX imports torch when it
    is installed (the `bench` extra), only to accept torch tensors, which costs 1.5–2 s per
    process; torch is hidden during that import and importable again afterwards."""
    hide = "torch" not in sys.modules
    if hide:
        sys.modules["torch"] = None  # makes `import torch` raise ImportError
    try:
        from tensorboardX import SummaryWriter
    finally:
        if hide:
            del sys.modules["torch"]
    return SummaryWriter


class Scalars:
    """TensorBoard scalar writer; `purge_step` hides events past a resumed checkpoint."""

    def __init__(self, log_dir: str | os.PathLike, purge_step: int | None = None):
        self._writer = _summary_writer()(str(log_dir), purge_step=purge_step, flush_secs=30)

    def write(self, step: int, scalars: dict[str, float]) -> None:
        from adarl.train import tracking

        finite = {k: float(v) for k, v in scalars.items() if np.isfinite(v)}
        for name, value in finite.items():  # a non-finite one is the divergence watch's to report
            self._writer.add_scalar(name, value, int(step))
        tracking.log(step, finite)  # `adarl train --track`: the same scalars to W&B

    def close(self) -> None:
        try:
            self._writer.close()
        except OSError:  # TensorBoard events are a convenience; the CSVs are the record
            pass


# ----------------------------------------------------------------------------- pytrees <-> arrays
def flatten_tree(tree, prefix: str = "") -> dict[str, np.ndarray]:
    """Flatten a pytree of arrays into `{path: np.ndarray}` (paths are jax key strings)."""
    import jax

    leaves = jax.tree_util.tree_flatten_with_path(tree)[0]
    return {prefix + jax.tree_util.keystr(path): np.asarray(leaf) for path, leaf in leaves}


def unflatten_tree(template, arrays: dict[str, np.ndarray], prefix: str = ""):
    """Rebuild a pytree shaped like `template` from `flatten_tree` output, checking shapes."""
    import jax

    paths, treedef = jax.tree_util.tree_flatten_with_path(template)
    leaves = []
    for path, leaf in paths:
        key = prefix + jax.tree_util.keystr(path)
        if key not in arrays:
            raise UsageError(
                f"checkpoint is missing array {key!r}; it was written by another version"
            )
        value = arrays[key]
        if tuple(value.shape) != tuple(np.shape(leaf)):
            raise UsageError(
                f"checkpoint array {key!r} has shape {value.shape}, expected {np.shape(leaf)}"
            )
        leaves.append(value)
    return jax.tree_util.tree_unflatten(treedef, leaves)


# ----------------------------------------------------------------------------- checkpoints
def checkpoint_dirs(run_dir: str | os.PathLike, folder: str = CHECKPOINT_DIR) -> list[Path]:
    """Complete checkpoints of a run, oldest first (a complete one has meta.json); `folder`
    PRE_TRUNCATION_DIR: the pre-truncation ones."""
    root = Path(run_dir) / folder
    if not root.is_dir():
        return []
    found = [p for p in root.iterdir() if p.is_dir() and p.name.startswith("step_")]
    found = [p for p in found if (p / "meta.json").exists() and (p / "arrays.npz").exists()]
    return sorted(found, key=lambda p: int(p.name.split("_")[1]))


def save_checkpoint(
    run_dir: str | os.PathLike,
    step: int,
    arrays: dict[str, np.ndarray],
    meta: dict,
    keep: int = 2,
    files: dict[str, bytes] | None = None,
    folder: str = CHECKPOINT_DIR,
) -> Path:
    """Write `<folder>/step_<step>/` (default `checkpoints/`) atomically: a temp folder holding
    arrays.npz, the extra `files` (name -> bytes, e.g. policy files) and meta.json (written last,
    with the sha256 of arrays.npz) is renamed into place, then older checkpoints of that folder
    beyond `keep` go (0: none). An OSError becomes a one-line `RunFailed`; the checkpoints
    already there are left as they were."""
    root = Path(run_dir) / folder
    final = root / f"step_{step:012d}"
    with fs_errors(final):
        root.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=root, prefix=".tmp_step_"))
        try:
            os.chmod(tmp, 0o755)  # mkdtemp makes 0700; a run folder is readable like its files
            with open(tmp / "arrays.npz", "wb") as f:
                np.savez(f, **arrays)
                f.flush()
                os.fsync(f.fileno())
            for name, data in (files or {}).items():
                with open(tmp / name, "wb") as f:
                    f.write(data)
                    f.flush()
                    os.fsync(f.fileno())
            meta = dict(
                meta,
                step=int(step),
                format_version=RUN_FORMAT_VERSION,
                adarl_version=__version__,
                arrays_sha256=file_sha256(tmp / "arrays.npz"),
            )
            with open(tmp / "meta.json", "w", encoding="utf-8") as f:
                json.dump(meta, f, indent=1, sort_keys=True, default=_json_default)
                f.flush()
                os.fsync(f.fileno())
            if final.exists():
                shutil.rmtree(final)
            os.replace(tmp, final)
            _fsync_dir(root)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    for old in checkpoint_dirs(run_dir, folder)[:-keep] if keep > 0 else []:
        shutil.rmtree(old, ignore_errors=True)
    for stale in root.glob(".tmp_step_*"):  # left by a killed writer
        shutil.rmtree(stale, ignore_errors=True)
    return final


def file_sha256(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


class CheckpointDamaged(UsageError):
    """A checkpoint that cannot be read back (bad zip, short file, wrong checksum)."""


def load_checkpoint(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict]:
    """Read one checkpoint folder. A damaged one (unreadable meta.json or arrays.npz, or
    arrays.npz not matching its checksum) raises `CheckpointDamaged`, another format version a
    UsageError; both one line. Checkpoints written before checksums load without the check."""
    path = Path(path)
    try:
        meta = json.loads((path / "meta.json").read_text(encoding="utf-8"))
        expected = meta.get("arrays_sha256")
        if expected is not None and file_sha256(path / "arrays.npz") != expected:
            raise CheckpointDamaged(
                f"checkpoint {path} is damaged (arrays.npz does not match its sha256 in meta.json)"
            )
        with np.load(path / "arrays.npz", allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except CheckpointDamaged:
        raise
    except Exception as exc:  # BadZipFile, EOFError, OSError, ValueError, …: all mean damaged
        reason = " ".join(f"{type(exc).__name__}: {exc}".split())
        raise CheckpointDamaged(f"checkpoint {path} is unreadable ({reason})") from exc
    if meta.get("format_version") != RUN_FORMAT_VERSION:
        raise UsageError(
            f"checkpoint {path} has format version {meta.get('format_version')!r}; "
            f"this adarl ({__version__}) reads version {RUN_FORMAT_VERSION}"
        )
    return arrays, meta


def latest_checkpoint(run_dir: str | os.PathLike) -> Path:
    found = checkpoint_dirs(run_dir)
    if not found:
        raise UsageError(f"run folder {run_dir} has no complete checkpoint")
    return found[-1]


def load_latest_intact(run_dir: str | os.PathLike, warn=None):
    """The newest checkpoint that loads: `(path, arrays, meta)`, or None if the run has none.

    Each damaged checkpoint is reported in one line (`warn`, default: stderr) and the next older
    one is tried; the damaged ones newer than the one used are renamed `damaged_step_<n>` (kept
    for inspection, never loaded again). With none intact, a one-line UsageError and nothing
    renamed. Call it only while holding the run's lock.
    """
    warn = warn or (lambda line: print(line, file=sys.stderr, flush=True))
    found = checkpoint_dirs(run_dir)
    damaged = []
    for path in reversed(found):
        try:
            arrays, meta = load_checkpoint(path)
        except CheckpointDamaged as exc:
            warn(f"adarl: warning: {exc}; trying the next older checkpoint")
            damaged.append(path)
            continue
        for bad in damaged:
            aside = bad.with_name(DAMAGED_PREFIX + bad.name)
            with fs_errors(aside):
                if aside.exists():
                    shutil.rmtree(aside)
                os.replace(bad, aside)
        return path, arrays, meta
    if found:
        raise UsageError(
            f"run folder {run_dir} has no intact checkpoint (all {len(found)} are damaged); "
            "start a new run"
        )
    return None


#: config fields a run may change between its checkpoint and a resume (the others are the run)
RESUMABLE_EDITS = (
    "checkpoint_before_truncation",
    "total_steps",
    "on_divergence",
    "keep_checkpoints",
    "checkpoint_every",
    "log_every",
    "eval_every",
    "eval_episodes",
    "eval_dynamics",
    "eager_candidates",  # RNAC: the same transitions, computed another way
)


def config_record(config) -> dict:
    """A config as checkpoints store it (`meta["config"]`): plain JSON values."""
    import dataclasses

    return json.loads(json.dumps(dataclasses.asdict(config), default=_json_default))


def check_resume_config(run_dir: str | os.PathLike, meta: dict, config) -> None:
    """A one-line UsageError naming the first field of config.yaml that differs from the config
    the checkpoint was written with (fields in `RESUMABLE_EDITS` may differ). Checkpoints
    written before the config was recorded are checked on their seeds only."""
    now = config_record(config)
    then = meta.get("config")
    if then is None:
        then = {"seeds": meta["seeds"]} if "seeds" in meta else {}
    for name, value in then.items():
        if name in RESUMABLE_EDITS or name not in now or now[name] == value:
            continue
        raise UsageError(
            f"{Path(run_dir) / 'config.yaml'} field {name!r} is {now[name]!r} but the run's "
            f"checkpoint was written with {value!r}; put it back to resume, or start a new run"
        )


# ----------------------------------------------------------------------------- divergence
class DivergenceWatch:
    """Non-finite losses, parameters and returns, per seed, checked at each logging point.

    `note(quantity, seeds)` records them; `check(step)` then stops the run with `Diverged` (exit
    code 3; no DONE; the last checkpoint stays the last good one) or, with `--on-divergence
    continue`, prints one warning line the first time and goes on.
    """

    def __init__(self, run_dir: str | os.PathLike, mode: str = "stop"):
        self.run_dir = Path(run_dir)
        self.mode = mode if mode in ON_DIVERGENCE else "stop"
        self.found: dict[str, list[int]] = {}
        self.warned = False

    def note(self, quantity: str, seeds) -> None:
        seeds = [int(s) for s in seeds]
        if seeds:
            known = self.found.setdefault(quantity, [])
            known.extend(s for s in seeds if s not in known)

    def note_values(self, quantity: str, seeds, values) -> None:
        """Note the seeds whose `values` (one per seed, or per seed × anything) are not all
        finite."""
        values = np.asarray(values, dtype=np.float64).reshape(len(seeds), -1)
        self.note(quantity, [s for s, ok in zip(seeds, np.isfinite(values).all(axis=1)) if not ok])

    def check(self, step: int) -> None:
        if not self.found:
            return
        what = "; ".join(
            f"{q} (seed{'s' * (len(s) > 1)} {', '.join(map(str, sorted(s)))})"
            for q, s in self.found.items()
        )
        self.found = {}
        good = checkpoint_dirs(self.run_dir)
        kept = f"last good checkpoint {good[-1].name}" if good else "no checkpoint yet"
        if self.mode == "stop":
            raise Diverged(
                f"training diverged at step {step}: non-finite {what}; {kept} "
                "(--on-divergence continue keeps training)"
            )
        if not self.warned:
            print(
                f"adarl: warning: training diverged at step {step}: non-finite {what}; "
                "continuing (--on-divergence continue)",
                file=sys.stderr,
                flush=True,
            )
            self.warned = True
