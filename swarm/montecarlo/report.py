"""``report.md``, ``report.json`` and the figures of a campaign directory, from its files alone.

Everything is recomputed from ``runs.csv`` (:mod:`swarm.montecarlo.stats`), ``trajectories.jsonl``,
``scenario.toml`` and ``campaign.json``, so a report can be regenerated at any time (``swarm montecarlo
... --resume DIR`` on a finished campaign does) and always says what the per-run file says.

Figures (PNG, matplotlib's Agg backend):

* ``fig5_trajectories.png``: every run's true trajectory per policy, coloured by guidance mode (paper Fig. 5);
* ``fig6_switching.png``: histograms of the ranges at which each policy entered REORIENT (``r2``) and ALIGN
  (``r1``, or the keep-out stall rule) (paper Fig. 6);
* ``mode_timelines.png``: the mode of every run over time, runs sorted by docking time;
* ``paired_differences.png``: the run-by-run differences of docking time and impulse.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from swarm.montecarlo.campaign import SCENARIO_FILE, read_manifest, read_runs, read_trajectories
from swarm.montecarlo.run import MAIN_MODES
from swarm.montecarlo.stats import PAPER_TABLE_II, PHASES, metrics_for, summarize

MODE_COLOURS = {
    "HOLD": "#999999",
    "APPROACH": "#1f77b4",
    "REORIENT": "#ff7f0e",
    "ALIGN": "#2ca02c",
    "DOCK": "#d62728",
}
FIGURES = ("fig5_trajectories.png", "fig6_switching.png", "mode_timelines.png", "paired_differences.png")
DPI = 90


def write_report(out_dir: str | Path, wall_s: float | None = None, figures: bool = True) -> dict:
    """Write ``report.md``, ``report.json`` (and the figures) into ``out_dir``; return the JSON record.

    ``wall_s`` is the campaign's wall time when the caller measured it (recorded in ``campaign.json`` so a
    regenerated report keeps it).
    """
    from swarm.scenario import load_scenario

    out_dir = Path(out_dir)
    man = read_manifest(out_dir)
    if wall_s is not None:
        man["wall_s"] = wall_s
        (out_dir / "campaign.json").write_text(json.dumps(man, indent=1) + "\n")
    policies = tuple(man["policies"])
    sc = load_scenario(out_dir / SCENARIO_FILE)
    rows = read_runs(out_dir)
    rec = summarize(rows, policies, int(man["runs"]), man.get("wall_s"), metrics_for(sc))
    rec["root_seed"] = man["root_seed"]
    rec["seed_rule"] = man["seed_rule"]
    rec["paper_table_ii"] = PAPER_TABLE_II
    (out_dir / "report.json").write_text(json.dumps(finite_or_null(rec), indent=1) + "\n")
    if figures:
        trajs = read_trajectories(out_dir)
        _figures(out_dir, sc, rows, trajs, policies)
    (out_dir / "report.md").write_text(_markdown(rec, man, sc, rows, policies, figures))
    return rec


def campaign_report(out_dir: str | Path, figures: bool = True) -> dict:
    """The docking campaign's report (:class:`~swarm.montecarlo.campaign.CampaignMission`):
    :func:`write_report`, and for a scenario with ``[faults]`` the outcome classes and NEES of
    :mod:`swarm.montecarlo.faults` added to the returned record under ``faults`` (not to ``report.json``)."""
    from swarm.montecarlo.faults import fault_summary
    from swarm.scenario import load_scenario

    rec = write_report(out_dir, figures=figures)
    if load_scenario(Path(out_dir) / SCENARIO_FILE).faults.enabled:
        rec["faults"] = fault_summary(read_runs(out_dir), read_trajectories(out_dir))
    return rec


def summary_text(rec: dict) -> str:
    """What ``swarm montecarlo`` prints of a docking campaign's record: per policy the docked count and
    the Table II means, the paired differences of time and effort, and the faults' table if any."""
    from swarm.montecarlo.faults import format_summary

    metrics = rec["metrics"]
    lines = [
        f"{rec['runs']} runs per policy" + (f", {rec['wall_s']:.1f} s wall" if rec.get("wall_s") else "")
    ]
    for pol, p in rec["policies"].items():
        parts = [f"docked {p['docked']}/{p['n_runs']}"]
        for m, (lab, unit, scale, dig) in metrics.items():
            d = p[m]
            if d["mean"] is not None:
                parts.append(f"{lab} {d['mean'] * scale:.{dig}f} {unit}")
        lines.append(f"  {pol:<6} " + ", ".join(parts))
    if "paired" in rec:
        base, other = rec["paired_policies"]
        for m in ("docking_time_s", list(metrics)[-1]):  # the time and the kind's effort
            d = rec["paired"][m]
            if d["mean_diff"] is None:
                continue
            ci = d["ci95"] or [float("nan")] * 2
            p = d["p_value"]
            lines.append(
                f"  {other} - {base} {m}: {d['mean_diff']:+.4g} [{ci[0]:+.4g}, {ci[1]:+.4g}] "
                f"({100 * d['relative']:+.1f} %), paired t p = {p if p is None else f'{p:.2g}'}"
            )
    if "faults" in rec:
        lines.append(format_summary(rec["faults"]))
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------ markdown


