"""Sweep files: expansion into units, precedence of overrides, the shipped presets."""

import pytest

from adarl.errors import UsageError
from adarl.sweeps import spec


def _parse(**doc):
    base = {"tasks": ["hopper"], "algos": ["sac"], "seeds": "0-1", "budget": 1000}
    return spec.parse({**base, **doc}, source="t.yaml")


def _flags(unit) -> dict:
    args = list(unit.train_args)
    return dict(zip(args[::2], args[1::2]))


def test_units_are_task_x_entry_x_seed_group():
    sweep = _parse(
        tasks=["hopper", "walker2d"], algos=["adarl", "rnac"], seeds="0-4", seeds_per_unit=2
    )
    assert len(sweep.units) == 2 * 2 * 3
    assert [u.id for u in sweep.units[:3]] == [
        "hopper/adarl/seeds-0-1",
        "hopper/adarl/seeds-2-3",
        "hopper/adarl/seeds-4",
    ]
    assert _flags(sweep.units[0])["--seeds"] == "0,1"
    assert len({u.id for u in sweep.units}) == len(sweep.units)


def test_an_entry_can_run_its_own_seeds_grouped_as_the_file_says():
    sweep = _parse(algos=["sac", {"algo": "rnac", "seeds": "0-2"}], seeds="0-4", seeds_per_unit=2)
    assert [u.id for u in sweep.units] == [
        "hopper/sac/seeds-0-1",
        "hopper/sac/seeds-2-3",
        "hopper/sac/seeds-4",
        "hopper/rnac/seeds-0-1",
        "hopper/rnac/seeds-2",
    ]
    with pytest.raises(UsageError, match=r"algos entry 'rnac': seeds: seeds contain duplicates"):
        _parse(algos=[{"algo": "rnac", "seeds": [1, 1]}])


def test_overrides_apply_where_the_field_exists_most_specific_last():
    sweep = _parse(
        tasks={"hopper": None, "walker2d": {"truncate_every": 700_000}},
        algos=["sac", {"algo": "adarl", "truncate_every": 5000}, "rnac"],
        budget={"hopper": "3e6", "walker2d": 2_000_000},
        overrides={"truncate_every": 1_000_000, "eval_every": 20_000},
    )
    flags = {u.id: _flags(u) for u in sweep.units}
    assert flags["hopper/sac/seeds-0-1"]["--truncate-every"] == "1000000"
    assert flags["walker2d/sac/seeds-0-1"]["--truncate-every"] == "700000"
    assert flags["walker2d/adarl_truncate_every-5000/seeds-0-1"]["--truncate-every"] == "5000"
    assert "--truncate-every" not in flags["hopper/rnac/seeds-0-1"]  # not an RNAC field
    assert flags["hopper/rnac/seeds-0-1"]["--eval-every"] == "20000"
    assert flags["hopper/sac/seeds-0-1"]["--total-steps"] == "3000000"
    assert flags["walker2d/rnac/seeds-0-1"]["--total-steps"] == "2000000"


def test_grid_expands_into_labelled_entries():
    sweep = _parse(algos=[{"algo": "sac-fixed-rank", "grid": {"rank": [1, 7]}}])
    assert [u.label for u in sweep.units] == ["sac-fixed-rank_rank-1", "sac-fixed-rank_rank-7"]
    assert sweep.units[1].config.rank == 7


@pytest.mark.parametrize("doc, message", [
    ({"algos": ["sac", "sac"]}, "both named 'sac'"),
    ({"algos": [{"algo": "rnac", "rank": 3}]}, "not a config field of rnac"),
    ({"overrides": {"seeds": [1]}}, "set by the spec's 'seeds' key"),
    ({"seeds": "0-1,1"}, "duplicates"),
    ({"budget": {"hopper": 10, "ant": 10}}, "not in tasks"),
    ({"evaluation": {"eval_every": "often"}}, "--eval-every expects int"),
    ({"dynamics": "stormy"}, "unknown dynamics"),
])  # fmt: skip
def test_bad_specs_name_the_problem(doc, message):
    with pytest.raises(UsageError, match=message):
        _parse(**doc)


