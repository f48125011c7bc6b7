"""Monte Carlo under injected faults (issue 7): outcome classes and the chaser's position NEES.

A campaign of a scenario with a ``[faults]`` table (``swarm/scenarios/docking-faults.toml``) runs through the
ordinary campaign runner (:func:`swarm.montecarlo.campaign.run_campaign`); with faults on,
:func:`swarm.montecarlo.run.run_one` adds to each trajectory line the chaser's position NEES at the saved
samples (:func:`nees_samples`) and the fault windows of the run, and this module reduces them:

* **outcome classes** per run (:func:`classify`): ``docked``; ``aborted``, ended in ABORT (or any other
  mode short of contact) without ever entering the keep-out sphere outside the corridor: safe;
  ``failed``, a keep-out violation or a contact outside the docking tolerances (a collision);
* **NEES** ``e^T P^-1 e`` of the chaser's position (``e = p_est - p_true``, ``P`` the filter's 3x3
  position covariance) at the trajectory samples (every ``trajectory_period_s``, 1 s by default) that lie
  outside every UWB dropout window and before the chaser first navigated relative to the target. The
  samples from the first vision update on are left out: under vision the estimate and its covariance are
  relative to the target's *estimated* pose (``agent.vision_target_cov`` off, as in the paper), so the
  truth in the navigation frame is not what the covariance describes, and when the markers leave the
  image again (intermittently in ALIGN) the estimate keeps that offset (the target's own estimate error,
  millimetres) with a covariance shrunk by the 1 mm features until the ranges re-anchor it, over the
  filter's time constant (tens of seconds): those samples are not UWB navigation either, although
  ``relative_nav`` is false again. For a consistent filter the NEES is chi-square with 3
  degrees of freedom; the ensemble average over the ``N_k`` runs with a sample at time ``t_k`` lies in
  ``chi2.ppf([0.025, 0.975], 3 N_k) / N_k`` with probability 0.95 (Bar-Shalom, Li & Kirubarajan 2001,
  sec. 5.4.2), and about 95 % of the times should. The average over every sample and run is reported
  with the same bound at ``3 n`` degrees of freedom, which assumes independent samples: successive
  samples 1 s apart are correlated, so that bound is too narrow and only indicative.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2

OUTCOMES = ("docked", "aborted", "failed")
CONFIDENCE = 0.95


def nees_samples(series: dict, idx: list[int], dropouts) -> tuple[list, list]:
    """``(nees, used)`` at the series samples ``idx``: the position NEES and whether the sample counts
    (outside every dropout window ``(start, end)`` [s] and before the first series sample at which the
    chaser navigated relative to the target: module docstring)."""
    rel = series["relative_nav"]
    first_rel = next((i for i, r in enumerate(rel) if r), len(rel))
    nees, used = [], []
    for i in idx:
        e = np.asarray(series["p_est_nav"][i]) - np.asarray(series["p_true_nav"][i])
        P = np.asarray(series["cov_pos"][i])
        nees.append(round(float(e @ np.linalg.solve(P, e)), 5))
        t = series["t_s"][i]
        in_drop = any(a <= t < b for a, b in dropouts)
        used.append(not in_drop and i < first_rel)
    return nees, used


def classify(row: dict) -> str:
    """The outcome class of one ``runs.csv`` row (module docstring)."""
    if row["collided"] or row["keepout_violated"]:
        return "failed"
    return "docked" if row["docked"] else "aborted"


def nees_consistency(trajs: list[dict], dof: int = 3) -> dict:
    """Ensemble NEES per sample time over the runs (module docstring): the fraction of times inside the
    95 % bounds, the times above and below, and the overall mean with its (indicative) bounds."""
    by_t: dict[float, list[float]] = {}
    for tr in trajs:
        for t, v, ok in zip(tr["t_s"], tr.get("nees_pos", ()), tr.get("nees_used", ()), strict=False):
            if ok:
                by_t.setdefault(round(t, 3), []).append(v)
    if not by_t:
        return {"samples": 0, "times": 0}
    times = sorted(by_t)
    inside = above = below = 0
    for t in times:
        vals = by_t[t]
        n = len(vals)
        lo, hi = chi2.ppf([(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2], dof * n) / n
        m = float(np.mean(vals))
        inside += lo <= m <= hi
        above += m > hi
        below += m < lo
    allv = np.concatenate([np.asarray(by_t[t]) for t in times])
    n_all = int(allv.size)
    lo, hi = chi2.ppf([(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2], dof * n_all) / n_all
    return {
        "samples": n_all,
        "times": len(times),
        "fraction_times_inside_95": inside / len(times),
        "times_above": int(above),
        "times_below": int(below),
        "mean_nees": float(np.mean(allv)),
        "median_nees": float(np.median(allv)),
        "mean_bounds_95_independent": [float(lo), float(hi)],
        "dof": dof,
    }


def fault_summary(rows: list[dict], trajs: list[dict]) -> dict:
    """Per policy: counts of each outcome class, the safe fraction (docked or aborted) with its exact
    (Clopper-Pearson) 95 % interval, the HOLD/ABORT counts and the NEES consistency."""
    from scipy.stats import binomtest

    out = {}
    for pol in sorted({r["policy"] for r in rows}):
        mine = [r for r in rows if r["policy"] == pol]
        counts = {k: 0 for k in OUTCOMES}
        for r in mine:
            counts[classify(r)] += 1
        n = len(mine)
        safe = counts["docked"] + counts["aborted"]
        ci = binomtest(safe, n).proportion_ci(CONFIDENCE, method="exact") if n else None
        out[pol] = {
            "n_runs": n,
            **counts,
            "safe_rate": safe / n if n else math.nan,
            "safe_ci95": [float(ci.low), float(ci.high)] if ci else None,
            "keepout_violations": sum(1 for r in mine if r["keepout_violated"]),
            "collisions": sum(1 for r in mine if r["collided"]),
            "runs_with_hold": sum(1 for r in mine if r["n_hold"] > 0),
            "runs_with_abort": sum(1 for r in mine if r["n_abort"] > 0),
            "closest_approach_m": _closest(mine),
            "nees": nees_consistency([t for t in trajs if t["policy"] == pol]),
        }
    return out


def _closest(rows: list[dict]) -> dict | None:
    """The closest true approach of the chaser to its target outside the corridor modes (``runs.csv``'s
    ``closest_approach_m``: what the keep-out sphere is judged on): the minimum, 1st percentile and median
    over the runs, in metres."""
    v = np.array([r["closest_approach_m"] for r in rows if r.get("closest_approach_m") is not None])
    if v.size == 0:
        return None
    return {"min": float(v.min()), "p1": float(np.percentile(v, 1)), "median": float(np.median(v))}


def format_summary(summary: dict) -> str:
    """The summary as a Markdown table (one row per policy)."""
    lines = [
        "| policy | runs | docked | aborted (safe) | failed | safe rate [95 % CI] | runs with HOLD | "
        "closest approach [mm] min / 1 % / median | NEES mean | times inside 95 % |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for pol, s in summary.items():
        ci = s["safe_ci95"] or [math.nan, math.nan]
        nees = s["nees"]
        frac = nees.get("fraction_times_inside_95")
        ca = s.get("closest_approach_m")
        closest = f"{1e3 * ca['min']:.1f} / {1e3 * ca['p1']:.1f} / {1e3 * ca['median']:.1f}" if ca else "-"
        lines.append(
            f"| {pol} | {s['n_runs']} | {s['docked']} | {s['aborted']} | {s['failed']} | "
            f"{100 * s['safe_rate']:.1f} % [{100 * ci[0]:.1f}, {100 * ci[1]:.1f}] | {s['runs_with_hold']} | "
            f"{closest} | {nees.get('mean_nees', math.nan):.2f} (3 ideal) | "
            + (f"{100 * frac:.0f} % of {nees['times']}" if frac is not None else "-")
            + " |"
        )
    return "\n".join(lines)
