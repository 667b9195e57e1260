"""adarl from Python: what `adarl train`, `adarl evaluate` and `adarl report` do, for notebooks and
scripts, with the same validation, run folder and exact resume.

    import adarl
    run = adarl.train(algo="adarl", task="HalfCheetah-v5", seeds=[0, 1], out="runs/hc",
                      total_steps=200_000, dynamics="uniform:body:torso.mass=4..9")
    run.final_ranks                # {"actor_1": 31.0, ...}, mean over seeds
    policy = adarl.load_policy("runs/hc", seed=0)
    adarl.evaluate("runs/hc", sweep="mass_scale=0.8..1.2:5")
    adarl.report(["runs/hc"], out="runs/hc/report")

`env_fn` trains on a Gymnasium env that is not registered: a callable returning it (a class
built on `gymnasium.envs.mujoco.MujocoEnv` gets episode-varying physics). It is registered as
`adarl-fn/<env_name>-v0` for the run; resume such a run by giving the same `env_fn` again
(`adarl.train(env_fn=make_robot, resume="runs/robot")`). Bad input raises `adarl.UsageError`
(the CLI's one-line message) and writes nothing.
"""

from __future__ import annotations

import contextlib
import io
import re
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from adarl.errors import Stopped, UsageError

#: The Gymnasium namespace `env_fn` envs are registered under.
FN_NAMESPACE = "adarl-fn"


@dataclass(frozen=True)
class Run:
    """A trained run: its folder, algorithm and config (the run's config.yaml)."""

    path: Path
    algo: str
    config: object

    @property
    def evaluations(self) -> list[dict]:
        """eval.csv's rows (every seed, every evaluation dynamics)."""
        from adarl.runs.logs import read_csv

        return read_csv(self.path / "eval.csv")

    @property
    def final_ranks(self) -> dict[str, float]:
        """Each bottleneck's rank in train.csv's last rows, mean over seeds ({} without one)."""
        from adarl.runs import layout
        from adarl.runs.logs import read_csv

        rows = read_csv(self.path / "train.csv")
        if not rows:
            return {}
        last = max(int(r["step"]) for r in rows)
        final = [r for r in rows if int(r["step"]) == last]
        return {
            layout.rank_layer(c): sum(float(r[c]) for r in final) / len(final)
            for c in layout.rank_columns(final[0])
        }

    def summary(self) -> str:
        """The lines `adarl train` prints at the end (returns, what the policies do, ranks)."""
        from adarl.report.summary import training_summary

        return training_summary(self.path, 0.0)


def train(
    algo: str = "adarl",
    task: str | None = None,
    *,
    env_fn: Callable | None = None,
    env_name: str | None = None,
    seeds: int | str | Iterable[int] = (0,),
    out: str | Path | None = None,
    preset: str | None = None,
    resume: str | Path | None = None,
    progress: bool = False,
    **config_fields,
) -> Run:
    """Train `algo` on `task` (a name `adarl tasks` lists or any Gymnasium id) or on the env that
    `env_fn()` returns, for `seeds`, into `out` (default runs/<task>-<algo>-<time>); any config
    field as a keyword (`total_steps=`, `dynamics=`, `env_kwargs=`, `truncate_every=`, ...; see
    `adarl train --algo ALGO --help`). `resume=RUN_DIR` continues a run exactly (give `env_fn`
    again if it was trained with one, and `env_module=` if a module of yours registers its
    task: adarl imports no module a run folder names; nothing else). Returns the `Run`.

    The process gets the CLI's XLA settings (one device per core, single-threaded computations)
    when JAX is not imported yet, so a run started here resumes from the CLI and the reverse;
    with JAX already imported under other settings, such a resume names the difference."""
    import sys

    if "jax" not in sys.modules:
        from adarl.runtime import configure_xla

        configure_xla()
    from adarl.envs.tasks import name_env_module
    from adarl.runs import folder
    from adarl.train import launch

    name_env_module(str(config_fields.get("env_module") or ""))  # yours: it may be imported
    if env_fn is not None:
        if task is not None:
            raise UsageError("give task or env_fn, not both")
        if not callable(env_fn):
            raise UsageError(
                f"bad env_fn {env_fn!r}; allowed: a callable returning a Gymnasium env"
            )
        task = register_env_fn(env_fn, env_name)
    if resume is not None:
        named = {"task": task if env_fn is None else None, "out": out, "preset": preset}
        given = [k for k, v in named.items() if v is not None]
        given += [k for k in config_fields if k != "env_module"]
        if given:
            raise UsageError(f"resume continues a run with its own settings; drop {given[0]}")
        if env_fn is not None:
            _trained_with(Path(resume), task)
        start, out = launch.Resume(str(resume)), None
    else:
        flags = dict(config_fields)
        if task is not None:
            flags["task"] = task
        flags["seeds"] = _seeds(seeds)
        start = launch.New(algo, preset, flags)
        start.config()  # every check before anything is written
    try:
        run_dir = launch.train(start, out, _command("resume" if resume else algo), progress)
    except Stopped as stopped:  # its hint names the call that resumes it from here
        keywords = ["env_fn=<the same env_fn>"] if env_fn is not None else []
        if config_fields.get("env_module"):
            keywords.append(f"env_module={config_fields['env_module']!r}")
        raise stopped.resume_from_python(*keywords) from None
    algo_back, config = folder.config_from_run(run_dir)
    return Run(Path(run_dir), algo_back, config)


