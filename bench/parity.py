"""Learning parity: adarl's `sac` against Stable-Baselines3's SAC on adarl's Hopper task.

Same hyperparameters, seeds, budget and evaluation for both; hours at the defaults:

    python bench/parity.py                     # 100k steps, seeds 0-2
    python bench/parity.py --steps 3000 --seeds 0-1 --eval-every 1500 --eval-episodes 1 \\
        --start-steps 1000 --update-after 500 --out /tmp/parity-smoke          # smoke test

Both train on `adarl.envs.make("hopper", dynamics="paper", seed=s)` (a new body every episode;
the same seed gives the same sequence of bodies and initial states) with the hyperparameters of
`adarl train --algo sac --preset paper` (`SACConfig`): (64, 64) ReLU actor and twin critics,
Adam lr 3e-3, batch 256, γ 0.99, polyak 0.995 (SB3 tau 0.005), fixed α 0.2, uniform random
actions for the first `start_steps` steps, no update before `update_after` steps, then 50 updates
after every 50 environment steps, 1000-step episodes with bootstrapping through the time limit.
Ours runs as `adarl train --algo sac` in a subprocess (all seeds in one process), SB3 as one
process per seed (`--sb3-procs` at a time, one torch thread each).

Every `--eval-every` steps, after that chunk's updates, each seed's deterministic policy
(tanh of the mean) runs `--eval-episodes` episodes on `nominal` dynamics through the same code for
both: `adarl.envs.rollout.run_episodes` with a `NumpyPolicy` and the evaluation seeds of our
trainer. SB3's actor is copied into that format and checked against its own `predict`.

Writes to --out: curves.csv (impl, seed, step, return = mean over the evaluation episodes),
parity.png (mean curves with 95% t bands over seeds), summary.md (final returns with stratified
bootstrap 95% CIs, the difference and P(adarl > SB3), wall times, and every known difference
between the two setups), and our run folder adarl-sac/. Wall times are of each implementation's
whole training including start-up, compilation and the periodic evaluations.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import io
import multiprocessing
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

from adarl.runtime import configure_xla  # noqa: E402

configure_xla()  # inherited by the `adarl train` subprocess

import numpy as np  # noqa: E402

from adarl import stats  # noqa: E402
from adarl.algos.flags import parse_int_list  # noqa: E402
from adarl.errors import UsageError  # noqa: E402
from adarl.files import atomic_write_bytes, atomic_write_text  # noqa: E402
from adarl.policy import file_arrays  # noqa: E402
from adarl.runs.layout import EVAL_CSV  # noqa: E402
from adarl.runs.logs import read_csv  # noqa: E402

# Heavy imports (JAX, torch) stay inside functions: SB3 workers are spawned processes that
# re-import this module, and they need neither JAX nor matplotlib.

TASK, TRAIN_DYNAMICS, EVAL_DYNAMICS = "hopper", "paper", "nominal"
EVAL_SEED_OFFSET = 1_000_000  # our trainer evaluates seed s with env seed 1_000_000 + s
IMPLS = {"adarl": "adarl `sac`", "sb3": "Stable-Baselines3 SAC"}
# settings both implementations take from the config (checked against our run's config.yaml)
SHARED = (
    "task",
    "dynamics",
    "physics",
    "model_version",
    "hidden",
    "activation",
    "lr_actor",
    "lr_critic",
    "batch_size",
    "buffer_size",
    "gamma",
    "polyak",
    "alpha",
    "autotune_alpha",
    "start_steps",
    "update_after",
    "update_every",
    "max_episode_steps",
    "init",
)

DIFFERENCES = [
    "**Random streams.** Initial weights are drawn from the same distribution in both (PyTorch's "
    "`nn.Linear` default, U(±1/√fan_in) for weights and biases; our `init: torch`), but from "
    "different generators (NumPy PCG64 vs torch), as are the warm-up actions (our per-seed NumPy "
    "generator vs SB3's seeded action space), the exploration noise and the minibatch indices "
    "(JAX keys vs NumPy's global generator). The environments are seeded identically: episode k "
    "of seed s has the same body and the same initial-state draw in both.",
    "**Warm-up.** SB3's one `learning_starts` means both 'random actions before' and 'no update "
    "before'. The SB3 side is a one-method subclass (`SpinningUpSAC._sample_action`) that draws "
    "uniform actions for the first `start_steps` steps, with `learning_starts = update_after − 1` "
    "(SB3 updates when `num_timesteps > learning_starts`, ours when the chunk ends at a step "
    "≥ update_after): both take their first 50 updates at the first multiple of 50 that is "
    "≥ update_after. No remaining difference.",
    "**Critic loss scale.** SB3 minimises 0.5·(MSE₁ + MSE₂), ours MSE₁ + MSE₂ (Spinning Up). "
    "Adam is invariant to a constant loss scale except through ε = 1e-8, so the updates are the "
    "same up to that.",
    "**tanh correction of log π.** SB3: Σ log(1 − tanh²(u) + 1e-6); ours: the exact, stable "
    "Σ 2(log 2 − u − softplus(−2u)). They differ only for saturated actions (|u| ≳ 6), where "
    "SB3's term is floored at log 1e-6 per dimension.",
    "**Order inside an update.** SB3 samples the actor's action ã ~ π(·|s) before the critic "
    "step and evaluates it on the just-updated critics; ours samples it after the critic step "
    "from the same, not yet updated actor. Same distribution, different noise draws; both "
    "update the actor against the just-updated critics, then the targets.",
    "**Replay storage.** SB3 keeps observations as float64 (the env's dtype) and converts to "
    "float32 for the networks; ours stores float32. Both treat time-limit truncation as "
    "non-terminal (SB3 `handle_timeout_termination=True`).",
    "**Processes and threads.** Ours trains all seeds in one process (seeds in lanes on one XLA "
    "CPU device per core, host-side acting); SB3 trains one seed per process, `--sb3-procs` at "
    "a time, `torch.set_num_threads(1)`. Wall times include start-up, our JIT compilation (its "
    "persistent cache may be warm), the periodic evaluations (the same code and episode counts "
    "for both, but episode lengths depend on the policy) and our final checkpoint.",
]


# ============================================================================ configuration
def parity_config(args: argparse.Namespace):
    """Our `sac` config under the `paper` preset with this benchmark's budget and evaluation."""
    from adarl.algos import sac_config
    from adarl.algos.sac_config import SAC_FAMILY

    values = {**SAC_FAMILY["sac"], **sac_config.PRESETS["paper"]}
    values.update(
        algo="sac",
        task=TASK,
        dynamics=TRAIN_DYNAMICS,
        seeds=tuple(args.seeds),
        total_steps=args.steps,
        eval_every=args.eval_every,
        eval_episodes=args.eval_episodes,
        eval_dynamics=(EVAL_DYNAMICS,),
        checkpoint_every=args.steps,  # one checkpoint, at the end (SB3 saves none)
        # never full at this budget, so a smaller buffer changes nothing but memory
        buffer_size=min(sac_config.SACConfig.buffer_size, args.steps),
    )
    if args.start_steps is not None:
        values["start_steps"] = args.start_steps
    if args.update_after is not None:
        values["update_after"] = args.update_after
    config = sac_config.SACConfig(**values)
    if args.steps % config.update_every:
        raise UsageError(f"--steps must be a multiple of {config.update_every}, got {args.steps}")
    return config.validate()


