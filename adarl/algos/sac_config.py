"""The SAC family's config and presets, JAX-free: `SAC_FAMILY` (the fields that make each of
`sac`, `adarl`, `adarl-control`, `sac-fixed-rank`, `sac-parseval`, `sac-sparse`), `SACConfig`
(`RunConfig` plus SAC's and AdaRL's hyperparameters) and `PRESETS`. The maths that reads them is
`adarl.algos.sac`; `adarl.algos.registry` lists them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from adarl.algos.config import BudgetRule, RunConfig
from adarl.errors import UsageError, check_choice
from adarl.nets.choices import ACTIVATIONS, INITS, LR_SCHEDULES, RANK_RULES

# the config fields that define each algorithm of the family (applied before presets and flags)
SAC_FAMILY: dict[str, dict] = {
    "sac": {},
    "adarl": {"bottleneck": ("actor:1", "critic:1"), "adapt_rank": True},
    # AdaRL's schedule-matched control: the same truncations (SVD re-parameterisation, resets,
    # warm-up), the rule's rank logged but never applied (docs/algorithms.md)
    "adarl-control": {
        "bottleneck": ("actor:1", "critic:1"),
        "adapt_rank": True,
        "apply_cuts": False,
    },
    "sac-fixed-rank": {"bottleneck": ("actor:1", "critic:1"), "adapt_rank": False},
    "sac-parseval": {"parseval_coef": 1e-4, "init": "orthogonal"},
    "sac-sparse": {"sparse_width": 1024},
}

BACKENDS = ("host", "device")
# what the device backend (adarl.train.device_learner) trains: the four tasks' v5 models (Ant's
# and Humanoid's physics differ from MuJoCo C's, docs/envs.md "Device physics") under every
# dynamics schedule (Gymnasium's own `default`; a schedule's models, compiled as the
# host's `consistent` physics compiles them, per episode for `paper`, `ompo`, `uniform`), every
# algorithm of the SAC family (RNAC is not: adarl.device.NOT_ON_DEVICE)
DEVICE_TASKS = ("hopper", "walker2d", "ant", "humanoid")
DEVICE_DYNAMICS = ("default", "nominal", "fixed", "paper", "ompo", "uniform")
DEVICE_ALGOS = ("sac", "adarl", "adarl-control", "sac-fixed-rank", "sac-parseval", "sac-sparse")

# AdaRL's budget where the user sets none (no --total-steps / --truncate-every, flag or preset):
# the paper's d_t (10⁶ gradient steps, 0.7·10⁶ on Walker2d) and the `paper-table1` step budgets,
# so that a default run truncates (Hopper 2, the others 4 times); a flat 10⁶ steps would not.
ADARL_TASK_DEFAULTS: dict[str, dict] = {
    "hopper": {"total_steps": 3_000_000, "truncate_every": 1_000_000},
    "walker2d": {"total_steps": 3_000_000, "truncate_every": 700_000},
    "ant": {"total_steps": 5_000_000, "truncate_every": 1_000_000},
    "humanoid": {"total_steps": 5_000_000, "truncate_every": 1_000_000},
    # any other task (registry.OTHER_TASKS): the paper's budget/d_t of Ant and Humanoid, 5, on
    # 1M steps: four cuts, 200k updates apart (BUDGET_RULES scale d_t with any other budget)
    "*": {"total_steps": 1_000_000, "truncate_every": 200_000},
}


@dataclass(frozen=True)
class SACConfig(RunConfig):
    """A SAC-family run: `RunConfig`'s fields plus every hyperparameter of SAC and AdaRL.
    Defaults: the AdaRL paper's setting."""

    algo: str = "adarl"  # the algorithm (adarl train --algo)
    # host: Gymnasium's MuJoCo C tasks, each seed its own lane; device: the MJX task, every seed
    # vmapped into one jitted scan (a seed's numbers then depend on the seeds beside it;
    # docs/algorithms.md, "The device backend")
    backend: str = "host"
    # the device task's constraint solver: "xml" (the task XML's, the physics of docs/envs.md) or
    # "ITERATIONS,LS_ITERATIONS" capped for speed (100,4 matched MuJoCo C as xml does; 1,4, as
    # MuJoCo Playground's MJX models, is a different physics); runs of different solvers never
    # share a report. With --backend device and none given: 100,4 for hopper and walker2d (their
    # float64 comparison against MuJoCo C passes capped), xml for ant and humanoid
    device_solver: str = "xml"
    # --- SAC (paper appendix / Spinning Up)
    hidden: tuple[int, ...] = (64, 64)  # hidden layer widths of actor and critics
    activation: str = "relu"  # hidden-layer activation
    lr_actor: float = 3e-3  # Adam learning rate of the actor
    lr_critic: float = 3e-3  # Adam learning rate of the critics
    gamma: float = 0.99  # discount factor
    polyak: float = 0.995  # target networks: θ' ← polyak·θ' + (1 − polyak)·θ after each update
    batch_size: int = 256  # replay samples per gradient step
    buffer_size: int = 1_000_000  # replay buffer capacity per seed (transitions)
    start_steps: int = 10_000  # uniform random actions before this many steps
    update_after: int = 1_000  # no updates before this many steps
    update_every: int = 50  # env steps between update bursts; one update per env step overall
    alpha: float = 0.2  # entropy coefficient (initial value when autotuned)
    autotune_alpha: bool = False  # learn α to keep the policy entropy at target-entropy (SAC v2)
    target_entropy: float | None = None  # default −|A|
    lr_alpha: float = 3e-4  # Adam learning rate of log α (with autotune-alpha)
    init: str = "torch"  # torch (nn.Linear defaults) or orthogonal
    # --- bottleneck / rank adaptation (AdaRL)
    bottleneck: tuple[str, ...] = ()  # layers to factorise: "actor:1", "critic:1" (hidden→hidden)
    rank: int = 0  # initial (fixed-rank: constant) rank; 0 = full width
    # cut the bottlenecks' rank by SVD every truncate-every gradient steps (AdaRL)
    adapt_rank: bool = False
    truncate_every: int = 1_000_000  # d_t, in policy-optimisation (gradient) steps
    beta: float = 0.98  # the rank rule's threshold β (e.g. the energy kept by the cut)
    # energy (the default, docs/experiments/rank-rules.md), cumulative (the paper's Eq. 5),
    # ratio (Eq. 7), energy-squared
    rank_rule: str = "energy"
    # the retain clause: a cut is kept only if the truncated network's relative output error on
    # `retain_samples` replay rows is at most this; None (flag value `off`) accepts every cut
    retain_tolerance: float | None = None
    retain_samples: int = 1024  # replay rows the retain clause measures the output error on
    # envelope: one cosine over the whole run, warm-ups rise to it (ReLoRA); restart: a full
    # warm-up + cosine in every iteration of d_t steps
    lr_schedule: str = "envelope"
    warmup_steps: int = 2000  # learning-rate warm-up after each truncation
    lr_min_ratio: float = 0.1  # floor of the cosine decay, as a fraction of the learning rate
    schedule_first_iteration: bool = False  # warm-up + cosine before the first truncation too
    # after a truncation, narrow each seed's bottlenecks to their ranks and recompile its
    # update: cheaper updates for the rest of the run; False keeps full width, masked
    compact_bottlenecks: bool = True
    # false: AdaRL's schedule-matched control (--algo adarl-control): every truncation computes
    # and logs the rule's rank but re-parameterises each bottleneck at its old rank, with the same
    # optimiser and target resets and warm-up as AdaRL
    apply_cuts: bool = True
    # keep a checkpoint of the state just before each truncation in checkpoints/pre_truncation/
    # (never rotated away): where `adarl train --fork` can start a run that cuts differently
    checkpoint_before_truncation: bool = True
    # --- regularisers / architectures of the baselines
    parseval_coef: float = 0.0  # c in c·‖WWᵀ − sI‖²_F (sac-parseval)
    parseval_scale: float = 2.0  # s
    sparse_width: int = 0  # >0: one hidden layer this wide + a sparse-coding layer (sac-sparse)
    sparse_eta: float = 0.1  # ISTA step size η of the sparse-coding layer
    sparse_lambda: float = 0.1  # ISTA soft threshold λ of the sparse-coding layer

    def validate(self) -> SACConfig:
        """Raise a one-line UsageError on any bad value; return self."""
        super().validate()
        check_choice("algo", self.algo, SAC_FAMILY)
        check_choice("activation", self.activation, ACTIVATIONS)
        check_choice("init", self.init, INITS)
        check_choice("rank rule", self.rank_rule, RANK_RULES)
        check_choice("lr schedule", self.lr_schedule, LR_SCHEDULES)
        check_choice("backend", self.backend, BACKENDS)
        if self.backend == "device":
            self.check_device()
        elif self.device_solver != "xml":
            raise UsageError(
                f"device-solver applies to --backend device, got --device-solver "
                f"{self.device_solver} with --backend {self.backend}"
            )
        if self.retain_tolerance is not None and not (
            math.isfinite(self.retain_tolerance) and self.retain_tolerance > 0
        ):
            raise UsageError(
                f"retain-tolerance must be a finite number > 0 (or off), got {self.retain_tolerance}"
            )
        for name in (
            "batch_size",
            "buffer_size",
            "update_every",
            "truncate_every",
            "retain_samples",
        ):
            if getattr(self, name) <= 0:
                raise UsageError(f"{name.replace('_', '-')} must be > 0, got {getattr(self, name)}")
        for name in ("eval_every", "log_every", "checkpoint_every"):  # they fire between chunks
            if getattr(self, name) % self.update_every:
                raise UsageError(
                    f"{name.replace('_', '-')} must be a multiple of update-every "
                    f"({self.update_every}), got {getattr(self, name)}"
                )
        for name in ("start_steps", "update_after", "warmup_steps"):
            if getattr(self, name) < 0:
                raise UsageError(f"{name.replace('_', '-')} must be ≥ 0, got {getattr(self, name)}")
        if not 0.0 < self.beta < 1.0:
            raise UsageError(f"beta must be in (0, 1), got {self.beta}")
        if not 0.0 <= self.polyak <= 1.0:
            raise UsageError(f"polyak must be in [0, 1], got {self.polyak}")
        if not 0.0 < self.gamma <= 1.0:
            raise UsageError(f"gamma must be in (0, 1], got {self.gamma}")
        for name in ("lr_actor", "lr_critic", "lr_alpha", "alpha"):
            if getattr(self, name) <= 0:
                raise UsageError(f"{name.replace('_', '-')} must be > 0, got {getattr(self, name)}")
        if not 0.0 <= self.lr_min_ratio <= 1.0:
            raise UsageError(f"lr-min-ratio must be in [0, 1], got {self.lr_min_ratio}")
        if not self.hidden or any(h < 1 for h in self.hidden):
            raise UsageError(f"hidden sizes must be ≥ 1, got {list(self.hidden)}")
        if self.sparse_width < 0:
            raise UsageError(f"sparse-width must be ≥ 0 (0 = off), got {self.sparse_width}")
        if self.parseval_coef < 0:
            raise UsageError(f"parseval-coef must be ≥ 0, got {self.parseval_coef}")
        if self.algo == "sac-parseval" and self.parseval_coef <= 0:
            raise UsageError(
                f"parseval-coef must be > 0 for sac-parseval, got {self.parseval_coef}"
            )
        n_hidden_layers = len(self.hidden) - 1
        for spec in self.bottleneck:
            net, _, idx = spec.partition(":")
            allowed = [
                f"{n}:{i}" for n in ("actor", "critic") for i in range(1, n_hidden_layers + 1)
            ]
            if net not in ("actor", "critic") or not idx.isdigit() or spec not in allowed:
                raise UsageError(
                    f"bottleneck layer {spec!r} does not exist; allowed: {', '.join(allowed) or 'none'}"
                )
        if self.bottleneck and self.sparse_width:
            raise UsageError("bottleneck and sparse-width cannot be combined")
        width = min(self.hidden)
        if self.rank < 0 or self.rank > width:
            raise UsageError(f"rank must be in 1..{width} (0 = full width), got {self.rank}")
        if self.algo == "adarl-control" and self.apply_cuts:
            raise UsageError(
                "adarl-control is AdaRL without its cuts: apply-cuts must be false for it"
            )
        if not self.apply_cuts and self.algo != "adarl-control":
            raise UsageError(
                f"apply-cuts false is AdaRL's schedule-matched control: train it as --algo "
                f"adarl-control, not {self.algo} (a fork with --apply-cuts false switches itself)"
            )
        if self.algo == "sac-fixed-rank" and self.rank < 1:
            raise UsageError(f"sac-fixed-rank needs --rank in 1..{width}, got {self.rank}")
        if self.target_entropy is not None and not math.isfinite(self.target_entropy):
            raise UsageError(f"target-entropy must be finite, got {self.target_entropy}")
        return self

    def check_device(self) -> None:
        """What the device backend trains (one-line UsageError otherwise)."""
        check_choice("task for --backend device", self.task, DEVICE_TASKS)
        check_choice(
            "dynamics for --backend device", self.dynamics.partition(":")[0], DEVICE_DYNAMICS
        )
        if self.dynamics != "default":  # the device's models are compiled as the host's default
            check_choice("physics for --backend device", self.physics, ("consistent",))
        check_choice("model version for --backend device", self.model_version, ("v5",))
        check_choice("algo for --backend device", self.algo, DEVICE_ALGOS)
        check_device_solver(self.device_solver)
        from adarl.device.tasks import solver_caps

        solver_caps(self.device_solver)


