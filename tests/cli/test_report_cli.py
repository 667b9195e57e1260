"""`adarl report`: a full report from synthetic run folders, and bad input (exit code 2, one
line on stderr, nothing half-written)."""

import pandas as pd
import pytest
from synthetic_runs import write_run, write_sweep

from adarl.cli.main import main
from adarl.report import build, common

TORSO = [0.2, 0.4, 0.6]


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """A sweep-like output folder: runs at different depths, as `adarl sweep` might write."""
    root = tmp_path_factory.mktemp("sweep")
    for task in ("hopper", "walker2d"):
        # walker2d without truncations keeps the number of figures (the test's cost) down
        write_run(root / task, "adarl", task=task, n_truncations=3 if task == "hopper" else 0)
        write_run(root / task, "sac", algo="sac", task=task, quality=0.8)
    write_run(root / "hopper", "ratio", algo="adarl", rank_rule="ratio", quality=0.7)
    for rank in (2, 16):
        write_run(
            root / "fixed-rank", f"r{rank}", algo="sac-fixed-rank", rank=rank, quality=rank / 16
        )
    for name, quality in (("adarl", 1.0), ("sac", 0.8)):
        write_sweep(
            root / "hopper" / name,
            "torso_length",
            TORSO,
            hold={"foot_length": 0.39},
            quality=quality,
        )
    return root


@pytest.fixture(scope="module")
def built(sweep, tmp_path_factory):
    out = tmp_path_factory.mktemp("reports") / "report"
    assert main(["report", str(sweep), "--out", str(out), "--bootstrap-reps", "200"]) == 0
    return out


def test_report_writes_every_table_and_figure(built):
    tables = {p.name for p in (built / "tables").iterdir()}
    assert {"table1.md", "table1.tex", "table1.csv", "aggregate.md", "aggregate.csv",
            "per_task.csv", "probability_of_improvement.csv", "performance_profiles.csv",
            "policy_size.md", "runs.csv", "fixed_rank_hopper.md"} <= tables  # fmt: skip
    stems = {p.stem for p in (built / "figures").glob("*.png")}
    assert stems == {p.stem for p in (built / "figures").glob("*.pdf")}
    assert {
        "training_curves", "ranks_hopper_adarl", "spectra_hopper_adarl",
        "robustness_hopper_sweep-torso_length-0.2-0.6-3_hold-foot_length-0.39",
        "bias_variance_hopper", "rank_rule_ablation_hopper", "aggregate_iqm_mean",
        "performance_profiles", "probability_of_improvement",
    } <= stems  # fmt: skip
    assert not list(built.parent.glob(".report.*"))  # no temp folder left


def test_table1_has_a_row_per_task_and_bold_best(built):
    md = (built / "tables" / "table1.md").read_text()
    assert md.splitlines()[0] == "| task | adarl | adarl (ratio rule) | sac |"
    hopper = next(line for line in md.splitlines() if line.startswith("| hopper"))
    assert hopper.split("|")[2].strip().startswith("**")  # adarl (quality 1.0) is best
    csv = pd.read_csv(built / "tables" / "table1.csv")
    assert set(csv["task"]) == {"hopper", "walker2d"} and set(csv["seeds"]) == {3}
    assert "sac-fixed-rank" not in md  # the rank sweep has its own table and figure


def test_statistics_tables(built):
    aggregate = pd.read_csv(built / "tables" / "aggregate.csv")
    assert set(aggregate["metric"]) == {"IQM", "Mean"}
    assert set(aggregate["method"]) == {"adarl", "sac"}  # the ratio rule ran on hopper only
    assert (aggregate["low"] <= aggregate["point"]).all() and (
        aggregate["point"] <= aggregate["high"]
    ).all()
    poi = pd.read_csv(built / "tables" / "probability_of_improvement.csv")
    assert set(poi["baseline"]) == {"adarl (ratio rule)", "sac"}  # fixed ranks: bias–variance
    sac = poi[poi["baseline"] == "sac"].iloc[0]
    assert sac["tasks"] == "hopper walker2d" and sac["point"] > 0.5


