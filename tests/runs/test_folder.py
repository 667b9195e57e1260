"""The run folder: runs written by earlier versions load, resume and evaluate; config.yaml is
written and read back through the registry.

tests/data/run-format-1 holds two tiny runs written by adarl at commit 96c9f8c (run format 1,
before the run-folder module): `sac-family` (adarl, 2 seeds, 200 steps, 4 truncations) and
`rnac` (2 seeds, 128 steps), each with checkpoints at two steps. `sac-family` recorded
`lanes: 1` (its seeds vmapped together), a layout adarl no longer trains: it evaluates, ranks
and exports, and its resume is refused naming the last commit that trains it."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from adarl.algos import registry
from adarl.cli.main import main
from adarl.errors import UsageError
from adarl.runs import folder
from adarl.runs.logs import read_csv

OLD = Path(__file__).parent.parent / "data" / "run-format-1"


def _rows(run: Path, name: str) -> list[dict]:
    rows = read_csv(run / name)
    for row in rows:
        row.pop("steps_per_s", None)  # wall-clock
    return rows


def _same_rows(a: list[dict], b: list[dict]) -> bool:
    """Equal rows; numbers equal to float32 rounding (the data was written on another machine,
    whose CPU may round a JAX reduction differently), everything else exactly."""
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if x.keys() != y.keys():
            return False
        for key in x:
            if x[key] == y[key]:
                continue
            try:
                if not np.isclose(float(x[key]), float(y[key]), rtol=1e-4, atol=1e-6):
                    return False
            except ValueError:
                return False
    return True


@pytest.mark.parametrize(("name", "algo"), [("sac-family", "adarl"), ("rnac", "rnac")])
def test_old_run_config_loads(name, algo):
    got_algo, config = folder.config_from_run(OLD / name)
    assert got_algo == algo
    assert config.seeds == (0, 1) and config.hidden == (16, 16)
    assert isinstance(config, registry.get(algo).config_class)


def _killed_copy(name: str, tmp_path: Path) -> Path:
    """The old run killed after its first checkpoint (the last one, DONE and half a CSV line
    lost)."""
    run = tmp_path / name
    shutil.copytree(OLD / name, run)
    saved = sorted((run / "checkpoints").iterdir())
    shutil.rmtree(saved[-1])
    (run / "DONE").unlink()
    with open(run / "episodes.csv", "a") as f:
        f.write("99,0,99,12.")
    return run


@pytest.mark.parametrize("name", ["rnac"])
def test_old_run_resumes_to_its_own_results(name, tmp_path):
    """Killed after its first checkpoint (the last one, DONE and half a CSV line lost), the old
    run resumes from its old-format checkpoint (old RNG keys, old env-state encoding, old CSV
    offset names) and writes the rows it wrote the first time."""
    run = _killed_copy(name, tmp_path)
    assert main(["train", "--resume", str(run), "--no-progress"]) == 0
    assert (run / "DONE").read_text() == (OLD / name / "DONE").read_text()
    for csv in sorted(p.name for p in (OLD / name).glob("*.csv")):
        assert _same_rows(_rows(run, csv), _rows(OLD / name, csv)), csv
    meta = json.loads((sorted((run / "checkpoints").iterdir())[-1] / "meta.json").read_text())
    assert "rng_states" in meta and "np_rngs" not in meta  # rewritten in today's keys


def test_a_retired_layout_is_refused_on_resume_and_fork(tmp_path, capsys):
    """`lanes: 1` (K ≥ 1: the retired vmapped layout): one line naming the commit that trains
    it, exit 2, nothing written; `lanes: 0` (today's layout, which the campaign's runs record)
    is read as today's config."""
    run = _killed_copy("sac-family", tmp_path)
    before = {p: p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()}
    assert main(["train", "--resume", str(run), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "has lanes: 1 (its seeds trained in K vmapped groups" in err
    assert "resume or fork it with adarl at commit 4ef91cf" in err
    fork = ["train", "--fork", str(run), "--at", "100", "--out", str(tmp_path / "child")]
    assert main([*fork, "--no-progress"]) == 2
    assert "with adarl at commit 4ef91cf" in capsys.readouterr().err
    assert not (tmp_path / "child").exists()
    after = {p: p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()}
    assert after.pop(run / ".lock") and after == before  # the lock the resume took, nothing else

    values = folder.load_config(run)
    _, config = folder.config_from_run(run)
    folder.write_config_values(run, {**values, "lanes": 0})
    assert folder.config_from_run(run) == ("adarl", config)
    registry.check_resumable(folder.load_config(run), "config.yaml")  # no error


def test_a_config_without_algo_is_refused(tmp_path):
    run = tmp_path / "rnac"
    shutil.copytree(OLD / "rnac", run)
    values = folder.load_config(run)
    del values["algo"]
    folder.write_config_values(run, values)
    with pytest.raises(UsageError, match="has no algo: line; put back the run's algorithm, one"):
        folder.config_from_run(run)


def test_old_runs_evaluate_rank_and_export(tmp_path, capsys):
    run = tmp_path / "sac-family"
    shutil.copytree(OLD / "sac-family", run)
    assert main(["ranks", str(run)]) == 0
    table = capsys.readouterr().out
    assert "actor_1" in table and "16→" in table
    assert main(["ranks", str(run), "--layer", "q1_1"]) == 0
    only = capsys.readouterr().out
    assert "q1_1" in only and "actor_1" not in only
    assert main(["ranks", str(run), "--layer", "q3_1"]) == 2
    assert "unknown layer 'q3_1'; this run has: actor_1, q1_1, q2_1" in capsys.readouterr().err
    assert main(["ranks", str(OLD / "rnac")]) == 2
    assert "has no truncations.csv (algo 'rnac'" in capsys.readouterr().err
    argv = ["evaluate", str(run), "--dynamics", "nominal", "--episodes", "1"]
    assert main([*argv, "--max-episode-steps", "10", "--workers", "1"]) == 0
    assert list((run / "evaluations").glob("*.csv"))
    rnac = tmp_path / "rnac"
    shutil.copytree(OLD / "rnac", rnac)
    assert main(["export", str(rnac), "--seed", "1", "--out", str(tmp_path / "p.npz")]) == 0
    assert (tmp_path / "p.npz").exists()


@pytest.mark.parametrize("algo", registry.ALGOS)
def test_config_yaml_round_trips_through_the_registry(algo, tmp_path):
    flags = {"seeds": "0-2", **({"rank": "7"} if "rank" in registry.field_names(algo) else {})}
    config = registry.resolve_config(algo, "smoke", flags)
    tmp_path.joinpath("run").mkdir()
    folder.write_config(tmp_path / "run", config, algo, "adarl train …")
    record = folder.load_config(tmp_path / "run")
    assert record["algo"] == algo and record["command"] == "adarl train …"
    assert folder.config_from_run(tmp_path / "run") == (algo, config)
