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

from dataclasses import dataclass, field, replace

from adarl.envs.params import PARAMS, Sinusoid
from adarl.errors import check_choice

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
    intrinsic_rank: int = field(init=False)

    def __post_init__(self):
        # Tiwari et al. 2025: reachable states lie on a manifold of dimension <= 2·d_a + 1.
        object.__setattr__(self, "intrinsic_rank", 2 * self.act_dim + 1)

    @property
    def all_params(self) -> dict[str, float]:
        """`params` and `optional_params`: every parameter name a schedule accepts, with its default."""
        return self.params | self.optional_params

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


def list_tasks() -> list[str]:
    """Task names: ["hopper", "walker2d", "ant", "humanoid"]."""
    return list(TASKS)


def get_task(name: str, version: str = "v5") -> TaskSpec:
    """The `TaskSpec` of `name` on Gymnasium's `version` models (its `gym_id` and `obs_dim`); a
    one-line `UsageError` lists the tasks or versions if either is unknown."""
    key = name.strip().lower() if isinstance(name, str) else name
    if key not in TASKS:
        check_choice("task", name, TASKS)
    check_choice("model version", version, VERSIONS)
    spec = TASKS[key]
    if version == spec.version:
        return spec
    return replace(
        spec, gym_id=spec.gym_id.replace("-v5", "-v4"), obs_dim=spec.v4_obs_dim, version="v4"
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
