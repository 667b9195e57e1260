"""The one training loop of every algorithm (the shape of Stable-Baselines3's `learn`: the loop
owns the run, the algorithm supplies a small learner).

The loop owns what every algorithm does alike: starting a run folder or resuming it from its
newest intact checkpoint (under the run's lock), the CSV and TensorBoard logs and the progress
bar, the triggers (`log_every`, `eval_every`, `checkpoint_every` and the end), the evaluation
(seed 1,000,000 + s), each seed's best policy by nominal evaluation return, the checkpoint
(arrays, meta.json, policy files), the divergence watch, a stop asked for by SIGTERM or Ctrl-C
(a checkpoint at the end of the current step, then `Stopped`) and the teardown.

A learner (`adarl.train.sac_learner`, `adarl.train.rnac_learner`) owns its algorithm's state
and how it acts and learns; the loop drives it one way through `adarl.train.learner.Learner`
(its members, the `Advance` each step returns and the `Event`s due), and writes whatever it
returns (episodes, train.csv rows, a truncation's spectra and rows, checkpoints).

Adding an on-policy algorithm (PPO, say) is a learner like RNAC's: its rollout buffer and
normalisers in `advance`, its jitted update when the rollout is full (docs/algorithms.md).
"""

from __future__ import annotations

import math
import signal
import sys
import threading
import time
from collections.abc import Callable
from io import BytesIO
from pathlib import Path

import numpy as np

from adarl.errors import Stopped, UsageError
from adarl.files import atomic_write_bytes
from adarl.runs import checkpoints, folder, layout, logs, provenance
from adarl.runs.lock import RunLock
from adarl.train.guards import DivergenceWatch, check_logged_physics, check_run_model, model_record
from adarl.train.learner import Episode, Event, Learner, Truncation, due

LOGS = (layout.EPISODES_CSV, layout.TRAIN_CSV, layout.EVAL_CSV)


class BestPolicies:
    """Each seed's best policy by mean nominal evaluation return, kept beside the final one (as
    RNAC's original keeps its best model). Every checkpoint stores it (`best_policy_seed_<s>.npz`
    and meta.json's `best`), so a resumed run selects exactly as an uninterrupted one; a run
    resumed from a checkpoint written before it kept them records the step it began
    (`from_step`)."""

    METRIC = "mean nominal evaluation return"

    def __init__(self, seeds, from_step: int = 0):
        self.seeds = [int(s) for s in seeds]
        self.from_step = int(from_step)
        self.record: dict[int, dict] = {}  # seed -> {"step": …, "return": …}
        self.files: dict[int, bytes] = {}  # seed -> the policy file's bytes

    def offer(self, seed: int, step: int, mean_return: float, policy: dict) -> None:
        """Keep `policy` if its finite `mean_return` beats the seed's best so far (ties: the
        earlier one)."""
        from adarl.policy import to_bytes

        best = self.record.get(seed)
        if math.isfinite(mean_return) and (best is None or mean_return > best["return"]):
            self.record[seed] = {"step": int(step), "return": float(mean_return)}
            self.files[seed] = to_bytes(policy)

    def meta(self) -> dict:
        seeds = {str(s): self.record[s] for s in self.seeds if s in self.record}
        meta = {"metric": self.METRIC, "dynamics": "nominal", "seeds": seeds}
        return meta | ({"from_step": self.from_step} if self.from_step else {})

    def checkpoint_files(self) -> dict[str, bytes]:
        return {
            layout.best_policy_file_name(s): self.files[s] for s in self.seeds if s in self.files
        }

    def restore(self, meta: dict, checkpoint: Path) -> None:
        """Read the best back from a checkpoint (none recorded: keep from the checkpoint's step)."""
        if "best" not in meta:
            self.from_step = int(meta["step"])
            return
        self.from_step = int(meta["best"].get("from_step", 0))
        for key, record in (meta["best"].get("seeds") or {}).items():
            path = Path(checkpoint) / layout.best_policy_file_name(int(key))
            try:
                self.files[int(key)] = path.read_bytes()
            except OSError:
                raise UsageError(
                    f"checkpoint {checkpoint} has no {path.name}, which its meta.json lists"
                ) from None
            self.record[int(key)] = {"step": int(record["step"]), "return": float(record["return"])}


