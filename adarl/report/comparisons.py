"""Comparisons between runs of one method: `--contrast FIELD` (runs that differ in one
setting) and AdaRL against its schedule-matched control, seed by seed."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from adarl import stats
from adarl.algos import registry
from adarl.errors import UsageError
from adarl.report import compare, tables
from adarl.report.common import (
    ReportOptions,
    Section,
    ci_text,
    csv_text,
    rounded,
    slug,
    write_file,
)
from adarl.report.statistics import power_text
from adarl.results.runs import (
    LAUNCH_KEYS,
    Run,
    differing_fields,
    flatten_config,
    method_label,
)


def contrast_groups(runs: Sequence[Run], contrast: str) -> tuple[str, str, dict]:
    """Split `FIELD[=REFERENCE]` and group the runs that differ only in FIELD.

    Returns `(field, reference, groups)`, groups mapping `(task, method, other settings)` to
    `{value: [runs]}`; "other settings" names the fields (seeds and launch details aside) that
    differ between groups of the same task and method. The reference defaults to the first value
    in sorted order. Raises `UsageError` when no run has FIELD or no run has REFERENCE.
    """
    field, _, reference = contrast.partition("=")
    keyed = []
    for r in runs:
        flat = flatten_config(r.config)
        keys = [k for k in flat if k.split(".")[-1] == field]
        if not keys:
            continue
        keyed.append((r, str(flat[keys[0]])))
    if not keyed:
        raise UsageError(f"--contrast {contrast!r}: no run has a config field {field!r}")
    values = sorted({value for _, value in keyed})
    reference = reference or values[0]
    if reference not in values:
        raise UsageError(
            f"--contrast {contrast!r}: no run has {field}={reference}; the runs have "
            f"{', '.join(values)}"
        )
    by_method: dict[tuple[str, str], list] = {}
    for r, value in keyed:
        by_method.setdefault((r.task, method_label(r.config)), []).append((r, value))
    groups: dict[tuple[str, str, str], dict[str, list[Run]]] = {}
    for (task, method), members in by_method.items():
        varying = differing_fields([r.config for r, _ in members], ignore={field})
        for r, value in members:
            flat = flatten_config(r.config)
            others = ", ".join(f"{k.split('.')[-1]}={flat[k]}" for k in varying if k in flat)
            groups.setdefault((task, method, others), {}).setdefault(value, []).append(r)
    return field, reference, groups


def _seed_scores(finals: dict, runs: list[Run]) -> np.ndarray:
    """The scores of every seed of `runs`, pooled."""
    return np.concatenate([finals[r.path][0]["score"].to_numpy(float) for r in runs])


def contrast_section(
    runs: list[Run], finals: dict, contrast: str, folder: Path, options: ReportOptions
) -> Section:
    """Score of each value of one setting minus the reference value's, among runs that agree on
    everything else: Welch interval, exact permutation p and power (`stats.compare_groups`)."""
    field, reference, groups = contrast_groups(runs, contrast)
    rows = []
    for (task, method, others), by_value in groups.items():
        if reference not in by_value:
            continue
        base = _seed_scores(finals, by_value[reference])
        for value in sorted(v for v in by_value if v != reference):
            other = _seed_scores(finals, by_value[value])
            if not len(base) or not len(other):
                continue
            comparison = stats.compare_groups(
                other, base, options.target_difference, options.confidence, options.power,
                options.alpha,
            )  # fmt: skip
            rows.append(
                {
                    "task": task,
                    "method": method,
                    "held fixed": others or "—",
                    "contrast": f"{field}: {value} − {reference}",
                    f"mean ({reference})": base.mean(),
                    "mean (other)": other.mean(),
                    **compare.comparison_row(comparison),
                }
            )
    df = pd.DataFrame(rows)
    if not df.empty:
        df = df.rename(columns={"low": "ci low", "high": "ci high", "p_value": "p"})
    stem = f"tables/contrast_{slug(field)}"
    files = [write_file(folder, f"{stem}.csv", csv_text(df))]
    if df.empty:
        return Section(f"Contrast: {field}", f"No pair of runs differs only in `{field}`.", files)
    pct, level = int(round(100 * options.confidence)), f"{options.power:.0%}"
    md = tables.markdown_table(
        ["task", "method", "held fixed", "contrast", f"mean ({reference})", "mean (other)",
         f"difference [{pct}% CI, Welch]", "p", "seeds", f"detectable at {level}",
         f"seeds for {options.target_difference:g}"],
        [
            [r["task"], r["method"], r["held fixed"], r["contrast"],
             f"{r[f'mean ({reference})']:.1f}", f"{r['mean (other)']:.1f}",
             f"{r['difference']:.1f} {ci_text(r['ci low'], r['ci high'], 1)}".replace(f" {tables.DASH}", ""),
             tables.p_text(r["p"]), r["seeds"], rounded(r["detectable"]), rounded(r["seeds_for_target"])]
            for r in df.to_dict("records")
        ],
    )  # fmt: skip
    files.append(write_file(folder, f"{stem}.md", md))
    text = (
        f"Score with `{field}` set to each value minus the same runs' setting at `{reference}`, "
        f"everything else equal; {pct}% Welch t interval over seeds (each side's seeds "
        "independent). An interval that contains 0 shows no difference at this number of "
        "seeds.\n\n" + md + "\n" + power_text(options) + "\n"
    )
    return Section(f"Contrast: {field}", text, files)


# fields in which a control may differ from the AdaRL run it is paired with (a fork may also
# change how it is logged and checkpointed)
CONTROL_PAIR_IGNORED = {
    "algo",
    "apply_cuts",
    "keep_checkpoints",
    "checkpoint_every",
    "checkpoint_before_truncation",
    "log_every",
    "eval_every",
    "on_divergence",
}


def control_section(
    runs: list[Run], finals: dict, folder: Path, options: ReportOptions
) -> Section | None:
    """AdaRL minus its schedule-matched control (`control_of` in the registry), seed by seed:
    runs of the two that agree on everything else are paired on their common seeds, and the mean
    per-seed difference of the score (as Table 1's: the mean of the last k evaluations) gets a
    Student-t interval (`stats.paired_difference_ci`). None without control runs."""
    arms = {r.algo: registry.role(r.algo, "control_of") for r in runs}
    arms = {control: arm for control, arm in arms.items() if arm}
    if not arms:
        return None

    def setting(r: Run) -> tuple:
        ignored = LAUNCH_KEYS | CONTROL_PAIR_IGNORED
        flat = flatten_config(r.config).items()
        return r.task, sorted(
            (k, repr(v)) for k, v in flat if k.split(".")[0] != "fork" and k not in ignored
        )

    groups: dict[str, dict[str, list[Run]]] = {}
    for r in runs:
        side = "control" if r.algo in arms else "method" if r.algo in arms.values() else None
        if side:
            groups.setdefault(repr(setting(r)), {}).setdefault(side, []).append(r)
    rows, summary, forks = [], [], []
    pct = int(round(100 * options.confidence))
    for group in groups.values():
        by_seed = {
            side: {int(seed): float(score) for r in group.get(side, [])
                   for seed, score in finals[r.path][0][["seed", "score"]].itertuples(index=False)}
            for side in ("method", "control")
        }  # fmt: skip
        seeds = sorted(set(by_seed["method"]) & set(by_seed["control"]))
        if not seeds:
            continue
        method, control = group["method"][0], group["control"][0]
        x = np.array([by_seed["method"][s] for s in seeds])
        y = np.array([by_seed["control"][s] for s in seeds])
        rows += [
            {"task": method.task, "method": method.label, "control": control.label, "seed": s,
             "method score": a, "control score": b, "difference": a - b}
            for s, a, b in zip(seeds, x, y)
        ]  # fmt: skip
        ci = stats.paired_difference_ci(x, y, options.confidence)
        sd_diff = float(np.std(x - y, ddof=1)) if len(seeds) > 1 else float("nan")
        detectable = stats.paired_minimum_detectable_difference(sd_diff, len(seeds), options.power)
        needed = stats.paired_seeds_needed(options.target_difference, sd_diff, options.power)
        summary.append(
            [method.task, method.label, control.label, str(len(seeds)), f"{x.mean():.1f}",
             f"{y.mean():.1f}", f"{ci.point:.1f} [{ci.low:.1f}, {ci.high:.1f}]",
             f"{stats.paired_permutation_p_value(x, y):.3g}", f"{detectable:.0f}",
             f"{needed:.0f}"]
        )  # fmt: skip
        forks += [
            f"- {r.path}: forked from {r.config['fork'].get('from')} at step "
            f"{r.config['fork'].get('step')}"
            for r in group["control"]
            if isinstance(r.config.get("fork"), dict)
        ]
    title = "AdaRL against its control"
    if not summary:
        return Section(title, "No control run has an AdaRL run with the same settings and seeds.\n")
    files = [write_file(folder, "tables/control_pairs.csv", csv_text(pd.DataFrame(rows)))]
    md = tables.markdown_table(
        ["task", "method", "control", "paired seeds", "mean (method)", "mean (control)",
         f"method − control [{pct}% t CI]", "sign-flip p",
         f"detectable at {options.power:.0%} power (paired)",
         f"pairs for {options.target_difference:g}"],
        summary,
    )  # fmt: skip
    files.append(write_file(folder, "tables/control_pairs.md", md))
    text = (
        "The score (as Table 1) of AdaRL minus its schedule-matched control (the same "
        "truncations, resets and warm-ups, no component removed), seed by seed: a control seed is "
        f"paired with the AdaRL seed of the same number; {pct}% Student-t interval of the mean "
        "per-seed difference, the exact sign-flip permutation p-value, the smallest difference "
        "the paired t-test detects at that power with these pairs and their spread, and the pairs "
        "a difference of the target size would need. Per-seed rows: tables/control_pairs.csv."
        "\n\n" + md
    )
    if forks:
        text = (
            text.rstrip("\n")
            + "\n\nForked controls (they share AdaRL's training up to that step):\n"
        )
        text += "\n".join(forks) + "\n"
    return Section(title, text, files)