def _last5(run_dir) -> pd.Series:
    """Each seed's mean over its last 5 evaluations in eval.csv, computed here from the file."""
    log = pd.read_csv(run_dir / "eval.csv")
    per_eval = log.groupby(["seed", "step"])["return"].mean().unstack()
    return per_eval.iloc[:, -5:].mean(axis=1)


def test_scores_are_the_mean_of_the_last_evaluations_with_the_final_checkpoint_beside(built, sweep):
    table1 = pd.read_csv(built / "tables" / "table1.csv").set_index(["task", "method"])
    for task in ("hopper", "walker2d"):
        recent = _last5(sweep / task / "adarl")
        final = pd.read_csv(sweep / task / "adarl" / "eval.csv").query("step == 10000")
        final = final.groupby("seed")["return"].mean()
        cell = table1.loc[(task, "adarl")]
        assert cell["mean"] == pytest.approx(recent.mean(), rel=1e-5)  # CSV: 6 digits
        assert cell["std"] == pytest.approx(recent.std(ddof=1), rel=1e-5)
        assert cell["final_mean"] == pytest.approx(final.mean(), rel=1e-5)
    line = ("score: mean of the last 5 evaluations (steps 2,000–10,000), 2 episodes each; final "
            "checkpoint (the last evaluation in eval.csv) in ")  # fmt: skip
    for name, where in (("table1.md", "the rows “<task>, final checkpoint”"),
                        ("per_task.md", "the column “final checkpoint”"),
                        ("aggregate.md", "the columns “…, final checkpoint”")):  # fmt: skip
        assert line + where in (built / "tables" / name).read_text(), name
    md = (built / "tables" / "table1.md").read_text().splitlines()
    assert md[3].startswith("| hopper, final checkpoint | 10")  # final ≈ 1000 · quality
    scores = pd.read_csv(built / "tables" / "scores.csv")
    assert {"score", "final", "evaluations", "first_step", "last_step"} <= set(scores.columns)


def test_per_task_means_and_differences_use_t_intervals(built):
    import scipy.stats

    scores = pd.read_csv(built / "tables" / "scores.csv")
    per_task = pd.read_csv(built / "tables" / "per_task.csv").set_index(["task", "method"])
    diffs = pd.read_csv(built / "tables" / "differences.csv").set_index(["task", "baseline"])
    assert set(diffs.index) == {("hopper", "sac"), ("hopper", "adarl (ratio rule)"),
                                ("walker2d", "sac")}  # fmt: skip
    for task in ("hopper", "walker2d"):
        on_task = scores[scores["task"] == task]
        x = on_task.loc[on_task["method"] == "adarl", "score"].to_numpy()
        y = on_task.loc[on_task["method"] == "sac", "score"].to_numpy()
        one = scipy.stats.ttest_1samp(x, 0.0).confidence_interval(0.95)
        row = per_task.loc[(task, "adarl")]
        assert (row["mean_low"], row["mean_high"]) == pytest.approx((one.low, one.high), rel=1e-5)
        welch = scipy.stats.ttest_ind(x, y, equal_var=False).confidence_interval(0.95)
        row = diffs.loc[(task, "sac")]
        assert row["difference"] == pytest.approx(x.mean() - y.mean(), rel=1e-5)
        assert (row["low"], row["high"]) == pytest.approx((welch.low, welch.high), rel=1e-5)
        assert row["p_value"] == pytest.approx(0.1) and row["seeds"] == "3 vs 3"  # 20 splits
    index = (built / "index.md").read_text()
    assert "## Differences from adarl per task" in index and "**Power.**" in index
    poi = (built / "tables" / "probability_of_improvement.md").read_text()
    assert "detectable at 80% (per task)" in poi and "hopper " in poi


