"""``swarm analyze anchors``: the section V-D study of :mod:`swarm.analysis.anchors` written to a directory.

Files: ``anchors_grid.csv`` (every grid point: steady-state ``max(sigma_pos)`` and ALIGN probability for
the scenario's layout and the optimised one), ``anchors.json`` (the numbers of ``anchors.md``),
``anchors.md``, and the heatmaps ``anchors_sigma.png``, ``anchors_pi_align.png`` and ``anchors_layout.png``.
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import numpy as np

from swarm.analysis.anchors import (
    AnchorStudyParams,
    align_probability,
    grid,
    optimise_layout,
    periodic_steady_state,
    sigma_map,
)


def _point_record(sc, params, p, sigma) -> dict:
    return {
        "point_m": [float(v) for v in p],
        "sigma_pos_max_m": float(sigma),
        "pi_align": float(align_probability(sigma, sc, params)),
    }


def run_study(sc, params: AnchorStudyParams, out_dir: str | Path, optimise: bool = True) -> dict:
    """Run the study and write its files into ``out_dir``; return the ``anchors.json`` record."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    axes, pts = grid(sc, params)
    ok = np.all(np.isfinite(pts), axis=1)
    sig = sigma_map(sc, pts, method="scipy")
    pi2 = align_probability(sig, sc, params)
    rec: dict = {
        "scenario": sc.name,
        "grid": {
            "min_m": [float(a[0]) for a in axes],
            "max_m": [float(a[-1]) for a in axes],
            "spacing_m": params.spacing_m,
            "points": int(ok.sum()),
        },
        "chain": {
            "r2_m": sc.fixed.r2_m if params.r2_m is None else params.r2_m,
            "d": params.d,
            "r_d_m": sc.mdp.r_d_m,
            "sigma_uwb_m": sc.mdp.sigma_uwb_m,
            "pi2_threshold": sc.mdp.pi2_threshold,
        },
        "model": {
            "accel_psd_m2_s3": sc.estimator.accel_psd_m2_s3,
            "sigma_range_m": sc.estimator.sigma_range_m,
            "cycle_s": len(sc.anchors_m) / sc.uwb.rate_hz,
        },
    }
    rec["paper"] = _layout_record(sc, params, np.asarray(sc.anchors_m, dtype=float), pts, sig, pi2)
    for name, vid in (("chaser_start", next(iter(sc.chasers))),):
        p = np.asarray(sc.vehicles[vid].position_m, dtype=float)
        rec["paper"][name] = _point_record(sc, params, p, sigma_map(sc, p[None])[0])
    tgt = sc.vehicles[next(iter(sc.chasers))].target
    p_t = np.asarray(sc.vehicles[tgt].position_m, dtype=float)
    rec["paper"]["target"] = _point_record(sc, params, p_t, sigma_map(sc, p_t[None])[0])
    # the stacked-cycle DARE against the filter's own round robin, tick by tick, at the best and worst points
    rec["validation"] = {}
    for which in ("best", "worst"):
        p = np.asarray(rec["paper"][which]["point_m"])
        before, after = periodic_steady_state(sc, p, cycles=1500)
        rec["validation"][which] = {
            "point_m": p.tolist(),
            "dare_sigma_pos_max_m": rec["paper"][which]["sigma_pos_max_m"],
            "round_robin_before_last_range_m": before,
            "round_robin_after_last_range_m": after,
        }
    sig_opt = pi2_opt = None
    if optimise:
        opt = optimise_layout(sc, params)
        anchors_opt = opt["anchors_m"]
        sig_opt = sigma_map(sc, pts, anchors_opt, method="scipy")
        pi2_opt = align_probability(sig_opt, sc, params)
        rec["optimised"] = _layout_record(sc, params, anchors_opt, pts, sig_opt, pi2_opt)
        rec["optimised"]["optimiser"] = {k: v for k, v in opt.items() if k != "anchors_m"}
        rec["gain"] = {
            "worst_pi_align": rec["optimised"]["worst"]["pi_align"] - rec["paper"]["worst"]["pi_align"],
            "worst_sigma_pos_max_m": rec["optimised"]["worst"]["sigma_pos_max_m"]
            - rec["paper"]["worst"]["sigma_pos_max_m"],
            "mean_pi_align": rec["optimised"]["mean_pi_align"] - rec["paper"]["mean_pi_align"],
        }
    rec["wall_s"] = time.perf_counter() - t0
    _write_csv(out_dir / "anchors_grid.csv", pts, ok, sig, pi2, sig_opt, pi2_opt)
    (out_dir / "anchors.json").write_text(json.dumps(rec, indent=1) + "\n")
    _heatmaps(out_dir, sc, params, axes, sig, pi2, sig_opt, pi2_opt, rec)
    (out_dir / "anchors.md").write_text(_markdown(rec))
    return rec


