"""What a policy's return means: one word from its mean episode length and forward distance.

A return alone hides what the robot did: on Hopper about 1,000 in 1,000 steps can be a policy
that balances in place, and 360 one that lunges forward and falls after 136 steps. The end of
training summary (`adarl.report.summary`) and the report's behaviour table
(`adarl.report.scores.behaviour_section`) both describe a policy with `describe`, from the mean
over its evaluation episodes of the episode length (out of the time limit) and of the forward
distance of the root body (recorded by `adarl evaluate`; NaN when only the training log exists):

* **falls**: the episodes end early, by termination (mean length below `FULL_LENGTH` of the
  limit), and the policy does not travel far in a long episode (below);
* **stands**: the episodes run to the limit but the robot moves less than `MOVING_DISTANCE`
  metres (a Hopper that only balances drifts well under 1 m in 1,000 steps);
* **moves**: the episodes are long (at least `LONG_LENGTH` of the limit) and the robot travels at
  least `MOVING_DISTANCE` metres (in the 100k-step Hopper and Walker2d runs of
  docs/experiments/repro-*, seeds that hop or walk travel 5.1–12.6 m in 518–1,000 steps, seeds
  that fall 0.6–4.9 m in 72–425 steps, seeds that stand 0.5–0.8 m in 1,000);
* **stands or moves**: the episodes run to the limit and the distance was not recorded, so
  standing and moving cannot be told apart.

The thresholds are set once here and documented in docs/evaluation.md.
"""

from __future__ import annotations

import math

FULL_LENGTH = 0.95  # mean length ≥ 95% of the limit: the episodes run to the time limit
LONG_LENGTH = 0.5  # mean length ≥ half the limit: long enough for a travelling policy to "move"
MOVING_DISTANCE = 3.0  # metres over an episode: at least this far is moving, less is standing
WORDS = ("falls", "stands", "moves", "stands or moves")


def describe(length: float, max_length: float, distance: float = math.nan) -> str:
    """One of `WORDS` for a policy whose episodes last `length` steps on average out of
    `max_length`, travelling `distance` metres forward (NaN: not recorded)."""
    fraction = length / max_length
    known = math.isfinite(distance)
    if known and fraction >= LONG_LENGTH and distance >= MOVING_DISTANCE:
        return "moves"
    if fraction < FULL_LENGTH:
        return "falls"
    return "stands" if known else "stands or moves"


MEANING = {
    "falls": "episodes end early by termination",
    "stands": f"full length, less than {MOVING_DISTANCE:g} m forward",
    "moves": f"long episodes, at least {MOVING_DISTANCE:g} m forward",
    "stands or moves": "full length; the forward distance would tell which",
}


def plural(word: str) -> str:
    """`word` (one of `WORDS`) for several seeds: falls → fall, stands or moves → stand or
    move."""
    return " ".join(w[:-1] if w.endswith("s") else w for w in word.split(" "))


def rule_text() -> str:
    """The rule of `describe` in one line, for tables and the docs."""
    return (
        f"moves: mean length at least {LONG_LENGTH:.0%} of the limit and {MOVING_DISTANCE:g} m "
        f"or more forward; otherwise falls: mean length below {FULL_LENGTH:.0%} of the limit; "
        f"stands: full length, under {MOVING_DISTANCE:g} m; stands or moves: full length, distance "
        "not recorded"
    )
