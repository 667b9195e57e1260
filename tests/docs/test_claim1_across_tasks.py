"""docs/experiments/claim1_across_tasks.py: the pre-registered analysis of claim 1 across tasks
(docs/experiments/claim1-across-tasks.md), on made-up run folders whose answers are known: equal
arms give Δ = 0, AdaRL at SAC + 0.2 of SAC's gap gives Δ = 0.2, a lower worst case reads
"contradicted". Independent computations: SciPy's one-sample t test, Holm and the normalisation
by hand."""

import csv
import importlib.util
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import stats as st

EXPERIMENTS = Path(__file__).parents[2] / "docs/experiments"
TASKS = (  # written here again: the design's ten
    "InvertedPendulum-v5", "Reacher-v5", "Swimmer-v5", "hopper", "HalfCheetah-v5", "walker2d",
    "Pusher-v5", "ant", "humanoid", "InvertedDoublePendulum-v5",
)  # fmt: skip
PAPER = ("hopper", "walker2d", "ant", "humanoid")
CUT_STEPS = (20_950, 40_950, 60_950, 80_950)
ALGO = {"adarl": ("adarl", "cumulative"), "sac": ("sac", None), "control": ("adarl-control", "cumulative"),
        "fixed": ("sac-fixed-rank", None), "energy": ("adarl", "energy")}  # fmt: skip


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location("claim1_across_tasks", EXPERIMENTS / "claim1_across_tasks.py")  # fmt: skip
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _grid_name(task):
    if task in PAPER:
        return "suite-paper.csv"
    return "sweep-mass_scale-0.5-1.5-5_sweep-friction_scale-0.5-1.5-5.csv"


def _run(root, task, arm, seed, nominal, grid, random=10.0, total_steps=100_000, cuts=4,
         points=25, episodes=10, done=True):  # fmt: skip
    """A finished one-seed run: nominal evaluations at 90k and 100k return `nominal` ± 1 (earlier
    ones −1e6); its grid's point j returns grid[j] ± 1 over `episodes` episodes (grid: a list of
    `points` values, or one value for every point); training episodes within 5,000 steps return
    `random` ± 2."""
    algo, rule = ALGO[arm]
    label = algo + (f"_rank_rule-{rule}" if rule else "")
    run = root / task / label / f"seeds-{seed}"
    (run / "evaluations").mkdir(parents=True)
    config = {"algo": algo, "task": task, "dynamics": "paper", "seeds": [seed], "total_steps": total_steps,
              "hidden": [64, 64], "start_steps": 5000, "format_version": 1}  # fmt: skip
    if rule:
        config.update(rank_rule=rule, truncate_every=20_000, beta=0.98)
    (run / "config.yaml").write_text(yaml.safe_dump(config))
    if rule:
        with (run / "truncations.csv").open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["step", "seed", "layer", "old_rank", "proposed_rank", "new_rank"])
            for step, old, new in list(zip(CUT_STEPS, (64, 40, 30, 25), (40, 30, 25, 20), strict=True))[:cuts]:  # fmt: skip
                for layer in ("actor_1", "q1_1", "q2_1"):
                    w.writerow([step, seed, layer, old, new, new])
    with (run / "eval.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "seed", "dynamics", "episode", "return", "length"])
        for step in range(10_000, total_steps + 1, 10_000):
            value = nominal if step > 80_000 else -1e6
            for episode, noise in enumerate((-1.0, 1.0)):
                w.writerow([step, seed, "nominal", episode, value + noise, 1000])
    with (run / "episodes.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "seed", "episode", "return", "length"])
        for i, (step, value) in enumerate(((2_500, random - 2), (5_000, random + 2), (5_001, 1e6))):
            w.writerow([step, seed, i, value, 100])
    grid = [grid] * points if np.isscalar(grid) else list(grid)
    with (run / "evaluations" / _grid_name(task)).open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "seed", "dynamics", "episode", "return", "length"])
        for j, value in enumerate(grid):
            for episode in range(episodes):
                w.writerow([total_steps, seed, f"point-{j}", episode, value + (1 if episode % 2 else -1), 100])  # fmt: skip
    if done:
        (run / "DONE").write_text(f"{total_steps}\n")
    return run


def _design(root, score_of, arms=("adarl", "sac"), seeds=range(15), tasks=TASKS, **kw):
    """Every task × arm × seed; score_of(task, arm, seed) -> (nominal, grid)."""
    for task in tasks:
        for arm in arms:
            for seed in seeds:
                nominal, grid = score_of(task, arm, seed)
                _run(root, task, arm, seed, nominal, grid, **kw)


def test_equal_arms_give_delta_0_and_no_rejection(script, tmp_path):
    _design(tmp_path, lambda task, arm, seed: (110.0 + seed, 60.0 + seed))
    seeds, running = script.load([tmp_path])
    assert running == [] and len(seeds) == 300 and script.complete(seeds)
    for test in script.primaries(seeds):
        assert test["delta"] == pytest.approx(0.0, abs=1e-12) and test["p"] == 1.0
        assert not test["rejected"]
    text = "\n".join(script.report(seeds))
    assert "every interval excludes ±0.10" in text


