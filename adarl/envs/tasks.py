"""The four tasks of the AdaRL paper: Gymnasium ids, sizes, parameters and schedule formulas.

Schedules (AdaRL appendix "Model Uncertainty Setting", i = episode index):
  Hopper    torso 0.4 + 0.2·sin(0.2i), foot 0.39 + 0.2·sin(0.2i)   (OMPO's code: amplitude 0.1)
  Walker2d  torso 0.2 + 0.1·sin(0.3i), foot 0.1 + 0.05·sin(0.3i)
  Ant       g 14.715 + 4.905·sin(0.5i), W 1 + 0.2·sin(0.5i)
  Humanoid  g 14.715 + 4.905·sin(0.5i), W 1 + 0.5·sin(0.5i)
Lengths are capsule half-lengths (Gymnasium: Hopper torso 0.2 / foot 0.195, Walker2d 0.2 / 0.1).

Model versions: `v5` (default) and `v4`, Gymnasium's port of the Gym v3 tasks the paper ran.
Physics: `consistent` recompiles the model (masses follow geometry), `ompo` edits the compiled
default model as OMPO does (masses and inertias stay the default robot's); see adarl.envs.model.
"""

from __future__ import annotations

import functools
import importlib
import json
import math
import os
import re
import sys
from dataclasses import dataclass, field, replace

from adarl.envs.params import PARAMS, Sinusoid
from adarl.errors import UsageError, check_choice

#: Generic robustness parameters every task has, at their no-change values.
GENERIC_DEFAULTS = {"mass_scale": 1.0, "friction_scale": 1.0, "damping_scale": 1.0}

#: Gymnasium model versions: v5 (default) and v4 (the port of Gym v3, which the paper ran).
VERSIONS = ("v5", "v4")
#: How parameters reach the model: recompiled from an edited MjSpec, or written into the
#: compiled default model as OMPO does.
PHYSICS = ("consistent", "ompo")

#: Gymnasium's torso and thigh masses (kg) of Hopper and Walker2d (v4 and v5 alike), the defaults
#: of their optional mass parameters (tests check them against the compiled models).
LEGGED_OPTIONAL = {"torso_mass": 3.6651914291880923, "thigh_mass": 4.057890510886818}

#: Air, as OMPO sets it for Ant and Humanoid so that MuJoCo's wind acts: (density kg/m^3, viscosity Pa s).
AIR = (1.2, 2e-5)


@dataclass(frozen=True)
class TaskSpec:
    """Static facts about one task. `params` maps each parameter to its Gymnasium default."""

    name: str
    gym_id: str
    obs_dim: int
    act_dim: int
    params: dict[str, float]  # shared: do not mutate
    schedules: dict[str, dict[str, Sinusoid]]  # "paper" / "ompo" -> {param: Sinusoid}
    medium: tuple[float, float] | None = None  # (density, viscosity) outside `default` mode
    stiffness_joints: tuple[str, ...] = ()
    spring_ref: float = 0.0  # rad; the spring reference of `stiffness_joints`
    version: str = "v5"  # Gymnasium model version of `gym_id` and `obs_dim`
    v4_obs_dim: int = 0  # observation size of the task's -v4 env
    #: Parameters a schedule may set but need not: left out of `params` (so of `info["dynamics"]`
    #: and the training logs) unless set; at their default they leave the model untouched.
    optional_params: dict[str, float] = field(default_factory=dict)
    #: "paper" (the four tasks above), "mujoco" (any other env built on Gymnasium's `MujocoEnv`:
    #: generic and addressed parameters) or "gym" (any other Gymnasium env: fixed dynamics)
    kind: str = "paper"
    env_kwargs: tuple[tuple[str, object], ...] = ()  # Gymnasium keywords (`xml_file`, ...)
    env_module: str = ""  # the module imported first, which registers `gym_id`
    xml_path: str = ""  # the model's XML (generic tasks; the paper's: adarl.envs.model)
    max_episode_steps: int = 1000  # the registered time limit (the paper's four: 1000)
    intrinsic_rank: int = field(init=False)

    def __post_init__(self):
        # Tiwari et al. 2025: reachable states lie on a manifold of dimension <= 2·d_a + 1.
        object.__setattr__(self, "intrinsic_rank", 2 * self.act_dim + 1)

    @property
    def all_params(self) -> dict[str, float]:
        """`params` and `optional_params`: every parameter name a schedule accepts, with its default."""
        return self.params | self.optional_params

    @property
    def paper(self) -> bool:
        """One of the paper's four tasks?"""
        return self.kind == "paper"

    @property
    def varied(self) -> tuple[str, ...]:
        """The parameters the paper's schedule varies from episode to episode."""
        return tuple(self.schedules["paper"])

    @property
    def formulas(self) -> dict[str, dict[str, str]]:
        """Schedule formulas as text: {"paper": {"torso_length": "0.4 + 0.2·sin(0.2·i)"}, ...}."""
        return {
            kind: {p: s.formula() for p, s in sched.items()}
            for kind, sched in self.schedules.items()
        }


