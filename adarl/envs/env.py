"""The task env: Gymnasium's v5 (or v4) MuJoCo env whose model is recompiled (or, under `ompo`
physics, edited) at reset when the schedule's parameters change, plus the 1000-step time limit.

`make` builds Gymnasium's env class directly (no PassiveEnvChecker / OrderEnforcing / TimeLimit
wrappers) and wraps it once in `DynamicsEnv`, which counts steps itself. Per step the wrapper only
adds two entries to `info`; per reset it evaluates the schedule and, if the parameters changed,
compiles a new model (about 0.5-1 ms) and swaps it into the env, reusing the `MjData` buffers;
under `ompo` physics it writes them into the env's own compiled model instead (`ModelEditor`).
"""

from __future__ import annotations

import copy
import time

import gymnasium
import mujoco
import numpy as np
from gymnasium.envs.registration import load_env_creator

from adarl.envs.dynamics import DynamicsSchedule, parse_dynamics
from adarl.envs.model import ModelBuilder, ModelEditor
from adarl.envs.params import is_addressed
from adarl.envs.tasks import PHYSICS, TaskSpec, get_task, make_raw_env
from adarl.errors import UsageError, check_choice

#: MuJoCo's full integration state: qpos, qvel, act, time, warmstart, ctrl, applied forces, ...
STATE_SIG = mujoco.mjtState.mjSTATE_INTEGRATION
#: Quantities computed from the state that Gymnasium's v5 tasks read before stepping (Ant: xpos
#: of the main body, Humanoid: xipos for the centre of mass) or put in observations. After
#: `mj_step` they belong to an intermediate point of the step, so they are stored, not recomputed.
DERIVED_FIELDS = ("xpos", "xquat", "xipos", "cinert", "cvel", "qfrc_actuator", "cfrc_ext")
#: Any other MuJoCo task may read more of them before a step (Reacher and Pusher: the fingertip's
#: and the object's xpos; a user's env: sites, sensors), so its states keep all of these.
GENERIC_DERIVED_FIELDS = (
    *DERIVED_FIELDS,
    "xmat",
    "ximat",
    "xanchor",
    "xaxis",
    "geom_xpos",
    "geom_xmat",
    "site_xpos",
    "site_xmat",
    "subtree_com",
    "cdof",
    "cacc",
    "cfrc_int",
    "qacc",
    "qfrc_bias",
    "qfrc_passive",
    "qfrc_constraint",
    "actuator_force",
    "actuator_length",
    "actuator_velocity",
    "sensordata",
    "ten_length",
    "energy",
)
_STATE_VERSION = 1


