"""What a resume or a fork does with a run folder that a hand or a disk changed (issue 38, classes
3 and 4; docs/reliability.md): no field of config.yaml is filled in with a default, a log that
lost its tail is said and kept, a checkpoint with a bad csv offset or a changed array falls back,
a fork checks everything before its first write, and every refusal names a command that works."""

from __future__ import annotations

import io
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_errors import one_line_exit_2

from adarl.algos import sac_config
from adarl.algos.sac_config import SAC_FAMILY
from adarl.cli.main import main
from adarl.errors import UsageError
from adarl.runs import checkpoints, logs
from adarl.runs.layout import LOCK_FILE
from adarl.runs.logs import read_csv
from adarl.train import trainers


@pytest.fixture(scope="module")
def sac_run(tmp_path_factory) -> Path:
    """A finished two-seed SAC smoke run with checkpoints at steps 500 and 1000."""
    values = {**SAC_FAMILY["sac"], **sac_config.PRESETS["smoke"], "algo": "sac", "task": "hopper"}
    config = sac_config.SACConfig(
        **{
            **values,
            "seeds": (0, 1),
            "total_steps": 1000,
            "checkpoint_every": 500,
            "eval_every": 250,
            "keep_checkpoints": 0,
        }  # fmt: skip
    )
    run_dir = tmp_path_factory.mktemp("sac") / "run"
    trainers.train(config, run_dir, progress=False)
    return run_dir


def rows(run_dir: Path, name: str) -> list[dict]:
    found = read_csv(run_dir / name)
    for row in found:
        row.pop("steps_per_s", None)  # wall clock
    return found


def unfinished(base: Path, dest: Path, drop_last_checkpoint: bool = False) -> Path:
    shutil.copytree(base, dest)
    (dest / "DONE").unlink()
    if drop_last_checkpoint:
        shutil.rmtree(checkpoints.checkpoint_dirs(dest)[-1])
    return dest


def files(run_dir: Path) -> dict:
    return {
        str(p.relative_to(run_dir)): p.read_bytes()
        for p in sorted(run_dir.rglob("*"))
        if p.is_file() and p.name != LOCK_FILE
    }


def resume(run_dir: Path) -> int:
    return main(["train", "--resume", str(run_dir), "--no-progress"])


# ----------------------------------------------------------------------------- class 3
@pytest.mark.parametrize("field", ["total_steps", "eval_every", "seeds", "dynamics", "lr_actor"])
@pytest.mark.parametrize("edit", ["deleted", "null", "empty"])
def test_a_config_field_missing_or_null_is_refused_on_resume(
    sac_run, tmp_path, capsys, monkeypatch, field, edit
):
    def went_on(*args, **kwargs):  # a resume that filled in a default (3M steps) fails at once
        raise AssertionError("the resume went on to restore the logs")

    monkeypatch.setattr(logs.CsvLog, "truncate", went_on)
    run_dir = unfinished(sac_run, tmp_path / "run", drop_last_checkpoint=True)
    doc = yaml.safe_load((run_dir / "config.yaml").read_text())
    recorded = doc.pop(field)
    text = yaml.safe_dump(doc, sort_keys=False)
    if edit == "null":
        text += f"{field}: null\n"
    elif edit == "empty":
        text += f"{field}:\n"
    (run_dir / "config.yaml").write_text(text)
    before = files(run_dir)
    err = one_line_exit_2(["train", "--resume", str(run_dir), "--no-progress"], capsys, field)
    if edit == "deleted":  # the value to put back, as the checkpoint recorded it
        assert f"has no field '{field}'" in err and f"--resume {run_dir}" in err, err
        value = {"total_steps": "1000", "eval_every": "250", "seeds": "[0, 1]",
                 "dynamics": '"paper"'}.get(field, repr(recorded))  # fmt: skip
        assert f"put back `{field}: {value}`" in err, err
    else:
        assert f"field '{field}' is None; allowed:" in err, err
    assert files(run_dir) == before  # nothing written, nothing renamed