def _task(name, gym_id, obs_dim, act_dim, varied_defaults, paper, ompo=None, **extra) -> TaskSpec:
    params = dict(varied_defaults) | GENERIC_DEFAULTS
    if extra.get("stiffness_joints"):
        params["stiffness"] = 0.0
    assert set(params) | set(extra.get("optional_params", {})) <= set(PARAMS), params
    return TaskSpec(
        name=name,
        gym_id=gym_id,
        obs_dim=obs_dim,
        act_dim=act_dim,
        params=params,
        schedules={"paper": dict(paper), "ompo": dict(ompo or paper)},
        **extra,
    )


TASKS: dict[str, TaskSpec] = {
    t.name: t
    for t in (
        _task(
            "hopper",
            "Hopper-v5",
            11,
            3,
            {"torso_length": 0.2, "foot_length": 0.195},
            paper={
                "torso_length": Sinusoid(0.4, 0.2, 0.2),
                "foot_length": Sinusoid(0.39, 0.2, 0.2),
            },
            ompo={"torso_length": Sinusoid(0.4, 0.1, 0.2), "foot_length": Sinusoid(0.39, 0.1, 0.2)},
            # RNAC's Hopper sweep writes springref 2.0 rad to the hopper's joints (leg stiffened).
            stiffness_joints=("leg_joint", "foot_joint"),
            spring_ref=2.0,
            v4_obs_dim=11,
            optional_params=LEGGED_OPTIONAL | {"floor_friction": 1.0},
        ),
        _task(
            "walker2d",
            "Walker2d-v5",
            17,
            6,
            {"torso_length": 0.2, "foot_length": 0.1},
            paper={
                "torso_length": Sinusoid(0.2, 0.1, 0.3),
                "foot_length": Sinusoid(0.1, 0.05, 0.3),
            },
            # RNAC's Walker2d env sets no springref: the spring pulls towards the standing pose.
            stiffness_joints=("foot_joint", "foot_left_joint"),
            spring_ref=0.0,
            v4_obs_dim=17,
            optional_params=LEGGED_OPTIONAL | {"floor_friction": 0.7},
        ),
        _task(
            "ant",
            "Ant-v5",
            105,
            8,
            {"gravity": 9.81, "wind": 0.0},
            paper={"gravity": Sinusoid(14.715, 4.905, 0.5), "wind": Sinusoid(1.0, 0.2, 0.5)},
            medium=AIR,
            v4_obs_dim=27,
            optional_params={
                "torso_mass": 0.32724923474893675,
                "front_left_leg_mass": 0.03915775372846671,
                "front_right_leg_mass": 0.03915775372846671,
            },  # Ant-v4 leaves contact forces out of the observation by default
        ),
        _task(
            "humanoid",
            "Humanoid-v5",
            348,
            17,
            {"gravity": 9.81, "wind": 0.0},
            paper={"gravity": Sinusoid(14.715, 4.905, 0.5), "wind": Sinusoid(1.0, 0.5, 0.5)},
            medium=AIR,
            v4_obs_dim=376,  # includes the world body's cinert/cvel/cfrc_ext and the root's forces
        ),
    )
}


