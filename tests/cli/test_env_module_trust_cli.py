"""Issue 61 §1: reading a run folder or a sweep file never runs code from it.

A downloaded run folder `dlrun` whose config.yaml names `env_module: dlrun.payload`: `adarl
evaluate dlrun` (and `adarl.evaluate("dlrun")` from Python in the folder holding it, where the
current folder is on the import path) imported `dlrun/payload.py` as a namespace package;
`adarl report` did too for an AdaRL run, `adarl sweep FILE --dry-run` for a sweep file's
env_module. A module is imported only when the user names it (`--env-module M`, `env_module=`,
their own sweep file when it runs), as `python -m` finds it; a run or file that needs one the
user did not name is refused in one line, exit 2, saying which and how to allow it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import synthetic_runs
from cli_errors import one_line_exit_2
from synthetic_runs import write_run

import adarl
from adarl.cli.main import main
from adarl.envs import tasks

ADARL_ROOT = Path(adarl.__file__).resolve().parents[1]  # the adarl these tests import
#: what the downloaded run's module does when imported: leaves a mark
PAYLOAD = 'from pathlib import Path\nPath(__file__).with_name("RAN").write_text("ran")\n'
ASK = "names env-module 'dlrun.payload', which you did not name"
ALLOW = "add --env-module dlrun.payload"
TASK = "InvertedPendulum-v5"


@pytest.fixture(autouse=True)
def in_the_download_folder(tmp_path, monkeypatch):
    """The current folder holds the run, and is on the import path (as in `python`, `python -c`
    or `python -m`); this process has named no module and imported no `dlrun`."""
    monkeypatch.setattr(tasks, "_NAMED", set(), raising=False)  # raising: the old code has none
    monkeypatch.setattr(sys, "path", [str(tmp_path), *sys.path])
    monkeypatch.chdir(tmp_path)
    tasks._gym_task.cache_clear()
    yield
    for name in [m for m in sys.modules if m == "dlrun" or m.startswith("dlrun.")]:
        del sys.modules[name]
    tasks._gym_task.cache_clear()


def downloaded_run(root: Path, seeds=(0,)) -> Path:
    """An AdaRL run of InvertedPendulum-v5 whose config names the module in its own folder."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(synthetic_runs.DIMS, TASK, (4, 1))
        patch.setitem(synthetic_runs.PARAMS, TASK, {"mass_scale": 1.0})
        run = write_run(
            root, "dlrun", algo="adarl", task=TASK, seeds=seeds,
            extra_config={"env_module": "dlrun.payload"},
        )  # fmt: skip
    (run / "payload.py").write_text(PAYLOAD)
    return run


COMMANDS = {
    "evaluate": ["evaluate", "dlrun", "--episodes", "1"],
    "suite": ["evaluate", "dlrun", "--suite", "rrls-1d"],
    "play": ["play", "dlrun", "--video", "v.gif"],
    "resume": ["train", "--resume", "dlrun"],
    "fork": ["train", "--fork", "dlrun", "--at", "10000", "--total-steps", "20000", "--out", "f"],
}


@pytest.mark.parametrize("command", COMMANDS)
def test_a_run_folder_that_names_a_module_is_refused(command, tmp_path, capsys):
    run = downloaded_run(tmp_path)
    if command == "resume":
        (run / "DONE").unlink()  # a run killed mid-way
    one_line_exit_2(COMMANDS[command], capsys, f"{Path('dlrun') / 'config.yaml'} {ASK}", ALLOW)
    assert not (run / "RAN").exists()
    assert "dlrun" not in sys.modules


def test_a_report_reads_the_run_and_imports_nothing(tmp_path, capsys):
    run = downloaded_run(tmp_path)
    assert main(["report", "dlrun", "--out", "rep", "--bootstrap-reps", "200"]) == 0
    assert not (run / "RAN").exists() and "dlrun" not in sys.modules
    from adarl.report.ranks import intrinsic_rank
    from adarl.results.runs import load_run

    assert intrinsic_rank(load_run(run)) == 3  # 2·d_a+1 from its policy file, not its module


def test_from_python_in_the_folder_holding_the_run(tmp_path):
    run = downloaded_run(tmp_path)
    with pytest.raises(adarl.UsageError, match=ASK):
        adarl.evaluate("dlrun", episodes=1)
    with pytest.raises(adarl.UsageError, match=ASK):
        adarl.train(resume="dlrun")
    assert not (run / "RAN").exists() and "dlrun" not in sys.modules


SWEEP = """tasks: [InvertedPendulum-v5]
algos: [sac]
seeds: 0
budget: 1000
preset: smoke
overrides: {env_module: dlrun.payload}
"""


def test_a_dry_run_imports_nothing_you_did_not_name(tmp_path, capsys):
    run = downloaded_run(tmp_path)
    Path("s.yaml").write_text(SWEEP)
    one_line_exit_2(["sweep", "s.yaml", "--dry-run", "--out", "sw"], capsys, f"s.yaml {ASK}", ALLOW)
    assert not (run / "RAN").exists() and not Path("sw").exists()
    # named on the command line, it is imported: the dry run goes on
    assert (
        main(["sweep", "s.yaml", "--dry-run", "--out", "sw", "--env-module", "dlrun.payload"]) == 0
    )
    assert (run / "RAN").exists()


def test_a_bad_module_name_is_one_line(capsys):
    one_line_exit_2(
        ["evaluate", "x", "--env-module", "../evil"], capsys, "bad env-module '../evil'"
    )


def test_a_named_module_is_imported_as_python_m_finds_it(tmp_path):
    """`adarl` runs as a script, whose folder (not the current one) Python puts on the path: a
    module named in the current folder is found there, by the evaluation's spawned workers too."""
    run = downloaded_run(tmp_path, seeds=(0, 1))
    script = tmp_path / "bin" / "adarl"
    script.parent.mkdir()
    script.write_text(  # as pip writes the `adarl` script
        "import sys\nfrom adarl.cli.main import main\nif __name__ == '__main__':\n    sys.exit(main())\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ADARL_ROOT)}
    argv = ["evaluate", "dlrun", "--episodes", "1", "--max-episode-steps", "3", "--workers", "2"]
    done = subprocess.run(
        [sys.executable, str(script), *argv, "--env-module", "dlrun.payload"],
        env=env, cwd=tmp_path, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (run / "RAN").exists()
    assert (run / "evaluations" / "nominal.csv").exists()


@pytest.mark.parametrize("argv", [["train", "--algo", "sac", "--task", "quits/Bot-v0"], ["tasks", "quits/Bot-v0"]])  # fmt: skip
def test_a_module_that_exits_as_it_is_imported_is_one_line_not_a_silent_exit_0(argv, tmp_path, capsys):  # fmt: skip
    # issue 61 §7: an --env-module whose import called sys.exit(0) made `adarl train` (and
    # `sweep --dry-run`) exit 0 with no output and no work
    (tmp_path / "quits.py").write_text("import sys\nsys.exit(0)\n")
    out = tmp_path / "run"
    extra = ["--out", str(out), "--total-steps", "500"] if argv[0] == "train" else []
    one_line_exit_2([*argv, "--env-module", "quits", *extra], capsys, "env-module 'quits' called sys.exit(0)")  # fmt: skip
    assert not out.exists()
