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
import stat
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
    refuse_special(path)  # the rename would replace a device, a FIFO or a socket
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
    check_utf8_name(path, what)
    kind = existing_kind(path)
    if kind is not None and kind != "a folder":
        what_it_is = "a file" if kind == "a regular file" else kind
        raise UsageError(f"{what} {path} is {what_it_is}; give a folder")
    _check_creatable(path, path, what)


def check_writable_file(path: str | os.PathLike, what: str = "--out") -> None:
    """A one-line UsageError unless `path` can be written as a file (leaves nothing behind):
    absent, or a regular file (a device, FIFO or socket there is refused: the atomic write
    would replace it)."""
    path = Path(path)
    check_utf8_name(path, what)
    if existing_kind(path) == "a folder":
        raise UsageError(f"{what} {path} is a folder; give a file name")
    refuse_special(path, what)
    _check_creatable(path, path.parent, what)


def check_utf8_name(path: str | os.PathLike, what: str = "--out") -> None:
    """A one-line UsageError if `path` holds bytes that are not UTF-8 (Python keeps them as
    surrogates): adarl writes its output paths into UTF-8 files (config.yaml, a report's
    index.md), which cannot hold them."""
    raw = os.fsencode(path)
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        shown = raw.decode("utf-8", errors="backslashreplace")
        raise UsageError(
            f"{what} {shown} is not a UTF-8 name (byte 0x{raw[exc.start]:02x} at offset "
            f"{exc.start}); allowed: a name in UTF-8, which adarl's files can record"
        ) from None


def existing_kind(path: str | os.PathLike) -> str | None:
    """What `path` is (links followed): "a regular file", "a folder", "a FIFO", "a character
    device", …; None when nothing is there (or a link points nowhere)."""
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return None
    except OSError:  # e.g. a permission error on the way: the write will say it
        return None
    return "a regular file" if stat.S_ISREG(mode) else _file_kind(mode)


def refuse_special(path: str | os.PathLike, what: str | None = None) -> None:
    """A one-line UsageError if something other than a regular file or nothing is at `path`
    (links followed): writing there would replace a device, a FIFO, a socket or a folder with
    a file (docs/reliability.md)."""
    kind = existing_kind(path)
    if kind is None or kind == "a regular file":
        return
    name = f"{what} {path}" if what else str(path)
    raise UsageError(
        f"{name} is {kind}, not a regular file; adarl writes only regular files there "
        "(allowed: a new name or an existing regular file)"
    )


#: `open_in_place`'s modes: a log appended to, the lock, a log cut back
_IN_PLACE = {
    "a": os.O_WRONLY | os.O_CREAT | os.O_APPEND,
    "a+": os.O_RDWR | os.O_CREAT | os.O_APPEND,
    "r+b": os.O_RDWR,
}


def open_in_place(path: str | os.PathLike, mode: str):
    """`open(path, mode)` for a file written in place (`a`, `a+`: UTF-8 text; `r+b`), never
    through a symbolic link at `path` (O_NOFOLLOW: an OSError, ELOOP): a run folder is checked
    for links before it is written (`refuse_links`), and this holds if one appears since."""
    fd = os.open(path, _IN_PLACE[mode] | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666)
    if "b" in mode:
        return os.fdopen(fd, mode)
    return os.fdopen(fd, mode, newline="", encoding="utf-8")


def refuse_links(folder: str | os.PathLike, what: str = "run folder") -> None:
    """A one-line UsageError naming the first symbolic link below `folder` (at any depth; a
    linked folder is named, not entered; `folder` itself may be one, as a path a user gave): a
    write through it would cut, replace or append to a file outside the folder. Nothing if
    `folder` is not there."""
    root = Path(folder)
    for parent, folders, files in os.walk(root):  # never follows a link
        for name in sorted([*folders, *files]):
            path = Path(parent, name)
            if path.is_symlink():
                target = os.readlink(path)
                raise UsageError(
                    f"{what} {root} holds a symbolic link, {path} -> {target!r}; adarl never "
                    "writes through a link out of a run folder: replace the link by the file or "
                    "folder itself (or remove it)"
                )


