"""The training timeline of every algorithm, in one JAX-free place: SAC's chunks of updates, the
gradient steps of a run, AdaRL's truncation steps and the update counts they fall at, and the
learning rate of every algorithm (SAC's envelope and restart schedules, RNAC's linear decay).

The learners (`adarl.train.sac_learner`, `adarl.train.rnac_learner`), forks (`adarl.train.fork`),
sweeps and their estimate (`adarl.sweeps.spec`), `adarl tasks` and the figures read it; none of
them needs JAX for this integer maths. SAC's jitted update computes its learning rate on the
device from the counters it carries (`n_updates`, `iteration_start`, `n_truncations`) with
`learning_rate(…, xp=jax.numpy)`: the same formula, written once over the array module.
"""

from __future__ import annotations

import numpy as np

from adarl.schedules import envelope_learning_rate, restart_learning_rate


# ============================================================================ SAC: chunks
def chunk_end(config, step: int) -> int:
    """The step at which the chunk after environment step `step` ends: chunk k ends at
    min(k·update_every, total_steps)."""
    c = config
    return min((step // c.update_every + 1) * c.update_every, c.total_steps)


def chunk_updates(config, end: int) -> bool:
    """Does the chunk ending at step `end` make its `update_every` gradient steps (it ends at or
    after `update_after`)?"""
    return end >= config.update_after


def updating_chunks(config) -> range:
    """The chunks of a run that make gradient steps, as the loop runs them: chunk k (k ≥ 1) ends
    at step min(k·update_every, total_steps) and runs `update_every` updates if it ends at or
    after `update_after`."""
    c = config
    if c.update_after > c.total_steps:
        return range(0)
    n_chunks = -(-c.total_steps // c.update_every)
    return range(max(-(-c.update_after // c.update_every), 1), n_chunks + 1)


def total_updates(config) -> int:
    """Gradient steps in a whole run: `update_every` per updating chunk."""
    return len(updating_chunks(config)) * config.update_every


# ============================================================================ AdaRL: truncations
def chunks_per_iteration(config) -> int:
    """Updating chunks between two truncations: ⌈d_t / update_every⌉ (an iteration of d_t
    gradient steps rounded up to whole chunks)."""
    return -(-config.truncate_every // config.update_every)


def truncation_steps(config) -> list[int]:
    """The environment steps at which a run of this config truncates, as the loop finds them: a
    truncation follows the chunk after which the updates since the last one reach d_t, i.e. every
    ⌈d_t / update_every⌉-th updating chunk (an iteration of d_t rounded up to update_every)."""
    if not getattr(config, "adapt_rank", False):
        return []
    c = config
    per_iteration = chunks_per_iteration(c)
    chunks = updating_chunks(c)[per_iteration - 1 :: per_iteration]
    return [min(chunk * c.update_every, c.total_steps) for chunk in chunks]


def n_truncations(config) -> int:
    """How many truncations a run of this config makes."""
    return len(truncation_steps(config))


def truncation_updates(config) -> list[int]:
    """The gradient steps made before each truncation (the device's `iteration_start` after it)."""
    period = chunks_per_iteration(config) * config.update_every
    return [k * period for k in range(1, n_truncations(config) + 1)]


def counters(config, updates) -> dict[str, np.ndarray]:
    """The counters the jitted update carries after `updates` gradient steps (an array):
    `n_updates`, `n_truncations` made before and `iteration_start`, the update count at the last
    one."""
    updates = np.asarray(updates)
    cuts = truncation_updates(config)
    made = np.searchsorted(np.asarray(cuts, dtype=np.int64), updates, side="right")
    return {
        "n_updates": updates,
        "n_truncations": made,
        "iteration_start": np.concatenate([[0], cuts]).astype(np.int64)[made],
    }


# ============================================================================ learning rates
def learning_rate(config, base_lr: float, state, xp=np):
    """SAC's learning rate at the counters in `state` (`n_updates`, `iteration_start`,
    `n_truncations`), computed with the array module `xp` (NumPy, or `jax.numpy` inside the
    jitted update). Without rank adaptation it is constant. With it, `lr_schedule` decides:
    `envelope` (default) follows one cosine over the run's gradient steps and warms up to it
    after each truncation (`envelope_learning_rate`, ReLoRA); `restart` is constant before the
    first truncation and a full warm-up + cosine over each iteration of d_t steps after it
    (`restart_learning_rate`). `schedule_first_iteration` warms up at the start too."""
    c = config
    if not c.adapt_rank:
        return xp.asarray(base_lr, xp.float32)
    if c.lr_schedule == "envelope":
        warm_up = state["n_truncations"] > 0
        if c.schedule_first_iteration:
            warm_up = xp.asarray(True)
        return envelope_learning_rate(
            state["n_updates"],
            state["iteration_start"],
            base_lr,
            c.warmup_steps,
            total_updates(c),
            c.lr_min_ratio,
            warm_up,
            xp,
        )
    t = state["n_updates"] - state["iteration_start"]
    scheduled = restart_learning_rate(
        t, base_lr, c.warmup_steps, c.truncate_every, c.lr_min_ratio, xp
    )
    if c.schedule_first_iteration:
        return scheduled
    return xp.where(state["n_truncations"] > 0, scheduled, base_lr)


def rnac_learning_rate(config, step: int) -> float:
    """RNAC's learning rate for the update at the end of the rollout ending at step `step`: it
    decays linearly from the previous update's step, as in the original (`lr_decay`)."""
    if not config.lr_decay:
        return config.lr
    return config.lr * (1.0 - (step - config.rollout_steps) / config.total_steps)


# ============================================================================ the budget, in words
#: A warm-up of more than this share of the budget is "mostly random" (said plainly, issue 62).
MOSTLY_RANDOM = 0.5


def budget_words(config) -> tuple[list[str], list[str]]:
    """What a run's budget gives, as `adarl train`'s start line and summary say it (issue 62):
    (facts, warnings). Facts: AdaRL's cuts (how many, d_t, the steps they fall at) and the
    random-action warm-up, each with the rule it follows where it follows one (a task outside
    the paper's four, `registry.resolve_config`); an algorithm without them has none. Warnings,
    one line each: a rank-adaptive budget with no cut, a budget that is mostly random warm-up."""
    from adarl.algos import registry
    from adarl.algos.config import follows_budget

    entry = registry.ALGORITHMS.get(str(getattr(config, "algo", "")))
    rules = dict(entry.budget_rules) if entry and follows_budget(config.task) else {}

    def rule_of(name: str) -> str:
        rule = rules.get(name)
        value = getattr(config, name)
        return f" = {rule.text}" if rule and rule.value(config.total_steps) == value else ""

    facts, warnings = [], []
    total = config.total_steps
    if getattr(config, "adapt_rank", False):
        steps = truncation_steps(config)
        d_t = f"d_t{rule_of('truncate_every')}"
        where = ", ".join(f"{s:,}" for s in steps[:6]) + (", …" if len(steps) > 6 else "")
        if steps:
            facts.append(
                f"{len(steps)} cut{'s' if len(steps) != 1 else ''} of the rank, every "
                f"{config.truncate_every:,} gradient steps ({d_t}), at step"
                f"{'s' if len(steps) > 1 else ''} {where}"
            )
        else:
            facts.append(f"no cut of the rank ({d_t}: {config.truncate_every:,} gradient steps)")
            warnings.append(
                f"no cut: this run makes {total_updates(config):,} gradient steps (updates "
                f"begin at step {config.update_after:,} of {total:,}), fewer than d_t = "
                f"{config.truncate_every:,}: the rank never adapts and AdaRL trains as SAC; "
                "give a smaller --truncate-every or more --total-steps"
            )
    if hasattr(config, "start_steps"):
        start = config.start_steps
        facts.append(
            f"random-action warm-up for the first {min(start, total):,} steps "
            f"(start-steps{rule_of('start_steps')})"
        )
        if start >= total:
            warnings.append(
                f"all random: start-steps {start:,} ≥ total-steps {total:,}: every step takes "
                "uniform random actions and the policy never acts; give a smaller --start-steps"
            )
        elif start > MOSTLY_RANDOM * total:
            warnings.append(
                f"mostly random: the first {start:,} of {total:,} steps ({start / total:.0%}) take "
                f"uniform random actions (start-steps); the policy acts in only {total - start:,}"
            )
    return facts, warnings
