"""``swarm bench montecarlo``: wall time of paired campaigns (BENCHMARKS.md), 1 vs 2 workers and the
number of runs, against the issue-6 target of 500 runs x 2 policies in 30 s on this 2-core machine.

Each case is a real :func:`swarm.montecarlo.campaign.run_campaign` of the paper's docking scenario (both
policies, per-run CSV and trajectories written to a temporary directory) on a fresh
:class:`~concurrent.futures.ProcessPoolExecutor`, so the wall time includes starting the workers. The
report is timed separately. The workers' CPU time (``getrusage(RUSAGE_CHILDREN)``) divided by the number of
workers is the wall time the campaign would take on idle cores; on this shared machine the measured wall
is often much longer. Where the time goes: the sum of the runs' own wall times (measured inside the
workers) against ``workers x wall``, the rest being pool start-up, pickling and the files; the time of a
run itself is the closed loop's (``swarm bench sim`` profiles it).
"""

from __future__ import annotations

import os
import resource
import tempfile
import time
from pathlib import Path

TARGET_WALL_S = 30.0
TARGET_RUNS = 500
FULL_CASES = ((1, 50), (2, 50), (2, 100), (2, TARGET_RUNS))
QUICK_CASES = ((1, 8), (2, 8), (2, 16))


def run(quick: bool = False) -> dict:
    from swarm.montecarlo.campaign import CampaignSpec, read_runs, run_campaign
    from swarm.montecarlo.report import write_report
    from swarm.scenario import load_scenario
    from swarm.sim.docking import run_docking

    sc = load_scenario("docking")
    run_docking(sc, "fixed", 0, record_series=False)  # warm-up: numba's cache loaded in this process
    cases = []
    load0 = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    for workers, runs in QUICK_CASES if quick else FULL_CASES:
        with tempfile.TemporaryDirectory(prefix="swarm-bench-mc-") as tmp:
            out = Path(tmp) / "c"
            cpu0 = _children_cpu_s()
            t0 = time.perf_counter()
            spec = CampaignSpec(sc, ("fixed", "mdp"), runs, 0)
            outcome = run_campaign(spec, out, workers=workers, progress=False)
            wall = time.perf_counter() - t0
            cpu = _children_cpu_s() - cpu0  # the pool's workers, joined at the end of the campaign
            rows = read_runs(out)
            t1 = time.perf_counter()
            write_report(out)
            report_s = time.perf_counter() - t1
        busy = sum(r["wall_s"] for r in rows)
        sim = sum(r["sim_time_s"] for r in rows)
        cases.append(
            {
                "workers": workers,
                "runs": runs,
                "tasks": outcome.done,
                "wall_s": wall,
                "report_s": report_s,
                "workers_cpu_s": cpu,
                "cpu_per_task_s": cpu / outcome.done,
                "cpu_bound_wall_s": cpu / workers,
                "run_wall_sum_s": busy,
                "run_wall_mean_s": busy / len(rows),
                "overhead_s": wall - busy / workers,
                "efficiency": busy / (workers * wall),
                "realtime_factor_per_run": sim / busy,
                "docked": sum(1 for r in rows if r["docked"]),
            }
        )
    by = {(c["workers"], c["runs"]): c for c in cases}
    n_small = (QUICK_CASES if quick else FULL_CASES)[0][1]
    two = sorted((c for c in cases if c["workers"] == 2), key=lambda c: c["runs"])
    # wall = a + b * runs at 2 workers (least squares over the 2-worker cases)
    xs, ys = [c["runs"] for c in two], [c["wall_s"] for c in two]
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    b = sum((x - mx) * (y - my) for x, y in zip(xs, ys, strict=True)) / sum((x - mx) ** 2 for x in xs)
    a = my - b * mx
    measured = by.get((2, TARGET_RUNS))
    rec = {
        "cases": cases,
        "speedup_2_vs_1_workers": by[1, n_small]["wall_s"] / by[2, n_small]["wall_s"],
        "fit_2_workers": {"intercept_s": a, "per_run_pair_s": b},
        "predicted_500x2_wall_s": a + b * TARGET_RUNS,
        "measured_500x2_wall_s": measured["wall_s"] if measured else None,
        "target_wall_s": TARGET_WALL_S,
        "cpu_count": os.cpu_count(),
        "load_avg_1m_before": round(load0, 2) if load0 is not None else None,
        "load_avg_1m_after": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None,
    }
    return rec


def _children_cpu_s() -> float:
    """User + system CPU time of this process's finished children [s] (the pool's worker processes)."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def format_report(rec: dict) -> str:
    lines = [
        "Monte Carlo campaigns (paper docking scenario, fixed + mdp, ProcessPoolExecutor), wall time",
        "",
    ]
    lines.append(
        f"{'workers':>7} {'runs':>5} {'tasks':>6} {'wall s':>8} {'per task ms':>12} {'run mean ms':>12} "
        f"{'efficiency':>10} {'overhead s':>10} {'report s':>9} {'CPU ms/task':>11} {'CPU/workers s':>13}"
    )
    for c in rec["cases"]:
        lines.append(
            f"{c['workers']:>7} {c['runs']:>5} {c['tasks']:>6} {c['wall_s']:>8.1f} "
            f"{1000 * c['wall_s'] / c['tasks']:>12.0f} {1000 * c['run_wall_mean_s']:>12.0f} "
            f"{c['efficiency']:>10.2f} {c['overhead_s']:>10.1f} {c['report_s']:>9.1f} "
            f"{1000 * c['cpu_per_task_s']:>11.0f} {c['cpu_bound_wall_s']:>13.1f}"
        )
    lines.append("")
    lines.append(f"2 workers vs 1: {rec['speedup_2_vs_1_workers']:.2f}x")
    f = rec["fit_2_workers"]
    lines.append(
        f"2 workers: wall = {f['intercept_s']:.1f} s + {f['per_run_pair_s']:.3f} s per paired run "
        f"-> {rec['predicted_500x2_wall_s']:.0f} s predicted for 500 x 2"
    )
    m = rec["measured_500x2_wall_s"]
    verdict = "not measured (--quick)" if m is None else ("met" if m <= rec["target_wall_s"] else "NOT met")
    shown = "-" if m is None else f"{m:.1f} s"
    lines.append(
        f"goal: 500 runs x 2 policies <= {rec['target_wall_s']:.0f} s on 2 workers: {verdict} ({shown})"
    )
    load = f"{rec['load_avg_1m_before']} -> {rec['load_avg_1m_after']}"
    lines.append(f"machine: {rec['cpu_count']} CPUs, 1-min load {load}")
    return "\n".join(lines)
