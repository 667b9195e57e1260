"""`adarl tasks`: every task adarl can make. The paper's four (their parameters and defaults,
schedule formulas, intrinsic ranks, model versions, the masses at the nominal point under each
physics); then every registered Gymnasium MuJoCo id (d_a, 2·d_a+1, time limit, the generic
parameters; a named one also lists the elements its XML names, `KIND:NAME.ATTR[i]`); ids a user's
`--env-module` registers too. Each Gymnasium env is built once to read its sizes."""

from __future__ import annotations

import json
import textwrap

HELP = (
    "List the tasks, their physical parameters, dynamics schedules, intrinsic ranks, model "
    "versions, nominal masses under each physics and where the device (MJX) task differs; every "
    "Gymnasium MuJoCo id too (a named one with its addressable elements)."
)
#: Gymnasium's own MuJoCo envs: the registry entries whose entry point is in this package.
GYMNASIUM_MUJOCO = "gymnasium.envs.mujoco."
WIDTH = 100


def add_arguments(parser) -> None:
    parser.add_argument(
        "names", nargs="*", metavar="TASK",
        help="tasks to show (default: all): hopper, walker2d, ant, humanoid or a Gymnasium id "
        "such as HalfCheetah-v5 (shown with its addressable elements)",
    )  # fmt: skip
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.add_argument(
        "--env-module", default="", metavar="PKG",
        help="import PKG first: the Gymnasium ids it registers are listed (or name one)",
    )  # fmt: skip
    parser.add_argument(
        "--env-kwargs", default="", metavar="K=V,...",
        help="keywords of a named Gymnasium id's env, e.g. xml_file=my_robot.xml",
    )  # fmt: skip


def run(args) -> int:
    from adarl.envs.tasks import TASKS, get_task, name_env_module
    from adarl.errors import UsageError

    name_env_module(args.env_module)  # yours: adarl may import it
    own = registered_by(args.env_module)  # imports it: a failure is one line
    if args.env_kwargs and not args.names:
        raise UsageError(
            f"--env-kwargs {args.env_kwargs!r} applies to a named Gymnasium id; allowed: "
            "adarl tasks ID --env-kwargs K=V"
        )
    names = args.names or [*TASKS, *gymnasium_ids(), *own]
    tasks, unavailable = [], {}
    for name in names:
        paper = not args.names and str(name).strip().lower() in TASKS  # a named one: checked
        options = {} if paper else {"env_kwargs": args.env_kwargs, "env_module": args.env_module}
        try:
            tasks.append(get_task(name, **options))
        except Exception as exc:  # noqa: BLE001 - listing: a Gymnasium id this install cannot make
            if args.names:
                if isinstance(exc, UsageError):
                    raise
                raise UsageError(f"task {name!r} cannot be made here: {_first_line(exc)}") from None
            unavailable[name] = _first_line(exc)
    detail = bool(args.names)
    if args.json:
        out = [_json(t, detail) for t in tasks]
        out += [{"name": n, "kind": "unavailable", "why": why} for n, why in unavailable.items()]
        print(json.dumps(out, indent=2, ensure_ascii=False))
        return 0
    paper_tasks = [t for t in tasks if t.paper]
    others = [t for t in tasks if not t.paper]
    for i, task in enumerate(paper_tasks):
        if i:
            print()
        _print_paper(task)
    if others and not detail:
        if paper_tasks:
            print()
        _print_table(others, unavailable)
    elif others:
        for i, task in enumerate(others):
            if i or paper_tasks:
                print()
            _print_gym(task)
    return 0


def gymnasium_ids() -> list[str]:
    """Every registered id of Gymnasium's own MuJoCo envs (v4 and v5 models)."""
    import gymnasium

    return sorted(
        name
        for name, spec in gymnasium.registry.items()
        if isinstance(spec.entry_point, str) and spec.entry_point.startswith(GYMNASIUM_MUJOCO)
    )


def registered_by(module: str) -> list[str]:
    """The Gymnasium ids `module` registers (none without one): those it adds to the registry
    when imported, and those whose entry point is in it (it may have been imported already)."""
    if not module:
        return []
    import gymnasium

    from adarl.envs.tasks import import_env_module

    before = set(gymnasium.registry)
    import_env_module(module)
    ids = set(gymnasium.registry) - before
    for name, spec in gymnasium.registry.items():
        entry = spec.entry_point
        where = (
            entry.partition(":")[0] if isinstance(entry, str) else getattr(entry, "__module__", "")
        )
        if where == module or str(where).startswith(module + "."):
            ids.add(name)
    return sorted(ids)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}"


