"""How long a sweep will take, from measured throughput: `adarl sweep` prints it before it starts
and with `--dry-run`.

A unit's time is a start-up plus its remaining environment steps, summed over its seeds, divided
by a measured rate in seed-steps per second of wall time (what a sweep unit pinned to its
`cpus_per_unit` cores achieved, evaluations, checkpoints, truncations and compilation included).
The sweep's time is that of the runner's schedule (`start_key`): each free slot takes a resumed
unit first, the nearest to done first, then the ready unit with the longest critical path (its
own time left, or the time until its parent reaches a fork point plus that fork's, when longer);
a fork unit is ready once its parent has reached the fork point (its share of the parent's
time). Rates come, most specific first, from the unit's own run folder (a resumed sweep), from
other runs of the same algorithm on the same task in the sweep folder, and from the sweep units
measured on this 2-core machine and shipped in `throughput.csv` (the committed experiments,
docs/experiments/). A unit with no measurement of its algorithm on its task borrows
one, and the line says how many did: its algorithm's rate on another task scaled by that task's
cost against its own, as another algorithm measured both (`scaled_rate`), else the median rate of
the same algorithm on other tasks, of other algorithms on its task or, last, of all measurements.

`python -m adarl.sweeps.estimate SWEEP_DIR...` prints the measurements of finished sweeps as
rows of `throughput.csv`.
"""

from __future__ import annotations

import csv
import io
import math
import os
import statistics
import sys
from dataclasses import dataclass
from pathlib import Path

from adarl.files import read_json
from adarl.runs.layout import DONE_FILE, TRAIN_CSV
from adarl.sweeps.spec import Sweep, Unit

MEASURED = Path(__file__).with_name("throughput.csv")
COLUMNS = ("algo", "task", "label", "seeds", "steps", "train_s", "source")
# Process start, imports and loading until the first step, per unit attempt: 4-13 s measured
# (manifest start to the first train.csv interval) in the committed sweeps; compilation is inside
# the first interval, so inside the rate.
STARTUP_S = 10.0
BORROWED = ("scaled", "algo", "task", "any")  # rates measured on another task or algorithm
# algorithms that train the same networks at the same cost as another (measured) one
SAME_COST = {"adarl-control": "adarl"}


@dataclass(frozen=True)
class Measurement:
    """One unit's training: `steps` environment steps per seed for each of `seeds` seeds took
    `train_s` seconds of wall time."""

    algo: str
    task: str
    label: str
    seeds: int
    steps: int
    train_s: float
    source: str

    @property
    def seed_steps_per_s(self) -> float:
        return self.seeds * self.steps / self.train_s


@dataclass(frozen=True)
class UnitEstimate:
    unit_id: str
    seconds: float
    matched: str  # which measurements gave its rate: a key of pick_rate's groups


@dataclass(frozen=True)
class Estimate:
    seconds: float  # wall time of the schedule
    unit_seconds: float  # sum over units (compute, in slot-seconds)
    slots: int
    units: tuple[UnitEstimate, ...]
    sources: tuple[str, ...]
    critical_paths: tuple[tuple[str, float], ...] = ()  # (unit id, seconds): the runner's order
    resumed: tuple[str, ...] = ()  # units with a checkpoint to resume from: they start first

    @property
    def borrowed(self) -> int:
        return sum(u.matched in BORROWED for u in self.units if u.seconds > 0)


# ----------------------------------------------------------------------------- pure pieces
def train_seconds(rows: list[dict]) -> tuple[int, float]:
    """(last step, seconds) of a run's train.csv rows: each row's interval since the previous row
    over its `steps_per_s` (all seeds of a run share one clock; the first seed's rows are used)."""
    if not rows:
        return 0, 0.0
    first = rows[0]["seed"]
    step, seconds = 0, 0.0
    for row in rows:
        if row["seed"] != first:
            continue
        try:
            now, rate = int(float(row["step"])), float(row["steps_per_s"])
        except (TypeError, ValueError):  # a damaged row: an estimate goes on without it
            continue
        if rate > 0 and math.isfinite(rate):
            seconds += (now - step) / rate
        step = now
    return step, seconds


