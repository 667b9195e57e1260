"""Table 1 on Ant and Humanoid at 300k steps (docs/experiments/table1-ant-humanoid.md): the raw
rows out of the sweep, and the pre-registered analysis from those rows only.

    python docs/experiments/table1_ant_humanoid.py export results/table1-ant-humanoid
    python docs/experiments/table1_ant_humanoid.py report          # prints the report's tables
    python docs/experiments/table1_ant_humanoid.py report --write  # ... into table1-ant-humanoid.md
    python docs/experiments/table1_ant_humanoid.py figure          # the learning curves

`export` copies each finished unit's eval.csv, truncations.csv, episodes.csv and train.csv (gzip)
to docs/experiments/table1-ant-humanoid/rows/<task>/<method>/ (never checkpoints; a unit still
training is left for a later export), so that `report`
and any referee recompute every number from the repository. `report` follows the
pre-registration: the score of a seed is the mean of its last 5 nominal evaluations, each
evaluation the mean return of its episodes; the primary tests are AdaRL − SAC on each task,
Welch's t-test, Holm over the two; beside each the inverted two-sample permutation interval and
Welch's detectable difference at 80% power with its range over the pooled SD's 95% interval;
AdaRL − each baseline (Parseval: the best of three by mean score, chosen after seeing the data;
until all three have finished, the best of those that have, and the table says so) is
exploratory and uncorrected; the ranks the energy rule kept at each cut, against 2·d_a + 1.
A method whose five seeds have not all reached the budget (in one unit of 5 seeds, or in
units of one seed, as the campaign ran them from 2026-12-05) is reported as running and enters
no test. `report --write` puts the tables into the report between its two markers, so that its
numbers are the script's on the committed rows (a test checks they are). `figure`
draws each method's nominal return over training per task (mean over seeds with its 95% t band,
Parseval at its best coefficient) into table1-ant-humanoid/curves.png and .pdf, descriptive.
"""

from __future__ import annotations

import csv
import gzip
import io
import shutil
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy import stats as st

from adarl import stats
from adarl.files import atomic_write_text
from adarl.report.tables import p_text
from adarl.sweeps.estimate import train_seconds

HERE = Path(__file__).resolve().parent
DOC = HERE / "table1-ant-humanoid.md"
BEGIN = "<!-- report: begin (written by `python docs/experiments/table1_ant_humanoid.py report --write`) -->"  # fmt: skip
END = "<!-- report: end -->"
ROWS = HERE / "table1-ant-humanoid" / "rows"
CURVES = HERE / "table1-ant-humanoid" / "curves"  # .png and .pdf
FILES = ("eval.csv", "truncations.csv", "episodes.csv", "train.csv")
BUDGET = 300_000
LAST_K = 5
TIME_LIMIT = 1000  # steps of an Ant or Humanoid episode that neither falls nor flips
TASKS = ("ant", "humanoid")
ACTION_DIM = {"ant": 8, "humanoid": 17}  # 2·d_a + 1: 17 and 35
ADARL, SAC = "adarl", "sac"
SEEDS = [0, 1, 2, 3, 4]
PARSEVAL_COEFS = (1e-3, 1e-4, 1e-5)  # the paper's three, every one run on both tasks


def export(sweep: Path, rows: Path = ROWS) -> tuple[list[Path], list[Path]]:
    """Copy the raw rows of every finished unit of `sweep` (task/method/seeds-*/, with its `DONE`)
    to `rows`, gzipped; a unit still training is left for a later export, so that no partial rows
    are committed. Returns the files written and the units left."""
    written, left = [], []
    for unit in sorted(sweep.glob("*/*/seeds-*")):
        task, method = unit.parts[-3], unit.parts[-2]
        if not (unit / "DONE").is_file():
            left.append(unit)
            continue
        for name in FILES:
            source = unit / name
            if not source.is_file():
                continue
            target = rows / task / method / f"{unit.name}-{name}.gz"
            gzip_copy(source, target)
            written.append(target)
    return written, left