def test_presets_expand_to_the_documented_protocols():
    units = {name: spec.load(name).units for name in spec.list_presets()}
    assert set(units) == {
        "smoke",
        "paper-hopper-small",
        "paper-table1",
        "fixed-rank-sweep",
        "fixed-rank-u",
        "rank-rule-ablation",
        "rank-rules",
        "physics",
        "repro-hopper",
        "repro-walker2d",
        "ratio-rule-hopper",
        "ratio-rule-walker2d",
        "mechanism-hopper",
        "mechanism-walker2d",
        "paper-schedule-hopper",
        "paper-schedule-walker2d",
        "physics-power",
        "fixed-rank-power",
        "claim2-first-look",
        "table1-ant-humanoid",
    }
    assert len(units["physics"]) == 8  # 2 tasks x physics consistent/ompo x models v5/v4
    # issue 34's pre-registered Table 1 on Ant and Humanoid: every method of the Hopper table,
    # 5 seeds, 300k steps, d_t = 60k (the paper's budget/d_t ratio), no pre-truncation copies
    ant_humanoid = units["table1-ant-humanoid"]
    assert len(ant_humanoid) == 14
    assert {u.task for u in ant_humanoid} == {"ant", "humanoid"}
    assert all(u.seeds == (0, 1, 2, 3, 4) for u in ant_humanoid)
    for u in ant_humanoid:
        flags = _flags(u)
        assert flags["--total-steps"] == "300000" and flags["--dynamics"] == "paper"
        if u.algo != "rnac":
            assert flags["--truncate-every"] == "60000"
            assert flags["--checkpoint-before-truncation"] == "false"
    table1 = units["paper-table1"]
    assert len(table1) == 28  # Parseval at each of the paper's three coefficients
    assert {(u.task, u.algo) for u in table1} == {
        (t, a)
        for t in ("hopper", "walker2d", "ant", "humanoid")
        for a in ("adarl", "sac", "sac-parseval", "sac-sparse", "rnac")
    }
    for name in ("paper-table1", "paper-hopper-small"):
        coefs = {
            (u.task, float(_flags(u)["--parseval-coef"]))
            for u in units[name]
            if u.algo == "sac-parseval"
        }
        tasks = {u.task for u in units[name]}
        assert coefs == {(t, c) for t in tasks for c in (1e-3, 1e-4, 1e-5)}, name
    assert all(u.seeds == (0, 1, 2, 3, 4) for u in table1)
    walker = next(u for u in table1 if u.id == "walker2d/adarl/seeds-0-4")
    assert _flags(walker)["--truncate-every"] == "700000"
    ranks = sorted(
        int(_flags(u)["--rank"]) for u in units["fixed-rank-sweep"] if u.task == "hopper"
    )
    assert ranks == [1, 2, 4, 7, 16, 32, 64]
    assert {_flags(u)["--rank-rule"] for u in units["rank-rule-ablation"]} == {
        "cumulative",
        "ratio",
    }
    small = units["paper-hopper-small"]
    assert len(small) == 7 and all(u.total_steps <= 200_000 for u in small)
    u_shape = units["fixed-rank-u"]
    assert len(u_shape) == 7
    assert {(u.task, u.algo, u.seeds, u.total_steps) for u in u_shape} == {
        ("hopper", "sac-fixed-rank", (0, 1, 2), 150_000)
    }
    assert sorted(int(_flags(u)["--rank"]) for u in u_shape) == [1, 2, 4, 7, 13, 32, 64]
    rules = units["rank-rules"]
    assert {u.task for u in rules} == {"hopper", "walker2d"} and len(rules) == 8
    assert {(_flags(u)["--rank-rule"], _flags(u)["--retain-tolerance"]) for u in rules} == {
        (rule, tol) for rule in ("cumulative", "energy") for tol in ("none", "0.01")
    }
    assert all(_flags(u)["--truncate-every"] == "10000" for u in rules)
    assert [u.algo for u in units["smoke"]] == ["adarl", "sac"]
    physics = units["physics"]
    assert {(u.task, _flags(u)["--physics"], _flags(u)["--model-version"]) for u in physics} == {
        (t, p, v)
        for t in ("hopper", "walker2d")
        for p in ("consistent", "ompo")
        for v in ("v5", "v4")
    }
    assert all(u.algo == "sac" and u.seeds == (0, 1, 2) for u in physics)
    for task in ("hopper", "walker2d"):
        repro = units[f"repro-{task}"]
        assert len(repro) == 7 and {u.task for u in repro} == {task}
        assert {u.algo for u in repro} == {"adarl", "sac", "sac-parseval", "sac-sparse", "rnac"}
        dense = [u for u in repro if u.algo != "sac-sparse"]
        assert {(u.seeds, u.total_steps) for u in dense} == {((0, 1, 2, 3, 4), 100_000)}
        (sparse,) = [u for u in repro if u.algo == "sac-sparse"]
        assert (sparse.seeds, sparse.total_steps) == ((0, 1, 2), 100_000)
        assert _flags(sparse)["--sparse-width"] == "256"
    for task in ("hopper", "walker2d"):
        adarl = next(u for u in units[f"repro-{task}"] if u.algo == "adarl")
        ratio = units[f"ratio-rule-{task}"]
        for unit in ratio:  # comparable with repro-<task>'s adarl
            assert set(unit.seeds) < set(adarl.seeds)
            assert _flags(unit)["--rank-rule"] == "ratio"
            assert {
                k: v
                for k, v in _flags(unit).items()
                if k not in ("--seeds", "--rank-rule", "--beta")
            } == {k: v for k, v in _flags(adarl).items() if k != "--seeds"}
        assert sorted(_flags(u)["--beta"] for u in ratio) == ["0.1", "0.98"]