#: One step's reward bounds (low, high) of the Gymnasium tasks whose reward function bounds it, at
#: their default reward keywords (Gymnasium's mujoco/*_v4.py and *_v5.py): InvertedPendulum gives
#: 1 per step (v5: 0 on the step that falls); InvertedDoublePendulum a healthy reward of 10 less
#: penalties ≥ 0; Reacher and Pusher only penalties. Other tasks (Hopper's control cost, a user's
#: own reward): unknown.
STEP_REWARD_BOUNDS = {
    **dict.fromkeys(("InvertedPendulum-v4", "InvertedPendulum-v5"), (0.0, 1.0)),
    **dict.fromkeys(("InvertedDoublePendulum-v4", "InvertedDoublePendulum-v5"), (-math.inf, 10.0)),
    **dict.fromkeys(("Reacher-v4", "Reacher-v5", "Pusher-v4", "Pusher-v5"), (-math.inf, 0.0)),
}


def return_bounds(spec: TaskSpec, max_steps: int) -> tuple[float, float]:
    """The lowest and highest return an episode of at most `max_steps` steps of `spec` can
    have, from `STEP_REWARD_BOUNDS` (a bound of 0 holds for any length); (-inf, inf) where a
    bound is unknown: another task, an env-module's env, or env-kwargs that set a reward
    keyword (`healthy_reward`, `reward_dist_weight`, …)."""
    step = STEP_REWARD_BOUNDS.get(spec.gym_id)
    if step is None or spec.env_module or any("reward" in k for k, _ in spec.env_kwargs):
        return -math.inf, math.inf
    low, high = step  # low ≤ 0 ≤ high: the longest episode reaches both
    return low * max_steps, high * max_steps


def list_tasks() -> list[str]:
    """Task names: ["hopper", "walker2d", "ant", "humanoid"]."""
    return list(TASKS)


def get_task(
    name: str | TaskSpec, version: str = "v5", *, env_kwargs=None, env_module: str = ""
) -> TaskSpec:
    """The `TaskSpec` of `name`: one of the paper's four on Gymnasium's `version` models (its
    `gym_id` and `obs_dim`), or any registered Gymnasium id (`HalfCheetah-v5`, a user's own after
    `env_module` registers it; `gym:ID` as well) made with `env_kwargs` (text `k=v,k=v` or JSON,
    or a dict: Gymnasium's own keywords such as `xml_file`). Without `env_kwargs`, an id gets the
    spec this process last made for it (a run's env and its schedules share it). Bad input: a
    one-line `UsageError`. A `TaskSpec` is returned as it is."""
    if isinstance(name, TaskSpec):
        return name
    key = name.strip().lower() if isinstance(name, str) else name
    if key in TASKS:
        if env_kwargs or env_module:
            raise UsageError(
                f"env-kwargs/env-module apply to Gymnasium ids, not to task {name!r}; allowed: "
                f"empty (the paper's tasks take their physics from --dynamics)"
            )
        check_choice("model version", version, VERSIONS)
        spec = TASKS[key]
        if version == spec.version:
            return spec
        return replace(
            spec, gym_id=spec.gym_id.replace("-v5", "-v4"), obs_dim=spec.v4_obs_dim, version="v4"
        )
    if not isinstance(name, str) or not name.strip():
        check_choice("task", name, TASKS)
    check_choice("model version", version, VERSIONS)
    if version != "v5":
        raise UsageError(
            f"model version {version!r} applies to {', '.join(TASKS)}; allowed for {name!r}: v5 "
            "(the id itself names its version)"
        )
    name = name.strip()
    if not env_module and not _GYM_ID.match(name):  # no Gymnasium import for a typo
        raise UsageError(
            f"unknown task {name!r}; allowed: {', '.join(TASKS)} or a registered Gymnasium id "
            "such as HalfCheetah-v5 (adarl tasks lists them)"
        )
    check_named(env_module, "a run folder or a file")  # before the cache of made tasks
    if env_kwargs is None and not env_module and name in _LAST:
        return _LAST[name]
    spec = _gym_task(name, kwargs_text(env_kwargs), env_module or "")
    _LAST[name] = spec
    return spec


