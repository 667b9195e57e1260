"""Fixed-seed smoke runs of every algorithm, and a bit-for-bit comparison of two sets of them.

Code that a running experiment uses may change only if its results stay bit-identical (the
campaign resumes across the change). Train with the old code, train with the new, compare:

    git worktree add /tmp/old <commit>
    python bench/same_bits.py train /tmp/bits-old --code /tmp/old
    python bench/same_bits.py train /tmp/bits-new
    python bench/same_bits.py compare /tmp/bits-old /tmp/bits-new

Every algorithm of the registry trains seeds 0 and 3 (two lanes) at the smoke preset, AdaRL with
a truncation in the budget, and AdaRL and its control once more with Eq. 5 (`cumulative`, the
campaign's rule). Each run's code is the checkout `--code` (default: this one): the trainer runs
in that folder, because `python -m` puts the working folder ahead of PYTHONPATH and of the
editable install, and `compare` reads the commit each side ran from its runs' environment.json
and refuses (exit 2) when both ran the same one. The comparison covers every CSV (timing columns
aside) and every array of every `.npz` (checkpoints, policies, spectra); it prints each difference
and exits 1 if there is one. Files only the new code writes are listed as added, not as
differences; TensorBoard event files (named by their time) are left out.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

TIMING_COLUMNS = {"steps_per_s", "wall_s", "time", "seconds"}
EXTRA_FLAGS = {"sac-fixed-rank": ["--rank", "16"]}  # what an algorithm cannot train without
EQ5 = ("adarl", "adarl-control")  # trained once more with the campaign's rule
HERE = Path(__file__).resolve().parents[1]


def algorithms() -> list[str]:
    from adarl.algos import registry

    return list(registry.ALGORITHMS)


def train(out: Path, algos: list[str], code: Path = HERE) -> None:
    """Smoke runs of `algos` into OUT/<algo> (and OUT/<algo>-cumulative), with `code`'s adarl."""
    out, code = out.resolve(), code.resolve()
    env = {**os.environ, "PYTHONPATH": str(code)}
    runs = [(algo, algo, []) for algo in algos]
    runs += [(algo, f"{algo}-cumulative", ["--rank-rule", "cumulative"]) for algo in EQ5]
    for algo, name, flags in runs:
        if algo not in algos:
            continue
        subprocess.run(
            [sys.executable, "-m", "adarl.cli.main", "train", "--algo", algo, "--preset", "smoke"]
            + ["--seeds", "0,3", "--out", str(out / name), "--no-report"]
            + EXTRA_FLAGS.get(algo, []) + flags,
            check=True, cwd=code, env=env,
        )  # fmt: skip


def commits(root: Path) -> set[str]:
    """The adarl commits the runs under `root` recorded in their environment.json (`+dirty` with
    uncommitted changes, `unknown` outside a git checkout)."""
    from adarl.runs.provenance import read_environment

    found = set()
    for path in root.glob("*/environment.json"):
        adarl = read_environment(path.parent)["adarl"]
        dirty = "+dirty" if adarl.get("git_dirty") else ""
        found.add(f"{adarl.get('git_commit') or 'unknown'}{dirty}")
    return found


def csv_rows(path: Path) -> list[dict]:
    with path.open(newline="") as f:
        return [
            {k: v for k, v in row.items() if k not in TIMING_COLUMNS} for row in csv.DictReader(f)
        ]


def files(root: Path) -> set[Path]:
    return {
        p.relative_to(root)
        for p in root.rglob("*")
        if p.is_file() and not p.name.startswith("events.out.tfevents")
    }


def compare(old: Path, new: Path) -> tuple[list[str], list[str]]:
    """(differences, files added by the new code)."""
    differences = []
    old_files, new_files = files(old), files(new)
    for name in sorted(old_files - new_files):
        differences.append(f"{name}: only in old")
    for name in sorted(old_files & new_files):
        a, b = old / name, new / name
        if name.suffix == ".csv" and csv_rows(a) != csv_rows(b):
            differences.append(f"{name}: rows differ")
        elif name.suffix == ".npz":
            with np.load(a) as x, np.load(b) as y:
                if sorted(x.files) != sorted(y.files):
                    differences.append(f"{name}: arrays {sorted(x.files)} != {sorted(y.files)}")
                    continue
                for key in x.files:
                    if x[key].dtype != y[key].dtype or not np.array_equal(x[key], y[key]):
                        differences.append(f"{name}: {key} differs")
    return differences, [f"{name}: added" for name in sorted(new_files - old_files)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train", help="smoke runs of every algorithm into OUT/<algo>")
    t.add_argument("out", type=Path)
    t.add_argument("--algos", nargs="*", help="default: every algorithm of the registry")
    t.add_argument("--code", type=Path, default=HERE, help="the checkout to run (default: this)")
    c = sub.add_parser("compare", help="compare two folders written by `train`")
    c.add_argument("old", type=Path)
    c.add_argument("new", type=Path)
    args = parser.parse_args()
    if args.command == "train":
        if not (args.code / "adarl").is_dir():
            parser.error(f"--code {args.code} holds no adarl package; allowed: a checkout of adarl")
        train(args.out, args.algos or algorithms(), args.code)
        return 0
    old_commits, new_commits = commits(args.old), commits(args.new)
    print(f"old ran {sorted(old_commits)}, new ran {sorted(new_commits)}")
    same = old_commits == new_commits and len(old_commits) == 1
    if same and not next(iter(old_commits)).endswith(("+dirty", "unknown")):
        print("both sides ran the same commit: nothing was compared")
        return 2
    differences, added = compare(args.old, args.new)
    print("\n".join(added + differences))
    print(f"{len(differences)} differences" if differences else "bit-identical")
    return 1 if differences else 0


if __name__ == "__main__":
    sys.exit(main())