@pytest.mark.parametrize("log", ["eval.csv", "episodes.csv"])
def test_a_log_shorter_than_the_checkpoint_says_is_said_and_kept(sac_run, tmp_path, capsys, log):
    run_dir = unfinished(sac_run, tmp_path / "run", drop_last_checkpoint=True)
    full = (sac_run / log).read_text().splitlines(keepends=True)
    header, body = full[0], full[1:]
    at_500 = [line for line in body if int(line.split(",")[0]) <= 500]
    assert len(at_500) >= 3
    kept = at_500[:-2]  # the last two rows before the checkpoint are lost, the next one half
    (run_dir / log).write_text(header + "".join(kept) + at_500[-2][:7])
    assert resume(run_dir) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{log} holds" in err and "last rows were lost" in err, err
    assert (run_dir / "DONE").exists()
    expected = [r for r in rows(sac_run, log)]
    lost = [r for r in expected if int(r["step"]) <= 500][-2:]
    assert rows(run_dir, log) == [r for r in expected if r not in lost]


@pytest.mark.parametrize("offset", [-1, -10_000, 1.5, True, "12"])
def test_a_bad_csv_offset_is_a_damaged_checkpoint(sac_run, tmp_path, capsys, offset):
    run_dir = unfinished(sac_run, tmp_path / "run")
    newest = checkpoints.checkpoint_dirs(run_dir)[-1]
    meta = yaml.safe_load((newest / "meta.json").read_text())  # JSON is YAML
    meta["csv_offsets"]["eval.csv"] = offset
    (newest / "meta.json").write_text(__import__("json").dumps(meta))
    assert resume(run_dir) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "csv_offsets['eval.csv']" in err and "older" in err, err
    for name in ("episodes.csv", "train.csv", "eval.csv"):  # resumed from step 500, exactly
        assert rows(run_dir, name) == rows(sac_run, name), name


def test_a_valid_npz_with_one_value_changed_is_a_damaged_checkpoint(sac_run, tmp_path, capsys):
    run_dir = unfinished(sac_run, tmp_path / "run")
    newest = checkpoints.checkpoint_dirs(run_dir)[-1]
    with np.load(newest / "arrays.npz") as z:
        arrays = {k: z[k] for k in z.files}
    key = next(k for k, v in arrays.items() if v.dtype.kind == "f" and v.size > 1)
    arrays[key] = arrays[key].copy()
    arrays[key].flat[0] += 1.0  # a zip that reads back fine: only the checksum sees it
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    (newest / "arrays.npz").write_bytes(buffer.getvalue())
    assert resume(run_dir) == 0
    err = capsys.readouterr().err
    assert "arrays.npz does not match its sha256" in err and err.count("\n") == 1, err
    assert (run_dir / "checkpoints" / f"damaged_{newest.name}").is_dir()
    for name in ("episodes.csv", "train.csv", "eval.csv"):
        assert rows(run_dir, name) == rows(sac_run, name), name


# ----------------------------------------------------------------------------- class 4
def _fork(parent: Path, out: Path, *flags: str) -> list[str]:
    return ["train", "--fork", str(parent), "--at", "500", "--out", str(out), "--no-progress",
            *flags]  # fmt: skip


