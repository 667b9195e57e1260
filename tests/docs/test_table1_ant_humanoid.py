"""docs/experiments/table1_ant_humanoid.py: the raw rows out of a sweep and the pre-registered
analysis from them. Expected values are computed here by hand from the rows the test writes."""

import csv
import importlib.util
import shutil
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).parents[2] / "docs/experiments/table1_ant_humanoid.py"


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location("table1_ant_humanoid", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _unit(root, task, method, returns, last_step=300_000, truncations=None, fell=(), seeds=None):
    """A unit whose seed s returns returns[s] + step/1e5 at every nominal evaluation; the seeds
    in `fell` end one episode of their last evaluation at step 300, the others last 1,000. Its
    seeds are 0, 1, ... in folder seeds-0-4, or `seeds` in folder seeds-<seeds joined by ->."""
    unit = root / task / method / ("seeds-0-4" if seeds is None else "seeds-" + "-".join(map(str, seeds)))  # fmt: skip
    unit.mkdir(parents=True)
    with (unit / "eval.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "seed", "dynamics", "episode", "return", "length"])
        for step in range(10_000, last_step + 1, 10_000):
            for seed, r in zip(seeds or range(len(returns)), returns, strict=True):
                for episode, noise in enumerate((-1.0, 1.0)):  # mean over episodes: r
                    length = 300 if seed in fell and step == last_step and episode else 1000
                    w.writerow([step, seed, "nominal", episode, r + step / 1e5 + noise, length])
                w.writerow([step, seed, "perturbed", 0, -1e6, 10])  # not nominal: ignored
    if truncations:
        with (unit / "truncations.csv").open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["step", "seed", "layer", "old_rank", "proposed_rank", "new_rank"])
            w.writerows(truncations)
    (unit / "checkpoints").mkdir()  # never exported
    if last_step >= 300_000:  # the run reached its budget (docs/run-format.md)
        (unit / "DONE").write_text(f"{last_step}\n")
    return unit


def test_scores_are_the_mean_of_the_last_five_nominal_evaluations(script, tmp_path):
    _unit(tmp_path / "sweep", "ant", "sac", [100.0, 200.0])
    script.export(tmp_path / "sweep", tmp_path / "rows")
    exported = sorted(p.name for p in (tmp_path / "rows/ant/sac").iterdir())
    assert exported == ["seeds-0-4-eval.csv.gz"]
    data = script.load(tmp_path / "rows")
    # last five evaluations at 260k..300k: mean of step/1e5 = 2.8
    assert data["ant"]["sac"]["scores"] == pytest.approx({0: 102.8, 1: 202.8})
    assert data["ant"]["sac"]["last_step"] == 300_000


def test_report_runs_the_primary_tests_only_when_both_tasks_finished(script, tmp_path):
    sweep = tmp_path / "sweep"
    sac = [1000.0, 1100.0, 900.0, 1050.0, 950.0]
    adarl = [2000.0, 2100.0, 1900.0, 2050.0, 1950.0]
    _unit(sweep, "ant", "sac", sac)
    cuts = [[60_000, s, "actor", 64, 20 + s, 20 + s] for s in range(5)]
    cuts += [[120_000, s, "actor", 20 + s, 19, 19] for s in range(5)]  # every seed at 19
    _unit(sweep, "ant", "adarl", adarl, truncations=cuts)
    _unit(sweep, "ant", "sac-parseval_parseval_coef-1e-03", [500.0] * 4 + [600.0])
    _unit(sweep, "ant", "sac-parseval_parseval_coef-1e-04", [700.0] * 4 + [800.0])
    _unit(sweep, "ant", "sac-parseval_parseval_coef-1e-05", [300.0] * 5)
    _unit(sweep, "humanoid", "sac", sac)
    _unit(sweep, "humanoid", "adarl", adarl, last_step=120_000)
    script.export(sweep, tmp_path / "rows")
    lines = script.report(script.load(tmp_path / "rows"))
    text = "\n".join(lines)
    assert "Not computed until both tasks' AdaRL and SAC units finish (humanoid: running)" in text
    assert "| humanoid | adarl |" not in text  # still training: not exported
    # exploratory: only the best Parseval (1e-04, mean 720) against AdaRL
    row = next(line for line in lines if line.startswith("| ant: adarl − sac-parseval"))
    assert "1e-04 (best of 3, chosen after the data)" in row
    assert f"{np.mean(adarl) - 720:+,.0f}" in row
    assert not any(("1e-03" in line or "1e-05" in line) and line.startswith("| ant: adarl") for line in lines)  # fmt: skip
    assert "| ant | actor | 17 | 5 | 20–24 | 19 | — | — |" in text


def test_report_detects_a_large_gap_on_both_tasks(script, tmp_path):
    sweep = tmp_path / "sweep"
    sac = np.array([1000.0, 1100.0, 900.0, 1050.0, 950.0])
    for task in ("ant", "humanoid"):
        _unit(sweep, task, "sac", list(sac))
        _unit(sweep, task, "adarl", list(sac + 1000.0))
    script.export(sweep, tmp_path / "rows")
    lines = script.report(script.load(tmp_path / "rows"))
    rows = [line for line in lines if line.startswith(("| ant: adarl − sac (", "| humanoid: adarl − sac ("))]  # fmt: skip
    assert len(rows) == 2 and all("**detected**" in r for r in rows)
    # equal SDs, identical shapes: difference exactly +1,000; Welch p from the t statistic by hand
    t = 1000.0 / np.sqrt(2 * sac.var(ddof=1) / 5)
    from scipy import stats

    p = 2 * stats.t.sf(t, 8)  # equal variances and sizes: Welch's df is 8
    assert p < 0.0005 and "| +1,000 |" in rows[0] and "| < 0.001 | < 0.001 |" in rows[0]
    assert script.compare(sac + 1000.0, sac)["p"] == pytest.approx(p)


def test_command_line(script, tmp_path, capsys):
    assert script.main(["nonsense"]) == 2
    assert "usage" in capsys.readouterr().err
    assert script.main(["--help"]) == 0
    assert "export" in capsys.readouterr().out


@pytest.mark.parametrize("command", ["export", "report"])
def test_a_folder_that_is_not_there_is_one_line_and_exit_2(script, tmp_path, capsys, command):
    with pytest.raises(SystemExit) as stopped:
        script.main([command, str(tmp_path / "nope")])
    err = capsys.readouterr().err
    assert stopped.value.code == 2 and err == f"error: {tmp_path / 'nope'} is not a folder (a sweep's, or exported rows)\n"  # fmt: skip


def test_survival_counts_with_fishers_test(script, tmp_path):
    sweep = tmp_path / "sweep"
    _unit(sweep, "ant", "adarl", [2000.0, 2100.0, 1900.0, 2050.0, 1950.0])
    _unit(sweep, "ant", "sac", [1000.0, 1100.0, 900.0, 1050.0, 950.0], fell=(0, 3))
    script.export(sweep, tmp_path / "rows")
    lines = script.report(script.load(tmp_path / "rows"))
    # 5 of 5 against 3 of 5 (margins 8 and 2 of 10): tables with AdaRL at 5, 4, 3 survivors have
    # probabilities 56, 140, 56 out of C(10, 5) = 252; two-sided Fisher p = (56 + 56) / 252
    assert f"| ant | sac | 3/5 | {112 / 252:.3f}, " in "\n".join(lines)
    assert "| ant | adarl | 5/5 | — |" in lines


def test_figure_draws_each_methods_mean_curve_with_the_best_parseval_only(script, tmp_path):
    sweep = tmp_path / "sweep"
    _unit(sweep, "ant", "sac", [100.0, 300.0])
    _unit(sweep, "ant", "sac-parseval_parseval_coef-1e-03", [500.0] * 5)
    _unit(sweep, "ant", "sac-parseval_parseval_coef-1e-04", [700.0, 900.0] * 2 + [800.0])
    _unit(sweep, "ant", "sac-parseval_parseval_coef-1e-05", [2000.0] * 4)  # 4 seeds: running
    _unit(sweep, "humanoid", "adarl", [50.0, 70.0])
    script.export(sweep, tmp_path / "rows")
    found = script.curves(tmp_path / "rows")
    # 1e-05 scores highest but is still running: the best of the two finished is 1e-04
    assert sorted(found["ant"]) == ["sac (2 of 5 seeds)", "sac-parseval 1e-04 (best of the 2 finished of 3)"]  # fmt: skip
    # the evaluation's mean over its two episodes (noise -1, +1): returns[s] + step/1e5
    sac = found["ant"]["sac (2 of 5 seeds)"]
    assert sac[sac.step == 20_000].sort_values("seed")["return"].tolist() == pytest.approx([100.2, 300.2])  # fmt: skip
    assert found["humanoid"]["adarl (2 of 5 seeds)"].step.max() == 300_000
    written = script.figure(tmp_path / "rows", tmp_path / "fig" / "curves")
    assert sorted(p.name for p in written) == ["curves.pdf", "curves.png"]
    with pytest.raises(SystemExit) as stopped:
        script.main(["figure", str(tmp_path / "nope")])
    assert stopped.value.code == 2


def test_the_score_table_gives_each_units_training_time_from_its_train_csv(script, tmp_path):
    unit = _unit(tmp_path / "sweep", "ant", "sac", [100.0, 200.0])
    with (unit / "train.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "seed", "steps_per_s", "loss_q"])
        for step, rate in ((180_000, 100.0), (300_000, 200.0 / 3)):  # 1,800 s each: one hour
            w.writerows([[step, 0, rate, 1.0], [step, 1, rate, 1.0]])  # one clock, both seeds
    _unit(tmp_path / "sweep", "humanoid", "sac", [100.0, 200.0])  # no train.csv
    script.export(tmp_path / "sweep", tmp_path / "rows")
    assert (tmp_path / "rows/ant/sac/seeds-0-4-train.csv.gz").exists()
    lines = script.report(script.load(tmp_path / "rows"))
    assert any(line.startswith("| ant | sac | 2 | 300,000 (running) |") and line.endswith("| 1.0 |") for line in lines)  # fmt: skip
    assert any(line.startswith("| humanoid | sac |") and line.endswith("| — |") for line in lines)
    # no AdaRL unit: no exploratory comparison, and no empty table
    assert "None yet: AdaRL and a baseline must both finish on a task." in lines
    assert not any(line.startswith("| comparison |") for line in lines)


def test_a_method_trained_one_seed_per_unit_is_finished_when_all_five_seeds_are(script, tmp_path):
    sweep = tmp_path / "sweep"
    sac = [1000.0, 1100.0, 900.0, 1050.0, 950.0]
    _unit(sweep, "humanoid", "sac", sac)  # one unit of five seeds
    for seed in (0, 1, 2):  # one unit per seed; seeds 3 and 4 not yet evaluated
        _unit(sweep, "humanoid", "adarl", [2000.0 + seed], seeds=[seed])
    _unit(sweep, "humanoid", "adarl", [2003.0], seeds=[3], last_step=120_000)
    written, left = script.export(sweep, tmp_path / "rows")
    assert left == [sweep / "humanoid/adarl/seeds-3"]  # still training: left for later
    exported = sorted(p.name for p in (tmp_path / "rows/humanoid/adarl").iterdir())
    assert exported == [f"seeds-{s}-eval.csv.gz" for s in range(3)]
    data = script.load(tmp_path / "rows")
    adarl = data["humanoid"]["adarl"]
    assert adarl["scores"] == pytest.approx({0: 2002.8, 1: 2003.8, 2: 2004.8})
    assert adarl["last_step"] == 300_000 and not script.is_finished(adarl)
    assert script.is_finished(data["humanoid"]["sac"])
    assert "| humanoid | adarl | 3 | 300,000 (running) |" in "\n".join(script.report(data))
    # the last seed arrives and reaches the budget; seed 3 too: all five seeds, finished
    shutil.rmtree(sweep / "humanoid/adarl/seeds-3")
    _unit(sweep, "humanoid", "adarl", [2003.0], seeds=[3])
    _unit(sweep, "humanoid", "adarl", [2004.0], seeds=[4])
    script.export(sweep, tmp_path / "rows")
    adarl = script.load(tmp_path / "rows")["humanoid"]["adarl"]
    assert script.is_finished(adarl) and sorted(adarl["scores"]) == [0, 1, 2, 3, 4]
    # three seeds at the budget are not "finished" either, nor a method with a sixth seed
    assert not script.is_finished({"last_step": 300_000, "scores": {0: 1.0, 1: 1.0, 2: 1.0}})
    assert not script.is_finished({"last_step": 300_000, "scores": dict.fromkeys(range(6), 1.0)})


def test_the_reports_tables_are_the_scripts_on_the_committed_rows(script):
    """table1-ant-humanoid.md shows what `report` computes now from the committed rows: rows
    committed without `report --write`, or a number edited by hand, fail here."""
    assert script.written_report() == "\n".join(script.report(script.load())).strip("\n")


def test_report_write_replaces_only_the_text_between_the_markers(script, tmp_path, capsys):
    doc = tmp_path / "doc.md"
    doc.write_text(f"# Title\n\nbefore\n\n{script.BEGIN}\nold table\n{script.END}\n\nafter\n")
    script.write_report(["### Scores", "", "| a |", ""], doc)
    expected = (
        f"# Title\n\nbefore\n\n{script.BEGIN}\n\n### Scores\n\n| a |\n\n{script.END}\n\nafter\n"
    )
    assert doc.read_text() == expected
    assert script.written_report(doc) == "### Scores\n\n| a |"
    script.write_report(["### Scores", "", "| b |", ""], doc)  # again: the same frame
    assert doc.read_text() == expected.replace("| a |", "| b |")
    doc.write_text(f"{script.END}\n{script.BEGIN}\n")  # markers out of order
    with pytest.raises(SystemExit) as stopped:
        script.write_report(["x"], doc)
    assert stopped.value.code == 2 and capsys.readouterr().err.startswith(f"error: {doc} lacks the lines")  # fmt: skip
    assert doc.read_text() == f"{script.END}\n{script.BEGIN}\n"  # nothing lost


def _permutation_p(x, y):
    """Exact two-sided p of the difference of means over every split of x ∪ y (by brute force)."""
    z = np.concatenate([x, y])
    first = np.array([np.isin(np.arange(z.size), i) for i in combinations(range(z.size), x.size)])
    differences = (first * z).sum(1) / x.size - (~first * z).sum(1) / y.size
    return float(np.mean(np.abs(differences) >= abs(x.mean() - y.mean()) - 1e-9))


def test_the_numbers_the_results_quote(script):
    """The Results section's numbers, written here from its text, recomputed from the committed
    rows with SciPy's Welch test, Holm by hand and a brute-force permutation test: independent of
    the script's statistics (only its reading of the rows is shared)."""
    from scipy import stats

    data = script.load()

    def arm(task, method):
        scores = data[task][method]["scores"]
        return np.array([scores[s] for s in sorted(scores)])

    quoted = {  # task: AdaRL mean, SD; SAC mean, SD; difference; Welch interval; Welch p
        "ant": (2025, 77, 1982, 46, 43, (-54, 140), 0.324),
        "humanoid": (999, 900, 521, 30, 478, (-639, 1595), 0.301),
    }
    p = {}
    for task, (m_a, sd_a, m_s, sd_s, diff, ci, p_welch) in quoted.items():
        x, y = arm(task, "adarl"), arm(task, "sac")
        assert (x.mean(), x.std(ddof=1), y.mean(), y.std(ddof=1)) == pytest.approx((m_a, sd_a, m_s, sd_s), abs=0.5)  # fmt: skip
        welch = stats.ttest_ind(x, y, equal_var=False)
        interval = welch.confidence_interval()
        assert x.mean() - y.mean() == pytest.approx(diff, abs=0.5)
        assert (interval.low, interval.high) == pytest.approx(ci, abs=0.5)
        assert welch.pvalue == pytest.approx(p_welch, abs=0.0005)
        p[task] = welch.pvalue
    low, high = sorted(p.values())
    holm = max(min(1, 2 * low), min(1, high))  # Holm over two: both adjusted p are this here
    assert min(1, 2 * low) == pytest.approx(0.602, abs=0.0005) and holm == pytest.approx(0.602, abs=0.0005)  # fmt: skip

    # detectable at 80% power: Welch's test simulated on normal arms with the pooled SD; its range
    # scales with the SD over the SD's 95% chi-square interval (8 degrees of freedom)
    rng = np.random.default_rng(0)
    z1, z2 = rng.standard_normal((2, 100_000, 5))
    for task, (sd, detectable, low, high) in {"ant": (64, 132, 89, 254), "humanoid": (637, 1327, 896, 2542)}.items():  # fmt: skip
        x, y = arm(task, "adarl"), arm(task, "sac")
        pooled = np.sqrt((x.var(ddof=1) + y.var(ddof=1)) / 2)
        assert pooled == pytest.approx(sd, abs=0.5)
        power = np.mean(stats.ttest_ind(z1 * pooled + detectable, z2 * pooled, axis=1, equal_var=False).pvalue < 0.05)  # fmt: skip
        assert power == pytest.approx(0.80, abs=0.01)
        scale = np.sqrt(8 / stats.chi2.ppf([0.975, 0.025], 8))
        assert detectable * scale == pytest.approx((low, high), rel=0.01)

    # the permutation intervals: the shifts d at which the exact test of (x − d, y) keeps p > 0.05
    for task, (lo, hi) in {"ant": (-45, 136), "humanoid": (-16, 1174)}.items():
        x, y = arm(task, "adarl"), arm(task, "sac")
        assert _permutation_p(x - (lo + 1), y) > 0.05 and _permutation_p(x - (hi - 1), y) > 0.05
        assert _permutation_p(x - (lo - 2), y) <= 0.05 and _permutation_p(x - (hi + 2), y) <= 0.05
    x, y = arm("humanoid", "adarl"), arm("humanoid", "sac")
    assert _permutation_p(x, y) == pytest.approx(28 / 252)  # "its exact two-sided p is 0.111"

    # exploratory: Ant, AdaRL − sparse
    x, sparse = arm("ant", "adarl"), arm("ant", "sac-sparse_sparse_width-256")
    welch = stats.ttest_ind(x, sparse, equal_var=False)
    interval = welch.confidence_interval()
    assert (x.mean() - sparse.mean(), interval.low, interval.high) == pytest.approx((-542, -830, -255), abs=0.5)  # fmt: skip
    assert welch.pvalue == pytest.approx(0.005, abs=0.0005)

    # the ranks after the first and the fourth cut (actor), min–max over seeds
    def actor_ranks(task, cut):
        rows = [r for r in data[task]["adarl"]["truncations"] if r["layer"] == "actor_1"]
        step = sorted({int(r["step"]) for r in rows})[cut - 1]
        ranks = [int(r["new_rank"]) for r in rows if int(r["step"]) == step]
        return min(ranks), max(ranks)

    assert actor_ranks("ant", 1) == (37, 38) and actor_ranks("ant", 4) == (26, 27)
    assert actor_ranks("humanoid", 1) == (40, 41) and actor_ranks("humanoid", 2) == (33, 34)
    assert actor_ranks("humanoid", 4) == (22, 27)


def test_how_long_the_humanoid_adarl_policies_stay_up(script):
    """ "fall within 90–155 steps on average; seed 3 ... stays up 549 steps on average": the mean
    episode length of the last 5 nominal evaluations, from the committed eval rows."""
    lengths = {}
    for path in sorted((script.ROWS / "humanoid" / "adarl").glob("*eval.csv.gz")):
        for row in script.read_gzipped(path):
            if row["dynamics"] == "nominal" and int(row["step"]) > 250_000:
                lengths.setdefault(int(row["seed"]), []).append(int(row["length"]))
    means = {seed: np.mean(v) for seed, v in lengths.items()}
    assert sorted(lengths) == [0, 1, 2, 3, 4] and all(len(v) == 25 for v in lengths.values())
    assert round(means.pop(3)) == 549 and all(90 <= m <= 155 for m in means.values())


def test_what_the_results_say_of_rnac_on_ant(script):
    """ "at 10k steps its deterministic policy stands for all 1,000 steps (return 842), at 300k it
    ends each episode after 17 steps"; "about 2.1 per step" of control cost at σ = 1; training
    return per step −1.25 (first 20k) and −1.6 (last 50k), episodes of 273 and 69 steps."""
    from scipy import stats

    unit = script.ROWS / "ant" / "rnac"
    evals = [r for r in script.read_gzipped(unit / "seeds-0-4-eval.csv.gz") if r["dynamics"] == "nominal"]  # fmt: skip

    def at(step, field):
        return np.mean([float(r[field]) for r in evals if int(r["step"]) == step])

    assert at(10_000, "length") == 1000 and round(at(10_000, "return")) == 842
    assert round(at(300_000, "length")) == 17
    episodes = script.read_gzipped(unit / "seeds-0-4-episodes.csv.gz")

    def per_step(lo, hi):
        sel = [r for r in episodes if lo <= int(r["step"]) < hi]
        returns, lengths = (np.array([float(r[f]) for r in sel]) for f in ("return", "length"))
        return returns.sum() / lengths.sum(), lengths.mean()

    (first, first_length), (last, last_length) = per_step(0, 20_000), per_step(250_000, 300_001)
    assert round(first, 2) == -1.25 and round(first_length) == 273
    assert round(last, 1) == -1.6 and round(last_length) == 69
    # E[clip(z, −1, 1)²] for z ~ N(0, 1), times Ant's 0.5 control weight and 8 joints
    inside = (2 * stats.norm.cdf(1) - 1) - 2 * stats.norm.pdf(1)  # E[z²; |z| < 1]
    assert 0.5 * 8 * (inside + 2 * stats.norm.sf(1)) == pytest.approx(2.1, abs=0.05)


def test_rnac_on_humanoid_never_stays_up_longer(script):
    """ "its evaluation episodes lasting 42–55 steps on average at every one of its 30 evaluations"."""
    lengths = {}
    for r in script.read_gzipped(script.ROWS / "humanoid" / "rnac" / "seeds-0-4-eval.csv.gz"):
        if r["dynamics"] == "nominal":
            lengths.setdefault(int(r["step"]), []).append(int(r["length"]))
    means = [np.mean(v) for v in lengths.values()]
    assert len(means) == 30 and (round(min(means)), round(max(means))) == (42, 55)


def test_the_best_parseval_says_among_how_many_finished_coefficients_it_was_chosen(script):
    done = {"last_step": 300_000, "scores": dict.fromkeys(range(5), 1.0)}
    running = {"last_step": 100_000, "scores": dict.fromkeys(range(5), 1.0)}
    ant = {"sac": done, "sac-parseval_parseval_coef-0.001": done}
    ant["sac-parseval_parseval_coef-0.0001"] = running
    data = {"ant": ant}
    assert script.best_of(data, "ant", chosen=True) == "the only one of 3 finished so far"
    ant["sac-parseval_parseval_coef-0.0001"] = done
    assert script.best_of(data, "ant", chosen=True) == "best of the 2 finished of 3, chosen after the data"  # fmt: skip
    ant["sac-parseval_parseval_coef-1e-05"] = done
    assert script.best_of(data, "ant") == "best of 3"


def test_what_the_results_say_of_parseval(script):
    """Each coefficient's mean ± SD as the Results quote them, the best one per task, and AdaRL −
    best with SciPy's Welch interval and the brute-force permutation interval (Humanoid)."""
    from scipy import stats

    data = script.load()

    def arm(task, method):
        scores = data[task][method]["scores"]
        return np.array([scores[s] for s in sorted(scores)])

    quoted = {  # task: {coefficient: (mean, SD or None)}, (AdaRL − best, Welch interval)
        "ant": (
            {"1e-05": (1732, 98), "0.0001": (1473, None), "0.001": (799, None)},
            (293, (162, 423)),
        ),
        "humanoid": (
            {"1e-05": (405, 45), "0.0001": (373, 43), "0.001": (323, 63)},
            (593, (-523, 1710)),
        ),
    }
    for task, (coefficients, (difference, interval)) in quoted.items():
        means = {}
        for coefficient, (mean, sd) in coefficients.items():
            scores = arm(task, f"sac-parseval_parseval_coef-{coefficient}")
            means[coefficient] = scores.mean()
            assert len(scores) == 5 and round(scores.mean()) == mean
            assert sd is None or round(scores.std(ddof=1)) == sd
        assert max(means, key=means.get) == "1e-05"  # "the best of the three" on both tasks
        x, y = arm(task, "adarl"), arm(task, "sac-parseval_parseval_coef-1e-05")
        ci = stats.ttest_ind(x, y, equal_var=False).confidence_interval()
        assert (x.mean() - y.mean(), ci.low, ci.high) == pytest.approx((difference, *interval), abs=0.5)  # fmt: skip
    x, y = arm("humanoid", "adarl"), arm("humanoid", "sac-parseval_parseval_coef-1e-05")
    lo, hi = 93, 1311  # "permutation [+93, +1,311]"
    assert _permutation_p(x - (lo + 1), y) > 0.05 and _permutation_p(x - (hi - 1), y) > 0.05
    assert _permutation_p(x - (lo - 2), y) <= 0.05 and _permutation_p(x - (hi + 2), y) <= 0.05


def test_how_long_the_table_trained(script):
    """ "44 unit-hours in all": each run's train.csv intervals over their rates (the first seed's
    rows; all seeds of a run share a clock), summed over every committed run."""
    import pandas as pd

    seconds = 0.0
    for path in script.ROWS.glob("*/*/*train.csv.gz"):
        rows = pd.read_csv(path)
        rows = rows[rows["seed"] == rows["seed"].iloc[0]]
        seconds += (np.diff(rows["step"], prepend=0) / rows["steps_per_s"]).sum()
    assert round(seconds / 3600) == 44


DOC = SCRIPT.with_name("table1-ant-humanoid.md")


def test_the_detectable_differences_at_the_arms_own_sds(script):
    """Issue 54 §2: where the arms' SDs differ, the detectable difference is Welch's at the arms'
    own SDs, its range with both SDs at the ends of their own 4-df 95% intervals (the
    pre-registered 0.60–2.87), and the pre-registered 4-df range at the pooled SD is given too.
    Welch's power here is simulated, independently of adarl.stats' quadrature."""
    from scipy import stats

    data = script.load()
    text = " ".join(DOC.read_text().split())

    def arm(task, method):
        scores = data[task][method]["scores"]
        return np.array([scores[s] for s in sorted(scores)])

    rng = np.random.default_rng(3)
    z1, z2 = rng.standard_normal((2, 100_000, 5))
    low4, high4 = np.sqrt(4 / stats.chi2.ppf([0.975, 0.025], 4))
    quoted = {  # (task, baseline): detectable at the arms' own SDs, its range, as the doc writes
        ("ant", "sac"): ("136", "82–391"),
        ("humanoid", "sac"): ("1,513", "907–4,349"),
        ("ant", "rnac"): ("131", "78–376"),
        ("ant", "sac-parseval_parseval_coef-1e-05"): ("185", "111–533"),
        ("ant", "sac-sparse_sparse_width-256"): ("396", "237–1,137"),
        ("humanoid", "rnac"): ("1,512", "906–4,346"),
        ("humanoid", "sac-parseval_parseval_coef-1e-05"): ("1,513", "907–4,348"),
        ("humanoid", "sac-sparse_sparse_width-256"): ("2,203", "1,320–6,331"),
    }
    for (task, baseline), (detectable, interval) in quoted.items():
        x, y = arm(task, "adarl"), arm(task, baseline)
        d = float(detectable.replace(",", ""))
        sims = z1 * x.std(ddof=1) + d, z2 * y.std(ddof=1)
        power = np.mean(stats.ttest_ind(*sims, axis=1, equal_var=False).pvalue < 0.05)
        assert power == pytest.approx(0.80, abs=0.01), (task, baseline, power)
        low, high = (float(v.replace(",", "")) for v in interval.split("–"))
        assert (d * low4, d * high4) == pytest.approx((low, high), rel=0.01)
        assert f"{detectable} ({interval})" in text or f"{detectable} ({interval};" in text
    # the pre-registered 4-df interval at the pooled SD (132 and 1,327, simulated in
    # test_the_numbers_the_results_quote): 79–381 and 795–3,812
    for pooled_detectable, interval in ((132, "79–381"), (1327, "795–3,812")):
        low, high = (float(v.replace(",", "")) for v in interval.split("–"))
        assert (pooled_detectable * low4, pooled_detectable * high4) == pytest.approx((low, high), rel=0.01)  # fmt: skip
        assert interval in text
    assert "1,327 at the pooled SD 637" in text and "1,513 would have been detected" in text


def test_what_the_rows_say_of_one_seed_per_unit_on_ant(script):
    """ "Ant SAC's five one-seed units took 738–792 s ... against 765–800 s per seed in the three
    five-seed Parseval units (3,827–4,000 s each); Ant AdaRL's ... 843–878 s ... 1.14×"."""
    import pandas as pd

    def seconds(path):
        rows = pd.read_csv(path)
        rows = rows[rows["seed"] == rows["seed"].iloc[0]]
        return (np.diff(rows["step"], prepend=0) / rows["steps_per_s"]).sum()

    ant = script.ROWS / "ant"
    sac = [seconds(ant / "sac" / f"seeds-{s}-train.csv.gz") for s in range(5)]
    adarl = [seconds(ant / "adarl" / f"seeds-{s}-train.csv.gz") for s in range(5)]
    parseval = [seconds(p) for p in sorted(ant.glob("sac-parseval_*/seeds-0-4-train.csv.gz"))]
    assert len(parseval) == 3
    assert (round(min(sac)), round(max(sac))) == (738, 792)
    assert (round(min(parseval)), round(max(parseval))) == (3827, 4000)
    assert (round(min(parseval) / 5), round(max(parseval) / 5)) == (765, 800)
    assert (round(min(adarl)), round(max(adarl))) == (843, 878)
    assert round(np.mean(adarl) / np.mean(sac), 2) == 1.14
    text = " ".join(DOC.read_text().split())
    for quoted in ("738–792 s each", "765–800 s per seed", "(3,827–4,000 s each)", "843–878 s", "1.14× SAC's"):  # fmt: skip
        assert quoted in text


def test_how_often_the_high_humanoid_adarl_seed_falls(script):
    """ "seed 3 falls in 19 of its last 25 episodes"."""
    rows = script.read_gzipped(script.ROWS / "humanoid" / "adarl" / "seeds-3-eval.csv.gz")
    last = [int(r["length"]) for r in rows if r["dynamics"] == "nominal" and int(r["step"]) > 250_000]  # fmt: skip
    assert len(last) == 25 and sum(length < 1000 for length in last) == 19
    assert "seed 3 falls in 19 of its last 25 episodes" in " ".join(DOC.read_text().split())


def test_the_humanoid_critics_at_the_first_two_cuts(script):
    """ "its critics are at 34–36 after the first (one seed's q2 already at 34) and 26–30 after
    the second"."""
    rows = script.load()["humanoid"]["adarl"]["truncations"]
    steps = sorted({int(r["step"]) for r in rows})

    def critics(cut):
        return [int(r["new_rank"]) for r in rows if r["layer"] != "actor_1" and int(r["step"]) == steps[cut - 1]]  # fmt: skip

    first = critics(1)
    assert (min(first), max(first)) == (34, 36) and first.count(34) == 1
    assert min(critics(2)) == 26 and max(critics(2)) == 30
    q2 = [int(r["new_rank"]) for r in rows if r["layer"] == "q2_1" and int(r["step"]) == steps[0]]
    assert min(q2) == 34
    text = " ".join(DOC.read_text().split())
    assert "its critics are at 34–36 after the first (one seed's q2 already at 34) and 26–30 after the second" in text  # fmt: skip
