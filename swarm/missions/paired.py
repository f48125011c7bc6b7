"""A paired campaign of any mission that gives :meth:`~swarm.missions.base.Mission.run_one`: each run
index flies every policy from the same seed (:func:`swarm.montecarlo.campaign.run_seed`), and the
statistics are the docking campaign's (:mod:`swarm.montecarlo.stats`: Student-t intervals of the mean,
Clopper-Pearson success interval, paired t-test and Wilcoxon signed-rank test of ``other - base``).

In process and one run after another: no directory, resume or workers (those are
:mod:`swarm.montecarlo.campaign`'s, which runs the docking mission).
"""

from __future__ import annotations

from typing import Any

from swarm.errors import ConfigError
from swarm.missions.base import Mission


def paired_campaign(
    mission: Mission, scenario: Any, policies: tuple[str, ...], runs: int, root_seed: int
) -> dict:
    """``runs`` paired runs of each of ``policies``: ``{"runs", "policies": {p: {"n_runs",
    <success_key>, "success_rate", "success_ci95", <metric>: describe}}, "paired_policies", "paired":
    {<metric>: paired}}`` over ``mission.campaign_metrics()``, the first policy the baseline; a metric is
    described and paired over the runs that reached the goal (``mission.success_key``)."""
    from swarm.montecarlo.campaign import run_seed
    from swarm.montecarlo.stats import describe, paired, success

    if not policies:
        raise ConfigError("a campaign needs at least one policy, got none")
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise ConfigError(f"--runs must be a positive integer, got {runs!r}")
    metrics, key = mission.campaign_metrics(), mission.success_key
    rows = []
    for run in range(runs):
        seed = run_seed(root_seed, run)
        for policy in policies:
            res = mission.run_one(scenario, policy, seed)
            row = {"run": run, "policy": policy, key: bool(res[key])}
            rows.append(row | {m: res.get(m) for m in metrics})
    out: dict = {"mission": mission.name, "runs": runs, "root_seed": root_seed, "policies": {}}
    for policy in policies:
        mine = [r for r in rows if r["policy"] == policy]
        ok = [r for r in mine if r[key]]
        s = success(mine, key)
        out["policies"][policy] = {
            "n_runs": len(mine),
            key: s[key],
            "success_rate": s["rate"],
            "success_ci95": s["ci95"],
            **{m: describe(r[m] for r in ok if r[m] is not None) for m in metrics},
        }
    if len(policies) >= 2:
        base, other = policies[0], policies[1]
        out["paired_policies"] = [base, other]
        out["paired"] = {m: paired(rows, base, other, m, key) for m in metrics}
    return out