class DynamicsEnv(gymnasium.Wrapper):
    """A Gymnasium MuJoCo env following a `DynamicsSchedule`, one parameter set per episode.

    `info["dynamics"]` (the episode's parameter dict, shared: do not mutate it) and
    `info["episode_index"]` are set at every reset and step. `physics` is how parameters reach
    the model: `consistent` recompiles it, `ompo` edits the env's compiled model in place.
    """

    def __init__(
        self,
        env: gymnasium.Env,
        task: TaskSpec,
        schedule: DynamicsSchedule,
        seed: int | None = 0,
        max_episode_steps: int = 1000,
        physics: str = "consistent",
    ):
        super().__init__(env)
        self.task = task
        self.schedule = schedule
        self.physics = check_choice("physics", physics, PHYSICS)
        self.max_episode_steps = int(max_episode_steps)
        self._raw = env.unwrapped
        self._derived = DERIVED_FIELDS if task.paper else GENERIC_DERIVED_FIELDS
        if schedule.mode == "default":
            self._builder = None
        elif not task.paper:
            from adarl.envs.elements import GenericBuilder

            textures = self._raw.render_mode is not None
            self._builder = GenericBuilder(self._raw.fullpath, textures=textures)
        elif physics == "ompo":
            self._builder = ModelEditor(task, self._raw.model)
        else:
            textures = self._raw.render_mode is not None
            self._builder = ModelBuilder(task, self._raw.fullpath, textures=textures)
        self._pending_seed = seed  # used by the first reset without a seed
        self._schedule_seed = (
            int(seed) if seed is not None else int(np.random.SeedSequence().entropy)
        )
        self._index = 0  # episode index of the current episode (or the next, before its reset)
        self._advance = False  # whether the next reset moves to _index + 1
        self._params: dict[str, float] | None = None  # parameters of the installed model
        self._key: tuple | None = None
        self._elapsed = 0
        self.compiles = 0  # number of models compiled (ompo: edited) so far
        self.compile_seconds = 0.0  # CPU time spent compiling and swapping them in

    # ---- public attributes --------------------------------------------------------------
    @property
    def episode_index(self) -> int:
        """Index of the current episode; set it to k to make the next reset start episode k."""
        return self._index

    @episode_index.setter
    def episode_index(self, value: int) -> None:
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
            raise UsageError(f"bad episode index {value!r}; allowed: an integer >= 0")
        self._index, self._advance = int(value), False

    @property
    def dynamics_params(self) -> dict[str, float] | None:
        """The current episode's parameters (None before the first reset)."""
        return self._params

    # ---- gymnasium API --------------------------------------------------------------------
    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._elapsed += 1
        if self._elapsed >= self.max_episode_steps:
            truncated = True
        info["dynamics"] = self._params
        info["episode_index"] = self._index
        return obs, reward, terminated, truncated, info

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start the next episode (the first reset uses `make`'s seed); `seed` also reseeds the
        schedule's random draws (uniform mode)."""
        if seed is None:
            seed = self._pending_seed
        self._pending_seed = None
        if seed is not None:
            self._schedule_seed = int(seed)
        if self._advance:
            self._index += 1
        self._advance = True
        self._install(self._episode_params(self._index))
        obs, info = self.env.reset(seed=seed, options=options)
        self._elapsed = 0
        info["dynamics"] = self._params
        info["episode_index"] = self._index
        return obs, info

    # ---- checkpointing ----------------------------------------------------------------------
    def get_state(self) -> dict:
        """Everything needed to continue bit-exactly: schedule position and seed, parameters,
        MuJoCo integration state (+ derived fields Gymnasium reads), step count, env RNG."""
        state = {
            "version": _STATE_VERSION,
            "task": self.task.name,
            "model_version": self.task.version,
            "physics": self.physics,
            "schedule": self.schedule.name,
            "episode_index": self._index,
            "advance": self._advance,
            "schedule_seed": self._schedule_seed,
            "pending_seed": self._pending_seed,
            "elapsed_steps": self._elapsed,
            "params": None if self._params is None else dict(self._params),
            "np_random": None,
            "mj_state": None,
            "mj_derived": None,
        }
        if self._params is not None:
            raw = self._raw
            mj_state = np.empty(mujoco.mj_stateSize(raw.model, STATE_SIG))
            mujoco.mj_getState(raw.model, raw.data, mj_state, STATE_SIG)
            state["mj_state"] = mj_state
            state["mj_derived"] = {f: getattr(raw.data, f).copy() for f in self._derived}
            state["np_random"] = copy.deepcopy(raw.np_random.bit_generator.state)
        return state

    def set_state(self, state: dict) -> None:
        """Restore `get_state()` output, recompiling the model for the stored parameters."""
        if state.get("version") != _STATE_VERSION:
            raise UsageError(
                f"bad env state version {state.get('version')!r}; allowed: {_STATE_VERSION}"
            )
        expected = {
            "task": self.task.name,
            "model_version": self.task.version,
            "physics": self.physics,
            "schedule": self.schedule.name,
        }
        for key, mine in expected.items():
            # states saved before the version and physics switches are v5 and consistent
            theirs = state.get(key, {"model_version": "v5", "physics": "consistent"}.get(key))
            if theirs != mine:
                raise UsageError(
                    f"env state is for {key} {theirs!r}; allowed: {mine!r} (this env's)"
                )
        self._index, self._advance = int(state["episode_index"]), bool(state["advance"])
        self._schedule_seed, self._pending_seed = int(state["schedule_seed"]), state["pending_seed"]
        self._elapsed = int(state["elapsed_steps"])
        if state["params"] is None:
            return
        self._install(dict(state["params"]))
        raw = self._raw
        mujoco.mj_resetData(raw.model, raw.data)
        mujoco.mj_setState(
            raw.model, raw.data, np.asarray(state["mj_state"], dtype=np.float64), STATE_SIG
        )
        for name, value in state["mj_derived"].items():
            getattr(raw.data, name)[...] = value
        raw.np_random.bit_generator.state = copy.deepcopy(state["np_random"])

    # ---- internals ----------------------------------------------------------------------------
    def _episode_params(self, index: int) -> dict[str, float]:
        rng = (
            np.random.default_rng([self._schedule_seed, index]) if self.schedule.needs_rng else None
        )
        return self.schedule.params_for_episode(index, rng)

    def _install(self, params: dict[str, float]) -> None:
        """Make the env simulate `params`: compile and swap in a model unless they are unchanged."""
        key = tuple(params.values())
        if key == self._key:
            return
        self._params, self._key = params, key
        if self._builder is not None:
            start = time.process_time()
            self._swap(self._builder.compile(params))
            self.compiles += 1
            self.compile_seconds += time.process_time() - start

    def _swap(self, model: mujoco.MjModel) -> None:
        """Put `model` into the Gymnasium env (model, data, init_qpos/qvel, renderer)."""
        raw = self._raw
        old, data = raw.model, raw.data
        # Only values changed, so the old MjData has the right sizes; the reset that follows
        # (mj_resetData) reinitialises it from the new model exactly as a fresh MjData.
        if model_sizes(old) != model_sizes(model):
            data = mujoco.MjData(model)
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, raw.width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, raw.height)
        raw.model, raw.data = model, data
        if self.task.paper or np.array_equal(
            raw.init_qpos, old.qpos0
        ):  # a user's env may set its own
            raw.init_qpos = model.qpos0.copy()
        if self.task.paper or not np.any(raw.init_qvel):
            raw.init_qvel = np.zeros(model.nv)
        renderer = raw.mujoco_renderer
        if renderer is not None:
            if renderer._viewers:
                renderer.close()
                renderer._viewers, renderer.viewer = {}, None
            renderer.model, renderer.data = model, data