def _print_paper(task) -> None:
    from adarl.device.tasks import DIFFERENCES
    from adarl.envs.params import PARAMS
    from adarl.envs.tasks import get_task

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
    _print_schedules(task)
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
    _print_masses(_masses(task.name), "torso_length" in task.varied)
    print(f"  addressed parameters too: KIND:NAME.ATTR[i] (adarl tasks {task.gym_id} lists them)")
    print(f"  {_adarl_budget(task.name)}")
    print(f"  device task (MJX, adarl.device): {DIFFERENCES[task.name]}")


def _print_schedules(task) -> None:
    for kind, formulas in task.formulas.items():
        text = ", ".join(f"{p} = {f}" for p, f in formulas.items())
        print(f"  {kind + ':':<9} {text}")
    paper = task.schedules.get("paper", {})
    nominal = ", ".join(f"{p} = {s.center:g}" for p, s in paper.items())
    print(f"  {'nominal:':<9} {nominal}")
    ranges = ", ".join(f"{p} ~ U[{s.low:g}, {s.high:g}]" for p, s in paper.items())
    print(f"  {'uniform:':<9} {ranges}  (i = episode index)")


def _print_table(tasks, unavailable: dict[str, str]) -> None:
    """One line per Gymnasium id, after what their generic parameters are."""
    from adarl.envs.params import param_info
    from adarl.envs.tasks import TASKS

    print(
        "Gymnasium tasks (--task ID; `adarl tasks ID` lists the elements its XML names, "
        "KIND:NAME.ATTR[i]):"
    )
    mujoco = [t for t in tasks if t.kind == "mujoco"]
    if mujoco:
        print("  generic parameters of every MuJoCo task (default: the model unchanged):")
        for name, default in mujoco[0].all_params.items():
            p = param_info(name)
            value = "|g|" if name == "gravity" else f"{default:g}"
            label = f"{name} (optional)" if name in mujoco[0].optional_params else name
            print(f"    {label:<15} {value:<4} {p.unit:<6} {p.meaning}; allowed: {p.allowed}")
        _print_schedules(mujoco[0])
    print(f"  {'id':<27} {'obs':>4} {'act':>4} {'2·d_a+1':>8} {'steps':>6} {'|g|':>6}  physics")
    for task in tasks:
        gravity = f"{task.params['gravity']:.4g}" if "gravity" in task.params else "-"
        physics = "varies" if task.kind == "mujoco" else "fixed (not a MujocoEnv)"
        print(
            f"  {task.name:<27} {task.obs_dim:>4} {task.act_dim:>4} {task.intrinsic_rank:>8} "
            f"{task.max_episode_steps:>6} {gravity:>6}  {physics}"
        )
    for name, why in unavailable.items():
        print(f"  {name:<27} not available here: {why}")
    robots = [t.name for t in tasks if t.gym_id.split("-v")[0].lower() in TASKS]
    if robots:
        print(
            textwrap.fill(
                f"{', '.join(robots)}: the paper's robots as generic tasks; hopper, walker2d, "
                "ant and humanoid (above) are the paper's tasks, with their own parameters and "
                "schedules.",
                WIDTH,
                initial_indent="  ",
                subsequent_indent="  ",
            )
        )


