"""Peak memory of writing and reading a checkpoint's replay buffers: joined in memory (np.savez
of the concatenated lanes, np.load of the whole array: what adarl did before adarl.runs.npz)
against adarl.runs.npz (lanes written one after another, members memory-mapped and copied in
lane by lane). Each way runs in a fresh process, whose peak anonymous resident memory
(RssAnon, sampled every 2 ms and at the joined arrays' peak) beyond the live buffers is
reported: pages of a memory-mapped file are page cache, which the kernel drops under pressure.

    python bench/checkpoint_memory.py [--seeds 5] [--rows 200000] [--task humanoid]

Humanoid's row is 1,466 bytes (float32 obs 348, act 17, rew; uint8 term, valid:
adarl.algos.replay.row_bytes), so 5 seeds × 200k rows are 1.47 GB of buffers.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

DIMS = {"hopper": (11, 3), "walker2d": (17, 6), "ant": (105, 8), "humanoid": (348, 17)}

CHILD = r"""
import sys, threading, time, numpy as np
from adarl.runs import npz
way, path, seeds, rows, obs, act = sys.argv[1], sys.argv[2], *map(int, sys.argv[3:])
def anon():  # anonymous resident memory: what the OOM killer frees (mapped file pages are not)
    for line in open("/proc/self/status"):
        if line.startswith("RssAnon"):
            return int(line.split()[1]) * 1024
peak, done = [0], []
def sample():
    while not done:
        peak[0] = max(peak[0], anon())
        time.sleep(0.002)
def lanes():
    return [{"obs": np.ones((1, rows, obs), np.float32), "act": np.ones((1, rows, act), np.float32),
             "rew": np.ones((1, rows), np.float32), "term": np.ones((1, rows), np.uint8),
             "valid": np.ones((1, rows), np.uint8)} for _ in range(seeds)]
live = lanes()
keys = list(live[0])
base = anon()
threading.Thread(target=sample, daemon=True).start()
if way == "write-joined":
    joined = {k: np.concatenate([b[k] for b in live]) for k in keys}
    peak[0] = max(peak[0], anon())
    np.savez(path, **joined)
elif way == "write-npz":
    with open(path, "wb") as f:
        npz.write(f, {k: npz.Stacked([b[k] for b in live]) for k in keys})
else:  # reading: the learner's lanes are filled from the file one by one
    if way == "read-joined":
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
    else:
        arrays = npz.read(path)
    for i, lane in enumerate(live):
        for k in keys:
            lane[k][:] = arrays[k][i : i + 1]
peak[0] = max(peak[0], anon())
done.append(1)
print(peak[0] - base)
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--rows", type=int, default=200_000)
    parser.add_argument("--task", choices=DIMS, default="humanoid")
    args = parser.parse_args()
    obs, act = DIMS[args.task]
    buffers = args.seeds * args.rows * (4 * (obs + act + 1) + 2)
    print(
        f"{args.task}: {args.seeds} seeds x {args.rows:,} rows = {buffers / 1e9:.2f} GB of buffers"
    )
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "arrays.npz"
        for way in ("write-joined", "write-npz", "read-joined", "read-npz"):
            out = subprocess.run(
                [
                    sys.executable,
                    "-c",
                    CHILD,
                    way,
                    str(path),
                    str(args.seeds),
                    str(args.rows),
                    str(obs),
                    str(act),
                ],
                capture_output=True,
                text=True,
                check=True,
            )
            extra = int(out.stdout.split()[-1])
            print(
                f"  {way:13s} anonymous peak beyond the live buffers: {extra / 1e9:5.2f} GB "
                f"({extra / buffers:.2f} x the buffers)"
            )


if __name__ == "__main__":
    main()
