"""Claim 3 with power (docs/experiments/fixed-rank-power.md): the raw rows out of the sweep, the
pre-registered analysis from those rows only, and the power it was planned with.

    python docs/experiments/fixed_rank_power.py export results/fixed-rank-power
    python docs/experiments/fixed_rank_power.py report          # prints the report's tables
    python docs/experiments/fixed_rank_power.py power           # the planning table (9,604 data sets a row)

`export` copies each finished unit's eval.csv and episodes.csv (gzip) to
docs/experiments/fixed-rank-power/rows/hopper/<method>/ (never checkpoints; a unit still training
is named and left for a later export). `report` follows the
pre-registration: a seed's score is the mean of its last 5 nominal evaluations (260k–300k); the
primary tests are rank 7 − rank 64 and rank 13 − rank 64, each the two-sided exact permutation
test of the difference of means (all C(20, 10) = 184,756 splits of 10 vs 10 seeds), Holm over the
two; beside each the interval from inverting that test, Welch's interval and p, the pooled SD,
Welch's detectable difference with its range over the SD's 95% interval, and the seeds that hop
(score above 1,500) with Fisher's and Boschloo's exact tests. Rank 7 − rank 13 is exploratory and
uncorrected. A rank whose units have not reached the budget is reported as running and enters
no test.
"""

from __future__ import annotations

import itertools
import math
import sys
from pathlib import Path

import numpy as np
import table1_ant_humanoid as table1
from table1_ant_humanoid import export, folder, read_gzipped, seed_scores

from adarl import stats
from adarl.report.tables import p_text

HERE = Path(__file__).resolve().parent
ROWS = HERE / "fixed-rank-power" / "rows"
BUDGET = 300_000
TASK = "hopper"
RANKS = (7, 13, 64)
SEEDS = 10
HOP = 1500.0  # a Hopper score above this is a seed that hops (balancing ~1,000, falling ~450)
PRIMARY = ((7, 64), (13, 64))
EXPLORATORY = ((7, 13),)


def method(rank: int) -> str:
    """The sweep's folder name of a rank's units."""
    return f"sac-fixed-rank_rank-{rank}"


def load(rows: Path = ROWS) -> dict[int, dict]:
    """rank -> {"scores": {seed: score}, "last_step"}: the ranks that have rows."""
    out = {}
    for rank in RANKS:
        paths = sorted((rows / TASK / method(rank)).glob("seeds-*-eval.csv.gz"))
        if not paths:
            continue
        scores, last = {}, BUDGET
        for path in paths:
            s, step = seed_scores(read_gzipped(path))
            scores |= s
            last = min(last, step)
        out[rank] = {"scores": scores, "last_step": last}
    return out


def compare(x: np.ndarray, y: np.ndarray) -> dict:
    """x − y: table1_ant_humanoid's comparison (Welch's interval and p, the inverted permutation
    interval, the pooled SD with Welch's detectable difference and its range) with the exact
    permutation p, the primary test here, and the hop counts."""
    c = table1.compare(x, y)
    return c | {
        "welch_p": c["p"],
        "p": stats.permutation_p_value(x, y),
        "counts": stats.counts_exact_test(
            stats.count_above(x, HOP), x.size, stats.count_above(y, HOP), y.size
        ),
    }


def _row(name: str, c: dict, holm_p: str) -> str:
    lo, hi = c["permutation"].low, c["permutation"].high
    w_lo, w_hi = c["welch"]
    r_lo, r_hi = c["range"]
    k = c["counts"]
    return (
        f"| {name} | {c['difference']:+,.0f} | [{lo:+,.0f}, {hi:+,.0f}] | {p_text(c['p'], 4)} | {holm_p} "
        f"| [{w_lo:+,.0f}, {w_hi:+,.0f}] | {p_text(c['welch_p'])} | {c['sd']:,.0f} "
        f"| {c['detectable']:,.0f} ({r_lo:,.0f}–{r_hi:,.0f}) "
        f"| {k.successes_x}/{k.n_x} vs {k.successes_y}/{k.n_y}: {p_text(k.fisher_p)}, {p_text(k.boschloo_p)} |"
    )