def gzip_copy(source: Path, target: Path) -> None:
    """`source` gzipped into `target` (no timestamp inside: the same rows, the same bytes),
    atomically; its folder is made."""
    target.parent.mkdir(parents=True, exist_ok=True)
    partial = target.with_suffix(".tmp")
    with source.open("rb") as f, gzip.GzipFile(partial, "wb", mtime=0) as g:
        shutil.copyfileobj(f, g)
    partial.replace(target)


def read_gzipped(path: Path) -> list[dict]:
    """The rows of a gzipped CSV (as `export` writes them)."""
    with gzip.open(path, "rt", newline="") as f:
        return list(csv.DictReader(io.StringIO(f.read())))


def seed_scores(eval_rows: list[dict], k: int = LAST_K) -> tuple[dict[int, float], int]:
    """Each seed's score, the mean over its last k nominal evaluations of each evaluation's
    mean episode return, and the last step evaluated."""
    returns = defaultdict(lambda: defaultdict(list))  # seed -> step -> returns
    for r in eval_rows:
        if r["dynamics"] == "nominal":
            returns[int(r["seed"])][int(r["step"])].append(float(r["return"]))
    scores, last = {}, 0
    for seed, by_step in returns.items():
        steps = sorted(by_step)[-k:]
        scores[seed] = float(np.mean([np.mean(by_step[s]) for s in steps]))
        last = max(last, steps[-1])
    return scores, last


def seed_survival(eval_rows: list[dict], k: int = LAST_K) -> dict[int, bool]:
    """Per seed, whether every episode of its last k nominal evaluations lasted the time limit
    (`TIME_LIMIT` steps): the policy neither fell nor flipped."""
    lengths = defaultdict(lambda: defaultdict(list))  # seed -> step -> episode lengths
    for r in eval_rows:
        if r["dynamics"] == "nominal":
            lengths[int(r["seed"])][int(r["step"])].append(int(float(r["length"])))
    return {
        seed: all(min(by_step[s]) >= TIME_LIMIT for s in sorted(by_step)[-k:])
        for seed, by_step in lengths.items()
    }


def load(rows: Path = ROWS) -> dict:
    """task -> method -> {"scores": {seed: score}, "survived": {seed: bool}, "last_step",
    "truncations": rows, "train_s": seconds of training summed over its attempts (train.csv's
    intervals over their rates, `adarl.sweeps.estimate.train_seconds`; None without train.csv),
    "nominal": its nominal evaluation rows}."""
    out = defaultdict(dict)
    for method_dir in sorted(rows.glob("*/*")):
        task, method = method_dir.parts[-2], method_dir.parts[-1]
        scores, survived, last, truncations, train_s = {}, {}, BUDGET, [], None
        nominal = []
        for path in sorted(method_dir.glob("seeds-*-eval.csv.gz")):
            evaluations = read_gzipped(path)
            nominal += [r for r in evaluations if r["dynamics"] == "nominal"]
            s, step = seed_scores(evaluations)
            scores |= s
            survived |= seed_survival(evaluations)
            last = min(last, step)
        for path in sorted(method_dir.glob("seeds-*-truncations.csv.gz")):
            truncations += read_gzipped(path)
        for path in sorted(method_dir.glob("seeds-*-train.csv.gz")):
            train_s = (train_s or 0.0) + train_seconds(read_gzipped(path))[1]
        out[task][method] = {
            "scores": scores,
            "survived": survived,
            "last_step": last,
            "truncations": truncations,
            "train_s": train_s,
            "nominal": nominal,
        }
    return out


def label(method: str) -> str:
    return method.replace("_parseval_coef-", " ").replace("_sparse_width-", " w=")


