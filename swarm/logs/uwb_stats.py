"""Range-residual statistics for ``swarm fit``: robust location and scale, the NLOS split, and the
Gauss-Markov fit of the autocorrelation (pure numpy / scipy, one anchor's series at a time).

**Location and scale.** The median and the scaled median absolute deviation ``1.4826 MAD`` (consistent for
a Gaussian; Rousseeuw & Croux 1993, JASA 88(424)) ignore up to half of the samples being anything.

**The NLOS split.** A blocked direct path makes a range long, never short (the first detected path is a
reflection), and for a while: the reflected path's extra length changes slowly with the geometry. So an
NLOS episode is a *sustained positive* excursion of the residual above the clear distribution, and the
clear distribution is the residual's lowest dense mode. The method:

1. start from the lowest dense mode: among the intervals holding a tenth of the samples, those at most
   3 times as long as the shortest are "dense" (a sample density at least a third of the peak's); the
   lowest run of dense intervals is the clear mode, its location the midpoint of the shortest interval in
   that run (a shortest-interval mode estimator, the "shorth" of Rousseeuw & Leroy 1988, Statistica
   Neerlandica 42(2), taken on a tenth and from below: a tight NLOS mode holding more than half of the
   samples is denser than the clear one and would win a plain shorth; up to 3 times denser, the clear
   mode still counts as dense); its scale from the samples below the location, which NLOS never reaches:
   ``1.4826 median(loc - x)`` (a half-normal's median is ``0.6745 sigma``);
2. flag the ranges whose running median over ``window`` ranges lies more than ``k`` sigmas above the clear
   location (the running median keeps an episode whole through single noisy ranges, and ignores one-off
   spikes); a run of flagged ranges that lasts ``min_duration_s`` and holds ``min_ranges`` ranges is an
   episode; a single range above ``k`` sigmas outside episodes is an isolated outlier;
3. re-estimate the location and scale as the median and ``1.4826 MAD`` of the clear ranges and repeat
   until the flags no longer change (at most 10 times).

An excursion of the clear noise itself is flagged with a small probability (a time-correlated error of
``k`` sigmas that lasts ``min_duration_s``); an episode whose excess is under ``k`` sigmas is not seen (its
ranges stay in the clear set, widening it a little): the measured onset rate is then low and the mean
excess high. Both are the usual price of a threshold; the plots show the split.

**The Gauss-Markov fit.** A clear residual is modelled as white noise (sigma_w) plus a first-order
Gauss-Markov process (stationary sigma_g, correlation time tau; Gelb 1974 table 3.1-1), whose
autocovariance is ``C(lag) = sigma_g^2 exp(-lag / tau)`` for lag > 0 and ``sigma_w^2 + sigma_g^2`` at 0.
The residual is put on a uniform grid of the anchor's median range interval (each range in its nearest
cell, no interpolation: interpolating would correlate the white noise), its mean and linear trend removed per
flight segment, and the sample autocovariance taken over the pairs where both cells hold a range
(Priestley 1981 sec. 5.3, the biased estimator, lags up to ``max_lag_s``). Then ``(sigma_g^2, tau)`` are
fitted by least squares (``scipy.optimize.curve_fit``) on lags > 0 of the model

    C(lag) = sigma_g^2 (exp(-lag / tau) - c),   c = p * 2 (tau / T) (1 - (tau / T) (1 - exp(-T / tau)))

where the constant ``c`` is what removing ``p = 2`` regressors (mean and trend) from a segment of length T
takes from every lag: the variance of the time average of a process of autocovariance C is
``(2 / T) int_0^T (1 - s / T) C(s) ds`` (Papoulis, Probability, Random Variables and Stochastic Processes,
"mean-ergodic processes"), which for the GM is ``sigma_g^2`` times the bracket, and each regressor removes
about that much (for tau << T).
Without it tau would come out short by roughly that share (~7 % at lag tau for tau = 1 s, T = 55 s).
``sigma_w^2 = C(0) - sigma_g^2 (1 - c)``. The estimate's own scatter is that of an autocorrelation over ~T /
(2 tau) independent stretches: for a minute of flight and tau = 1 s, tau is known to ~20-30 %.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage, optimize

MAD_SCALE = 1.4826
"""1 / Phi^-1(3/4): MAD * this is a Gaussian's sigma."""


def robust(x: np.ndarray) -> tuple[float, float]:
    """Median and ``1.4826 MAD`` of ``x`` (NaN, NaN when empty)."""
    if len(x) == 0:
        return math.nan, math.nan
    m = float(np.median(x))
    return m, float(MAD_SCALE * np.median(np.abs(x - m)))