def pick_rate(
    unit: Unit, own: list[Measurement], here: list[Measurement], shipped: list[Measurement]
) -> tuple[float, str, tuple[str, ...]]:
    """Seed-steps per second for `unit`, which group of measurements gave it, and their sources:
    the unit's own run (`own`), else the most specific match, measurements in the sweep folder
    (`here`) before the shipped ones at each level."""

    def same(key):
        return lambda m: key(m) == key(unit)

    def cost(x) -> str:
        return SAME_COST.get(x.algo, x.algo)

    def first_group(level: str, pools: list[list[Measurement]], key):
        for pool in pools:
            group = [m for m in pool if key(m) and m.train_s > 0 and m.steps > 0]
            if not group:
                continue
            if level in BORROWED:  # other algorithms or tasks: the median, so one very slow
                # or fast network (sac-sparse, RNAC) does not set everyone's rate
                rate = statistics.median(m.seed_steps_per_s for m in group)
            else:
                rate = pooled_rate(group)
            return rate, level, tuple(sorted({m.source for m in group}))
        return None

    everywhere = [here, shipped]
    for found in (
        first_group("own run", [own], lambda m: True),
        first_group("label and task", everywhere, same(lambda x: (x.label, x.task))),
        first_group("algo and task", everywhere, same(lambda x: (cost(x), x.task))),
        scaled_rate(cost(unit), unit.task, here + shipped, cost),
        first_group("algo", everywhere, same(cost)),
        first_group("task", everywhere, same(lambda x: x.task)),
        first_group("any", everywhere, lambda m: True),
    ):
        if found is not None:
            return found
    raise ValueError("no throughput measurement at all")


def pooled_rate(group: list[Measurement]) -> float:
    """Total seed-steps over total seconds."""
    return sum(m.seeds * m.steps for m in group) / sum(m.train_s for m in group)


def scaled_rate(
    algo: str, task: str, measurements: list[Measurement], cost=lambda m: m.algo
) -> tuple[float, str, tuple[str, ...]] | None:
    """The rate of `algo` on `task` where neither was measured together: its rate on another
    task t' scaled by what another algorithm a' measured on both tasks says `task` costs against
    t', rate(algo, t') · rate(a', task) / rate(a', t'), the geometric median over every such
    (a', t') (a network's cost and the physics' cost multiply, to a first approximation). Each
    (algorithm, task) rate is pooled over its measurements; `cost` names the algorithm whose
    measurements count for another's (SAME_COST). None when no such (a', t') exists."""
    cells: dict[tuple[str, str], list[Measurement]] = {}
    for m in measurements:
        if m.train_s > 0 and m.steps > 0:
            cells.setdefault((cost(m), m.task), []).append(m)
    rate = {cell: pooled_rate(group) for cell, group in cells.items()}
    logs, used = [], set()
    for (other_algo, other_task), base in rate.items():
        if other_algo == algo or other_task == task:
            continue
        mine, theirs = rate.get((algo, other_task)), rate.get((other_algo, task))
        if mine is None or theirs is None:
            continue
        logs.append(math.log(mine * theirs / base))
        for cell in ((algo, other_task), (other_algo, task), (other_algo, other_task)):
            used.update(m.source for m in cells[cell])
    if not logs:
        return None
    return math.exp(statistics.median(logs)), "scaled", tuple(sorted(used))


def critical_paths(jobs: list[tuple[str, float, str | None, float]]) -> dict[str, float]:
    """Each job's critical path with unlimited slots, by id: the seconds from its start until it
    and every fork that starts from it have finished, max(duration, max over its forks of (start
    offset + the fork's critical path)). `jobs` as for `fork_schedule_seconds`."""
    forks: dict[str, list[tuple]] = {}
    for job in jobs:
        if job[2] is not None:
            forks.setdefault(job[2], []).append(job)
    paths: dict[str, float] = {}

    def path(job: tuple) -> float:
        if job[0] not in paths:
            paths[job[0]] = max([job[1], *(fork[3] + path(fork) for fork in forks.get(job[0], []))])
        return paths[job[0]]

    for job in jobs:
        path(job)
    return paths