def _f(v, digits: int = 3, scale: float = 1.0) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v * scale:.{digits}f}"


def _cell(d: dict, scale: float, digits: int) -> str:
    """``mean ± std [lo, hi]``."""
    if d["mean"] is None:
        return "-"
    s = _f(d["mean"], digits, scale)
    if d["std"] is not None:
        s += f" ± {_f(d['std'], digits, scale)}"
    if d["ci95"] is not None:
        s += f" [{_f(d['ci95'][0], digits, scale)}, {_f(d['ci95'][1], digits, scale)}]"
    return s


def _pct(v) -> str:
    return "-" if v is None else f"{100 * v:+.1f} %"


def _p(v) -> str:
    if v is None:
        return "-"
    return f"{v:.2e}" if v < 1e-3 else f"{v:.3f}"


def _paper(pol: str, metrics: dict) -> dict | None:
    """The paper's Table II row of ``pol`` when it has every metric (the cube's campaigns), else None."""
    row = PAPER_TABLE_II.get(pol)
    return row if row is not None and all(m in row for m in metrics) else None


def _markdown(rec: dict, man: dict, sc, rows: list[dict], policies: tuple[str, ...], figures: bool) -> str:
    METRICS = {m: tuple(v) for m, v in rec["metrics"].items()}
    n_runs = rec["runs"]
    L = [f"# Monte Carlo: scenario `{sc.name}`, {n_runs} paired runs of {' and '.join(policies)}", ""]
    L.append(
        f"Generated by `swarm montecarlo` from `runs.csv` ({len(rows)} rows) in this directory. "
        f"Root seed {man['root_seed']}; run *i* has seed `{man['seed_rule']}` (column `seed`), the same "
        "for every policy, so the comparison is paired. Re-run one run exactly with "
        "`swarm sim scenario.toml --policy POLICY --seed SEED`."
    )
    if man.get("wall_s") is not None:
        L.append(f"Wall time of the campaign: {man['wall_s']:.1f} s.")
    L += ["", "## Dispersions", "", *_dispersion_table(sc), ""]

    L += ["## Table II analogue", ""]
    L.append(
        "Mean ± standard deviation [95 % confidence interval of the mean, Student t] over the docked runs; "
        "success rate with its exact (Clopper-Pearson) 95 % interval."
    )
    L.append("")
    head = (
        "| policy | runs | docked | " + " | ".join(f"{lab} [{u}]" for lab, u, _, _ in METRICS.values()) + " |"
    )
    L += [head, "|" + "---|" * (3 + len(METRICS))]
    for pol in policies:
        p = rec["policies"][pol]
        ci = p["success_ci95"]
        succ = "-" if p["success_rate"] is None else f"{100 * p['success_rate']:.1f} %"
        if ci is not None:
            succ += f" [{100 * ci[0]:.1f}, {100 * ci[1]:.1f}]"
        cells = [_cell(p[m], scale, dig) for m, (_, _, scale, dig) in METRICS.items()]
        L.append(f"| {pol} | {p['n_runs']} | {succ} | " + " | ".join(cells) + " |")
    for pol in policies:
        paper = _paper(pol, METRICS)
        if paper is not None:
            cells = [_f(paper[m], dig, scale) for m, (_, _, scale, dig) in METRICS.items()]
            L.append(f"| paper {pol} | 500 | 100 % | " + " | ".join(cells) + " |")
    L.append("")
    L.append(
        "Collisions: "
        + ", ".join(f"{pol} {rec['policies'][pol]['collisions']}" for pol in policies)
        + "; keep-out violations: "
        + ", ".join(f"{pol} {rec['policies'][pol]['keepout_violations']}" for pol in policies)
        + "."
    )
    L.append("")

    L += _failures(rows, policies, sc)
    if "paired" in rec:
        base, other = rec["paired_policies"]
        L += [f"## Paired differences ({other} − {base})", ""]
        L.append(
            f"Run by run over the {rec['paired']['docking_time_s']['n']} runs both policies docked: mean "
            "difference, its 95 % t interval, relative to the "
            f"{base} mean, the two-sided paired t-test (`scipy.stats.ttest_rel`) and the Wilcoxon "
            "signed-rank test (`scipy.stats.wilcoxon`); the paper's relative difference of the means beside."
        )
        L += [
            "",
            "| metric | mean difference | 95 % CI | relative | paired t p | Wilcoxon p | paper |",
            "|---|---|---|---|---|---|---|",
        ]
        for m, (lab, unit, scale, dig) in METRICS.items():
            d = rec["paired"][m]
            ci = (
                "-"
                if d["ci95"] is None
                else f"[{_f(d['ci95'][0], dig, scale)}, {_f(d['ci95'][1], dig, scale)}]"
            )
            paper = "-"
            if _paper(base, METRICS) is not None and _paper(other, METRICS) is not None:
                pa, pb = PAPER_TABLE_II[base][m], PAPER_TABLE_II[other][m]
                paper = _pct((pb - pa) / pa)
            L.append(
                f"| {lab} [{unit}] | {_f(d['mean_diff'], dig, scale)} | {ci} | {_pct(d['relative'])} | "
                f"{_p(d['p_value'])} | {_p(d['wilcoxon_p_value'])} | {paper} |"
            )
        L.append("")
        L += ["### Where the docking time goes", ""]
        L.append(
            "Mean time in each phase (entry of a mode to entry of the next; `start` is the initial HOLD "
            "until the first estimate converged), and the paired difference with its 95 % t interval."
        )
        L += [
            "",
            "| phase | " + " | ".join(f"{p} [s]" for p in policies) + f" | {other} − {base} [s] | 95 % CI |",
            "|---|" + "---|" * (len(policies) + 2),
        ]
        for ph in PHASES:
            means = [_f(rec["policies"][p]["phases_s"][ph]["mean"], 2) for p in policies]
            d = rec["paired_phases_s"][ph]
            ci = "-" if d["ci95"] is None else f"[{_f(d['ci95'][0], 2)}, {_f(d['ci95'][1], 2)}]"
            L.append(f"| {ph} | " + " | ".join(means) + f" | {_f(d['mean_diff'], 2)} | {ci} |")
        L.append("")
        L += _path_table(rows, policies)

    L += ["## Switching distances", ""]
    L += [
        "| policy | REORIENT entered at r [m] | ALIGN entered at r [m] | ALIGN by radius / stall / skipped |"
        " Algorithm 1 r1 fired |",
        "|---|---|---|---|---|",
    ]
    for pol in policies:
        mine = [r for r in rows if r["policy"] == pol]
        p = rec["policies"][pol]
        reo = [r["range_reorient_m"] for r in mine if r["range_reorient_m"] is not None]
        ali = [r["range_align_m"] for r in mine if r["range_align_m"] is not None]
        ab = p["align_by"]
        fired = f"{p['r1_fired']} of {len(mine)}" if pol == "mdp" else "-"
        L.append(
            f"| {pol} | {_range(reo)} | {_range(ali)} | "
            f"{ab['radius']} / {ab['stall']} / {ab['skipped']} | {fired} |"
        )
    mdp_rows = [r for r in rows if r["policy"] == "mdp" and r["min_pi2"] is not None]
    if mdp_rows:
        sig = np.array([r["sigma_pos_reorient_m"] for r in mdp_rows])
        dd = np.array([r["d_reorient"] for r in mdp_rows])
        pi2 = np.array([r["min_pi2"] for r in mdp_rows])
        a32 = np.array([r["max_a32"] for r in mdp_rows])
        thr = sc.mdp.pi2_threshold
        L += [
            "",
            "Algorithm 1 in REORIENT (MDP runs): mean max(σ_pos) over the decisions "
            f"{1000 * sig.mean():.2f} mm (range {1000 * sig.min():.2f}-{1000 * sig.max():.2f} mm), i.e. "
            f"σ_pos / σ_UWB = {sig.mean() / sc.mdp.sigma_uwb_m:.2f}; mean Mahalanobis d {dd.mean():.2f}; "
            f"largest A32 per run {a32.mean():.3f} on average (max {a32.max():.3f}); lowest π2 per run "
            f"{pi2.mean():.3f} on average (min {pi2.min():.3f}) against the threshold {thr:g}.",
        ]
    L.append("")
    if figures:
        L += ["## Figures", ""]
        captions = {
            "fig5_trajectories.png": "True trajectories of all runs, coloured by mode (paper Fig. 5).",
            "fig6_switching.png": "Ranges at which REORIENT and ALIGN were entered (paper Fig. 6).",
            "mode_timelines.png": "Mode of every run over time, runs sorted by docking time.",
            "paired_differences.png": "Run-by-run differences of docking time and total impulse.",
        }
        for name in FIGURES:
            L += [f"![{captions[name]}]({name})", "", f"*{captions[name]}*", ""]
    L += [
        "## Files",
        "",
        "`runs.csv` one row per run, policy and chaser (seeds, outcomes, mode entry times, Algorithm 1 "
        "summary, "
        "drawn dispersions); `trajectories.jsonl` the true trajectories (1 s samples); `scenario.toml` the "
        "scenario as run; `campaign.json` root seed, seed rule, policies; `report.json` the numbers above "
        "(`swarm montecarlo --json` format).",
        "",
    ]
    return "\n".join(L)


