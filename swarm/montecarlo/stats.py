"""Statistics of a campaign: the Table II analogue per policy and the paired differences between policies.

* Mean, sample standard deviation (``ddof = 1``) and the 95 % confidence interval of the mean from
  Student's t distribution, ``mean +- t_{0.975, n-1} s / sqrt(n)`` (``scipy.stats.t``), over the runs that
  docked (errors and docking time exist only for those).
* Success rate with its exact (Clopper-Pearson) 95 % interval (``scipy.stats.binomtest``).
* Paired differences ``second policy - first policy`` run by run, over the runs both policies docked:
  mean, t interval, the two-sided **paired t-test** (``scipy.stats.ttest_rel``) and, as a check that does
  not assume normal differences, the two-sided **Wilcoxon signed-rank test** (``scipy.stats.wilcoxon``).

Everything here is computed from the typed rows of ``runs.csv`` (:func:`swarm.montecarlo.campaign.read_runs`)
so the report says only what the per-run file says.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from swarm.montecarlo.campaign import complete_pairs, finite

METRICS: dict[str, tuple[str, str, float, int]] = {
    "position_error_m": ("position error", "cm", 100.0, 3),
    "attitude_error_rad": ("attitude error", "rad", 1.0, 4),
    "docking_time_s": ("docking time", "s", 1.0, 2),
    "total_impulse_ns": ("total impulse", "N s", 1.0, 4),
}
"""Table II metrics of the cube: field -> (label, unit shown, scale to that unit, decimals)."""


def metrics_for(scenario) -> dict[str, tuple[str, str, float, int]]:
    """The Table II metrics of a campaign of ``scenario``: :data:`METRICS` with its chasers' kind's effort
    (a cube's total impulse, a wheeled module's wheel travel, ...) in place of the impulse."""
    kind = scenario.kind(scenario.chasers[0])
    out = {}
    for m, spec in METRICS.items():
        if m == "total_impulse_ns":
            out[kind.effort_key] = (
                spec if kind.effort_key == m else (kind.effort_label, kind.effort_unit, 1.0, 2)
            )
        else:
            out[m] = spec
    return out


PAPER_TABLE_II: dict[str, dict[str, float]] = {
    "fixed": {
        "position_error_m": 0.00567,
        "attitude_error_rad": 0.0137,
        "docking_time_s": 140.05,
        "total_impulse_ns": 10.7858,
    },
    "mdp": {
        "position_error_m": 0.00568,
        "attitude_error_rad": 0.0129,
        "docking_time_s": 126.65,
        "total_impulse_ns": 9.2679,
    },
}
"""The paper's Table II (500-run averages; position error given in cm there)."""

PHASES: dict[str, tuple[str, tuple[str, ...]]] = {
    "start": ("t_approach_s", ()),
    "APPROACH": ("t_reorient_s", ("t_approach_s",)),
    "REORIENT": ("t_align_s", ("t_reorient_s",)),
    "ALIGN": ("t_dock_s", ("t_align_s",)),
    "DOCK": ("docking_time_s", ("t_dock_s",)),
}
"""Time in each phase = entry of the next mode minus entry of this one (``start``: the initial HOLD until
the first estimate converged)."""

CONFIDENCE = 0.95


def describe(values) -> dict:
    """``{"n", "mean", "std", "ci95"}`` of the finite ``values``; ``std`` and ``ci95`` are None below two
    values, everything is None for none."""
    x = finite(values)
    n = int(x.size)
    if n == 0:
        return {"n": 0, "mean": None, "std": None, "ci95": None}
    mean = float(np.mean(x))
    if n < 2:
        return {"n": n, "mean": mean, "std": None, "ci95": None}
    std = float(np.std(x, ddof=1))
    half = float(stats.t.ppf(0.5 + CONFIDENCE / 2, n - 1)) * std / math.sqrt(n)
    return {"n": n, "mean": mean, "std": std, "ci95": [mean - half, mean + half]}


def success(rows: list[dict], key: str = "docked") -> dict:
    """How many of ``rows`` reached the goal (``row[key]``: ``docked``, ``landed``), with the exact
    (Clopper-Pearson) 95 % interval of the rate: ``{"n", key, "rate", "ci95"}``."""
    n = len(rows)
    k = sum(1 for r in rows if r[key])
    if n == 0:
        return {"n": 0, key: 0, "rate": None, "ci95": None}
    ci = stats.binomtest(k, n).proportion_ci(CONFIDENCE, method="exact")
    return {"n": n, key: k, "rate": k / n, "ci95": [float(ci.low), float(ci.high)]}


