"""IMU noise from a log: the overlapping Allan deviation of a static segment and the in-flight vibration.

The Allan variance of a rate signal ``y`` (a gyro's rate, an accelerometer's specific force) sampled at
``dt`` is, for clusters of ``m`` samples (``tau = m dt``), with ``theta`` the running integral of ``y``
(IEEE Std 952-1997, annex C, eq. C.4; El-Sheimy, Hou & Niu 2008, IEEE T-IM 57(1), eq. 4-5)::

    sigma^2(tau) = 1 / (2 tau^2 (N - 2m)) sum_k (theta_{k+2m} - 2 theta_{k+m} + theta_k)^2

(the overlapping estimator: every start ``k``, not only every ``m``-th). On a log-log plot each noise term
has its slope (IEEE Std 952 table C.1): white noise (angular / velocity random walk) ``sigma = N /
sqrt(tau)``, so ``N`` is the curve's value at ``tau = 1 s`` on its -1/2 line; bias instability is the flat
floor, ``sigma_min = 0.664 B`` (``sqrt(2 ln 2 / pi)``). A short static segment shows only short ``tau``:
``N`` is then read on the -1/2 line where it is well sampled (``tau`` from ``tau_white_min_s`` to a tenth of
the segment, extrapolated to 1 s), and the floor is not reached: the minimum then only bounds ``B`` from
above (:attr:`AllanFit.floor_reached` False, and a note).

The vibration is the standard deviation of the high-pass filtered signal (4th-order Butterworth, zero phase,
``scipy.signal.sosfiltfilt``) in flight, minus, in quadrature, the same on the ground (independent noises add
their variances): what the rotors add above the vehicle's motion band.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

BIAS_INSTABILITY_FACTOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
"""0.664: the flicker floor of the Allan deviation is this times the bias instability B (IEEE Std 952 C.1)."""


def overlapping_adev(y: np.ndarray, dt: float, m: np.ndarray | None = None):
    """Overlapping Allan deviation (module docstring) of the samples ``y`` (n,) or (n, k) at interval ``dt``
    [s], for cluster sizes ``m`` (default: ~10 per decade, up to a quarter of the samples). Returns
    ``(tau_s, adev, clusters)``: ``adev`` in the unit of ``y`` ((len(m),) or (len(m), k)), ``clusters`` the
    number of terms of each sum ``N - 2m``."""
    y = np.asarray(y, dtype=float)
    n = len(y)
    if m is None:
        top = max(1, (n - 1) // 4)
        m = np.unique(np.round(np.logspace(0, math.log10(top), max(2, int(10 * math.log10(top)) + 1))))
    m = np.asarray(m, dtype=np.int64)
    m = m[(m >= 1) & (2 * m < n)]
    theta = np.concatenate([np.zeros((1, *y.shape[1:])), np.cumsum(y, axis=0) * dt])
    out = np.empty((len(m), *y.shape[1:]))
    for i, mi in enumerate(m):
        d = theta[2 * mi :] - 2.0 * theta[mi:-mi] + theta[: -2 * mi]
        tau = mi * dt
        out[i] = np.sqrt(np.sum(d * d, axis=0) / (2.0 * tau * tau * (n - 2 * mi)))
    return m * dt, out, n - 2 * m


@dataclass(frozen=True)
class AllanFit:
    """The noise terms of one sensor's three axes, read on its Allan deviation."""

    tau_s: np.ndarray
    adev: np.ndarray
    """(len(tau_s), 3), in the unit of the signal."""
    noise_density: np.ndarray
    """N per axis, the white-noise (random walk) coefficient [unit * sqrt(s)] = [unit / sqrt(Hz)]."""
    bias_instability: np.ndarray
    """B per axis = min adev / 0.664 [unit], the minimum taken from the white range's start on (an upper
    bound when the floor is not reached)."""
    tau_min_s: np.ndarray
    """Where each axis' minimum lies [s]."""
    floor_reached: bool
    """Whether every axis' minimum lies inside the curve (not at its longest tau)."""
    white_slope: float
    """The log-log slope fitted where N is read (-0.5 for white noise)."""
    white_taus_s: tuple[float, float]
    """The tau range N was read on [s]."""