def _failures(rows: list[dict], policies: tuple[str, ...], sc) -> list[str]:
    """What the runs that did not dock have in common (contact outside tolerance, a contact the estimate
    announced but the truth never made), and whether the target had fired its thrusters."""
    bad = [r for r in rows if not r["docked"]]
    if not bad:
        return []
    g = sc.guidance
    target_effort = sc.kind(sc.chasers[0]).target_effort_key
    L = ["### Runs that did not dock", ""]
    L += [
        "| policy | not docked | contact outside tolerance: lateral / attitude / speed | no contact "
        "(final mode) | target fired (failed runs) | target fired (docked runs) |",
        "|---|---|---|---|---|---|",
    ]
    for pol in policies:
        mine = [r for r in rows if r["policy"] == pol]
        b = [r for r in mine if not r["docked"]]
        col = [r for r in b if r["collided"]]
        lat = sum(1 for r in col if (r["contact_lateral_m"] or 0.0) > g.contact_lateral_m)
        att = sum(1 for r in col if (r["contact_attitude_rad"] or 0.0) > g.contact_attitude_rad)
        spd = sum(1 for r in col if (r["contact_closing_m_s"] or 0.0) > g.contact_speed_m_s)
        none = [r for r in b if not r["collided"]]
        modes = ", ".join(sorted({r["final_mode"] for r in none})) or "-"
        fired_bad = sum(1 for r in b if r[target_effort] > 0)
        ok = [r for r in mine if r["docked"]]
        fired_ok = sum(1 for r in ok if r[target_effort] > 0)
        L.append(
            f"| {pol} | {len(b)} | {lat} / {att} / {spd} | {len(none)} ({modes}) | {fired_bad} of {len(b)} "
            f"| {fired_ok} of {len(ok)} |"
        )
    return [*L, ""]