def lowest_mode(x: np.ndarray, share: float = 0.1, slack: float = 3.0) -> tuple[float, float]:
    """Location and scale of the lowest dense mode of ``x`` (module docstring, step 1)."""
    xs = np.sort(np.asarray(x, dtype=float))
    n = len(xs)
    h = max(2, math.ceil(share * n))
    if n < 8 or h >= n:
        return robust(x)
    widths = xs[h - 1 :] - xs[: n - h + 1]
    dense = widths <= slack * widths.min()
    first = int(np.argmax(dense))
    run_end = first + int(np.argmin(dense[first:])) if not dense[first:].all() else len(dense)
    i = first + int(np.argmin(widths[first:run_end]))
    loc = 0.5 * float(xs[i] + xs[i + h - 1])
    below = loc - xs[xs < loc]
    scale = MAD_SCALE * float(np.median(below)) if len(below) >= 3 else float(widths[i])
    return loc, scale


@dataclass(frozen=True)
class NlosSplit:
    """One anchor's in-flight ranges split into clear, NLOS episodes and isolated outliers."""

    location_m: float
    """Median of the clear residuals [m]."""
    sigma_m: float
    """Their 1.4826 MAD [m]."""
    label: np.ndarray
    """Per range: -1 clear, -2 isolated outlier, k >= 0 the episode's index."""
    episodes: list[tuple[float, float, float]]
    """Each episode's ``(start_s, end_s, mean excess over location_m)``."""


