"""Forks (`adarl train --fork RUN_DIR --at STEP`) and AdaRL's schedule-matched control: a fork
with no change continues exactly as its parent; a fork with `--apply-cuts false` at the first
truncation equals the control trained from scratch and shares AdaRL's schedule; pre-truncation
checkpoints survive rotation; bad forks are one-line UsageErrors."""

import itertools

import numpy as np
import pytest
import yaml

from adarl.algos import sac, sac_config, schedule
from adarl.algos.sac_config import SAC_FAMILY
from adarl.errors import UsageError
from adarl.runs import checkpoints
from adarl.runs.layout import PRE_TRUNCATION, PRE_TRUNCATION_DIR
from adarl.runs.logs import read_csv
from adarl.train import fork, launch, sac_family, trainers

CSVS = ("episodes.csv", "train.csv", "eval.csv", "truncations.csv")


def tiny(algo="adarl", **overrides):
    """Two seeds, truncations at steps 550, 650 and 750 (d_t = 100 updates from step 500), a
    train.csv row every 100 steps (so the truncation at 550 falls between two rows), checkpoints
    every 200 steps of which one is kept."""
    values = {**SAC_FAMILY[algo], **sac_config.PRESETS["smoke"], "algo": algo, "task": "hopper"}
    values.update(
        seeds=(0, 1),
        total_steps=800,
        truncate_every=100,
        rank_rule="cumulative",
        log_every=100,
        eval_every=400,
        checkpoint_every=200,
        keep_checkpoints=1,
    )
    values.update(overrides)
    return sac_config.SACConfig(**values)


def rows(run_dir, name):
    found = read_csv(run_dir / name)
    for row in found:
        row.pop("steps_per_s", None)  # wall clock
    return found


def final_arrays(run_dir):
    arrays, _ = checkpoints.load_checkpoint(checkpoints.latest_checkpoint(run_dir))
    return arrays


def assert_same_arrays(a: dict, b: dict):
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