def paired(rows: list[dict], base: str, other: str, metric: str, key: str = "docked") -> dict:
    """``other - base`` of ``metric`` run by run (same run index and, where rows have one, the same
    ``chaser``), over the runs both reached the goal (``row[key]``), in run order: the mean difference, its
    t interval (:func:`describe`), relative to the ``base`` mean, the two-sided paired t-test
    (``scipy.stats.ttest_rel``) and Wilcoxon signed-rank test (``scipy.stats.wilcoxon``). The one paired
    comparison of every mission's campaign."""
    by = {(r["run"], r.get("chaser"), r["policy"]): r for r in rows}
    a, b = [], []
    for (run, chaser, pol), r in sorted(by.items()):
        if pol != base:
            continue
        s = by.get((run, chaser, other))
        if s is None or not (r[key] and s[key]):
            continue
        if r[metric] is None or s[metric] is None:
            continue
        a.append(r[metric])
        b.append(s[metric])
    a_arr, b_arr = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    diff = b_arr - a_arr
    out = describe(diff)
    res = {
        "n": out["n"],
        "mean_diff": out["mean"],
        "std_diff": out["std"],
        "ci95": out["ci95"],
        "relative": out["mean"] / float(np.mean(a_arr)) if out["n"] and np.mean(a_arr) != 0 else None,
        "test": "paired t-test, two-sided (scipy.stats.ttest_rel)",
        "p_value": None,
        "wilcoxon_p_value": None,
    }
    if out["n"] >= 2 and np.any(diff != diff[0]):
        res["p_value"] = float(stats.ttest_rel(b_arr, a_arr).pvalue)
    if out["n"] >= 2 and np.any(diff != 0):
        res["wilcoxon_p_value"] = float(stats.wilcoxon(diff).pvalue)
    return res


def phase_durations(row: dict) -> dict[str, float | None]:
    """Seconds spent in each of :data:`PHASES` in one run (None where a mode was never entered; a
    skipped ALIGN counts as zero and its REORIENT runs to DOCK)."""
    out: dict[str, float | None] = {}
    for phase, (end_key, start_keys) in PHASES.items():
        end = row[end_key]
        if phase == "REORIENT" and end is None and row["align_by"] == "skipped":
            end = row["t_dock_s"]
        start = row[start_keys[0]] if start_keys else 0.0
        if phase == "ALIGN" and row["align_by"] == "skipped":
            out[phase] = 0.0
            continue
        out[phase] = None if end is None or start is None else end - start
    return out


def summarize(
    rows: list[dict],
    policies: tuple[str, ...],
    runs: int,
    wall_s: float | None = None,
    metrics: dict | None = None,
) -> dict:
    """The ``swarm montecarlo --json`` record (swarm/step/outcome.py), from the typed rows of ``runs.csv``;
    ``metrics`` the Table II metrics (:func:`metrics_for` the campaign's scenario; the cube's by default),
    recorded under ``"metrics"``.

    ``paired`` compares the second policy with the first (``mdp - fixed`` for ``--policy fixed --policy
    mdp``) over the runs both finished and docked.
    """
    metrics = METRICS if metrics is None else metrics
    rows = sorted(rows, key=lambda r: (r["run"], r["policy"], r["chaser"]))
    out: dict = {"runs": runs, "wall_s": wall_s, "confidence": CONFIDENCE, "policies": {},
                 "metrics": {m: list(v) for m, v in metrics.items()}}  # fmt: skip
    for pol in policies:
        mine = [r for r in rows if r["policy"] == pol]
        docked = [r for r in mine if r["docked"]]
        s = success(mine)
        rec: dict = {
            "n_runs": len(mine),
            "success_rate": s["rate"],
            "success_ci95": s["ci95"],
            "docked": s["docked"],
            "collisions": sum(1 for r in mine if r["collided"]),
            "keepout_violations": sum(1 for r in mine if r["keepout_violated"]),
        }
        for m in metrics:
            rec[m] = describe(r[m] for r in docked)
        rec["r2_m"] = describe(r["r2_m"] for r in mine)
        rec["range_align_m"] = describe(r["range_align_m"] for r in mine)
        rec["align_by"] = {
            k: sum(1 for r in mine if r["align_by"] == k) for k in ("radius", "stall", "skipped")
        }
        rec["r1_fired"] = sum(1 for r in mine if r["r1_fired"])
        rec["phases_s"] = {ph: describe(phase_durations(r)[ph] for r in docked) for ph in PHASES}
        out["policies"][pol] = rec
    if len(policies) >= 2:
        base, other = policies[0], policies[1]
        pairs = complete_pairs(rows, (base, other))
        out["paired_policies"] = [base, other]
        out["paired_runs"] = len(pairs)
        out["paired"] = {m: paired(rows, base, other, m) for m in metrics}
        out["paired_phases_s"] = _paired_phases(rows, base, other)
    return out


def _paired_phases(rows: list[dict], base: str, other: str) -> dict:
    """Paired difference of the time in each phase (same runs as :func:`paired`)."""
    by = {(r["run"], r["chaser"], r["policy"]): r for r in rows}
    out = {}
    for ph in PHASES:
        diffs = []
        for (run, chaser, pol), r in sorted(by.items()):
            s = by.get((run, chaser, other))
            if pol != base or s is None or not (r["docked"] and s["docked"]):
                continue
            a, b = phase_durations(r)[ph], phase_durations(s)[ph]
            if a is not None and b is not None:
                diffs.append(b - a)
        d = describe(diffs)
        out[ph] = {"n": d["n"], "mean_diff": d["mean"], "ci95": d["ci95"]}
    return out
