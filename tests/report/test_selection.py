"""The baselines' protocol in the report: every best-of family at its best value per task
(Parseval's coefficient, as the paper selects it) with every value in a supplementary table, and
RNAC's final or best checkpoint."""

import json

import pandas as pd
import pytest
from synthetic_runs import write_run

from adarl.cli.main import main
from adarl.report import common, selection
from adarl.report.scores import long_scores
from adarl.results import collect
from adarl.results.runs import find_runs

# quality ≈ final return / 1000; the best coefficient differs between the tasks
QUALITY = {
    "hopper": {1e-3: 0.6, 1e-4: 0.9, 1e-5: 0.7},
    "walker2d": {1e-3: 0.9, 1e-4: 0.5, 1e-5: 0.6},
}
PHRASE = "best of 3 values of parseval_coef (selected on the reported metric, as in the paper)"


@pytest.fixture
def no_figures(monkeypatch):
    monkeypatch.setattr(common, "save_figure", lambda folder, fig, stem: [])


@pytest.fixture
def sweep(tmp_path):
    root = tmp_path / "sweep"
    for task, by_coef in QUALITY.items():
        write_run(root / task, "sac", algo="sac", task=task, quality=0.8)
        for coef, quality in by_coef.items():
            write_run(
                root / task,
                f"parseval-{coef:g}",
                algo="sac-parseval",
                task=task,
                quality=quality,
                extra_config={"parseval_coef": coef},
            )
    return root


def _scores(runs):
    finals = {r.path: collect.final_scores(r) for r in runs}
    return long_scores(runs, finals)


def test_selection_picks_the_best_coefficient_per_task(sweep):
    runs = find_runs([sweep])
    scores = _scores(runs)
    chosen = selection.select_best_of(runs, scores)
    (family,) = chosen.families
    assert (family.algo, family.field) == ("sac-parseval", "parseval_coef")
    assert family.labels == {t: "sac-parseval (best of 3)" for t in QUALITY}
    cells = family.cells.set_index(["task", "parseval_coef"])
    assert len(cells) == 6 and set(cells["seeds"]) == {3}
    for task, by_coef in QUALITY.items():
        best = max(by_coef, key=by_coef.get)
        assert cells.loc[(task, best), "selected"]
        assert cells.loc[task, "selected"].sum() == 1
        means = cells.loc[task, "mean"]
        assert means[best] == means.max()
        # the main table keeps only the selected coefficient's seeds, under one label
        kept = chosen.scores[(chosen.scores["task"] == task) & (chosen.scores["method"] != "sac")]
        assert set(kept["method"]) == {"sac-parseval (best of 3)"} and len(kept) == 3
        assert kept["score"].mean() == pytest.approx(means[best])
        assert all(f"parseval-{best:g}" in run for run in kept["run"])
    assert len(chosen.scores) == len(scores) - 2 * 2 * 3  # two coefficients dropped per task
    assert not chosen.notes


def test_ties_keep_the_larger_coefficient_and_one_coefficient_selects_nothing(tmp_path):
    rows = pd.DataFrame(
        {"task": "hopper", "value": [1e-3, 1e-4, 1e-4], "seed": [0, 0, 1], "score": [5.0, 4, 6]}
    )
    cells = selection.value_cells(rows, "parseval_coef")
    assert cells.loc[cells["selected"], "parseval_coef"].tolist() == [1e-3]
    write_run(tmp_path, "p", algo="sac-parseval", extra_config={"parseval_coef": 1e-4})
    runs = find_runs([tmp_path])
    chosen = selection.select_best_of(runs, _scores(runs))
    assert chosen.labels == [] and chosen.families == []
    assert set(chosen.scores["method"]) == {"sac-parseval"}


def test_runs_that_differ_in_more_than_the_coefficient_are_not_selected(tmp_path):
    for coef, hidden in ((1e-3, [64, 64]), (1e-4, [256, 256])):
        write_run(
            tmp_path,
            f"p{coef:g}",
            algo="sac-parseval",
            extra_config={"parseval_coef": coef, "hidden": hidden},
        )
    runs = find_runs([tmp_path])
    chosen = selection.select_best_of(runs, _scores(runs))
    assert chosen.labels == [] and "differ in hidden" in chosen.notes[0]
    assert len(set(chosen.scores["method"])) == 2


