"""README.md's front page and docs/results.md (issue 57): the numbers the front page adds to
its sources are recomputed from the committed tables and rows, every number of the front page's
tables is in docs/results.md, and the links of README.md, docs/results.md and
docs/architecture.md lead to files and headings that exist."""

import csv
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).parents[2]
README = ROOT / "README.md"
RESULTS = ROOT / "docs" / "results.md"
ARCHITECTURE = ROOT / "docs" / "architecture.md"
EXPERIMENTS = ROOT / "docs" / "experiments"


def _flat(path):
    return " ".join(path.read_text().split())


def _table1_sds(report):
    rows = list(csv.DictReader((EXPERIMENTS / report / "tables" / "table1.csv").open()))
    return {r["method"]: float(r["std"]) for r in rows}


def _welch_detectable_by_simulation(sd_x, sd_y, guess, n=5, draws=100_000, seed=0):
    """The difference at which Welch's test (SciPy) rejects 80% of normal data sets of n vs n
    seeds at SDs sd_x, sd_y: bisection on simulated power, common random numbers."""
    from scipy import stats

    z1, z2 = np.random.default_rng(seed).standard_normal((2, draws, n))

    def power(d):
        return np.mean(stats.ttest_ind(z1 * sd_x + d, z2 * sd_y, axis=1, equal_var=False).pvalue < 0.05)  # fmt: skip

    low, high = 0.5 * guess, 1.5 * guess
    for _ in range(25):
        mid = (low + high) / 2
        low, high = (mid, high) if power(mid) < 0.8 else (low, mid)
    return (low + high) / 2


def test_the_detectable_differences_at_the_arms_own_sds():
    """Hopper and Walker2d at 100k (SDs from the reports' table1.csv) and Hopper at 3M (the
    per-seed scores of scores-3m.csv): Welch's detectable difference at the arms' own SDs, its
    range with both SDs at the ends of their 4-df 95% intervals, as README and results quote."""
    from scipy import stats

    hopper, walker = _table1_sds("repro-hopper"), _table1_sds("repro-walker2d")
    with (EXPERIMENTS / "paper-schedule-hopper" / "scores-3m.csv").open() as f:
        rows = list(csv.DictReader(f))
    adarl_3m, sac_3m = (np.array([float(r[k]) for r in rows]) for k in ("adarl", "sac"))
    arms = {  # name: (AdaRL's SD, SAC's SD, the quoted detectable difference, its range)
        "Hopper, 100k": (hopper["adarl"], hopper["sac"], "918", "550–2,639"),
        "Walker2d, 100k": (walker["adarl"], walker["sac"], "601", "360–1,727"),
        "Hopper, 3M": (adarl_3m.std(ddof=1), sac_3m.std(ddof=1), "2,174", "1,303–6,248"),
    }
    low4, high4 = np.sqrt(4 / stats.chi2.ppf([0.975, 0.025], 4))
    results, readme = _flat(RESULTS), _flat(README)
    for name, (sd_a, sd_s, detectable, interval) in arms.items():
        d = float(detectable.replace(",", ""))
        assert _welch_detectable_by_simulation(sd_a, sd_s, d) == pytest.approx(d, rel=0.01), name
        low, high = (float(v.replace(",", "")) for v in interval.split("–"))
        assert (d * low4, d * high4) == pytest.approx((low, high), rel=0.01), name
        assert f"| {detectable} ({interval}) |" in results, name
        assert f"| {detectable} |" in readme, name


def test_the_humanoid_sac_seeds_fall_within_96_to_119_steps():
    """results.md: "SAC's five within 96–119" (the mean episode length of each SAC seed's last
    5 nominal evaluations, from the committed rows)."""
    import pandas as pd

    means = []
    for path in sorted((EXPERIMENTS / "table1-ant-humanoid/rows/humanoid/sac").glob("seeds-*-eval.csv.gz")):  # fmt: skip
        rows = pd.read_csv(path)
        rows = rows[(rows["dynamics"] == "nominal") & (rows["step"] > 250_000)]
        assert len(rows) == 25
        means.append(rows["length"].mean())
    assert len(means) == 5 and (round(min(means)), round(max(means))) == (96, 119)
    assert "SAC's five within 96–119" in _flat(RESULTS)


def _front_page_tables():
    """The table rows of README's "Does AdaRL work?" section."""
    text = README.read_text()
    section = text[text.index("## Does AdaRL work?") : text.index("## Where to go next")]
    return [line for line in section.splitlines() if line.startswith("| ") and "---" not in line]


def test_every_number_of_the_front_pages_tables_is_in_results():
    rows = _front_page_tables()
    assert len(rows) >= 15  # three tables, a header and at least three rows each
    results = RESULTS.read_text()
    for row in rows:
        for number in re.findall(r"\d[\d,]*(?:\.\d+)?", row):
            assert number in results, (number, row)


def _slug(heading):
    """GitHub's anchor of a Markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


@pytest.mark.parametrize("doc", [README, RESULTS, ARCHITECTURE], ids=lambda p: p.name)
def test_links_lead_to_files_and_headings_that_exist(doc):
    for target in re.findall(r"\]\(([^)\s]+)\)", doc.read_text()):
        if target.startswith(("http://", "https://")):
            continue
        path, _, anchor = target.partition("#")
        file = (doc.parent / path).resolve() if path else doc
        assert file.exists(), f"{doc.name}: {target}"
        if not anchor or file.suffix != ".md":
            continue
        headings = [line.lstrip("#") for line in file.read_text().splitlines() if line.startswith("#")]  # fmt: skip
        assert anchor in map(_slug, headings), f"{doc.name}: {target}"