def register_env_fn(env_fn: Callable, env_name: str | None = None) -> str:
    """Register `env_fn` with Gymnasium as `adarl-fn/<env_name>-v0` (default name: its
    `__name__`) and return the id (registering the same name again re-points it)."""
    import gymnasium

    name = env_name or getattr(env_fn, "__name__", "") or type(env_fn).__name__
    name = re.sub(r"[^A-Za-z0-9_]", "_", name).strip("_") or "env"
    env_id = f"{FN_NAMESPACE}/{name}-v0"
    if env_id in gymnasium.registry:
        del gymnasium.registry[env_id]
    gymnasium.register(env_id, entry_point=lambda **kwargs: env_fn(**kwargs))
    from adarl.envs import tasks

    tasks._gym_task.cache_clear()  # a re-registered id may be another env
    tasks._LAST.pop(env_id, None)
    return env_id


def load_policy(run_dir: Run | str | Path, seed: int = 0, step: int | None = None):
    """The NumPy policy of `seed` at the final checkpoint of `run_dir` (a `Run` or its folder;
    or at `step`): call it on an observation for the deterministic action
    (`adarl.policy.NumpyPolicy`)."""
    from adarl import policy
    from adarl.runs import checkpoints

    return policy.load(checkpoints.policy_file(_path(run_dir), seed, step))


def evaluate(runs: Run | str | Path | Sequence[Run | str | Path], **options) -> int:
    """`adarl evaluate RUNS` with `options` as its flags (`sweep="mass_scale=0.8..1.2:5"`,
    `suite="paper"`, `episodes=5`, `dynamics=...`, `env_module="myrobots"` for a run of a
    Gymnasium id a module of yours registers); writes what the command writes."""
    return _cli("evaluate", _paths(runs), options)


def report(runs: Run | str | Path | Sequence[Run | str | Path], out: str | Path, **options) -> Path:
    """`adarl report RUNS --out OUT` with `options` as its flags; returns OUT."""
    _cli("report", _paths(runs), {"out": str(out), **options})
    return Path(out)


# ---------------------------------------------------------------------------- internals
def _trained_with(run_dir: Path, env_id: str) -> bool:
    """Does the run at `run_dir` record `env_id` as its task? (UsageError otherwise.)"""
    from adarl.runs import folder

    recorded = str(folder.load_config(run_dir).get("task", ""))
    if recorded != env_id:
        raise UsageError(
            f"run {run_dir} was trained on task {recorded!r}, not on env_fn {env_id!r}; allowed: "
            "the env_fn (and env_name) it was trained with"
        )
    return True


def _seeds(seeds) -> str:
    if isinstance(seeds, bool):
        raise UsageError(f"bad seeds {seeds!r}; allowed: an integer, 'A-B' or a list of integers")
    if isinstance(seeds, int):
        return str(seeds)
    if isinstance(seeds, str):
        return seeds
    seeds = list(seeds)
    if not all(isinstance(s, int) and not isinstance(s, bool) for s in seeds):
        raise UsageError(f"bad seeds {seeds!r}; allowed: a list of integers >= 0")
    return ",".join(map(str, seeds))


def _path(run) -> Path:
    """A run's folder, from a `Run` (anything with a `path`: a Run of a reloaded module too) or
    a path."""
    return Path(run) if isinstance(run, str | Path) else Path(getattr(run, "path", run))


def _paths(runs) -> list[str]:
    """Run folders from a `Run`, a path, or a sequence of them."""
    if isinstance(runs, str | Path) or hasattr(runs, "path"):
        runs = [runs]
    return [str(_path(r)) for r in runs]


def _command(what: str) -> str:
    return f"adarl.train({what}) at {time.strftime('%Y-%m-%d %H:%M:%S')}"


def _cli(command: str, positional: list[str], options: dict) -> int:
    """Run `adarl COMMAND` with `options` as flags (True: the flag alone; False/None: left out),
    raising `UsageError` with the CLI's message instead of exiting."""
    from adarl.cli import main

    argv = [command, *positional]
    for key, value in options.items():
        if value is None or value is False:
            continue
        for one in value if isinstance(value, list | tuple) else [value]:  # a repeated flag
            argv.append("--" + key.replace("_", "-"))
            if one is not True:
                argv.append(str(one))
    parser = main.build_parser([command])
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            args = parser.parse_args(argv)
    except SystemExit:
        lines = [line for line in err.getvalue().splitlines() if line.strip()]
        raise UsageError(lines[-1] if lines else f"bad arguments for adarl {command}") from None
    args.no_progress = True
    code = args._run(args)
    return code if isinstance(code, int) else 0


__all__ = ["Run", "evaluate", "load_policy", "register_env_fn", "report", "train"]