def cli_flags(config) -> list[str]:
    """`adarl train` flags that reproduce `config` on top of `--algo sac --preset paper`."""
    values = dataclasses.asdict(config)
    flags = []
    for name in ("task", "dynamics", "seeds", "total_steps", "eval_every", "eval_episodes",
                 "eval_dynamics", "checkpoint_every", "buffer_size", "start_steps",
                 "update_after"):  # fmt: skip
        value = values[name]
        text = ",".join(map(str, value)) if isinstance(value, tuple) else str(value)
        flags += [f"--{name.replace('_', '-')}", text]
    return flags


# ============================================================================ adarl
def train_adarl(config, run_dir: Path) -> tuple[dict[int, list], float]:
    """Train our `sac` through the CLI into `run_dir`; returns ({seed: [(step, return)]}, wall s)."""
    from adarl.runs.folder import load_config as load_run_config

    command = [sys.executable, "-m", "adarl.cli.main", "train", "--algo", "sac"]
    command += ["--preset", "paper", *cli_flags(config), "--out", str(run_dir), "--no-progress"]
    print("adarl: " + shlex.join(["adarl", *command[3:]]), flush=True)
    start = time.perf_counter()
    subprocess.run(command, check=True)
    wall = time.perf_counter() - start
    written = load_run_config(run_dir)
    for name in SHARED:  # the SB3 side is built from `config`: make sure ours ran with it
        mine = getattr(config, name)
        theirs = tuple(written[name]) if isinstance(written[name], list) else written[name]
        if theirs != mine:
            raise RuntimeError(f"{run_dir}/config.yaml has {name}={theirs!r}, expected {mine!r}")
    per_step: dict[tuple[int, int], list[float]] = {}
    for row in read_csv(run_dir / EVAL_CSV):
        if row["dynamics"] == EVAL_DYNAMICS:
            key = (int(row["seed"]), int(row["step"]))
            per_step.setdefault(key, []).append(float(row["return"]))
    curves: dict[int, list] = {}
    for (seed, step), returns in sorted(per_step.items()):
        curves.setdefault(seed, []).append((step, float(np.mean(returns))))
    return curves, wall


