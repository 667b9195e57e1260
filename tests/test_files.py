"""Output paths are checked before anything is written."""

import os

import pytest

from adarl.errors import UsageError
from adarl.files import check_writable_dir, check_writable_file


def test_output_folders_are_checked_before_anything_is_written(tmp_path, monkeypatch):
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(UsageError, match="is a file"):
        check_writable_dir(afile)
    with pytest.raises(UsageError, match="is a file, not a folder"):
        check_writable_dir(afile / "run")
    with pytest.raises(UsageError, match="is a file, not a folder"):
        check_writable_file(afile / "x.csv")
    check_writable_dir(tmp_path / "new" / "run")  # creatable
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]  # the probe is gone
    monkeypatch.setattr(os, "access", lambda *a, **k: True)  # what root is told about /proc
    with pytest.raises(UsageError, match="/proc is not writable"):
        check_writable_dir("/proc/new/run")
    with pytest.raises(UsageError, match="/proc is not writable"):
        check_writable_file("/proc/p.npz")


def test_a_read_only_folder_is_found_by_its_probe(tmp_path, monkeypatch):
    import errno

    from adarl import files

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))

    monkeypatch.setattr(files, "temp_file", read_only)
    with pytest.raises(UsageError, match=r"is not writable \(Read-only file system\)"):
        check_writable_dir(tmp_path / "run")


@pytest.mark.parametrize(
    "umask, file_mode, dir_mode", [(0o077, 0o600, 0o700), (0o022, 0o644, 0o755)]
)
def test_every_file_and_folder_follows_the_umask(umask, file_mode, dir_mode, tmp_path, capsys):
    from synthetic_runs import write_run

    from adarl.cli.main import main

    old = os.umask(umask)
    try:  # a run folder (config, CSVs, checkpoints built in a temp folder), an export, a report
        run = write_run(tmp_path / "runs", "r", seeds=(0,))
        assert main(["export", str(run), "--out", str(tmp_path / "out" / "p.npz")]) == 0
        assert main(["report", str(tmp_path / "runs"), "--out", str(tmp_path / "report"),
                     "--bootstrap-reps", "10"]) == 0  # fmt: skip
    finally:
        os.umask(old)
    capsys.readouterr()
    made = list(tmp_path.rglob("*"))
    assert {"arrays.npz", "policy_seed_0.npz", "config.yaml", "p.npz", "index.md"} <= {
        p.name for p in made
    }
    for path in made:
        expected = dir_mode if path.is_dir() else file_mode
        assert path.stat().st_mode & 0o777 == expected, path


# ----------------------------------------------------------------------------- reading back
# issue 38, class 1: every file adarl reads back goes through one reader (adarl.files)
def test_the_reader_refuses_what_is_not_a_regular_utf8_file(tmp_path):
    from adarl.files import UnreadableFile, read_json, read_text, read_yaml

    (tmp_path / "ok.yaml").write_text("a: [1, 2]\nb: café\n", encoding="utf-8")
    assert read_yaml(tmp_path / "ok.yaml") == {"a": [1, 2], "b": "café"}
    (tmp_path / "bom.yaml").write_bytes(b"\xff\xfea: 1\n")
    with pytest.raises(UnreadableFile, match=r"bom.yaml is not UTF-8 text \(byte 0xff at offset 0"):
        read_yaml(tmp_path / "bom.yaml")
    (tmp_path / "zero.yaml").symlink_to("/dev/zero")  # read whole, it would fill the memory
    with pytest.raises(UnreadableFile, match="zero.yaml is not a regular file .a character device"):
        read_yaml(tmp_path / "zero.yaml")
    os.mkfifo(tmp_path / "fifo.json")  # opening it for reading must not wait for a writer
    with pytest.raises(UnreadableFile, match="fifo.json is not a regular file .a FIFO"):
        read_json(tmp_path / "fifo.json")
    (tmp_path / "big.txt").write_bytes(b"x" * 101)
    with pytest.raises(UnreadableFile, match="big.txt is 101 bytes; allowed: at most 100"):
        read_text(tmp_path / "big.txt", max_bytes=100)
    assert read_text(tmp_path / "big.txt", max_bytes=101) == "x" * 101
    with pytest.raises(UnreadableFile, match="missing.json is unreadable .No such file"):
        read_json(tmp_path / "missing.json")


@pytest.mark.parametrize("depth, ok", [(100, True), (101, False), (200_000, False)])
def test_the_reader_bounds_the_depth_of_json(depth, ok, tmp_path):
    from adarl.files import UnreadableFile, read_json

    (tmp_path / "deep.json").write_text("[" * depth + "]" * depth)
    if ok:
        value = read_json(tmp_path / "deep.json")
        for _ in range(depth - 1):
            (value,) = value
        assert value == []
    else:
        with pytest.raises(UnreadableFile, match="nested too deep; allowed: at most 100 levels"):
            read_json(tmp_path / "deep.json")


