"""Throwaway: true vs estimated lateral port offset through DOCK, run 30 (seed 31145354, fixed) with the
code the BENCHMARKS table measured (03d2bec) and with HEAD; plus the target's displacement."""

from __future__ import annotations

import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

fig, axs = plt.subplots(1, 2, figsize=(9, 3.2), sharey=True)
for ax, (path, title) in zip(
    axs, [(sys.argv[1], "03d2bec (BENCHMARKS table)"), (sys.argv[2], "HEAD (station fix merged)")]
):
    tr = [r for r in json.load(open(path))["trace"] if r["mode"] == "DOCK"]
    t = np.array([r["t"] for r in tr]) - tr[0]["t"]
    lt = 1e3 * np.array([r["true_geom"]["lateral_m"] for r in tr])
    le = 1e3 * np.array([r["est_geom"]["lateral_m"] for r in tr])
    p0 = np.array(tr[0]["pt_true"])
    mv = 1e3 * np.linalg.norm(np.array([r["pt_true"] for r in tr]) - p0, axis=1)
    ax.plot(t, lt, label="lateral offset, truth")
    ax.plot(t, le, label="lateral offset, as the guidance sees it")
    ax.plot(t, mv, "--", label="target displacement since DOCK entry")
    lost = next((ti for ti, r in zip(t, tr) if r["vis_age"] > 0.5), None)
    if lost is not None:
        ax.axvline(lost, color="k", lw=0.8)
        ax.text(lost + 0.2, 45, "markers leave\nthe image", fontsize=7)
    ax.axhline(20, color="r", lw=0.8, ls=":")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("time in DOCK [s]")
axs[0].set_ylabel("[mm]")
axs[0].legend(fontsize=7, loc="upper left")
fig.tight_layout()
fig.savefig(sys.argv[3], dpi=80)
