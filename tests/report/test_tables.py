"""Table 1 and the Markdown/LaTeX/CSV writers."""

import io

import pandas as pd
import pytest

from adarl.report import tables


@pytest.fixture
def scores():
    rows = [
        ("hopper", "adarl", 0, 10.0), ("hopper", "adarl", 1, 20.0), ("hopper", "adarl", 2, 30.0),
        ("hopper", "sac", 0, 5.0), ("hopper", "sac", 1, 7.0),
        ("walker2d", "sac", 0, 50.0), ("walker2d", "sac", 1, 50.0),
        ("walker2d", "adarl", 0, 40.0),
    ]  # fmt: skip
    return pd.DataFrame(rows, columns=["task", "method", "seed", "score"])


def test_score_table_mean_std_and_best(scores):
    t = tables.score_table(scores)
    assert t.rows == ["hopper", "walker2d"] and t.columns == ["adarl", "sac"]
    assert t.mean.at["hopper", "adarl"] == pytest.approx(20.0)
    assert t.std.at["hopper", "adarl"] == pytest.approx(10.0)  # sample std of 10, 20, 30
    assert t.std.at["hopper", "sac"] == pytest.approx(1.4142135)
    assert t.best.at["hopper", "adarl"] and not t.best.at["hopper", "sac"]
    assert t.best.at["walker2d", "sac"] and not t.best.at["walker2d", "adarl"]
    assert t.cell("hopper", "adarl") == "20.0 ± 10.0"
    assert t.cell("walker2d", "adarl") == "40.0"  # one seed: no spread


def test_markdown_bolds_the_best_per_row(scores):
    md = tables.table_markdown(tables.score_table(scores))
    lines = md.strip().splitlines()
    assert lines[0] == "| task | adarl | sac |"
    assert lines[2] == "| hopper | **20.0 ± 10.0** | 6.0 ± 1.4 |"
    assert lines[3] == "| walker2d | 40.0 | **50.0 ± 0.0** |"


def test_latex_and_csv(scores):
    t = tables.score_table(scores)
    tex = tables.table_latex(t, caption="Final return")
    assert r"\textbf{20.0 $\pm$ 10.0}" in tex and r"\begin{tabular}{lrr}" in tex
    assert r"\caption{Final return}" in tex and r"\toprule" in tex
    csv = pd.read_csv(io.StringIO(tables.table_csv(t)))
    assert list(csv.columns) == ["task", "method", "mean", "std", "seeds", "best"]
    assert csv.loc[(csv.task == "hopper") & (csv.method == "adarl"), "best"].item()
    assert len(csv) == 4


def test_missing_cells_are_dashes():
    scores = pd.DataFrame(
        [("hopper", "adarl", 0, 1.0), ("ant", "sac", 0, 2.0)],
        columns=["task", "method", "seed", "score"],
    )
    md = tables.table_markdown(tables.score_table(scores))
    assert "| hopper | **1.0** | — |" in md and "| ant | — | **2.0** |" in md
    assert "--" in tables.table_latex(tables.score_table(scores))


def test_latex_escapes_and_markdown_table_alignment():
    assert tables.latex_escape("sac_fixed & 50%") == r"sac\_fixed \& 50\%"
    md = tables.markdown_table(["a", "b", "c"], [["x", 1.5, "text"], ["y|z", 2, "more"]])
    assert md.splitlines()[1] == "| :--- | ---: | :--- |"
    assert r"y\|z" in md


@pytest.mark.parametrize(
    "p, text",
    [(0.04999, "0.050"), (0.0005, "0.001"), (0.000499, "< 0.001"), (0.0, "< 0.001"),
     (1.0, "1.000"), (float("nan"), tables.DASH)],
)  # fmt: skip
def test_a_p_value_never_prints_as_zero(p, text):
    assert tables.p_text(p) == text