def model_sizes(model: mujoco.MjModel) -> tuple:
    """The sizes an MjData is allocated with: two models with the same sizes can share one (a
    dynamics change edits values only)."""
    return (
        model.nq,
        model.nv,
        model.nu,
        model.na,
        model.nbody,
        model.ngeom,
        model.njnt,
        model.nmocap,
        model.nuserdata,
        model.narena,
        model.nbuffer,
    )


def make(
    task: str | TaskSpec,
    dynamics: str | DynamicsSchedule = "paper",
    seed: int | None = 0,
    *,
    max_episode_steps: int | None = None,
    render_mode: str | None = None,
    physics: str = "consistent",
    model_version: str = "v5",
    env_kwargs: str | dict = "",
    env_module: str = "",
    **overrides: float,
) -> DynamicsEnv:
    """Task env following `dynamics` (a name like "paper" or "fixed:torso_length=0.5", or a
    `DynamicsSchedule`), with `overrides` fixed on top. `seed` seeds the first reset and the
    schedule's draws: the same seed gives the same parameter sequence. `physics`: `consistent`
    (recompile, masses follow geometry) or `ompo` (edit the compiled default model as OMPO does);
    `model_version`: Gymnasium's `v5` or `v4` models. `task` may also be any registered Gymnasium
    id (`HalfCheetah-v5`; `env_module` imports the package that registers a user's own, and
    `env_kwargs` are the env's keywords, such as `xml_file`): an env built on Gymnasium's
    `MujocoEnv` gets generic and addressed parameters (adarl.envs.elements), any other env
    fixed dynamics (`adarl.envs.plain`). `max_episode_steps` (None: 1000 for the paper's four,
    the registered limit otherwise)."""
    spec, schedule = check_dynamics(
        dynamics,
        task,
        physics=physics,
        model_version=model_version,
        env_kwargs=env_kwargs,
        env_module=env_module,
        **overrides,
    )
    if max_episode_steps is None:
        max_episode_steps = spec.max_episode_steps
    if schedule is None:
        from adarl.envs.plain import make_plain

        return make_plain(spec, dynamics, seed, max_episode_steps=max_episode_steps, **overrides)
    if (
        isinstance(max_episode_steps, bool)
        or not isinstance(max_episode_steps, int)
        or max_episode_steps < 1
    ):
        raise UsageError(f"bad max_episode_steps {max_episode_steps!r}; allowed: an integer >= 1")
    if seed is not None and (
        isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0
    ):
        raise UsageError(f"bad seed {seed!r}; allowed: an integer >= 0 or None")
    gym_spec = gymnasium.spec(spec.gym_id)
    if spec.paper:
        raw = load_env_creator(gym_spec.entry_point)(render_mode=render_mode)
    else:
        raw = make_raw_env(spec, render_mode)
    raw.spec = copy.copy(gym_spec)
    raw.spec.max_episode_steps = max_episode_steps
    return DynamicsEnv(
        raw, spec, schedule, seed=seed, max_episode_steps=max_episode_steps, physics=physics
    )