def _layout_record(sc, params, anchors, pts, sig, pi2) -> dict:
    ok = np.isfinite(sig)
    i_best = int(np.nanargmin(sig))
    i_worst = int(np.nanargmax(sig))
    return {
        "anchors_m": np.asarray(anchors).round(6).tolist(),
        "best": _point_record(sc, params, pts[i_best], sig[i_best]),
        "worst": _point_record(sc, params, pts[i_worst], sig[i_worst]),
        "mean_sigma_pos_max_m": float(np.mean(sig[ok])),
        "mean_pi_align": float(np.mean(pi2[ok])),
        "fraction_pi_align_above_threshold": float(np.mean(pi2[ok] > sc.mdp.pi2_threshold)),
    }


def _write_csv(path, pts, ok, sig, pi2, sig_opt, pi2_opt) -> None:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        head = ["x_m", "y_m", "z_m", "sigma_pos_max_paper_m", "pi_align_paper"]
        if sig_opt is not None:
            head += ["sigma_pos_max_optimised_m", "pi_align_optimised"]
        w.writerow(head)
        for i in np.flatnonzero(ok):
            row = [*(repr(float(v)) for v in pts[i]), repr(float(sig[i])), repr(float(pi2[i]))]
            if sig_opt is not None:
                row += [repr(float(sig_opt[i])), repr(float(pi2_opt[i]))]
            w.writerow(row)


def _signed(x: float, digits: int) -> str:
    """``+0.000`` rather than ``-0.000`` for a difference that rounds to zero."""
    return f"{round(x, digits) + 0.0:+.{digits}f}"


def _fmt_point(p) -> str:
    return "(" + ", ".join(f"{round(v, 6) + 0.0:.2f}" for v in p) + ")"


def _markdown(rec: dict) -> str:
    g, ch = rec["grid"], rec["chain"]
    L = [f"# Section V-D: anchor placement, scenario `{rec['scenario']}`", ""]
    L.append(
        f"Steady-state position covariance of the translation filter (stacked round-robin cycle of "
        f"{rec['model']['cycle_s'] * 1000:.0f} ms, acceleration PSD "
        f"{rec['model']['accel_psd_m2_s3']:g} m²/s³, "
        f"range noise {rec['model']['sigma_range_m']} m; `scipy.linalg.solve_discrete_are`) over "
        f"{g['points']} grid points {_fmt_point(g['min_m'])} to {_fmt_point(g['max_m'])} m, spacing "
        f"{g['spacing_m']} m; ALIGN probability π2 of Algorithm 1's chain at its worst point of the REORIENT "
        f"leg (r2 = {ch['r2_m']} m, d = {ch['d']}, r_d = {ch['r_d_m']} m, σ_UWB = {ch['sigma_uwb_m']} m); "
        f"Algorithm 1 aligns when π2 ≤ {ch['pi2_threshold']}."
    )
    L += ["", "| layout | point | where [m] | max σ_pos [mm] | π2 (ALIGN) |", "|---|---|---|---|---|"]
    for lay in ("paper", "optimised"):
        if lay not in rec:
            continue
        for which in ("best", "worst", "chaser_start", "target"):
            if which not in rec[lay]:
                continue
            r = rec[lay][which]
            L.append(
                f"| {lay} | {which} | {_fmt_point(r['point_m'])} | {1000 * r['sigma_pos_max_m']:.2f} | "
                f"{r['pi_align']:.3f} |"
            )
    L.append("")
    for lay in ("paper", "optimised"):
        if lay in rec:
            r = rec[lay]
            L.append(
                f"- {lay} layout: anchors {', '.join(_fmt_point(a) for a in r['anchors_m'])}; mean max σ_pos "
                f"{1000 * r['mean_sigma_pos_max_m']:.2f} mm, mean π2 {r['mean_pi_align']:.3f}, π2 above the "
                f"threshold at {100 * r['fraction_pi_align_above_threshold']:.1f} % of the points."
            )
    if "gain" in rec:
        gn, o = rec["gain"], rec["optimised"]["optimiser"]
        L.append(
            f"- gain of the optimised layout over the paper's (anchors anywhere on the faces of the "
            f"mothership box: every choice of 4 of its 8 corners, then differential evolution over the faces "
            f"from the best one; "
            f"{o['evaluations']} layouts evaluated on a coarser grid, worst max σ_pos there: paper "
            f"{1000 * o['paper_worst_sigma_coarse_m']:.2f} mm, best corners "
            f"{1000 * o['best_corner_worst_sigma_coarse_m']:.2f} mm, face search "
            f"{1000 * o['face_search_worst_sigma_coarse_m']:.2f} mm): worst-case π2 "
            f"{_signed(gn['worst_pi_align'], 3)}, worst-case max σ_pos "
            f"{_signed(1000 * gn['worst_sigma_pos_max_m'], 2)} mm, "
            f"mean π2 {_signed(gn['mean_pi_align'], 3)}. Of the {o['corner_layouts_observable']} corner "
            f"choices that observe the position, the second best has a worst max σ_pos of "
            f"{1000 * o['second_corner_worst_sigma_coarse_m']:.2f} mm and the median one "
            f"{1000 * o['median_corner_worst_sigma_coarse_m']:.2f} mm on the coarse grid."
        )
    L += [
        "",
        "Check of the stacked-cycle DARE against the filter's own round robin iterated tick by tick:",
        "",
    ]
    L += [
        "| point | where [m] | DARE [mm] | round robin, before / after the last range of a cycle [mm] |",
        "|---|---|---|---|",
    ]
    for which, v in rec["validation"].items():
        L.append(
            f"| {which} | {_fmt_point(v['point_m'])} | {1000 * v['dare_sigma_pos_max_m']:.2f} | "
            f"{1000 * v['round_robin_before_last_range_m']:.2f} / "
            f"{1000 * v['round_robin_after_last_range_m']:.2f} |"
        )
    L += [
        "",
        "![max sigma_pos](anchors_sigma.png)",
        "",
        "![pi_align](anchors_pi_align.png)",
        "",
        "![layouts](anchors_layout.png)",
        "",
    ]
    return "\n".join(L)