def test_the_files_preset_reaches_the_algorithms_that_have_it():
    sweep = _parse(algos=["sac", "rnac", {"algo": "rnac", "preset": "ipm"}], preset="quickstart")
    presets = [_flags(u).get("--preset") for u in sweep.units]
    assert presets == ["quickstart", None, "ipm"]
    with pytest.raises(UsageError, match="unknown preset 'quikstart'"):
        _parse(preset="quikstart")


ARMS = [
    {"algo": "adarl", "name": "a", "rank_rule": "cumulative"},
    {"algo": "adarl-control", "name": "c", "rank_rule": "cumulative",
     "fork": {"from": "a", "at": "first-truncation"}},
]  # fmt: skip
FORKED = {"preset": "smoke", "seeds": "0-3", "seeds_per_unit": 2, "budget": 2000}


def test_a_fork_entry_forks_each_unit_of_its_parent_at_its_truncation():
    sweep = _parse(algos=ARMS, **FORKED)
    parents, forks = sweep.units[:2], sweep.units[2:]
    assert [u.fork_of for u in forks] == [u.id for u in parents]
    # smoke: updates from step 500, d_t = 500 updates: the first truncation after step 950
    assert [u.fork_step for u in forks] == [950, 950]
    assert forks[0].train_args == (
        "--fork", "hopper/a/seeds-0-1", "--at", "950", "--apply-cuts", "false"
    )  # fmt: skip
    assert forks[0].config.algo == "adarl-control" and not forks[0].config.apply_cuts
    assert forks[1].config.seeds == (2, 3) and forks[1].total_steps == 2000
    later = dict(ARMS[1], fork={"from": "a", "at": 1450}, eval_every=500)
    fork = _parse(algos=[ARMS[0], later], **FORKED).units[-1]
    assert fork.train_args == ("--fork", "hopper/a/seeds-2-3", "--at", "1450",
                               "--apply-cuts", "false", "--eval-every", "500")  # fmt: skip


@pytest.mark.parametrize("entry, message", [
    ({"fork": {"from": "b", "at": "first-truncation"}}, r"fork from 'b': no such entry .*; entries: a"),
    ({"fork": {"from": "a"}}, "fork must be a mapping {from: <entry label>, at: first-truncation"),
    ({"fork": {"from": "a", "at": 1000}}, r"fork at step 1000: hopper/a/seeds-0-1 truncates at 950, 1450"),
    ({"fork": {"from": "a", "at": "later"}}, "--at expects a step or first-truncation, got 'later'"),
    ({"hidden": [32, 32]}, "hidden differs .* but cannot change at a fork"),
    ({"seeds": "1-2"}, r"its parent hopper/a/seeds-1-2 is not in the sweep"),
    ({"grid": {"beta": [0.9, 0.95]}, "name": None}, "on an entry without a grid"),
])  # fmt: skip
def test_bad_fork_entries_name_the_problem(entry, message):
    child = {k: v for k, v in {**ARMS[1], **entry}.items() if v is not None}
    with pytest.raises(UsageError, match=message):
        _parse(algos=[ARMS[0], child], **{**FORKED, "seeds_per_unit": 2, "seeds": "0-3"})


