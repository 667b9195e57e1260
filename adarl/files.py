"""Atomic file writes, one-line file-system errors and the check that an output path can be
written: the lowest layer of adarl's I/O, used by the run folder (`adarl.runs`), policy files
(`adarl.policy`) and every command's outputs."""

from __future__ import annotations

import contextlib
import errno
import glob
import json
import os
import secrets
import shutil
import socket
from pathlib import Path

import numpy as np

from adarl.errors import RunFailed, UsageError


@contextlib.contextmanager
def fs_errors(path: str | os.PathLike, doing: str = "write"):
    """Turn an OSError in the block (disk full, permission lost) into a one-line `RunFailed`
    naming the path and the OS error (exit code 1)."""
    try:
        yield
    except OSError as exc:
        where = exc.filename or path
        raise RunFailed(f"cannot {doing} {where}: {exc.strerror or exc}") from exc


# Permissions (docs/reliability.md): every file and folder adarl creates gets the mode the umask
# gives any new one (files 0666, folders 0777, less the umask), temporary ones renamed into place
# included; hence `temp_file` and `temp_dir` instead of tempfile's 0600 / 0700.
def temp_file(folder: str | os.PathLike, prefix: str, suffix: str = "") -> tuple[int, str]:
    """`(fd, path)` of a new file in `folder` with a free random name, as `tempfile.mkstemp`
    but with the mode the umask gives (mkstemp makes 0600)."""
    for _ in range(100):
        name = os.path.join(folder, f"{prefix}{secrets.token_hex(6)}{suffix}")
        try:
            return os.open(name, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o666), name
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, "no free temporary file name", str(folder))


def temp_dir(folder: str | os.PathLike, prefix: str) -> Path:
    """A new folder in `folder` with a free random name, as `tempfile.mkdtemp` but with the
    mode the umask gives (mkdtemp makes 0700)."""
    for _ in range(100):
        name = Path(folder) / f"{prefix}{secrets.token_hex(6)}"
        try:
            name.mkdir(0o777)
            return name
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, "no free temporary folder name", str(folder))


def process_temp_dir(folder: str | os.PathLike, prefix: str) -> Path:
    """`temp_dir` named `<prefix><pid>-<host>-<random>`, so that `remove_orphans` can tell one
    whose process is gone (killed before it could remove it)."""
    return temp_dir(folder, f"{prefix}{os.getpid()}-{socket.gethostname()}-")


def remove_orphans(folder: str | os.PathLike, prefix: str) -> None:
    """Remove the folders `process_temp_dir(folder, prefix)` made for processes of this host that
    no longer run; those of live processes, or of other hosts, stay."""
    host = socket.gethostname()
    for path in Path(folder).glob(f"{glob.escape(prefix)}*"):
        pid, _, rest = path.name[len(prefix) :].partition("-")
        if pid.isdigit() and rest.rpartition("-")[0] == host and not _alive(int(pid)):
            shutil.rmtree(path, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's
        return True
    return True


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write `data` to `path` via a temp file in the same folder, fsync and rename."""
    path = Path(path)
    with fs_errors(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = temp_file(path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | os.PathLike, obj) -> None:
    atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=True, default=json_default) + "\n")


def json_default(obj):
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")


def fsync_dir(path: Path) -> None:
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


# Every command checks its output paths with these two, before it writes anything (dry runs
# too). Missing folders are fine: every command creates them, like `mkdir -p`.
def check_writable_dir(path: str | os.PathLike, what: str = "--out") -> None:
    """A one-line UsageError unless `path` is a writable folder or can be created as one
    (leaves nothing behind: see `probe_writable`)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UsageError(f"{what} {path} is a file; give a folder")
    _check_creatable(path, path, what)


def check_writable_file(path: str | os.PathLike, what: str = "--out") -> None:
    """A one-line UsageError unless `path` can be written as a file (leaves nothing behind)."""
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"{what} {path} is a folder; give a file name")
    _check_creatable(path, path.parent, what)


def _check_creatable(path: Path, folder: Path, what: str) -> None:
    """`folder` (to hold `path`) exists and is writable, or its nearest existing ancestor is."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise UsageError(f"{what} {path} cannot be written: {existing} is a file, not a folder")
    why = probe_writable(existing)
    if why is not None:
        raise UsageError(f"{what} {path} cannot be written: {existing} is not writable ({why})")


def probe_writable(folder: Path) -> str | None:
    """None if a file can be created in `folder`, else the OS's reason. It creates and removes
    a probe file: `os.access` says yes to root for folders no one can write (/proc, a read-only
    mount)."""
    try:
        fd, probe = temp_file(folder, prefix=".adarl-probe-")
    except OSError as exc:
        return exc.strerror or str(exc)
    os.close(fd)
    os.unlink(probe)
    return None
