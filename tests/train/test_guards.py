"""The divergence watch: non-finite values stop a run, or warn once with --on-divergence continue."""

import numpy as np
import pytest

from adarl.errors import Diverged
from adarl.train.guards import DivergenceWatch


def test_divergence_watch_names_step_seeds_and_quantity(tmp_path, capsys):
    watch = DivergenceWatch(tmp_path, "stop")
    watch.check(10)  # nothing noted: nothing happens
    watch.note_values("loss_q", [0, 3, 5], [1.0, np.inf, np.nan])
    watch.note_values("actor parameters", [0, 3, 5], np.ones((3, 4)))
    with pytest.raises(Diverged) as err:
        watch.check(500)
    assert err.value.exit_code == 3
    assert "step 500" in str(err.value) and "loss_q (seeds 3, 5)" in str(err.value)
    assert "actor" not in str(err.value)
    keep_going = DivergenceWatch(tmp_path, "continue")
    for step in (500, 1000):
        keep_going.note("episode return", [1])
        keep_going.check(step)
    err_text = capsys.readouterr().err
    assert err_text.count("\n") == 1 and "episode return (seed 1)" in err_text


def test_divergence_is_noted_for_one_non_finite_value_among_finite_ones(tmp_path):
    watch = DivergenceWatch(tmp_path, "stop")
    values = np.ones((3, 5))
    values[1, 3] = np.nan  # seed 7: one value of five
    values[2, 0] = -np.inf  # seed 9: one value of five
    watch.note_values("critic parameters", [5, 7, 9], values)
    assert watch.found == {"critic parameters": [7, 9]}
    watch.note_values("loss_q", [5, 7, 9], [1.0, 2.0, 3.0])
    assert "loss_q" not in watch.found
    with pytest.raises(Diverged, match=r"critic parameters \(seeds 7, 9\)"):
        watch.check(100)


def test_network_bytes_are_counted_by_hand_and_match_the_initialised_state():
    import jax

    from adarl.algos import rnac, sac
    from adarl.algos.rnac_config import RNACConfig
    from adarl.algos.sac_config import SACConfig

    # obs 11, act 3, one hidden layer of 4. SAC actor: trunk 11·4+4 = 48, two heads 2·(4·3+3)
    # = 30; one critic: (14·4+4) + (4·1+1) = 65. Actor x 3 (Adam's two moments), two critics x 4
    # (target copies, two moments): 3·78 + 4·130 = 754 floats
    spec = sac.make_spec(SACConfig(algo="sac", hidden=(4,)), 11, 3, [-1.0] * 3, [1.0] * 3)
    assert sac.state_bytes(spec) == 4 * 754
    state = sac.init_state(spec, 0, with_buffer=False)
    keys = ("actor", "critic", "critic_target", "opt_actor", "opt_critic")
    leaves = [x for k in keys for x in jax.tree_util.tree_leaves(state[k]) if x.dtype == np.float32]
    assert sum(x.nbytes for x in leaves) == 4 * 754
    # RNAC actor: 48 + (4·3+3) + 3 log-stds = 66; critic 48 + 5 = 53; x 3 (two moments)
    config = RNACConfig(hidden=(4,))
    assert rnac.state_bytes(config, 11, 3) == 4 * 3 * 119
    trained, _ = rnac.init_states([0], config, 11, 3)
    leaves = [x for x in jax.tree_util.tree_leaves(trained) if x.dtype == np.float32]
    assert sum(x.nbytes for x in leaves) == 4 * 3 * 119


