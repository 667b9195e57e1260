"""`adarl export RUN_DIR --seed S --out policy.npz`: copy one seed's deterministic policy out of
a run. The file runs with NumPy alone:

    from adarl.policy import load
    act = load("policy.npz")
    action = act(obs)
"""

from __future__ import annotations

import argparse

from adarl.cli.common import add_checkpoint_argument

HELP = "export one seed's deterministic policy as a NumPy-only .npz file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", metavar="RUN_DIR", help="a run folder")
    parser.add_argument("--seed", type=int, default=None, help="seed (default: the lowest)")
    parser.add_argument("--out", required=True, metavar="FILE", help="output .npz file")
    add_checkpoint_argument(parser)


def run(args: argparse.Namespace) -> int:
    from adarl.export.policy import export_policy
    from adarl.results.runs import load_run
    from adarl.runs.checkpoints import policy_files, select_checkpoint

    run_ = load_run(args.run_dir)
    seed = args.seed
    if seed is None:
        seed = next(iter(policy_files(select_checkpoint(run_.path, args.checkpoint))))
    done = export_policy(run_, seed, args.out, args.checkpoint)
    print(
        f"wrote {done.out}: seed {seed} of {run_.path} ({run_.task}, {run_.label}) at step "
        f"{done.step}; obs {done.obs_dim} -> action {done.act_dim}"
    )
    print(
        f"parameters: {done.n_params:,} (full rank: {done.n_params_full:,}; "
        f"{100 * done.kept:.1f}% kept after rank adaptation)"
    )
    print(f'load with NumPy only: from adarl.policy import load; act = load("{done.out}")')
    return 0
