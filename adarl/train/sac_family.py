"""What the SAC family's two learners share: `SACFamily`, the one base of the host learner
(`adarl.train.sac_learner.SACLearner`, a lane per seed) and the device learner
(`adarl.train.device_learner.DeviceSACLearner`, every seed in one vmapped state).

The base holds what a SAC-family run is whatever its backend: the spec and bottleneck layers,
the truncation steps, train.csv's and truncations.csv's columns, the memory check and the check
of the evaluation dynamics made before anything is written, and what the loop reads back (the
train.csv rows, the policies, the divergence watch's quantities, the truncations.csv rows). A
learner gives the base its per-seed values through six methods (`take_metric_means`,
`seed_ranks`, `seed_diagnostics`, `seed_finite`, `seed_actors`, `episode_returns`); how it
stores its seeds is its own.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from adarl.algos import replay, sac, schedule
from adarl.runs import layout
from adarl.train.guards import check_device_memory, check_training_memory, nonfinite_seeds

LEGACY_TRUNCATION_COLUMNS = ["step", "seed", "layer", "old_rank", "proposed_rank", "new_rank"]
# proposed_rank: the rule's r̂; candidate_rank: max(1, min(old, r̂)); error: the candidate's
# relative output error on the replay sample; decision: accepted, retained, unchanged or control
# (adarl-control: logged, not applied)
TRUNCATION_COLUMNS = [*LEGACY_TRUNCATION_COLUMNS, "candidate_rank", "error", "decision"]
BASE_COLUMNS = [
    "step",
    "seed",
    "steps_per_s",
    "loss_q",
    "loss_pi",
    "alpha",
    "entropy",
    "q_mean",
    "lr",
]
# the update metrics averaged into train.csv as they are, and those the divergence watch reads
ROW_METRICS = ("loss_q", "loss_pi", "alpha", "entropy", "q_mean", "lr")
WATCHED_METRICS = ("loss_q", "loss_pi", "q_mean", "alpha", "entropy")


class SACFamily:
    """The part of a SAC-family learner that does not depend on its backend (see the module)."""

    def setup(self, config, obs_dim: int, act_dim: int, act_low, act_high) -> None:
        """The run's spec, layers, truncation steps and log columns (called first by `__init__`)."""
        self.config = config
        self.algo = config.algo
        self.seeds = list(config.seeds)
        self.n = len(self.seeds)
        self.env_options = config.env_options()
        self.spec = sac.make_spec(config, obs_dim, act_dim, act_low, act_high)
        self.layer_names = sac.bottleneck_names(config)
        self.truncation_steps = set(schedule.truncation_steps(config))
        self.metric_means: dict | None = None  # of the latest train.csv rows, per seed
        extra = ["parseval_penalty"] if config.parseval_coef > 0 else []
        extra += ["active_fraction"] if config.sparse_width else []
        self.train_columns = (
            BASE_COLUMNS + extra + [layout.rank_column(n) for n in self.layer_names]
        )
        # AdaRL's truncations.csv (a run from before the retain clause keeps its columns)
        self.extra_logs = (
            {layout.TRUNCATIONS_CSV: (TRUNCATION_COLUMNS, LEGACY_TRUNCATION_COLUMNS)}
            if config.adapt_rank
            else {}
        )

    def check_memory(self, extra_bytes: int = 0, device: bool = False) -> None:
        """The memory check before the networks exist: every seed's replay buffer and SAC state
        (and `extra_bytes`, the device's physics rows), in host memory and, for the device
        backend (`device`), in the accelerator's."""
        c = self.config
        memory = (
            self.n,
            self.n * c.buffer_size * replay.row_bytes(self.spec.obs_dim, self.spec.act_dim),
            self.n * sac.state_bytes(self.spec) + extra_bytes,
            f"lower --buffer-size ({c.buffer_size}) or --hidden "
            f"({','.join(map(str, c.hidden))}), or train fewer seeds per run",
        )
        check_training_memory(*memory)
        if device:
            check_device_memory(*memory)

    def check_eval_dynamics(self) -> None:
        """Make each evaluation dynamics' environment once, so that a bad label fails now, not
        at the first evaluation (the host evaluates every backend's policies)."""
        from adarl.envs import make

        for label in self.config.eval_dynamics:
            options = self.env_options | {"max_episode_steps": 1}
            make(self.config.task, dynamics=label, seed=0, **options).close()

    # ------------------------------------------------------------------ per-seed values
    def take_metric_means(self) -> dict | None:
        """The update metrics since the last train.csv rows averaged per seed (name -> (seeds,)),
        forgetting them; None when no update ran since."""
        raise NotImplementedError

    def seed_ranks(self) -> dict:
        """Each bottleneck's rank per seed (layer -> (seeds,))."""
        raise NotImplementedError

    def seed_diagnostics(self) -> dict:
        """sac-sparse's `active_fraction` per seed (`{}` for the others)."""
        raise NotImplementedError

    def seed_finite(self) -> dict:
        """`finite_parameters` per seed (quantity -> (seeds,) flags)."""
        raise NotImplementedError

    def seed_actors(self) -> list[tuple[sac.Spec, dict, dict]]:
        """Each seed's (spec, actor parameters, actor masks) on the host, without a seed axis."""
        raise NotImplementedError

    def episode_returns(self) -> np.ndarray:
        """Each seed's return of its current episode so far."""
        raise NotImplementedError

    # ------------------------------------------------------------------ what the loop reads
    def train_rows(self, step: int, steps_per_s: float) -> list[dict]:
        """One train.csv row per seed: the update metrics averaged since the last rows, the
        ranks and diagnostics (none before the first update)."""
        mean = self.take_metric_means()
        if mean is None:
            return []
        self.metric_means = mean
        ranks = self.seed_ranks()
        diagnostics = self.seed_diagnostics() if self.config.sparse_width else {}
        rows = []
        for i, seed in enumerate(self.seeds):
            row = {"step": step, "seed": seed, "steps_per_s": steps_per_s}
            row.update({k: mean[k][i] for k in ROW_METRICS})
            if self.config.parseval_coef > 0:
                row["parseval_penalty"] = mean["penalty_actor"][i] + mean["penalty_critic"][i]
            if self.config.sparse_width:
                row["active_fraction"] = diagnostics["active_fraction"][i]
            row.update({layout.rank_column(n): int(ranks[n][i]) for n in self.layer_names})
            rows.append(row)
        return rows

    def policies(self) -> list[dict]:
        """Each seed's deterministic policy (its actor's arrays, bottlenecks compacted)."""
        return [sac.export_policy(spec, actor, masks) for spec, actor, masks in self.seed_actors()]

    def parameters_finite(self) -> bool:
        return all(np.all(ok) for ok in self.seed_finite().values())

    def nonfinite(self, step: int) -> dict[str, list[int]]:
        """Non-finite update metrics of the latest train.csv rows, parameters, optimiser states
        or returns, by quantity (only quantities with seeds)."""
        found = {}
        if self.metric_means is not None:
            for key in WATCHED_METRICS:
                found[key] = nonfinite_seeds(self.seeds, self.metric_means[key])
        for name, ok in self.seed_finite().items():
            found[name] = [s for s, o in zip(self.seeds, ok) if not o]
        found["episode return"] = nonfinite_seeds(self.seeds, self.episode_returns())
        return {quantity: bad for quantity, bad in found.items() if bad}


