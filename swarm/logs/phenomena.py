"""What real Crazyflie flights show and the synthetic log of :mod:`swarm.logs.synthetic` adds when it is
given a sensor profile (:class:`swarm.sensors.profile.SensorProfile`; docs/logs.md, ``docs/logs.md``):

* ranges (:func:`range_errors`): a common offset and per-anchor offsets (an antenna delay: real ranges
  read short by 0.17-0.36 m), a per-anchor step once airborne (the ground-to-air bias step), white noise of
  one sigma on the ground and another in flight, a first-order Gauss-Markov error per anchor in flight
  (time-correlated multipath), sustained NLOS episodes (Poisson onsets per anchor, exponential lengths, a
  long excess) and isolated outliers;
* the IMU (:func:`vibration`): an extra white spread in flight (rotor vibration);
* a downward range finder (:func:`height_rows`) and a barometer (:func:`baro_rows`).

Each phenomenon draws from its own child stream of the log's seed (:func:`child`), so switching one on
changes no other sample of the log.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

STREAM_GM, STREAM_NLOS, STREAM_OUTLIER, STREAM_VIBRATION, STREAM_HEIGHT, STREAM_BARO = range(1, 7)
"""Spawn keys of the phenomena's child streams (:func:`child`)."""

SQRT12 = math.sqrt(12.0)
"""A uniform of width ``w`` has standard deviation ``w / sqrt(12)``."""


def child(seed: int, key: int) -> np.random.Generator:
    """The child stream ``key`` of the log's seed: independent of ``default_rng(seed)`` (which is the root
    ``SeedSequence(seed)``) and of the other children (NumPy, ``SeedSequence`` spawn keys)."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(key),)))


@dataclass(frozen=True)
class Episode:
    """One NLOS episode of one anchor: every range of ``anchor`` in ``[start_s, end_s)`` is long by
    ``excess_m``."""

    anchor: int
    start_s: float
    end_s: float
    excess_m: float


def spread_draw(mean: float, sd: float, u: np.ndarray) -> np.ndarray:
    """Per-anchor values of mean ``mean`` and standard deviation ``sd`` from uniforms ``u`` in [0, 1): a
    uniform of width ``sd sqrt(12)`` (bounded, as a batch of antenna delays is). The default profile's
    ``offset_m = 0.35``, ``offset_spread_m = 0.0866`` so gives the synthetic log's U(0.2, 0.5) biases."""
    return mean + sd * SQRT12 * (np.asarray(u) - 0.5)


def gauss_markov(t: np.ndarray, sigma: float, tau_s: float, z: np.ndarray) -> np.ndarray:
    """A first-order Gauss-Markov process sampled at the increasing times ``t`` (n,) from the standard
    normals ``z`` (n,): stationary from the first sample, ``x_0 = sigma z_0``, then the exact discretisation
    ``x_k = phi x_{k-1} + sigma sqrt(1 - phi^2) z_k``, ``phi = exp(-(t_k - t_{k-1}) / tau)`` (Maybeck 1979,
    vol. 1, ch. 4; Brown & Hwang 2012, sec. 2.9): variance ``sigma^2`` and autocorrelation
    ``exp(-|dt| / tau)`` at any sampling."""
    x = np.empty(len(t))
    if not len(t):
        return x
    phi = np.exp(-np.diff(t) / tau_s)
    s = sigma * np.sqrt(1.0 - phi * phi)
    x[0] = sigma * z[0]
    for k in range(1, len(t)):
        x[k] = phi[k - 1] * x[k - 1] + s[k - 1] * z[k]
    return x


def poisson_episodes(
    rng: np.random.Generator,
    anchors: int,
    t0: float,
    t1: float,
    rate_hz: float,
    mean_s: float,
    excess_m: float,
) -> list[Episode]:
    """NLOS episodes of every anchor in ``[t0, t1)``: onsets a Poisson process of ``rate_hz`` while the
    anchor is clear (exponential gaps), lengths exponential of mean ``mean_s``, excess uniform in
    ``[0.5, 1.5] excess_m`` (always long; mean ``excess_m``). The clear/NLOS state is so the two-state
    Markov process that :func:`swarm.core.range_errors.episode_step` samples at each exchange."""
    out: list[Episode] = []
    if rate_hz <= 0.0:
        return out
    for a in range(anchors):
        t = t0
        while True:
            t += rng.exponential(1.0 / rate_hz)
            length = rng.exponential(mean_s)
            excess = excess_m * rng.uniform(0.5, 1.5)
            if t >= t1:
                break
            out.append(Episode(a, float(t), float(min(t + length, t1)), float(excess)))
            t += length
    return out