def test_one_method_or_one_seed_shows_no_aggregate_or_comparison(tmp_path, no_figures):
    """The quickstart's report: one method, one seed. No aggregate, profile or probability of
    improvement (nothing to compare), no interval from one seed; one note says why."""
    write_run(tmp_path / "runs", "a", algo="adarl", seeds=(0,))
    out = tmp_path / "report"
    assert main(["report", str(tmp_path / "runs"), "--out", str(out)]) == 0
    index = (out / "index.md").read_text()
    for absent in ("## Aggregate", "## Per-task", "## Probability of improvement",
                   "## Performance profiles", "## Differences", "IQM", "## Bias–variance"):  # fmt: skip
        assert absent not in index, absent
    assert "One seed per task and method: no intervals" in index
    hidden = next(line for line in index.splitlines() if line.startswith("- Not shown"))
    assert "Bias–variance" in hidden and "Rank-rule ablation" in hidden
    assert not (out / "tables" / "aggregate.csv").exists()
    # one method, three seeds: per-task means with their intervals, still no comparison
    write_run(tmp_path / "runs3", "a", algo="adarl", seeds=(0, 1, 2))
    assert main(["report", str(tmp_path / "runs3"), "--out", str(out)]) == 0
    index = (out / "index.md").read_text()
    assert "## Per-task means" in index and "## Aggregate" not in index
    assert "One method: no aggregate statistics" in index


def test_last_k(tmp_path, capsys, no_figures):
    run = write_run(tmp_path / "runs", "a", algo="sac", seeds=(0, 1), n_evals=3)
    out = tmp_path / "report"
    argv = ["report", str(run), "--out", str(out), "--bootstrap-reps", "20"]
    assert main([*argv, "--last-k", "1"]) == 0
    cell = pd.read_csv(out / "tables" / "table1.csv").iloc[0]
    assert cell["mean"] == pytest.approx(cell["final_mean"])  # the last evaluation is the final
    assert main(argv) == 0  # k = 5 with 3 evaluations: all 3, and the report says so
    cell = pd.read_csv(out / "tables" / "table1.csv").iloc[0]
    log = pd.read_csv(run / "eval.csv")
    assert cell["mean"] == pytest.approx(log.groupby("step")["return"].mean().mean(), rel=1e-5)
    index = (out / "index.md").read_text()
    assert "fewer evaluations than that, all of them used: hopper sac (3)" in index
    assert "3 evaluation(s) logged, fewer than --last-k 5" in index
    _fails([*argv, "--last-k", "0"], capsys, "--last-k must be ≥ 1, got 0")


def test_a_report_recomputes_its_tables_from_its_scores(built, sweep, tmp_path, no_figures, capsys):
    out = tmp_path / "again"
    assert main(["report", str(built), "--out", str(out), "--bootstrap-reps", "200"]) == 0
    for name in ("table1.csv", "per_task.csv", "aggregate.csv", "differences.csv",
                 "probability_of_improvement.csv", "performance_profiles.csv"):  # fmt: skip
        assert (out / "tables" / name).read_text() == (built / "tables" / name).read_text(), name
    assert "from the per-seed scores of" in (out / "index.md").read_text()
    csv = str(built / "tables" / "scores.csv")
    _fails(["report", csv, str(sweep), "--out", str(tmp_path / "x")], capsys, "not both")
    _fails(["report", csv, "--out", str(tmp_path / "x"), "--contrast", "algo"], capsys,
           "--contrast needs run folders")  # fmt: skip


def test_index_links_everything_and_states_budget_seeds_and_commands(built):
    index = (built / "index.md").read_text()
    for text in ("## Budget and seeds", "10,000", "0 1 2", "## Table 1", "## Robustness",
                 "## Bias–variance", "## Rank-rule ablation", "## Policy size", "## Commands",
                 "adarl train --algo sac --task walker2d", "adarl evaluate",
                 "--bootstrap-reps 200", "](figures/training_curves.png)",
                 "](figures/training_curves.pdf)", "](tables/table1.tex)"):  # fmt: skip
        assert text in index, text
    for link in [part.split(")")[0] for part in index.split("](")[1:]]:
        assert (built / link).is_file(), link


def test_rerun_replaces_a_previous_report(tmp_path, no_figures):
    write_run(tmp_path / "runs", "a", algo="sac", seeds=(0,))
    out = tmp_path / "report"
    assert (
        main(["report", str(tmp_path / "runs" / "a"), "--out", str(out), "--bootstrap-reps", "20"])
        == 0
    )
    write_run(tmp_path / "runs", "b", algo="sac-parseval", seeds=(0,))
    assert (
        main(["report", str(tmp_path / "runs"), "--out", str(out), "--bootstrap-reps", "20"]) == 0
    )
    assert "sac-parseval" in (out / "tables" / "table1.md").read_text()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.fixture
