"""Reading a run folder's logs into tidy tables for the report (no computation beyond grouping).

Each function takes a `Run` and returns a pandas DataFrame (empty when the run lacks that log):
final nominal returns per seed, the training curve, the rank history, truncation steps,
singular-value spectra, stored evaluations and policy sizes. File layout: docs/run-format.md.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from adarl.errors import UsageError, reason
from adarl.files import UnreadableFile, read_json
from adarl.results.runs import Run, config_value
from adarl.runs import layout
from adarl.runs.checkpoints import checkpoint_dirs, policy_files
from adarl.runs.layout import (
    EPISODES_CSV,
    EVAL_CSV,
    EVALUATIONS_DIR,
    META_FILE,
    SPECTRA_DIR,
    STEP_PREFIX,
    TRAIN_CSV,
    TRUNCATIONS_CSV,
    checkpoint_step,
)
from adarl.runs.logs import TEXT_COLUMNS, read_csv

NOMINAL = "nominal"
CURVE_BINS = 50
MAX_EPISODE_STEPS = 1000  # the environments' time limit (`adarl.envs.make`), `adarl evaluate`'s


#: The columns the report reads from each run log (`needed_columns`): the log must have them,
#: and those in `FINITE` must hold a finite number in every row (issue 38: a `nan`, `inf` or
#: renamed column would otherwise be a traceback or NaN statistics).
NEEDED = {
    EVAL_CSV: ("step", "seed", "dynamics", "episode", "return"),
    EPISODES_CSV: ("step", "seed", "episode", "return"),
    TRAIN_CSV: ("step", "seed"),
    TRUNCATIONS_CSV: ("step", "seed", "layer", "new_rank"),
}
EVALUATION_NEEDED = ("step", "seed", "dynamics", "episode", "return")  # evaluations/*.csv
FINITE = frozenset({"step", "seed", "episode", "return", "new_rank"})
#: what a run itself writes for a non-finite return (`CsvLog`: an episode of diverged weights,
#: kept by --on-divergence continue): data, read as NaN (no return), not damage (issue 55)
RUN_NON_FINITE = {"return": frozenset({"nan", "inf", "-inf"})}


def needed_columns(path: Path) -> tuple[str, ...]:
    if Path(path).parent.name == EVALUATIONS_DIR:
        return EVALUATION_NEEDED
    return NEEDED.get(Path(path).name, ())


def read_table(path: Path) -> pd.DataFrame:
    """A run CSV as a DataFrame, every column but the `TEXT_COLUMNS` as numbers (an empty cell:
    NaN); empty if the file is missing. A cell that is no number, a missing `needed_columns`
    column or a non-finite value in one of them (`FINITE`): a one-line UsageError naming the
    file, its line and column; except a `return` of `nan`, `inf` or `-inf` as the run writes
    one (`RUN_NON_FINITE`), which is read as NaN: an episode without a finite return."""
    if not Path(path).is_file():
        return pd.DataFrame()
    df = pd.DataFrame(read_csv(path))
    needed = needed_columns(path)
    if len(df):
        missing = [c for c in needed if c not in df.columns]
        if missing:
            raise UsageError(
                f"{path} has no column {missing[0]!r} (its columns: {', '.join(df.columns)}); "
                f"adarl writes it with {', '.join(needed)}: restore the file or leave the run "
                "out of the report"
            )
    for column in df.columns:
        if column in TEXT_COLUMNS:
            continue
        finite = column in needed and column in FINITE
        written = RUN_NON_FINITE.get(column, frozenset()) if finite else frozenset()
        if written and Path(path).parent.name == EVALUATIONS_DIR:
            written = written | {""}  # `adarl evaluate` writes NaN as an empty cell (pandas)
        if written:
            df[column] = [np.nan if t in written else t for t in df[column]]
        for line, text in enumerate(df[column], start=2):  # line 1: the header
            if not (written and isinstance(text, float)):  # NaN: the run's own, read above
                _check_number(text, path, column, line, finite)
        try:
            df[column] = pd.to_numeric(df[column].replace("", np.nan))
        except ValueError:  # pandas refuses "nan" or "inf" beside numbers: checked above
            df[column] = [np.nan if t is None or t == "" else float(t) for t in df[column]]
    return df


def _check_number(text, path: Path, column: str, line: int, finite: bool = False) -> None:
    if (text is None or text == "") and not finite:  # a short row, an empty cell: NaN
        return
    try:
        value = float(text)  # "nan" and "inf" too, as CsvLog writes non-finite values
    except (TypeError, ValueError):
        if finite and (text is None or text == ""):  # an empty cell where a number must be
            value = math.nan
        else:
            raise UsageError(
                f"{path} line {line}: {column} is {text!r}, not a number; is the file damaged?"
            ) from None
    if finite and not math.isfinite(value):
        raise UsageError(
            f"{path} line {line}: {column} is {text!r}; allowed: a finite number (the "
            "statistics cannot take it): restore the file or leave the run out of the report"
        )


# ----------------------------------------------------------------------------- evaluations
@dataclass(frozen=True)
class Evaluation:
    """One `adarl evaluate` output stored in the run: its name, sidecar and table."""

    name: str
    meta: dict
    table: pd.DataFrame

    @property
    def swept(self) -> list[str]:
        return list(self.meta.get("sweep") or {})


def evaluations(run: Run) -> list[Evaluation]:
    """Evaluations stored under `RUN_DIR/evaluations/` (CSV files that have a JSON sidecar)."""
    folder = run.path / EVALUATIONS_DIR
    found = []
    for csv_path in sorted(folder.glob("*.csv")) if folder.is_dir() else []:
        sidecar = layout.evaluation_sidecar(csv_path)
        if not sidecar.is_file():
            continue
        try:
            meta = read_json(sidecar)
        except UnreadableFile as exc:  # dropping it would change the report silently
            raise UsageError(f"evaluation sidecar {exc}") from None
        if not isinstance(meta, dict):
            raise UsageError(f"evaluation sidecar {sidecar} is not a JSON object")
        table = read_table(csv_path)
        if not table.empty:
            found.append(Evaluation(csv_path.stem, meta, table))
    return found


def final_step(run: Run) -> int | None:
    found = checkpoint_dirs(run.path)
    return checkpoint_step(found[-1]) if found else None


def final_scores(run: Run) -> tuple[pd.DataFrame, str]:
    """Each seed's final return under nominal dynamics: columns `seed, score`, and a note
    saying where it came from.

    Preferred: an `adarl evaluate --dynamics nominal` of the final checkpoint (the mean over its
    episodes); else the last evaluation logged during training (eval.csv, dynamics `nominal`).
    """
    episodes, note = final_nominal_episodes(run)
    if episodes.empty:
        return _scores(pd.Series(dtype=float)), note
    return _scores(episodes.groupby("seed")["return"].agg(_mean_with_nan)), note


def _mean_with_nan(values: pd.Series) -> float:
    """The mean, NaN if any value is (an episode without a finite return, RUN_NON_FINITE): a
    seed's score is not the mean of its finite episodes only."""
    return float(values.mean(skipna=False))


