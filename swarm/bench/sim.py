"""``swarm bench sim``: speed of one in-process docking of each vehicle kind (DESIGN.md section 7; issue
12's target: >= 500x real time on one core for both kinds).

For each kind (:data:`BENCH_SCENARIOS`: the paper's cube docking, and the ground docking from a start that
flies every mode), one run per policy and seed after a warm-up run (numba compilation and caches
excluded), on one core: simulated seconds per wall second (the real-time factor) and wall time per 10 ms
tick, side by side in one run of the bench; and where the time goes (cProfile, top functions by own time)
for the cube's first policy.
"""

from __future__ import annotations

import cProfile
import io
import os
import pstats
import time

TARGET_RTF = 500.0

BENCH_SCENARIOS = {
    "cubesat": ("docking", {}),
    "ground": ("ground-docking", {"vehicles.chaser.position_m": [0.4, 0.3, 0.05],
                                  "vehicles.chaser.euler_deg": [0.0, 0.0, 90.0]}),
}  # fmt: skip
"""Kind -> (scenario, overrides) of its benchmark docking."""


def _cases(sc, seeds) -> dict:
    from swarm.sim.docking import run_docking

    cases = {}
    for policy in ("fixed", "mdp"):
        walls, sims = [], []
        for seed in seeds:
            t0 = time.perf_counter()
            res = run_docking(sc, policy, seed, record_series=False)
            walls.append(time.perf_counter() - t0)
            sims.append(res["sim_time_s"])
        rtf = sorted(s / w for s, w in zip(sims, walls, strict=True))
        ticks = [s / sc.dt_s for s in sims]
        cases[policy] = {
            "realtime_factor_median": rtf[len(rtf) // 2],
            "realtime_factor_min": rtf[0],
            "wall_s": walls,
            "sim_time_s": sims,
            "us_per_tick_median": sorted(w / t * 1e6 for w, t in zip(walls, ticks, strict=True))[
                len(ticks) // 2
            ],
        }
    return cases


def run(quick: bool = False) -> dict:
    from swarm.scenario import load_scenario
    from swarm.sim.docking import run_docking

    scenarios = {k: load_scenario(name, ov) for k, (name, ov) in BENCH_SCENARIOS.items()}
    for sc in scenarios.values():
        run_docking(sc, "fixed", 0, record_series=False)  # warm-up: compilation, caches
    seeds = (0,) if quick else (0, 1, 2)
    kinds = {k: {"scenario": sc.name, "cases": _cases(sc, seeds)} for k, sc in scenarios.items()}
    for rec in kinds.values():
        rec["realtime_factor"] = min(c["realtime_factor_median"] for c in rec["cases"].values())
        rec["us_per_tick"] = max(c["us_per_tick_median"] for c in rec["cases"].values())
    prof = cProfile.Profile()
    prof.enable()
    run_docking(scenarios["cubesat"], "fixed", 0, record_series=False)
    prof.disable()
    buf = io.StringIO()
    pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(12)
    return {
        "realtime_factor": min(k["realtime_factor"] for k in kinds.values()),
        "target_realtime_factor": TARGET_RTF,
        "kinds": kinds,
        "cases": kinds["cubesat"]["cases"],  # the cube's, as before kinds
        "load_avg_1m": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None,
        "profile_top": buf.getvalue(),
    }


def format_report(rec: dict) -> str:
    lines = ["In-process docking of each vehicle kind (one core), after a warm-up run", ""]
    lines.append(
        f"{'kind':<8} {'policy':<8} {'real-time factor (median, min)':>32} {'us per 10 ms tick':>18} "
        f"{'sim s':>8}"
    )
    for kind, k in rec["kinds"].items():
        for policy, c in k["cases"].items():
            rtf = f"{c['realtime_factor_median']:>22.0f}x ({c['realtime_factor_min']:.0f}x)"
            lines.append(
                f"{kind:<8} {policy:<8} {rtf} {c['us_per_tick_median']:>18.1f} {c['sim_time_s'][0]:>8.1f}"
            )
    met = rec["realtime_factor"] >= rec["target_realtime_factor"]
    lines.append("")
    lines.append(
        f"goal: one docking >= {rec['target_realtime_factor']:.0f}x real time for every kind: "
        f"{'met' if met else 'NOT met'} ({rec['realtime_factor']:.0f}x, the slowest kind)"
    )
    lines.append(f"machine: 1-min load {rec['load_avg_1m']}")
    lines.append("")
    lines.append("profile of one run (cProfile inflates Python-heavy code), top functions by own time:")
    lines.extend("  " + ln for ln in rec["profile_top"].splitlines() if ln.strip() and "/" in ln)
    return "\n".join(lines)
