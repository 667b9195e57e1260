"""Flags every command shares are defined once (`adarl.cli.common`) and accepted by each."""

from adarl.cli.main import COMMANDS, build_parser

MINIMAL = {  # the required arguments of each command
    "train": [],
    "tasks": [],
    "ranks": ["RUN"],
    "evaluate": ["RUN"],
    "report": ["RUN", "--out", "R"],
    "play": ["RUN", "--video", "v.gif"],
    "export": ["RUN", "--out", "p.npz"],
    "sweep": ["smoke"],
    "theory": ["--out", "T"],
}


def test_every_command_takes_the_common_flags():
    assert set(MINIMAL) == set(COMMANDS)
    parser = build_parser()
    for command, argv in MINIMAL.items():
        assert parser.parse_args([command, *argv]).no_progress is False, command
        assert parser.parse_args([command, *argv, "--no-progress"]).no_progress is True, command


def test_policy_commands_share_the_checkpoint_flag():
    parser = build_parser()
    for command in ("evaluate", "play", "export"):
        args = parser.parse_args([command, *MINIMAL[command], "--checkpoint", "5000"])
        assert args.checkpoint == 5000, command
        assert parser.parse_args([command, *MINIMAL[command]]).checkpoint is None, command