def final_behaviour(run: Run) -> pd.DataFrame:
    """What each seed's final policy does on nominal dynamics, from the episodes behind its final
    return: columns `seed, length, distance` (means over episodes; `distance`, the root body's
    forward displacement, is recorded by `adarl evaluate` only, else NaN) and `max_length`, the
    time limit of those episodes (`adarl evaluate`'s full-length episodes, or the run's
    `max_episode_steps` for eval.csv)."""
    episodes, note = final_nominal_episodes(run)
    columns = ["length", "distance"]
    if episodes.empty:
        return pd.DataFrame(columns=["seed", *columns, "max_length"])
    present = [c for c in columns if c in episodes]
    means = episodes.groupby("seed")[present].mean().reindex(columns=columns).reset_index()
    logged = note.startswith(EVAL_CSV)
    limit = config_value(run.config, "max_episode_steps") if logged else None
    return means.assign(max_length=int(limit or MAX_EPISODE_STEPS))


def final_nominal_episodes(run: Run) -> tuple[pd.DataFrame, str]:
    """The nominal episodes of the final policy (see `final_scores` for which ones) and a note
    saying where they came from; empty with note "none" if there are none."""
    last = final_step(run)
    for ev in evaluations(run):
        meta = ev.meta
        if (
            meta.get("dynamics") == NOMINAL
            and not meta.get("sweep")
            and not meta.get("hold")
            and meta.get("final_checkpoint", True)
            and meta.get("checkpoint_step") == last
            and not meta.get("max_episode_steps")
        ):
            return ev.table, f"`adarl evaluate` ({meta.get('episodes')} episodes, step {last})"
    log = _nominal_evaluations(run)
    if log.empty:
        return log, "none"
    at_last = log[log["step"] == log.groupby("seed")["step"].transform("max")]
    steps = sorted(int(s) for s in at_last["step"].unique())
    return at_last, f"eval.csv at step {', '.join(map(str, steps))}"