def report(data: dict[int, dict]) -> list[str]:
    def finished(rank):
        d = data.get(rank)
        return d is not None and d["last_step"] >= BUDGET and len(d["scores"]) == SEEDS

    lines = ["### Scores (mean of the last 5 nominal evaluations per seed)", ""]
    lines += ["| rank | seeds | last step | mean ± SD | hop | per seed |", "| ---: | ---: | ---: | ---: | ---: | --- |"]  # fmt: skip
    for rank, d in sorted(data.items()):
        v = np.array([d["scores"][s] for s in sorted(d["scores"])])
        state = f"{d['last_step']:,}" + ("" if finished(rank) else " (running)")
        spread = f"{v.mean():,.0f} ± {v.std(ddof=1):,.0f}" if v.size > 1 else "—"
        per_seed = ", ".join(f"{x:,.0f}" for x in v)
        hops = stats.count_above(v, HOP)
        lines.append(f"| {rank} | {v.size} | {state} | {spread} | {hops} | {per_seed} |")
    lines.append("")

    def arm(rank):
        d = data[rank]["scores"]
        return np.array([d[s] for s in sorted(d)])

    head = [
        "| comparison | difference | permutation 95% | permutation p | Holm p | Welch 95% "
        "| Welch p | pooled SD | detectable at 80% (range) | hop: Fisher, Boschloo p |",
        "| --- | ---: | --- | ---: | ---: | --- | ---: | ---: | ---: | --- |",
    ]
    lines += ["### Primary: each lower rank − rank 64 (exact permutation test, Holm over the two)", ""]  # fmt: skip
    if not all(finished(r) for r in RANKS):
        waiting = ", ".join(str(r) for r in RANKS if not finished(r))
        lines += [f"Not computed until every rank's {SEEDS} seeds finish (rank {waiting}: running).", ""]  # fmt: skip
        return lines
    results = [compare(arm(x), arm(y)) for x, y in PRIMARY]
    adjusted = stats.holm([r["p"] for r in results])
    lines += head
    for (x, y), r, a in zip(PRIMARY, results, adjusted, strict=True):
        decision = "**detected**" if a < 0.05 else "not detected"
        lines.append(_row(f"rank {x} − rank {y} ({decision})", r, p_text(a, 4)))
    lines += ["", "### Exploratory, uncorrected", ""] + head
    for x, y in EXPLORATORY:
        lines.append(_row(f"rank {x} − rank {y}", compare(arm(x), arm(y)), "—"))
    lines.append("")
    return lines


# ---------------------------------------------------------------- planning: the power table
HALF_WIDTH = 0.01  # the Monte-Carlo error the power table is to have, at 95%
CHUNK = 32  # data sets whose exact p are computed in one matrix product


def sims_for(half_width: float = HALF_WIDTH, z: float = 1.959964) -> int:
    """Data sets per row so that a simulated power's 95% band, z·√(p(1 − p)/n) (the binomial
    SE), is at most ±half_width whatever p is: its worst case p = 0.5 gives n = ⌈(z/2w)²⌉,
    9,604 for ±0.01."""
    return math.ceil((z / (2.0 * half_width)) ** 2)


def band(power: float, sims: int, z: float = 1.959964) -> float:
    """Half-width of the 95% Monte-Carlo band of a power simulated on `sims` data sets."""
    return z * math.sqrt(power * (1.0 - power) / sims)


def _splits(n_x: int, n_y: int) -> np.ndarray:
    """Every split of n_x + n_y seeds into a first group of n_x, as 0/1 rows (C(20, 10) = 184,756
    at 10 vs 10); the first row is the observed split."""
    first = np.array(list(itertools.combinations(range(n_x + n_y), n_x)), dtype=np.intp)
    indicator = np.zeros((first.shape[0], n_x + n_y))
    np.put_along_axis(indicator, first, 1.0, axis=1)
    return indicator