# ============================================================================ Stable-Baselines3
def env_kwargs(c: dict) -> dict:
    """`adarl.envs.make` arguments of our trainer's environments, for the config values `c`."""
    return {
        "max_episode_steps": c["max_episode_steps"],
        "physics": c["physics"],
        "model_version": c["model_version"],
    }


def sb3_policy_arrays(model) -> dict[str, np.ndarray]:
    """SB3's SAC actor (latent_pi MLP, mu head) as an `adarl.policy` file: same deterministic
    map obs -> low + (high − low)·(tanh(μ) + 1)/2."""
    actor = model.actor
    linears = [m for m in actor.latent_pi if hasattr(m, "weight")]
    space = model.action_space

    def numpy(t):
        return t.detach().cpu().numpy().astype(np.float32)

    layers = [("dense", numpy(layer.weight).T, numpy(layer.bias)) for layer in linears]
    mean = (numpy(actor.mu.weight).T, numpy(actor.mu.bias))
    return file_arrays(layers, mean, space.low, space.high, "relu")


def train_sb3(job: dict) -> dict:
    """Train one seed of SB3 SAC (a worker process); returns its curve and wall time (from
    before the imports of torch and SB3)."""
    start = time.perf_counter()
    import torch
    from stable_baselines3 import SAC
    from stable_baselines3.common.callbacks import BaseCallback

    from adarl.envs import make
    from adarl.envs.rollout import run_episodes
    from adarl.policy import NumpyPolicy

    torch.set_num_threads(1)
    c, seed = job["config"], job["seed"]

    class SpinningUpSAC(SAC):
        """SB3 SAC with uniform actions for the first `start_steps` steps (SB3 ties them to
        `learning_starts`, which here only delays the updates)."""

        start_steps = 0

        def _sample_action(self, learning_starts, action_noise=None, n_envs=1):
            return super()._sample_action(self.start_steps, action_noise, n_envs)

    class NominalEval(BaseCallback):
        """Deterministic evaluation every `every` steps, after that chunk's updates (at the
        start of the next rollout, or at the end of training), as our trainer does."""

        def __init__(self):
            super().__init__()
            self.curve, self.seconds = [], 0.0

        def _on_step(self) -> bool:
            return True

        def _on_rollout_start(self) -> None:
            if self.num_timesteps and self.num_timesteps % job["eval_every"] == 0:
                self.evaluate()

        def _on_training_end(self) -> None:
            if not self.curve or self.curve[-1][0] != self.num_timesteps:
                self.evaluate()

        def evaluate(self) -> None:
            start = time.perf_counter()
            policy = NumpyPolicy(sb3_policy_arrays(self.model))
            probe = np.random.default_rng(0).normal(size=(16, policy.arrays["l0_w"].shape[0]))
            expected, _ = self.model.predict(probe.astype(np.float32), deterministic=True)
            if not np.allclose(policy(probe), expected, atol=1e-5):
                raise RuntimeError("SB3 actor export does not match model.predict")
            rows = run_episodes(
                policy,
                c["task"],
                EVAL_DYNAMICS,
                job["eval_episodes"],
                seed=EVAL_SEED_OFFSET + seed,
                **env_kwargs(c),
            )
            self.curve.append((self.num_timesteps, float(np.mean([r["return"] for r in rows]))))
            self.seconds += time.perf_counter() - start

    env = make(c["task"], c["dynamics"], seed=seed, **env_kwargs(c))
    model = SpinningUpSAC(
        "MlpPolicy",
        env,  # SB3 adds Monitor + DummyVecEnv; seed=seed makes its first reset reset(seed=seed)
        learning_rate=c["lr_actor"],
        buffer_size=c["buffer_size"],
        learning_starts=max(c["update_after"] - 1, 0),
        batch_size=c["batch_size"],
        tau=1.0 - c["polyak"],
        gamma=c["gamma"],
        train_freq=(c["update_every"], "step"),
        gradient_steps=c["update_every"],
        ent_coef=c["alpha"],
        policy_kwargs={"net_arch": list(c["hidden"]), "activation_fn": torch.nn.ReLU},
        device="cpu",
        seed=seed,
        verbose=0,
    )
    model.start_steps = c["start_steps"]
    callback = NominalEval()
    model.learn(total_timesteps=job["steps"], callback=callback)
    wall = time.perf_counter() - start
    print(f"sb3 seed {seed}: {wall:.0f} s (evaluation {callback.seconds:.0f} s)", flush=True)
    return {"seed": seed, "curve": callback.curve, "wall": wall, "eval_seconds": callback.seconds}


