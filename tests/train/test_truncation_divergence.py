"""Issue 55: weights that went non-finite between two checks never reach the SVD of a
truncation (jaxlib's SVD of a matrix holding inf does not return): the run stops there with exit
3 (`Diverged`) before the cut; with `--on-divergence continue` the cut leaves the non-finite
layer as it was and training goes on to the end, and no pre-truncation checkpoint is written
after the divergence warning, whether the weights or only a metric went non-finite."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from adarl.algos import sac_config, schedule
from adarl.algos.sac_config import SAC_FAMILY
from adarl.errors import Diverged
from adarl.runs import layout
from adarl.runs.logs import read_csv
from adarl.train import sac_family, sac_learner, trainers


def adarl_config(**overrides):
    values = {**SAC_FAMILY["adarl"], **sac_config.PRESETS["smoke"], "algo": "adarl"}
    values.update(task="hopper", seeds=(1,), total_steps=200, start_steps=100)
    values.update(update_after=100, truncate_every=100, log_every=200, eval_every=200)
    values.update(checkpoint_every=200, checkpoint_before_truncation=False)
    values.update(eval_dynamics=("nominal",), compact_bottlenecks=False, **overrides)
    first = schedule.truncation_steps(sac_config.SACConfig(**values))[0]
    values.update(total_steps=first, log_every=first, eval_every=first, checkpoint_every=first)
    return sac_config.SACConfig(**values)  # one truncation, at the end


def poison_bottleneck_before(step, monkeypatch):
    """Set one entry of the (only) seed's first actor bottleneck's W1 to inf after the update of
    the chunk ending at `step` (after the last check, before the truncation there)."""
    original = sac_learner.SACLearner.advance

    def then_poison(self, t):
        advance = original(self, t)
        if advance.step == step:
            lane = self.lanes[0]
            trunk = list(lane.state["actor"]["trunk"])
            i = next(k for k, layer in enumerate(trunk) if "w1" in layer)
            trunk[i] = dict(trunk[i], w1=jnp.asarray(trunk[i]["w1"]).at[0, 0].set(jnp.inf))
            lane.state = dict(lane.state, actor=dict(lane.state["actor"], trunk=trunk))
        return advance

    monkeypatch.setattr(sac_learner.SACLearner, "advance", then_poison)


def test_weights_gone_inf_before_a_cut_stop_the_run_there_with_exit_3(tmp_path, monkeypatch):
    config = adarl_config()
    first, *_ = schedule.truncation_steps(config)
    assert first == config.total_steps  # then log, evaluation, checkpoint, at the same step
    poison_bottleneck_before(first, monkeypatch)
    run_dir = tmp_path / "run"
    with pytest.raises(Diverged) as err:
        trainers.train(config, run_dir, progress=False)
    assert Diverged.exit_code == 3
    message = str(err.value)
    assert f"diverged at step {first}: non-finite actor parameters (seed 1)" in message, message
    assert not (run_dir / "spectra").exists() or not list((run_dir / "spectra").iterdir())
    assert not read_csv(run_dir / "truncations.csv")  # the cut never ran
    assert not (run_dir / "DONE").exists()


def test_with_on_divergence_continue_the_cut_leaves_the_inf_layer_and_goes_on(
    tmp_path, monkeypatch, capsys
):
    config = adarl_config(on_divergence="continue", checkpoint_before_truncation=True)
    steps = schedule.truncation_steps(config)
    poison_bottleneck_before(steps[0], monkeypatch)
    run_dir = tmp_path / "run"
    trainers.train(config, run_dir, progress=False)  # returns: no hang at the cut
    assert (run_dir / "DONE").exists()
    pre = run_dir / layout.PRE_TRUNCATION_DIR
    assert not pre.exists() or not list(pre.iterdir())  # never a checkpoint of inf weights
    assert f"training diverged at step {steps[0]}" in capsys.readouterr().err
    rows = [r for r in read_csv(run_dir / "truncations.csv") if r["layer"].startswith("actor")]
    poisoned = [r for r in rows if r["seed"] == "1" and int(r["step"]) == steps[0]]
    assert poisoned and all(r["old_rank"] == r["new_rank"] for r in poisoned)
    spectra = np.load(run_dir / "spectra" / sorted((run_dir / "spectra").iterdir())[0].name)
    actor = next(k for k in spectra.files if k.startswith("actor"))
    assert np.isnan(spectra[actor][0]).all()
    critic = next(k for k in spectra.files if k.startswith("q1"))
    assert np.isfinite(spectra[critic][0]).all()  # the finite layers were cut as usual


def test_a_nan_metric_with_finite_weights_before_a_cut_writes_no_pre_truncation_checkpoint(
    tmp_path, monkeypatch, capsys
):
    """The other half of the rule: the weights stay finite, but a divergence is noted at the
    cut's check (a NaN loss): the warning is printed and no pre-truncation checkpoint follows."""
    config = adarl_config(on_divergence="continue", checkpoint_before_truncation=True)
    steps = schedule.truncation_steps(config)
    original = sac_learner.SACLearner.advance

    def then_nan_loss(self, t):
        advance = original(self, t)
        if advance.step == steps[0]:  # the latest train.csv metrics, as if loss_q went NaN
            means = {k: np.zeros(len(self.seeds)) for k in sac_family.WATCHED_METRICS}
            self.metric_means = dict(means, loss_q=np.full(len(self.seeds), np.nan))
        return advance

    monkeypatch.setattr(sac_learner.SACLearner, "advance", then_nan_loss)
    run_dir = tmp_path / "run"
    trainers.train(config, run_dir, progress=False)
    assert (run_dir / "DONE").exists()
    err = capsys.readouterr().err
    assert f"training diverged at step {steps[0]}: non-finite loss_q (seed 1)" in err, err
    pre = run_dir / layout.PRE_TRUNCATION_DIR
    assert not pre.exists() or not list(pre.iterdir())