def test_the_memory_check_says_what_to_lower(monkeypatch):
    from adarl.errors import UsageError
    from adarl.train import guards

    monkeypatch.setattr(guards, "machine_memory", lambda: 2**30)
    guards.check_memory(2**30, "the thing", "lower --size")  # exactly the memory: fits
    with pytest.raises(UsageError) as err:
        guards.check_training_memory(3, 2**30, 2**29, "lower --size")
    assert str(err.value) == (  # and 3 environments of 2 MiB: 1.506 GiB
        "3 seeds (buffers 1.0 GiB, networks 0.5 GiB, environments 0.0 GiB) need 1.5 GiB "
        "but this machine has 1.0 GiB of memory; lower --size"
    )
    monkeypatch.setattr(guards, "machine_memory", lambda: None)  # not knowable: no guess
    guards.check_memory(10**30, "the thing", "lower --size")


def test_the_device_memory_check_counts_the_accelerator(monkeypatch):
    from adarl.errors import UsageError
    from adarl.train import guards

    assert guards.accelerator_memory() is None  # the tests run on a CPU
    guards.check_device_memory(3, 10**30, 0, "lower --size")  # a CPU: the machine's check
    monkeypatch.setattr(guards, "accelerator_memory", lambda: 2**30)
    guards.check_device_memory(3, 2**29, 2**29, "lower --size")  # exactly the memory: fits
    with pytest.raises(UsageError) as err:
        guards.check_device_memory(256, 2**30, 2**28, "lower --size")
    assert str(err.value) == (
        "256 seeds (buffers 1.0 GiB, networks 0.2 GiB) need 1.2 GiB but the accelerator has "
        "1.0 GiB of memory; lower --size"
    )


def _episodes(run, columns: dict[str, list[float]]):
    names = list(columns)
    rows = zip(*columns.values(), strict=True)
    text = "step,seed,episode,return,length," + ",".join(f"p_{n}" for n in names) + "\n"
    text += "".join(
        f"{100 * i},0,{i},1.0,10," + ",".join(map(str, r)) + "\n" for i, r in enumerate(rows)
    )
    (run / "episodes.csv").write_text(text)


def test_a_resume_whose_logged_physics_vary_what_its_spec_now_fixes_is_refused(tmp_path):
    # a run trained before issue 62: `uniform:body:pole.mass=4..6` on a Gymnasium task also drew
    # mass_scale each episode; this adarl reads the spec as varying the pole's mass alone
    from adarl.errors import UsageError
    from adarl.train.guards import check_logged_physics

    spec = "uniform:body:pole.mass=4..6"
    _episodes(tmp_path, {"mass_scale": [0.91, 1.13, 0.85], "body:pole.mass": [4.2, 5.5, 4.9]})
    with pytest.raises(UsageError, match="shows mass_scale varying over 3 values"):
        check_logged_physics(tmp_path, "InvertedPendulum-v5", spec)
    _episodes(tmp_path, {"mass_scale": [1.0, 1.0, 1.0], "body:pole.mass": [4.2, 5.5, 4.9]})
    check_logged_physics(tmp_path, "InvertedPendulum-v5", spec)  # what it trained: goes on
    _episodes(tmp_path, {"mass_scale": [0.91, 1.13, 0.85]})
    check_logged_physics(tmp_path, "InvertedPendulum-v5", "paper")  # the generic schedule varies it


def test_the_resume_checks_the_logged_physics_before_reading_a_checkpoint(tmp_path, monkeypatch):
    # the loop calls the check on every resume (planted: without the call, this resume goes on)
    import adarl.train.loop as loop

    calls = []
    monkeypatch.setattr(loop, "check_logged_physics", lambda *a: calls.append(a) or (_ for _ in ()).throw(SystemExit(7)))  # fmt: skip
    monkeypatch.setattr(loop.folder, "lock_to_resume", lambda run_dir, lock: True)

    class Config:
        task, dynamics = "InvertedPendulum-v5", "paper"

        def validate(self):
            pass

    class Stub:
        algo = "sac"

    monkeypatch.setattr(loop, "Loop", lambda learner, run_dir, progress: Stub())
    with pytest.raises(SystemExit):
        loop.train(lambda config: None, Config(), tmp_path, resume=True)
    assert calls == [(tmp_path, "InvertedPendulum-v5", "paper")]