def _check_creatable(path: Path, folder: Path, what: str) -> None:
    """`folder` (to hold `path`) exists and is writable, or its nearest existing ancestor is."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        kind = existing_kind(existing) or "not a folder"
        kind = "a file" if kind == "a regular file" else kind
        raise UsageError(f"{what} {path} cannot be written: {existing} is {kind}, not a folder")
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


# ----------------------------------------------------------------------------- reading back
# Every file adarl reads back (config.yaml, environment.json, meta.json, DONE, .lock, a sweep
# file, a sweep's manifest) goes through `read_text` / `read_json` / `read_yaml`: a regular file
# (not a device, FIFO or folder, whatever a link points to), at most `max_bytes`, strict UTF-8,
# and (JSON, YAML) nested at most `MAX_DEPTH` deep and at most `MAX_NODES` values once YAML's
# aliases are expanded. Anything else is one `UsageError` line naming the file (exit code 2);
# docs/reliability.md.
MAX_TEXT_BYTES = 16 << 20
MAX_YAML_BYTES = 1 << 20
MAX_DEPTH = 100
MAX_NODES = 1_000_000


class UnreadableFile(UsageError):
    """A file adarl reads back is not what it wrote: not a regular file, too large, not UTF-8,
    not valid JSON/YAML, nested too deep or too large once expanded (one line, exit code 2)."""


def read_bytes(
    path: str | os.PathLike, max_bytes: int = MAX_TEXT_BYTES, head: bool = False
) -> bytes:
    """The bytes of the regular file `path` (links followed), at most `max_bytes`; else a
    one-line `UnreadableFile`. With `head`, its first `max_bytes` bytes, whatever its size."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # O_NONBLOCK: a FIFO cannot hang us
    except OSError as exc:
        raise UnreadableFile(f"{path} is unreadable ({exc.strerror or exc})") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise UnreadableFile(
                f"{path} is not a regular file ({_file_kind(info.st_mode)}); "
                "adarl reads only regular files there"
            )
        if info.st_size > max_bytes and not head:
            raise UnreadableFile(
                f"{path} is {info.st_size} bytes; allowed: at most {max_bytes} (is it the "
                "file adarl wrote?)"
            )
        chunks, size = [], 0
        while size <= max_bytes:
            chunk = os.read(fd, min(1 << 20, max_bytes + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise UnreadableFile(f"{path} is unreadable ({exc.strerror or exc})") from None
    finally:
        os.close(fd)
    if head:
        return b"".join(chunks)[:max_bytes]
    if size > max_bytes:  # grew while read
        raise UnreadableFile(f"{path} is over {max_bytes} bytes; allowed: at most {max_bytes}")
    return b"".join(chunks)


def _file_kind(mode: int) -> str:
    for test, kind in (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return kind
    return "not a plain file"


def read_text(path: str | os.PathLike, max_bytes: int = MAX_TEXT_BYTES) -> str:
    """`read_bytes` decoded strictly as UTF-8; a one-line `UnreadableFile` if it is not."""
    data = read_bytes(path, max_bytes)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UnreadableFile(
            f"{path} is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}); "
            "adarl writes its files as UTF-8"
        ) from None


def read_json(path: str | os.PathLike, max_bytes: int = MAX_TEXT_BYTES):
    """The JSON value in `path` (see `read_text`), nested at most `MAX_DEPTH` deep."""
    text = read_text(path, max_bytes)
    try:
        value = json.loads(text)
    except RecursionError:
        raise UnreadableFile(
            f"{path} is nested too deep; allowed: at most {MAX_DEPTH} levels"
        ) from None
    except ValueError as exc:  # JSONDecodeError, an integer of too many digits
        raise UnreadableFile(f"{path} is unreadable (not valid JSON: {_one_line(exc)})") from None
    check_shape(value, path)
    return value


def read_yaml(path: str | os.PathLike, max_bytes: int = MAX_YAML_BYTES):
    """The YAML value in `path` (see `read_text`), read with yaml's safe loader, nested at most
    `MAX_DEPTH` deep and at most `MAX_NODES` values with its aliases expanded (an alias bomb is
    refused, not expanded), without cycles."""
    import yaml

    text = read_text(path, max_bytes)
    try:
        value = yaml.safe_load(text)
    except RecursionError:
        raise UnreadableFile(
            f"{path} is nested too deep; allowed: at most {MAX_DEPTH} levels"
        ) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or type(exc).__name__
        raise UnreadableFile(f"{path} is not valid YAML{where}: {_one_line(problem)}") from None
    except ValueError as exc:  # e.g. an integer of too many digits
        raise UnreadableFile(f"{path} is not valid YAML ({_one_line(exc)})") from None
    check_shape(value, path)
    return value


def _one_line(exc) -> str:
    return " ".join(str(exc).split())


def check_shape(value, path) -> None:
    """A one-line `UnreadableFile` if the lists and dicts of `value` nest deeper than
    `MAX_DEPTH`, refer to themselves, or hold more than `MAX_NODES` values when shared ones
    (YAML aliases) are counted each time they appear. Linear in the distinct values."""
    sizes: dict[int, tuple[int, int]] = {}  # id -> (expanded size, depth)
    active: set[int] = set()
    stack = [(value, False)]
    while stack:
        node, done = stack.pop()
        if not isinstance(node, dict | list):
            continue
        key = id(node)
        children = list(node.values()) if isinstance(node, dict) else node
        if isinstance(node, dict):
            children = children + list(node.keys())
        if done:
            active.discard(key)
            size, depth = 1, 1
            for child in children:
                s, d = sizes.get(id(child), (1, 0)) if isinstance(child, dict | list) else (1, 0)
                size += s
                depth = max(depth, d + 1)
            if depth > MAX_DEPTH:
                raise UnreadableFile(
                    f"{path} is nested too deep; allowed: at most {MAX_DEPTH} levels"
                )
            if size > MAX_NODES:
                raise UnreadableFile(
                    f"{path} holds over {MAX_NODES} values once its aliases are expanded "
                    "(an alias bomb?); adarl refuses it"
                )
            sizes[key] = (size, depth)
            continue
        if key in sizes:
            continue
        if key in active:
            raise UnreadableFile(f"{path} refers to itself (a recursive alias); adarl refuses it")
        if len(active) >= MAX_DEPTH:
            raise UnreadableFile(f"{path} is nested too deep; allowed: at most {MAX_DEPTH} levels")
        active.add(key)
        stack.append((node, True))
        stack.extend((child, False) for child in children)
