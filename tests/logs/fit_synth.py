"""A log folder with KNOWN sensor-model parameters, for the tests of ``swarm fit`` (tests/logs/test_fit.py).

Written directly from the error model, not through a filter: the truth is a pad, a climb, a slow circle, a
descent and the pad again; each range is the true tag distance plus a known per-anchor offset, a known
take-off step, a Gauss-Markov error (flight), white noise (one sigma on the ground, another in flight),
fixed NLOS episodes on one anchor (a constant excess each) and isolated exponential outliers. The IMU is
still on the pad and in flight only adds known white vibration: its motion would lie below the fit's 20 Hz
high-pass, and its static segment is still, so the specific force is gravity plus bias plus noise (the fit
uses the IMU only for the Allan deviation of the static segment and the high-passed spread).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ANCHORS = np.array(
    [[-4, -3, 0.2], [4, -3, 0.2], [4, 3, 0.2], [-4, 3, 0.2], [-4, -3, 2.8], [4, -3, 2.8], [4, 3, 2.8],
     [-4, 3, 2.8]], dtype=float,
)  # fmt: skip
LEVER_M = np.array([0.0, 0.0, 0.03])


@dataclass(frozen=True)
class Known:
    """The parameters the log is drawn with."""

    static_s: float = 20.0
    climb_s: float = 2.0
    flight_s: float = 60.0
    ground_after_s: float = 6.0
    range_hz_per_anchor: float = 10.0
    offset_m: float = -0.25
    offset_spread_m: float = 0.05
    step_m: float = 0.05
    step_spread_m: float = 0.03
    ground_sigma_m: float = 0.015
    sigma_m: float = 0.04
    gm_sigma_m: float = 0.05
    gm_tau_s: float = 1.0
    nlos_anchor: int = 3
    nlos_episodes: tuple[tuple[float, float, float], ...] = (
        (5.0, 3.0, 0.5),
        (14.0, 5.0, 0.4),
        (25.0, 2.0, 0.6),
        (33.0, 6.0, 0.45),
        (45.0, 4.0, 0.55),
        (55.0, 2.5, 0.5),
    )
    """(start after take-off + climb [s], length [s], excess [m])."""
    outlier_share: float = 0.01
    outlier_excess_m: float = 1.0
    imu_hz: float = 500.0
    gyro_noise: float = 0.002  # [rad/s/sqrt(Hz)]
    accel_noise: float = 0.004  # [m/s^2/sqrt(Hz)]
    gyro_vibration: float = 0.04  # [rad/s]
    accel_vibration: float = 0.1  # [m/s^2]

    @property
    def takeoff_s(self) -> float:
        return self.static_s

    @property
    def landing_s(self) -> float:
        return self.static_s + 2 * self.climb_s + self.flight_s

    @property
    def duration_s(self) -> float:
        return self.landing_s + self.ground_after_s


def _height(k: Known, t: np.ndarray) -> np.ndarray:
    up = np.clip((t - k.takeoff_s) / k.climb_s, 0, 1) - np.clip(
        (t - k.landing_s + k.climb_s) / k.climb_s, 0, 1
    )
    return 0.05 + 1.0 * up


def _position(k: Known, t: np.ndarray) -> np.ndarray:
    fly = np.clip(t - k.takeoff_s - k.climb_s, 0, k.flight_s)
    on = (fly > 0) & (fly < k.flight_s)
    x = np.where(on, 1.0 * np.sin(0.2 * fly), 0.0)
    y = np.where(on, 1.0 - np.cos(0.2 * fly), 0.0)
    y = np.where(fly >= k.flight_s, 1.0 - math.cos(0.2 * k.flight_s), y)
    x = np.where(fly >= k.flight_s, math.sin(0.2 * k.flight_s), x)
    return np.column_stack([x, y, _height(k, t)])


def _gm(rng, t, sigma, tau):
    x = np.empty(len(t))
    x[0] = sigma * rng.normal()
    phi = np.exp(-np.diff(t) / tau)
    z = rng.normal(size=len(t))
    for i in range(1, len(t)):
        x[i] = phi[i - 1] * x[i - 1] + sigma * math.sqrt(1 - phi[i - 1] ** 2) * z[i]
    return x


def write_log(d: Path, seed: int = 0, k: Known | None = None) -> dict:
    """Write the log into ``d``; returns the drawn per-anchor offsets and steps, the episodes' times."""
    k = k or Known()
    rng = np.random.default_rng(seed)
    d.mkdir(parents=True, exist_ok=True)
    T = k.duration_s
    m = len(ANCHORS)
    # truth at 100 Hz, level, yaw 0: q = identity
    tt = np.arange(0.0, T, 0.01)
    pt = _position(k, tt)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (len(tt), 1))
    np.savetxt(d / "truth.csv", np.column_stack([tt, pt, q]), delimiter=",", fmt="%.6f",
               header="t_s,x_m,y_m,z_m,qx,qy,qz,qw", comments="")  # fmt: skip

    # ranges: round robin, each anchor every 1 / range_hz_per_anchor, a little jitter
    step = 1.0 / (k.range_hz_per_anchor * m)
    n = int((T - 0.05) / step)
    tr = np.arange(n) * step + rng.uniform(0, 0.002, n)
    an = np.arange(n) % m
    tag = _position(k, tr) + LEVER_M
    dist = np.linalg.norm(tag - ANCHORS[an], axis=1)
    off = k.offset_m + rng.uniform(-0.5, 0.5, m) * k.offset_spread_m * math.sqrt(12)
    steps = k.step_m + rng.uniform(-0.5, 0.5, m) * k.step_spread_m * math.sqrt(12)
    air = (tr >= k.takeoff_s) & (tr < k.landing_s)
    err = off[an] + np.where(air, steps[an], 0.0)
    err += rng.normal(size=n) * np.where(air, k.sigma_m, k.ground_sigma_m)
    for a in range(m):
        rows = np.flatnonzero((an == a) & air)
        err[rows] += _gm(rng, tr[rows], k.gm_sigma_m, k.gm_tau_s)
    t_fly = k.takeoff_s + k.climb_s
    nlos = np.zeros(n, dtype=bool)
    for start, length, excess in k.nlos_episodes:
        inside = (an == k.nlos_anchor) & (tr >= t_fly + start) & (tr < t_fly + start + length)
        err[inside] += excess
        nlos |= inside
    out = air & ~nlos & (rng.random(n) < k.outlier_share)
    err[out] += rng.exponential(k.outlier_excess_m, out.sum())
    np.savetxt(d / "uwb.csv", np.column_stack([tr, an, dist + err]), delimiter=",",
               fmt=["%.6f", "%d", "%.6f"], header="t_s,anchor_id,range_m", comments="")  # fmt: skip
    np.savetxt(d / "anchors.csv", np.column_stack([np.arange(m), ANCHORS]), delimiter=",",
               fmt=["%d", "%.4f", "%.4f", "%.4f"], header="anchor_id,x_m,y_m,z_m", comments="")  # fmt: skip

    # IMU: still + white noise + biases, vibration while airborne
    ti = np.arange(int(T * k.imu_hz)) / k.imu_hz
    ni = len(ti)
    air_i = ((ti >= k.takeoff_s) & (ti < k.landing_s))[:, None]
    gyro = np.array([0.003, -0.002, 0.001]) + rng.normal(size=(ni, 3)) * k.gyro_noise * math.sqrt(k.imu_hz)
    gyro += air_i * rng.normal(size=(ni, 3)) * k.gyro_vibration
    acc = np.array([0.05, -0.03, 9.81]) + rng.normal(size=(ni, 3)) * k.accel_noise * math.sqrt(k.imu_hz)
    acc += air_i * rng.normal(size=(ni, 3)) * k.accel_vibration
    np.savetxt(d / "imu.csv", np.column_stack([ti, gyro, acc]), delimiter=",", fmt="%.6f",
               header="t_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,acc_x_m_s2,acc_y_m_s2,acc_z_m_s2",
               comments="")  # fmt: skip
    (d / "log.toml").write_text("[estimator]\nlever_arm_m = [0.0, 0.0, 0.03]\n")
    return {"offsets": off, "steps": steps, "nlos": nlos, "outliers": out, "air": air, "anchor": an}
