"""Issue 61 §2: a write into a run folder never goes through a symbolic link out of it.

`adarl train --resume` of a run whose `train.csv` was a link to a file outside cut that file
back to the checkpoint's offset and appended to it; a linked `evaluations/` made `adarl
evaluate` write outside the run. Every command that writes into a run folder (train, its
resume and its end-of-training report, a fork, evaluate, a suite, a report into the run)
refuses a run folder holding a link, in one line naming it, exit 2, before anything is
written: nothing outside the run folder changes, nor inside it."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from cli_errors import one_line_exit_2
from synthetic_runs import write_run

from adarl.algos import sac_config
from adarl.algos.sac_config import SAC_FAMILY
from adarl.runs import checkpoints
from adarl.train import trainers


@pytest.fixture(scope="module")
def sac_run(tmp_path_factory) -> Path:
    """A finished one-seed SAC smoke run with checkpoints at steps 200 and 400."""
    values = {**SAC_FAMILY["sac"], **sac_config.PRESETS["smoke"], "algo": "sac", "task": "hopper"}
    fields = {"seeds": (0,), "total_steps": 400, "checkpoint_every": 200, "eval_every": 200}
    config = sac_config.SACConfig(**{**values, **fields, "keep_checkpoints": 0})
    run_dir = tmp_path_factory.mktemp("sac") / "run"
    trainers.train(config, run_dir, progress=False)
    return run_dir


def unfinished(base: Path, dest: Path) -> Path:
    """A copy of `base` killed after its first checkpoint: it resumes from step 200."""
    shutil.copytree(base, dest)
    (dest / "DONE").unlink()
    shutil.rmtree(checkpoints.checkpoint_dirs(dest)[-1])
    return dest


def contents(folder: Path) -> dict[str, bytes | None]:
    """Every path below `folder` (links not followed) and the bytes of its regular files."""
    return {
        str(p.relative_to(folder)): p.read_bytes() if p.is_file() and not p.is_symlink() else None
        for p in sorted(folder.rglob("*"))
    }


def link_out(run: Path, name: str, outside: Path) -> Path:
    """Move `run/name` to `outside/name` (a log gains a row past the checkpoint, which a cut
    would lose) and leave a link to it in its place; the link's target."""
    target = outside / name
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.move(run / name, target)
    if name.endswith(".csv"):
        with open(target, "a") as f:
            f.write(f"{target.read_text().splitlines()[-1]}\n")  # a line the cut would remove
    (run / name).symlink_to(target, target_is_directory=target.is_dir())
    return target


LINKED = ["train.csv", "episodes.csv", "eval.csv", ".lock", "environment.json", "checkpoints"]


@pytest.mark.parametrize("name", LINKED)
def test_a_resume_never_writes_through_a_link(name, sac_run, tmp_path, capsys):
    run = unfinished(sac_run, tmp_path / "run")
    outside = tmp_path / "outside"
    link_out(run, name, outside)
    before, inside = contents(outside), contents(run)
    one_line_exit_2(
        ["train", "--resume", str(run), "--no-progress"], capsys, "symbolic link", f"{run / name}"
    )
    assert contents(outside) == before
    assert contents(run) == inside


def test_a_finished_run_with_a_link_writes_no_report_through_it(sac_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(sac_run, run)
    outside = tmp_path / "outside"
    outside.mkdir()
    (run / "report").symlink_to(outside, target_is_directory=True)
    argv = ["train", "--resume", str(run), "--report", "--no-progress"]
    one_line_exit_2(argv, capsys, "symbolic link", str(run / "report"))
    assert list(outside.iterdir()) == []


def test_a_new_run_never_takes_a_linked_lock(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / ".lock").symlink_to(tmp_path / "elsewhere")  # a lock-only folder is a new run's
    one_line_exit_2(
        ["train", "--algo", "sac", "--preset", "smoke", "--total-steps", "200", "--out", str(out)],
        capsys,
        "symbolic link",
    )
    assert not (tmp_path / "elsewhere").exists()


@pytest.mark.parametrize("linked", ["evaluations", "suites", "eval.csv"])
def test_evaluate_never_writes_through_a_link(linked, tmp_path, capsys):
    run = write_run(tmp_path, "r", algo="sac", seeds=(0,))
    outside = tmp_path / "outside"
    outside.mkdir()
    if (run / linked).exists():
        link_out(run, linked, outside)
    else:
        (outside / linked).mkdir()
        (run / linked).symlink_to(outside / linked, target_is_directory=True)
    before, inside = contents(outside), contents(run)
    quick = ["--episodes", "1", "--max-episode-steps", "3", "--workers", "1"]
    for argv in (
        ["evaluate", str(run), *quick],
        ["evaluate", str(run), "--suite", "m2td3-1d", "--points", "2", *quick],
        ["evaluate", str(run), "--out", str(run / "evaluations" / "mine.csv"), *quick],
    ):
        one_line_exit_2(argv, capsys, "symbolic link", str(run / linked))
    assert contents(outside) == before
    assert contents(run) == inside
    # an evaluation written outside every run folder reads the run through its links
    assert main_ok(["evaluate", str(run), *quick, "--out", str(tmp_path / "e.csv")], capsys)


def test_a_report_into_a_run_folder_never_writes_through_a_link(tmp_path, capsys):
    run = write_run(tmp_path, "r", algo="sac", seeds=(0,))
    outside = tmp_path / "outside"
    outside.mkdir()
    (run / "report").symlink_to(outside, target_is_directory=True)
    one_line_exit_2(["report", str(run), "--out", str(run / "report")], capsys, "symbolic link")
    assert list(outside.iterdir()) == []


def main_ok(argv, capsys) -> bool:
    from adarl.cli.main import main

    code = main(argv)
    err = capsys.readouterr().err
    assert code == 0, err
    return True


def test_the_check_walks_every_level(tmp_path):
    from adarl.errors import UsageError
    from adarl.files import refuse_links

    deep = tmp_path / "run" / "checkpoints" / "step_000000000200"
    deep.mkdir(parents=True)
    refuse_links(tmp_path / "run")  # none: nothing said
    os.symlink(tmp_path / "x", deep / "arrays.npz")  # a dangling link counts too
    with pytest.raises(UsageError, match="arrays.npz"):
        refuse_links(tmp_path / "run")