#: On a task outside the paper's four, AdaRL's d_t and every SAC-family run's random-action
#: warm-up follow --total-steps where neither a flag nor the preset sets them (issue 62): d_t =
#: total-steps / 5 gradient steps, four cuts in the budget (the paper's 5M steps / 10⁶ on Ant and
#: Humanoid; claim 2's 100k / 20k), and the warm-up 5% of the budget, at most the paper's
#: 10,000 (claim 2's 5k of 100k). At the default 1M steps they are 200,000 and 10,000, as before.
#: The resolved values are config.yaml's: a resume reads them, never recomputes them.
TRUNCATE_EVERY_RULE = BudgetRule("total-steps / 5", lambda total: max(total // 5, 1))
START_STEPS_RULE = BudgetRule(
    f"5% of total-steps, at most {SACConfig.start_steps:,}",
    lambda total: min(total // 20, SACConfig.start_steps),
)


def budget_rules(algo: str) -> dict[str, BudgetRule]:
    """The fields of a SAC-family `algo` that follow the budget on other tasks."""
    rules = {"start_steps": START_STEPS_RULE}
    if SAC_FAMILY.get(algo, {}).get("adapt_rank"):
        rules["truncate_every"] = TRUNCATE_EVERY_RULE
    return rules


#: the most iterations `--device-solver` takes, each (MuJoCo's defaults: 100 and 50)
MAX_SOLVER_ITERATIONS = 10_000


def check_device_solver(value: str) -> None:
    """`--device-solver` is "xml" or "I,L", each an ASCII integer from 1 to
    `MAX_SOLVER_ITERATIONS` (`str.isdigit` also takes "²", which `int` refuses, and MuJoCo's C
    int no 20-digit number); else a one-line UsageError (issue 55)."""
    parts = str(value).split(",")
    if value == "xml" or (
        len(parts) == 2
        and all(
            p.strip().isascii() and p.strip().isdigit() and 1 <= int(p) <= MAX_SOLVER_ITERATIONS
            for p in parts
        )
    ):
        return
    raise UsageError(
        f"device-solver must be 'xml' or 'ITERATIONS,LS_ITERATIONS' (integers from 1 to "
        f"{MAX_SOLVER_ITERATIONS:,}, e.g. 100,4), got {value!r}"
    )


PRESETS: dict[str, dict] = {
    # The AdaRL paper's appendix: (64, 64) ReLU, lr 3e-3, fixed α = 0.2, Spinning Up's schedule.
    "paper": {},
    # Spinning Up's own SAC defaults (its sac() signature).
    "spinningup": {
        "hidden": (256, 256),
        "lr_actor": 1e-3,
        "lr_critic": 1e-3,
        "batch_size": 100,
        "start_steps": 10_000,
        "update_after": 1_000,
        "update_every": 50,
    },
    # Hopper with paper dynamics in under 15 minutes on a 2-core machine.
    "quickstart": {
        "task": "hopper",
        "dynamics": "paper",
        "total_steps": 150_000,
        "truncate_every": 30_000,
        "start_steps": 5_000,
        "eval_every": 10_000,
        "log_every": 5_000,
        "checkpoint_every": 25_000,
        "buffer_size": 200_000,
    },
    # Parseval coefficients the paper tunes over (with --algo sac-parseval)
    "parseval-1e-3": {"parseval_coef": 1e-3},
    "parseval-1e-4": {"parseval_coef": 1e-4},
    "parseval-1e-5": {"parseval_coef": 1e-5},
    # The closest reproduction of what the paper ran: OMPO's schedules (Hopper amplitude 0.1),
    # lengths written into the compiled model as OMPO does (default masses), Gymnasium's v4 models
    # (the port of the Gym v3 tasks). Hyperparameters as `paper`. See docs/envs.md.
    "paper-ompo": {"dynamics": "ompo", "physics": "ompo", "model_version": "v4"},
    # tiny budgets for tests and smoke runs
    "smoke": {
        "total_steps": 2_000,
        "start_steps": 500,
        "update_after": 500,
        "update_every": 50,
        "truncate_every": 500,
        "warmup_steps": 100,
        "eval_every": 1_000,
        "eval_episodes": 1,
        "log_every": 500,
        "checkpoint_every": 1_000,
        "buffer_size": 5_000,
        "batch_size": 64,
        "max_episode_steps": 200,
    },
}