def compare(x: np.ndarray, y: np.ndarray) -> dict:
    """Welch's interval and p, the inverted permutation interval and Welch's detectable
    difference (with its range over the pooled SD's interval) for the difference x − y."""
    ci = stats.welch_difference_ci(x, y)
    sd = stats.pooled_sd(x, y)
    return {
        "difference": ci.point,
        "welch": (ci.low, ci.high),
        "p": float(st.ttest_ind(x, y, equal_var=False).pvalue),
        "permutation": stats.two_sample_permutation_interval(x, y),
        "sd": sd,
        "detectable": stats.welch_minimum_detectable_difference(sd, sd, len(x), len(y)),
        "range": stats.detectable_difference_range(sd, len(x), len(y)),
    }


def _num(x: float) -> str:
    return ("+∞" if x > 0 else "−∞") if np.isinf(x) else f"{x:+,.0f}"


def comparison_row(name: str, c: dict, extra: str) -> str:
    """A table row of `compare`'s result; `extra` fills the Holm column."""
    lo, hi = c["welch"]
    perm = c["permutation"]
    r_lo, r_hi = c["range"]
    return (
        f"| {name} | {c['difference']:+,.0f} | [{lo:+,.0f}, {hi:+,.0f}] | {p_text(c['p'])} | {extra} "
        f"| [{_num(perm.low)}, {_num(perm.high)}] | {c['sd']:,.0f} "
        f"| {c['detectable']:,.0f} ({r_lo:,.0f}–{r_hi:,.0f}) |"
    )


