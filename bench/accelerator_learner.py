"""Training throughput of the device backend against the host backend (issue 36): AdaRL on Hopper
(nominal physics, or `--task`/`--dynamics`), seed-steps/s at several seed counts, one chunk's
time, and the memory used.

    python bench/accelerator_learner.py --seeds 1 16 64 256 1024 --chunks 20 --csv OUT.csv
    python bench/accelerator_learner.py --host --chunks 20          # the host backend, one seed
    python bench/accelerator_learner.py --task walker2d --dynamics paper --seeds 1024
    python bench/accelerator_learner.py --seeds 1024 --device-solver 100,4   # line search capped

Each measurement builds the learner the one loop would (`trainers.make_learner`, the config
`adarl train --algo adarl --backend device --task T --dynamics D --seeds 0-(N-1)` resolves to, with
`start_steps` = `update_after` = one chunk so that every timed chunk updates), calls `advance` once
to compile and fill one chunk, then times `--chunks` more chunks of `update_every` env steps and
`update_every` gradient steps each, for all seeds at once (on the device up to
`device_learner.MAX_CHUNKS` per advance, chunk k+1 dispatched before chunk k's episodes are
read, as in training). Prints one CSV line per measurement:

    task,dynamics,solver,backend,platform,seeds,chunk_steps,compile_s,chunk_s,seed_steps_per_s,update_ms,memory_mb

`solver`: the device's `--device-solver` (`xml`, or `100/4` for 100,4). `update_ms`: a chunk's
time over its `update_every` gradient steps (the env steps included: an upper bound on one
update). `memory_mb`: the device's peak bytes in use where JAX reports them
(GPU), else the process's peak resident set. A seed count that does not fit (memory, time) prints
a `failed` line and the next one runs.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time

HEADER = "task,dynamics,solver,backend,platform,seeds,chunk_steps,compile_s,chunk_s,seed_steps_per_s,update_ms,memory_mb"


def config_for(
    task: str,
    dynamics: str,
    backend: str,
    n_seeds: int,
    buffer_size: int,
    update_every: int,
    solver: str = "xml",
):
    from adarl.algos import registry

    flags = {
        "task": task,
        "backend": backend,
        "dynamics": dynamics,
        "seeds": list(range(n_seeds)),
        "buffer_size": buffer_size,
        "update_every": update_every,
        "start_steps": update_every,
        "update_after": update_every,
        "total_steps": 10**9 // update_every * update_every,
    }
    if backend == "device":
        flags["device_solver"] = solver
    return registry.resolve_config("adarl", None, flags)


def progress(message: str) -> None:
    """A line on stderr as the measurement goes (bench/accelerator.sh keeps them in
    accelerator.err), so that one stopped by its time limit still tells how far it got."""
    print(f"# {message}", file=sys.stderr, flush=True)


def solver_column(solver: str, backend: str) -> str:
    """The solver as the CSV shows it: empty for the host, `100/4` for `--device-solver 100,4`."""
    return solver.replace(",", "/") if backend == "device" else ""


def memory_mb() -> float:
    import jax

    stats = jax.devices()[0].memory_stats() or {}
    if "peak_bytes_in_use" in stats:
        return stats["peak_bytes_in_use"] / 2**20
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10  # kB on Linux


def measure(args, backend: str, n_seeds: int) -> str:
    import jax

    from adarl.train import device_learner
    from adarl.train.trainers import make_learner

    chunks, update_every = args.chunks, args.update_every
    config = config_for(
        args.task,
        args.dynamics,
        backend,
        n_seeds,
        args.buffer_size,
        update_every,
        args.device_solver,
    )
    begin = time.perf_counter()
    learner = make_learner(config)
    learner.fresh()
    progress(f"{n_seeds} seeds: built in {time.perf_counter() - begin:.1f} s")
    step = 0
    most = device_learner.MAX_CHUNKS  # a device advance runs up to this many chunks
    device_learner.MAX_CHUNKS = 1
    try:
        start = time.perf_counter()
        step = learner.advance(step).step  # compiles, fills the first chunk
        jax.block_until_ready(getattr(learner, "state", None))
        compile_s = time.perf_counter() - start
        progress(f"{n_seeds} seeds: compiled and ran the first chunk in {compile_s:.1f} s")
        start, first, k = time.perf_counter(), step, 0
        while step - first < chunks * update_every:  # `chunks` chunks, pipelined as in training
            device_learner.MAX_CHUNKS = min(most, chunks - (step - first) // update_every)
            before, k = time.perf_counter(), k + 1
            step = learner.advance(step).step  # returns its episodes: the host has waited
            progress(
                f"{n_seeds} seeds: advance {k} to step {step} in "
                f"{time.perf_counter() - before:.3f} s"
            )
    finally:
        device_learner.MAX_CHUNKS = most
    jax.block_until_ready(getattr(learner, "state", None))
    run_s = time.perf_counter() - start
    chunk_s = run_s * update_every / (step - first)
    rate = n_seeds * (step - first) / run_s
    platform = jax.devices()[0].platform
    return (
        f"{args.task},{args.dynamics},{solver_column(args.device_solver, backend)},"
        f"{backend},{platform},{n_seeds},{update_every},{compile_s:.1f},{chunk_s:.4f},"
        f"{rate:.1f},{1e3 * chunk_s / update_every:.3f},{memory_mb():.0f}"
    )


def emit(line: str, csv: str | None) -> None:
    print(line, flush=True)
    if csv:
        new = not os.path.exists(csv)
        with open(csv, "a") as f:
            f.write((HEADER + "\n" if new else "") + line + "\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--host", action="store_true", help="the host backend, one lane per seed")
    parser.add_argument(
        "--task", default="hopper", choices=["hopper", "walker2d", "ant", "humanoid"]
    )
    parser.add_argument("--dynamics", default="nominal")
    parser.add_argument("--device-solver", default="xml", help="xml, or ITERATIONS,LS_ITERATIONS")
    parser.add_argument("--chunks", type=int, default=20)
    parser.add_argument("--update-every", type=int, default=50)
    parser.add_argument("--buffer-size", type=int, default=100_000)
    parser.add_argument("--csv", default=None)
    args = parser.parse_args(argv)
    from adarl.device.tasks import solver_caps
    from adarl.errors import UsageError

    try:
        solver_caps(args.device_solver)
    except UsageError as exc:
        print(f"accelerator_learner.py: error: {exc}", file=sys.stderr)
        return 2
    backend = "host" if args.host else "device"
    for n in args.seeds:
        try:
            line = measure(args, backend, n)
        except Exception as exc:  # one seed count failing (memory) must not lose the others
            solver = solver_column(args.device_solver, backend)
            line = (
                f"{args.task},{args.dynamics},{solver},{backend},failed,{n},{args.update_every},"
                f",,,,{type(exc).__name__}"
            )
        emit(line, args.csv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
