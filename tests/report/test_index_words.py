"""Issue 62: the words around the report's figures for a run of 1, 2 or 5 seeds. index.md's
budget table counts the seeds and lists their ids apart (a lone seed `0` under "seeds" read as
zero seeds), and the summary's verb agrees with its subject ("both seeds fall", not "all 2 seeds
falls")."""

import numpy as np
import pandas as pd
import pytest
from synthetic_runs import write_run

from adarl.report import build
from adarl.report.common import ReportOptions, seed_ids
from adarl.report.summary import behaviour_line
from adarl.results.runs import find_runs

TASK = "InvertedPendulum-v5"  # not the paper's
LIMIT = 200


def test_the_budget_table_counts_seeds_and_lists_their_ids(tmp_path):
    for n, first in ((1, 0), (2, 10), (5, 20)):  # one method: no seed twice
        write_run(tmp_path, f"seeds{n}", algo="adarl", task=TASK, seeds=range(first, first + n))
    runs = find_runs([tmp_path])
    (tmp_path / "out").mkdir()
    build.write_index(tmp_path / "out", runs, [], ReportOptions(), [])
    lines = (tmp_path / "out" / "index.md").read_text().splitlines()
    header = lines.index("## Budget and seeds") + 2
    assert lines[header] == "| task | method | steps per seed | seeds | seed ids |"
    rows = [line.split(" | ")[-2:] for line in lines[header + 2 : header + 5]]
    assert sorted(rows) == [["1", "0 |"], ["2", "10, 11 |"], ["5", "20–24 |"]]


@pytest.mark.parametrize(
    "n, words",
    [(1, ": falls (episodes end early"), (2, ": both seeds fall ("), (5, ": all 5 seeds fall (")],
)
def test_the_behaviour_line_agrees_in_number(n, words):
    table = pd.DataFrame(
        {"seed": range(n), "length": 60.0, "distance": np.nan, "max_length": LIMIT}
    )
    assert words in behaviour_line(table)
    standing = table.assign(length=float(LIMIT))
    assert ("stand or move (full length" in behaviour_line(standing)) == (n > 1)


def test_seed_ids_shorten_runs_of_consecutive_ids():
    assert seed_ids([0]) == "0" and seed_ids([1, 0]) == "0, 1" and seed_ids(range(5)) == "0–4"
    assert seed_ids([0, 1, 2, 7, 9, 10]) == "0–2, 7, 9, 10"