@pytest.fixture(scope="module")
def parent(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("fork") / "parent"
    trainers.train(tiny(), run_dir, progress=False)
    return run_dir


def test_truncation_steps_follow_the_loops_counters():
    """`schedule.truncation_steps` against a step-by-step count of the loop's rules (chunks of
    update_every steps, updates from the chunk that reaches update_after, a truncation once the
    updates since the last one reach d_t)."""
    for total, every, after, d_t in itertools.product(
        (1_000, 1_030), (1, 50), (0, 100, 130, 1_040, 2_000), (1, 90, 100, 450)
    ):  # update_after 1,040 with 1,030 steps: the last chunk ends before it and never updates
        config = tiny(
            total_steps=total,
            update_every=every,
            update_after=after,
            truncate_every=d_t,
            log_every=every,
            eval_every=every,
            checkpoint_every=every,
        )
        expected, step, updates, since = [], 0, 0, 0
        while step < total:
            step = min(step + every - step % every, total)
            if step >= after:
                updates += every
                since += every
            if since >= d_t:
                expected.append(step)
                since = 0
        assert schedule.truncation_steps(config) == expected, (total, every, after, d_t)
        assert schedule.total_updates(config) == updates, (total, every, after, d_t)
    assert schedule.truncation_steps(tiny(algo="sac")) == []


def test_adarl_keeps_a_checkpoint_before_every_truncation(parent):
    cuts = sorted({int(r["step"]) for r in read_csv(parent / "truncations.csv")})
    assert cuts == schedule.truncation_steps(tiny()) == [550, 650, 750]
    kept = [p.name for p in checkpoints.checkpoint_dirs(parent, PRE_TRUNCATION_DIR)]
    assert kept == [f"step_{s:012d}" for s in cuts]  # none rotated away (keep_checkpoints 1)
    assert [p.name for p in checkpoints.checkpoint_dirs(parent)] == ["step_000000000800"]
    arrays, meta = checkpoints.load_checkpoint(
        checkpoints.checkpoint_dirs(parent, PRE_TRUNCATION_DIR)[0]
    )
    assert meta["phase"] == PRE_TRUNCATION and meta["step"] == 550
    # the update metrics since the train.csv row at 500 travel with it (one chunk of 50)
    assert arrays["pending/0/loss_q"].shape == (1, 1)
    # the state before the cut: every bottleneck still at full rank
    for mask in (arrays["state['masks']['actor'][1]"], arrays["state['masks']['critic'][1]"]):
        assert mask.sum(axis=-1).min() == 64


def test_a_fork_without_changes_continues_exactly_as_its_parent(parent, tmp_path):
    child = tmp_path / "child"
    planned = fork.prepare(parent, 550, {})
    assert planned.record["changed"] == {} and planned.record["checkpoint"] == "pre_truncation"
    fork.write(planned, child, "adarl train --fork …")
    # before training, the child holds the parent's rows up to the fork point: those of the
    # steps up to 550, but not the truncation made after the checkpoint at 550
    for name in CSVS:
        last = 549 if name == "truncations.csv" else 550
        prefix = [r for r in rows(parent, name) if int(r["step"]) <= last]
        assert rows(child, name) == prefix, name
    assert {r["step"] for r in rows(child, "eval.csv")} == {"400"}
    trainers.train(planned.config, child, resume=True, progress=False)
    for name in CSVS:
        assert rows(child, name) == rows(parent, name), name
    assert_same_arrays(final_arrays(child), final_arrays(parent))
    spectra = sorted(p.name for p in (child / "spectra").iterdir())
    assert spectra == sorted(p.name for p in (parent / "spectra").iterdir())
    for name in spectra:
        with np.load(child / "spectra" / name) as a, np.load(parent / "spectra" / name) as b:
            assert_same_arrays(dict(a), dict(b))
    record = yaml.safe_load((child / "config.yaml").read_text())["fork"]
    assert record == {
        "from": str(parent.resolve()),
        "step": 550,
        "checkpoint": "pre_truncation",
        "changed": {},
    }


def test_the_forked_control_is_the_control_trained_from_scratch(parent, tmp_path):
    """`--apply-cuts false` at the first truncation: the control (algo adarl-control) shares
    AdaRL's prefix bit for bit, so it equals the control trained from step 0; its truncations
    log the rule's proposals (AdaRL's own at the fork step) and keep the old rank; its
    learning rate follows AdaRL's at every logged step."""
    forked = tmp_path / "forked"
    planned = fork.prepare(parent, fork.FIRST_TRUNCATION, {"apply_cuts": "false"})
    assert planned.step == 550 and planned.algo == "adarl-control"
    assert planned.record["changed"] == {
        "algo": {"from": "adarl", "to": "adarl-control"},
        "apply_cuts": {"from": True, "to": False},
    }
    fork.write(planned, forked, "")
    trainers.train(planned.config, forked, resume=True, progress=False)
    scratch = tmp_path / "scratch"
    trainers.train(tiny("adarl-control"), scratch, progress=False)
    for name in CSVS:
        assert rows(forked, name) == rows(scratch, name), name
    assert_same_arrays(final_arrays(forked), final_arrays(scratch))

    control = rows(forked, "truncations.csv")
    assert {r["old_rank"] for r in control} == {"64"}
    assert all(r["new_rank"] == r["old_rank"] for r in control)
    assert {r["decision"] for r in control} == {"control"}  # Eq. 5 proposes a cut every time
    at_fork = [{k: r[k] for k in ("seed", "layer", "proposed_rank", "candidate_rank", "error")}
               for r in control if r["step"] == "550"]  # fmt: skip
    adarl = [{k: r[k] for k in ("seed", "layer", "proposed_rank", "candidate_rank", "error")}
             for r in rows(parent, "truncations.csv") if r["step"] == "550"]  # fmt: skip
    assert at_fork == adarl
    lr = [(r["step"], r["seed"], r["lr"]) for r in rows(forked, "train.csv")]
    assert lr == [(r["step"], r["seed"], r["lr"]) for r in rows(parent, "train.csv")]
    assert {r["rank_actor_1"] for r in rows(forked, "train.csv")} == {"64"}
    # issue 38: the control from scratch keeps AdaRL's pre-truncation fork points (550, 650, 750)
    pre = [p.name for p in checkpoints.checkpoint_dirs(scratch, PRE_TRUNCATION_DIR)]
    assert pre == [f"step_{s:012d}" for s in (550, 650, 750)]
    assert pre == [p.name for p in checkpoints.checkpoint_dirs(parent, PRE_TRUNCATION_DIR)]


def test_a_fork_ending_at_its_pre_truncation_step_makes_that_one_truncation(parent, tmp_path):
    """`--at 650 --total-steps 650` from the checkpoint kept before the truncation at 650: the
    child makes that truncation (as its parent did, from the same state) and ends at 650."""
    child = tmp_path / "child"
    planned = fork.prepare(parent, 650, {"total_steps": "650"})
    assert planned.record["checkpoint"] == "pre_truncation" and planned.config.total_steps == 650
    fork.write(planned, child, "")
    trainers.train(planned.config, child, resume=True, progress=False)
    cuts = rows(child, "truncations.csv")
    assert sorted({int(r["step"]) for r in cuts}) == [550, 650]  # 550 inherited, 650 made
    made = [r for r in cuts if r["step"] == "650"]
    assert made == [r for r in rows(parent, "truncations.csv") if r["step"] == "650"]
    assert len(made) == 2 * 3  # one per seed and bottleneck (actor, two critics)
    assert (child / "DONE").read_text().split()[0] == "650"
    assert [p.name for p in checkpoints.checkpoint_dirs(child)][-1] == "step_000000000650"
    assert max(int(r["step"]) for r in rows(child, "train.csv")) <= 650


def test_the_control_reparameterises_at_the_old_rank():
    """One truncation of the control: the product W1·W2 is kept (to float rounding) in the SVD
    basis, Adam and the targets are reset and the schedule restarts, as AdaRL's truncation does."""
    config = tiny("adarl-control")
    spec = sac.make_spec(config, 11, 3, -np.ones(3), np.ones(3))
    state = sac.init_state(spec, 0)
    buffer = state["buffer"]  # rows to measure the cut's error on
    buffer["obs"][:] = np.random.default_rng(0).normal(size=buffer["obs"].shape)
    buffer["valid"][:], buffer["size"] = 1, np.int32(len(buffer["valid"]))
    state["opt_actor"] = state["opt_actor"]._replace(count=np.int32(7))
    state["n_updates"] = np.int32(300)
    new, report = sac.truncate(spec, state)
    for key in ("actor_1", "q1_1", "q2_1"):
        spectrum, proposed, rank, candidate, error = report[key]
        assert int(rank) == 64 and int(candidate) < 64 and float(error) > 0
    before = state["actor"]["trunk"][1]
    after = new["actor"]["trunk"][1]
    np.testing.assert_allclose(
        np.asarray(after["w1"]) @ np.asarray(after["w2"]),
        before["w1"] @ before["w2"],
        atol=1e-5,
    )
    assert not np.allclose(np.asarray(after["w1"]), before["w1"])  # a new basis
    assert int(new["opt_actor"].count) == 0 and int(new["iteration_start"]) == 300
    assert int(new["n_truncations"]) == 1
    for t, c in zip(np.asarray(new["critic_target"][1]["w1"]), np.asarray(new["critic"][1]["w1"])):
        np.testing.assert_array_equal(t, c)


@pytest.mark.parametrize(
    "at, changes, message",
    [
        (551, {}, r"has no checkpoint at step 551; fork points: 550 \(pre-truncation\), 650 "),
        ("soon", {}, "--at expects a step or first-truncation, got 'soon'"),
        (550, {"hidden": "32,32"}, "--hidden cannot change at a fork"),
        (550, {"buffer_size": "100"}, "--buffer-size cannot change at a fork"),
        (550, {"seeds": "0"}, "--seeds cannot change at a fork"),
        (550, {"task": "walker2d"}, "--task cannot change at a fork"),
        (550, {"total_steps": "500"}, "total-steps 500 leaves nothing to train"),
        (800, {}, "total-steps 800 leaves nothing to train after the fork at step 800"),
        (550, {"beta": "2"}, "beta must be in"),
        (550, {"parseval_kind": "x"}, "--parseval-kind does not apply to --algo adarl"),
    ],
)
def test_bad_forks_name_the_value_and_what_is_allowed(parent, at, changes, message):
    with pytest.raises(UsageError, match=message):
        fork.prepare(parent, at, changes)


def test_a_fork_refuses_a_folder_in_use(parent, tmp_path):
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "x").write_text("x")
    with pytest.raises(UsageError, match="already exists and is not empty"):
        fork.write(fork.prepare(parent, 550, {}), tmp_path / "taken", "")


