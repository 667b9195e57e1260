"""`adarl theory --out DIR`: check the paper's bias–variance theorem (Theorem 1) numerically.

Writes into DIR (created if needed; files replaced atomically):

- ``synthetic.csv``, ``mdp.csv``: one row per (ε, r), columns ``adarl.theory.synthetic.COLUMNS``
- ``picard.csv``: singular values, ``|u_iᵀb°|`` and the Picard limit of both ground-truth systems
- ``summary.json``: parameters, ground truth, best rank and bound check per ε
- ``{synthetic,mdp}_error.{png,pdf}``, ``{synthetic,mdp}_bound.{png,pdf}``, ``picard.{png,pdf}``

See docs/theory.md.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from adarl.errors import UsageError

HELP = "check the bias-variance theorem numerically (synthetic + tabular MDP); CSVs and figures"

DEFAULT_EPS = [0.0, 0.01, 0.1, 0.3, 0.5]
MAX_D = 512
MAX_DRAWS = 100_000
MAX_STATES = 256


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `adarl theory`."""
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    g = parser.add_argument_group("synthetic system")
    g.add_argument("--d", type=int, default=16, help="dimension d of θ (default 16)")
    g.add_argument("--r0", type=int, default=4, help="rank r° of the true system (default 4)")
    g.add_argument("--p", type=float, default=2.0, help="Picard exponent p > 1 (default 2)")
    g.add_argument(
        "--kappa", type=float, default=10.0, help="σ°_1 / σ°_r° of the true system (default 10)"
    )
    g.add_argument(
        "--eps",
        type=float,
        nargs="+",
        default=DEFAULT_EPS,
        metavar="EPS",
        help="uncertainty radii in [0, 1] (default: 0 0.01 0.1 0.3 0.5)",
    )
    g.add_argument("--draws", type=int, default=200, help="perturbed systems per ε (default 200)")
    g.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    m = parser.add_argument_group("tabular MDP")
    m.add_argument("--mdp-states", type=int, default=8, help="number of states (default 8)")
    m.add_argument("--mdp-actions", type=int, default=2, help="number of actions (default 2)")
    m.add_argument(
        "--mdp-core",
        type=int,
        default=2,
        help="states reachable under the true kernel; r° = core × actions (default 2)",
    )
    m.add_argument("--mdp-d", type=int, default=10, help="feature dimension (default 10)")
    m.add_argument("--gamma", type=float, default=0.9, help="discount in [0, 1) (default 0.9)")
    m.add_argument("--skip-mdp", action="store_true", help="run the synthetic experiment only")


def _finite(x: float) -> bool:
    return isinstance(x, int | float) and math.isfinite(x)


def validate(args: argparse.Namespace) -> None:
    """Raise a one-line ``UsageError`` for the first bad flag; nothing is written before this."""
    if not 1 <= args.d <= MAX_D:
        raise UsageError(f"--d {args.d} is not allowed; use 1 <= --d <= {MAX_D}")
    if not 1 <= args.r0 <= args.d:
        raise UsageError(f"--r0 {args.r0} is not allowed; use 1 <= --r0 <= --d = {args.d}")
    if not (_finite(args.p) and args.p > 1):
        raise UsageError(f"--p {args.p} is not allowed; the Picard exponent must be > 1")
    if not (_finite(args.kappa) and args.kappa >= 1):
        raise UsageError(f"--kappa {args.kappa} is not allowed; use a finite --kappa >= 1")
    for e in args.eps:
        if not (_finite(e) and 0 <= e <= 1):
            raise UsageError(f"--eps {e} is not allowed; radii must lie in [0, 1]")
    if not 1 <= args.draws <= MAX_DRAWS:
        raise UsageError(f"--draws {args.draws} is not allowed; use 1 <= --draws <= {MAX_DRAWS}")
    if args.seed < 0:
        raise UsageError(f"--seed {args.seed} is not allowed; use a seed >= 0")
    if not args.skip_mdp:
        n_s, n_a, core, d = args.mdp_states, args.mdp_actions, args.mdp_core, args.mdp_d
        if not 2 <= n_s <= MAX_STATES:
            raise UsageError(
                f"--mdp-states {n_s} is not allowed; use 2 <= --mdp-states <= {MAX_STATES}"
            )
        if not 1 <= n_a <= 16:
            raise UsageError(f"--mdp-actions {n_a} is not allowed; use 1 <= --mdp-actions <= 16")
        if not 1 <= core < n_s:
            raise UsageError(
                f"--mdp-core {core} is not allowed; use 1 <= --mdp-core < --mdp-states = {n_s}"
            )
        if not core * n_a <= d <= n_s * n_a:
            raise UsageError(
                f"--mdp-d {d} is not allowed; use --mdp-core*--mdp-actions = {core * n_a} <= "
                f"--mdp-d <= --mdp-states*--mdp-actions = {n_s * n_a}"
            )
        if not (_finite(args.gamma) and 0 <= args.gamma < 1):
            raise UsageError(
                f"--gamma {args.gamma} is not allowed; the discount must lie in [0, 1)"
            )
    from adarl.files import check_writable_dir

    check_writable_dir(args.out)  # the same check as every command's --out


