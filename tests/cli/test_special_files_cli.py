"""Issue 55: an output path that exists and is not a regular file (a FIFO, a device, a link to
one) is refused in one line, exit 2, and left as it was; made in a temp folder, never the real
devices."""

import os

import pytest
from cli_errors import one_line_exit_2
from synthetic_runs import write_run
from test_files import special_files


@pytest.mark.parametrize("flag", ["export", "play", "evaluate"])
def test_a_special_output_file_is_refused_and_left_as_it_was(flag, tmp_path, capsys):
    run = write_run(tmp_path, "r", seeds=(0,))
    for kind, path in special_files(tmp_path).items():
        mode = os.lstat(path).st_mode
        argv = {
            "export": ["export", str(run), "--out", str(path)],
            "play": ["play", str(run), "--video", str(path) + ".gif"],
            "evaluate": ["evaluate", str(run), "--out", str(path)],
        }[flag]
        if flag == "play":  # the video's name must end in .gif or .mp4
            os.rename(path, str(path) + ".gif")
            path = tmp_path / (path.name + ".gif")
        one_line_exit_2(argv, capsys, f"is {kind}, not a regular file")
        assert os.lstat(path).st_mode == mode


def test_a_special_output_folder_is_refused(tmp_path, capsys):
    run = write_run(tmp_path, "r", seeds=(0,))
    for kind, path in special_files(tmp_path).items():
        one_line_exit_2(
            ["report", str(run), "--out", str(path)], capsys, f"is {kind}; give a folder"
        )
        one_line_exit_2(
            ["train", "--preset", "smoke", "--out", str(path)], capsys, f"is {kind}; give a folder"
        )


def test_a_special_json_sidecar_is_refused_before_evaluating(tmp_path, capsys):
    """`--out X.csv` writes X.json last: a FIFO there is refused before any episode runs, so no
    CSV is written without its sidecar."""
    run = write_run(tmp_path, "r", seeds=(0,))
    out = tmp_path / "table.csv"
    os.mkfifo(tmp_path / "table.json")
    argv = ["evaluate", str(run), "--out", str(out), "--episodes", "1", "--max-episode-steps", "5"]
    one_line_exit_2(argv, capsys, "--out's JSON sidecar")
    assert not out.exists() and os.path.exists(tmp_path / "table.json")