def test_a_fork_whose_parent_lost_a_log_writes_nothing_and_names_what_works(
    sac_run, tmp_path, capsys
):
    parent = shutil.copytree(sac_run, tmp_path / "parent")
    eval_csv = (parent / "eval.csv").read_bytes()
    (parent / "eval.csv").unlink()
    out = tmp_path / "child"
    one_line_exit_2(_fork(parent, out), capsys, "eval.csv is shorter", "restore")
    assert not out.exists() or not any(out.iterdir())
    (parent / "eval.csv").write_bytes(eval_csv[: len(eval_csv) // 3])  # rows up to ~step 300
    err = one_line_exit_2(_fork(parent, out), capsys, "eval.csv is shorter")
    assert "fork at a step whose rows are all there: none" not in err
    (parent / "eval.csv").write_bytes(eval_csv)
    assert main(_fork(parent, out)) == 0, capsys.readouterr().err  # the retry into the same --out
    assert rows(out, "eval.csv") == rows(sac_run, "eval.csv")  # a fork that changes nothing


def test_a_fork_with_bad_eval_dynamics_writes_nothing(sac_run, tmp_path, capsys):
    out = tmp_path / "child"
    one_line_exit_2(_fork(sac_run, out, "--eval-dynamics", "fixed:bogus=1"), capsys, "'bogus'")
    assert not out.exists() or not any(out.iterdir())
    assert main(_fork(sac_run, out, "--eval-dynamics", "fixed:torso_length=0.3")) == 0


def test_an_interrupted_fork_names_a_command_that_works(sac_run, tmp_path, capsys, monkeypatch):
    out = tmp_path / "child"

    def killed(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(checkpoints, "save_checkpoint", killed)
    assert main(_fork(sac_run, out)) == 130
    monkeypatch.undo()
    capsys.readouterr()
    assert (out / "config.yaml").exists() and not checkpoints.checkpoint_dirs(out)
    for argv in (["train", "--resume", str(out), "--no-progress"], _fork(sac_run, out)):
        err = one_line_exit_2(argv, capsys, "interrupted while being made", f"rm -r {out} && ")
        remedy = err.split(" && ", 1)[1].strip()
        assert shlex.split(remedy)[:2] == ["adarl", "train"] and "--fork" in remedy, remedy
    shutil.rmtree(out)  # the advice, followed
    assert main(shlex.split(remedy)[1:]) == 0
    assert rows(out, "eval.csv") == rows(sac_run, "eval.csv")


def test_a_non_empty_folder_without_a_run_is_not_offered_to_resume(sac_run, tmp_path, capsys):
    out = tmp_path / "child"
    out.mkdir()
    (out / "episodes.csv").write_text("step\n")  # a fork killed before its config.yaml
    err = one_line_exit_2(_fork(sac_run, out), capsys, "holds no run", f"rm -r {out}")
    assert "--resume" not in err


def test_an_environment_json_nested_200000_deep_is_one_warning_on_resume(sac_run, tmp_path, capsys):
    """The record of the resumes is not the run: the resume says in one line that it cannot add
    to it (no RecursionError), leaves the file as it is and finishes the run exactly."""
    run_dir = unfinished(sac_run, tmp_path / "run", drop_last_checkpoint=True)
    deep = "[" * 200_000 + "]" * 200_000
    (run_dir / "environment.json").write_text(deep)
    assert resume(run_dir) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "environment.json is nested too deep" in err, err
    assert (run_dir / "environment.json").read_text() == deep
    for name in ("episodes.csv", "train.csv", "eval.csv"):
        assert rows(run_dir, name) == rows(sac_run, name), name


def test_a_log_header_that_is_not_utf8_is_one_line_on_resume(sac_run, tmp_path, capsys):
    run_dir = unfinished(sac_run, tmp_path / "run", drop_last_checkpoint=True)
    data = (run_dir / "train.csv").read_bytes()
    (run_dir / "train.csv").write_bytes(b"\xff\xfe" + data[2:])  # same size: offsets still fit
    one_line_exit_2(
        ["train", "--resume", str(run_dir), "--no-progress"],
        capsys,
        "train.csv has a header that is not UTF-8 text",
    )


def test_a_run_without_checkpoint_written_before_a_field_existed_resumes(sac_run, tmp_path):
    """`backend` came after the campaign's runs (8bee27f): their config.yaml has no such line, and
    a unit killed before its first checkpoint must still resume; any other missing field is
    still refused."""
    from adarl.runs.folder import check_complete_config

    run_dir = unfinished(sac_run, tmp_path / "run")
    for found in checkpoints.checkpoint_dirs(run_dir):
        shutil.rmtree(found)
    doc = yaml.safe_load((run_dir / "config.yaml").read_text())
    assert doc.pop("backend") == "host"
    (run_dir / "config.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    check_complete_config(run_dir)  # no error
    doc.pop("total_steps")
    (run_dir / "config.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(UsageError, match="has no field 'total_steps'"):
        check_complete_config(run_dir)


def test_a_run_created_before_a_field_existed_resumes_from_a_checkpoint_that_records_it(
    sac_run, tmp_path
):
    """The campaign's Table 1 units, created by 8bee27f (no `backend` line) and resumed on newer
    code, wrote checkpoints whose config records `backend: host`; their next resume must accept
    the missing line at that value, and still refuse it when the checkpoint recorded another."""
    from adarl.runs.folder import check_complete_config

    run_dir = unfinished(sac_run, tmp_path / "run")
    doc = yaml.safe_load((run_dir / "config.yaml").read_text())
    assert doc.pop("backend") == "host"
    (run_dir / "config.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    _, meta = checkpoints.load_checkpoint(checkpoints.checkpoint_dirs(run_dir)[-1])
    assert meta["config"]["backend"] == "host"
    check_complete_config(run_dir, meta["config"])  # no error
    assert main(["train", "--resume", str(run_dir), "--no-progress"]) == 0
    with pytest.raises(UsageError, match="has no field 'backend'.*`backend: \"device\"`"):
        check_complete_config(run_dir, {**meta["config"], "backend": "device"})
