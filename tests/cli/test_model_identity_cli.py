"""Issue 61 §3: a run trained on one model never resumes or evaluates on another. A run of
HalfCheetah-v5 with a relative `xml_file` (`./cheetah.xml`) records its model (the XML's resolved path and
SHA-256) in environment.json; from another folder holding another `cheetah.xml`, resume and
evaluate refuse in one line, exit 2, writing nothing; from its own folder they go on."""

import json
import os
import shutil
from pathlib import Path

import gymnasium
from cli_errors import one_line_exit_2

from adarl.cli.main import main

XML = Path(gymnasium.__file__).parent / "envs/mujoco/assets/half_cheetah.xml"


def test_a_run_refuses_another_model_than_it_trained_on(tmp_path, monkeypatch, capsys):
    home, elsewhere = tmp_path / "home", tmp_path / "elsewhere"
    home.mkdir()
    elsewhere.mkdir()
    shutil.copyfile(XML, home / "cheetah.xml")
    heavier = XML.read_text().replace('<geom name="torso"', '<geom name="torso" density="2000"', 1)
    (elsewhere / "cheetah.xml").write_text(heavier)
    monkeypatch.chdir(home)
    run = tmp_path / "run"
    argv = ["train", "--algo", "sac", "--task", "HalfCheetah-v5", "--env-kwargs", "xml_file=./cheetah.xml"]  # fmt: skip
    argv += ["--preset", "smoke", "--total-steps", "400", "--checkpoint-every", "200", "--no-progress"]  # fmt: skip
    assert main([*argv, "--out", str(run)]) == 0
    model = json.loads((run / "environment.json").read_text())["model"]
    assert model["xml"] == os.path.realpath(home / "cheetah.xml") and len(model["sha256"]) == 64
    capsys.readouterr()
    monkeypatch.chdir(elsewhere)
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    one_line_exit_2(
        ["evaluate", str(run)], capsys, "was trained on the model", "evaluating it here"
    )
    (run / "DONE").unlink()
    before.pop(run / "DONE")
    one_line_exit_2(["train", "--resume", str(run)], capsys, "resuming it here would use")
    assert not (run / "evaluations").exists()
    assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file() and p.name != ".lock"} == {
        p: b for p, b in before.items() if p.name != ".lock"
    }
    monkeypatch.chdir(home)  # its own folder: the same model, evaluation goes on
    assert main(["evaluate", str(run), "--episodes", "1", "--no-progress"]) == 0