def test_the_campaign_presets():
    for task in ("hopper", "walker2d"):
        units = spec.load(f"mechanism-{task}").units
        assert [(u.algo, u.seeds) for u in units] == [
            (algo, seeds) for algo in ("adarl", "adarl-control")
            for seeds in ((0, 1, 2, 3, 4), (5, 6, 7, 8, 9))
        ]  # fmt: skip
        adarl, control = units[0].config, units[2].config
        assert (adarl.rank_rule, adarl.truncate_every, adarl.total_steps) == (
            "cumulative", 300_000, 450_000)  # fmt: skip
        assert (adarl.start_steps, adarl.buffer_size) == (10_000, 1_000_000)
        assert [u.fork_step for u in units[2:]] == [300_950, 300_950]
        assert units[2].fork_of == units[0].id and control.rank_rule == "cumulative"
    for task, d_t in (("hopper", 1_000_000), ("walker2d", 700_000)):  # the paper's d_t
        paper = spec.load(f"paper-schedule-{task}").units
        assert [(u.task, u.algo) for u in paper] == [
            (task, "adarl"), (task, "adarl-control"), (task, "sac")
        ]  # fmt: skip
        assert all(u.seeds == (0, 1, 2, 3, 4) and u.total_steps == 3_000_000 for u in paper)
        # the first cut: d_t updates from step 1,000 (update_after), 50 every 50 steps
        assert paper[1].fork_step == d_t + 950 and paper[0].config.truncate_every == d_t
        assert paper[1].fork_of == paper[0].id and paper[0].config.rank_rule == "cumulative"
        assert {
            (u.config.eval_every, u.config.start_steps, u.config.buffer_size, u.config.dynamics)
            for u in paper
        } == {(50_000, 10_000, 1_000_000, "paper")}
    physics = spec.load("physics-power").units
    assert sorted({(u.config.dynamics, u.config.physics, u.config.model_version) for u in physics}) == [
        ("ompo", "ompo", "v4"), ("paper", "consistent", "v5"), ("paper", "ompo", "v5")
    ]  # fmt: skip
    assert all(u.algo == "sac" and u.total_steps == 150_000 for u in physics)
    assert sorted(s for u in physics for s in u.seeds) == sorted(list(range(10)) * 3)
    fixed = spec.load("fixed-rank-power").units
    assert sorted((u.config.rank, u.seeds) for u in fixed) == [
        (r, s) for r in (7, 13, 64) for s in ((0, 1, 2, 3, 4), (5, 6, 7, 8, 9))
    ]
    assert {u.total_steps for u in fixed} == {300_000}
    for name in (
        "mechanism-hopper",
        "paper-schedule-hopper",
        "paper-schedule-walker2d",
        "physics-power",
        "fixed-rank-power",
    ):
        header = spec.resolve(name).read_text().split("\nname:")[0]
        assert "seed-steps" in header and "Estimated ~" in header, name


# ----------------------------------------------------------------------------- any task
def test_a_gymnasium_id_is_a_task_of_a_sweep():
    pytest.importorskip("mujoco")
    sweep = _parse(tasks=["HalfCheetah-v5", "hopper"], dynamics="uniform:body:torso.mass=4..9")
    assert [u.id for u in sweep.units] == ["HalfCheetah-v5/sac/seeds-0-1", "hopper/sac/seeds-0-1"]
    flags = _flags(sweep.units[0])
    assert flags["--task"] == "HalfCheetah-v5" and flags["--dynamics"].endswith("torso.mass=4..9")
    assert sweep.units[0].config.max_episode_steps == 1000  # Gymnasium's registered limit
    # every unit's schedule is checked on its own model: hopper has no bthigh
    with pytest.raises(UsageError) as err:
        _parse(tasks=["HalfCheetah-v5", "hopper"], dynamics="uniform:body:bthigh.mass=1..2")
    message = str(err.value)
    assert message.startswith("t.yaml: hopper/sac/seeds-0-1: unknown body 'bthigh'")
    assert "\n" not in message
    with pytest.raises(UsageError, match="t.yaml: unknown task 'Cheetah-v9'"):
        _parse(tasks=["Cheetah-v9"])


