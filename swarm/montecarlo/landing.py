"""``swarm montecarlo landing``: a paired campaign of the UAV landing (issue 15; paper Figs. 9-10).

Run ``r`` of every policy flies from the same seed (:func:`swarm.montecarlo.campaign.run_seed`), so the
same start, IMU biases, anchor reach and noise: the policies are compared run by run (paired differences,
``t`` and Wilcoxon tests, as the docking campaign). Rows go to ``runs.csv`` as they finish, the decimated
trajectories to ``trajectories.jsonl``; ``report.md`` has the table, the paired differences, what they mean,
and the figures: trajectories coloured by mode (Fig. 9), landing error and energy distributions (Fig. 10)
and the deviation points against the navigation quality.
"""

from __future__ import annotations

import csv
import json
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy import stats

from swarm.montecarlo.campaign import default_workers, run_seed
from swarm.montecarlo.stats import CONFIDENCE, describe

COLUMNS = (
    "run",
    "seed",
    "policy",
    "landed",
    "aborted",
    "landed_off_pad",
    "landing_error_m",
    "landing_time_s",
    "energy_j",
    "deviation_distance_m",
    "retries",
    "sim_time_s",
    "start_x_m",
    "start_y_m",
    "start_z_m",
    "uwb_range_m",
)
MODES = ("CRUISE", "DEVIATE", "DESCEND", "FINAL", "CLIMB", "LANDED", "ABORT")


def _one(args) -> tuple[dict, dict]:
    sc, policy, run, seed = args
    from swarm.sim.landing import run_landing

    r = run_landing(sc, policy, seed, record_series=True)
    row = {"run": run, "seed": seed, "policy": policy}
    for k in (
        "landed",
        "aborted",
        "landed_off_pad",
        "landing_error_m",
        "landing_time_s",
        "energy_j",
        "deviation_distance_m",
        "retries",
        "sim_time_s",
        "uwb_range_m",
    ):
        row[k] = r[k]
    row["start_x_m"], row["start_y_m"], row["start_z_m"] = r["start_m"]
    s = r["series"]
    step = 10  # the series is at 10 Hz: keep 1 Hz
    traj = {
        "run": run,
        "policy": policy,
        "t_s": s["t_s"][::step],
        "p": [[round(v, 3) for v in p] for p in s["p_true_nav"][::step]],
        "mode": [MODES.index(m) for m in s["mode"][::step]],
        "sigma_h_m": [round(v, 4) for v in s["sigma_h_m"][::step]],
    }
    return row, traj


def run_landing_campaign(
    sc,
    runs: int,
    root_seed: int,
    policies: tuple[str, ...],
    out_dir: Path,
    workers: int | None = None,
    progress: bool = True,
) -> dict:
    """Run the campaign into ``out_dir`` (module docstring); returns the statistics of ``report.md``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    jobs = [(sc, p, r, run_seed(root_seed, r)) for r in range(runs) for p in policies]
    rows, trajs = [], []
    t0 = time.perf_counter()
    workers = workers or default_workers()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), unit="run", desc="landing campaign")
    with (
        open(out_dir / "runs.csv", "w", newline="") as fh_rows,
        open(out_dir / "trajectories.jsonl", "w") as fh_t,
    ):
        w = csv.DictWriter(fh_rows, fieldnames=COLUMNS)
        w.writeheader()
        if workers == 1:
            results = map(_one, jobs)
            pool = None
        else:
            pool = ProcessPoolExecutor(workers)
            results = pool.map(_one, jobs, chunksize=4)
        try:
            for row, traj in results:
                w.writerow(row)
                fh_rows.flush()
                fh_t.write(json.dumps(traj) + "\n")
                rows.append(row)
                trajs.append(traj)
                if bar is not None:
                    bar.update(1)
        finally:
            if pool is not None:
                pool.shutdown()
            if bar is not None:
                bar.close()
    wall = time.perf_counter() - t0
    rec = summarize(rows, policies)
    rec.update(
        {"scenario": sc.name, "runs": runs, "root_seed": root_seed, "wall_s": wall, "workers": workers}
    )
    write_report(out_dir, rec, rows, trajs, policies, sc)
    return rec


def _rate(k: int, n: int) -> dict:
    if n == 0:
        return {"n": 0, "k": 0, "rate": None, "ci95": None}
    ci = stats.binomtest(k, n).proportion_ci(CONFIDENCE, method="exact")
    return {"n": n, "k": k, "rate": k / n, "ci95": [float(ci.low), float(ci.high)]}


def _paired(rows: list[dict], base: str, other: str, metric: str) -> dict:
    by = {(r["run"], r["policy"]): r for r in rows}
    a, b = [], []
    for (run, pol), r in sorted(by.items()):
        if pol != base:
            continue
        s = by.get((run, other))
        if s is None or not (r["landed"] and s["landed"]) or r[metric] is None or s[metric] is None:
            continue
        a.append(float(r[metric]))
        b.append(float(s[metric]))
    diff = np.asarray(b) - np.asarray(a)
    d = describe(diff)
    out = {
        "n": d["n"],
        "mean_diff": d["mean"],
        "ci95": d["ci95"],
        "relative": d["mean"] / float(np.mean(a)) if d["n"] and np.mean(a) else None,
        "p_value": None,
        "wilcoxon_p_value": None,
    }
    if d["n"] >= 2 and np.any(diff != diff[0]):
        out["p_value"] = float(stats.ttest_rel(b, a).pvalue)
    if d["n"] >= 2 and np.any(diff != 0):
        out["wilcoxon_p_value"] = float(stats.wilcoxon(diff).pvalue)
    return out


METRICS = ("energy_j", "landing_time_s", "landing_error_m", "deviation_distance_m")


def summarize(rows: list[dict], policies: tuple[str, ...]) -> dict:
    rec: dict = {"policies": {}, "paired": {}}
    for p in policies:
        rs = [r for r in rows if r["policy"] == p]
        landed = [r for r in rs if r["landed"]]
        rec["policies"][p] = {
            "landed": _rate(len(landed), len(rs)),
            "aborted": sum(1 for r in rs if r["aborted"]),
            "landed_off_pad": sum(1 for r in rs if r["landed_off_pad"]),
            "retried": sum(1 for r in rs if r["retries"]),
            **{m: describe([r[m] for r in landed if r[m] is not None]) for m in METRICS},
        }
    base = policies[0]
    for other in policies[1:]:
        rec["paired"][f"{other}-{base}"] = {m: _paired(rows, base, other, m) for m in METRICS[:3]}
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
                    m: _paired(sub_rows, base, other, m) for m in ("energy_j", "landing_time_s")
                }
    return rec


def _fmt(d: dict, digits: int = 2) -> str:
    if d.get("mean") is None:
        return "-"
    ci = d.get("ci95")
    return f"{d['mean']:.{digits}f}" + (f" [{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]" if ci else "")


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


def write_report(
    out_dir: Path, rec: dict, rows: list[dict], trajs: list[dict], policies, sc, figures: bool = True
) -> None:
    lines = [
        f"# Landing campaign: {rec['scenario']}, {rec['runs']} paired runs, root seed {rec['root_seed']}",
        "",
    ]
    lines.append(
        f"{len(rows)} runs in {rec['wall_s']:.1f} s on {rec['workers']} workers. Dispersions: start "
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