def _exact_ps(indicator: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """`stats.permutation_p_value(x[i], y[i])` for each row i of the (data sets × seeds) arrays
    x and y, over the splits `indicator` (`_splits`) enumerated once by the caller: the null
    difference of means of every split as one matrix product, `stats._two_sided`'s p and tie
    tolerance applied per row."""
    n_x, n_y = x.shape[1], y.shape[1]
    pooled = np.concatenate([x, y], axis=1)
    sums = pooled @ indicator.T
    null = sums / n_x - (pooled.sum(axis=1, keepdims=True) - sums) / n_y
    observed = (x.mean(axis=1) - y.mean(axis=1))[:, None]
    scale = np.maximum(np.abs(observed), np.abs(null).max(axis=1, keepdims=True))
    tol = 1e-12 * np.maximum(scale, 1e-300)
    less = np.mean(null <= observed + tol, axis=1)
    greater = np.mean(null >= observed - tol, axis=1)
    return np.minimum(1.0, 2.0 * np.minimum(less, greater))


def _permutation_power(draw, sims: int, alphas: tuple, rng: np.random.Generator) -> list[float]:
    """Rejection rates of the two-sided exact permutation test over `sims` data sets
    (x, y) = draw(rng), drawn one after another, at each level in `alphas`."""
    indicator = _splits(SEEDS, SEEDS)
    rejections = np.zeros(len(alphas))
    for start in range(0, sims, CHUNK):
        drawn = [draw(rng) for _ in range(min(CHUNK, sims - start))]
        x, y = (np.array(arm, dtype=float) for arm in zip(*drawn, strict=True))
        p = _exact_ps(indicator, x, y)
        rejections += [np.count_nonzero(p < a) for a in alphas]
    return (rejections / sims).tolist()


def power_table(sims: int | None = None, seed: int = 0) -> list[str]:
    """Power of each primary test at 10 vs 10 seeds: normal arms of equal SD (Welch's computed
    power beside the permutation test's simulated one), and two-kind arms where a seed hops
    (score ~ N(2,400, 300)) or not (~ N(700, 300)) with the arms' hop probabilities differing.
    α = 0.05, and 0.025, the level the smaller p of the two faces under Holm. `sims` data sets
    per row (default `sims_for()`, 9,604: a 95% band of at most ±0.01), each simulated power
    with its own band."""
    sims = sims_for() if sims is None else sims
    rng = np.random.default_rng(seed)
    alphas = (0.05, 0.025)
    lines = [
        "| arms | true difference | permutation power, α 0.05 / 0.025 (95% band) "
        "| Welch power, α 0.05 / 0.025 |",
        "| --- | ---: | ---: | ---: |",
    ]

    def simulated(perm):
        return " / ".join(f"{q:.3f} ± {band(q, sims):.3f}" for q in perm)

    for sd in (600, 900, 1200):
        for factor in (1.0, 1.33):
            delta = round(factor * sd)

            def normal(r, delta=delta, sd=sd):
                return r.normal(delta, sd, SEEDS), r.normal(0.0, sd, SEEDS)

            perm = _permutation_power(normal, sims, alphas, rng)
            welch = [stats.welch_power(delta, sd, sd, SEEDS, SEEDS, a) for a in alphas]
            lines.append(
                f"| normal, SD {sd:,} | {delta:,} | {simulated(perm)} "
                f"| {welch[0]:.3f} / {welch[1]:.3f} |"
            )
    for h_x, h_y in ((0.6, 0.2), (0.7, 0.2), (0.8, 0.2)):

        def two_kinds(r, h_x=h_x, h_y=h_y):
            def arm(h):
                hops = r.random(SEEDS) < h
                return np.where(hops, r.normal(2400.0, 300.0, SEEDS), r.normal(700.0, 300.0, SEEDS))

            return arm(h_x), arm(h_y)

        perm = _permutation_power(two_kinds, sims, alphas, rng)
        delta = (h_x - h_y) * 1700.0
        lines.append(f"| hop with p {h_x} vs {h_y} | {delta:,.0f} | {simulated(perm)} | — |")
    lines += ["", f"({sims:,} simulated data sets per row, seed {seed}.)"]
    return lines


def main(argv: list[str]) -> int:
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__)
        return 0
    if argv[:1] == ["export"] and len(argv) == 2:
        written, left = export(folder(argv[1]), ROWS)
        print(f"wrote {len(written)} files under {ROWS}")
        for unit in left:
            print(f"left {unit}: still training (no DONE)")
        return 0
    if argv[:1] == ["report"] and len(argv) in (1, 2):
        print("\n".join(report(load(folder(argv[1]) if len(argv) == 2 else ROWS))))
        return 0
    if argv == ["power"]:
        print("\n".join(power_table()))
        return 0
    print("usage: fixed_rank_power.py export SWEEP | report [ROWS] | power", file=sys.stderr)
    return 2


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
