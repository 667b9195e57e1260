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

The code, by concern (each module's public names also import from here):

- `build`: `build_report` (input checks, the atomic write), `write_report` (the sections in
  the report's order), `write_index` (index.md), `write_scores_report` (from scores.csv).
- `scores`: each seed's score and the sections that list runs and scores (runs, scores.csv,
  Table 1, what the final policies do, best-of families, environments).
- `statistics`: aggregate IQM/mean, per-task means, differences with power, probability of
  improvement, performance profiles.
- `comparisons`: `--contrast FIELD` and AdaRL against its schedule-matched control.
- `ranks`: training curves, rank over training, bias–variance, rank-rule ablation, spectra,
  policy size.
- `robustness`: parameter sweeps, robustness suites, return against the perturbation's size.
- `common`: options, `Section`, the score types, constants, file and number-format helpers.
"""

from adarl.evaluation.report.build import (
    build_report,
    check_output,
    check_rows,
    read_scores,
    scores_file,
    usable_runs,
    write_index,
    write_report,
    write_scores_report,
)
from adarl.evaluation.report.common import (
    INDEX,
    MARKER,
    PROFILE_TAUS,
    REFERENCE,
    ReportOptions,
    Scored,
    ScoreNote,
    Section,
)
from adarl.evaluation.report.comparisons import (
    CONTROL_PAIR_IGNORED,
    contrast_groups,
    contrast_section,
    control_section,
)
from adarl.evaluation.report.ranks import (
    ablation_section,
    bias_variance_section,
    intrinsic_rank,
    policy_size_section,
    rank_section,
    settling_table,
    spectra_section,
    training_section,
)
from adarl.evaluation.report.robustness import (
    robustness_section,
    size_curves,
    suites_section,
)
from adarl.evaluation.report.scores import (
    SCORE_COLUMNS,
    SCORES_CSV,
    TABLE1,
    behaviour_section,
    best_of_section,
    environment_section,
    few_evaluations_notes,
    final_sources,
    long_scores,
    protocol_notes,
    run_scores,
    runs_section,
    score_line,
    scores_section,
    table1_section,
)
from adarl.evaluation.report.statistics import (
    aggregate_section,
    differences_section,
    improvement_section,
    per_task_section,
    profile_section,
    statistics_sections,
)

__all__ = [
    "CONTROL_PAIR_IGNORED",
    "INDEX",
    "MARKER",
    "PROFILE_TAUS",
    "REFERENCE",
    "ReportOptions",
    "SCORES_CSV",
    "SCORE_COLUMNS",
    "ScoreNote",
    "Scored",
    "Section",
    "TABLE1",
    "long_scores",
    "ablation_section",
    "aggregate_section",
    "behaviour_section",
    "best_of_section",
    "bias_variance_section",
    "build_report",
    "check_output",
    "check_rows",
    "contrast_groups",
    "contrast_section",
    "control_section",
    "differences_section",
    "environment_section",
    "few_evaluations_notes",
    "final_sources",
    "improvement_section",
    "intrinsic_rank",
    "per_task_section",
    "policy_size_section",
    "profile_section",
    "protocol_notes",
    "rank_section",
    "read_scores",
    "robustness_section",
    "run_scores",
    "runs_section",
    "score_line",
    "scores_file",
    "scores_section",
    "settling_table",
    "size_curves",
    "spectra_section",
    "statistics_sections",
    "suites_section",
    "table1_section",
    "training_section",
    "usable_runs",
    "write_index",
    "write_report",
    "write_scores_report",
]