#: A task outside the paper's four that `paper` (and `ompo`) name: adarl's generic schedule.
GENERIC_SCHEDULE = {
    "mass_scale": Sinusoid(1.0, 0.2, 0.5),
    "friction_scale": Sinusoid(1.0, 0.2, 0.5),
}
GYM_PREFIX = "gym:"
#: A Gymnasium id, `[gym:][namespace/]Name-vN` (an unversioned id needs its env-module).
_GYM_ID = re.compile(r"^(gym:)?([\w.-]+/)?[\w.:-]+-v\d+$")
_LAST: dict[str, TaskSpec] = {}


def parse_env_kwargs(text) -> dict[str, object]:
    """`k=v,k=v` (each value read as YAML: numbers, booleans, text) or a JSON object, or a dict,
    -> a dict; a one-line `UsageError` otherwise."""
    if isinstance(text, dict):
        return _checked_kwargs(dict(text), repr(text))
    text = (text or "").strip()
    if not text:
        return {}
    if text.startswith("{"):
        try:
            value = json.loads(text)
        except ValueError:
            value = None
        if not isinstance(value, dict):
            raise UsageError(f"bad env-kwargs {text!r}; allowed: a JSON object or k=v,k=v")
        return _checked_kwargs(value, repr(text))
    import yaml

    out = {}
    for item in text.split(","):
        key, eq, value = (part.strip() for part in item.partition("="))
        if not eq or not key.isidentifier():
            raise UsageError(
                f"malformed env-kwargs {text!r} (at {item.strip()!r}); allowed: k=v[,k=v...] "
                "with k a keyword of the env's class, or a JSON object"
            )
        try:  # safe_load builds plain values only: a python/ tag is an error, never run
            out[key] = yaml.safe_load(value) if value else ""
        except yaml.YAMLError:
            raise UsageError(
                f"bad env-kwargs value {key}={value!r}; allowed: a number, true/false, or text "
                "(JSON for lists: a JSON object of all the keywords)"
            ) from None
    return _checked_kwargs(out, repr(text))


def _checked_kwargs(kwargs: dict, text: str) -> dict:
    """`kwargs` with every float finite and an `xml_file` that names a regular file (a FIFO
    would block the first read for ever), or a one-line UsageError (issue 61 §6, §7)."""
    for key, value in kwargs.items():
        if isinstance(value, float) and not math.isfinite(value):
            raise UsageError(f"bad env-kwargs {key}={value!r} in {text}; allowed: a finite number")
        if key == "render_mode":  # human opens a window mid-run (a GLFW abort on a server)
            raise UsageError(
                f"env-kwargs render_mode={value!r}: adarl renders only in `adarl play`; "
                "allowed: leave render_mode out"
            )
        if key == "xml_file" and isinstance(value, str) and os.path.exists(value):
            if not os.path.isfile(value):
                raise UsageError(
                    f"env-kwargs xml_file={value!r} is not a regular file; allowed: an XML file"
                )
    return kwargs


def kwargs_text(env_kwargs) -> str:
    """Canonical text of `env_kwargs` (sorted JSON; "" for none): a run's config field."""
    kwargs = parse_env_kwargs(env_kwargs)
    return json.dumps(kwargs, sort_keys=True) if kwargs else ""


