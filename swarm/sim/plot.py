"""``swarm sim --plot``: what a GNC engineer looks at first after a docking run.

Left: the 3-D trajectory of each chaser (truth solid, estimate dotted) coloured by guidance mode, the mode
switch points, the target with its docking-face normal, and the r_t / r2 / r1 spheres the switcher used.
Right: the estimation error per axis with its +-3 sigma envelope from the filter's covariance.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

MODE_COLOURS = {
    "HOLD": "#7f7f7f",
    "APPROACH": "#1f77b4",
    "REORIENT": "#ff7f0e",
    "ALIGN": "#2ca02c",
    "DOCK": "#d62728",
    "DOCKED": "#9467bd",
    "ABORT": "#8c564b",
}


def _sphere(ax, centre, radius, colour, label):
    u, v = np.mgrid[0 : 2 * np.pi : 24j, 0 : np.pi : 12j]
    x = centre[0] + radius * np.cos(u) * np.sin(v)
    y = centre[1] + radius * np.sin(u) * np.sin(v)
    z = centre[2] + radius * np.cos(v)
    ax.plot_wireframe(x, y, z, color=colour, linewidth=0.3, alpha=0.35, label=label)


def plot_run(res: dict, scenario, path: str | Path) -> None:
    """Draw the run summary ``res`` (with series) of ``scenario`` into the PNG ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from swarm.core.guidance import docking_geometry

    chasers = res["chasers"]
    fig = plt.figure(figsize=(15, 4.2 * max(1, len(chasers)) + 1.5))
    rows = len(chasers)
    for row, (cid, c) in enumerate(chasers.items()):
        s = c.get("series")
        if not s or not s["t_s"]:
            continue
        t = np.asarray(s["t_s"])
        pt = np.asarray(s["p_true_nav"])
        pe = np.asarray(s["p_est_nav"])
        cov = np.asarray(s["cov_pos"])
        modes = np.asarray(s["mode"])
        ax = fig.add_subplot(rows, 2, 2 * row + 1, projection="3d")
        for mode, colour in MODE_COLOURS.items():
            m = modes == mode
            if m.any():
                ax.scatter(*pt[m].T, s=2, color=colour, label=mode)
        ax.plot(*pe.T, ":", color="k", linewidth=0.6, label="estimate")
        for ev in c["modes"]:
            i = min(np.searchsorted(t, ev["t_s"]), len(t) - 1)
            ax.scatter(*pt[i], marker="x", s=40, color=MODE_COLOURS.get(ev["mode"], "k"))
        tid = scenario.vehicles[cid].target
        spec = scenario.vehicles[tid]
        p_t = np.asarray(spec.position_m)
        n_nav, _, _ = docking_geometry(scenario.guidance, p_t, scenario.q0(tid))
        ax.scatter(*p_t, marker="s", s=60, color="k", label="target")
        ax.quiver(*p_t, *(0.3 * n_nav), color="k")
        if res["policy"] == "mdp":
            _sphere(ax, p_t, scenario.mdp.r_t_m, "#bbbbbb", "r_t")
        _sphere(ax, p_t, c["r2_m"], MODE_COLOURS["REORIENT"], "r2")
        _sphere(ax, p_t, c["r1_m"], MODE_COLOURS["ALIGN"], "r1")
        _sphere(ax, p_t, scenario.guidance.keepout_radius_m, "#d62728", "keep-out")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m]")
        status = f"docked at {c['docking_time_s']:.1f} s" if c["docked"] else "not docked"
        ax.set_title(f"{cid} ({res['policy']}, seed {res['seed']}): {status}")
        ax.legend(fontsize=6, loc="upper left", markerscale=3)

        ax2 = fig.add_subplot(rows, 2, 2 * row + 2)
        err = pe - pt
        sig = np.sqrt(np.maximum(np.diagonal(cov, axis1=1, axis2=2), 0.0))
        for i, (name, colour) in enumerate(zip("xyz", ("#1f77b4", "#ff7f0e", "#2ca02c"), strict=True)):
            ax2.plot(t, 100 * err[:, i], color=colour, linewidth=0.8, label=f"{name} error")
            ax2.plot(t, 300 * sig[:, i], "--", color=colour, linewidth=0.6)
            ax2.plot(t, -300 * sig[:, i], "--", color=colour, linewidth=0.6)
        for ev in c["modes"]:
            ax2.axvline(ev["t_s"], color=MODE_COLOURS.get(ev["mode"], "k"), linewidth=0.6, alpha=0.6)
            ax2.text(ev["t_s"], ax2.get_ylim()[1] * 0.9, ev["mode"], fontsize=6, rotation=90, va="top")
        ax2.set_xlabel("t [s]")
        ax2.set_ylabel("position error [cm] (dashed: +-3 sigma)")
        ax2.set_title("estimation error per axis, frame nav")
        ax2.legend(fontsize=7)
        ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