def no_figures(monkeypatch):
    """Skip drawing (the slow part) in tests about folders, not figures."""
    monkeypatch.setattr(common, "save_figure", lambda folder, fig, stem: [])


def _fails(argv, capsys, fragment):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("adarl report: error:") and err.count("\n") == 1 and fragment in err, err


def test_bad_input_exits_2_and_writes_nothing(tmp_path, sweep, capsys):
    out = tmp_path / "out"
    (tmp_path / "empty").mkdir()
    _fails(["report", str(tmp_path / "empty"), "--out", str(out)], capsys, "holds none")
    bare = write_run(tmp_path / "runs", "bare", checkpoint=False)
    _fails(["report", str(bare), "--out", str(out)], capsys, f"{bare} has no complete checkpoint")
    ompo = write_run(tmp_path / "runs2", "ompo", dynamics="ompo", algo="sac")
    _fails(["report", str(sweep / "hopper" / "adarl"), str(ompo), "--out", str(out)], capsys,
           "would share the table row 'hopper'")  # fmt: skip
    # one report, one physics backend: a device run (MJX) beside host runs, even on another task
    device = write_run(tmp_path / "runs3", "dev", task="walker2d", extra_config={"backend": "device"})  # fmt: skip
    _fails(["report", str(sweep / "hopper" / "adarl"), str(device), "--out", str(out)], capsys,
           "(backend device) and")  # fmt: skip
    # nor two device runs, one with the XML's solver and one capped (a different physics)
    capped = write_run(tmp_path / "runs4", "cap", task="walker2d",
                       extra_config={"backend": "device", "device_solver": "1,4"})  # fmt: skip
    _fails(["report", str(device), str(capped), "--out", str(out)], capsys,
           "(backend device) and " + str(capped) + " (backend device, solver 1,4) ran on different physics")  # fmt: skip
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "notes.txt").write_text("mine")
    _fails(["report", str(sweep), "--out", str(tmp_path / "busy")], capsys, "not an adarl report")
    assert not out.exists() and (tmp_path / "busy" / "notes.txt").read_text() == "mine"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_skip_incomplete(tmp_path, capsys, no_figures):
    write_run(tmp_path, "done", algo="sac")
    write_run(tmp_path, "early", checkpoint=False)
    out = tmp_path / "r"
    assert (
        main(
            [
                "report",
                str(tmp_path),
                "--out",
                str(out),
                "--skip-incomplete",
                "--bootstrap-reps",
                "20",
            ]
        )
        == 0
    )
    assert "Skipped" in (out / "index.md").read_text() and "early" in (out / "index.md").read_text()