def score_dynamics(log: pd.DataFrame) -> str | None:
    """The dynamics whose evaluations make a run's score: `nominal` when eval.csv has it, else
    the first dynamics it lists (`--eval-dynamics`); None for an empty log."""
    if log.empty or "dynamics" not in log:
        return None
    labels = list(dict.fromkeys(log["dynamics"]))
    return NOMINAL if NOMINAL in labels else labels[0]


def last_evaluations(log: pd.DataFrame, k: int) -> pd.DataFrame:
    """Each seed's score from eval.csv rows of one dynamics (`step, seed, episode, return`): the
    mean over its last `k` evaluations (fewer if it has fewer) of each evaluation's mean return
    over its episodes, (1/k) Σ_{j=m−k+1..m} (1/E_j) Σ_e R_{j,e}. Columns `seed, score,
    evaluations` (how many were averaged), `first_step, last_step` (of those) and `episodes`
    (the fewest episodes in any of them)."""
    columns = ["seed", "score", "evaluations", "first_step", "last_step", "episodes"]
    if log.empty:
        return pd.DataFrame(columns=columns)
    per_eval = log.groupby(["seed", "step"], as_index=False).agg(
        ret=("return", _mean_with_nan), episodes=("return", "size")
    )
    last = per_eval.sort_values(["seed", "step"]).groupby("seed").tail(k)
    out = last.groupby("seed", as_index=False).agg(
        score=("ret", _mean_with_nan),
        evaluations=("ret", "size"),
        first_step=("step", "min"),
        last_step=("step", "max"),
        episodes=("episodes", "min"),
    )
    return out[columns].astype({"seed": int})


def last_k_scores(run: Run, k: int) -> tuple[pd.DataFrame, str]:
    """`last_evaluations` of the run's eval.csv under `score_dynamics`, and a note saying where
    the scores came from (empty with note "none" when the run logged no evaluation)."""
    log = read_table(run.path / EVAL_CSV)
    dynamics = score_dynamics(log)
    if dynamics is None:
        return last_evaluations(log.iloc[0:0], k), "none"
    scores = last_evaluations(log[log["dynamics"] == dynamics], k)
    used = sorted(set(scores["evaluations"]))
    steps = sorted({*scores["first_step"], *scores["last_step"]})
    span = f"steps {steps[0]}–{steps[-1]}" if len(steps) > 1 else f"step {steps[0]}"
    count = "/".join(map(str, used))
    return scores, f"eval.csv, mean of the last {count} evaluation(s) ({span}, {dynamics})"


def best_scores(run: Run) -> tuple[pd.DataFrame, str]:
    """Each seed's return at its best checkpoint by mean nominal evaluation return (RNAC keeps
    it, docs/rnac.md): columns `seed, score`, and a note saying where it came from.

    From the `best` record of the final checkpoint's meta.json; a run without one (written
    before it existed) falls back to the best mean `nominal` evaluation per seed in eval.csv.
    """
    found = checkpoint_dirs(run.path)
    record = {}
    if found:
        try:
            meta = read_json(found[-1] / META_FILE)
            record = (meta.get("best") or {}).get("seeds") or {}
        except (OSError, ValueError):
            record = {}
    if record:
        seeds = sorted(record, key=int)
        returns = [float(record[s]["return"]) for s in seeds]
        scores = pd.Series(returns, index=[int(s) for s in seeds])
        steps = ", ".join(f"seed {s}: {record[s]['step']}" for s in seeds)
        return _scores(scores), f"best checkpoint by evaluation (steps {steps})"
    log = _nominal_evaluations(run)
    if log.empty:
        return _scores(pd.Series(dtype=float)), "none"
    means = log.groupby(["seed", "step"], as_index=False)["return"].mean()
    best = means.loc[means.groupby("seed")["return"].idxmax()]
    scores = pd.Series(best["return"].to_numpy(float), index=best["seed"].to_numpy(int))
    return _scores(scores), "best nominal evaluation in eval.csv (no best-checkpoint record)"