def report(data: dict) -> list[str]:
    lines = ["### Scores (mean of the last 5 nominal evaluations per seed)", ""]
    lines += ["| task | method | seeds | last step | mean ± SD | per seed | training (h) |", "| --- | --- | ---: | ---: | ---: | --- | ---: |"]  # fmt: skip
    for task in TASKS:
        for method, d in sorted(data.get(task, {}).items()):
            v = np.array([d["scores"][s] for s in sorted(d["scores"])])
            state = f"{d['last_step']:,}" + ("" if is_finished(d) else " (running)")
            per_seed = ", ".join(f"{x:,.0f}" for x in v)
            spread = f"{v.mean():,.0f} ± {v.std(ddof=1):,.0f}" if v.size > 1 else "—"
            hours = "—" if d["train_s"] is None else f"{d['train_s'] / 3600:.1f}"
            lines.append(
                f"| {task} | {label(method)} | {v.size} | {state} | {spread} | {per_seed} | {hours} |"
            )
    lines.append("")

    def finished(task, method):
        return is_finished(data.get(task, {}).get(method))

    def arm(task, method):
        d = data[task][method]["scores"]
        return np.array([d[s] for s in sorted(d)])

    head = [
        "| comparison | difference | Welch 95% | Welch p | Holm p | permutation 95% | pooled SD "
        "| detectable at 80% (range) |",
        "| --- | ---: | --- | ---: | ---: | --- | ---: | ---: |",
    ]
    primary = [t for t in TASKS if finished(t, ADARL) and finished(t, SAC)]
    lines += ["### Primary: AdaRL − SAC (Welch, Holm over the two tasks)", ""]
    if len(primary) < len(TASKS):
        waiting = ", ".join(t for t in TASKS if t not in primary)
        lines += [f"Not computed until both tasks' AdaRL and SAC units finish ({waiting}: running).", ""]  # fmt: skip
    else:
        results = {t: compare(arm(t, ADARL), arm(t, SAC)) for t in TASKS}
        adjusted = stats.holm([results[t]["p"] for t in TASKS])
        lines += head
        for t, a in zip(TASKS, adjusted):
            decision = "**detected**" if a < 0.05 else "not detected"
            lines.append(comparison_row(f"{t}: adarl − sac ({decision})", results[t], p_text(a)))
        lines.append("")

    lines += [
        f"### Descriptive: seeds whose every episode of the last {LAST_K} evaluations lasted "
        f"{TIME_LIMIT:,} steps",
        "",
        "| task | method | seeds that lasted | AdaRL against it: Fisher p, Boschloo p |",
        "| --- | --- | ---: | ---: |",
    ]
    for task in TASKS:
        for method in sorted(m for m in data.get(task, {}) if finished(task, m)):
            kept = data[task][method]["survived"]
            cell = "—"
            if method != ADARL and finished(task, ADARL):
                ours = data[task][ADARL]["survived"]
                test = stats.counts_exact_test(sum(ours.values()), len(ours), sum(kept.values()), len(kept))  # fmt: skip
                cell = f"{p_text(test.fisher_p)}, {p_text(test.boschloo_p)}"
            lines.append(f"| {task} | {label(method)} | {sum(kept.values())}/{len(kept)} | {cell} |")  # fmt: skip
    lines.append("")

    lines += ["### Exploratory, uncorrected: AdaRL − each baseline", ""]
    exploratory = []
    for task in TASKS:
        if not finished(task, ADARL):
            continue
        best = best_parseval(data, task)
        for method in sorted(data[task]):
            if method in (ADARL, SAC) or not finished(task, method):
                continue
            if method.startswith("sac-parseval") and method != best:
                continue
            name = label(method) + (f" ({best_of(data, task, chosen=True)})" if method == best else "")  # fmt: skip
            exploratory.append(comparison_row(f"{task}: adarl − {name}", compare(arm(task, ADARL), arm(task, method)), "—"))  # fmt: skip
    lines += (head + exploratory) if exploratory else ["None yet: AdaRL and a baseline must both finish on a task."]  # fmt: skip
    lines.append("")

    lines += ["### Ranks the energy rule kept (AdaRL), per cut: min–max over seeds", ""]
    lines += ["| task | layer | 2·d_a + 1 | seeds | " + " | ".join(f"cut {i}" for i in range(1, 5)) + " |"]  # fmt: skip
    lines += ["| --- | --- | ---: | ---: |" + " ---: |" * 4]
    for task in TASKS:
        unit = data.get(task, {}).get(ADARL)
        rows = unit["truncations"] if unit else []
        seeds = f"{len({r['seed'] for r in rows})}" + ("" if is_finished(unit) else " (running)")
        by_layer = defaultdict(lambda: defaultdict(list))
        for r in rows:
            by_layer[r["layer"]][int(r["step"])].append(int(r["new_rank"]))
        for layer, by_step in sorted(by_layer.items()):
            cells = [f"{min(v)}–{max(v)}" if min(v) < max(v) else f"{v[0]}" for _, v in sorted(by_step.items())][:4]  # fmt: skip
            cells += ["—"] * (4 - len(cells))
            lines.append(f"| {task} | {layer} | {2 * ACTION_DIM[task] + 1} | {seeds} | " + " | ".join(cells) + " |")  # fmt: skip
    lines.append("")
    return lines


def is_finished(unit: dict | None) -> bool:
    """A method of `load` whose pre-registered seeds all reached the budget (one unit of 5 seeds,
    or units of one seed each, as the campaign ran them from 2026-12-05)."""
    return unit is not None and unit["last_step"] >= BUDGET and sorted(unit["scores"]) == SEEDS


def finished_parseval(data: dict, task: str) -> list[str]:
    """The Parseval methods (one per coefficient) of `task` whose five seeds have finished."""
    return [m for m, d in data.get(task, {}).items() if m.startswith("sac-parseval") and is_finished(d)]  # fmt: skip


def best_parseval(data: dict, task: str) -> str | None:
    """The Parseval coefficient with the highest mean score among the finished ones (chosen
    after seeing the data, as the paper did)."""
    return max(
        finished_parseval(data, task),
        key=lambda m: np.mean(list(data[task][m]["scores"].values())),
        default=None,
    )


def best_of(data: dict, task: str, chosen: bool = False) -> str:
    """Among how many Parseval coefficients `best_parseval` chose: "best of 3" once all three have
    finished, before that "best of the 2 finished of 3", or "the only one of 3 finished so far";
    `chosen` adds that a choice among several was made after seeing the data."""
    n = len(finished_parseval(data, task))
    total = len(PARSEVAL_COEFS)
    if n == 1:
        return f"the only one of {total} finished so far"
    text = f"best of {n}" if n == total else f"best of the {n} finished of {total}"
    return text + (", chosen after the data" if chosen else "")