def test_a_users_id_and_xml_in_a_sweep(tmp_path):
    """A user's registered id, made with the env-module and env-kwargs its task overrides give;
    each unit's schedule is checked on its own XML (an entry may name another one)."""
    pytest.importorskip("mujoco")
    import user_env

    puck, ball = tmp_path / "puck.xml", tmp_path / "ball.xml"
    puck.write_text(user_env.XML.replace('name="ball"', 'name="puck"'))
    ball.write_text(user_env.XML)
    own = {"env_module": "user_env", "env_kwargs": f"xml_file={puck}"}
    tasks = {user_env.ENV_ID: own}
    # smoke sets max_episode_steps: without it the registry reads the registered time limit
    # with the env-module but not the env-kwargs, which this env needs (adarl/algos/registry.py)
    smoke = {"preset": "smoke"}
    sweep = _parse(tasks=tasks, dynamics="uniform:body:puck.mass=0.5..2", **smoke)
    (unit,) = sweep.units
    assert unit.id == "adarltest__PointBot-v0/sac/seeds-0-1"  # the id's "/" is no folder level
    flags = _flags(unit)
    assert (flags["--task"], flags["--env-module"]) == (user_env.ENV_ID, "user_env")
    assert flags["--env-kwargs"] == f"xml_file={puck}"
    entries = ["sac", {"algo": "sac", "name": "ball", "env_kwargs": f"xml_file={ball}"}]
    with pytest.raises(UsageError, match="ball/seeds-0-1: unknown body 'puck'"):
        _parse(tasks=tasks, algos=entries, dynamics="uniform:body:puck.mass=0.5..2", **smoke)
    forked = _parse(tasks=tasks, algos=ARMS, **{**FORKED, "seeds": "0-1"})
    assert forked.units[1].fork_of == forked.units[0].id == "adarltest__PointBot-v0/a/seeds-0-1"
    with pytest.raises(UsageError, match="t.yaml: unknown task 'adarltest/Nothing-v0'"):
        _parse(tasks=[user_env.ENV_ID.replace("PointBot", "Nothing")], overrides=own)


def test_the_device_backend_refuses_a_gymnasium_id_in_one_line():
    pytest.importorskip("mujoco")
    with pytest.raises(UsageError) as err:
        _parse(tasks=["HalfCheetah-v5"], overrides={"backend": "device"})
    assert str(err.value) == (
        "t.yaml: HalfCheetah-v5/sac/seeds-0-1: unknown task for --backend device "
        "'HalfCheetah-v5'; allowed: hopper, walker2d, ant, humanoid"
    )


def test_two_tasks_that_map_to_one_unit_folder_are_refused():
    # issue 61 §7: `rel6/Bot-v0` and `rel6__Bot-v0` both train into `rel6__Bot-v0/...`; the
    # second was never trained but reported done, the manifest naming the wrong task
    from types import SimpleNamespace

    from adarl.errors import UsageError
    from adarl.sweeps import spec as sweep_spec

    def unit(task):
        return SimpleNamespace(task=task, id=f"{task.replace('/', '__')}/sac/seeds-0")

    sweep_spec._check_distinct_folders([unit("rel6/Bot-v0"), unit("hopper")], "f.yaml")
    with pytest.raises(UsageError, match="tasks 'rel6/Bot-v0' and 'rel6__Bot-v0' would train into one unit folder 'rel6__Bot-v0/sac/seeds-0'"):  # fmt: skip
        sweep_spec._check_distinct_folders([unit("rel6/Bot-v0"), unit("rel6__Bot-v0")], "f.yaml")


def test_every_sweep_checks_its_unit_folders_are_distinct(monkeypatch):
    from adarl.sweeps import spec as sweep_spec

    calls = []
    monkeypatch.setattr(sweep_spec, "_check_distinct_folders", lambda units, where: calls.append(len(units)))  # fmt: skip
    sweep_spec.load("smoke")
    assert calls and calls[0] > 0
