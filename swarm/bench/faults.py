"""``swarm bench faults``: a Monte Carlo campaign of the issue-7 fault set (``docking-faults.toml``:
10 % NLOS outliers, a 5 s UWB dropout from the start of REORIENT, the camera lost in ALIGN), 200 runs of
each policy on the ordinary campaign runner (2 workers), reduced by :mod:`swarm.montecarlo.faults`: how
many runs docked, aborted safely or failed (keep-out violation or collision), and the chaser's position
NEES outside the dropout windows against its chi-square 95 % bounds.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

FULL_RUNS = 200
QUICK_RUNS = 10
WORKERS = 2


def run(quick: bool = False) -> dict:
    from swarm.montecarlo.campaign import CampaignSpec, read_runs, read_trajectories, run_campaign
    from swarm.montecarlo.faults import fault_summary
    from swarm.scenario import load_scenario

    sc = load_scenario("docking-faults")
    runs = QUICK_RUNS if quick else FULL_RUNS
    with tempfile.TemporaryDirectory(prefix="swarm-bench-faults-") as tmp:
        out = Path(tmp) / "c"
        t0 = time.perf_counter()
        run_campaign(CampaignSpec(sc, ("fixed", "mdp"), runs, 0), out, workers=WORKERS, progress=False)
        wall = time.perf_counter() - t0
        rows, trajs = read_runs(out), read_trajectories(out)
    return {
        "scenario": sc.name,
        "runs": runs,
        "root_seed": 0,
        "workers": WORKERS,
        "wall_s": wall,
        "policies": fault_summary(rows, trajs),
        "command": "swarm montecarlo docking-faults --runs 200 --seed 0 --workers 2",
    }


def format_report(rec: dict) -> str:
    from swarm.montecarlo.faults import format_summary

    lines = [
        f"Faults (docking-faults: 10 % NLOS, 5 s UWB dropout in REORIENT, camera lost for the first 10 s of "
        f"ALIGN), "
        f"{rec['runs']} runs per policy, root seed {rec['root_seed']}, {rec['wall_s']:.0f} s wall on "
        f"{rec['workers']} workers",
        "",
        format_summary(rec["policies"]),
        "",
    ]
    for pol, s in rec["policies"].items():
        n = s["nees"]
        if n.get("samples"):
            lo, hi = n["mean_bounds_95_independent"]
            lines.append(
                f"{pol}: NEES over {n['samples']} samples (UWB navigation before the first vision update, "
                f"outside the dropout): mean "
                f"{n['mean_nees']:.2f}, median {n['median_nees']:.2f}; ensemble mean inside its 95 % "
                f"bounds at {100 * n['fraction_times_inside_95']:.0f} % of {n['times']} times "
                f"({n['times_above']} above, {n['times_below']} below); bound of the overall mean "
                f"if samples were independent [{lo:.2f}, {hi:.2f}]"
            )
    return "\n".join(lines)