def episode_excess(t: np.ndarray, anchor: np.ndarray, episodes: list[Episode]) -> np.ndarray:
    """The NLOS excess of each range (times ``t``, anchors ``anchor``) inside one of ``episodes`` [m]."""
    e = np.zeros(len(t))
    for ep in episodes:
        inside = (anchor == ep.anchor) & (t >= ep.start_s) & (t < ep.end_s)
        e[inside] = np.maximum(e[inside], ep.excess_m)
    return e


def range_errors(
    seed: int, uwb, t: np.ndarray, anchor: np.ndarray, airborne: np.ndarray, anchors: int, t_end: float
) -> tuple[np.ndarray, list[Episode], np.ndarray]:
    """The profile's time-correlated and episodic range errors (``uwb`` a
    :class:`swarm.sensors.profile.UwbProfile`) of the ranges at ``t`` to ``anchor`` (``airborne`` (n,) where
    the vehicle flies): ``(gm + NLOS excess + outlier excess (n,), the episodes, outlier mask (n,))``. The
    Gauss-Markov part runs per anchor over its airborne ranges, stationary from the first; episodes start
    once airborne."""
    n = len(t)
    gm = np.zeros(n)
    if uwb.gm_sigma_m > 0.0:
        z = child(seed, STREAM_GM).standard_normal(n)
        for a in range(anchors):
            rows = np.flatnonzero((anchor == a) & airborne)
            gm[rows] = gauss_markov(t[rows], uwb.gm_sigma_m, uwb.gm_tau_s, z[rows])
    t_air = float(t[airborne][0]) if airborne.any() else t_end
    episodes = poisson_episodes(
        child(seed, STREAM_NLOS),
        anchors,
        t_air,
        t_end,
        uwb.nlos_rate_hz,
        uwb.nlos_duration_s,
        uwb.nlos_excess_m,
    )
    r = child(seed, STREAM_OUTLIER)
    u, size = r.random(n), r.exponential(uwb.outlier_excess_m if uwb.outlier_excess_m > 0 else 1.0, n)
    outlier = u < uwb.outlier_share
    return gm + episode_excess(t, anchor, episodes) + np.where(outlier, size, 0.0), episodes, outlier


def vibration(seed: int, imu, airborne: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotors' extra white spread of the gyro and the accelerometer ((n, 3) each; ``imu`` a
    :class:`swarm.sensors.profile.ImuProfile`): ``gyro_vibration_rad_s`` and ``accel_vibration_m_s2``
    standard deviations per sample where ``airborne`` (rotors spinning), zero on the ground."""
    r = child(seed, STREAM_VIBRATION)
    n = len(airborne)
    on = airborne[:, None].astype(float)
    g = r.standard_normal((n, 3)) * imu.gyro_vibration_rad_s * on
    a = r.standard_normal((n, 3)) * imu.accel_vibration_m_s2 * on
    return g, a


def height_rows(seed: int, t: np.ndarray, z_m: np.ndarray, cos_tilt: np.ndarray, spec) -> np.ndarray:
    """``height.csv`` rows ``(t_s, range_m)``: a downward range finder at the body origin, along body -z
    (docs/logs.md): ``(z - ground_z) / cos(tilt)`` plus white noise ``spec.height_sigma_m``; no return
    (NaN) beyond ``spec.height_max_range_m`` or when ``cos(tilt) < spec.height_min_cos_tilt``."""
    r = child(seed, STREAM_HEIGHT)
    d = (z_m - spec.height_ground_z_m) / np.maximum(cos_tilt, 1e-9)
    meas = d + r.standard_normal(len(t)) * spec.height_sigma_m
    meas[(d > spec.height_max_range_m) | (cos_tilt < spec.height_min_cos_tilt)] = np.nan
    return np.column_stack([t, np.maximum(meas, 0.0)])


def baro_rows(seed: int, t: np.ndarray, z_m: np.ndarray, spec) -> tuple[np.ndarray, np.ndarray]:
    """``baro.csv`` rows ``(t_s, height_m)`` and the drift (n,): the altitude ``z`` plus a constant offset
    ``spec.baro_offset_m``, a slow drift (a random walk of ``spec.baro_drift_m_rts`` [m/sqrt(s)] from 0)
    and white noise ``spec.baro_sigma_m``."""
    r = child(seed, STREAM_BARO)
    steps = r.standard_normal(len(t)) * spec.baro_drift_m_rts * np.sqrt(np.diff(t, prepend=t[0]))
    drift = np.cumsum(steps)
    meas = z_m + spec.baro_offset_m + drift + r.standard_normal(len(t)) * spec.baro_sigma_m
    return np.column_stack([t, meas]), drift