def train(
    make_learner: Callable[..., Learner],
    config,
    run_dir,
    resume: bool = False,
    progress: bool = True,
    command: str = "",
) -> Path:
    """Train (or resume) a run of `config` into `run_dir` with the learner `make_learner(config)`;
    returns the run folder. The run folder's lock is held from the first write to the end
    (docs/reliability.md)."""
    run_dir = Path(run_dir)
    config.validate()
    with RunLock(run_dir) as lock:
        if resume:
            if not folder.lock_to_resume(run_dir, lock):  # complete
                return run_dir
            # the learner's checks (environments, dynamics, memory) come before any checkpoint
            # is read, so a refusal leaves a damaged newest one under its own name
            loop = Loop(make_learner(config), run_dir, progress)
            if getattr(config, "dynamics", None) and getattr(config, "task", None):
                check_logged_physics(run_dir, config.task, config.dynamics)
            check_run_model(run_dir, config)
            path, arrays, meta = folder.newest_to_resume(run_dir, config)
            if meta is None:  # killed before its first checkpoint: start again, nothing half-done
                loop.learner.fresh()
                loop.open_logs({name: 0 for name in loop.log_names()})
            else:
                loop.restore(path, arrays, meta)
            del arrays  # the lanes hold copies; let go of the checkpoint's memory maps
            provenance.record_resume(run_dir, loop.step)  # the code that goes on from here
        else:
            folder.check_new_run_dir(run_dir)
            learner = make_learner(config)  # unknown tasks or dynamics fail before any write
            folder.start_new(run_dir, lock, config, learner.algo, command, model_record(config))
            loop = Loop(learner, run_dir, progress)
            learner.fresh()
            loop.open_logs(None)
        announce(config, loop.learner.algo, loop.step)
        try:
            with StopSignals() as stop:
                loop.run(stop)
        finally:
            loop.close()
    return run_dir


def start_line(config, algo: str, step: int = 0) -> str:
    """The line a run prints as it starts (or resumes from `step`): the algorithm, task, seeds
    and budget, and what the budget gives (`schedule.budget_words`: AdaRL's cuts, the warm-up
    and the rules they follow; issue 62)."""
    from adarl.algos import schedule

    seeds = len(config.seeds)
    head = (
        f"{'resume' if step else 'start'}: {algo} on {config.task}, {seeds} seed"
        f"{'s' if seeds > 1 else ''} x {config.total_steps:,} steps"
        + (f", from step {step:,}" if step else "")
    )
    return "; ".join([head, *schedule.budget_words(config)[0]])


def announce(config, algo: str, step: int = 0) -> None:
    """Print `start_line` (stdout) and, as a run starts (not as it resumes: it said them then,
    and the summary says them again), the budget's warnings (stderr, `warning: ...`, one line
    each: no cut, mostly random warm-up), after the run's checks and before its first step."""
    from adarl.algos import schedule

    print(start_line(config, algo, step), flush=True)
    for warning in schedule.budget_words(config)[1] if step == 0 else ():
        print(f"warning: {warning}", file=sys.stderr, flush=True)