#: (task, model version, XML, parameters) whose model `check_builds` compiled in this process
_BUILT: set[tuple] = set()


def check_builds(spec: TaskSpec, schedule: DynamicsSchedule) -> None:
    """Compile `schedule`'s model once at its centroid, with a builder of its own, as a reset
    under `consistent` physics would: what the model refuses (a mass its geoms cannot carry, a
    geom its fromto sets, MuJoCo's compiler) is a one-line `UsageError` when an env is made,
    before a run writes anything, not at its first reset. Once per task and parameters."""
    if schedule.mode == "default" or spec.kind == "gym":
        return
    from adarl.envs.dynamics import xml_path
    from adarl.envs.elements import GenericBuilder

    params = schedule.centroid()
    xml = xml_path(spec)
    key = (spec.name, spec.version, xml, tuple(params.items()))
    if key in _BUILT:
        return
    builder = ModelBuilder(spec, xml, textures=False) if spec.paper else GenericBuilder(xml, False)
    try:
        builder.compile(params)
    except UsageError:
        raise
    except ValueError as exc:  # MuJoCo's compiler
        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise UsageError(
            f"cannot build the model of {spec.name} under dynamics {schedule.name!r}: {message}"
        ) from None
    _BUILT.add(key)


def check_dynamics(
    dynamics: str | DynamicsSchedule,
    task: str | TaskSpec,
    *,
    physics: str = "consistent",
    model_version: str = "v5",
    env_kwargs: str | dict = "",
    env_module: str = "",
    max_episode_steps: int | None = None,
    **overrides: float,
) -> tuple[TaskSpec, DynamicsSchedule | None]:
    """Every check `make` makes of its task, physics and dynamics, without making the env (it
    takes `make`'s keywords; `max_episode_steps` is `make`'s to check): the task's spec and the
    schedule, its model built once under `consistent` physics (`check_builds`); None for a task
    with fixed dynamics (`adarl.envs.plain`)."""
    check_choice("physics", physics, PHYSICS)
    spec = get_task(task, model_version, env_kwargs=env_kwargs or "", env_module=env_module)
    if not spec.paper and physics != "consistent":
        raise UsageError(
            f"physics {physics!r} applies to hopper, walker2d, ant, humanoid; allowed for task "
            f"{spec.name!r}: consistent"
        )
    if spec.kind == "gym":
        from adarl.envs.plain import check_plain

        check_plain(spec, dynamics, overrides)
        return spec, None
    schedule = parse_dynamics(dynamics, spec).with_overrides(**overrides)
    if physics == "ompo" and any(is_addressed(p) for p in schedule.centroid()):
        raise UsageError(
            "addressed parameters (KIND:NAME.ATTR) need physics 'consistent'; allowed under "
            "ompo: the task's named parameters"
        )
    if physics == "consistent":
        check_builds(spec, schedule)
    return spec, schedule


def make_vec(
    task: str,
    dynamics: str | DynamicsSchedule = "paper",
    seeds: list[int] = (0,),
    **overrides,
) -> gymnasium.vector.SyncVectorEnv:
    """One `make(task, dynamics, seed, **overrides)` env per seed, stepped together; `overrides`
    may include `physics=` and `model_version=` (bad input raises from the first `make`, before any
    model is built)."""
    seeds = list(seeds)
    if not seeds:
        raise UsageError("bad seeds []; allowed: a non-empty list of integers >= 0")
    return gymnasium.vector.SyncVectorEnv(
        [lambda s=s: make(task, dynamics, s, **overrides) for s in seeds]
    )