def _heatmaps(out_dir, sc, params, axes, sig, pi2, sig_opt, pi2_opt, rec) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xs, ys, zs = axes
    shape = (len(xs), len(ys), len(zs))
    z_pick = sorted({float(v.position_m[2]) for v in sc.vehicles.values()})
    if len(z_pick) == 2:
        z_pick = [z_pick[0], 0.5 * (z_pick[0] + z_pick[1]), z_pick[1]]
    k_idx = [int(np.argmin(np.abs(zs - z))) for z in z_pick]
    layouts = [("paper", sig, pi2, np.asarray(sc.anchors_m))]
    if sig_opt is not None:
        layouts.append(("optimised", sig_opt, pi2_opt, np.asarray(rec["optimised"]["anchors_m"])))
    for fname, key, label, vmin, vmax, cmap in (
        ("anchors_sigma.png", 1, "steady-state max σ_pos [mm]", None, None, "viridis"),
        ("anchors_pi_align.png", 2, "π2 = P(ALIGN), worst point of REORIENT", None, None, "RdYlGn"),
    ):
        vals = [lay[key].reshape(shape) * (1000.0 if key == 1 else 1.0) for lay in layouts]
        lo = np.nanmin([np.nanmin(v) for v in vals]) if vmin is None else vmin
        hi = np.nanmax([np.nanmax(v) for v in vals]) if vmax is None else vmax
        fig, axs = plt.subplots(
            len(layouts),
            len(k_idx),
            figsize=(4.2 * len(k_idx), 3.8 * len(layouts)),
            squeeze=False,
            layout="constrained",
        )
        for r, (name, *_rest, anchors) in enumerate(layouts):
            for c, k in enumerate(k_idx):
                ax = axs[r][c]
                im = ax.imshow(
                    vals[r][:, :, k].T,
                    origin="lower",
                    extent=(xs[0], xs[-1], ys[0], ys[-1]),
                    vmin=lo,
                    vmax=hi,
                    cmap=cmap,
                    aspect="equal",
                )
                if key == 2:
                    ax.contour(
                        xs, ys, vals[r][:, :, k].T, levels=[sc.mdp.pi2_threshold], colors="k", linewidths=1
                    )
                ax.plot(anchors[:, 0], anchors[:, 1], "w^", mec="k", ms=6)
                for v in sc.vehicles.values():
                    ax.plot(v.position_m[0], v.position_m[1], "ko" if v.role == "chaser" else "ks", ms=5)
                ax.set(
                    title=f"{name}, z = {round(float(zs[k]), 6) + 0.0:.2f} m", xlabel="x [m]", ylabel="y [m]"
                )
                ax.set_xlim(min(xs[0], anchors[:, 0].min() - 0.1), xs[-1])
                ax.set_ylim(min(ys[0], anchors[:, 1].min() - 0.1), ys[-1])
        fig.colorbar(im, ax=axs, label=label, shrink=0.9)
        fig.savefig(out_dir / fname, dpi=80)
        plt.close(fig)
    fig = plt.figure(figsize=(6, 5))
    ax = fig.add_subplot(projection="3d")
    h = np.asarray(params.mothership_half_extents_m)
    for s1 in (-1, 1):
        for s2 in (-1, 1):
            for axis in range(3):
                a = np.zeros((2, 3))
                a[:, axis] = [-h[axis], h[axis]]
                o = [i for i in range(3) if i != axis]
                a[:, o[0]] = s1 * h[o[0]]
                a[:, o[1]] = s2 * h[o[1]]
                ax.plot(*a.T, color="0.6", lw=0.8)
    for name, *_rest, anchors in layouts:
        ax.scatter(*anchors.T, s=40, marker="^", label=f"{name} anchors")
    for v in sc.vehicles.values():
        ax.scatter(*v.position_m, color="k", marker="o" if v.role == "chaser" else "s", s=25)
    ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]", title="mothership box and anchor layouts")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "anchors_layout.png", dpi=80)
    plt.close(fig)
