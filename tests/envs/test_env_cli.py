"""`adarl tasks`."""

import json

from adarl.cli.main import main


def test_tasks_lists_everything(capsys):
    assert main(["tasks"]) == 0
    out = capsys.readouterr().out
    for text in (
        "hopper (Hopper-v5)",
        "walker2d (Walker2d-v5)",
        "ant (Ant-v5)",
        "humanoid (Humanoid-v5)",
        "intrinsic rank 2·3+1 = 7",
        "intrinsic rank 2·6+1 = 13",
        "intrinsic rank 2·8+1 = 17",
        "intrinsic rank 2·17+1 = 35",
        "torso_length = 0.4 + 0.2·sin(0.2·i)",  # paper
        "torso_length = 0.4 + 0.1·sin(0.2·i)",  # ompo
        "foot_length = 0.1 + 0.05·sin(0.3·i)",
        "gravity = 14.715 + 4.905·sin(0.5·i), wind = 1 + 0.5·sin(0.5·i)",
        "foot_length     0.195",
        "spring reference 2 rad",
        "density 1.2",
    ):
        assert text in out, text


def test_tasks_json_and_bad_name(capsys):
    assert main(["tasks", "ant", "--json"]) == 0
    (ant,) = json.loads(capsys.readouterr().out)
    assert ant["intrinsic_rank"] == 17 and ant["params"]["gravity"] == 9.81
    assert ant["nominal"] == {"gravity": 14.715, "wind": 1.0}
    assert main(["tasks", "cheetah"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "'cheetah'" in err and "hopper" in err
