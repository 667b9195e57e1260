"""`adarl play RUN_DIR --seed S --dynamics … --video out.mp4`: render deterministic rollouts of a
seed's policy offscreen.

MuJoCo renders with the backend in `MUJOCO_GL` (default here: egl). EGL needs the system package
`libegl1` (Debian/Ubuntu); `MUJOCO_GL=osmesa` renders in software and needs `libosmesa6`.
`.mp4` needs `pip install 'adarl[video]'` (imageio-ffmpeg); `.gif` works without it.
"""

from __future__ import annotations

import argparse

from adarl.cli.common import add_checkpoint_argument, add_env_module_argument, name_env_modules

HELP = "render a seed's policy offscreen to a video (.mp4 or .gif) under chosen dynamics"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", metavar="RUN_DIR", help="a run folder")
    parser.add_argument("--seed", type=int, default=None, help="seed (default: the lowest)")
    parser.add_argument(
        "--dynamics", default="nominal", help="nominal (default), default, paper, fixed:P=V,…"
    )
    parser.add_argument(
        "--hold", action="append", default=[], metavar="P=V", help="fix parameter P at V"
    )
    parser.add_argument("--video", required=True, metavar="FILE", help="output .mp4 or .gif")
    parser.add_argument("--episodes", type=int, default=1, help="episodes to render (default 1)")
    add_checkpoint_argument(parser)
    add_env_module_argument(parser)
    parser.add_argument("--env-seed", type=int, default=0, help="episode k resets with seed+k")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--fps", type=int, default=30, help="target frames per second")
    parser.add_argument(
        "--max-episode-steps", type=int, default=None, help="cut episodes after this many steps"
    )


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from adarl.evaluation import grid
    from adarl.export.video import check_video_path, play, prepare_backend
    from adarl.files import check_writable_file
    from adarl.results.runs import load_run
    from adarl.runs.checkpoints import policy_file, policy_files, select_checkpoint
    from adarl.runs.folder import check_run_output

    name_env_modules(args)
    prepare_backend()  # before anything imports MuJoCo
    check_video_path(Path(args.video))
    check_run_output(args.video)
    check_writable_file(args.video, "--video")
    run_ = load_run(args.run_dir)
    seed = args.seed
    if seed is None:
        seed = next(iter(policy_files(select_checkpoint(run_.path, args.checkpoint))))
    path = policy_file(run_.path, seed, args.checkpoint)
    holds = dict(grid.parse_hold(h) for h in args.hold)
    dynamics = grid.point_label(args.dynamics, holds)

    from adarl.envs import parse_dynamics
    from adarl.evaluation.evaluate import run_env_options, run_task
    from adarl.policy import load

    parse_dynamics(dynamics, run_task(run_))  # the run's model: its env-kwargs and env-module
    episodes = play(
        load(path),
        run_.task,
        dynamics,
        args.video,
        episodes=args.episodes,
        seed=args.env_seed,
        width=args.width,
        height=args.height,
        fps=args.fps,
        max_steps=args.max_episode_steps,
        overrides=run_env_options(run_),  # the run's physics, model version, env-kwargs, …
    )
    for k, ep in enumerate(episodes):
        params = ", ".join(f"{p}={v:g}" for p, v in ep.params.items())
        print(f"episode {k}: return {ep.ret:.1f}, {ep.length} steps ({params})")
    print(f"wrote {args.video} (seed {seed}, {run_.task}, {dynamics})")
    return 0
