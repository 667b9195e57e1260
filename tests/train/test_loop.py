"""The one training loop (adarl/train/loop.py): what it does alike for every learner — when it
logs, evaluates and checkpoints, each seed's best policy, and what a stop signal does (a stopped
run's checkpoint and exact resume: tests/train/test_resume_every_algorithm.py)."""

import json
import os
import signal
import threading

import numpy as np
import pytest

from adarl.algos import rnac_config, sac, sac_config
from adarl.algos.sac_config import SAC_FAMILY
from adarl.policy import to_bytes
from adarl.runs import checkpoints
from adarl.runs.logs import read_csv
from adarl.train import loop, trainers


def smoke_sac(**overrides):
    values = {**SAC_FAMILY["sac"], **sac_config.PRESETS["smoke"], "algo": "sac", "task": "hopper"}
    return sac_config.SACConfig(**{**values, **overrides})


# (trainer, config, the steps of train.csv rows, of evaluations): the multiples of log_every
# and eval_every, and the last step, which is neither
CASES = {
    "sac": (
        trainers.train,
        smoke_sac(seeds=(0, 1), total_steps=1_050, log_every=500, eval_every=500),
        [500, 1_000, 1_050],
        [500, 1_000, 1_050],
    ),
    "rnac": (
        trainers.train,
        rnac_config.RNACConfig(
            **rnac_config.PRESETS["smoke"]
            | {"seeds": (0, 1), "total_steps": 1_280, "log_every": 512, "eval_every": 1_024}
        ),
        [512, 1_024, 1_280],
        [1_024, 1_280],
    ),
}


@pytest.mark.parametrize("name", CASES)
def test_logs_evaluations_and_best_policies_alike_for_every_learner(name, tmp_path):
    train, config, train_steps, eval_steps = CASES[name]
    run_dir = train(config, tmp_path / "run", progress=False)
    rows = read_csv(run_dir / "train.csv")
    assert sorted({int(r["step"]) for r in rows}) == train_steps
    evals = read_csv(run_dir / "eval.csv")
    assert sorted({int(r["step"]) for r in evals}) == eval_steps
    assert (run_dir / "DONE").read_text().strip() == str(config.total_steps)

    last = checkpoints.latest_checkpoint(run_dir)
    best = json.loads((last / "meta.json").read_text())["best"]
    assert best["metric"] == "mean nominal evaluation return" and "from_step" not in best
    for seed in config.seeds:
        mine = [r for r in evals if r["seed"] == str(seed) and r["dynamics"] == "nominal"]
        by_step = {}
        for r in mine:
            by_step.setdefault(int(r["step"]), []).append(float(r["return"]))
        means = {step: np.mean(v) for step, v in by_step.items()}
        top = max(means, key=lambda s: (means[s], -s))  # the first of equal maxima
        assert best["seeds"][str(seed)]["step"] == top
        assert best["seeds"][str(seed)]["return"] == pytest.approx(means[top], rel=1e-5)
        assert (last / f"best_policy_seed_{seed}.npz").is_file()


def test_a_checkpoint_from_before_best_policies_records_where_they_begin(tmp_path):
    spec = sac.make_spec(smoke_sac(), 11, 3, -np.ones(3), np.ones(3))
    policies = []
    for seed in (0, 1):
        state = sac.init_state(spec, seed, with_buffer=False)
        policies.append(sac.export_policy(spec, state["actor"], state["masks"]["actor"]))
    best = loop.BestPolicies([0, 1])
    best.restore({"step": 600_000}, tmp_path)  # a meta.json written before the loop kept them
    assert best.meta()["from_step"] == 600_000 and best.meta()["seeds"] == {}
    best.offer(0, 650_000, 12.5, policies[0])
    best.offer(0, 700_000, float("nan"), policies[1])  # never a non-finite return
    best.offer(0, 750_000, 12.5, policies[1])  # a tie keeps the earlier
    assert best.meta()["seeds"] == {"0": {"step": 650_000, "return": 12.5}}
    assert best.checkpoint_files() == {"best_policy_seed_0.npz": to_bytes(policies[0])}


def test_a_signal_asks_for_a_stop_and_a_second_one_stops_at_once():
    before = {s: signal.getsignal(s) for s in loop.StopSignals.SIGNALS}
    with loop.StopSignals() as stop:
        os.kill(os.getpid(), signal.SIGTERM)
        assert stop.received == signal.SIGTERM  # noted, the process goes on
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
    assert {s: signal.getsignal(s) for s in loop.StopSignals.SIGNALS} == before


def test_stop_signals_installs_nothing_outside_the_main_thread():
    seen = []

    def in_thread():
        with loop.StopSignals():
            seen.append(signal.getsignal(signal.SIGTERM))

    before = signal.getsignal(signal.SIGTERM)
    thread = threading.Thread(target=in_thread)
    thread.start()
    thread.join()
    assert seen == [before]


def test_the_progress_bar_names_its_return(tmp_path, capsys):
    """Issue 62: the bar's figure is the mean return of the last training episodes (exploring,
    under the training dynamics), said as such; it read `return 1098` beside a summary of 521.3
    nominal and nothing said what it was."""
    assert loop.progress_text([]) == "train return -"
    assert loop.progress_text([10.0, 20.0, 1_200.0]) == "train return 410 (mean of last 3 episodes)"
    assert loop.progress_text([1_098.4]) == "train return 1,098 (last episode)"
    config = smoke_sac(total_steps=600, start_steps=100, update_after=100, eval_every=500)
    trainers.train(config, tmp_path / "run", progress=True)
    bar = capsys.readouterr().err.replace("\r", "\n").splitlines()
    last = [line for line in bar if "600/600" in line][-1]
    episodes = [float(r["return"]) for r in read_csv(tmp_path / "run" / "episodes.csv")][-10:]
    assert f"train return {np.mean(episodes):,.0f} (mean of last {len(episodes)} episodes)" in last