def test_report_labels_the_selection_and_shows_every_coefficient(sweep, tmp_path, no_figures):
    out = tmp_path / "report"
    assert main(["report", str(sweep), "--out", str(out), "--bootstrap-reps", "20"]) == 0
    md = (out / "tables" / "table1.md").read_text()
    assert md.splitlines()[0] == "| task | sac | sac-parseval (best of 3) |"
    assert f"sac-parseval (best of 3): {PHRASE}" in md
    assert "chosen parseval_coef: hopper 1e-4, walker2d 1e-3" in md
    assert PHRASE.replace("_", r"\_") in (out / "tables" / "table1.tex").read_text()
    index = (out / "index.md").read_text()
    assert PHRASE in index and "## Supplementary: sac-parseval at each parseval_coef" in index
    table = (out / "tables" / "best-of-sac-parseval.md").read_text().splitlines()
    assert table[0] == (
        "| task | parseval_coef=1e-3 | parseval_coef=1e-4 | parseval_coef=1e-5 | selected |"
    )
    hopper = table[2].split("|")
    assert hopper[1].strip() == "hopper" and hopper[3].strip().startswith("**")
    assert hopper[5].strip() == "1e-4"
    cells = pd.read_csv(out / "tables" / "best-of-sac-parseval.csv")
    assert len(cells) == 6 and cells["selected"].sum() == 2
    aggregate = pd.read_csv(out / "tables" / "aggregate.csv")
    assert set(aggregate["method"]) == {"sac", "sac-parseval (best of 3)"}


def _rnac_run(root):
    run = write_run(root, "rnac", algo="rnac", seeds=(0, 1), quality=0.5)
    meta_path = next((run / "checkpoints").iterdir()) / "meta.json"
    meta = json.loads(meta_path.read_text())
    meta["best"] = {
        "metric": "mean nominal evaluation return",
        "dynamics": "nominal",
        "seeds": {"0": {"step": 4000, "return": 900.5}, "1": {"step": 6000, "return": 800.25}},
    }
    meta_path.write_text(json.dumps(meta))
    return run


def test_rnac_final_checkpoint_by_default_and_best_on_request(tmp_path, no_figures, capsys):
    run = _rnac_run(tmp_path / "runs")
    write_run(tmp_path / "runs", "sac", algo="sac", seeds=(0, 1))
    final, best = tmp_path / "final", tmp_path / "best"
    argv = ["report", str(tmp_path / "runs"), "--bootstrap-reps", "20"]
    assert main([*argv, "--out", str(final)]) == 0
    md = (final / "tables" / "table1.md").read_text()
    assert md.splitlines()[0] == "| task | sac | rnac |"
    assert "rnac: the final checkpoint" in md
    assert main([*argv, "--out", str(best), "--best-checkpoint", "best"]) == 0
    md = (best / "tables" / "table1.md").read_text()
    assert md.splitlines()[0] == "| task | sac | rnac (best checkpoint) |"
    assert "rnac (best checkpoint): each seed's best checkpoint" in md
    assert "850.4 ± 70.9" in md  # mean ± std of 900.5 and 800.25
    runs = pd.read_csv(best / "tables" / "runs.csv")
    source = runs.loc[runs["method"] == "rnac (best checkpoint)", "score from"].item()
    assert source == "best checkpoint by evaluation (steps seed 0: 4000, seed 1: 6000)"
    assert "hopper rnac (best checkpoint): the best checkpoint's evaluation return" in md
    assert "--best-checkpoint best" in (best / "index.md").read_text()
    # without a best record (an older run): the best nominal evaluation in eval.csv
    (next((run / "checkpoints").iterdir()) / "meta.json").write_text('{"step": 10000}')
    scores, note = collect.best_scores(find_runs([run])[0])
    log = pd.read_csv(run / "eval.csv").groupby(["seed", "step"])["return"].mean()
    assert scores["score"].tolist() == pytest.approx(log.groupby("seed").max().tolist())
    assert note.startswith("best nominal evaluation in eval.csv")
    # a bad value: one line, exit 2, nothing written
    capsys.readouterr()
    assert main([*argv, "--out", str(tmp_path / "bad"), "--best-checkpoint", "top"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown --best-checkpoint 'top'; allowed: final, best" in err
    assert not (tmp_path / "bad").exists()


def test_every_best_of_family_is_selected(sweep, monkeypatch):
    families = {"sac-parseval": "parseval_coef", "sac-sparse": "sparse_width"}
    monkeypatch.setattr(selection, "best_of_families", lambda: families)
    for width, quality in ((256, 0.4), (1024, 0.7)):
        write_run(
            sweep / "hopper",
            f"sparse-{width}",
            algo="sac-sparse",
            quality=quality,
            extra_config={"sparse_width": width},
        )
    runs = find_runs([sweep])
    chosen = selection.select_best_of(runs, _scores(runs))
    assert [(f.algo, f.field) for f in chosen.families] == list(families.items())
    sparse = chosen.families[1]
    assert sparse.labels == {"hopper": "sac-sparse (best of 2)"}
    assert sparse.cells.loc[sparse.cells["selected"], "sparse_width"].tolist() == [1024]
    kept = chosen.scores[chosen.scores["method"] == "sac-sparse (best of 2)"]
    assert len(kept) == 3 and all("sparse-1024" in run for run in kept["run"])
    assert "sac-parseval (best of 3)" in set(chosen.scores["method"])
