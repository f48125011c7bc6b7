"""The landing's campaign (issue 15; paper Figs. 9-10): what :mod:`swarm.montecarlo.campaign` asks of it.

The campaign runner is the one of every mission (resume, ``--dask``, ``campaign.json``, rows as they
finish); the landing gives its :class:`~swarm.montecarlo.campaign.CampaignMission`, :data:`CAMPAIGN`: its
scenario (one UAV per run: a ``[[fleet]]`` is refused), one seeded run reduced to a ``runs.csv`` row
(:data:`COLUMNS`; a moving pad adds :data:`PLATFORM_COLUMNS`) and a trajectory, and ``report.md`` with
``stats.json``: the table, the paired differences (:func:`swarm.montecarlo.stats.paired`, the docking
campaign's), what they mean, and the figures: trajectories coloured by mode (Fig. 9), landing error and
energy distributions (Fig. 10) and the deviation points against the navigation quality.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from swarm.errors import ConfigError
from swarm.montecarlo.campaign import (
    SCENARIO_FILE,
    CampaignMission,
    read_manifest,
    read_runs,
    read_trajectories,
)
from swarm.montecarlo.stats import describe, paired, success

COLUMNS: dict[str, str] = {
    "run": "int",
    "seed": "int",
    "policy": "str",
    "landed": "bool",
    "aborted": "bool",
    "landed_off_pad": "bool",
    "landing_error_m": "float?",
    "landing_time_s": "float?",
    "energy_j": "float",
    "deviation_distance_m": "float?",
    "retries": "int",
    "sim_time_s": "float",
    "start_x_m": "float",
    "start_y_m": "float",
    "start_z_m": "float",
    "uwb_range_m": "float?",
}
"""``runs.csv`` columns (the run summary's names, :func:`swarm.step.landing.landing_summary`) and types."""
PLATFORM_COLUMNS: dict[str, str] = {
    "touchdown_rel_speed_m_s": "float?",
    "touchdown_vz_m_s": "float?",
    "platform_start_arc_m": "float?",
    "platform_speed_m_s": "float",
}
"""The columns a scenario with a moving pad (``[platform] enabled``) adds."""
TDOA_COLUMNS: dict[str, str] = {
    "tdoa_accepted": "int",
    "tdoa_rejected": "int",
    "tdoa_nis_mean": "float?",
}
"""The columns a scenario on a TDoA radio (``uwb.mode`` tdoa2/tdoa3) adds, after :data:`COLUMNS` (only then:
a two-way-ranging campaign's ``runs.csv`` is the same as before, byte for byte): the UAV's distance
differences its filter accepted and rejected over the run and the mean NIS of the accepted ones (the
summary's ``tdoa_pairs`` pooled: ``sum(nis_mean * accepted) / sum(accepted)``; 1 for a consistent filter;
empty when none was accepted). :meth:`swarm.step.landing.LandingAgent.tdoa_counts`."""
MODES = ("CRUISE", "DEVIATE", "DESCEND", "FINAL", "CLIMB", "LANDED", "ABORT")
METRICS = ("energy_j", "landing_time_s", "landing_error_m", "deviation_distance_m")
PAIRED_KEYS = ("n", "mean_diff", "ci95", "relative", "p_value", "wilcoxon_p_value")
"""What ``stats.json`` keeps of :func:`swarm.montecarlo.stats.paired` (its format since issue 15)."""
CAMPAIGN = CampaignMission(
    name="landing",
    load="swarm.montecarlo.landing:load_campaign_scenario",
    columns="swarm.montecarlo.landing:columns",
    run_one="swarm.montecarlo.landing:run_one",
    report="swarm.montecarlo.landing:write_report",
    summary="swarm.montecarlo.landing:summary_text",
    preload="swarm.sim.landing",
)
"""The landing's campaign part (:meth:`swarm.missions.Mission.campaign`)."""


def _moving(sc) -> bool:
    return bool(getattr(getattr(sc, "platform", None), "enabled", False))  # a scenario without [platform]


def load_campaign_scenario(scenario, overrides: dict | None = None):
    """The landing scenario ``scenario`` (a file or a bundled name) with ``overrides``; a ConfigError for a
    ``[[fleet]]``, since a campaign flies one UAV per run."""
    from swarm.landing_scenario import load_landing

    sc = load_landing(scenario, overrides)
    if sc.fleet:
        raise ConfigError(
            f"{scenario}: a landing campaign flies one UAV per run, this scenario has a [[fleet]] of "
            f"{len(sc.fleet)}; run it with `swarm sim` or `swarm launch`, or campaign on `landing`"
        )
    return sc


def columns(sc) -> dict[str, str]:
    """The ``runs.csv`` columns of a campaign of ``sc``."""
    tdoa = TDOA_COLUMNS if sc.uwb.mode != "twr" else {}
    return COLUMNS | tdoa | (PLATFORM_COLUMNS if _moving(sc) else {})


def tdoa_nis_mean(pairs: dict) -> float | None:
    """The mean NIS of every accepted difference (:data:`TDOA_COLUMNS`) from the summary's ``tdoa_pairs``."""
    acc = sum(p["accepted"] for p in pairs.values())
    if not acc:
        return None
    return sum(p["nis_mean"] * p["accepted"] for p in pairs.values() if p["accepted"]) / acc


def run_one(sc, policy: str, run: int, seed: int, trajectory_period_s: float = 1.0):
    """Run ``run`` of ``policy`` from ``seed``: ``([row], [trajectory])``, the trajectory sampled every
    ``trajectory_period_s`` (positions to the millimetre, the mode as an index into :data:`MODES`)."""
    from swarm.sim.landing import run_landing
    from swarm.step.landing_nb import SERIES_EVERY

    r = run_landing(sc, policy, seed, record_series=True)
    row = {"run": run, "seed": seed, "policy": policy}
    for k in columns(sc):
        if k in r:
            row[k] = r[k]
    row["start_x_m"], row["start_y_m"], row["start_z_m"] = r["start_m"]
    if "tdoa_pairs" in r:  # (TDOA_COLUMNS)
        row["tdoa_nis_mean"] = tdoa_nis_mean(r["tdoa_pairs"])
    s = r["series"]
    step = max(1, round(trajectory_period_s / (SERIES_EVERY * sc.dt_s)))
    traj = {
        "run": run,
        "policy": policy,
        "t_s": s["t_s"][::step],
        "p": [[round(v, 3) for v in p] for p in s["p_true_nav"][::step]],
        "mode": [MODES.index(m) for m in s["mode"][::step]],
        "sigma_h_m": [round(v, 4) for v in s["sigma_h_m"][::step]],
    }
    return [row], [traj]


def summarize(rows: list[dict], policies: tuple[str, ...]) -> dict:
    """The statistics of ``stats.json`` from the typed rows: per policy the landed rate, the counts and
    :data:`METRICS` over the landed runs; the paired differences of the other policies against the first,
    also split by the anchors' reach (the navigation quality)."""
    rec: dict = {"policies": {}, "paired": {}}
    for p in policies:
        rs = [r for r in rows if r["policy"] == p]
        landed = [r for r in rs if r["landed"]]
        s = success(rs, "landed")
        rec["policies"][p] = {
            "landed": {"n": s["n"], "k": s["landed"], "rate": s["rate"], "ci95": s["ci95"]},
            "aborted": sum(1 for r in rs if r["aborted"]),
            "landed_off_pad": sum(1 for r in rs if r["landed_off_pad"]),
            "retried": sum(1 for r in rs if r["retries"]),
            **{m: describe([r[m] for r in landed if r[m] is not None]) for m in METRICS},
        }

    def pair(sub: list[dict], other: str, m: str) -> dict:
        d = paired(sub, policies[0], other, m, key="landed")
        return {k: d[k] for k in PAIRED_KEYS}

    base = policies[0]
    for other in policies[1:]:
        rec["paired"][f"{other}-{base}"] = {m: pair(rows, other, m) for m in METRICS[:3]}
    # by navigation quality: the anchors' reach against the distance at which the fixed rule deviates plus
    # the glide's height, split at the middle of the dispersion's interval
    reach = [r["uwb_range_m"] for r in rows if r.get("uwb_range_m") is not None]
    if reach:
        split = float(np.median(reach))
        rec["reach_split_m"] = split
        rec["paired_by_reach"] = {}
        for name, keep in (
            ("short", lambda r: r["uwb_range_m"] < split),
            ("long", lambda r: r["uwb_range_m"] >= split),
        ):
            sub_rows = [r for r in rows if keep(r)]
            for other in policies[1:]:
                rec["paired_by_reach"][f"{name}:{other}-{base}"] = {
                    m: pair(sub_rows, other, m) for m in ("energy_j", "landing_time_s")
                }
    return rec


def write_report(out_dir: str | Path, figures: bool = True) -> dict:
    """Write ``report.md``, ``stats.json`` (and the figures) from the campaign directory's files; return
    the statistics."""
    out_dir = Path(out_dir)
    man = read_manifest(out_dir)
    policies = tuple(man["policies"])
    sc = load_campaign_scenario(out_dir / SCENARIO_FILE)
    order = {p: k for k, p in enumerate(policies)}
    rows = sorted(read_runs(out_dir, sc, CAMPAIGN), key=lambda r: (r["run"], order[r["policy"]]))
    trajs = sorted(read_trajectories(out_dir), key=lambda t: (t["run"], order[t["policy"]]))
    rec = summarize(rows, policies)
    rec.update({"scenario": sc.name, "runs": int(man["runs"]), "root_seed": man["root_seed"],
                "wall_s": man.get("wall_s"), "workers": man.get("workers")})  # fmt: skip
    _write(out_dir, rec, rows, trajs, policies, sc, figures)
    return rec


def summary_text(rec: dict) -> str:
    """What ``swarm montecarlo`` prints of a landing campaign's statistics."""
    lines = []
    for p, s in rec["policies"].items():
        ld = s["landed"]
        energy, time_s = s["energy_j"]["mean"], s["landing_time_s"]["mean"]
        lines.append(
            f"{p:<6} landed {ld['k']}/{ld['n']}, aborted {s['aborted']}, off the pad {s['landed_off_pad']}"
            + ("" if energy is None else f"; energy {energy:.0f} J, time {time_s:.2f} s")
        )
    return "\n".join(lines)


def _fmt(d: dict, digits: int = 2) -> str:
    if d.get("mean") is None:
        return "-"
    ci = d.get("ci95")
    return f"{d['mean']:.{digits}f}" + (f" [{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]" if ci else "")


def _wall(rec: dict) -> str:
    """How long the campaign's last session took and where: ``13.0 s on 2 workers``."""
    where = "on a cluster" if rec["workers"] is None else f"on {rec['workers']} workers"
    return (
        f"{rec['wall_s']:.1f} s {where}" if rec["wall_s"] is not None else f"(wall time not recorded) {where}"
    )


def _verdict(p: dict, metric: str, unit: str) -> str:
    if p["n"] == 0 or p["mean_diff"] is None:
        return f"{metric}: no paired landings to compare"
    lo, hi = p["ci95"] if p["ci95"] else (p["mean_diff"], p["mean_diff"])
    rel = f" ({p['relative']:+.1%})" if p["relative"] is not None else ""
    if hi < 0:
        word = "lower"
    elif lo > 0:
        word = "higher"
    else:
        word = "not different (the interval contains 0)"
    return f"{metric}: {p['mean_diff']:+.3g} {unit}{rel}, 95 % CI [{lo:+.3g}, {hi:+.3g}]: {word}"


def _write(
    out_dir: Path, rec: dict, rows: list[dict], trajs: list[dict], policies, sc, figures: bool
) -> None:
    lines = [
        f"# Landing campaign: {rec['scenario']}, {rec['runs']} paired runs, root seed {rec['root_seed']}",
        "",
    ]
    lines.append(
        f"{len(rows)} runs in {_wall(rec)}. Dispersions: start "
        f"position sigma {list(sc.dispersions.start_sigma_m)} m, anchor reach uniform in "
        f"{list(sc.dispersions.uwb_range_m)} m, IMU biases, initial estimate errors, sensor noise."
    )
    lines += [
        "",
        "| policy | landed [95 % CI] | aborted | off the pad | retried | energy [J] | landing time [s] | "
        "landing error [cm] | deviation distance [m] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for p in policies:
        s = rec["policies"][p]
        ld = s["landed"]
        rate = f"{ld['k']}/{ld['n']} [{ld['ci95'][0]:.3f}, {ld['ci95'][1]:.3f}]" if ld["n"] else "-"
        err = dict(s["landing_error_m"])
        if err.get("mean") is not None:
            err = {"mean": err["mean"] * 100, "ci95": [c * 100 for c in err["ci95"]] if err["ci95"] else None}
        lines.append(
            f"| {p} | {rate} | {s['aborted']} | {s['landed_off_pad']} | {s['retried']} | "
            f"{_fmt(s['energy_j'], 0)} | {_fmt(s['landing_time_s'])} | {_fmt(err)} | "
            f"{_fmt(s['deviation_distance_m'])} |"
        )
    lines.append("")
    for key, pr in rec["paired"].items():
        lines.append(f"Paired differences {key} over the runs both landed:")
        lines.append("")
        units = {"energy_j": "J", "landing_time_s": "s", "landing_error_m": "m"}
        for m, p in pr.items():
            lines.append(
                f"- {_verdict(p, m, units[m])}; t-test p = {p['p_value']}, "
                f"Wilcoxon p = {p['wilcoxon_p_value']}"
            )
        lines.append("")
        if "paired_by_reach" in rec:
            split = rec["reach_split_m"]
            lines.append(
                f"By navigation quality (the anchors' reach in the run, split at its median {split:.1f} m):"
            )
            lines.append("")
            for name, label in (("short", f"reach < {split:.1f} m"), ("long", f"reach >= {split:.1f} m")):
                prs = rec["paired_by_reach"].get(f"{name}:{key}")
                if prs:
                    lines.append(
                        f"- {label}: {_verdict(prs['energy_j'], 'energy_j', 'J')}; "
                        f"{_verdict(prs['landing_time_s'], 'landing_time_s', 's')}"
                    )
            lines.append("")
        e = pr["energy_j"]
        by = rec.get("paired_by_reach", {})
        short, long_ = by.get(f"short:{key}", {}).get("energy_j"), by.get(f"long:{key}", {}).get("energy_j")

        def sign(p):
            if not p or not p.get("ci95"):
                return 0
            return -1 if p["ci95"][1] < 0 else (1 if p["ci95"][0] > 0 else 0)

        text = (
            "What it means: the Markov rule leaves the energy-optimal glide where the navigation says "
            "the pad will not be seen from its end. With good navigation (the anchors reach the approach) "
            "it flies the glide to within a few metres and skips the fixed policy's detour to the "
            "viewpoint; with poor navigation it deviates at its activation radius, earlier than the fixed "
            "rule, and flies a longer detour. "
        )
        if sign(long_) < 0 and sign(short) > 0:
            text += (
                "Here it saves energy where the navigation is good and costs energy where it is poor, and "
                "over the whole campaign the two "
                + (
                    "cancel."
                    if sign(e) == 0
                    else ("leave a net saving." if sign(e) < 0 else "leave a net cost.")
                )
            )
        elif sign(e) < 0:
            text += "Here it saves energy overall."
        elif sign(e) > 0:
            text += "Here it costs energy overall."
        else:
            text += "Here the difference in energy is not significant."
        text += " Precision and safety are the same for both policies (the table)."
        lines.append(text)
        lines.append("")
    if figures:
        _figures(out_dir, rows, trajs, policies, sc)
        lines += [
            "![trajectories](fig9_trajectories.png)",
            "",
            "![distributions](fig10_distributions.png)",
            "",
            "![deviation](deviation_points.png)",
            "",
        ]
    (out_dir / "report.md").write_text("\n".join(lines) + "\n")
    (out_dir / "stats.json").write_text(json.dumps(rec, indent=1, default=lambda v: None) + "\n")


def _figures(out_dir: Path, rows, trajs, policies, sc) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colors = {
        "CRUISE": "tab:blue",
        "DEVIATE": "tab:orange",
        "DESCEND": "tab:green",
        "FINAL": "tab:red",
        "CLIMB": "tab:purple",
        "LANDED": "k",
        "ABORT": "tab:gray",
    }
    pad = np.asarray(sc.pad.position_m)
    fig, axes = plt.subplots(1, len(policies), figsize=(7 * len(policies), 5), sharey=True)
    axes = np.atleast_1d(axes)
    for ax, p in zip(axes, policies, strict=True):
        for tr in [t for t in trajs if t["policy"] == p][:100]:
            P = np.asarray(tr["p"])
            r = np.linalg.norm(P[:, :2] - pad[:2], axis=1)
            for i in range(len(P) - 1):
                ax.plot(r[i : i + 2], P[i : i + 2, 2], color=colors[MODES[tr["mode"][i]]], lw=0.6, alpha=0.6)
        ax.set(
            title=f"{p}: horizontal distance vs height, coloured by mode", xlabel="distance to the pad [m]"
        )
        ax.invert_xaxis()
    axes[0].set_ylabel("height [m]")
    handles = [plt.Line2D([], [], color=c, label=m) for m, c in colors.items()]
    axes[-1].legend(handles=handles, fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "fig9_trajectories.png", dpi=90)
    plt.close(fig)
    fig, ax = plt.subplots(1, 2, figsize=(12, 4))
    for p in policies:
        lr = [r for r in rows if r["policy"] == p and r["landed"]]
        ax[0].hist([100 * r["landing_error_m"] for r in lr], bins=20, alpha=0.5, label=p)
        ax[1].hist([r["energy_j"] for r in lr], bins=20, alpha=0.5, label=p)
    ax[0].set(xlabel="landing error [cm]", ylabel="runs", title="landing error")
    ax[1].set(xlabel="energy [J]", title="energy")
    ax[0].legend()
    fig.tight_layout()
    fig.savefig(out_dir / "fig10_distributions.png", dpi=90)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6, 4))
    for p in policies:
        rs = [r for r in rows if r["policy"] == p and r["deviation_distance_m"] is not None]
        ax.scatter([r["uwb_range_m"] for r in rs], [r["deviation_distance_m"] for r in rs], s=8, label=p)
    ax.set(
        xlabel="anchor reach in the run [m]",
        ylabel="deviation distance [m]",
        title="where each run left the energy-optimal glide",
    )
    ax.legend()
    fig.tight_layout()
    fig.savefig(out_dir / "deviation_points.png", dpi=90)
    plt.close(fig)
