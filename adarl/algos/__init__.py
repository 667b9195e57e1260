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
