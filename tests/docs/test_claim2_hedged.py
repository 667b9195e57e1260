"""docs/experiments/claim2_hedged.py: the pre-registered analysis of claim 2 in its hedged form
(docs/experiments/claim2-hedged.md), on made-up run folders whose answers are known: ranks that
settle exactly on 2·d_a + 1 at one β read "supported" there, constant ranks "refuted", ranks still
falling "not settled". Independent computations: statsmodels' OLS, Holm by hand, the sweep file
against the design written out again here."""

import csv
import importlib.util
from pathlib import Path

import numpy as np
import pytest
import yaml

EXPERIMENTS = Path(__file__).parents[2] / "docs/experiments"
SWEEP = EXPERIMENTS / "claim2-hedged/claim2-hedged.yaml"
CLAIM2_MAIN = EXPERIMENTS / "claim2-across-tasks/claim2-across-tasks.yaml"
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
CUT_STEPS = tuple(10_950 + 10_000 * k for k in range(9))
BETAS = (0.9, 0.95, 0.98)


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location("claim2_hedged", EXPERIMENTS / "claim2_hedged.py")  # fmt: skip
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _settling(final: int, at: int = 4, width: int = 64) -> list[int]:
    """Nine kept ranks that fall from `width` to `final` by cut `at` and stay there."""
    path = np.linspace(width, final, at + 1)[1:].round().astype(int).tolist()
    return path + [final] * (9 - at)


def _decisions(old, new):
    """What the trainer logs: `accepted` where the rank fell, `retained` where Eq. 5 proposed a
    cut (it always does above rank 1) and the clause refused it, `unchanged` at rank 1."""
    out = []
    for o, n in zip(old, new, strict=True):
        out.append("accepted" if n < o else ("unchanged" if o == 1 else "retained"))
    return out