def truncation_rows(
    step: int, seeds, old: dict, report: dict, apply_cuts: bool
) -> tuple[dict[str, np.ndarray], list[dict]]:
    """A truncation's spectra (one row per seed) and its truncations.csv rows, one per layer and
    seed, from `sac.truncate`'s report (singular values, proposed, new and candidate rank, error
    per layer, seeds stacked) and the ranks before it (`old`)."""
    spectra = {name: np.asarray(item[0]) for name, item in report.items()}
    rows = []
    for name, (_, proposed, new, candidate, error) in report.items():
        for i, seed in enumerate(seeds):
            rows.append(
                {
                    "step": step,
                    "seed": seed,
                    "layer": name,
                    "old_rank": int(old[name][i]),
                    "proposed_rank": int(proposed[i]),
                    "new_rank": int(new[i]),
                    "candidate_rank": int(candidate[i]),
                    "error": float(error[i]),
                    "decision": truncation_decision(
                        int(old[name][i]), int(candidate[i]), int(new[i]), apply_cuts
                    ),
                }
            )
    return spectra, rows


def truncation_decision(
    old_rank: int, candidate_rank: int, new_rank: int, apply_cuts: bool = True
) -> str:
    """`accepted`: the rule's cut was made; `retained`: the retain clause kept the old rank;
    `control`: the schedule-matched control kept it (the cut was proposed, never applied);
    `unchanged`: the rule proposed no cut."""
    if candidate_rank >= old_rank:
        return "unchanged"
    if not apply_cuts:
        return "control"
    return "accepted" if new_rank == candidate_rank else "retained"


@jax.jit
def finite_parameters(state: dict) -> dict:
    """Per seed of a seed-stacked state: are all actor, critic and temperature parameters, and
    their optimisers' states (Adam's moments), finite? Keyed by the divergence watch's words."""

    def finite(tree):
        leaves = jax.tree_util.tree_leaves(tree)
        return jnp.stack([jnp.isfinite(x).reshape(x.shape[0], -1).all(axis=1) for x in leaves]).all(
            axis=0
        )

    return {
        "actor parameters": finite(state["actor"]),
        "critic parameters": finite(state["critic"]),
        "critic target parameters": finite(state["critic_target"]),
        "temperature parameters": finite(state["log_alpha"]),
        "actor optimiser state": finite(state["opt_actor"]),
        "critic optimiser state": finite(state["opt_critic"]),
        "temperature optimiser state": finite(state["opt_alpha"]),
    }