def run(args: argparse.Namespace) -> int:
    """Validate, run both experiments, write CSVs, figures and the summary into ``--out``."""
    validate(args)
    import numpy as np

    from adarl.theory import mdp as mdp_mod
    from adarl.theory import report
    from adarl.theory.synthetic import run_synthetic

    eps = tuple(float(e) for e in args.eps)
    truth, sweeps = run_synthetic(
        args.d, args.r0, args.p, eps, args.draws, kappa=args.kappa, seed=args.seed
    )
    norm_theta = float(np.linalg.norm(truth.theta))
    summary = {
        "command": "adarl theory",
        "synthetic": {
            "params": {
                "d": args.d,
                "r0": args.r0,
                "p": args.p,
                "kappa": args.kappa,
                "eps": list(eps),
                "draws": args.draws,
                "seed": args.seed,
            },
            "perturbation": "mixture: A_P = (1-eps) A° + eps C, b_P = (1-eps) b° + eps C theta_N",
            "lipschitz_term": "L * eps * ||theta°|| / sigma_{P,r} with L = 1",
            "sigma0": truth.sigma,
            "picard_coef": np.abs(truth.coef),
            "theta0_norm": norm_theta,
            "per_eps": report.sweep_summary(sweeps),
            # error > var + bias + L·ε·‖θ°‖/σ°_{r°}: the O(Lε) term with an r-free constant
            "r_independent_lipschitz_violations": [
                int(
                    np.sum(
                        sw.error
                        > sw.var_term
                        + sw.bias_term
                        + sw.eps * norm_theta / truth.sigma[args.r0 - 1]
                        + 1e-12
                    )
                )
                for sw in sweeps
            ],
        },
    }
    picard = [("synthetic", truth.sigma, np.abs(truth.coef), args.r0, args.p, 1.0)]
    mdp_result = None
    if not args.skip_mdp:
        mdp_result = mdp_mod.run_mdp(
            args.mdp_states,
            args.mdp_actions,
            args.mdp_core,
            args.mdp_d,
            eps,
            args.draws,
            p=args.p,
            gamma=args.gamma,
            seed=args.seed,
        )
        mtruth, msweeps = mdp_result
        summary["mdp"] = {
            "params": {
                "n_states": args.mdp_states,
                "n_actions": args.mdp_actions,
                "n_core": args.mdp_core,
                "d": args.mdp_d,
                "gamma": args.gamma,
                "n_latent": mtruth.mdp.n_latent,
            },
            "r0": mtruth.r0,
            "sigma0": mtruth.sigma,
            "picard_coef": mtruth.coef,
            "picard_p_with_C1": mtruth.picard_p,
            "picard_C_at_p": mtruth.picard_c,
            "theta0_norm": float(np.linalg.norm(mtruth.theta)),
            "max_lipschitz_ratio": [float(sw.extra["lipschitz_ratio"].max()) for sw in msweeps],
            "per_eps": report.sweep_summary(msweeps),
        }
        picard.append(("MDP", mtruth.sigma, mtruth.coef, mtruth.r0, args.p, mtruth.picard_c))

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    written = report.write_sweep(
        out,
        "synthetic",
        sweeps,
        args.r0,
        f"synthetic: d = {args.d}, r° = {args.r0}, p = {args.p:g}, {args.draws} draws per ε",
    )
    if mdp_result is not None:
        mtruth, msweeps = mdp_result
        written += report.write_sweep(
            out,
            "mdp",
            msweeps,
            mtruth.r0,
            f"tabular MDP: {args.mdp_states} states × {args.mdp_actions} actions, "
            f"d = {args.mdp_d}, r° = {mtruth.r0}, γ = {args.gamma:g}, {args.draws} draws per ε",
        )
    rows = [row for sys in picard for row in report.picard_rows(*sys)]
    path = out / "picard.csv"
    report.atomic_write_bytes(path, report.csv_text(rows, report.PICARD_COLUMNS).encode())
    written.append(path)
    written += report.save_figure(report.plot_picard(picard), out, "picard")
    written.append(report.write_json(out / "summary.json", summary))

    for name in ("synthetic", "mdp"):
        if name in summary:
            best = ", ".join(
                f"ε={row['eps']:g}: r={row['best_r']}" for row in summary[name]["per_eps"]
            )
            r0 = args.r0 if name == "synthetic" else summary["mdp"]["r0"]
            print(f"{name}: r° = {r0}; best rank by mean error: {best}")
    print(f"wrote {len(written)} files to {out}")
    return 0
