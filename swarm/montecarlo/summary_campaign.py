"""The campaign part of a mission that gives only one run's summary (:class:`swarm.missions.Mission`'s
``run_one``, ``name``, ``load``, ``success_key`` and ``summary_metrics``), run by the one runner
(:func:`swarm.montecarlo.campaign.run_campaign`). A run is one ``runs.csv`` row: ``run``, ``seed``,
``policy``, the success flag and the metrics; no trajectory. The report is the shared statistics
(:mod:`swarm.montecarlo.stats`): the success count with its Clopper-Pearson interval and each metric's
Student-t interval over the runs that reached the goal; the paired t and Wilcoxon tests of ``other - base``.
"""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path

from swarm.montecarlo.campaign import CampaignMission, read_manifest, read_runs


def summary_campaign(mission) -> CampaignMission:
    """The campaign part of ``mission`` (module docstring)."""
    cols = {"run": "int", "seed": "int", "policy": "str", mission.success_key: "bool"}
    cols |= dict.fromkeys(mission.summary_metrics, "float?")
    return CampaignMission(
        name=mission.name,
        load=mission.load,
        columns=lambda _sc: dict(cols),
        run_one=partial(_run_one, mission),
        report=partial(_report, mission),
        summary=partial(_summary_text, mission.success_key),
    )


def _run_one(mission, sc, policy: str, run: int, seed: int, trajectory_period_s: float = 1.0):
    """One run's row, in a worker: its summary's success flag and metrics (None where it has none)."""
    res, key = mission.run_one(sc, policy, seed), mission.success_key
    row = {"run": run, "seed": seed, "policy": policy, key: bool(res[key])}
    return [row | {m: res.get(m) for m in mission.summary_metrics}], []


def _report(mission, out_dir: str | Path, figures: bool = True) -> dict:
    """``stats.json`` and ``report.md`` (no figures) from the directory; the statistics."""
    from swarm.montecarlo.report import finite_or_null
    from swarm.montecarlo.stats import describe, paired, success

    out_dir, man = Path(out_dir), read_manifest(out_dir)
    policies, key, metrics = tuple(man["policies"]), mission.success_key, mission.summary_metrics
    rows = read_runs(out_dir, mission=summary_campaign(mission))
    rec: dict = {
        "mission": mission.name,
        "runs": int(man["runs"]),
        "root_seed": man["root_seed"],
        "policies": {},
    }
    for p in policies:
        mine = [r for r in rows if r["policy"] == p]
        s = success(mine, key)
        rec["policies"][p] = {
            "n_runs": len(mine),
            key: s[key],
            "success_rate": s["rate"],
            "success_ci95": s["ci95"],
        }
        rec["policies"][p] |= {
            m: describe(r[m] for r in mine if r[key] and r[m] is not None) for m in metrics
        }
    if len(policies) >= 2:
        rec["paired_policies"] = [policies[0], policies[1]]
        rec["paired"] = {m: paired(rows, policies[0], policies[1], m, key) for m in metrics}
    rec = finite_or_null(rec)
    (out_dir / "stats.json").write_text(json.dumps(rec, indent=1) + "\n")
    (out_dir / "report.md").write_text(
        f"# {mission.name}, {rec['runs']} paired runs\n\n```\n{_summary_text(key, rec)}\n```\n"
    )
    return rec


def _summary_text(key: str, rec: dict) -> str:
    """Per policy the success count and the metrics' means; the paired differences of the means."""
    lines = []
    for p, s in rec["policies"].items():
        means = [
            f"{m} {d['mean']:.4g}" for m, d in s.items() if isinstance(d, dict) and d["mean"] is not None
        ]
        lines.append(f"  {p:<6} " + ", ".join([f"{key} {s[key]}/{s['n_runs']}", *means]))
    for m, d in rec.get("paired", {}).items():
        if d["mean_diff"] is not None:
            base, other = rec["paired_policies"]
            pv = "-" if d["p_value"] is None else f"{d['p_value']:.2g}"
            lines.append(f"  {other} - {base} {m}: {d['mean_diff']:+.4g}, paired t p = {pv}")
    return "\n".join(lines)
