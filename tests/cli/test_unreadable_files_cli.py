"""Files adarl reads back that are not text, hold extreme values or are not files at all (issue
38, classes 1 and 5; docs/reliability.md): every command that reads one says so in one line
naming it, exit code 2, never a traceback, a hang or a read of /dev/zero."""

import os

import pytest
from cli_errors import one_line_exit_2
from synthetic_runs import write_run

from adarl.cli.main import main


def _commands(run, tmp_path):
    return {
        "train --resume": ["train", "--resume", str(run)],
        "evaluate": ["evaluate", str(run), "--episodes", "1", "--out", str(tmp_path / "e.csv")],
        "report": ["report", str(run.parent), "--out", str(tmp_path / "report")],
        "ranks": ["ranks", str(run)],
        "export": ["export", str(run), "--out", str(tmp_path / "p.npz")],
    }


def _bomb() -> str:
    """A billion laughs in config.yaml's `command:` field (9**9 strings once expanded)."""
    lines = ['a0: &a0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    lines += [f"a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 9)]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("command", ["train --resume", "evaluate", "report", "ranks", "export"])
@pytest.mark.parametrize("damage", ["bom", "dev-zero", "alias-bomb"])
def test_an_unreadable_config_yaml_is_one_line_for_every_command(command, damage, tmp_path, capsys):
    run = write_run(tmp_path / "runs", "r", algo="adarl", seeds=(0,))
    config = run / "config.yaml"
    text = config.read_text()
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    if damage == "bom":
        config.write_bytes(b"\xff\xfe" + text.encode())
        needles = ["config.yaml is not UTF-8 text"]
    elif damage == "dev-zero":
        config.unlink()
        config.symlink_to("/dev/zero")
        needles = ["config.yaml is not a regular file"]
    else:
        config.write_text(_bomb() + text.replace("command:", "old_command:") + "command: *a8\n")
        needles = ["config.yaml holds over", "aliases"]
    one_line_exit_2(_commands(run, tmp_path)[command], capsys, *needles)
    after = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    assert after == before  # nothing written, nothing renamed


@pytest.mark.parametrize("text", [b"\xff\xfe10000\n", b"inf\n", b"1e400\n", b"-nan\n"])
def test_a_done_file_without_a_step_is_reported_not_a_traceback(text, tmp_path, capsys):
    run = write_run(tmp_path / "runs", "r", seeds=(0,))
    (run / "DONE").write_bytes(text)
    assert main(["report", str(tmp_path / "runs"), "--out", str(tmp_path / "report"),
                 "--bootstrap-reps", "10"]) == 0  # fmt: skip
    assert "Traceback" not in capsys.readouterr().err


def test_an_environment_json_nested_200000_deep_is_one_line(tmp_path, capsys):
    run = write_run(tmp_path / "runs", "r", seeds=(0,))
    (run / "environment.json").write_text('{"a": ' + "[" * 200_000 + "]" * 200_000 + "}")
    argv = ["report", str(tmp_path / "runs"), "--out", str(tmp_path / "report")]
    one_line_exit_2(argv, capsys, "environment.json is nested too deep")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]


def test_a_sweep_file_nested_5000_deep_is_one_line(tmp_path, capsys):
    spec = tmp_path / "s.yaml"
    spec.write_text("name: s\nunits: " + "[" * 5000 + "]" * 5000 + "\n")
    one_line_exit_2(
        ["sweep", str(spec), "--dry-run", "--out", str(tmp_path / "sw")],
        capsys,
        "s.yaml is nested too deep",
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.yaml"]


def test_a_report_onto_a_symlinked_folder_writes_where_it_points(tmp_path, capsys):
    write_run(tmp_path / "runs", "r", seeds=(0,))
    target = tmp_path / "reports" / "latest"
    target.mkdir(parents=True)
    link = tmp_path / "link"
    link.symlink_to(target)
    argv = ["report", str(tmp_path / "runs"), "--out", str(link), "--bootstrap-reps", "10"]
    for _ in range(2):  # the second replaces the first report
        assert main(argv) == 0, capsys.readouterr().err
        assert link.is_symlink() and os.readlink(link) == str(target)
        assert (target / "index.md").is_file()
        assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "reports", "runs"]
        assert sorted(p.name for p in target.parent.iterdir()) == ["latest"]
