"""RNAC's config and presets, JAX-free: `RNACConfig` (`RunConfig` plus the uncertainty set and
PPO's hyperparameters, defaults of the public RNAC code) and `PRESETS`. The maths is
`adarl.algos.rnac`.
"""

from __future__ import annotations

from dataclasses import dataclass

from adarl.algos.config import RunConfig
from adarl.errors import UsageError, check_choice

UNCERTAINTY_SETS = ("ds", "ipm")


@dataclass(frozen=True)
class RNACConfig(RunConfig):
    """An RNAC run: `RunConfig`'s fields (the budget, evaluation and logging defaults of the
    public RNAC code) plus every hyperparameter of RNAC. Defaults: that code's settings."""

    algo: str = "rnac"  # the algorithm (adarl train --algo)
    total_steps: int = 3_000_000  # environment steps per seed
    # --- uncertainty set
    uncertainty_set: str = "ds"  # ds (double sampling) or ipm
    # ds: P(take the worst-valued candidate). The original draws one of n+1 outcomes, outcome n
    # being "the worst", i.e. δ = 1/(n+1) = 1/3 for its 2 candidates.
    delta: float = 1.0 / 3.0
    n_candidates: int = 2  # ds: candidate next states drawn per step
    # ds: simulate and value the candidates at every step, as the original does, instead of only
    # on the steps that take the worst case (same transitions, more simulator steps)
    eager_candidates: bool = False
    action_noise: float = 5e-3  # uniform ±noise on every executed action (both sets)
    weight_reg: float = 1e-5  # ipm: TD residual −= weight_reg·‖θ_V‖₂ (ds: 0, as the original)
    # --- PPO (the original's tricks 1-10)
    hidden: tuple[int, ...] = (64, 64)  # hidden layer widths (tanh) of actor and critic
    rollout_steps: int = 2048  # "batch_size" of the original: env steps per seed per update
    minibatch_size: int = 64  # samples per gradient step
    epochs: int = 10  # passes over each rollout
    clip_eps: float = 0.2  # PPO's clip range ε
    gamma: float = 0.99  # discount factor
    gae_lambda: float = 0.95  # GAE's λ
    lr: float = 3e-4  # actor and critic
    lr_decay: bool = True  # linear to 0 at total_steps
    adam_eps: float = 1e-5  # Adam's ε
    max_grad_norm: float = 0.5  # gradients are clipped to this global norm
    ent_coef: float = 0.01  # entropy bonus coefficient
    init_log_std: float = 0.0  # initial log standard deviation of the policy
    norm_adv: bool = True  # normalise the advantages over each rollout
    obs_norm: bool = True  # normalise observations by a running mean and variance
    obs_clip: float = 10.0  # normalised observations are clipped to ±obs_clip
    reward_scaling: bool = True  # divide rewards by the running std of the discounted return
    # --- evaluation, logging, checkpoints (in environment steps per seed)
    eval_every: int = 5000  # environment steps between evaluations
    eval_episodes: int = 3  # deterministic episodes per seed and evaluation dynamics
    log_every: int = 2048  # environment steps between train.csv rows
    checkpoint_every: int = 100_000  # environment steps between checkpoints

    def validate(self) -> RNACConfig:
        """Raise a one-line UsageError on any bad value; return self."""
        super().validate()
        check_choice("algo", self.algo, ("rnac",))
        check_choice("uncertainty set", self.uncertainty_set, UNCERTAINTY_SETS)
        if not (0.0 <= self.delta <= 1.0):
            raise UsageError(f"delta must be in [0, 1], got {self.delta}")
        if self.n_candidates < 1:
            raise UsageError(f"n-candidates must be ≥ 1, got {self.n_candidates}")
        positive = [
            "rollout_steps",
            "minibatch_size",
            "epochs",
            "lr",
            "clip_eps",
            "adam_eps",
            "max_grad_norm",
            "obs_clip",
        ]
        for name in positive:
            if not getattr(self, name) > 0:
                raise UsageError(f"{name.replace('_', '-')} must be > 0, got {getattr(self, name)}")
        for name in ("action_noise", "weight_reg", "ent_coef"):
            if not getattr(self, name) >= 0:
                raise UsageError(f"{name.replace('_', '-')} must be ≥ 0, got {getattr(self, name)}")
        if self.rollout_steps % self.minibatch_size:
            raise UsageError(
                f"rollout-steps ({self.rollout_steps}) must be a multiple of minibatch-size "
                f"({self.minibatch_size})"
            )
        if self.rollout_steps < 2:
            raise UsageError(f"rollout-steps must be ≥ 2, got {self.rollout_steps}")
        if not 0.0 < self.gamma <= 1.0:
            raise UsageError(f"gamma must be in (0, 1], got {self.gamma}")
        if not 0.0 <= self.gae_lambda <= 1.0:
            raise UsageError(f"gae-lambda must be in [0, 1], got {self.gae_lambda}")
        if not self.hidden or any(h < 1 for h in self.hidden):
            raise UsageError(f"hidden sizes must be ≥ 1, got {list(self.hidden)}")
        return self


PRESETS: dict[str, dict] = {
    # the (= the public RNAC code's) settings, double sampling
    "default": {},
    # the same with the IPM uncertainty set
    "ipm": {"uncertainty_set": "ipm"},
    # the AdaRL paper's environments as its OMPO code ran them (as sac's `paper-ompo`)
    "paper-ompo": {"dynamics": "ompo", "physics": "ompo", "model_version": "v4"},
    # tiny budgets for tests and smoke runs
    "smoke": {
        "total_steps": 2048,
        "rollout_steps": 256,
        "minibatch_size": 64,
        "epochs": 2,
        "eval_every": 1024,
        "eval_episodes": 1,
        "log_every": 256,
        "checkpoint_every": 1024,
    },
}