def _print_gym(task) -> None:
    from adarl.envs.params import param_info

    what = "Gymnasium MuJoCo task" if task.kind == "mujoco" else "Gymnasium task, fixed dynamics"
    print(
        f"{task.name} ({what}): obs {task.obs_dim}, act {task.act_dim}, intrinsic rank "
        f"2·{task.act_dim}+1 = {task.intrinsic_rank}, time limit {task.max_episode_steps} steps"
    )
    if task.xml_path:
        print(f"  model: {task.xml_path}")
    if task.env_module or task.env_kwargs:
        kwargs = ", ".join(f"{k}={v}" for k, v in task.env_kwargs)
        print(f"  env-module {task.env_module or '-'}, env-kwargs {kwargs or '-'}")
    if task.kind != "mujoco":
        print("  no physical parameters (the env is not built on Gymnasium's MujocoEnv)")
        print(f"  {_device_line(task)}")
        return
    print("  parameters (default: the model unchanged):")
    for name, default in task.all_params.items():
        p = param_info(name)
        label = f"{name} (optional)" if name in task.optional_params else name
        print(f"    {label:<15} {default:<7g} {p.unit:<6} {p.meaning}; allowed: {p.allowed}")
    _print_schedules(task)
    print("  addressable elements (KIND:NAME.ATTR[i]; absolute values, default the model's own):")
    for kind, attrs, names in _elements(task):
        head = f"    {kind:<9} {attrs}: "
        body = ", ".join(names) if names else "(none named; actuator_scale scales them all)"
        print(textwrap.fill(body, WIDTH, initial_indent=head, subsequent_indent=" " * 6))
    print(f"  {_adarl_budget(task.name)}")
    print(f"  {_device_line(task)}")


def _elements(task) -> list[tuple[str, str, list[str]]]:
    """(kind, its attributes as text, the element names; bodies with their masses in kg)."""
    from adarl.envs.elements import address_default, element_names
    from adarl.envs.params import ATTRS

    out = []
    for kind, names in element_names(task.xml_path).items():
        attrs = ", ".join(
            f".{a}" + (f"[0-{info.size - 1}]" if info.size > 1 else "")
            for a, info in ATTRS[kind].items()
        )
        if kind == "body":
            attrs += " (kg)"
            names = [f"{n} {address_default(task.xml_path, f'body:{n}.mass'):.4g}" for n in names]
        out.append((kind, attrs, names))
    return out


def _device_line(task) -> str:
    return (
        "device task (MJX, adarl.device): none; --backend device runs hopper, walker2d, ant, "
        "humanoid"
    )


def _json(task, detail: bool) -> dict:
    """A task as JSON: the paper's as before (with their masses, budget and device line), a
    Gymnasium id with its kind, time limit and (mujoco) the elements its XML names."""
    if task.paper:
        from adarl.device.tasks import DIFFERENCES

        return (
            _as_dict(task)
            | {"kind": "paper"}
            | {
                "nominal_masses": _masses(task.name),
                "adarl_budget": _adarl_budget(task.name),
                "device": DIFFERENCES[task.name],
            }
        )
    out = _as_dict(task) | {
        "kind": task.kind,
        "max_episode_steps": task.max_episode_steps,
        "env_kwargs": dict(task.env_kwargs),
        "env_module": task.env_module,
        "xml_path": task.xml_path or None,
        "device": None,
    }
    if task.kind == "mujoco" and detail:
        from adarl.envs.elements import element_names

        out["elements"] = element_names(task.xml_path)
    return out


def _adarl_budget(task: str) -> str:
    """AdaRL's default budget on the task and how many truncations it makes."""
    from adarl.algos import registry, sac_config, schedule
    from adarl.algos.config import follows_budget

    adarl = registry.get("adarl")
    budget = dict(adarl.task_defaults.get(task, adarl.task_defaults.get(registry.OTHER_TASKS, {})))
    config = adarl.config_class(**adarl.defaults, task=task, **budget)
    budget.setdefault("total_steps", config.total_steps)
    budget.setdefault("truncate_every", config.truncate_every)
    line = (
        f"adarl default budget: {budget['total_steps']:,} steps, d_t = "
        f"{budget['truncate_every']:,} gradient steps ({schedule.n_truncations(config)} truncations)"
    )
    rules = sac_config.budget_rules("adarl") if follows_budget(task) else {}
    if rules:  # outside the paper's four: the fields that follow --total-steps (issue 62)
        said = "; ".join(f"{field} = {rule.text}" for field, rule in rules.items())
        line += f"; with another --total-steps, unless given: {said}"
    return line


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
        "nominal": {p: s.center for p, s in task.schedules.get("paper", {}).items()},
        "uniform": {p: [s.low, s.high] for p, s in task.schedules.get("paper", {}).items()},
        "stiffness_joints": list(task.stiffness_joints),
        "spring_ref": task.spring_ref,
        "medium": None
        if task.medium is None
        else {"density": task.medium[0], "viscosity": task.medium[1]},
    }