def test_adarl_ahead_by_a_fifth_of_sacs_gap_gives_delta_0_2_and_supported(script, tmp_path):
    # random 10, SAC's nominal 10,010 + seed noise averaging to 0: D_t = 10,000 on every task
    # (above every floor); AdaRL +2,000 on every score -> u differs by 0.2 exactly, on every task
    noise = {s: (s - 7) * 300.0 for s in range(15)}  # mean 0 over seeds 0-14

    def score(task, arm, seed):
        up = 2000.0 if arm == "adarl" else 0.0
        return 10_010.0 + noise[seed] + up, [5000.0 + noise[seed] + up + j for j in range(25)]

    _design(tmp_path, score)
    seeds, _ = script.load([tmp_path])
    scale = script.scales(seeds)
    assert scale["random"].to_numpy() == pytest.approx(10.0)
    assert scale["sac"].to_numpy() == pytest.approx(10_010.0)
    assert scale["scale"].to_numpy() == pytest.approx(10_000.0) and not scale["floored"].any()
    used = script.normalise(seeds)
    sac0 = used[(used["arm"] == "sac") & (used["seed"] == 0)].iloc[0]
    assert sac0["u_nominal"] == pytest.approx((10_010 - 2100 - 10) / 10_000)  # by hand
    assert sac0["u_worst"] == pytest.approx((5000 - 2100 - 10) / 10_000)  # the lowest point's mean
    assert sac0["u_average"] == pytest.approx((5000 - 2100 + 12 - 10) / 10_000)  # j = 0..24: 12
    tests = script.primaries(seeds)
    for test in tests:
        assert test["delta"] == pytest.approx(0.2) and test["rejected"]
    assert "claim 1 is supported" in script.decision(tests)


def test_the_primary_is_scipys_t_test_over_tasks_and_holm_by_hand(script, tmp_path):
    rng = np.random.default_rng(3)
    effect = dict(zip(TASKS, rng.normal(0.05, 0.1, len(TASKS)), strict=True))
    draws = {(t, a, s): rng.normal(0, 5, 3) for t in TASKS for a in ("adarl", "sac") for s in range(15)}  # fmt: skip

    def score(task, arm, seed):
        e = draws[(task, arm, seed)]
        up = 10_000 * effect[task] if arm == "adarl" else 0.0  # D_t = 10,000: above every floor
        return 10_010 + 100 * e[0] + up, [5000 + 100 * e[1] + up, 9000 + 100 * e[2] + up] + [
            20_000.0
        ] * 23

    _design(tmp_path, score)
    seeds, _ = script.load([tmp_path])
    used = script.normalise(seeds)
    tests = script.primaries(seeds)
    ps = []
    for test, score_name in zip(tests, ("nominal", "worst", "average"), strict=True):
        # independent: per task, means of u by hand from the raw numbers
        d = []
        for task in TASKS:
            g = seeds[seeds["task"] == task]
            r = g["random_return"].mean()
            s = g[g["arm"] == "sac"]["nominal"].mean()
            a = g[g["arm"] == "adarl"][score_name].mean() - g[g["arm"] == "sac"][score_name].mean()
            d.append(a / (s - r))
        ref = st.ttest_1samp(d, 0.0)
        assert test["delta"] == pytest.approx(np.mean(d))
        assert test["p"] == pytest.approx(ref.pvalue)
        low, high = ref.confidence_interval(0.95)
        assert (test["low"], test["high"]) == pytest.approx((low, high))
        ps.append(ref.pvalue)
    order = np.argsort(ps)
    holm = np.empty(3)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (3 - rank) * ps[i]))
        holm[i] = running
    assert [t["holm"] for t in tests] == pytest.approx(list(holm))
    # the fixed-task interval: SE from within-task variances, by hand
    low, high = script.stratified_interval(used, "nominal")
    var = sum(used[(used["task"] == t) & (used["arm"] == a)]["u_nominal"].var(ddof=1) / 15 for t in TASKS for a in ("adarl", "sac"))  # fmt: skip
    half = 1.959964 * np.sqrt(var) / len(TASKS)
    assert (low, high) == pytest.approx(
        (tests[0]["delta"] - half, tests[0]["delta"] + half), rel=1e-5
    )


def test_a_lower_worst_case_reads_contradicted(script, tmp_path):
    def score(task, arm, seed):
        down = -3000.0 if arm == "adarl" else 0.0
        return 10_010.0 + 100 * (seed % 3), [4000.0 + down + 100 * (seed % 5)] * 25

    _design(tmp_path, score)
    seeds, _ = script.load([tmp_path])
    tests = script.primaries(seeds)
    worst = next(t for t in tests if t["score"] == "worst")
    assert worst["delta"] == pytest.approx(-0.3, abs=0.02) and worst["rejected"]
    assert "claim 1 is contradicted" in script.decision(tests)