def _nominal_evaluations(run: Run) -> pd.DataFrame:
    """The rows of the run's eval.csv on nominal dynamics (empty if there are none)."""
    log = read_table(run.path / EVAL_CSV)
    if log.empty or "dynamics" not in log:
        return log.iloc[0:0]
    return log[log["dynamics"] == NOMINAL]


def _scores(series: pd.Series) -> pd.DataFrame:
    return pd.DataFrame({"seed": series.index.astype(int), "score": series.to_numpy(float)})


# ----------------------------------------------------------------------------- curves
def training_curve(run: Run) -> tuple[pd.DataFrame, str]:
    """Return over training, columns `step, seed, return`, and its source.

    From the nominal evaluations logged in eval.csv (mean over episodes per step and seed); a
    run without them falls back to the training episodes (episodes.csv) averaged in
    `CURVE_BINS` equal step bins with edges e_0 = 0 < … < e_50 = the last episode's step: bin k
    holds the episodes ending in (e_{k−1}, e_k] (the first also those at step 0) and is drawn at
    its right edge e_k, so an episode ending exactly on an edge counts in the bin it closes.
    """
    log = read_table(run.path / EVAL_CSV)
    if not log.empty and "dynamics" in log:
        log = log[log["dynamics"] == NOMINAL]
        if not log.empty:
            curve = log.groupby(["step", "seed"], as_index=False)["return"].mean()
            return curve, "nominal evaluation (eval.csv)"
    episodes = read_table(run.path / EPISODES_CSV)
    if episodes.empty:
        return pd.DataFrame(columns=["step", "seed", "return"]), "none"
    top = float(episodes["step"].max())
    edges = np.linspace(0.0, top, CURVE_BINS + 1)
    bins = np.clip(np.searchsorted(edges, episodes["step"], side="left"), 1, CURVE_BINS)
    episodes = episodes.assign(step=edges[bins].round().astype(int))
    curve = episodes.groupby(["step", "seed"], as_index=False)["return"].mean()
    return curve, "training episodes (episodes.csv)"


def rank_history(run: Run) -> pd.DataFrame:
    """Rank of each bottleneck over training: columns `step, seed, layer, rank`, from train.csv's
    logging points and, at the exact step of each truncation, its new rank (truncations.csv), so
    that a step plot changes where the rank did, not at the next logging point. Where a
    bottleneck's first truncation comes before its first logging point (a cut at step 4,950,
    the first row at 5,000), the history starts at step 0 at that cut's old rank, the initial
    rank: the cut and the level it cut from are not lost."""
    log = read_table(run.path / TRAIN_CSV)
    columns = layout.rank_columns(log.columns)
    if log.empty or not columns:
        return pd.DataFrame(columns=["step", "seed", "layer", "rank"])
    long = log.melt(
        id_vars=["step", "seed"], value_vars=columns, var_name="layer", value_name="rank"
    )
    long["layer"] = long["layer"].map(layout.rank_layer)
    long = long.dropna(subset=["rank"])
    cuts = read_table(run.path / TRUNCATIONS_CSV)
    if not cuts.empty:
        first_cut = cuts.sort_values("step", kind="stable").groupby(["seed", "layer"]).head(1)
        first_log = long.groupby(["seed", "layer"])["step"].min()
        logged = [
            first_log.get((s, layer), np.inf)
            for s, layer in zip(first_cut["seed"], first_cut["layer"])
        ]
        start = first_cut[first_cut["step"].to_numpy(float) < np.asarray(logged, float)]
        start = start[["seed", "layer", "old_rank"]].rename(columns={"old_rank": "rank"})
        cuts = cuts[["step", "seed", "layer", "new_rank"]].rename(columns={"new_rank": "rank"})
        cuts = pd.concat([start.assign(step=0)[cuts.columns], cuts], ignore_index=True)
        long = pd.concat([cuts, long], ignore_index=True)  # a truncation's row wins a tie
        long = long.drop_duplicates(["step", "seed", "layer"], keep="first")
    return long.sort_values(["step", "seed", "layer"], kind="stable").reset_index(drop=True)