def run_sb3(config, args) -> tuple[dict[int, list], float, dict[int, float]]:
    """All seeds of SB3 SAC, `--sb3-procs` processes at a time; ({seed: curve}, wall s, {seed:
    wall s})."""
    c = {name: getattr(config, name) for name in SHARED}
    if c["lr_actor"] != c["lr_critic"] or c["autotune_alpha"] or c["activation"] != "relu":
        raise RuntimeError("SB3 SAC here takes one learning rate, a fixed α and ReLU networks")
    jobs = [
        {
            "config": c,
            "seed": seed,
            "steps": args.steps,
            "eval_every": args.eval_every,
            "eval_episodes": args.eval_episodes,
        }
        for seed in args.seeds
    ]
    print(f"sb3: {len(jobs)} seeds, {args.sb3_procs} processes", flush=True)
    start = time.perf_counter()
    with multiprocessing.get_context("spawn").Pool(min(args.sb3_procs, len(jobs))) as pool:
        results = pool.map(train_sb3, jobs, chunksize=1)
    wall = time.perf_counter() - start
    return (
        {r["seed"]: r["curve"] for r in results},
        wall,
        {r["seed"]: r["wall"] for r in results},
    )


# ============================================================================ report
def write_curves(path: Path, curves: dict[str, dict[int, list]]) -> None:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["impl", "seed", "step", "return"])
    for impl, by_seed in curves.items():
        for seed, curve in sorted(by_seed.items()):
            writer.writerows([impl, seed, step, f"{ret:.6g}"] for step, ret in curve)
    atomic_write_text(path, buf.getvalue())


