"""`adarl tasks`: every Gymnasium MuJoCo id beside the paper's four, with d_a and 2·d_a+1 read
from Gymnasium itself, a named id's elements read from its compiled model, JSON, a user's
module, and bad input (one line, exit 2)."""

import json

import pytest

from adarl.cli.main import main

gymnasium = pytest.importorskip("gymnasium")
mujoco = pytest.importorskip("mujoco")

V5 = [
    "Ant-v5", "HalfCheetah-v5", "Hopper-v5", "Humanoid-v5", "HumanoidStandup-v5",
    "InvertedDoublePendulum-v5", "InvertedPendulum-v5", "Pusher-v5", "Reacher-v5", "Swimmer-v5",
    "Walker2d-v5",
]  # fmt: skip


def gymnasium_sizes(gym_id):
    """(obs, act, time limit, |g| as printed) of a registered id, from Gymnasium alone."""
    import numpy as np

    env = gymnasium.make(gym_id)
    try:
        gravity = np.linalg.norm(env.unwrapped.model.opt.gravity)
        return (
            env.observation_space.shape[0],
            env.action_space.shape[0],
            gymnasium.spec(gym_id).max_episode_steps,
            f"{gravity:.4g}",
        )
    finally:
        env.close()


def model_names(xml_path):
    """{kind: names} of the named bodies (but the world), geoms, joints and actuators."""
    model = mujoco.MjModel.from_xml_path(xml_path)
    kinds = {
        "body": (mujoco.mjtObj.mjOBJ_BODY, model.nbody),
        "geom": (mujoco.mjtObj.mjOBJ_GEOM, model.ngeom),
        "joint": (mujoco.mjtObj.mjOBJ_JOINT, model.njnt),
        "actuator": (mujoco.mjtObj.mjOBJ_ACTUATOR, model.nu),
    }
    names = {
        kind: [mujoco.mj_id2name(model, obj, i) for i in range(count)]
        for kind, (obj, count) in kinds.items()
    }
    return {kind: [n for n in ns if n and n != "world"] for kind, ns in names.items()}, model


def test_every_gymnasium_mujoco_v5_id_is_listed_with_its_sizes(capsys):
    assert main(["tasks"]) == 0
    out = capsys.readouterr().out
    assert "hopper (Hopper-v5): obs 11, act 3, intrinsic rank 2·3+1 = 7" in out  # as before
    lines = {line.split()[0]: line.split() for line in out.splitlines() if line.startswith("  ")}
    for gym_id in V5:
        obs, act, limit, gravity = gymnasium_sizes(gym_id)
        expected = [str(obs), str(act), str(2 * act + 1), str(limit), gravity, "varies"]
        assert lines[gym_id][1:7] == expected, gym_id
    assert "Ant-v4" in lines  # v4 models too
    for param in ("mass_scale", "friction_scale", "damping_scale", "actuator_scale", "gravity"):
        assert f"    {param} " in out
    assert "wind (optional)" in out


def test_a_named_id_shows_the_elements_of_its_model(capsys):
    from adarl.envs import get_task

    assert main(["tasks", "HalfCheetah-v5"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(
        "HalfCheetah-v5 (Gymnasium MuJoCo task): obs 17, act 6, intrinsic rank 2·6+1 = 13, "
        "time limit 1000 steps"
    )
    names, model = model_names(get_task("HalfCheetah-v5").xml_path)
    text = " ".join(out.split())  # the lists wrap
    bodies = ", ".join(f"{b} {model.body(b).mass[0]:.4g}" for b in names["body"])
    assert f"body .mass (kg): {bodies}" in text and "torso 6.25," in text
    assert f"geom .friction[0-2], .size[0-2]: {', '.join(names['geom'])}" in text
    assert f".frictionloss: {', '.join(names['joint'])}" in text
    assert f"actuator .gear: {', '.join(names['actuator'])}" in text
    assert main(["tasks", "Hopper-v5"]) == 0  # Hopper's motors are unnamed
    assert (
        "actuator  .gear: (none named; actuator_scale scales them all)" in capsys.readouterr().out
    )


def test_json_lists_them_all_and_a_named_one_with_its_elements(capsys):
    from adarl.envs import get_task

    assert main(["tasks", "--json"]) == 0
    tasks = {t["name"]: t for t in json.loads(capsys.readouterr().out)}
    assert [tasks[n]["kind"] for n in ("hopper", "walker2d", "ant", "humanoid")] == ["paper"] * 4
    for gym_id in V5:
        obs, act, limit, _ = gymnasium_sizes(gym_id)
        task = tasks[gym_id]
        assert (task["kind"], task["obs_dim"], task["act_dim"]) == ("mujoco", obs, act)
        assert task["intrinsic_rank"] == 2 * act + 1 and task["max_episode_steps"] == limit
        assert "elements" not in task
    assert tasks["Pusher-v5"]["params"]["gravity"] == 0.0  # Pusher's XML has no gravity
    assert main(["tasks", "InvertedPendulum-v5", "--json"]) == 0
    (pendulum,) = json.loads(capsys.readouterr().out)
    names, _ = model_names(get_task("InvertedPendulum-v5").xml_path)
    assert pendulum["elements"] == names and names["body"] == ["cart", "pole"]


def test_a_users_module_and_xml(tmp_path, capsys):
    import user_env

    xml = user_env.write_xml(tmp_path)
    assert main(["tasks", "--env-module", "user_env"]) == 0
    out = capsys.readouterr().out
    assert f"{user_env.ENV_ID}" in out and "xml_file" in out  # listed; it needs its XML
    argv = ["tasks", user_env.ENV_ID, "--env-module", "user_env", "--env-kwargs", f"xml_file={xml}"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{user_env.ENV_ID} (Gymnasium MuJoCo task): obs 4, act 2")
    assert (
        f"model: {xml}" in out and ".mass (kg): ball 1\n" in out and ".gear: push_x, push_y" in out
    )


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["cheetah"], "unknown task 'cheetah'; allowed: hopper, walker2d, ant, humanoid"),
        (["Cheetah-v9"], "unknown task 'Cheetah-v9'"),
        (["--env-kwargs", "xml_file=a.xml"], "applies to a named Gymnasium id"),
        (["hopper", "--env-kwargs", "xml_file=a.xml"], "apply to Gymnasium ids, not to task"),
        (["--env-module", "no_such_module_here"], "cannot import env-module"),
        (
            ["HalfCheetah-v5", "--env-kwargs", "xml_file=/nowhere.xml"],
            "cannot make env 'HalfCheetah-v5' (OSError: File /nowhere.xml",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2(capsys, argv, fragment):
    assert main(["tasks", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and fragment in err, err
