"""What a run starts from (`adarl.train.launch`): the `adarl train` flags each kind stands for,
its JSON record for the sweep worker, and the tracking flags. Training through `launch.train`:
tests/cli/test_train_cli.py, tests/train/test_fork.py and tests/sweeps/test_worker.py."""

import json

import pytest

from adarl.errors import UsageError
from adarl.train import launch

NEW = launch.New("sac", "smoke", {"task": "hopper", "total_steps": "1000"})
FORK = launch.ForkOf("/s/hopper/a/seeds-0-1", 950, {"apply_cuts": "false"})


def test_the_flags_each_start_stands_for():
    assert NEW.argv() == (
        "--algo", "sac", "--preset", "smoke", "--task", "hopper", "--total-steps", "1000"
    )  # fmt: skip
    assert launch.New("adarl").argv() == ("--algo", "adarl")
    assert FORK.argv() == (
        "--fork", "/s/hopper/a/seeds-0-1", "--at", "950", "--apply-cuts", "false"
    )  # fmt: skip
    assert launch.Resume("runs/r").argv() == ("--resume", "runs/r")


@pytest.mark.parametrize("start", [NEW, FORK, launch.New("adarl")])
def test_a_record_survives_json(start):
    assert launch.from_record(json.loads(json.dumps(launch.record(start)))) == start


def test_a_new_run_resolves_as_its_flags_do():
    config = NEW.config()
    assert (config.algo, config.task, config.total_steps) == ("sac", "hopper", 1000)
    with pytest.raises(UsageError, match="--uncertainty-set does not apply to --algo sac"):
        launch.New("sac", None, {"uncertainty_set": "ds"}).config()


def test_tracking_flags():
    assert launch.Tracking().argv() == ()
    both = launch.Tracking(True, project="p", group="g")
    assert both.argv() == ("--track", "--wandb-project", "p", "--wandb-group", "g")
    both.check()
    with pytest.raises(UsageError, match="^--wandb-entity is for --track$"):
        launch.Tracking(entity="me").check()