def _run(root, task, beta, seed, actor, critics=None, score=100.0, random=10.0,
         total_steps=100_000, truncate_every=10_000, tolerance=0.1, rule="cumulative",
         width=64, done=True, refused_error=0.2):  # fmt: skip
    """A finished one-seed run: the actor's kept ranks after the 9 cuts are `actor` (a list; an
    int: `_settling(int)`), the critics' `critics` (default: actor + 10 and + 12, capped at the
    width); a refused cut's error `refused_error` (accepted ones 0.05); nominal evaluations at 90k
    and 100k return `score` ± 1 (earlier ones −1e6); training episodes within the first 5,000
    steps `random` ± 2."""
    from adarl.train.sac_family import TRUNCATION_COLUMNS

    actor = _settling(actor, width=width) if isinstance(actor, int) else list(actor)
    critics = critics or ([min(width, a + 10) for a in actor], [min(width, a + 12) for a in actor])
    run = root / task / f"adarl_beta-{beta}" / f"seeds-{seed}"
    run.mkdir(parents=True)
    config = {
        "algo": "adarl", "task": task, "dynamics": "paper", "seeds": [seed],
        "total_steps": total_steps, "hidden": [width, width], "start_steps": 5000,
        "truncate_every": truncate_every, "beta": beta, "rank_rule": rule,
        "retain_tolerance": tolerance, "format_version": 1,
    }  # fmt: skip
    (run / "config.yaml").write_text(yaml.safe_dump(config))
    with (run / "truncations.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(TRUNCATION_COLUMNS)  # the trainer's own columns
        for layer, ranks in (("actor_1", actor), ("q1_1", critics[0]), ("q2_1", critics[1])):
            old = [width, *ranks[:-1]]
            for step, o, n, d in zip(CUT_STEPS, old, ranks, _decisions(old, ranks)):
                candidate = n if d == "accepted" else max(1, o - 2)
                error = 0.05 if d == "accepted" else (refused_error if d == "retained" else 0.0)
                w.writerow([step, seed, layer, o, max(0, candidate - 1), n, candidate, error, d])
    with (run / "eval.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "seed", "dynamics", "episode", "return", "length"])
        for step in range(10_000, total_steps + 1, 10_000):
            value = score if step > 80_000 else -1e6
            for episode, noise in enumerate((-1.0, 1.0)):
                w.writerow([step, seed, "nominal", episode, value + noise, 1000])
    with (run / "episodes.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "seed", "episode", "return", "length"])
        for i, (step, value) in enumerate(((2_500, random - 2), (5_000, random + 2), (5_001, 1e6))):
            w.writerow([step, seed, i, value, 100])
    if done:
        (run / "DONE").write_text(f"{total_steps}\n")
    return run


def _design(root, rank_of, seeds=range(3), betas=BETAS, tasks=tuple(D_A), **kw):
    """Every task × β × seed, the actor's ranks `rank_of(task, beta, seed)`."""
    for task in tasks:
        for beta in betas:
            for seed in seeds:
                _run(root, task, beta, seed, rank_of(task, beta, seed), **kw)


def test_ranks_settling_on_2_da_plus_1_at_one_beta_read_supported_there(script, tmp_path):
    def rank(task, beta, seed):
        return {0.9: 5, 0.95: 2 * D_A[task] + 1, 0.98: 30}[beta]

    _design(tmp_path, rank)
    seeds, running = script.load([tmp_path])
    assert running == [] and len(seeds) == 81 and script.complete(seeds)
    assert seeds["settled"].all() and set(seeds["last_change"]) == {4}
    tests = script.primaries(seeds)
    assert [(t["beta"], t["test"]) for t in tests] == [(b, n) for b in BETAS for n in ("paper", "flat")]  # fmt: skip
    on = [t for t in tests if t["beta"] == 0.95]
    assert float(on[0]["fit"]["slope"]) == pytest.approx(1.0)
    assert float(on[0]["fit"]["intercept"]) == pytest.approx(0.0, abs=1e-9)
    assert (on[0]["p"], on[1]["p"]) == (1.0, 0.0)
    for beta in (0.9, 0.98):  # flat: on no line, no slope
        paper, flat = (t for t in tests if t["beta"] == beta)
        assert (paper["p"], flat["p"]) == (0.0, 1.0)
    kinds = {b: k for b, (k, _) in script.readings(seeds, tests).items()}
    assert kinds == {0.9: "off", 0.95: "consistent", 0.98: "off"}
    text = "\n".join(script.report(seeds))
    assert "- decision: **supported** at β = 0.95: the settled actor rank is consistent with 2·d_a + 1 there" in text  # fmt: skip
    assert "| 0.95 | 27/27 | 9/9 | yes | — | 0 |" in text


def test_constant_settled_ranks_are_refuted(script, tmp_path):
    _design(tmp_path, lambda task, beta, seed: {0.9: 9, 0.95: 17, 0.98: 24}[beta])
    seeds, _ = script.load([tmp_path])
    tests = script.primaries(seeds)
    for beta in BETAS:
        paper, flat = (t for t in tests if t["beta"] == beta)
        assert float(paper["fit"]["slope"]) == pytest.approx(0.0, abs=1e-12)
        assert (paper["rejected"], flat["rejected"]) == (True, False)
    text = "\n".join(script.report(seeds))
    assert text.count("settles off 2·d_a + 1: the line (0, 1) rejected; no dependence on d_a detected") == 3  # fmt: skip
    assert "- decision: **refuted in this design's form**: at every β the actor rank settles off 2·d_a + 1" in text  # fmt: skip
    # the β effect on log rank: exactly log(9/24) and log(17/24)
    effects = script.beta_effects(seeds)
    assert effects[0.9]["effect"] == pytest.approx(np.log(9 / 24))
    assert effects[0.95]["effect"] == pytest.approx(np.log(17 / 24))


def test_settled_and_unsettled_seeds(script, tmp_path):
    """k = 3: a rank that last changed at cut 6 has settled, one that changed at cut 7 has not;
    a task settles with 2 of its 3 seeds settled; a β with one unsettled task is not read."""
    assert script.settled([40, 30, 25, 22, 20, 19, 19, 19, 19])
    assert not script.settled([40, 30, 25, 22, 20, 19, 18, 18, 18])
    assert not script.settled([19, 19, 19]) and not script.settled([20, 19, 19, 19])
    assert script.settled([20, 19, 19, 19, 19])
    assert script.last_change([64, 40, 40], [40, 40, 40]) == 1
    assert script.last_change([64, 64], [64, 64]) == 0
    assert script.margin(["accepted", "retained", "retained", "retained"], [0.05, 0.3, 0.12, 0.2]) == 0.12  # fmt: skip
    assert np.isnan(script.margin(["accepted", "unchanged", "unchanged", "unchanged"], [0.05, 0, 0, 0]))  # fmt: skip

    still = [60, 50, 40, 35, 30, 27, 24, 22, 20]  # changes at every cut

    def rank(task, beta, seed):
        if beta == 0.98 and task == "ant" and seed >= 1:
            return still  # ant at 0.98: 1 of 3 settled
        if beta == 0.95 and task == "ant" and seed == 2:
            return still  # 2 of 3: settled
        if beta == 0.9 and task == "hopper" and seed == 0:
            return [64] * 9  # never cut: every proposal refused, settled at the width
        return {0.9: 9, 0.95: 17, 0.98: 24}[beta]

    _design(tmp_path, rank)
    seeds, _ = script.load([tmp_path])
    ant = seeds[(seeds["task"] == "ant") & (seeds["beta"] == 0.98)].sort_values("seed")
    assert list(ant["settled"]) == [True, False, False] and list(ant["last_change"]) == [4, 9, 9]
    assert script.settling(seeds, 0.95)["settles"] and not script.settling(seeds, 0.98)["settles"]
    assert script.settling(seeds, 0.98)["per_task"]["ant"] == (1, 3)
    kinds = {b: k for b, (k, _) in script.readings(seeds).items()}
    assert kinds == {0.9: "off", 0.95: "off", 0.98: "unsettled"}
    text = "\n".join(script.report(seeds))
    assert "- decision: neither supported nor refuted" in text
    assert "| 0.98 | 25/27 | 8/9 | no | ant | 0 |" in text
    assert "| 0.9 | 27/27 | 9/9 | yes | — | 1 |" in text
    never = seeds[(seeds["task"] == "hopper") & (seeds["beta"] == 0.9) & (seeds["seed"] == 0)].iloc[
        0
    ]
    assert (never["settled"], never["last_change"], never["actor"], never["retained"]) == (
        True,
        0,
        64,
        9,
    )
    # refusals logged at the settled rank: margin 0.2 (the made-up refused error)
    settled = seeds[seeds["settled"] & (seeds["last_change"] == 4)]
    assert (settled["margin"] == 0.2).all() and (settled["retained"] == 5).all()


def test_holm_over_the_six_by_hand(script, tmp_path):
    rng = np.random.default_rng(11)
    offsets = {(t, b): rng.normal(0, 4) for t in D_A for b in BETAS}
    _design(tmp_path, lambda task, beta, seed: int(round(12 + 0.6 * (2 * D_A[task] + 1) + offsets[(task, beta)])) + seed % 2)  # fmt: skip
    tests = script.primaries(script.load([tmp_path])[0])
    p = np.array([t["p"] for t in tests])
    assert len(p) == 6 and np.all(np.isfinite(p))
    order = np.argsort(p)
    adjusted = np.maximum.accumulate(np.minimum(1, (6 - np.arange(6)) * p[order]))
    expected = np.empty(6)
    expected[order] = adjusted
    assert [t["holm"] for t in tests] == pytest.approx(expected)
    assert script.holm_rows(p[None, :])[0] == pytest.approx(expected)
    assert [t["rejected"] for t in tests] == list(expected < 0.05)


def test_the_predictor_fits_agree_with_statsmodels(script, tmp_path):
    """One predictor at a time on the task means (slope, interval, p, R²), and a seed's rank on
    its u with task fixed effects."""
    import statsmodels.formula.api as smf

    rng = np.random.default_rng(5)
    draws = {}

    def rank(task, beta, seed):
        draws[(task, beta, seed)] = (int(rng.integers(8, 40)), float(rng.uniform(50, 400)))
        return draws[(task, beta, seed)][0]

    for task in D_A:
        for seed in range(3):
            _run(tmp_path, task, 0.95, seed, rank(task, 0.95, seed), score=draws[(task, 0.95, seed)][1], random=-1000.0)  # fmt: skip
    arm = script.at_beta(script.load([tmp_path])[0], 0.95)
    frame = script.task_predictors(arm)
    assert list(frame["task"]) == list(D_A)
    assert list(frame["log2_obs"]) == pytest.approx(np.log2([4, 10, 8, 11, 17, 17, 23, 105, 348]))
    for name in ("x", "log2_obs", "u"):
        fit = script.predictor_fit(frame[name], frame["actor"])
        ols = smf.ols(f"actor ~ {name}", frame).fit()
        assert fit["slope"] == pytest.approx(ols.params[name])
        assert fit["p"] == pytest.approx(ols.pvalues[name])
        assert fit["r2"] == pytest.approx(ols.rsquared)
        assert list(fit["ci"]) == pytest.approx(list(ols.conf_int().loc[name]))
    within = script.within_task(arm)
    seeds = arm.astype({"actor": float, "normalised": float})
    ols = smf.ols("actor ~ C(task) + normalised", seeds).fit()
    assert within["effect"] == pytest.approx(ols.params["normalised"])
    assert within["p"] == pytest.approx(ols.pvalues["normalised"])


def test_return_random_return_and_learned_as_claim_2(script, tmp_path):
    _run(tmp_path, "hopper", 0.98, 0, 20, score=230.0, random=18.0)  # u = 212 / 2091.8 = 0.101
    _run(tmp_path, "hopper", 0.98, 1, 20, score=220.0, random=18.0)  # u = 0.0966
    seeds, _ = script.load([tmp_path])
    rows = {r["seed"]: r for _, r in seeds.iterrows()}
    assert (rows[0]["return"], rows[0]["random_return"]) == (230.0, 18.0)
    assert rows[0]["normalised"] == pytest.approx(212 / (2109.8 - 18))
    assert rows[0]["learned"] and not rows[1]["learned"]


def test_runs_off_the_design_are_left_out_with_their_reason(script, tmp_path):
    _run(tmp_path, "hopper", 0.98, 0, [40, 30, 25, 22, 20, 19, 19, 19])  # eight cuts
    _run(tmp_path, "hopper", 0.98, 1, 20, truncate_every=20_000)
    _run(tmp_path, "hopper", 0.98, 2, 20, tolerance=None)
    _run(tmp_path, "hopper", 0.98, 3, 20, rule="energy")
    _run(tmp_path, "hopper", 0.98, 4, 20, width=128)
    unfinished = _run(tmp_path, "hopper", 0.98, 5, 20, done=False)
    _run(tmp_path, "hopper", 0.98, 6, 20)
    seeds, running = script.load([tmp_path])
    assert running == [str(unfinished)]
    reasons = dict(zip(seeds["seed"], seeds["excluded"], strict=True))
    assert reasons == {
        0: "8 truncations, not 9",
        1: "schedule 100,000 steps, d_t 20,000, not the design's",
        2: "retain tolerance None, not 0.1",
        3: "rank rule energy, not cumulative",
        4: "width 128, not 64",
        6: "",
    }
    assert list(script.at_beta(seeds, 0.98)["seed"]) == [6]
    text = "\n".join(script.report(seeds, running))
    assert "1 finished seeds in the design, 1 runs still training" in text and "**interim**" in text
    assert "- decision: interim" in text
    # a smoke run of another schedule is read when its schedule is given
    smoke, _ = script.load([tmp_path / "hopper/adarl_beta-0.98/seeds-1"], every=20_000)
    assert list(smoke["excluded"]) == [""]


def test_the_sweep_file_is_the_design(script):
    """Nine tasks, Eq. 5 with the retain clause at 0.1, β 0.9/0.95/0.98, d_t 10k over 100k steps
    (nine cuts), seeds 0-2 one per unit; every other setting is claim 2's main arm's."""
    from adarl.algos import schedule
    from adarl.sweeps import spec

    mine = yaml.safe_load(SWEEP.read_text())
    claim2 = yaml.safe_load(CLAIM2_MAIN.read_text())
    assert list(mine["tasks"]) == list(D_A) == list(script.TASKS)
    assert mine["tasks"] == claim2["tasks"]
    assert mine["algos"] == [{"algo": "adarl", "grid": {"beta": [0.9, 0.95, 0.98]}}]
    assert tuple(mine["algos"][0]["grid"]["beta"]) == script.BETAS
    assert (mine["seeds"], mine["seeds_per_unit"], mine["budget"]) == ("0-2", 1, 100_000)
    for key in ("dynamics", "preset", "evaluation", "budget", "seeds_per_unit"):
        assert mine[key] == claim2[key], key
    changed = {"rank_rule": "cumulative", "retain_tolerance": 0.1, "truncate_every": 10_000}
    assert {k: mine["overrides"][k] for k in changed} == changed
    assert (script.RULE, script.TOLERANCE, script.TRUNCATE_EVERY, script.BUDGET) == ("cumulative", 0.1, 10_000, 100_000)  # fmt: skip
    same = {k: v for k, v in mine["overrides"].items() if k not in changed}
    assert same == {k: v for k, v in claim2["overrides"].items() if k not in ("beta", "truncate_every")}  # fmt: skip
    units = spec.load(str(SWEEP)).units
    assert len(units) == 81 == len({u.id for u in units}) and all(len(u.seeds) == 1 for u in units)
    assert {u.total_steps for u in units} == {100_000}
    assert {(u.task, u.config.beta, u.seeds[0]) for u in units} == {(t, b, s) for t in D_A for b in BETAS for s in range(3)}  # fmt: skip
    for u in units:
        c = u.config
        assert (c.rank_rule, c.retain_tolerance, c.retain_samples, list(c.hidden)) == ("cumulative", 0.1, 1024, [64, 64])  # fmt: skip
        assert schedule.truncation_steps(c) == list(CUT_STEPS)
    assert script.CUTS == len(CUT_STEPS) == 9


def test_the_power_tables_type_one_errors_and_decisions(script):
    lines = script.power_table(sims=3000, seed=3)
    band = 4 * np.sqrt(0.05 * 0.95 / 3000)
    rows = [line for line in lines if "type I" in line]
    assert len(rows) == 2
    for line in rows:
        cells = [float(c) for c in line.strip("|").split("|")[2:] if c.strip()]
        assert all(abs(c - 0.05) < band for c in cells), line
    rng = np.random.default_rng(0)
    x = script.X
    # the paper at every β with almost no task scatter: supported, never refuted
    sure = script.simulate_decisions((x, x, x), 0.01, 0.5, 2000, rng)
    assert sure["supported"] > 0.99 and sure["refuted"] == 0.0
    flat = script.simulate_decisions((np.full(9, 24.0),) * 3, 1.0, 2.0, 2000, rng)
    assert flat["refuted"] > 0.99 and flat["supported"] == 0.0


def test_export_and_command_line(script, tmp_path, capsys, monkeypatch):
    sweep = tmp_path / "sweep"
    _design(sweep, lambda task, beta, seed: {0.9: 9, 0.95: 17, 0.98: 24}[beta], betas=(0.98,))
    _run(sweep, "ant", 0.95, 7, 20, done=False)
    (sweep / "ant/adarl_beta-0.98/seeds-0/checkpoints").mkdir()
    rows = tmp_path / "rows"
    monkeypatch.setattr(script, "ROWS", rows)
    assert script.main(["export", str(sweep)]) == 0
    assert "left " in capsys.readouterr().out
    assert not (rows / "ant/adarl_beta-0.95/seeds-7").exists()
    assert not (rows / "ant/adarl_beta-0.98/seeds-0/checkpoints").exists()
    assert (rows / "ant/adarl_beta-0.98/seeds-0/truncations.csv.gz").is_file()
    columns = ["task", "beta", "seed", "actor", "settled", "margin", "critic", "return"]
    key = ["task", "beta", "seed"]
    a, b = script.load([sweep])[0], script.load([rows])[0]
    assert a[columns].sort_values(key).reset_index(drop=True).equals(b[columns].sort_values(key).reset_index(drop=True))  # fmt: skip
    out = tmp_path / "out"
    assert script.main([str(rows), "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["ranks.pdf", "ranks.png", "report.md"]
    report = (out / "report.md").read_text()
    assert "**interim**" in report
    assert "| hopper | 7 | 0.98 | 3 | 54 | 44 | 34 | 24 | 24 | 24 | 24 | 24 | 24 | 3/3 | 4 | 0.200–0.200 | 12 / 15 |" in report  # fmt: skip
    capsys.readouterr()
    assert script.main([str(tmp_path / "nope")]) == 2
    assert capsys.readouterr().err == f"error: {tmp_path / 'nope'} does not exist\n"
    assert script.main(["power", "--sims", "x"]) == 2
    assert script.main(["export"]) == 2
    assert script.main([]) == 2


def test_the_document_states_the_scripts_design(script):
    """The pre-registration and the script agree on the numbers the decision rests on."""
    doc = (EXPERIMENTS / "claim2-hedged.md").read_text()
    assert "**T = 0.1**" in doc and script.TOLERANCE == 0.1
    assert "**k = 3**" in doc and script.SETTLE_CUTS == 3
    assert "at least 2 of its 3 seeds settled" in doc and script.SETTLED_SEEDS == 2
    assert "**81 units, one seed each**" in doc and "β ∈ {0.9, 0.95, 0.98}" in doc
    assert "**A seed learned when\n  u ≥ 0.1.**" in doc and script.LEARNED_FRACTION == 0.1