def start_key(seconds_left: float, path: float, resumed: bool, index: int) -> tuple:
    """The runner's order among ready units, smallest first: a resumed unit (one with a
    checkpoint) before any other, the nearest to done first, since a lost machine loses the
    training it holds; then the longest critical path (`critical_paths`), so that a long unit
    does not start last and run alone at the end; file order (`index`) among equals."""
    return (0, seconds_left, index) if resumed else (1, -path, index)


def fork_schedule_seconds(
    jobs: list[tuple[str, float, str | None, float]],
    slots: int,
    by_critical_path: bool = True,
    capacity: float | None = None,
    resumed: frozenset[str] = frozenset(),
) -> float:
    """Wall time of the runner's schedule of `jobs` (id, duration, parent id or None, seconds of
    the parent's work after which it may start), listed in file order. A fork is ready once its
    parent has done that much work (at once if its parent is not in `jobs`); each free slot takes
    the ready job first in `start_key` order (the `resumed` ones, nearest to done first, then the
    longest critical path), or with `by_critical_path` false the one that became ready first
    (file order at the start).

    Durations are seconds of work at the measured rate, which `capacity` jobs at once sustain
    (cores ÷ cpus_per_unit; None: every slot). With k > `capacity` jobs running, the cores are
    shared: each advances at capacity/k of its rate (processor sharing), so a job that runs alone
    at the end runs at full speed again."""
    ids = {job[0] for job in jobs}
    paths = critical_paths(jobs) if by_critical_path else {}
    index = {job[0]: i for i, job in enumerate(jobs)}
    forks: dict[str, list[tuple]] = {}
    for job in jobs:
        if job[2] in ids:
            forks.setdefault(job[2], []).append(job)
    ready = [job for job in jobs if job[2] not in ids]
    running: dict[str, list] = {}  # id -> [job, work done]
    now = 0.0

    def release(uid: str, done: float, finished: bool) -> list[tuple]:
        out = [f for f in forks.get(uid, []) if finished or f[3] <= done * (1 + 1e-12)]
        forks[uid] = [f for f in forks.get(uid, []) if f not in out]
        return out

    while ready or running:
        while ready and len(running) < max(1, slots):
            job = (
                min(ready, key=lambda j: start_key(j[1], paths[j[0]], j[0] in resumed, index[j[0]]))
                if paths
                else ready[0]
            )
            ready.remove(job)
            running[job[0]] = [job, 0.0]
            ready.extend(release(job[0], 0.0, False))  # forks at the parent's very start
        speed = 1.0 if capacity is None else min(1.0, capacity / len(running))
        # the next event: a job finishes, or a parent reaches one of its fork points
        work = min(job[1] - done for job, done in running.values())
        for job, done in running.values():
            work = min([work, *(f[3] - done for f in forks.get(job[0], []))])
        now += work / speed
        released = []
        for uid, state in list(running.items()):
            state[1] += work
            finished = state[1] >= state[0][1] * (1 - 1e-12)
            released += release(uid, state[1], finished)
            if finished:
                del running[uid]
        ready.extend(sorted(released, key=lambda f: index[f[0]]))
    return now