def runs(flag: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` of each run of True."""
    d = np.diff(np.concatenate([[0], flag.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def split_nlos(
    t: np.ndarray,
    r: np.ndarray,
    k: float = 3.0,
    window: int = 5,
    min_duration_s: float = 0.3,
    min_ranges: int = 3,
    interval_s: float | None = None,
) -> NlosSplit:
    """The NLOS split of one anchor's time-ordered in-flight residuals ``r`` at times ``t`` (module
    docstring). ``interval_s`` is the anchor's nominal range interval (default: the median one), added to an
    episode's first-to-last span to give its duration."""
    n = len(r)
    if n < max(3, window):
        loc, sig = robust(r)
        return NlosSplit(loc, sig, np.full(n, -1), [])
    dt = float(np.median(np.diff(t))) if interval_s is None else interval_s
    smooth = ndimage.median_filter(r, size=window, mode="nearest")
    loc, sig = lowest_mode(r)
    label = np.full(n, -1)
    episodes: list[tuple[float, float, float]] = []
    for _ in range(10):
        thr = loc + k * max(sig, 1e-6)
        new = np.full(n, -1)
        episodes = []
        for a, b in runs(smooth > thr):
            if b - a >= min_ranges and t[b - 1] - t[a] + dt >= min_duration_s:
                new[a:b] = len(episodes)
                episodes.append((float(t[a]), float(t[b - 1] + dt), 0.0))
        new[(new == -1) & (r > thr)] = -2
        clear = new == -1
        loc, sig = robust(r[clear])
        if np.array_equal(new, label):
            break
        label = new
    episodes = [(a, b, float(np.mean(r[label == i]) - loc)) for i, (a, b, _) in enumerate(episodes)]
    return NlosSplit(loc, sig, label, episodes)


def detrend_segments(t: np.ndarray, x: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """``x`` minus its least-squares line in each segment (``seg`` gives each sample's segment index)."""
    out = np.array(x, dtype=float)
    for s in np.unique(seg):
        i = seg == s
        if i.sum() >= 3:
            out[i] -= np.polyval(np.polyfit(t[i] - t[i].mean(), x[i], 1), t[i] - t[i].mean())
        else:
            out[i] -= x[i].mean()
    return out


def autocovariance(t: np.ndarray, x: np.ndarray, dt: float, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """Sample autocovariance of ``x`` at times ``t`` on a grid of ``dt``: each sample in its nearest cell
    (several in one cell averaged), the mean over the pairs of filled cells at each lag 0..max_lag. Returns
    ``(cov, pairs)``."""
    idx = np.round((t - t[0]) / dt).astype(np.int64)
    n = int(idx[-1]) + 1
    s = np.bincount(idx, weights=x, minlength=n)
    c = np.bincount(idx, minlength=n)
    z = np.where(c > 0, s / np.maximum(c, 1), 0.0)
    have = (c > 0).astype(float)
    cov = np.empty(max_lag + 1)
    pairs = np.empty(max_lag + 1, dtype=np.int64)
    for k in range(max_lag + 1):
        p = have[: n - k] * have[k:]
        pairs[k] = int(p.sum())
        cov[k] = float(np.sum(z[: n - k] * z[k:])) / pairs[k] if pairs[k] else math.nan
    return cov, pairs


def trend_loss(tau: np.ndarray | float, T: float, p: int = 2) -> np.ndarray | float:
    """``c`` of the module docstring: the share of a GM process's covariance that removing ``p``
    regressors from a segment of length ``T`` takes from every lag."""
    r = np.asarray(tau, dtype=float) / T
    return p * 2.0 * r * (1.0 - r * (1.0 - np.exp(-1.0 / np.maximum(r, 1e-12))))


@dataclass(frozen=True)
class GmFit:
    """The white + Gauss-Markov split of one anchor's clear in-flight residual."""

    lag_s: np.ndarray
    rho: np.ndarray
    """Sample autocorrelation (autocovariance / its lag-0 value) at ``lag_s``."""
    gm_sigma_m: float
    gm_tau_s: float
    white_sigma_m: float
    ok: bool
    """False when the series was too short or the fit failed (then gm_sigma_m = 0, white = the total)."""
    T_s: float = math.nan
    """The segment length of the trend-removal term [s]."""

    def rho_model(self, lag_s: np.ndarray) -> np.ndarray:
        """The fitted model's autocorrelation at ``lag_s`` > 0 (as the sample one, trend removal included)."""
        c = trend_loss(self.gm_tau_s, self.T_s)
        var = self.gm_sigma_m**2
        return (
            var * (np.exp(-np.asarray(lag_s) / self.gm_tau_s) - c) / (var * (1.0 - c) + self.white_sigma_m**2)
        )


@dataclass(frozen=True)
class Autocov:
    """A residual series' sample autocovariance on a lag grid, and what the GM fit needs with it."""

    lag_s: np.ndarray
    cov: np.ndarray
    """[m^2] at each lag."""
    pairs: np.ndarray
    """Pairs of filled grid cells at each lag."""
    T_s: float
    """Mean length of the segments the mean and trend were removed from [s], weighted by their samples."""

    @staticmethod
    def pooled(items: list[Autocov]) -> Autocov:
        """Several anchors' autocovariances on one lag grid, averaged weighted by their pairs."""
        w = np.array([a.pairs for a in items], dtype=float)
        cov = np.array([np.nan_to_num(a.cov) for a in items])
        tot = w.sum(axis=0)
        T = float(np.sum([a.T_s * a.pairs[0] for a in items]) / max(tot[0], 1.0))
        return Autocov(items[0].lag_s, (w * cov).sum(axis=0) / np.maximum(tot, 1.0), tot.astype(np.int64), T)


def residual_autocov(t: np.ndarray, x: np.ndarray, seg: np.ndarray, dt: float, max_lag_s: float) -> Autocov:
    """The autocovariance of the clear residuals ``x`` at times ``t`` (segment index ``seg``) on the grid
    ``dt``, after removing each segment's mean and trend (module docstring)."""
    xd = detrend_segments(t, x, seg)
    max_lag = max(3, round(max_lag_s / dt))
    cov, pairs = autocovariance(t, xd, dt, max_lag)
    segs, counts = np.unique(seg, return_counts=True)
    seg_len = np.array([np.ptp(t[seg == s]) for s in segs])
    T = float(max(np.sum(seg_len * counts) / counts.sum(), 10 * dt))
    return Autocov(np.arange(max_lag + 1) * dt, cov, pairs, T)


def fit_gm(ac: Autocov, min_pairs: int = 100) -> GmFit:
    """Fit white + GM to an autocovariance (module docstring); ``ok`` False (GM sigma 0, white = the total)
    with fewer than ``min_pairs`` samples at lag 0 or a failed fit."""
    c0 = float(ac.cov[0]) if len(ac.cov) else math.nan
    if len(ac.cov) == 0 or ac.pairs[0] < min_pairs or not c0 > 0:
        return GmFit(
            ac.lag_s, ac.cov / c0 if c0 > 0 else ac.cov, 0.0, math.nan, math.sqrt(max(c0, 0.0)), False
        )
    rho = ac.cov / c0
    dt = float(ac.lag_s[1])
    use = (ac.lag_s > 0) & (ac.pairs > 10)
    T = ac.T_s

    def model(lg, a, tau):
        return a * (np.exp(-lg / tau) - trend_loss(tau, T))

    try:
        (a, tau), _ = optimize.curve_fit(
            model,
            ac.lag_s[use],
            ac.cov[use],
            p0=(max(ac.cov[1], 0.1 * c0), max(2 * dt, 0.5)),
            bounds=([0.0, 0.2 * dt], [2.0 * c0, 0.5 * T]),
        )
    except (RuntimeError, ValueError):
        return GmFit(ac.lag_s, rho, 0.0, math.nan, math.sqrt(c0), False)
    white2 = c0 - a * (1.0 - trend_loss(tau, T))
    return GmFit(ac.lag_s, rho, float(math.sqrt(a)), float(tau), float(math.sqrt(max(white2, 0.0))), True, T)
