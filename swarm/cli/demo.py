"""``swarm demo``: the first thing a newcomer runs (``make demo``), on embedded defaults.

Today: two dockings of the paper's scenario in-process (fixed radii and Algorithm 1), with their plots
written to ``artifacts/``, then the pose estimator of paper section IV over a seeded Monte Carlo, both
structures, with and without NLOS outliers (accuracy, consistency, rejections).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import chi2

from swarm.args import positive_int, seed
from swarm.core.estimator import EstimatorParams, Structure
from swarm.sim.estimation import EstimationScenario, run_estimation


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the main demonstration on embedded defaults")
    p.add_argument(
        "--runs", type=positive_int("--runs"), default=50, help="estimator Monte Carlo runs (default 50)"
    )
    p.add_argument("--seed", type=seed, default=0, help="root seed (default 0)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from swarm.cli.sim import print_summary
    from swarm.scenario import load_scenario
    from swarm.sim.docking import run_docking
    from swarm.sim.plot import plot_run

    sc = load_scenario("docking")
    out = Path("artifacts")
    out.mkdir(exist_ok=True)
    print("TPODS swarm demo 1/2: the paper's docking scenario, in-process, both switching policies\n")
    for policy in ("fixed", "mdp"):
        res = run_docking(sc, policy, args.seed)
        print_summary(res)
        png = out / f"demo-{policy}.png"
        plot_run(res, sc, png)
        print(f"  plot: {png}\n")
    print("TPODS swarm demo 2/2: pose estimator (paper sec. IV) on the paper's sensors")
    print(
        f"{args.runs} seeded runs x 30 s: gyro 100 Hz (VN-100), UWB 50 Hz round robin over 4 anchors, 2 cm,"
    )
    print("AHRS 10 Hz; 'NLOS' adds 5 % long outliers (+0.3 .. +1.5 m).\n")
    header = (
        f"{'structure':<11} {'outliers':<8} {'pos RMS':>9} {'att RMS':>9} {'ANEES':>7} {'95% bounds':>14}"
    )
    print(header + f" {'outliers rejected':>18} {'clean rejected':>15} {'wall':>6}")
    for structure in Structure:
        for p_out in (0.0, 0.05):
            sc = EstimationScenario(runs=args.runs, seed=args.seed, ahrs_every=10, outlier_probability=p_out)
            t0 = time.perf_counter()
            r = run_estimation(EstimatorParams(structure=structure), sc)
            wall = time.perf_counter() - t0
            lo, hi = chi2.ppf([0.025, 0.975], 9 * args.runs) / args.runs
            out = f"{r.outlier_rejected}/{r.outlier_total}" if r.outlier_total else "-"
            pos_cm = np.sqrt(np.mean(r.pos_err_m**2)) * 100
            att_rad = np.sqrt(np.mean(r.att_err_rad**2))
            print(
                f"{structure.value:<11} {'NLOS' if p_out else 'clean':<8} "
                f"{pos_cm:>7.2f}cm {att_rad:>7.4f}rd "
                f"{r.nees.mean():>7.2f} [{lo:5.2f}, {hi:5.2f}] {out:>18} "
                f"{r.clean_rejected:>7}/{r.clean_total:<7} {wall:>5.1f}s"
            )
    return 0
