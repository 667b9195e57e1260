"""Numerical check of the paper's bias–variance theorem (Theorem 1, ``theorem:tradeoff``).

- ``adarl.theory.linalg``: truncated-SVD solutions, the proof's exact error split, the bias term,
  the discrete Picard condition.
- ``adarl.theory.synthetic``: a rank-r° ground-truth system satisfying the Picard condition and
  perturbed systems at radius ε (moment-level mixture perturbations).
- ``adarl.theory.mdp``: the same on a random tabular MDP with low-rank transitions, linear features
  and kernels resampled from an ε-ball, for the soft-Q fixed point's linear system.
- ``adarl.theory.report``: CSV, JSON and figures for ``adarl theory``.

See docs/theory.md.
"""

from adarl.theory.linalg import (
    ErrorSplit,
    bias_term,
    picard_coefficients,
    picard_constant,
    picard_exponent,
    satisfies_picard,
    split_error,
    truncated_pinv,
    truncated_solutions,
)
from adarl.theory.mdp import LowRankMDP, MdpTruth, make_low_rank_mdp, mdp_truth, run_mdp
from adarl.theory.synthetic import (
    GroundTruth,
    Sweep,
    draw_perturbation,
    make_ground_truth,
    run_synthetic,
)

__all__ = [
    "ErrorSplit",
    "GroundTruth",
    "LowRankMDP",
    "MdpTruth",
    "Sweep",
    "bias_term",
    "draw_perturbation",
    "make_ground_truth",
    "make_low_rank_mdp",
    "mdp_truth",
    "picard_coefficients",
    "picard_constant",
    "picard_exponent",
    "run_mdp",
    "run_synthetic",
    "satisfies_picard",
    "split_error",
    "truncated_pinv",
    "truncated_solutions",
]