# A run folder or a sweep file is data: reading one never runs code (docs/reliability.md). An
# env-module is imported only when the user names it: a flag (`--env-module M`), a keyword
# (`adarl.train(env_module=M)`, `adarl.evaluate(..., env_module=M)`), their own sweep file when
# it runs (not `--dry-run`); or when it is already imported (importing it again runs nothing).
_NAMED: set[str] = set()
_MODULE = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$")


def name_env_module(*modules: str) -> None:
    """Let `import_env_module` import each of `modules` (those the user named; empty ones are
    skipped); a one-line `UsageError` for a name that is not a module's."""
    for module in modules:
        module = str(module or "").strip()
        if not module:
            continue
        if not _MODULE.match(module):
            raise UsageError(
                f"bad env-module {module!r}; allowed: a module name such as myrobots or "
                "my_pkg.envs (importable from the current folder or the Python path)"
            )
        _NAMED.add(module)


def check_named(module: str, where: str) -> None:
    """A one-line `UsageError` if `module` (which `where`, a run's config.yaml or a sweep file,
    names) was not named by the user, saying how to allow it."""
    module = str(module or "").strip()
    if module and module not in _NAMED and module not in sys.modules:
        raise UsageError(
            f"{where} names env-module {module!r}, which you did not name: adarl never imports "
            f"a module because a run folder or a file names it; allowed: add --env-module "
            f"{module} (Python: env_module={module!r}) if you trust its code"
        )


def import_env_module(module: str) -> None:
    """Import `module` (which registers a user's Gymnasium ids) as `python -m` finds it, the
    current folder first, if the user named it (`name_env_module`); a one-line `UsageError`
    otherwise, or if it fails."""
    if not module:
        return
    check_named(module, "a run folder or a file")
    if module in sys.modules:
        return
    cwd = os.getcwd()
    if not any(os.path.abspath(entry or os.curdir) == cwd for entry in sys.path):
        sys.path.insert(0, cwd)  # as `python -m` has it (the `adarl` script has its own folder)
    try:
        importlib.import_module(module)
    except SystemExit as exc:  # a module that exits as it is imported: say so, do not exit 0
        raise UsageError(
            f"env-module {module!r} called sys.exit({exc.code!r}) as it was imported; allowed: a "
            "module that registers its Gymnasium ids and returns"
        ) from None
    except Exception as exc:  # any failure of a user's module is theirs: say which and why
        raise UsageError(f"cannot import env-module {module!r}: {exc!r}".splitlines()[0]) from None


def make_raw_env(spec: TaskSpec, render_mode: str | None = None):
    """The unwrapped Gymnasium env of `spec` (no checker, order or time-limit wrappers)."""
    import gymnasium
    from gymnasium.envs.registration import load_env_creator

    from adarl.envs.elements import quiet_settotalmass

    quiet_settotalmass()
    import_env_module(spec.env_module)
    gym_spec = gymnasium.spec(spec.gym_id)
    kwargs = dict(gym_spec.kwargs) | dict(spec.env_kwargs)
    if render_mode is not None:
        kwargs["render_mode"] = render_mode
    try:  # loading the entry point imports its module (a missing dependency fails here)
        creator = (
            load_env_creator(gym_spec.entry_point)
            if isinstance(gym_spec.entry_point, str)
            else gym_spec.entry_point
        )
        raw = creator(**kwargs)
    except TypeError as exc:
        raise UsageError(
            f"env {spec.gym_id!r} does not take env-kwargs {dict(spec.env_kwargs)}: {exc}"
        ) from None
    except UsageError:
        raise
    except Exception as exc:  # a missing dependency, a bad XML: the env's own message, one line
        message = f"{type(exc).__name__}: {exc}".splitlines()[0]
        raise UsageError(f"cannot make env {spec.gym_id!r} ({message})") from None
    if not isinstance(raw, gymnasium.Env):
        raise UsageError(
            f"the entry point of {spec.gym_id!r} returned {raw!r:.60} ({type(raw).__name__}), not "
            "a Gymnasium env; allowed: a callable that returns a gymnasium.Env"
        )
    return getattr(raw, "unwrapped", raw)


