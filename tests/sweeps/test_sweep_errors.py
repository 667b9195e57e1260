"""Bad input: a one-line error naming the problem, exit code 2, and nothing started (no output
folder, no Ray instance)."""

import fcntl
import socket
import sys
import time

import pytest

from adarl.cli.main import main
from adarl.runs import folder
from adarl.runs.layout import RUN_FORMAT_VERSION
from adarl.sweeps import manifest, spec


def _run(capsys, *argv) -> str:
    code = main(["sweep", *map(str, argv)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("adarl sweep: error: "), err
    return err


@pytest.mark.parametrize("changes, message", [
    ({"seed": 3}, "unknown key 'seed'"),
    ({"tasks": ["hopper", "cheetah"]}, "unknown task 'cheetah'"),
    ({"algos": ["sac", "ppo"]}, "unknown algo 'ppo'"),
    ({"tasks": []}, "tasks is empty"),
    ({"algos": [{"algo": "sac-fixed-rank", "grid": {"rank": []}}]}, "grid 'rank' is empty"),
    ({"seeds": []}, "seeds is empty"),
    ({"budget": 0}, "budget for hopper must be a number of steps > 0"),
    ({"budget": -5}, "budget for hopper must be a number of steps > 0"),
    ({"overrides": {"learning_rate": 0.1}}, "unknown key 'learning_rate'"),
    ({"algos": [{"algo": "sac", "rank_rule": "cumulative", "gamma": 2}]}, "gamma must be in"),
])  # fmt: skip
def test_bad_sweep_file(tmp_path, capsys, write_spec, changes, message):
    err = _run(capsys, write_spec(tmp_path / "s.yaml", **changes), "--out", tmp_path / "out")
    assert message in err
    assert not (tmp_path / "out").exists()


def test_unknown_preset_and_broken_yaml(tmp_path, capsys):
    listed = "presets: claim2-first-look, fixed-rank-power, fixed-rank-sweep, fixed-rank-u"
    assert listed in _run(capsys, "paper-table2")
    broken = tmp_path / "b.yaml"
    broken.write_text("tasks: [hopper\n")
    assert "is not valid YAML" in _run(capsys, broken, "--out", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_ray_backend_without_ray_says_how_to_install(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    err = _run(capsys, "smoke", "--backend", "ray", "--out", tmp_path / "out")
    assert "pip install 'adarl[ray]'" in err
    assert not (tmp_path / "out").exists()


def test_unreachable_ray_address(tmp_path, capsys):
    pytest.importorskip("ray")
    err = _run(
        capsys, "smoke", "--backend", "ray", "--address", "127.0.0.1:1", "--out", tmp_path / "out"
    )
    assert "cannot reach the Ray cluster at 127.0.0.1:1" in err
    assert not (tmp_path / "out").exists()
    import ray

    assert not ray.is_initialized()


def test_a_ray_address_that_does_not_answer(tmp_path, capsys, monkeypatch):
    """A port that accepts connections and never replies (a firewall, a hung head node, another
    service): a one-line error after the connect timeout, not Ray's minutes of retrying."""
    pytest.importorskip("ray")
    from adarl import executor

    monkeypatch.setattr(executor, "CONNECT_TIMEOUT_S", 0.5)
    with socket.create_server(("127.0.0.1", 0)) as silent:  # listens, never accepts or answers
        address = f"127.0.0.1:{silent.getsockname()[1]}"
        started = time.monotonic()
        err = _run(
            capsys, "smoke", "--backend", "ray", "--address", address, "--out", tmp_path / "o"
        )
        assert time.monotonic() - started < 10
    assert f"the Ray cluster at {address} does not answer (no reply in 0.5 s)" in err
    assert not (tmp_path / "o").exists()
    import ray

    assert not ray.is_initialized()


def test_address_needs_the_ray_backend(tmp_path, capsys):
    assert "--address is for --backend ray" in _run(
        capsys, "smoke", "--address", "h:1", "--out", tmp_path / "out"
    )


def test_a_folder_holding_another_sweep_is_refused(tmp_path, capsys, write_spec):
    out = tmp_path / "out"
    first = spec.load(str(write_spec(tmp_path / "a.yaml")))
    manifest.Manifest.open(out, first, "adarl sweep a.yaml").save()
    other = write_spec(tmp_path / "b.yaml", budget=2000)
    assert "holds a different sweep" in _run(capsys, other, "--out", out)
    assert not (out / "hopper").exists()


def test_a_folder_in_use_by_another_sweep_is_refused(tmp_path, capsys, write_spec):
    out = tmp_path / "out"
    (out / ".state").mkdir(parents=True)
    with open(out / ".state" / "sweep.lock", "a+") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        assert "in use by another adarl sweep" in _run(
            capsys, write_spec(tmp_path / "s.yaml"), "--out", out
        )
    assert not (out / "hopper").exists() and not (out / "manifest.json").exists()


def test_a_run_folder_with_other_settings_is_refused(tmp_path, capsys, write_spec):
    from adarl import __version__
    from adarl.algos import registry

    spec_file = write_spec(tmp_path / "s.yaml")
    unit = spec.load(str(spec_file)).units[0]
    start = unit.start
    other = registry.resolve_config(unit.algo, start.preset, {**start.flags, "total_steps": "2000"})
    run_dir = tmp_path / "out" / unit.id
    run_dir.mkdir(parents=True)
    extra = {"format_version": RUN_FORMAT_VERSION, "adarl_version": __version__}
    (run_dir / "config.yaml").write_text(folder.config_yaml(other, extra))
    err = _run(capsys, spec_file, "--out", tmp_path / "out")
    assert "holds a run with other settings (total_steps: 2000 there, 1000 in this sweep)" in err
    assert not (tmp_path / "out" / "manifest.json").exists()