def truncation_steps(run: Run) -> list[int]:
    """Steps at which the run truncated its bottlenecks (from truncations.csv)."""
    log = read_table(run.path / TRUNCATIONS_CSV)
    if log.empty:
        return []
    return sorted(int(s) for s in log["step"].unique())


def final_ranks(run: Run) -> pd.DataFrame:
    """The last logged rank of each bottleneck per seed: columns `seed, layer, rank`."""
    history = rank_history(run)
    if history.empty:
        return pd.DataFrame(columns=["seed", "layer", "rank"])
    history = history.sort_values("step")
    return history.groupby(["seed", "layer"], as_index=False)["rank"].last()


def rank_settling(run: Run) -> pd.DataFrame:
    """Per bottleneck and seed, from truncations.csv: `seed, layer, final_rank, truncations,
    cuts` (truncations that lowered the rank), `retained` (cuts refused by the retain clause),
    `last_change` (step of the last truncation that lowered the rank; NaN if none) and `settled`
    (the rank did not change at the last truncation: it stopped before the run did)."""
    columns = ["seed", "layer", "final_rank", "truncations", "cuts", "retained", "last_change"]
    log = read_table(run.path / TRUNCATIONS_CSV)
    if log.empty:
        return pd.DataFrame(columns=[*columns, "settled"])
    rows = []
    for (seed, layer), g in log.sort_values("step").groupby(["seed", "layer"]):
        changed = g[g["new_rank"] < g["old_rank"]]
        decisions = g["decision"] if "decision" in g else pd.Series(dtype=str)
        rows.append(
            {
                "seed": int(seed),
                "layer": layer,
                "final_rank": int(g["new_rank"].iloc[-1]),
                "truncations": len(g),
                "cuts": len(changed),
                "retained": int((decisions == "retained").sum()),
                "last_change": int(changed["step"].max()) if len(changed) else np.nan,
                "settled": bool(g["new_rank"].iloc[-1] == g["old_rank"].iloc[-1]),
            }
        )
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------- spectra
@dataclass(frozen=True)
class Spectrum:
    """Singular values of every bottleneck at one truncation (`n_seeds × width` per layer)."""

    step: int
    layers: dict[str, np.ndarray]
    seeds: np.ndarray


def spectra(run: Run) -> list[Spectrum]:
    folder = run.path / SPECTRA_DIR
    found = []
    for path in sorted(folder.glob(f"{STEP_PREFIX}*.npz")) if folder.is_dir() else []:
        m = re.match(r"^step_(\d+)\.npz$", path.name)
        if not m:
            continue
        try:
            with np.load(path, allow_pickle=False) as z:
                layers = {k: np.atleast_2d(z[k]) for k in z.files if k != "seeds"}
                seeds = (
                    z["seeds"]
                    if "seeds" in z.files
                    else np.arange(len(next(iter(layers.values()))))
                )
        except Exception as exc:  # BadZipFile, EOFError, ValueError, StopIteration…: damaged
            raise UsageError(f"spectrum file {path} is damaged ({reason(exc)})") from None
        found.append(Spectrum(int(m.group(1)), layers, np.asarray(seeds)))
    return sorted(found, key=lambda s: s.step)


# ----------------------------------------------------------------------------- policy sizes
def policy_sizes(run: Run) -> pd.DataFrame:
    """Parameters of each seed's final policy: columns `seed, n_params, n_params_full`
    (`n_params_full`: the same network at full rank, `NumpyPolicy.n_params_full`)."""
    from adarl.policy import load

    found = checkpoint_dirs(run.path)
    rows = []
    if found:
        for seed, path in policy_files(found[-1]).items():
            policy = load(path)
            rows.append(
                {
                    "seed": seed,
                    "n_params": policy.n_params(),
                    "n_params_full": policy.n_params_full(),
                }
            )
    return pd.DataFrame(rows, columns=["seed", "n_params", "n_params_full"])