@functools.lru_cache(maxsize=64)
def _gym_task(name: str, env_kwargs: str, env_module: str) -> TaskSpec:
    import gymnasium

    import_env_module(env_module)
    gym_id = name[len(GYM_PREFIX) :] if name.startswith(GYM_PREFIX) else name
    try:
        gym_spec = gymnasium.spec(gym_id)
    except gymnasium.error.Error:
        if gym_id.startswith("adarl-fn/"):
            raise UsageError(
                f"task {name!r} was an env_fn of adarl.train; allowed: resume it from Python, "
                "adarl.train(env_fn=<the same callable>, resume=RUN_DIR)"
            ) from None
        raise UsageError(
            f"unknown task {name!r}; allowed: {', '.join(TASKS)} or a registered Gymnasium id "
            "such as HalfCheetah-v5 (--env-module PKG imports the package that registers yours; "
            "adarl tasks lists them)"
        ) from None
    kwargs = tuple(sorted(json.loads(env_kwargs).items())) if env_kwargs else ()
    probe = TaskSpec(
        name, gym_id, 0, 0, {}, {}, kind="gym", env_kwargs=kwargs, env_module=env_module
    )
    raw = make_raw_env(probe)
    try:
        obs_dim, act_dim = check_spaces(name, raw.observation_space, raw.action_space)
        check_steps(name, raw, obs_dim)
        from gymnasium.envs.mujoco.mujoco_env import MujocoEnv

        limit = int(gym_spec.max_episode_steps or 1000)
        if not isinstance(raw, MujocoEnv):
            return replace(probe, obs_dim=obs_dim, act_dim=act_dim, max_episode_steps=limit)
        from adarl.envs.elements import GENERIC_SCALES, model_gravity

        xml = raw.fullpath
        params = dict(GENERIC_SCALES) | {"gravity": model_gravity(xml)}
        return replace(
            probe,
            obs_dim=obs_dim,
            act_dim=act_dim,
            params=params,
            schedules={"paper": dict(GENERIC_SCHEDULE), "ompo": dict(GENERIC_SCHEDULE)},
            optional_params={"wind": 0.0},
            kind="mujoco",
            xml_path=xml,
            max_episode_steps=limit,
        )
    finally:
        raw.close()


def check_steps(name: str, raw, obs_dim: int) -> None:
    """Reset `raw` and step it once with the middle of its action space: a one-line UsageError
    naming the task if either raises, returns an observation of another size than its space's,
    or a step that is not Gymnasium's (obs, reward, terminated, truncated, info) with a finite
    reward (issue 61 §6: these were tracebacks from inside adarl, after the run folder was
    written)."""
    import numpy as np

    def observation(value, where: str) -> None:
        size = np.asarray(value, dtype=np.float64).size if value is not None else 0
        if size != obs_dim:
            raise UsageError(
                f"task {name!r}: {where} returned an observation of {size} numbers, but its "
                f"observation space has {obs_dim}; allowed: an env whose observations match it"
            )

    try:
        out = raw.reset(seed=0)
        if not (isinstance(out, tuple) and len(out) == 2):
            raise UsageError(f"task {name!r}: reset() returned {out!r:.60}, not (obs, info)")
        observation(out[0], "reset()")
        space = raw.action_space
        step = raw.step(((space.low + space.high) / 2).astype(space.dtype))
        if not (isinstance(step, tuple) and len(step) == 5):
            raise UsageError(
                f"task {name!r}: step() returned {step!r:.60}, not Gymnasium's (obs, reward, "
                "terminated, truncated, info)"
            )
        observation(step[0], "step()")
        if not np.isfinite(float(step[1])):
            raise UsageError(f"task {name!r}: step() returned the reward {step[1]!r}")
    except UsageError:
        raise
    except Exception as exc:  # the env's own failure, one line
        message = f"{type(exc).__name__}: {exc}".splitlines()[0]
        raise UsageError(f"task {name!r} fails when reset and stepped once ({message})") from None


