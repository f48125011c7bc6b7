"""``swarm analyze anchors SCENARIO``: the paper's section V-D study (anchor placement -> steady-state
position covariance -> steady-state probabilities of Algorithm 1's chain), with an optimised anchor layout."""

from __future__ import annotations

import argparse
from pathlib import Path

from swarm.args import add_scenario_args, load_from_args, positive_float
from swarm.errors import ConfigError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("analyze", help="offline analyses of a scenario (section V-D anchor placement)")
    kinds = p.add_subparsers(dest="analysis", metavar="ANALYSIS", required=True)
    a = kinds.add_parser(
        "anchors",
        help="steady-state covariance and ALIGN probability over a grid; optimised anchor layout",
        description=__doc__,
    )
    add_scenario_args(a)
    a.add_argument(
        "--out", type=Path, default=None, metavar="DIR", help="output directory (default anchors-SCENARIO)"
    )
    a.add_argument(
        "--spacing", type=positive_float("--spacing"), default=None, help="grid spacing [m] (default 0.1)"
    )
    a.add_argument(
        "--margin", type=float, default=None, help="grid margin around the vehicles [m] (default 0.5)"
    )
    a.add_argument("--no-optimise", action="store_true", help="skip the anchor-layout optimisation")
    a.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from swarm.analysis.anchor_report import run_study
    from swarm.analysis.anchors import AnchorStudyParams

    sc = load_from_args(args)
    kw = {}
    if args.spacing is not None:
        kw["spacing_m"] = args.spacing
    if args.margin is not None:
        if not args.margin >= 0:
            raise ConfigError(f"--margin must be a non-negative number, got {args.margin}")
        kw["margin_m"] = args.margin
    params = AnchorStudyParams(**kw)
    out = args.out if args.out is not None else Path(f"anchors-{sc.name}")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {str(out)!r}: cannot create it: {exc.strerror or exc}") from None
    rec = run_study(sc, params, out, optimise=not args.no_optimise)
    for lay in ("paper", "optimised"):
        if lay in rec:
            b, w = rec[lay]["best"], rec[lay]["worst"]
            print(
                f"{lay:<9} max sigma_pos best {1000 * b['sigma_pos_max_m']:.2f} mm "
                f"(pi2 {b['pi_align']:.3f}), "
                f"worst {1000 * w['sigma_pos_max_m']:.2f} mm (pi2 {w['pi_align']:.3f}) at {w['point_m']}"
            )
    if "gain" in rec:
        print(f"optimised layout: worst-case pi2 {round(rec['gain']['worst_pi_align'], 3) + 0.0:+.3f}")
    print(f"written to {out}/anchors.md ({rec['wall_s']:.1f} s)")
    return 0