def test_the_reader_bounds_yaml_depth_aliases_and_cycles(tmp_path):
    from adarl.files import UnreadableFile, read_yaml

    (tmp_path / "deep.yaml").write_text("a: " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(UnreadableFile, match="nested too deep"):
        read_yaml(tmp_path / "deep.yaml")
    # a billion laughs: 9 levels of 9 aliases, 9**9 strings once expanded
    lines = ['a0: &a0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    lines += [f"a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 9)]
    (tmp_path / "bomb.yaml").write_text("\n".join(lines) + "\ncommand: *a8\n")
    with pytest.raises(UnreadableFile, match="over 1000000 values once its aliases are expanded"):
        read_yaml(tmp_path / "bomb.yaml")
    (tmp_path / "cycle.yaml").write_text("a: &x [1, *x]\n")
    with pytest.raises(UnreadableFile, match="refers to itself"):
        read_yaml(tmp_path / "cycle.yaml")
    # aliases a user writes in a sweep file are fine while they expand to a sane size
    (tmp_path / "shared.yaml").write_text("base: &b {lr: 1, seeds: [0, 1]}\nx: *b\ny: *b\n")
    assert read_yaml(tmp_path / "shared.yaml")["y"] == {"lr": 1, "seeds": [0, 1]}


# ----------------------------------------------------------------------------- special files
def special_files(folder):
    """A FIFO and, where this process may make one (root), a character device like /dev/full
    (1, 7), made in `folder`: never the real devices."""
    import stat

    made = {}
    fifo = folder / "fifo"
    os.mkfifo(fifo)
    made["a FIFO"] = fifo
    device = folder / "full"
    try:
        os.mknod(device, stat.S_IFCHR | 0o666, os.makedev(1, 7))
        made["a character device"] = device
    except (PermissionError, OSError):
        pass
    return made


def test_a_special_file_is_refused_and_left_as_it_was(tmp_path):
    """Issue 55: `export --out /dev/full` replaced the device with a zip. Every writer refuses
    what exists and is not a regular file (links followed), naming what it is."""
    import stat

    from adarl.files import atomic_write_bytes

    made = special_files(tmp_path)
    link = tmp_path / "link"
    link.symlink_to(made["a FIFO"])
    for kind, path in [*made.items(), ("a FIFO", link)]:
        mode = os.lstat(path).st_mode
        with pytest.raises(UsageError, match=f"is {kind}, not a regular file"):
            check_writable_file(path)
        with pytest.raises(UsageError, match=f"is {kind}; give a folder"):
            check_writable_dir(path)
        with pytest.raises(UsageError, match=f"is {kind}, not a regular file"):
            atomic_write_bytes(path, b"data")
        assert os.lstat(path).st_mode == mode  # still what it was
        with pytest.raises(UsageError, match=f"is {kind}, not a folder"):
            check_writable_file(path / "x.npz")
    assert stat.S_ISFIFO(os.stat(link).st_mode)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp file left
    regular = tmp_path / "regular"
    regular.write_bytes(b"old")
    check_writable_file(regular)  # a regular file may be replaced
    atomic_write_bytes(regular, b"new")
    assert regular.read_bytes() == b"new"


def test_a_failed_replace_leaves_no_temp_file(tmp_path, monkeypatch):
    """The atomic write removes its temporary file when the rename fails (disk error, EXDEV)."""
    import errno

    from adarl import files
    from adarl.errors import RunFailed

    target = tmp_path / "out.bin"
    target.write_bytes(b"old")

    def fail(src, dst):
        raise OSError(errno.EIO, os.strerror(errno.EIO), str(dst))

    monkeypatch.setattr(files.os, "replace", fail)
    with pytest.raises(RunFailed, match="Input/output error"):
        files.atomic_write_bytes(target, b"new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bin"]
    assert target.read_bytes() == b"old"


def test_remove_orphans_keeps_live_and_other_hosts_folders(tmp_path, monkeypatch):
    """Only this host's folders of processes that no longer run are removed."""
    import socket

    from adarl import files

    host = socket.gethostname()
    dead = 2**22 + 12345  # above any pid_max default: no such process
    monkeypatch.setattr(files, "_alive", lambda pid: pid != dead)
    names = {
        "mine-dead": f".R.tmp-{dead}-{host}-abc",
        "mine-live": f".R.tmp-{os.getpid()}-{host}-abc",
        "other-host-dead": f".R.tmp-{dead}-{host}x-abc",
        "other-host-prefix": f".R.tmp-{dead}-x{host}-abc",
        "not-a-pid": f".R.tmp-12a-{host}-abc",
    }
    for name in names.values():
        (tmp_path / name).mkdir()
    files.remove_orphans(tmp_path, ".R.tmp-")
    left = {p.name for p in tmp_path.iterdir()}
    assert left == set(names.values()) - {names["mine-dead"]}