def _range(v: list[float]) -> str:
    if not v:
        return "-"
    a = np.asarray(v)
    return f"{a.mean():.3f} (min {a.min():.3f}, max {a.max():.3f})"


def _path_table(rows: list[dict], policies: tuple[str, ...]) -> list[str]:
    L = [
        "Mean distance flown in each mode [m] (truth):",
        "",
        "| policy | " + " | ".join(MAIN_MODES) + " | total |",
        "|---|" + "---|" * (len(MAIN_MODES) + 1),
    ]
    for pol in policies:
        mine = [r for r in rows if r["policy"] == pol and r["docked"]]
        means = []
        total = 0.0
        for mode in MAIN_MODES:
            v = [r[f"path_{mode.lower()}_m"] or 0.0 for r in mine]
            m = float(np.mean(v)) if v else float("nan")
            total += m
            means.append(_f(m, 3))
        L.append(f"| {pol} | " + " | ".join(means) + f" | {_f(total, 3)} |")
    return [*L, ""]


def _dispersion_table(sc) -> list[str]:
    ini, d = sc.initial, sc.dispersions
    dist = "normal" if d.distribution == "normal" else "uniform ±√3σ"
    L = ["| quantity | distribution | σ | declared in |", "|---|---|---|---|"]
    L.append(
        f"| initial estimate error, position (per axis) | normal | {ini.sigma_position_m} m | "
        "`[initial] sigma_position_m` |"
    )
    L.append(
        f"| initial estimate error, velocity | normal | {ini.sigma_velocity_m_s} m/s | "
        "`[initial] sigma_velocity_m_s` |"
    )
    L.append(
        f"| initial estimate error, attitude | normal | {ini.sigma_attitude_deg} deg | "
        "`[initial] sigma_attitude_deg` |"
    )
    L.append(
        f"| UWB range noise | normal | {sc.uwb.sigma_m} m (NLOS p = {sc.uwb.nlos_probability}, "
        f"dropout p = {sc.uwb.dropout_probability}) | `[uwb]` |"
    )
    L.append(
        "| gyro noise and bias | ARW + Gauss-Markov | "
        f"{math.degrees(sc.gyro.gyro_noise_rad_s_rthz):.4g} deg/s/√Hz, "
        f"{sc.gyro.bias_instability_deg_h} deg/h | `[gyro]` |"
    )
    if sc.ahrs.enabled:
        L.append(f"| AHRS attitude | normal | {sc.ahrs.sigma_deg} deg | `[ahrs]` |")
    L.append(f"| camera features | normal | {sc.camera.feature_sigma_m} m | `[camera]` |")
    for name, unit in (
        ("position_sigma_m", "m"),
        ("velocity_sigma_m_s", "m/s"),
        ("attitude_sigma_deg", "deg"),
        ("mass_sigma_frac", ""),
        ("inertia_sigma_frac", ""),
    ):
        v = getattr(d, name)
        L.append(
            f"| {name.rsplit('_sigma', 1)[0].replace('_', ' ')} | {dist if v > 0 else 'off'} | "
            f"{v} {unit} | `[dispersions] {name}` |"
        )
    for kind_name in sc.kinds_used:  # each kind's own dispersions
        kd = getattr(sc.kinds, kind_name).dispersions
        for f in dataclasses.fields(kd):
            v = getattr(kd, f.name)
            L.append(
                f"| {f.name.split('_sigma')[0].replace('_deg', '').replace('_', ' ')} ({kind_name}) | "
                f"{dist if v > 0 else 'off'} | {v} | `[kinds.{kind_name}.dispersions] {f.name}` |"
            )
    return L