def test_the_floor_sets_the_scale_where_sac_barely_moves(script, tmp_path):
    _design(tmp_path, lambda task, arm, seed: (12.0, 11.0), tasks=("humanoid",), seeds=range(2))
    seeds, _ = script.load([tmp_path])
    row = script.scales(seeds).loc["humanoid"]
    assert row["floored"] and row["scale"] == pytest.approx(0.05 * (5428.72 - 10.0))


def test_seeds_off_the_design_are_left_out_with_their_reason(script, tmp_path):
    _run(tmp_path, "hopper", "adarl", 0, 100.0, 50.0, total_steps=50_000)
    _run(tmp_path, "hopper", "adarl", 1, 100.0, 50.0, cuts=3)
    _run(tmp_path, "hopper", "sac", 2, 100.0, 50.0, points=24)
    _run(tmp_path, "hopper", "sac", 3, 100.0, 50.0, episodes=9)
    _run(tmp_path, "hopper", "sac", 4, 100.0, 50.0, done=False)
    seeds, running = script.load([tmp_path])
    reasons = dict(zip(seeds["seed"], seeds["excluded"], strict=True))
    assert reasons[0].startswith("budget 50,000")
    assert reasons[1] == "3 truncations, not 4"
    assert reasons[2] == reasons[3] == "no complete robustness grid"
    assert len(running) == 1 and running[0].endswith("seeds-4")


def test_ceiling_and_unlearned_tasks_are_named(script, tmp_path):
    _design(tmp_path, lambda task, arm, seed: (1000.0, 500.0), tasks=("InvertedPendulum-v5",), seeds=range(2))  # fmt: skip
    _design(tmp_path, lambda task, arm, seed: (100.0, 50.0), tasks=("humanoid",), seeds=range(2))
    _design(tmp_path, lambda task, arm, seed: (700.0, 50.0), tasks=("hopper",), seeds=range(2))
    used = script.normalise(script.load([tmp_path])[0])
    assert script.special_tasks(used) == (["InvertedPendulum-v5"], ["humanoid"])


def test_the_sweep_files_are_the_design(script, tmp_path):
    paths = script.write_sweeps(tmp_path)
    assert [p.name for p in paths] == [f"primary-seed-{s}.yaml" for s in range(15)]
    for seed, path in enumerate(paths):
        file = yaml.safe_load(path.read_text())
        assert list(file["tasks"]) == list(TASKS)
        assert file["tasks"]["Reacher-v5"] == {"max_episode_steps": 50}
        assert file["tasks"]["Pusher-v5"] == {"max_episode_steps": 100}
        assert file["algos"] == [{"algo": "adarl", "grid": {"rank_rule": ["cumulative"]}}, {"algo": "sac"}]  # fmt: skip
        assert file["seeds"] == seed and file["seeds_per_unit"] == 1
        assert (file["budget"], file["dynamics"], file["preset"]) == (100_000, "paper", "paper")
        o = file["overrides"]
        assert (o["truncate_every"], o["start_steps"], o["buffer_size"], o["beta"], o["hidden"]) == (20_000, 5_000, 100_000, 0.98, [64, 64])  # fmt: skip
        assert file["evaluation"] == {"eval_every": 10_000, "eval_episodes": 5, "eval_dynamics": ["nominal"]}  # fmt: skip
    committed = EXPERIMENTS / "claim1-across-tasks"
    for path in paths:
        assert (committed / path.name).read_text() == path.read_text()


def test_export_keeps_no_checkpoint_or_policy_and_restore_gives_it_back(script, tmp_path):
    sweep = tmp_path / "sweep"
    run = _run(sweep, "Reacher-v5", "sac", 0, 100.0, 50.0)
    (run / "checkpoints").mkdir()
    (run / "checkpoints" / "step_100000.npz").write_bytes(b"x")
    (run / "policy_seed_0.npz").write_bytes(b"x")
    _run(sweep, "hopper", "sac", 1, 100.0, 50.0, done=False)
    rows = tmp_path / "rows"
    written, left = script.export(sweep, rows)
    assert len(left) == 1 and not any("checkpoint" in str(p) or "policy" in str(p) for p in written)
    again = tmp_path / "again"
    script.restore(again, rows)
    for name in ("eval.csv", "episodes.csv", "config.yaml", "DONE", f"evaluations/{_grid_name('Reacher-v5')}"):  # fmt: skip
        assert (again / run.relative_to(sweep) / name).read_bytes() == (run / name).read_bytes()
    assert not (again / "hopper").exists()


def test_the_power_table_has_type_i_error_at_most_alpha_and_power_rising_with_seeds(script):
    spread = np.array([script.CLAIM2_SPREAD[t] for t in script.TASKS])
    rng = np.random.default_rng(0)
    noise = (rng.standard_normal((2000, 20, 10)), rng.standard_normal((2000, 20, 10)), rng.standard_normal((2000, 10)))  # fmt: skip
    null = script.simulated_p(0.0, np.full(10, 0.3), 0.0, 10, noise, 0.05)
    assert abs(null - 0.05) < 0.015  # equal spreads: the t test's level
    powers = [script.simulated_p(0.15, spread, 0.0, n, noise, 0.0167) for n in (5, 10, 20)]
    assert powers == sorted(powers) and powers[0] < powers[-1]