def estimate(
    sweep: Sweep,
    remaining: dict[str, int],
    slots: int,
    shipped: list[Measurement],
    here: dict[str, Measurement] | None = None,
    cores: int | None = None,
    by_critical_path: bool = True,
) -> Estimate:
    """The sweep's wall time on `slots` slots with `remaining[unit.id]` steps per seed left per
    unit (0: done; default: its budget, from its fork point for a fork), from the `shipped`
    measurements and those of the runs already in the sweep folder (`here`, by unit id). While
    more units run than `cores` hold (k × cpus_per_unit > `cores`), they share the cores and each
    runs at cores / (k × cpus_per_unit) of its measured rate (the measurements had their cores to
    themselves). The schedule is the runner's (`start_key`: units with fewer steps left than
    their budget resume first, then critical path first), or with `by_critical_path` false the
    file order (how sweeps ran before the runner ordered them)."""
    here = here or {}
    resumed = tuple(u.id for u in sweep.units if resumes(u, remaining.get(u.id, 0)))
    units, sources = [], set()
    for unit in sweep.units:
        steps = remaining.get(unit.id, unit.total_steps - unit.fork_step)
        if steps <= 0:
            units.append(UnitEstimate(unit.id, 0.0, "own run"))
            continue
        own = [here[unit.id]] if unit.id in here else []
        rate, matched, used = pick_rate(unit, own, list(here.values()), shipped)
        seconds = STARTUP_S + len(unit.seeds) * steps / rate
        units.append(UnitEstimate(unit.id, seconds, matched))
        sources.update(used)
    todo = [u.seconds for u in units if u.seconds > 0]
    seconds = {u.unit_id: u.seconds for u in units}
    by_id = {u.id: u for u in sweep.units}
    jobs = []
    for unit in sweep.units:
        if seconds[unit.id] <= 0:
            continue
        parent, after = unit.fork_of, 0.0
        if parent is not None and seconds.get(parent, 0) > 0:  # the parent still has to get there
            total = by_id[parent].total_steps
            left = remaining.get(parent, total)
            part = (unit.fork_step - (total - left)) / left if left > 0 else 0.0
            after = STARTUP_S + (seconds[parent] - STARTUP_S) * min(1.0, max(0.0, part))
        jobs.append((unit.id, seconds[unit.id], parent, after))
    return Estimate(
        seconds=fork_schedule_seconds(
            jobs,
            slots,
            by_critical_path,
            cores / sweep.cpus_per_unit if cores else None,
            frozenset(resumed),
        ),
        unit_seconds=sum(todo),
        slots=slots,
        units=tuple(units),
        sources=tuple(sorted(sources)),
        critical_paths=tuple(critical_paths(jobs).items()),
        resumed=resumed,
    )


def duration_text(seconds: float) -> str:
    minutes = seconds / 60
    if minutes < 1:
        return "under a minute"
    if minutes < 100:
        return f"~{minutes:.0f} min"
    if minutes < 48 * 60:
        return f"~{minutes / 60:.1f} h"
    return f"~{minutes / 60 / 24:.1f} days"


def describe(result: Estimate, where: str) -> str:
    """One line: `estimated wall time: ~78 min on this machine (2 workers; ...)`."""
    todo = [u for u in result.units if u.seconds > 0]
    if not todo:
        return "estimated wall time: nothing left to run"
    sources = ", ".join(result.sources)
    borrowed = (
        f"; {result.borrowed} of {len(todo)} units borrow the rate of another algorithm or task"
        if result.borrowed
        else ""
    )
    hours = result.unit_seconds / 3600
    compute = f", {hours:.1f} unit-hours" if hours >= 0.1 else ""
    return (
        f"estimated wall time: {duration_text(result.seconds)} {where} ({result.slots} "
        f"worker{'s' * (result.slots != 1)}; {len(todo)} unit{'s' * (len(todo) != 1)}{compute}; "
        f"from measured throughput of {sources}{borrowed})"
    )


# ----------------------------------------------------------------------------- files
def read_measurements(path: Path = MEASURED) -> list[Measurement]:
    with open(path, newline="", encoding="utf-8") as f:
        rows = [r for r in csv.DictReader(line for line in f if not line.startswith("#"))]
    return [
        Measurement(
            algo=r["algo"],
            task=r["task"],
            label=r["label"],
            seeds=int(r["seeds"]),
            steps=int(r["steps"]),
            train_s=float(r["train_s"]),
            source=r["source"],
        )
        for r in rows
    ]


