"""The figures of ``swarm fit --plot DIR`` (matplotlib, Agg): what a reader checks the fit against."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from swarm.logs.fit import FitResult


def _grid(n: int) -> tuple[int, int]:
    cols = min(4, max(1, n))
    return math.ceil(n / cols), cols


def plot_fit(result: FitResult, directory: Path) -> list[Path]:
    """Write ``residuals.png`` (per-anchor histograms, ground vs flight clear vs NLOS),
    ``autocorrelation.png`` (per-anchor and pooled, with the fitted model) and ``allan.png`` (gyro and
    accelerometer, with the white-noise line and the floor) into ``directory``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    directory.mkdir(parents=True, exist_ok=True)
    out = []
    anchors = result.anchors

    rows, cols = _grid(len(anchors))
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 2.8 * rows), squeeze=False)
    for ax, a in zip(axes.flat, anchors, strict=False):
        fr = a.flight_residual
        lo = np.nanpercentile(np.concatenate([a.ground_residual, fr]), 0.5) - 0.05 if len(fr) else -1
        hi = min(np.nanpercentile(fr, 99.5) + 0.05, a.flight_bias_m + 2.0) if len(fr) else 1
        bins = np.linspace(lo, hi, 80)
        kw = {"bins": bins, "density": True, "histtype": "step"}
        if len(a.ground_residual):
            ax.hist(a.ground_residual, color="k", label=f"ground s={a.ground_sigma_m:.3f}", **kw)
        ax.hist(fr[a.flight_label == -1], color="C0", label=f"flight clear s={a.flight_sigma_m:.3f}", **kw)
        if (a.flight_label != -1).any():
            w = np.full((a.flight_label != -1).sum(), 1.0 / max(len(fr), 1) / (bins[1] - bins[0]))
            share = 100 * (1 - np.mean(a.flight_label == -1))
            ax.hist(fr[a.flight_label != -1], bins=bins, weights=w, histtype="stepfilled", alpha=0.4,
                    color="C3", label=f"NLOS+outliers {share:.0f} %")  # fmt: skip
        ax.axvline(a.ground_bias_m, color="k", lw=0.6, ls=":")
        ax.axvline(a.flight_bias_m, color="C0", lw=0.6, ls=":")
        ax.set_title(f"anchor {a.anchor_id}", fontsize=9)
        ax.set_xlabel("range residual [m]", fontsize=8)
        ax.legend(fontsize=6)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(anchors) :]:
        ax.set_visible(False)
    fig.tight_layout()
    out.append(directory / "residuals.png")
    fig.savefig(out[-1], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4.2))
    for i, a in enumerate(anchors):
        if len(a.gm.lag_s):
            ax.plot(a.gm.lag_s, a.gm.rho, ".", ms=3, color=f"C{i % 10}", label=f"anchor {a.anchor_id}")
    g = result.gm_pooled
    if len(g.lag_s):
        ax.plot(g.lag_s, g.rho, "k-", lw=1.2, label="pooled")
        if g.ok:
            lag = np.linspace(0, g.lag_s[-1], 200)[1:]
            label = (
                f"fit: GM sigma {g.gm_sigma_m:.3f} m, tau {g.gm_tau_s:.2f} s; white {g.white_sigma_m:.3f} m"
            )
            ax.plot(lag, g.rho_model(lag), "r--", lw=1.5, label=label)
    ax.axhline(0, color="grey", lw=0.5)
    ax.set_xlabel("lag [s]")
    ax.set_ylabel("autocorrelation of the clear in-flight residual")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    out.append(directory / "autocorrelation.png")
    fig.savefig(out[-1], dpi=110)
    plt.close(fig)

    if result.gyro is not None and result.accel is not None:
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
        for ax, fit, unit in ((axes[0], result.gyro, "rad/s"), (axes[1], result.accel, "m/s^2")):
            for k in range(3):
                ax.loglog(fit.tau_s, fit.adev[:, k], ".-", ms=3, color=f"C{k}", label="xyz"[k])
                n = fit.noise_density[k]
                ax.loglog(fit.tau_s, n / np.sqrt(fit.tau_s), "--", color=f"C{k}", lw=0.8)
                ax.axhline(0.664 * fit.bias_instability[k], color=f"C{k}", lw=0.6, ls=":")
            ax.axvspan(*fit.white_taus_s, color="grey", alpha=0.12, label="N read here")
            ax.axvline(1.0, color="k", lw=0.4)
            ax.set_xlabel("tau [s]")
            ax.set_ylabel(f"Allan deviation [{unit}]")
            floor = "" if fit.floor_reached else " (floor not reached: B upper bound)"
            ax.set_title(f"N {np.sqrt(np.mean(fit.noise_density**2)):.3g}, "
                         f"B {np.sqrt(np.mean(fit.bias_instability**2)):.3g}{floor}", fontsize=8)  # fmt: skip
            ax.legend(fontsize=7)
        axes[0].set_title("gyro: " + axes[0].get_title(), fontsize=8)
        axes[1].set_title("accelerometer: " + axes[1].get_title(), fontsize=8)
        fig.tight_layout()
        out.append(directory / "allan.png")
        fig.savefig(out[-1], dpi=110)
        plt.close(fig)
    return out