def test_a_failure_midway_leaves_the_previous_report_untouched(tmp_path, monkeypatch, no_figures):
    write_run(tmp_path / "runs", "a", algo="sac")
    out = tmp_path / "report"
    assert (
        main(["report", str(tmp_path / "runs"), "--out", str(out), "--bootstrap-reps", "20"]) == 0
    )
    before = (out / "index.md").read_text()

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(build, "policy_size_section", boom)
    with pytest.raises(RuntimeError):
        main(["report", str(tmp_path / "runs"), "--out", str(out), "--bootstrap-reps", "20"])
    assert (out / "index.md").read_text() == before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_contrast_tables_each_value_against_the_reference(tmp_path, no_figures, capsys):
    """Two factors crossed (as the `physics` preset): each contrast pairs runs equal in the
    other factor; its difference is the means' difference, inside its bootstrap interval."""
    for physics, shift in (("consistent", 0.0), ("ompo", 0.3)):
        for version, vshift in (("v5", 0.0), ("v4", -0.2)):
            write_run(tmp_path / "runs", f"{physics}-{version}", algo="sac",
                      quality=1.0 + shift + vshift,
                      extra_config={"physics": physics, "model_version": version})  # fmt: skip
    out = tmp_path / "report"
    argv = ["report", str(tmp_path / "runs"), "--out", str(out), "--bootstrap-reps", "300"]
    assert main([*argv, "--contrast", "physics", "--contrast", "model_version=v5"]) == 0
    physics = pd.read_csv(out / "tables" / "contrast_physics.csv")
    assert sorted(physics["held fixed"]) == ["model_version=v4", "model_version=v5"]
    assert set(physics["contrast"]) == {"physics: ompo − consistent"}
    assert (
        physics["difference"] - (physics["mean (other)"] - physics["mean (consistent)"])
    ).abs().max() < 0.01  # the CSV rounds to 3 decimals
    assert (physics["ci low"] <= physics["difference"]).all() and (
        physics["difference"] <= physics["ci high"]
    ).all()
    # quality +0.3 is +300 at the last evaluation and +180 over the last five (steps 2k–10k of
    # 10k, returns ∝ step: mean 0.6 of the final one), the default score
    assert (physics["difference"] > 120).all() and (physics["difference"] < 240).all()
    # 3 seeds a side: 20 splits, so the exact permutation p is at least 2/20
    assert (physics["p"] >= 0.1 - 1e-9).all() and (physics["seeds"] == "3 vs 3").all()
    assert (physics["detectable"] > 0).all() and (physics["seeds_for_target"] >= 2).all()
    version = pd.read_csv(out / "tables" / "contrast_model_version.csv")
    assert (
        set(version["contrast"]) == {"model_version: v4 − v5"} and (version["difference"] < 0).all()
    )
    index = (out / "index.md").read_text()
    assert "## Contrast: physics" in index and "--contrast model_version=v5" in index
    _fails([*argv, "--contrast", "nosuchfield"], capsys, "no run has a config field 'nosuchfield'")
    _fails([*argv, "--contrast", "physics=mars"], capsys, "consistent, ompo")


def test_behaviour_table_prefers_adarl_evaluate_with_distance(tmp_path, no_figures):
    """Episode length comes from eval.csv when nothing else exists; an `adarl evaluate` of the
    final checkpoint (which records forward distance) takes precedence for both."""
    import json

    write_run(tmp_path / "runs", "logged", algo="sac", seeds=(0, 1))
    evaluated = write_run(tmp_path / "runs", "evaluated", algo="sac-sparse", seeds=(0, 1))
    step = 10_000  # write_run's final checkpoint: its total_steps
    (evaluated / "evaluations").mkdir()
    pd.DataFrame(
        {"step": step, "seed": [0, 0, 1, 1], "dynamics": "nominal", "episode": [0, 1, 0, 1],
         "return": [10.0, 20.0, 30.0, 40.0], "length": [100, 300, 1000, 1000],
         "distance": [0.5, 1.5, 3.0, 5.0]}
    ).to_csv(evaluated / "evaluations" / "nominal.csv", index=False)  # fmt: skip
    meta = {"dynamics": "nominal", "sweep": {}, "hold": {}, "episodes": 2,
            "checkpoint_step": step, "final_checkpoint": True, "max_episode_steps": None}  # fmt: skip
    (evaluated / "evaluations" / "nominal.json").write_text(json.dumps(meta))
    out = tmp_path / "report"
    assert (
        main(["report", str(tmp_path / "runs"), "--out", str(out), "--bootstrap-reps", "20"]) == 0
    )
    table = pd.read_csv(out / "tables" / "behaviour.csv").set_index(["method", "seed"])
    assert (
        table.loc[("sac-sparse", 0), "length"] == 200
        and table.loc[("sac-sparse", 1), "distance"] == 4.0
    )
    assert table.loc[("sac", 0), "length"] == 1000 and pd.isna(table.loc[("sac", 0), "distance"])
    index = (out / "index.md").read_text()
    assert (
        "## What the final policies do" in index
        and "| hopper | sac-sparse | 600 ± 566 | 2.50 ± 2.12 | fall 1, move 1 |" in index
        and "| hopper | sac | 1000 ± 0 | — | stand or move 2 |" in index
    )