def curves(rows: Path = ROWS) -> dict:
    """task -> method label -> DataFrame (step, seed, return): the mean return of each nominal
    evaluation, every method but the Parseval coefficients other than the best finished one; a
    method short of its five seeds says how many it has."""
    import pandas as pd

    data = load(rows)
    out = {}
    for task in TASKS:
        best = best_parseval(data, task)
        for method, unit in sorted(data.get(task, {}).items()):
            if method.startswith("sac-parseval") and best is not None and method != best:
                continue
            table = pd.DataFrame(unit["nominal"], columns=["step", "seed", "return"]).astype(float)
            name = label(method) + (f" ({best_of(data, task)})" if method == best else "")
            if not is_finished(unit):
                name += f" ({len(unit['scores'])} of {len(SEEDS)} seeds)"
            out.setdefault(task, {})[name] = table.groupby(["step", "seed"], as_index=False).mean()
    return out


def figure(rows: Path = ROWS, stem: Path = CURVES) -> list[Path]:
    """Draw `curves(rows)`, one panel per task; returns the files written."""
    from adarl.report import figures

    # Ant's curves leave no corner free: "best" put the legend over RNAC's curve
    return figures.save_figure(figures.training_curves(curves(rows), legend_loc="below"), stem)


def _split(doc: Path) -> tuple[str, str, str]:
    """(before, between, after) the report's markers of `doc`; a doc without both, in order, is a
    one-line error and exit 2."""
    head, begin, rest = doc.read_text(encoding="utf-8").partition(BEGIN)
    body, end, tail = rest.partition(END)
    if not (begin and end):
        print(f"error: {doc} lacks the lines {BEGIN} and {END}, in that order", file=sys.stderr)
        raise SystemExit(2)
    return head, body, tail


def written_report(doc: Path = DOC) -> str:
    """The report's text between the markers of `doc`, without the blank lines around it."""
    return _split(doc)[1].strip("\n")


def write_report(lines: list[str], doc: Path = DOC) -> None:
    """Put the report's `lines` between the markers of `doc`, the rest of it unchanged
    (atomically)."""
    head, _, tail = _split(doc)
    body = "\n".join(lines).strip("\n")
    atomic_write_text(doc, f"{head}{BEGIN}\n\n{body}\n\n{END}{tail}")


def folder(argument: str) -> Path:
    """The folder a command-line argument names (a sweep's, or exported rows); where there is
    none, a one-line error and exit 2."""
    path = Path(argument)
    if not path.is_dir():
        print(f"error: {argument} is not a folder (a sweep's, or exported rows)", file=sys.stderr)
        raise SystemExit(2)
    return path


def main(argv: list[str]) -> int:
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__)
        return 0
    if argv[:1] == ["export"] and len(argv) == 2:
        written, left = export(folder(argv[1]))
        print(f"wrote {len(written)} files under {ROWS}")
        for unit in left:
            print(f"left {unit}: still training (no DONE)")
        return 0
    if argv == ["report", "--write"]:
        write_report(report(load(ROWS)))
        print(f"wrote the report's tables into {DOC}")
        return 0
    if argv[:1] == ["report"] and len(argv) in (1, 2):
        print("\n".join(report(load(folder(argv[1]) if len(argv) == 2 else ROWS))))
        return 0
    if argv[:1] == ["figure"] and len(argv) in (1, 2):
        for path in figure(folder(argv[1]) if len(argv) == 2 else ROWS):
            print(f"wrote {path}")
        return 0
    print("usage: table1_ant_humanoid.py export SWEEP | report [ROWS | --write] | figure [ROWS]", file=sys.stderr)  # fmt: skip
    return 2


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
