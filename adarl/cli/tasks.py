"""`adarl tasks`: the tasks, their parameters and defaults, schedule formulas, intrinsic ranks,
model versions and the masses at the nominal point under each physics."""

from __future__ import annotations

import json

HELP = (
    "List the tasks, their physical parameters, dynamics schedules, intrinsic ranks, model "
    "versions, nominal masses under each physics and where the device (MJX) task differs."
)


def add_arguments(parser) -> None:
    parser.add_argument("names", nargs="*", metavar="TASK", help="tasks to show (default: all)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")


def run(args) -> int:
    from adarl.device.tasks import DIFFERENCES
    from adarl.envs.params import PARAMS
    from adarl.envs.tasks import get_task, list_tasks

    tasks = [get_task(name) for name in (args.names or list_tasks())]
    masses = {t.name: _masses(t.name) for t in tasks}
    if args.json:
        out = [
            _as_dict(t)
            | {
                "nominal_masses": masses[t.name],
                "adarl_budget": _adarl_budget(t.name),
                "device": DIFFERENCES[t.name],
            }
            for t in tasks
        ]
        print(json.dumps(out, indent=2, ensure_ascii=False))
        return 0
    for i, task in enumerate(tasks):
        if i:
            print()
        print(
            f"{task.name} ({task.gym_id}): obs {task.obs_dim}, act {task.act_dim}, "
            f"intrinsic rank 2·{task.act_dim}+1 = {task.intrinsic_rank}"
        )
        print("  parameters (Gymnasium default):")
        for name, default in task.params.items():
            p = PARAMS[name]
            print(f"    {name:<15} {default:<7g} {p.unit:<8} {p.meaning}; allowed: {p.allowed}")
        if task.optional_params:
            print("  optional parameters (set only when given; the robustness suites use them):")
            for name, default in task.optional_params.items():
                p = PARAMS[name]
                print(f"    {name:<20} {default:<7.4g} {p.unit:<3} {p.meaning}")
        for kind, formulas in task.formulas.items():
            text = ", ".join(f"{p} = {f}" for p, f in formulas.items())
            print(f"  {kind + ':':<9} {text}")
        nominal = ", ".join(f"{p} = {s.center:g}" for p, s in task.schedules["paper"].items())
        print(f"  {'nominal:':<9} {nominal}")
        ranges = ", ".join(
            f"{p} ~ U[{s.low:g}, {s.high:g}]" for p, s in task.schedules["paper"].items()
        )
        print(f"  {'uniform:':<9} {ranges}  (i = episode index)")
        if task.stiffness_joints:
            print(
                f"  stiffness acts on {', '.join(task.stiffness_joints)} "
                f"(spring reference {task.spring_ref:g} rad)"
            )
        if task.medium:
            density, viscosity = task.medium
            print(
                f"  medium: air, density {density:g} kg/m^3, viscosity {viscosity:g} Pa s "
                "(so wind acts; it also adds drag at zero wind; not in 'default')"
            )
        v4 = get_task(task.name, "v4")
        print(
            f"  model versions: v5 {task.gym_id} obs {task.obs_dim} (default), "
            f"v4 {v4.gym_id} obs {v4.obs_dim}"
        )
        _print_masses(masses[task.name], "torso_length" in task.varied)
        print(f"  {_adarl_budget(task.name)}")
        print(f"  device task (MJX, adarl.device): {DIFFERENCES[task.name]}")
    return 0


def _adarl_budget(task: str) -> str:
    """AdaRL's default budget on the task and how many truncations it makes."""
    from adarl.algos import registry, schedule

    adarl = registry.get("adarl")
    budget = adarl.task_defaults[task]
    config = adarl.config_class(**adarl.defaults, task=task, **budget)
    return (
        f"adarl default budget: {budget['total_steps']:,} steps, d_t = "
        f"{budget['truncate_every']:,} gradient steps ({schedule.n_truncations(config)} truncations)"
    )


def _masses(task: str) -> dict[str, dict[str, float]]:
    """{physics: {body: kg}} at the nominal point (the same on v4 and v5 models)."""
    from adarl.envs.model import nominal_masses
    from adarl.envs.tasks import PHYSICS

    return {physics: nominal_masses(task, physics) for physics in PHYSICS}


def _print_masses(masses: dict[str, dict[str, float]], lengths_vary: bool) -> None:
    consistent, ompo = masses["consistent"], masses["ompo"]
    totals = f"{sum(consistent.values()):.3f} / {sum(ompo.values()):.3f}"
    print("  masses at the nominal point (kg), physics consistent / ompo:")
    if consistent == ompo:
        why = (
            "the nominal lengths are Gymnasium's; other lengths differ"
            if lengths_vary
            else "no length varies"
        )
        print(f"    total {totals}: every body as in Gymnasium's model under both ({why})")
        return
    bodies = ", ".join(f"{b} {consistent[b]:.3f} / {ompo[b]:.3f}" for b in consistent)
    print(f"    {bodies}; total {totals}")


def _as_dict(task) -> dict:
    return {
        "name": task.name,
        "gym_id": task.gym_id,
        "obs_dim": task.obs_dim,
        "act_dim": task.act_dim,
        "intrinsic_rank": task.intrinsic_rank,
        "params": dict(task.params),
        "optional_params": dict(task.optional_params),
        "formulas": task.formulas,
        "nominal": {p: s.center for p, s in task.schedules["paper"].items()},
        "uniform": {p: [s.low, s.high] for p, s in task.schedules["paper"].items()},
        "stiffness_joints": list(task.stiffness_joints),
        "spring_ref": task.spring_ref,
        "medium": None
        if task.medium is None
        else {"density": task.medium[0], "viscosity": task.medium[1]},
    }
