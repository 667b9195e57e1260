"""`adarl report`: everything a comparison needs from any set of run folders, in one folder.

`build_report(paths, out, options)` checks its input first (run folders, checkpoints, one
training setting per task), writes the whole report into a temporary folder next to `out` and
renames it into place at the end, so `out` is never half-written: on an error the previous
report (if any) stays as it was.

Layout of the report folder::

    index.md                 links everything; budget, seeds, the exact commands
    tables/scores.csv            every seed's score (mean of the last k evaluations) and final
                                 checkpoint score: everything the tables below are computed from
    tables/table1.{md,tex,csv}   nominal score per task × method (mean ± std over seeds)
    tables/aggregate.{md,csv}    IQM and mean with 95% stratified-bootstrap CIs
    tables/per_task.{md,csv}     mean per task and method with its 95% t interval
    tables/differences.{md,csv}  AdaRL − each baseline per task: Welch CI, permutation p, power
    tables/probability_of_improvement.{md,csv}
    tables/performance_profiles.csv
    tables/best-of-<algo>.{md,csv}  every value's cell of a best-of family (Table 1 keeps the
                                 best; today sac-parseval's coefficient)
    tables/contrast_FIELD.{md,csv}  with --contrast FIELD: differences along one setting, CIs
    tables/control_pairs.{md,csv}   AdaRL minus its schedule-matched control, seed by seed
    tables/rank_settling.{md,csv}   final ranks, cuts and settled seeds per bottleneck
    tables/fixed_rank.{md,csv}   score per fixed rank (bias–variance sweep)
    tables/policy_size.{md,csv}  policy parameters before/after rank adaptation
    tables/suites.{md,csv}       worst-case / average return over robustness suites' grids
    tables/robustness_size_<task>_<suite>.csv   return against the size of the perturbation
    tables/runs.csv
    tables/environments.csv      versions, CPU and XLA flags each run was made with
    figures/*.{png,pdf}

The code, by concern (import from the module: `from adarl.report.build import build_report`,
`from adarl.report.common import ReportOptions`):

- `build`: `build_report` (input checks, the atomic write), `write_report` (the sections in
  the report's order), `write_index` (index.md), `write_scores_report` (from scores.csv).
- `scores`: each seed's score and the sections that list runs and scores (runs, scores.csv,
  Table 1, what the final policies do, best-of families, environments).
- `statistics`: aggregate IQM/mean, per-task means, differences with power, probability of
  improvement, performance profiles; `compare` computes them as DataFrames (on `adarl.stats`).
- `comparisons`: `--contrast FIELD` and AdaRL against its schedule-matched control.
- `ranks`: training curves, rank over training, bias–variance, rank-rule ablation, spectra,
  policy size.
- `robustness`: parameter sweeps, robustness suites, return against the perturbation's size
  (`perturbation`).
- `selection`: the protocol choices made after training (best of N, best checkpoint).
- `behaviour`: one word for what a policy does (falls, stands, hops) from its episodes.
- `tables`, `figures`: Markdown/LaTeX/CSV tables and matplotlib figures from DataFrames.
- `common`: options, `Section`, the score types, constants, file and number-format helpers.
- `summary`: the report's short form, the lines `adarl train` prints when a run ends.
"""