def check_spaces(name: str, obs_space, act_space) -> tuple[int, int]:
    """(obs_dim, act_dim) of a task adarl can train: a flat Box of observations and of actions
    with finite bounds; a one-line `UsageError` otherwise."""
    import gymnasium
    import numpy as np

    if not isinstance(act_space, gymnasium.spaces.Box) or len(act_space.shape) != 1:
        raise UsageError(
            f"task {name!r} has actions {act_space}; allowed: a 1-D Box (continuous actions; "
            "adarl trains SAC-family agents)"
        )
    if not (np.all(np.isfinite(act_space.low)) and np.all(np.isfinite(act_space.high))):
        raise UsageError(f"task {name!r} has unbounded actions {act_space}; allowed: finite bounds")
    if not isinstance(obs_space, gymnasium.spaces.Box) or len(obs_space.shape) != 1:
        raise UsageError(
            f"task {name!r} has observations {obs_space}; allowed: a 1-D Box (no Dict, image or "
            "discrete observations; flatten them with a Gymnasium wrapper in your env)"
        )
    return int(obs_space.shape[0]), int(act_space.shape[0])


def registered_time_limit(task: str, env_module: str = "", env_kwargs="") -> int | None:
    """The registered `max_episode_steps` of a task outside the paper's four (None for the
    paper's, whose limit is 1000); errors as `get_task`."""
    if str(task).strip().lower() in TASKS:
        return None
    return get_task(task, env_kwargs=env_kwargs or "", env_module=env_module).max_episode_steps


def model_identity(spec: TaskSpec) -> dict | None:
    """What model a Gymnasium MuJoCo task is: its XML's resolved path and the SHA-256 of its
    bytes (recorded in a run's environment.json, `model`); None for a task without an XML of its
    own (the paper's four build theirs from adarl's code). Meshes and other assets the XML
    includes are not hashed."""
    if spec.kind != "mujoco" or not spec.xml_path:
        return None
    import hashlib

    path = os.path.realpath(spec.xml_path)
    with open(path, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()
    return {"xml": path, "sha256": digest}


def check_model(spec: TaskSpec, recorded, where: str, what: str) -> None:
    """A one-line UsageError if `recorded` (a run's `model`) is not `spec`'s model now: `what`
    (resuming, evaluating) would run on another model than the run trained on (issue 61 §3: a
    relative xml_file from another folder, or the file edited since). Runs without a record
    are not checked."""
    if not isinstance(recorded, dict) or "sha256" not in recorded:
        return
    now = model_identity(spec)
    if now is None or now == {"xml": recorded.get("xml"), "sha256": recorded["sha256"]}:
        return
    raise UsageError(
        f"{where} was trained on the model {recorded.get('xml')} (sha256 "
        f"{str(recorded['sha256'])[:12]}), but {what} it here would use {now['xml']} (sha256 "
        f"{now['sha256'][:12]}); allowed: run from the folder it trained in, or put its model "
        "back as it was (or start a new run)"
    )


def task_of(config) -> TaskSpec:
    """The `TaskSpec` of a run's config (a config dataclass or its config.yaml dict)."""
    if not isinstance(config, dict):
        config = vars(config)
    return get_task(
        str(config.get("task", "hopper")),
        str(config.get("model_version", VERSIONS[0])),
        env_kwargs=config.get("env_kwargs", ""),
        env_module=str(config.get("env_module", "")),
    )


def env_options(config) -> dict[str, str]:
    """`make`'s `physics` and `model_version` keywords from a run's config (a config dataclass or the
    dict of its config.yaml, whose fields are top-level keys: docs/run-format.md); a config
    without them (runs made before these switches) gets the defaults, `consistent` and `v5`."""
    if not isinstance(config, dict):
        config = vars(config)
    return {
        "physics": str(config.get("physics", PHYSICS[0])),
        "model_version": str(config.get("model_version", VERSIONS[0])),
    }