def allan_fit(y: np.ndarray, dt: float, tau_white_min_s: float = 0.02) -> AllanFit:
    """Allan deviation of the (n, 3) static samples ``y`` at ``dt`` and its noise terms (module docstring).
    ``N`` is the geometric mean of ``adev * sqrt(tau)``, weighted by ``1 / tau`` (the number of independent
    clusters), over ``tau`` from ``lo`` to ``max(T / 10, 2 lo)`` clamped at 1 s (T the segment's length),
    ``lo`` the larger of ``tau_white_min_s`` and three times the tau of the curve's maximum: a low-pass
    filter in the sensor (a Crazyflie's firmware filters its gyro and accelerometer) makes the curve rise
    as ``sqrt(tau)`` up to about its time constant and bend over; the -1/2 line starts a few times past
    the hump. The slope over that range is reported, so a caller can see whether white noise dominates
    there."""
    y = np.asarray(y, dtype=float)
    tau, adev, _ = overlapping_adev(y - y.mean(axis=0), dt)
    T = len(y) * dt
    lo = max(tau_white_min_s, 3.0 * float(np.max(tau[np.argmax(adev, axis=0)])))
    hi = min(1.0, max(T / 10.0, 2.0 * lo))
    sel = (tau >= lo * 0.999) & (tau <= hi * 1.001)
    if sel.sum() < 2:
        sel = np.zeros(len(tau), dtype=bool)
        sel[: min(3, len(tau))] = True
    lt, la = np.log(tau[sel]), np.log(adev[sel])
    # each tau weighted by its number of independent clusters (~ T / tau): the short taus are the sure ones
    w = 1.0 / tau[sel]
    n_density = np.exp(np.sum(w[:, None] * (la + 0.5 * lt[:, None]), axis=0) / w.sum())
    slope = (
        float(np.mean([np.polyfit(lt, la[:, k], 1)[0] for k in range(la.shape[1])])) if len(lt) > 1 else -0.5
    )
    # the floor is looked for past the low-pass hump (below it the filter, not the sensor, shapes the curve)
    start = int(np.flatnonzero(sel)[0])
    imin = start + np.argmin(adev[start:], axis=0)
    floor = bool(np.all(imin < len(tau) - 1))
    return AllanFit(
        tau,
        adev,
        n_density,
        adev[imin, np.arange(adev.shape[1])] / BIAS_INSTABILITY_FACTOR,
        tau[imin],
        floor,
        slope,
        (float(tau[sel][0]), float(tau[sel][-1])),
    )


def _chunks(t: np.ndarray, max_gap_s: float) -> list[slice]:
    """Index ranges of ``t`` without a gap longer than ``max_gap_s``."""
    cut = np.flatnonzero(np.diff(t) > max_gap_s) + 1
    edges = [0, *cut.tolist(), len(t)]
    return [slice(a, b) for a, b in itertools.pairwise(edges) if b > a]


def highpass_spread(
    t: np.ndarray, y: np.ndarray, sel: np.ndarray, cutoff_hz: float, order: int = 4
) -> np.ndarray:
    """Per-axis standard deviation of ``y`` (n, 3) high-passed at ``cutoff_hz`` (Butterworth, zero phase,
    per stretch without a gap of more than 5 sample intervals, the interval taken as the median one), over
    the samples where ``sel``. NaN for an axis with fewer than 100 selected samples."""
    dt = float(np.median(np.diff(t)))
    fs = 1.0 / dt
    out = np.full(y.shape[1], np.nan)
    if cutoff_hz >= 0.5 * fs:
        return out
    sos = signal.butter(order, cutoff_hz, btype="highpass", fs=fs, output="sos")
    hp = np.full(y.shape, np.nan)
    pad = 3 * (2 * len(sos) + 1)
    for s in _chunks(t, 5 * dt):
        if s.stop - s.start > 4 * pad:
            hp[s] = signal.sosfiltfilt(sos, y[s], axis=0)
    use = sel & np.all(np.isfinite(hp), axis=1)
    if use.sum() >= 100:
        out = hp[use].std(axis=0)
    return out


def vibration(flight: np.ndarray, ground: np.ndarray) -> np.ndarray:
    """Extra in-flight spread: ``sqrt(flight^2 - ground^2)`` per axis (0 where flight is not above)."""
    return np.sqrt(np.clip(flight * flight - ground * ground, 0.0, None))