def curve_matrix(by_seed: dict[int, list]) -> tuple[np.ndarray, np.ndarray]:
    """(steps, returns of shape (n_seeds, n_steps)); NaN where a seed has no evaluation."""
    steps = np.array(sorted({s for curve in by_seed.values() for s, _ in curve}))
    values = np.full((len(by_seed), len(steps)), np.nan)
    for i, curve in enumerate(by_seed.values()):
        for step, ret in curve:
            values[i, np.searchsorted(steps, step)] = ret
    return steps, values


def write_figure(path: Path, curves: dict[str, dict[int, list]], title: str) -> None:
    import matplotlib
    from matplotlib.figure import Figure

    from adarl.report.figures import STYLE

    with matplotlib.rc_context(STYLE):
        fig = Figure(figsize=(4.5, 2.8))
        ax = fig.add_subplot()
        for impl, by_seed in curves.items():
            steps, values = curve_matrix(by_seed)
            centre, low, high = stats.t_interval(values)
            (line,) = ax.plot(
                steps, centre, marker="o", markersize=2.5, label=IMPLS[impl].replace("`", "")
            )
            ax.fill_between(steps, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
        ax.set_xlabel("environment steps")
        ax.set_ylabel(f"return ({EVAL_DYNAMICS} dynamics)")
        ax.set_title(title)
        ax.legend(loc="upper left")
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png")
    atomic_write_bytes(path, buf.getvalue())


def final_returns(by_seed: dict[int, list], seeds: list[int]) -> np.ndarray:
    return np.array([by_seed[s][-1][1] for s in seeds])


def summary_text(config, args, curves, walls, sb3_seed_walls, command: str) -> str:
    import jax
    import stable_baselines3
    import torch

    from adarl import __version__

    seeds = list(args.seeds)
    finals = {impl: final_returns(curves[impl], seeds) for impl in curves}
    step = curves["adarl"][seeds[0]][-1][0]
    lines = [
        "# Learning parity: adarl `sac` vs Stable-Baselines3 SAC",
        "",
        f"    {command}",
        "",
        f"Hopper, `{TRAIN_DYNAMICS}` dynamics for training, {args.steps} environment steps, "
        f"seeds {', '.join(map(str, seeds))}; every {args.eval_every} steps "
        f"{args.eval_episodes} deterministic episode(s) on `{EVAL_DYNAMICS}` dynamics. adarl "
        f"{__version__} (jax {jax.__version__}), stable-baselines3 {stable_baselines3.__version__} "
        f"(torch {torch.__version__}); {os.cpu_count()} CPU cores.",
        "",
        f"## Final return (step {step}): mean over seeds, stratified bootstrap 95% CI",
        "",
        "| implementation | mean [95% CI] | per seed | wall time |",
        "| --- | ---: | --- | ---: |",
    ]
    wall_text = {
        "adarl": f"{walls['adarl']:.0f} s (all seeds, one process)",
        "sb3": f"{walls['sb3']:.0f} s ({args.sb3_procs} processes; per seed "
        + ", ".join(f"{sb3_seed_walls[s]:.0f}" for s in seeds)
        + " s)",
    }
    for impl, values in finals.items():
        ci = stats.bootstrap_ci(values[:, None], stats.mean)
        per_seed = ", ".join(f"{v:.0f}" for v in values)
        lines.append(
            f"| {IMPLS[impl]} | {ci.point:.0f} [{ci.low:.0f}, {ci.high:.0f}] | {per_seed} | "
            f"{wall_text[impl]} |"
        )
    diff = stats.difference_ci(finals["adarl"], finals["sb3"])
    poi = stats.probability_of_improvement_ci(finals["adarl"][:, None], finals["sb3"][:, None])
    lines += [
        "",
        f"adarl − SB3, final mean: {diff.point:+.0f} [{diff.low:+.0f}, {diff.high:+.0f}]; "
        f"P(adarl > SB3) = {poi.point:.2f} [{poi.low:.2f}, {poi.high:.2f}] (independent "
        "bootstrap over seeds). With few seeds these intervals are wide; see the curves in "
        "parity.png (bands: 95% t intervals over seeds) and curves.csv.",
        "",
        "## Shared settings (from adarl's `sac`, `paper` preset)",
        "",
        "| setting | value | SB3 argument |",
        "| --- | --- | --- |",
        f"| environment | `{config.task}`, `{config.dynamics}` dynamics, `{config.physics}` "
        f"physics, {config.model_version} model | the same `adarl.envs.make` env (SB3 adds "
        "Monitor + DummyVecEnv) |",
        f"| networks | {config.hidden} {config.activation}, actor and 2 critics | "
        "`policy_kwargs={net_arch, activation_fn=ReLU}` |",
        f"| learning rate (actor, critics) | {config.lr_actor}, {config.lr_critic} | "
        "`learning_rate` |",
        f"| batch, buffer | {config.batch_size}, {config.buffer_size} | `batch_size`, "
        "`buffer_size` |",
        f"| γ, polyak | {config.gamma}, {config.polyak} | `gamma`, `tau={1 - config.polyak:g}` |",
        f"| α (fixed) | {config.alpha} | `ent_coef={config.alpha}` |",
        f"| random actions for the first | {config.start_steps} steps | `SpinningUpSAC."
        "start_steps` |",
        f"| first update at step | ≥ {config.update_after} | `learning_starts="
        f"{max(config.update_after - 1, 0)}` |",
        f"| updates | {config.update_every} every {config.update_every} steps | "
        f"`train_freq={config.update_every}, gradient_steps={config.update_every}` |",
        f"| episode limit | {config.max_episode_steps} steps, bootstrapped | our env's limit; "
        "`handle_timeout_termination=True` |",
        "",
        "## Known differences",
        "",
        *[f"- {item}" for item in DIFFERENCES],
        "",
    ]
    return "\n".join(lines)


# ============================================================================ main
def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000, help="environment steps per seed")
    parser.add_argument("--seeds", type=parse_int_list, default=(0, 1, 2), help="e.g. 0-2")
    parser.add_argument("--eval-every", type=int, default=10_000)
    parser.add_argument("--eval-episodes", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path("results/parity"))
    parser.add_argument("--sb3-procs", type=int, default=2, help="SB3 seeds trained at once")
    parser.add_argument("--start-steps", type=int, default=None, help="default: the preset's")
    parser.add_argument("--update-after", type=int, default=None, help="default: the preset's")
    args = parser.parse_args()
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        parser.error("Stable-Baselines3 is not installed: pip install -e .[bench]")
    if args.sb3_procs < 1:
        parser.error("--sb3-procs must be >= 1")
    try:
        config = parity_config(args)
    except UsageError as exc:  # e.g. a budget that is not a multiple of update-every
        parser.error(str(exc))
    run_dir = args.out / "adarl-sac"
    if run_dir.exists() and any(run_dir.iterdir()):
        parser.error(f"{run_dir} exists; remove it or choose another --out")
    command = shlex.join(["python", "bench/parity.py", *sys.argv[1:]])

    adarl_curves, adarl_wall = train_adarl(config, run_dir)
    print(f"adarl: {adarl_wall:.0f} s", flush=True)
    sb3_curves, sb3_wall, sb3_seed_walls = run_sb3(config, args)
    print(f"sb3: {sb3_wall:.0f} s", flush=True)

    curves = {"adarl": adarl_curves, "sb3": sb3_curves}
    walls = {"adarl": adarl_wall, "sb3": sb3_wall}
    write_curves(args.out / "curves.csv", curves)
    write_figure(
        args.out / "parity.png",
        curves,
        f"Hopper ({TRAIN_DYNAMICS} dynamics), {len(args.seeds)} seeds",
    )
    text = summary_text(config, args, curves, walls, sb3_seed_walls, command)
    atomic_write_text(args.out / "summary.md", text)
    print("\n" + text.split("## Shared settings")[0].rstrip())
    print(f"\nwrote {args.out}/curves.csv, parity.png, summary.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
