"""docs/experiments/claim2_across_tasks.py: the pre-registered analysis of claim 2 across tasks
(docs/experiments/claim2-across-tasks.md), on made-up run folders whose answers are known: ranks
made exactly 2·d_a + 1 give slope 1, constant ranks slope 0, a doubling with the width w = log 2.
Independent computations: statsmodels' OLS and mixed model, the noncentral t, Holm by hand."""

import csv
import importlib.util
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import stats as st

EXPERIMENTS = Path(__file__).parents[2] / "docs/experiments"
FILES = EXPERIMENTS / "claim2-across-tasks"
D_A = {  # Gymnasium's action sizes, written here again
    "InvertedPendulum-v5": 1,
    "Reacher-v5": 2,
    "Swimmer-v5": 2,
    "hopper": 3,
    "HalfCheetah-v5": 6,
    "walker2d": 6,
    "Pusher-v5": 7,
    "ant": 8,
    "humanoid": 17,
}
CUT_STEPS = (20_950, 40_950, 60_950, 80_950)


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location("claim2_across_tasks", EXPERIMENTS / "claim2_across_tasks.py")  # fmt: skip
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run(root, task, rule, seed, actor, critics=None, beta=0.98, width=64, score=100.0,
         random=10.0, total_steps=100_000, truncate_every=20_000, done=True):  # fmt: skip
    """A finished run of one seed: its actor's kept ranks after the cuts are `actor` (a list, one
    per cut; an int: the same after every cut), the critics' `critics` (default: actor + 10 and
    actor + 12); the nominal evaluations at 90k and 100k return `score` ± 1 (the earlier ones
    −1e6), the training episodes within the first 5,000 steps `random` ± 2, the later ones 1e6."""
    actor = [actor] * 4 if isinstance(actor, int) else list(actor)
    critics = critics or ([a + 10 for a in actor], [a + 12 for a in actor])
    label = f"adarl_rank_rule-{rule}" + ("" if (beta, width) == (0.98, 64) else f"_beta-{beta}_w-{width}")  # fmt: skip
    run = root / task / label / f"seeds-{seed}"
    run.mkdir(parents=True)
    config = {
        "algo": "adarl", "task": task, "dynamics": "paper", "seeds": [seed],
        "total_steps": total_steps, "hidden": [width, width], "start_steps": 5000,
        "truncate_every": truncate_every, "beta": beta, "rank_rule": rule, "format_version": 1,
    }  # fmt: skip
    (run / "config.yaml").write_text(yaml.safe_dump(config))
    with (run / "truncations.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "seed", "layer", "old_rank", "proposed_rank", "new_rank"])
        for layer, ranks in (("actor_1", actor), ("q1_1", critics[0]), ("q2_1", critics[1])):
            for step, old, new in zip(CUT_STEPS, [width, *ranks], ranks):
                w.writerow([step, seed, layer, old, new, new])
    with (run / "eval.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "seed", "dynamics", "episode", "return", "length"])
        for step in range(10_000, total_steps + 1, 10_000):
            value = score if step > 80_000 else -1e6
            for episode, noise in enumerate((-1.0, 1.0)):
                w.writerow([step, seed, "nominal", episode, value + noise, 1000])
            w.writerow([step, seed, "fixed:mass_scale=2", 0, 1e9, 1000])  # not nominal
    with (run / "episodes.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "seed", "episode", "return", "length"])
        for i, (step, value) in enumerate(((2_500, random - 2), (5_000, random + 2), (5_001, 1e6))):
            w.writerow([step, seed, i, value, 100])
    if done:
        (run / "DONE").write_text(f"{total_steps}\n")
    return run


def _design(root, rank_of, seeds=range(5), rules=("cumulative", "energy"), tasks=tuple(D_A), **kw):
    """The main arm: every task × rule × seed, the actor's ranks `rank_of(task, rule, seed)`."""
    for task in tasks:
        for rule in rules:
            for seed in seeds:
                _run(root, task, rule, seed, rank_of(task, rule, seed), **kw)


def _arm(root, rank_of, rules=("cumulative", "energy"), **kw):
    """The width and β arm's three cells other than (64, 0.98), seeds 0-2."""
    for task in ("InvertedPendulum-v5", "walker2d"):
        for rule in rules:
            for width, beta in ((64, 0.9), (128, 0.98), (128, 0.9)):
                for seed in range(3):
                    _run(root, task, rule, seed, rank_of(task, rule, width, beta, seed), beta=beta, width=width, **kw)  # fmt: skip


def test_ranks_made_exactly_2_da_plus_1_give_slope_1_and_keep_the_papers_line(script, tmp_path):
    _design(tmp_path, lambda task, rule, seed: [40, 30, 20, 2 * D_A[task] + 1])
    _arm(tmp_path, lambda task, rule, width, beta, seed: 2 * D_A[task] + 1)
    seeds, running = script.load([tmp_path])
    assert running == [] and len(seeds) == 90 + 36 and script.complete(seeds)
    tests = script.primaries(seeds)
    for rule in ("cumulative", "energy"):
        paper, flat, width = (t for t in tests if t["rule"] == rule)
        assert float(paper["fit"]["slope"]) == pytest.approx(1.0)
        assert float(paper["fit"]["intercept"]) == pytest.approx(0.0, abs=1e-9)
        assert (paper["p"], flat["p"]) == (1.0, 0.0)  # on the line: nothing left, nothing flat
        assert width["fit"]["effect"] == pytest.approx(0.0, abs=1e-12) and width["p"] == 1.0
    text = "\n".join(script.report(seeds))
    assert text.count("consistent with 2·d_a + 1: slope 0 is rejected, the line (0, 1) is not; the width effect is not detected") == 2  # fmt: skip


def test_constant_ranks_give_slope_0_and_reject_the_papers_line(script, tmp_path):
    _design(tmp_path, lambda task, rule, seed: [40, 30, 27, 24])
    _arm(tmp_path, lambda task, rule, width, beta, seed: round(24 * width / 64))  # follows width
    seeds, _ = script.load([tmp_path])
    tests = script.primaries(seeds)
    for rule in ("cumulative", "energy"):
        paper, flat, width = (t for t in tests if t["rule"] == rule)
        assert float(paper["fit"]["slope"]) == pytest.approx(0.0, abs=1e-12)
        assert float(paper["fit"]["intercept"]) == pytest.approx(24.0)
        assert (paper["p"], flat["p"]) == (0.0, 1.0)
        assert width["fit"]["effect"] == pytest.approx(np.log(2)) and width["p"] == 0.0
    text = "\n".join(script.report(seeds))
    assert text.count("does not follow 2·d_a + 1: the line (0, 1) is rejected and no dependence on d_a was detected; the width effect is **detected**") == 2  # fmt: skip


def test_a_known_line_with_seed_noise_that_cancels_in_each_task(script, tmp_path):
    """rank = 10 + d_a + (−2, −1, 0, 1, 2)[seed]: task means exactly 10 + (x − 1)/2, so slope 0.5
    and intercept 9.5 with no residual: both tests reject."""
    _design(tmp_path, lambda task, rule, seed: 10 + D_A[task] + (seed - 2), rules=("cumulative",))
    seeds, _ = script.load([tmp_path])
    tests = script.primaries(seeds)
    paper, flat, _width = tests[:3]
    assert float(paper["fit"]["slope"]) == pytest.approx(0.5)
    assert float(paper["fit"]["intercept"]) == pytest.approx(9.5)
    assert (paper["p"], flat["p"]) == (0.0, 0.0)
    assert script.decision(True, True).startswith("depends on d_a, but not as 2·d_a + 1")
    assert not script.complete(seeds)  # the arm is missing
    assert "**interim**" in "\n".join(script.report(seeds))


def test_line_tests_agree_with_statsmodels(script):
    """Slope, intercept, their SEs and the slope-0 p from statsmodels' OLS; the F test of
    (a, b) = (0, 1) from the restricted and full residual sums of squares."""
    import statsmodels.api as sm

    rng = np.random.default_rng(3)
    x = np.array([2 * d + 1 for d in D_A.values()], float)
    for y in (24 + rng.normal(0, 3, x.size), 0.8 * x + rng.normal(0, 2, x.size), x + rng.normal(0, 0.5, x.size)):  # fmt: skip
        fit = script.line_tests(x, y)
        ols = sm.OLS(y, sm.add_constant(x)).fit()
        assert (float(fit["intercept"]), float(fit["slope"])) == pytest.approx(tuple(ols.params))
        assert (float(fit["se_intercept"]), float(fit["se_slope"])) == pytest.approx(tuple(ols.bse))
        assert float(fit["p_flat"]) == pytest.approx(ols.pvalues[1])
        assert [float(v) for v in fit["slope_ci"]] == pytest.approx(list(ols.conf_int()[1]))
        rss, rss_paper = ols.ssr, ((y - x) ** 2).sum()
        f = (rss_paper - rss) / 2 / (rss / (x.size - 2))
        assert float(fit["f_paper"]) == pytest.approx(f)
        assert float(fit["p_paper"]) == pytest.approx(st.f.sf(f, 2, x.size - 2))
        assert float(fit["p_paper"]) == pytest.approx(ols.f_test((np.eye(2), [0.0, 1.0])).pvalue)
    batch = np.stack([24 + rng.normal(0, 3, x.size) for _ in range(4)])  # vectorised = one by one
    assert script.line_tests(x, batch)["p_flat"] == pytest.approx([float(script.line_tests(x, y)["p_flat"]) for y in batch])  # fmt: skip


def test_the_fit_on_task_means_is_the_mixed_models(script, tmp_path):
    """Seeds nested in tasks, 5 per task: statsmodels' random-intercept model (REML) on the seeds
    gives the slope and its standard error of the OLS fit on the task means."""
    import statsmodels.formula.api as smf

    rng = np.random.default_rng(7)
    offsets = dict(zip(D_A, rng.normal(0, 3, len(D_A))))
    _design(tmp_path, lambda task, rule, seed: int(round(20 + 0.3 * (2 * D_A[task] + 1) + offsets[task] + rng.normal(0, 2))), rules=("cumulative",))  # fmt: skip
    seeds, _ = script.load([tmp_path])
    arm = script.main_arm(seeds, "cumulative")
    x, y, tasks = script.task_means(arm, "actor")
    assert tasks == list(D_A)
    fit = script.line_tests(x, y)
    frame = arm[["task", "x", "actor"]].astype({"actor": float, "x": float})
    mixed = smf.mixedlm("actor ~ x", frame, groups=frame["task"]).fit(reml=True)
    assert float(fit["slope"]) == pytest.approx(mixed.params["x"], rel=1e-6)
    assert float(fit["se_slope"]) == pytest.approx(mixed.bse["x"], rel=1e-3)


def test_holm_over_the_six_primaries(script, tmp_path):
    rng = np.random.default_rng(11)
    offsets = {task: rng.normal(0, 4) for task in D_A}
    _design(tmp_path, lambda task, rule, seed: int(round(22 + 0.2 * (2 * D_A[task] + 1) + offsets[task])) + seed % 2)  # fmt: skip
    _arm(tmp_path, lambda task, rule, width, beta, seed: 20 + seed + (width == 128) * (seed == 1))
    tests = script.primaries(script.load([tmp_path])[0])
    p = np.array([t["p"] for t in tests])
    assert len(p) == 6 and np.all(np.isfinite(p))
    order = np.argsort(p)
    adjusted = np.maximum.accumulate(np.minimum(1, (6 - np.arange(6)) * p[order]))
    expected = np.empty(6)
    expected[order] = adjusted
    assert [t["holm"] for t in tests] == pytest.approx(expected)
    assert [t["rejected"] for t in tests] == list(expected < 0.05)


def test_width_effect_agrees_with_statsmodels(script, tmp_path):
    """log rank on cell dummies (task × β) and the width indicator, by statsmodels' OLS."""
    import statsmodels.formula.api as smf

    rng = np.random.default_rng(5)
    draw = {}

    def rank(task, rule, width, beta, seed):
        draw[(task, rule, width, beta, seed)] = int(rng.integers(15, 40)) * (1 + (width == 128))
        return draw[(task, rule, width, beta, seed)]

    _design(tmp_path, lambda task, rule, seed: rank(task, rule, 64, 0.98, seed), rules=("energy",), tasks=("InvertedPendulum-v5", "walker2d"))  # fmt: skip
    _arm(tmp_path, rank, rules=("energy",))
    arm = script.width_arm(script.load([tmp_path])[0], "energy")
    assert len(arm) == 2 * (5 + 3 * 3)
    frame = arm.assign(cell=arm["task"] + arm["beta"].astype(str), wide=(arm["width"] == 128).astype(float), log_rank=np.log(arm["actor"].astype(float)))  # fmt: skip
    ols = smf.ols("log_rank ~ C(cell) + wide", frame).fit()
    effect = script.width_effect(arm)
    assert effect["effect"] == pytest.approx(ols.params["wide"])
    assert effect["p"] == pytest.approx(ols.pvalues["wide"])
    assert list(effect["ci"]) == pytest.approx(list(ols.conf_int().loc["wide"]))
    beta = script.width_effect(arm, factor="beta")
    frame = frame.assign(cell=frame["task"] + frame["width"].astype(str), low=np.isclose(frame["beta"], 0.9).astype(float))  # fmt: skip
    assert beta["effect"] == pytest.approx(smf.ols("log_rank ~ C(cell) + low", frame).fit().params["low"])  # fmt: skip


def test_return_random_return_and_learned(script, tmp_path):
    # hopper: u = (score − random) / (2109.8 − random); learned from u ≥ 0.1
    _run(tmp_path, "hopper", "energy", 0, 20, score=230.0, random=18.0)  # u = 212 / 2091.8 = 0.101
    _run(tmp_path, "hopper", "energy", 1, 20, score=220.0, random=18.0)  # u = 0.0966
    _run(tmp_path, "Reacher-v5", "energy", 0, 20, score=-30.0, random=-43.0)  # 13 / 39.25 = 0.33
    seeds, _ = script.load([tmp_path])
    rows = {(r["task"], r["seed"]): r for _, r in seeds.iterrows()}
    hopper = rows[("hopper", 0)]
    # the mean of the evaluations after the last cut (90k and 100k), each the mean of its two
    # episodes; the random phase's mean over the episodes that ended by step 5,000
    assert (hopper["return"], hopper["random_return"]) == (230.0, 18.0)
    assert hopper["normalised"] == pytest.approx(212 / (2109.8 - 18))
    assert hopper["learned"] and not rows[("hopper", 1)]["learned"]
    assert rows[("Reacher-v5", 0)]["normalised"] == pytest.approx(13 / (43 - 3.75))
    assert script.normalised("Pusher-v5", 1.0, 5.0) != script.normalised("Pusher-v5", 1.0, 5.0)  # NaN: reference not above random  # fmt: skip


def test_runs_off_the_design_are_left_out_and_running_ones_named(script, tmp_path):
    _run(tmp_path, "hopper", "energy", 0, [40, 30, 20])  # three cuts
    _run(tmp_path, "hopper", "energy", 1, 20, total_steps=50_000)  # another budget
    unfinished = _run(tmp_path, "hopper", "energy", 2, 20, done=False)
    _run(tmp_path, "hopper", "energy", 3, 20)
    seeds, running = script.load([tmp_path])
    assert running == [str(unfinished)]
    reasons = dict(zip(seeds["seed"], seeds["excluded"], strict=True))
    assert reasons == {0: "3 truncations, not 4", 1: "schedule 50,000 steps, d_t 20,000, not the design's", 3: ""}  # fmt: skip
    assert list(script.main_arm(seeds, "energy")["seed"]) == [3]
    text = "\n".join(script.report(seeds, running))
    assert "1 finished seeds in the design, 1 runs still training" in text
    assert "seed 0: 3 truncations, not 4" in text


def test_the_task_bootstrap_drops_draws_without_spread(script, tmp_path):
    """Three tasks with x = 3, 5, 5 on an exact line: every draw with two x values has slope 1;
    draws of one x (probability (1/3)³ + (2/3)³ = 1/3) are dropped."""
    for task in ("InvertedPendulum-v5", "Reacher-v5", "Swimmer-v5"):
        for seed in range(5):
            _run(tmp_path, task, "energy", seed, 2 * D_A[task] + 1)
    arm = script.main_arm(script.load([tmp_path])[0], "energy")
    low, high, dropped = script.bootstrap_slope(arm, "actor", reps=3000, seed=1)
    assert (low, high) == pytest.approx((1.0, 1.0))
    assert abs(dropped - 1000) < 4 * np.sqrt(3000 * (1 / 3) * (2 / 3))


def test_leaving_out_the_task_off_the_line(script, tmp_path):
    _design(tmp_path, lambda task, rule, seed: 2 * D_A[task] + 1 + (20 if task == "humanoid" else 0), rules=("energy",))  # fmt: skip
    loo = script.leave_one_out(script.main_arm(script.load([tmp_path])[0], "energy"), "actor")
    assert loo["humanoid"] == pytest.approx(1.0)
    assert all(v > 1.0 for t, v in loo.items() if t != "humanoid")


def test_the_slope_tests_power_is_the_noncentral_t(script):
    """On normal task means (no rounding), the share of rejections of slope 0 is the noncentral
    t's power, λ = b·√Sxx / s, K − 2 degrees of freedom."""
    x = script.DESIGN_X
    rng = np.random.default_rng(2)
    b, s, sims = 0.15, 2.0, 40_000
    y = 20 + b * x + rng.normal(0, s, (sims, x.size))
    simulated = np.mean(script.line_tests(x, y)["p_flat"] < 0.05)
    df = x.size - 2
    lam = b * np.sqrt(((x - x.mean()) ** 2).sum()) / s
    crit = st.t.ppf(0.975, df)
    exact = st.nct.sf(crit, df, lam) + st.nct.cdf(-crit, df, lam)
    assert simulated == pytest.approx(exact, abs=4 * np.sqrt(exact * (1 - exact) / sims))


def test_the_power_table_keeps_its_type_one_errors(script):
    lines = script.power_table(sims=4000, seed=3)
    band = 4 * np.sqrt(0.05 * 0.95 / 4000)
    for line in lines:
        if "type I" in line:
            cells = [float(c) for c in line.strip("|").split("|")[2:] if c.strip()]
            assert all(abs(c - 0.05) < band for c in cells), line


def test_export_and_command_line(script, tmp_path, capsys, monkeypatch):
    sweep = tmp_path / "sweep"
    _design(sweep, lambda task, rule, seed: [40, 33, 28, 24], rules=("energy",))
    _arm(sweep, lambda task, rule, width, beta, seed: round(24 * width / 64 * (1.5 if beta == 0.9 else 1)), rules=("energy",))  # fmt: skip
    _run(sweep, "ant", "energy", 7, 20, done=False)
    (sweep / "ant/adarl_rank_rule-energy/seeds-0/checkpoints").mkdir()
    rows = tmp_path / "rows"
    monkeypatch.setattr(script, "ROWS", rows)
    assert script.main(["export", str(sweep)]) == 0
    assert "left " in capsys.readouterr().out
    assert not (rows / "ant/adarl_rank_rule-energy/seeds-7").exists()
    assert not (rows / "ant/adarl_rank_rule-energy/seeds-0/checkpoints").exists()
    assert (rows / "ant/adarl_rank_rule-energy/seeds-0/truncations.csv.gz").is_file()
    from_sweep, from_rows = script.load([sweep])[0], script.load([rows])[0]
    columns = ["task", "rule", "beta", "width", "seed", "actor", "critic", "return", "random_return"]  # fmt: skip
    key = ["task", "rule", "beta", "width", "seed"]
    assert from_sweep[columns].sort_values(key).reset_index(drop=True).equals(from_rows[columns].sort_values(key).reset_index(drop=True))  # fmt: skip
    out = tmp_path / "out"
    assert script.main([str(rows), "--out", str(out)]) == 0
    written = sorted(p.name for p in out.iterdir())
    assert written == ["ranks.pdf", "ranks.png", "report.md", "width-beta.pdf", "width-beta.png"]
    report = (out / "report.md").read_text()
    assert "**interim**" in report  # the Eq. 5 seeds are missing
    assert "| energy | width 128 vs 64 | +0.693 | [+0.693, +0.693] | 2.00 | < 0.001 | primary |" in report  # fmt: skip
    assert "| energy | β 0.9 vs 0.98 | +0.405 | [+0.405, +0.405] | 1.50 | < 0.001 | secondary |" in report  # fmt: skip
    assert "| hopper | 7 | energy | actor_1 | 5 | 40 | 33 | 28 | 24 |" in report
    capsys.readouterr()
    assert script.main([str(tmp_path / "nope")]) == 2
    assert capsys.readouterr().err == f"error: {tmp_path / 'nope'} does not exist\n"
    assert script.main(["power", "--sims", "x"]) == 2
    assert script.main(["export"]) == 2
    assert script.main([]) == 2


def test_a_task_outside_the_design_is_one_line(script):
    from adarl.errors import UsageError

    assert script.canonical("INVERTEDPENDULUM-V5") == "InvertedPendulum-v5"
    with pytest.raises(UsageError, match="task 'Acrobot-v1' is not one of this experiment's: InvertedPendulum-v5, "):  # fmt: skip
        script.canonical("Acrobot-v1")


def test_the_sweep_files_are_the_design(script):
    """The two sweep files list the design's tasks, rules, cells, seeds and schedule, and share
    every setting but their tasks, algorithms and seeds (written out again here)."""
    main = yaml.safe_load((FILES / "claim2-across-tasks.yaml").read_text())
    arm = yaml.safe_load((FILES / "width-beta.yaml").read_text())
    assert list(main["tasks"]) == list(D_A) == list(script.TASKS)
    assert list(arm["tasks"]) == ["InvertedPendulum-v5", "walker2d"] == list(script.ARM_TASKS)
    assert main["tasks"]["Reacher-v5"] == {"max_episode_steps": 50} and main["tasks"]["Pusher-v5"] == {"max_episode_steps": 100}  # fmt: skip
    for key in set(main) | set(arm):
        if key not in ("tasks", "algos", "seeds", "description"):
            assert main[key] == arm[key], key
    assert (main["budget"], main["overrides"]["truncate_every"]) == (100_000, 20_000) == (script.BUDGET, script.TRUNCATE_EVERY)  # fmt: skip
    assert main["seeds_per_unit"] == 1 and (main["seeds"], arm["seeds"]) == ("0-4", "0-2")
    assert main["algos"] == [{"algo": "adarl", "grid": {"rank_rule": ["cumulative", "energy"]}}]
    assert (main["overrides"]["beta"], main["overrides"]["hidden"]) == (0.98, [64, 64])
    cells = set()
    for entry in arm["algos"]:
        width = entry.get("hidden", main["overrides"]["hidden"])[0]
        for rule in entry["grid"]["rank_rule"]:
            cells |= {(rule, width, beta) for beta in entry["grid"]["beta"]}
    assert cells == {(r, w, b) for r in ("cumulative", "energy") for w, b in ((64, 0.9), (128, 0.98), (128, 0.9))}  # fmt: skip


def test_the_sweep_files_expand_to_126_units_once_every_task_is_known():
    """With the "any task" feature (every Gymnasium MuJoCo id a task), the two files expand to
    90 + 36 units of one seed each; before it, the spec rejects the Gymnasium ids."""
    from adarl.errors import UsageError
    from adarl.sweeps import spec

    try:
        units = [u for name in ("claim2-across-tasks", "width-beta") for u in spec.load(str(FILES / f"{name}.yaml")).units]  # fmt: skip
    except UsageError as exc:
        if "InvertedPendulum-v5" in str(exc) or "Reacher-v5" in str(exc):
            pytest.skip(f"the Gymnasium ids are not tasks yet: {exc}")
        raise
    assert len(units) == 126 and all(len(u.seeds) == 1 for u in units)
    assert len({u.id for u in units}) == 126
    assert {u.total_steps for u in units} == {100_000}


def test_the_committed_report_and_results_are_the_rows_own(script, tmp_path):
    """The committed report.md is what the script computes from the committed raw rows, and the
    doc's Results quote its primaries (the decision) as it prints them."""
    out = tmp_path / "out"
    assert script.main([str(FILES / "rows"), "--out", str(out)]) == 0
    report = (out / "report.md").read_text()
    assert report == (FILES / "report.md").read_text()
    assert "126 finished seeds in the design, 0 runs still training" in report
    results = (EXPERIMENTS / "claim2-across-tasks.md").read_text().split("## Results", 1)[1]
    for rule, line, slope, width in (
        ("cumulative", "a = 20.06, F = 28.8", "b = +0.171", "w = +0.623 (elasticity +0.90)"),
        ("energy", "a = 22.87, F = 36.7", "b = +0.165", "w = +0.497 (elasticity +0.72)"),
    ):
        for estimate in (line, slope, width):
            assert f"| {rule} |" in report and estimate in report, estimate
        assert f"- {rule}: does not follow 2·d_a + 1: the line (0, 1) is rejected" in report
    for quoted in ("a = 20.06 [13.58, 26.53], F = 28.8", "b = +0.171 [−0.245, +0.586]",
                   "w = +0.623 [+0.576, +0.670]", "a = 22.87 [16.07, 29.67], F = 36.7",
                   "b = +0.165 [−0.272, +0.601]", "w = +0.497 [+0.436, +0.558]"):  # fmt: skip
        assert quoted in results, quoted


def test_runs_off_the_design_stay_out_of_the_width_effect(script, tmp_path):
    """The arm's design runs by statsmodels' OLS on the ranks drawn here; runs of another
    schedule or with three cuts, whose ranks would reverse the effect, change nothing."""
    import pandas as pd
    import statsmodels.formula.api as smf

    rng = np.random.default_rng(11)
    drawn = []

    def rank(task, rule, width, beta, seed):
        value = int(rng.integers(15, 40)) * (1 + (width == 128))
        drawn.append({"task": task, "width": width, "beta": beta, "rank": value})
        return value

    _design(tmp_path, lambda task, rule, seed: rank(task, rule, 64, 0.98, seed), rules=("energy",), tasks=("InvertedPendulum-v5", "walker2d"))  # fmt: skip
    _arm(tmp_path, rank, rules=("energy",))
    for seed, task, width, ranks, steps in (
        (7, "walker2d", 64, 60, 50_000),  # another budget
        (8, "walker2d", 128, 2, 50_000),
        (9, "InvertedPendulum-v5", 64, [60, 60, 60], 100_000),  # three cuts
        (10, "InvertedPendulum-v5", 128, [2, 2, 2], 100_000),
    ):
        _run(tmp_path, task, "energy", seed, ranks, width=width, total_steps=steps)
    seeds, _ = script.load([tmp_path])
    assert (seeds["excluded"] != "").sum() == 4
    frame = pd.DataFrame(drawn).assign(
        cell=lambda f: f["task"] + f["beta"].astype(str),
        wide=lambda f: (f["width"] == 128).astype(float),
        log_rank=lambda f: np.log(f["rank"].astype(float)),
    )
    assert len(frame) == 2 * (5 + 3 * 3)
    ols = smf.ols("log_rank ~ C(cell) + wide", frame).fit()
    effect = script.width_effect(script.width_arm(seeds, "energy"))
    assert effect["n"] == len(frame)
    assert effect["effect"] == pytest.approx(ols.params["wide"])
    assert effect["p"] == pytest.approx(ols.pvalues["wide"])
    (width,) = (t for t in script.primaries(seeds) if (t["rule"], t["test"]) == ("energy", "width"))
    assert width["fit"]["effect"] == pytest.approx(ols.params["wide"])


def test_a_seed_missing_one_critics_ranks_has_no_critic_rank(script, tmp_path):
    _run(tmp_path, "hopper", "energy", 0, 20, critics=([30] * 4, [34] * 4))
    _run(tmp_path, "hopper", "energy", 1, 20, critics=([30] * 4, []))  # no q2_1 rows
    _run(tmp_path, "hopper", "energy", 2, 20, critics=([], [34] * 4))  # no q1_1 rows
    seeds, _ = script.load([tmp_path])
    critic = dict(zip(seeds["seed"], seeds["critic"], strict=True))
    assert critic[0] == 32.0  # the mean of the two critics' final ranks
    assert np.isnan(critic[1]) and np.isnan(critic[2])  # not one critic's rank alone
    assert list(seeds["actor"]) == [20, 20, 20] and list(seeds["excluded"]) == ["", "", ""]