def measure_run(run_dir: Path, unit_fields: dict, source: str) -> Measurement | None:
    """What a run folder's train.csv says about its unit's speed, or None if it has no rows."""
    from adarl.runs.logs import read_csv

    path = Path(run_dir) / TRAIN_CSV
    if not path.exists():
        return None
    try:
        steps, seconds = train_seconds(read_csv(path))
    except (OSError, ValueError, KeyError):
        return None
    if steps <= 0 or seconds <= 0:
        return None
    return Measurement(
        algo=unit_fields["algo"],
        task=unit_fields["task"],
        label=unit_fields["label"],
        seeds=len(unit_fields["seeds"]),
        steps=steps,
        train_s=seconds,
        source=source,
    )


def resumes(unit: Unit, steps_left: int) -> bool:
    """Does a run of `unit` with `steps_left` steps per seed left resume from a checkpoint?"""
    return 0 < steps_left < unit.total_steps - unit.fork_step


def remaining_steps(out: Path, unit: Unit) -> int:
    """Steps per seed a run of `unit` still has to train: from its newest checkpoint."""
    from adarl.runs.checkpoints import checkpoint_dirs

    run_dir = Path(out) / unit.id
    if (run_dir / DONE_FILE).exists():
        return 0
    found = checkpoint_dirs(run_dir)
    done = int(found[-1].name.split("_")[1]) if found else unit.fork_step  # a fork: the prefix
    return max(0, unit.total_steps - done)  # is its parent's


def for_sweep(sweep: Sweep, out: Path, slots: int, cores: int | None = None) -> Estimate:
    """The estimate for running `sweep` into `out` now, from the shipped measurements and the
    runs already in `out`."""
    here = {}
    for unit in sweep.units:
        fields = {"algo": unit.algo, "task": unit.task, "label": unit.label, "seeds": unit.seeds}
        found = measure_run(Path(out) / unit.id, fields, "this sweep's runs")
        if found is not None:
            here[unit.id] = found
    remaining = {u.id: remaining_steps(out, u) for u in sweep.units}
    return estimate(sweep, remaining, slots, read_measurements(), here, cores)


def unit_critical_paths(sweep: Sweep, out: Path) -> dict[str, float]:
    """Each unfinished unit's critical path (seconds on its own slot, `critical_paths`), by unit
    id. A ValueError if no measurement exists."""
    return dict(for_sweep(sweep, out, 1).critical_paths)


def start_order(sweep: Sweep, out: Path) -> list[Unit]:
    """The units in the order the runner starts them (`start_key`). Without any throughput
    measurement, resumed units go first by steps left, then the others in file order."""
    try:
        result = for_sweep(sweep, out, 1)
        seconds: dict[str, float] = {u.unit_id: u.seconds for u in result.units}
        paths, resumed = dict(result.critical_paths), set(result.resumed)
    except (ValueError, OSError):  # no throughput measurement to go by
        seconds = {u.id: float(remaining_steps(out, u)) for u in sweep.units}
        paths, resumed = {}, {u.id for u in sweep.units if resumes(u, int(seconds[u.id]))}
    index = {u.id: i for i, u in enumerate(sweep.units)}
    return sorted(
        sweep.units,
        key=lambda u: start_key(seconds[u.id], paths.get(u.id, 0.0), u.id in resumed, index[u.id]),
    )


def measurements_of(sweep_dir: Path, source: str) -> list[Measurement]:
    """Measurements of every unit of a sweep folder with a train.csv (its manifest lists them)."""
    data = read_json(Path(sweep_dir) / "manifest.json")
    found = []
    for uid, record in sorted(data["units"].items()):
        m = measure_run(Path(sweep_dir) / uid, record, source)
        if m is not None:
            found.append(m)
    return found


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(COLUMNS)
    for sweep_dir in argv:
        name = os.path.basename(os.path.normpath(sweep_dir))
        for m in measurements_of(Path(sweep_dir), f"{name} sweep"):
            writer.writerow(
                [m.algo, m.task, m.label, m.seeds, m.steps, f"{m.train_s:.1f}", m.source]
            )
    print(out.getvalue(), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
