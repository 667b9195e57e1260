"""Damaged or hand-edited files that commands read back (issue 27, class 1; docs/reliability.md):
a policy file, a run log (truncations.csv, eval.csv, …), a spectrum file, a report's scores.csv,
environment.json, a sweep file, a sweep manifest. Each is one line
on stderr naming the file, exit code 2, never a traceback."""

import json
import os

import pytest
from cli_errors import one_line_exit_2
from synthetic_runs import write_run, write_sweep

from adarl.runs import checkpoints


@pytest.fixture
def mujoco_env(monkeypatch):
    # `adarl play` sets these for MuJoCo; monkeypatch restores them afterwards
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)


def _commands(run, tmp_path):
    return {
        "evaluate": ["evaluate", str(run), "--episodes", "1", "--out", str(tmp_path / "e.csv")],
        "export": ["export", str(run), "--out", str(tmp_path / "p.npz")],
        "play": ["play", str(run), "--video", str(tmp_path / "v.gif")],
    }


def _flip_bit(path):
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))


def _truncate(path):
    path.write_bytes(path.read_bytes()[:100])


@pytest.mark.parametrize("command", ["evaluate", "export", "play"])
@pytest.mark.parametrize("damage", [_flip_bit, _truncate])
def test_a_damaged_policy_file_is_named_in_one_line(command, damage, tmp_path, capsys, mujoco_env):
    run = write_run(tmp_path, "r", seeds=(0,))
    policy = checkpoints.latest_checkpoint(run) / "policy_seed_0.npz"
    damage(policy)
    one_line_exit_2(_commands(run, tmp_path)[command], capsys, "policy_seed_0.npz", "sha256")
    assert not (tmp_path / "p.npz").exists() and not (tmp_path / "v.gif").exists()


@pytest.mark.parametrize("command", ["export", "play"])
def test_a_truncated_policy_file_without_a_checksum_is_named_in_one_line(
    command, tmp_path, capsys, mujoco_env
):
    run = write_run(tmp_path, "r", seeds=(0,))
    newest = checkpoints.latest_checkpoint(run)
    meta = json.loads((newest / "meta.json").read_text())
    del meta["files_sha256"]  # as checkpoints were written before policy files were covered
    (newest / "meta.json").write_text(json.dumps(meta))
    _truncate(newest / "policy_seed_0.npz")
    one_line_exit_2(
        _commands(run, tmp_path)[command], capsys, f"policy file {newest / 'policy_seed_0.npz'}"
    )


def test_a_garbage_row_in_truncations_csv_is_named_with_its_line(tmp_path, capsys):
    run = write_run(tmp_path, "r", algo="adarl", seeds=(0,))
    with open(run / "truncations.csv", "a") as f:
        f.write("garbage,,,\n")
    lines = (run / "truncations.csv").read_text().splitlines()
    one_line_exit_2(["ranks", str(run)], capsys, f"truncations.csv line {len(lines)}")


@pytest.mark.parametrize("log", ["eval.csv", "train.csv", "truncations.csv"])
def test_a_garbage_row_in_a_run_log_is_named_with_its_line_by_the_report(log, tmp_path, capsys):
    run = write_run(tmp_path / "runs", "r", algo="adarl", seeds=(0,))
    with open(run / log, "a") as f:
        f.write("garbage,1,2\n")
    line = len((run / log).read_text().splitlines())
    needle = f"{log} line {line}: step is 'garbage', not a number"
    one_line_exit_2(
        ["report", str(tmp_path / "runs"), "--out", str(tmp_path / "report")], capsys, needle
    )
    assert [p.name for p in tmp_path.iterdir()] == ["runs"]  # no report, no temporary folder


def test_a_damaged_spectrum_file_is_named_by_the_report(tmp_path, capsys):
    run = write_run(tmp_path / "runs", "r", algo="adarl", seeds=(0,))
    spectrum = sorted((run / "spectra").glob("*.npz"))[0]
    _truncate(spectrum)
    out = tmp_path / "report"
    one_line_exit_2(["report", str(tmp_path / "runs"), "--out", str(out)], capsys, spectrum.name)
    assert [p.name for p in tmp_path.iterdir()] == ["runs"]


@pytest.mark.parametrize("text, needle", [("{bad", "is unreadable"), ("[1]", "not a JSON object")])
def test_a_damaged_evaluation_sidecar_is_named_not_skipped(text, needle, tmp_path, capsys):
    run = write_run(tmp_path / "runs", "r", seeds=(0,))
    write_sweep(run, "torso_length", [0.2, 0.4])
    sidecar = next((run / "evaluations").glob("*.json"))
    sidecar.write_text(text)
    out = tmp_path / "report"
    one_line_exit_2(
        ["report", str(tmp_path / "runs"), "--out", str(out)], capsys, sidecar.name, needle
    )
    assert not out.exists()


@pytest.mark.parametrize(
    "data, needle",
    [
        (
            b"task,method,run,seed,score\nhopper,sac,r,0,1\nhopper,sac,r,x,2\n",
            "line 3: seed is 'x'",
        ),
        (b'task,score\n"unterminated\n', "is not a report's scores.csv (ParserError"),
        (b"\xff\xfe", "is not a report's scores.csv (UnicodeDecodeError"),
        (b"", "is not a report's scores.csv (EmptyDataError"),
    ],
)
def test_a_damaged_scores_csv_is_named(data, needle, tmp_path, capsys):
    scores = tmp_path / "scores.csv"
    scores.write_bytes(data)
    out = tmp_path / "report"
    one_line_exit_2(["report", str(scores), "--out", str(out)], capsys, needle)
    assert not out.exists()


@pytest.mark.parametrize(
    "text, needle",
    [("{not json", "is unreadable"), ("[1, 2]", "not a JSON object"), ('{"cpu": 4}', "'cpu'")],
)
def test_a_malformed_environment_json_is_named(text, needle, tmp_path, capsys):
    run = write_run(tmp_path / "runs", "r", seeds=(0,))
    (run / "environment.json").write_text(text)
    out = tmp_path / "report"
    one_line_exit_2(["report", str(tmp_path / "runs"), "--out", str(out)], capsys, needle)
    assert [p.name for p in tmp_path.iterdir()] == ["runs"]  # no report, no temporary folder


def test_a_sweep_file_that_is_not_utf8_is_named(tmp_path, capsys):
    spec = tmp_path / "s.yaml"
    spec.write_bytes(b"name: caf\xe9\n")
    one_line_exit_2(
        ["sweep", str(spec), "--dry-run", "--out", str(tmp_path / "sw")],
        capsys,
        f"{spec} is not UTF-8",
    )


@pytest.mark.parametrize(
    "units, needle",
    [([], "field 'units' is a list"), ({"hopper/sac": "done"}, "unit 'hopper/sac'")],
)
def test_a_sweep_manifest_of_the_wrong_shape_is_named(units, needle, tmp_path, capsys):
    out = tmp_path / "sw"
    out.mkdir()
    (out / "manifest.json").write_text(json.dumps({"format_version": 1, "units": units}))
    one_line_exit_2(
        ["sweep", "smoke", "--dry-run", "--out", str(out)], capsys, "manifest.json", needle
    )
