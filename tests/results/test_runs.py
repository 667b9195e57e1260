"""Finding run folders, method labels, checkpoints and policy files."""

import pytest
from synthetic_runs import write_run

from adarl.errors import UsageError
from adarl.results import runs


def test_find_runs_in_a_run_and_in_a_folder_of_runs(tmp_path):
    a = write_run(tmp_path / "sweep" / "hopper", "adarl", seeds=(0, 1))
    b = write_run(tmp_path / "sweep" / "walker", "sac", algo="sac", task="walker2d", seeds=(0,))
    found = runs.find_runs([tmp_path / "sweep"])
    assert [r.path for r in found] == [a, b]
    assert [r.label for r in found] == ["adarl", "sac"]
    assert found[0].seeds == [0, 1] and found[0].total_steps == 10_000 and found[0].task == "hopper"
    assert runs.find_runs([a])[0].path == a
    assert len(runs.find_runs([a, tmp_path / "sweep"])) == 2  # no duplicates


def test_not_a_run(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(UsageError, match="is not a run folder and holds none"):
        runs.find_runs([tmp_path / "empty"])
    with pytest.raises(UsageError, match="does not exist"):
        runs.find_runs([tmp_path / "nowhere"])
    with pytest.raises(UsageError, match="is not a run folder"):
        runs.load_run(tmp_path / "empty")
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "config.yaml").write_text("algo: sac\ntask: hopper\n")
    with pytest.raises(UsageError, match="run format None; this adarl .* reads format 1"):
        runs.load_run(bad)
    (bad / "config.yaml").write_text("task: hopper\nformat_version: 1\n")
    with pytest.raises(UsageError, match="no 'algo' field"):
        runs.load_run(bad)
    (bad / "config.yaml").write_text("algo: sac\ntask: hopper\nformat_version: 2\n")
    with pytest.raises(UsageError, match="run format 2 by a newer adarl"):
        runs.load_run(bad)  # checked as a resume checks it


def test_config_values_are_top_level_and_seed_forms():
    # a nested record (a fork's `changed`) is another run's setting, never this run's
    config = {"algo": "adarl", "seeds": "0-2,5", "fork": {"changed": {"task": "walker2d"}}}
    assert runs.config_value(config, "task") is None
    assert runs.config_value(config, "task", "hopper") == "hopper"
    assert runs.parse_seeds(runs.config_value(config, "seeds")) == [0, 1, 2, 5]
    assert runs.parse_seeds(3) == [3] and runs.parse_seeds([1, 2]) == [1, 2]
    with pytest.raises(UsageError):
        runs.parse_seeds("a-b")


def test_method_labels_tell_variants_apart():
    assert runs.method_label({"algo": "sac-fixed-rank", "rank": 7}) == "sac-fixed-rank r=7"
    assert runs.method_label({"algo": "adarl", "rank_rule": "ratio"}) == "adarl (ratio rule)"
    assert runs.method_label({"algo": "sac-sparse", "sparse_width": 256}) == "sac-sparse w=256"
    assert runs.method_label({"algo": "sac-sparse", "sparse_width": 1024}) == "sac-sparse"
    from adarl.algos.registry import DEFAULT_BETA, DEFAULT_RANK_RULE
    from adarl.algos.sac_config import SACConfig

    assert (DEFAULT_RANK_RULE, DEFAULT_BETA) == (SACConfig.rank_rule, SACConfig.beta)
    assert runs.method_label({"algo": "adarl", "rank_rule": "ratio", "beta": 0.1}) == (
        "adarl (ratio rule, beta 0.1)"
    )
    assert runs.method_label({"algo": "adarl", "rank_rule": "energy", "beta": 0.98}) == "adarl"
    assert runs.method_label({"algo": "adarl", "rank_rule": "energy"}) == "adarl"  # the default
    assert runs.method_label({"algo": "adarl"}) == "adarl (cumulative rule)"  # older runs
    assert (
        runs.method_label({"algo": "adarl", "rank_rule": "cumulative", "retain_tolerance": 0.01})
        == "adarl (cumulative rule, retain 0.01)"
    )
    assert (
        runs.method_label({"algo": "adarl", "rank_rule": "energy", "retain_tolerance": None})
        == "adarl"
    )
    assert runs.sort_methods(["sac", "sac-fixed-rank r=16", "adarl (ratio rule)", "sac-fixed-rank r=2", "adarl"]) == [
        "adarl", "adarl (ratio rule)", "sac", "sac-fixed-rank r=2", "sac-fixed-rank r=16",
    ]  # fmt: skip
    assert runs.sort_tasks(["ant", "zoo", "hopper"]) == ["hopper", "ant", "zoo"]


def test_overlapping_seeds_get_labels_from_differing_config_fields(tmp_path):
    write_run(tmp_path, "c3", algo="sac-parseval", seeds=(0, 1), extra_config={"coef": 1e-3})
    write_run(tmp_path, "c4", algo="sac-parseval", seeds=(0, 1), extra_config={"coef": 1e-4})
    write_run(tmp_path, "more", algo="sac", seeds=(0,))
    write_run(tmp_path, "more2", algo="sac", seeds=(1,))  # disjoint seeds: pooled as one method
    labels = sorted(r.label for r in runs.find_runs([tmp_path]))
    assert labels == ["sac", "sac", "sac-parseval (coef=0.0001)", "sac-parseval (coef=0.001)"]


def test_the_same_run_twice_is_refused(tmp_path):
    write_run(tmp_path / "x", "a", seeds=(0, 1))
    write_run(tmp_path / "y", "a", seeds=(1, 2))
    with pytest.raises(UsageError, match=r"both 'adarl' on hopper with seed\(s\) \[1\]"):
        runs.find_runs([tmp_path])


def test_rank_settling_reads_cuts_retained_cuts_and_the_last_change(tmp_path):
    from adarl.results import collect

    (tmp_path / "truncations.csv").write_text(
        "step,seed,layer,old_rank,proposed_rank,new_rank,candidate_rank,error,decision\n"
        "100,0,actor_1,64,40,40,40,0.001,accepted\n"
        "200,0,actor_1,40,30,40,30,0.2,retained\n"
        "300,0,actor_1,40,39,39,39,0.01,accepted\n"
        "100,1,actor_1,64,50,50,50,0.001,accepted\n"
        "200,1,actor_1,50,60,50,50,0.0,unchanged\n"
        "300,1,actor_1,50,49,50,49,0.3,retained\n"
    )
    run = runs.Run(path=tmp_path, config={"task": "hopper", "algo": "adarl"}, label="adarl")
    table = collect.rank_settling(run).set_index("seed")
    assert table.loc[0, "final_rank"] == 39 and table.loc[1, "final_rank"] == 50
    assert list(table["cuts"]) == [2, 1] and list(table["retained"]) == [1, 1]
    assert list(table["last_change"]) == [300, 100]
    assert list(table["settled"]) == [False, True]
