"""Run-folder I/O shared by every trainer: atomic writes, append-only CSV logs that a resumed run
truncates back to the last checkpoint, TensorBoard scalars, and checkpoints that survive SIGKILL.

The layout of a run folder is documented in docs/run-format.md.
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from adarl import __version__
from adarl.errors import UsageError

RUN_FORMAT_VERSION = 1
CHECKPOINT_DIR = "checkpoints"


# ----------------------------------------------------------------------------- atomic writes
def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write `data` to `path` via a temp file in the same folder, fsync and rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)  # mkstemp makes 0600; outputs are ordinary readable files
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | os.PathLike, obj) -> None:
    atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n")


def _json_default(obj):
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")


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
        self._file = open(self.path, "a", newline="", encoding="utf-8")
        self._writer = csv.DictWriter(self._file, fieldnames=self.columns, extrasaction="raise")
        if new:
            self._writer.writeheader()
            self._file.flush()

    def write(self, rows: dict | list[dict]) -> None:
        if isinstance(rows, dict):
            rows = [rows]
        for row in rows:
            self._writer.writerow({k: _fmt(v) for k, v in row.items()})
        self._file.flush()

    def offset(self) -> int:
        self._file.flush()
        return self._file.tell()

    def close(self) -> None:
        self._file.close()

    @staticmethod
    def truncate(path: str | os.PathLike, offset: int) -> None:
        """Cut `path` back to `offset` bytes (the size recorded in a checkpoint)."""
        path = Path(path)
        if path.exists() and path.stat().st_size > offset:
            with open(path, "r+b") as f:
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
        for name, value in scalars.items():
            self._writer.add_scalar(name, float(value), int(step))

    def close(self) -> None:
        self._writer.close()


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
def checkpoint_dirs(run_dir: str | os.PathLike) -> list[Path]:
    """Complete checkpoints of a run, oldest first (a complete one has meta.json)."""
    root = Path(run_dir) / CHECKPOINT_DIR
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
) -> Path:
    """Write `checkpoints/step_<step>/` atomically: a temp folder holding arrays.npz, the extra
    `files` (name -> bytes, e.g. policy files) and meta.json (written last) is renamed into
    place, then older checkpoints beyond `keep` go."""
    root = Path(run_dir) / CHECKPOINT_DIR
    root.mkdir(parents=True, exist_ok=True)
    final = root / f"step_{step:012d}"
    tmp = Path(tempfile.mkdtemp(dir=root, prefix=".tmp_step_"))
    try:
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
            meta, step=int(step), format_version=RUN_FORMAT_VERSION, adarl_version=__version__
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
    for old in checkpoint_dirs(run_dir)[:-keep] if keep > 0 else []:
        shutil.rmtree(old, ignore_errors=True)
    for stale in root.glob(".tmp_step_*"):  # left by a killed writer
        shutil.rmtree(stale, ignore_errors=True)
    return final


def load_checkpoint(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict]:
    """Read one checkpoint folder; raise a one-line UsageError if it is unusable."""
    path = Path(path)
    try:
        meta = json.loads((path / "meta.json").read_text(encoding="utf-8"))
        with np.load(path / "arrays.npz", allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, KeyError) as exc:
        raise UsageError(f"checkpoint {path} is unreadable ({type(exc).__name__}: {exc})") from exc
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


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
