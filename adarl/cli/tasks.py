"""`adarl tasks`: the tasks, their parameters and defaults, schedule formulas and intrinsic ranks."""

from __future__ import annotations

import json

HELP = "List the tasks, their physical parameters, dynamics schedules and intrinsic ranks."


def add_arguments(parser) -> None:
    parser.add_argument("names", nargs="*", metavar="TASK", help="tasks to show (default: all)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")


def run(args) -> int:
    from adarl.envs.params import PARAMS
    from adarl.envs.tasks import get_task, list_tasks

    tasks = [get_task(name) for name in (args.names or list_tasks())]
    if args.json:
        print(json.dumps([_as_dict(t) for t in tasks], indent=2, ensure_ascii=False))
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
    return 0


def _as_dict(task) -> dict:
    return {
        "name": task.name,
        "gym_id": task.gym_id,
        "obs_dim": task.obs_dim,
        "act_dim": task.act_dim,
        "intrinsic_rank": task.intrinsic_rank,
        "params": dict(task.params),
        "formulas": task.formulas,
        "nominal": {p: s.center for p, s in task.schedules["paper"].items()},
        "uniform": {p: [s.low, s.high] for p, s in task.schedules["paper"].items()},
        "stiffness_joints": list(task.stiffness_joints),
        "spring_ref": task.spring_ref,
        "medium": None
        if task.medium is None
        else {"density": task.medium[0], "viscosity": task.medium[1]},
    }
