"""`adarl ranks RUN_DIR`: the rank history of every bottleneck, per seed, as a table."""

from __future__ import annotations

import argparse
from pathlib import Path

from adarl.errors import UsageError

HELP = "print the rank history (per truncation, layer and seed) of a rank-adaptive run"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", metavar="RUN_DIR", help="a run folder of --algo adarl")
    parser.add_argument("--layer", default=None, help="only this bottleneck (e.g. actor_1)")


def rank_table(run_dir: Path, layer: str | None = None) -> list[str]:
    """Lines of a table: step, layer, then one column per seed with `old→new` ranks; a cut the
    retain clause refused shows as `old→old (retained r_c, err e)`."""
    from adarl.runs.folder import load_config
    from adarl.runs.layout import TRUNCATIONS_CSV
    from adarl.runs.logs import read_csv

    config = load_config(run_dir)
    path = run_dir / TRUNCATIONS_CSV
    if not path.exists():
        raise UsageError(
            f"{run_dir} has no truncations.csv (algo {config.get('algo')!r} does "
            "not adapt its rank)"
        )
    rows = read_csv(path)
    if layer is not None:
        layers = sorted({r["layer"] for r in rows})
        if layer not in layers:
            raise UsageError(f"unknown layer {layer!r}; this run has: {', '.join(layers)}")
        rows = [r for r in rows if r["layer"] == layer]
    seeds = [int(s) for s in config["seeds"]]
    table: dict[tuple[int, str], dict[int, str]] = {}
    for line, r in enumerate(rows, start=2):  # line 1: the header
        try:
            cell = f"{int(r['old_rank'])}→{int(r['new_rank'])}"
            if r.get("decision") == "retained":  # runs before the retain clause have no column
                cell += f" (retained {int(r['candidate_rank'])}, err {float(r['error']):.3g})"
            table.setdefault((int(r["step"]), str(r["layer"])), {})[int(r["seed"])] = cell
        except (KeyError, TypeError, ValueError) as exc:
            raise UsageError(
                f"{path} line {line} is not a truncation row ({type(exc).__name__}: {exc}); "
                "allowed: integer step, seed and ranks (docs/run-format.md)"
            ) from None
    header = ["step", "layer", *[f"seed {s}" for s in seeds]]
    body = [
        [str(step), name, *[cells.get(s, "") for s in seeds]]
        for (step, name), cells in sorted(table.items())
    ]
    widths = [max(len(row[i]) for row in [header, *body]) for i in range(len(header))]
    fmt = lambda row: "  ".join(c.rjust(w) for c, w in zip(row, widths))  # noqa: E731
    lines = [fmt(header), fmt(["-" * w for w in widths])] + [fmt(row) for row in body]
    if not body:
        lines.append("(no truncation yet)")
    retained = sum(r.get("decision") == "retained" for r in rows)
    if retained:
        lines.append(f"{retained} proposed cut(s) retained by the retain clause")
    return lines


def run(args: argparse.Namespace) -> int:
    for line in rank_table(Path(args.run_dir), args.layer):
        print(line)
    return 0