class StopSignals:
    """SIGTERM (a cluster's preemption, `kill PID`, a sweep being stopped) and SIGINT (Ctrl-C)
    while a run trains ask it to stop at the end of its current step, with a checkpoint there
    (`Loop.run`), so that nothing trained is lost; a second one stops it at once
    (KeyboardInterrupt). Python delivers signals to the main thread only, so elsewhere (a
    thread of a notebook or a service) nothing is installed; the previous handlers come back
    when the run ends."""

    SIGNALS = (signal.SIGTERM, signal.SIGINT)

    def __init__(self) -> None:
        self.received: int | None = None
        self.previous: dict[int, object] = {}

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            for sig in self.SIGNALS:
                self.previous[sig] = signal.signal(sig, self.handle)
        return self

    def handle(self, signum: int, frame) -> None:
        if self.received is not None:
            raise KeyboardInterrupt
        self.received = signum

    def __exit__(self, *exc) -> None:
        for sig, handler in self.previous.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)


class Loop:
    """A run in progress: its learner, step, logs, best policies and divergence watch."""

    def __init__(self, learner: Learner, run_dir: Path, progress: bool):
        self.learner, self.config = learner, learner.config
        self.run_dir, self.progress = run_dir, progress
        self.seeds = list(learner.seeds)
        self.step = 0
        self.best = BestPolicies(self.seeds)
        self.watch = DivergenceWatch(run_dir, self.config.on_divergence)
        self.logs, self.tb, self.recent_returns = {}, None, []
        self.resumes_mid_step = False  # restored from a pre-truncation checkpoint

    def restore(self, path: Path, arrays: dict, meta: dict) -> None:
        self.step = int(meta["step"])
        self.learner.restore(arrays, meta)
        self.resumes_mid_step = meta.get("phase") == layout.PRE_TRUNCATION
        self.best.restore(meta, path)
        self.open_logs(checkpoints.csv_offsets(meta))

    # ------------------------------------------------------------------ logs
    def log_names(self) -> list[str]:
        return [*LOGS, *self.learner.extra_logs]

    def extra_columns(self, resuming: bool) -> dict[str, list[str]]:
        """The learner's logs and their columns: a resumed file keeps an older column set its
        header has."""
        columns = {}
        for name, (current, *older) in self.learner.extra_logs.items():
            columns[name] = current
            path = self.run_dir / name
            if resuming and older and path.exists() and path.stat().st_size:
                with open(path, encoding="utf-8", errors="replace") as f:  # CsvLog names a bad one
                    header = sorted(f.readline(1 << 16).strip().split(","))
                columns[name] = next((c for c in older if sorted(c) == header), current)
        return columns

    def open_logs(self, offsets: dict | None) -> None:
        """Open the CSV and TensorBoard logs; resuming (`offsets`: file name -> byte offset of
        the checkpoint), first cut each CSV back to what the checkpoint had seen."""
        d = self.run_dir
        for name, offset in (offsets or {}).items():
            logs.CsvLog.truncate(d / name, offset)
        columns = {
            layout.EPISODES_CSV: logs.episode_columns(self.learner.param_names()),
            layout.TRAIN_CSV: self.learner.train_columns,
            layout.EVAL_CSV: logs.EVAL_COLUMNS,
            **self.extra_columns(offsets is not None),
        }
        self.logs = {name: logs.CsvLog(d / name, cols) for name, cols in columns.items()}
        self.tb = logs.Scalars(
            d / layout.TB_DIR, purge_step=self.step if offsets is not None else None
        )

    def close(self) -> None:
        for log in self.logs.values():
            log.close()
        if self.tb is not None:
            self.tb.close()
        self.learner.close()

    def episode_done(self, episode: Episode) -> None:
        """Log an episode a learner's `advance` finished."""
        i, step, info = episode.index, episode.step, episode.info
        ep_return, length = episode.ret, episode.length
        seed = self.seeds[i]
        row = {
            "step": step,
            "seed": seed,
            "episode": int(info["episode_index"]),
            "return": float(ep_return),
            "length": int(length),
        }
        row.update({layout.param_column(k): v for k, v in info["dynamics"].items()})
        self.logs[layout.EPISODES_CSV].write(row)
        self.tb.write(step, {logs.tb_episode_return(seed): ep_return})
        self.recent_returns.append(float(ep_return))
        if not math.isfinite(ep_return):
            self.watch.note("episode return", [seed])

    # ------------------------------------------------------------------ the step's work
    def write_train_rows(self, steps_per_s: float) -> None:
        rows = self.learner.train_rows(self.step, steps_per_s)
        for row in rows:
            self.tb.write(
                self.step,
                {
                    logs.tb_train(k, row["seed"]): v
                    for k, v in row.items()
                    if k not in ("step", "seed") and math.isfinite(v)
                },
            )
        if rows:
            self.logs[layout.TRAIN_CSV].write(rows)

    def evaluate(self) -> None:
        """Every seed's policy on every evaluation dynamics, `eval_episodes` episodes from seed
        1,000,000 + s; the nominal return is offered to the seed's best policies."""
        from adarl.envs.rollout import run_episodes
        from adarl.policy import NumpyPolicy

        c = self.config
        # a learner with its own evaluation (the device learner's, on its accelerator) starts
        # it first, so that it runs while the host evaluates; its rows go to its own logs
        start = getattr(self.learner, "start_evaluation", None)
        own_rows = start(self.step) if start is not None else None
        for seed, arrays in zip(self.seeds, self.learner.policies()):
            policy = NumpyPolicy(arrays)
            for label in c.eval_dynamics:
                rows = run_episodes(
                    policy,
                    c.task,
                    label,
                    c.eval_episodes,
                    seed=1_000_000 + seed,
                    **self.learner.env_options,
                )
                self.logs[layout.EVAL_CSV].write(logs.eval_rows(self.step, seed, label, rows))
                mean_return = float(np.mean([r["return"] for r in rows]))
                self.tb.write(self.step, {logs.tb_eval_return(label, seed): mean_return})
                if label == "nominal":
                    self.best.offer(seed, self.step, mean_return, arrays)
        for name, rows in own_rows().items() if own_rows is not None else ():
            self.logs[name].write(rows)

    def check_divergence(self) -> bool:
        """Stop the run (or warn once) on non-finite parameters, optimiser states, metrics or
        returns (docs/reliability.md); whether this check found any (`--on-divergence
        continue` returns)."""
        for quantity, seeds in self.learner.nonfinite(self.step).items():
            self.watch.note(quantity, seeds)
        found = bool(self.watch.found)
        self.watch.check(self.step)  # clears what it found
        return found

    def checkpoint(self) -> None:
        self.check_divergence()  # never checkpoint non-finite parameters
        self.save()

    def save(self, phase: str | None = None) -> None:
        """A checkpoint of everything; `phase` PRE_TRUNCATION: one kept in
        checkpoints/pre_truncation/ (never rotated), taken before the rest of the step's work."""
        from adarl.policy import to_bytes

        arrays, extra = self.learner.checkpoint_state()
        offsets = {name: log.offset() for name, log in self.logs.items()}
        meta = checkpoints.checkpoint_meta(self.learner.algo, self.config, self.seeds, offsets)
        meta.update(extra)
        meta["best"] = self.best.meta()
        if phase is not None:
            meta["phase"] = phase
        files = {
            layout.policy_file_name(seed): to_bytes(policy)
            for seed, policy in zip(self.seeds, self.learner.policies())
        }
        files.update(self.best.checkpoint_files())
        checkpoints.save_checkpoint(
            self.run_dir,
            self.step,
            arrays,
            meta,
            keep=0 if phase == layout.PRE_TRUNCATION else self.config.keep_checkpoints,
            files=files,
            folder=layout.PRE_TRUNCATION_DIR
            if phase == layout.PRE_TRUNCATION
            else layout.CHECKPOINT_DIR,
        )

    def truncate(self, pre_checkpoint: bool) -> None:
        """The learner's truncation: first (`pre_checkpoint`, and if the config asks) a
        pre-truncation checkpoint, never of non-finite parameters; then the spectra and the
        truncations.csv rows the learner returns. Weights gone non-finite since the last check
        stop the run here (exit 3), before any SVD (`--on-divergence continue`: the cut leaves
        a non-finite layer as it was, `adarl.lowrank.cut_layer`)."""
        diverged = self.check_divergence()  # read-only: a finite run's numbers do not change
        if pre_checkpoint and self.config.checkpoint_before_truncation:
            if self.learner.parameters_finite() and not diverged:
                self.save(phase=layout.PRE_TRUNCATION)
        result: Truncation = self.learner.truncate(self.step)
        buf = BytesIO()
        np.savez(buf, seeds=np.asarray(self.seeds), **result.spectra)
        atomic_write_bytes(
            self.run_dir / layout.SPECTRA_DIR / layout.spectrum_file(self.step), buf.getvalue()
        )
        log = self.logs[layout.TRUNCATIONS_CSV]
        log.write([{k: row[k] for k in log.columns} for row in result.rows])

    def end_of_step(self, events: frozenset[Event], pre_checkpoint: bool = True) -> None:
        """What follows the learner's update at a step the loop looks at, as `events` says: a
        truncation, then the train.csv rows, the evaluation and the checkpoint. A run restored
        from a pre-truncation checkpoint starts here (without that checkpoint)."""
        t = self.step
        if Event.TRUNCATE in events:
            self.truncate(pre_checkpoint)
        if Event.LOG in events:
            now = time.perf_counter()
            t_log, s_log = self.clock
            self.write_train_rows((t - s_log) / max(now - t_log, 1e-9))
            self.check_divergence()
            self.clock = now, t
        if Event.EVALUATE in events:
            self.evaluate()
        if Event.CHECKPOINT in events:
            self.checkpoint()

    def run(self, stop: StopSignals | None = None) -> None:
        """Train to `total_steps`; when `stop` has received a signal, write a checkpoint at the
        end of the current step (unless the step wrote one) and raise `Stopped`."""
        c = self.config
        bar = _progress(c.total_steps, self.step, self.progress, f"{self.learner.algo} {c.task}")
        self.clock = time.perf_counter(), self.step  # (time, step) of the last train.csv rows
        if self.resumes_mid_step:
            self.end_of_step(due(c, self.step, truncate=True), pre_checkpoint=False)
        while self.step < c.total_steps:
            advance = self.learner.advance(self.step)
            for episode in advance.episodes:
                self.episode_done(episode)
            self.step = advance.step
            self.end_of_step(advance.events)
            recent = self.recent_returns[-RECENT_EPISODES * len(self.seeds) :]
            self.recent_returns = recent
            if bar is not None and (self.step - bar.n >= 256 or self.step == c.total_steps):
                bar.set_postfix_str(progress_text(recent), refresh=False)
                bar.update(self.step - bar.n)
            if stop is not None and stop.received is not None and self.step < c.total_steps:
                if bar is not None:
                    bar.close()
                if Event.CHECKPOINT not in advance.events:
                    self.checkpoint()
                raise Stopped(stop.received, self.step, self.run_dir)
        if bar is not None:
            bar.close()
        folder.finish(self.run_dir, self.step)


#: Training episodes per seed the progress bar's return averages (over all seeds together).
RECENT_EPISODES = 10


def progress_text(recent: list[float]) -> str:
    """The progress bar's figure, named (issue 62): the mean return of the last training
    episodes the seeds finished (at most `RECENT_EPISODES` per seed, pooled), which explore and
    run under the training dynamics, so it is not the summary's nominal evaluation return."""
    if not recent:
        return "train return -"
    which = "last episode" if len(recent) == 1 else f"mean of last {len(recent)} episodes"
    return f"train return {np.mean(recent):,.0f} ({which})"


def _progress(total: int, start: int, enabled: bool, desc: str):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=start,
        unit="step",
        dynamic_ncols=True,
        file=sys.stderr,
        smoothing=0.05,
        desc=desc,
    )