def finite_or_null(x):
    if isinstance(x, dict):
        return {k: finite_or_null(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [finite_or_null(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


# ------------------------------------------------------------------------------------------------- figures


def _mode_at(row: dict, t: np.ndarray) -> np.ndarray:
    """Index into ``["HOLD", *MAIN_MODES]`` of the mode at times ``t`` (from the entry times), -1 after
    contact."""
    out = np.zeros(t.shape, dtype=int)
    for k, mode in enumerate(MAIN_MODES, start=1):
        te = row[f"t_{mode.lower()}_s"]
        if te is not None:
            out[t >= te] = k
    if row["docking_time_s"] is not None:
        out[t > row["docking_time_s"]] = -1
    return out


def _figures(out_dir: Path, sc, rows: list[dict], trajs: list[dict], policies: tuple[str, ...]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by_key = {(r["run"], r["policy"], r["chaser"]): r for r in rows}
    _fig5(plt, out_dir, sc, by_key, trajs, policies)
    _fig6(plt, out_dir, sc, rows, policies)
    _timelines(plt, out_dir, rows, policies)
    _paired(plt, out_dir, rows, policies, sc)


def _fig5(plt, out_dir, sc, by_key, trajs, policies) -> None:
    """Top row: 3-D trajectories. Bottom row: the same in the plane of the docking-face normal ``n`` and the
    initial line of sight, near the target (keep-out sphere, alignment point, fixed radii)."""
    from matplotlib.collections import LineCollection
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    from swarm.core.guidance import docking_geometry

    names = ["HOLD", *MAIN_MODES]
    k_pol = len(policies)
    fig = plt.figure(figsize=(5.5 * k_pol, 10))
    chaser = next(v for v in sc.vehicles.values() if v.role == "chaser")
    p_t = np.asarray(sc.vehicles[chaser.target].position_m)
    n_nav, _, _ = docking_geometry(sc.guidance, p_t, sc.q0(chaser.target))
    los = np.asarray(chaser.position_m) - p_t
    e2 = los - (los @ n_nav) * n_nav
    e2 /= np.linalg.norm(e2)
    basis = np.vstack([e2, n_nav])  # plane coordinates: along the LOS (normal removed), along n
    g = sc.guidance
    for k, pol in enumerate(policies):
        segs: dict[int, list] = {i: [] for i in range(len(names))}
        n = 0
        for tr in trajs:
            row = by_key.get((tr["run"], tr["policy"], tr["chaser"]))
            if tr["policy"] != pol or row is None:
                continue
            n += 1
            t, p = np.asarray(tr["t_s"]), np.asarray(tr["p_nav"])
            m = _mode_at(row, t)
            for a in range(len(t) - 1):
                if m[a] >= 0:
                    segs[m[a]].append(p[a : a + 2])
        alpha = float(np.clip(30.0 / max(n, 1), 0.04, 0.6))
        ax = fig.add_subplot(2, k_pol, k + 1, projection="3d")
        for i, name in enumerate(names):
            if segs[i]:
                ax.add_collection3d(
                    Line3DCollection(segs[i], colors=MODE_COLOURS[name], linewidths=0.5, alpha=alpha)
                )
        ax.scatter(*p_t, color="k", marker="s", s=40)
        ax.plot(*np.c_[p_t, p_t + g.align_distance_m * n_nav], color="k", lw=1.5)
        ax.scatter(*chaser.position_m, color="k", marker="o", s=20)
        lo = np.minimum(p_t, chaser.position_m) - 0.2
        hi = np.maximum(p_t, chaser.position_m) + 0.2
        ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
        ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]", title=f"{pol}: {n} runs")
        ax.view_init(elev=25, azim=-60)
        ax2 = fig.add_subplot(2, k_pol, k_pol + k + 1)
        for i, name in enumerate(names):
            if segs[i]:
                flat = [(np.asarray(s_) - p_t) @ basis.T for s_ in segs[i]]
                ax2.add_collection(
                    LineCollection(flat, colors=MODE_COLOURS[name], linewidths=0.6, alpha=alpha)
                )
        ang = np.linspace(0, 2 * np.pi, 200)
        for radius, style, label in (
            (g.keepout_radius_m, "k-", "keep-out"),
            (sc.fixed.r1_m, "k--", f"r1 = {sc.fixed.r1_m} m"),
            (sc.fixed.r2_m, "k:", f"r2 = {sc.fixed.r2_m} m"),
        ):
            ax2.plot(radius * np.cos(ang), radius * np.sin(ang), style, lw=0.8, label=label)
        ax2.plot([0, 0], [0, g.align_distance_m], "k", lw=1.5)
        ax2.plot(0, g.align_distance_m, "k^", ms=6, label="alignment point")
        ax2.plot(0, 0, "ks", ms=6)
        ax2.set(
            xlim=(-0.35, 0.95),
            ylim=(-0.45, 0.85),
            aspect="equal",
            xlabel="along the initial line of sight, normal removed [m]",
            ylabel="along the face normal [m]",
            title=f"{pol}: near the target, plane of LOS and face normal",
        )
        if k == 0:
            handles = [plt.Line2D([], [], color=MODE_COLOURS[nm], lw=2, label=nm) for nm in names]
            ax2.legend(handles=handles + ax2.get_legend_handles_labels()[0], fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(out_dir / "fig5_trajectories.png", dpi=DPI)
    plt.close(fig)


def _fig6(plt, out_dir, sc, rows, policies) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    bins = np.linspace(0.1, max(0.85, sc.mdp.r_t_m), 60)
    for ax, key, title, fixed in (
        (axes[0], "range_reorient_m", "entering REORIENT (r2)", sc.fixed.r2_m),
        (axes[1], "range_align_m", "entering ALIGN (r1 or keep-out stall)", sc.fixed.r1_m),
    ):
        for pol in policies:
            v = [r[key] for r in rows if r["policy"] == pol and r[key] is not None]
            if v:
                ax.hist(v, bins=bins, alpha=0.6, label=f"{pol} ({len(v)} runs)")
        ax.axvline(fixed, color="k", ls="--", lw=1, label=f"fixed radius {fixed} m")
        ax.set(xlabel="range to target [m]", ylabel="runs", title=title)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "fig6_switching.png", dpi=DPI)
    plt.close(fig)


def _timelines(plt, out_dir, rows, policies) -> None:
    from matplotlib.colors import ListedColormap

    names = ["HOLD", *MAIN_MODES]
    t_max = max([r["sim_time_s"] for r in rows] + [1.0])
    t = np.arange(0.0, t_max + 0.5, 0.5)
    cmap = ListedColormap(["white"] + [MODE_COLOURS[n] for n in names])
    fig, axes = plt.subplots(1, len(policies), figsize=(5.5 * len(policies), 4.5), squeeze=False)
    for ax, pol in zip(axes[0], policies, strict=True):
        mine = sorted((r for r in rows if r["policy"] == pol), key=lambda r: r["docking_time_s"] or math.inf)
        img = np.array([_mode_at(r, t) + 1 for r in mine]) if mine else np.zeros((1, t.size))
        ax.imshow(
            img,
            aspect="auto",
            cmap=cmap,
            vmin=0,
            vmax=len(names),
            interpolation="nearest",
            extent=(0.0, t[-1], len(mine), 0),
        )
        ax.set(xlabel="time [s]", ylabel="run (sorted by docking time)", title=pol)
    handles = [plt.Rectangle((0, 0), 1, 1, color=MODE_COLOURS[n]) for n in names]
    axes[0][-1].legend(handles, names, loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "mode_timelines.png", dpi=DPI)
    plt.close(fig)


def _paired(plt, out_dir, rows, policies, sc) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    kind = sc.kind(sc.chasers[0])
    if len(policies) >= 2:
        base, other = policies[0], policies[1]
        by = {(r["run"], r["chaser"], r["policy"]): r for r in rows}
        for ax, m, unit in ((axes[0], "docking_time_s", "s"), (axes[1], kind.effort_key, kind.effort_unit)):
            d = []
            for (run, ch, pol), r in by.items():
                s = by.get((run, ch, other))
                if pol == base and s is not None and r["docked"] and s["docked"]:
                    d.append(s[m] - r[m])
            if d:
                ax.hist(d, bins=40, color="#555555")
                ax.axvline(np.mean(d), color="r", lw=1.5, label=f"mean {np.mean(d):+.3g} {unit}")
            if m in PAPER_TABLE_II.get(base, {}) and m in PAPER_TABLE_II.get(other, {}):
                rel = PAPER_TABLE_II[other][m] / PAPER_TABLE_II[base][m] - 1.0
                ref = np.mean([r[m] for r in rows if r["policy"] == base and r["docked"]] or [np.nan])
                ax.axvline(
                    rel * ref,
                    color="b",
                    ls="--",
                    lw=1.5,
                    label=f"paper's {100 * rel:+.1f} % of our {base} mean",
                )
            ax.axvline(0.0, color="k", lw=0.8)
            ax.set(xlabel=f"{other} − {base}, {m} [{unit}]", ylabel="runs")
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "paired_differences.png", dpi=DPI)
    plt.close(fig)
