"""Algorithms by name. Every SAC-family algorithm is a configuration of `adarl.algos.sac`;
RNAC has its own PPO-style trainer in `adarl.algos.rnac`."""

from __future__ import annotations

# name -> config fields that define it (applied before presets and user overrides)
SAC_FAMILY: dict[str, dict] = {
    "sac": {},
    "adarl": {"bottleneck": ("actor:1", "critic:1"), "adapt_rank": True},
    "sac-fixed-rank": {"bottleneck": ("actor:1", "critic:1"), "adapt_rank": False},
    "sac-parseval": {"parseval_coef": 1e-4, "init": "orthogonal"},
    "sac-sparse": {"sparse_width": 1024},
}
ALGOS: tuple[str, ...] = (*SAC_FAMILY, "rnac")

# AdaRL's budget where the user sets none (no --total-steps / --truncate-every, flag or preset):
# the paper's d_t (10⁶ gradient steps, 0.7·10⁶ on Walker2d) and the `paper-table1` step budgets,
# so that a default run truncates (Hopper 2, the others 4 times); a flat 10⁶ steps would not.
TASK_DEFAULTS: dict[str, dict[str, dict]] = {
    "adarl": {
        "hopper": {"total_steps": 3_000_000, "truncate_every": 1_000_000},
        "walker2d": {"total_steps": 3_000_000, "truncate_every": 700_000},
        "ant": {"total_steps": 5_000_000, "truncate_every": 1_000_000},
        "humanoid": {"total_steps": 5_000_000, "truncate_every": 1_000_000},
    },
}