def test_a_fork_with_a_bad_tracking_flag_writes_nothing(parent, tmp_path):
    """`launch.train` checks everything before it writes the fork's folder."""
    start = launch.ForkOf(str(parent), 550, {"apply_cuts": "false"})
    with pytest.raises(UsageError, match="--wandb-project is for --track"):
        launch.train(start, tmp_path / "child", "", False, launch.Tracking(project="p"))
    assert not (tmp_path / "child").exists()


def test_a_fork_interrupted_while_being_made_is_refused(parent, tmp_path, monkeypatch):
    """The fork's first checkpoint is written last: without it the folder is no fork to
    resume (the sweeps' worker, which sees no checkpoint, makes it again from scratch)."""
    planned = fork.prepare(parent, 550, {})

    def killed(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(checkpoints, "save_checkpoint", killed)
    with pytest.raises(KeyboardInterrupt):
        fork.write(planned, tmp_path / "child", "")
    monkeypatch.undo()
    assert (tmp_path / "child" / "config.yaml").exists() and not checkpoints.checkpoint_dirs(
        tmp_path / "child"
    )
    with pytest.raises(UsageError, match="was interrupted while being made .*: remove it and fork"):
        trainers.train(planned.config, tmp_path / "child", resume=True, progress=False)


def test_forkable_fields_are_config_fields_and_the_sweeps_check_agrees():
    names = {f.name for f in sac_config.SACConfig.__dataclass_fields__.values()}
    assert set(fork.FORKABLE) <= names
    base = tiny()
    changed = fork.check_forkable(base, tiny("adarl-control", apply_cuts=False, eval_every=200))
    assert set(changed) == {"algo", "apply_cuts", "eval_every"}
    with pytest.raises(UsageError, match="hidden differs"):
        fork.check_forkable(base, tiny(hidden=(32, 32)))
    with pytest.raises(UsageError, match="a fork keeps its parent's algorithm"):
        fork.check_forkable(tiny("sac"), tiny("sac-parseval", parseval_coef=1e-4))


def test_apply_cuts_false_is_only_the_control():
    with pytest.raises(UsageError, match="train it as --algo adarl-control, not adarl"):
        tiny(apply_cuts=False).validate()
    with pytest.raises(UsageError, match="apply-cuts must be false"):
        tiny("adarl-control", apply_cuts=True).validate()
    assert sac_family.truncation_decision(64, 40, 64, apply_cuts=False) == "control"
    assert sac_family.truncation_decision(64, 64, 64, apply_cuts=False) == "unchanged"
    assert sac_family.truncation_decision(64, 40, 40) == "accepted"
