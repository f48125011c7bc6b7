"""Calibration from a static segment: IMU biases, initial roll and pitch, per-anchor range bias and sigma.

While a vehicle stands still, its accelerometer measures ``f = R^T (-g) + b_a`` and its gyro ``w = b_g``
(Earth rate, 7e-5 rad/s, is below a MEMS gyro's bias stability and ignored). So:

* the gyro bias is the mean rate;
* roll and pitch are those that align ``R^T (-g)`` with the mean specific force (the heading, which gravity
  does not show, comes from ``[initial] yaw_deg``). The accelerometer bias is then observable only along
  gravity: ``b_a = (|f| - |g|) f / |f|``; its horizontal part is indistinguishable from a tilt in a static
  segment and is left to the filter (its prior, ``[initial] sigma_accel_bias_m_s2``);
* with the pad's surveyed position, each anchor's range bias is the median of its ranges minus the true
  distance, and its sigma the scaled median absolute deviation (``1.4826 MAD``): median and MAD ignore
  the NLOS excess of an obstructed anchor, where a mean and a standard deviation would take it in. Without
  a position, the least-squares fix of the median ranges stands in for it, and the biases are the fix's
  residuals (their common part is absorbed into the fix: say so in a report).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarm.core import rotations as rot
from swarm.core.ranging import position_from_ranges
from swarm.errors import LogError


@dataclass(frozen=True)
class StaticCalibration:
    """What :func:`calibrate_static` found (nav frame, SI units)."""

    until_s: float
    q_nav_body: np.ndarray
    accel_bias: np.ndarray
    gyro_bias: np.ndarray
    position_nav: np.ndarray
    position_surveyed: bool
    range_bias: np.ndarray
    """Per anchor index [m] (NaN for an anchor without ranges in the segment)."""
    range_sigma: np.ndarray
    range_count: np.ndarray


def level_attitude(f_body: np.ndarray, gravity_nav: np.ndarray, yaw_rad: float) -> np.ndarray:
    """``q_nav_body`` whose ``R^T (-g)`` is along ``f_body``, with heading ``yaw_rad`` about ``-g``."""
    up_body = f_body / np.linalg.norm(f_body)
    up_nav = -gravity_nav / np.linalg.norm(gravity_nav)
    # the body's up axis in nav is up_nav; choose the rotation taking up_body to up_nav with least turn,
    # then turn about up_nav by the heading
    axis = np.cross(up_body, up_nav)
    s, c = np.linalg.norm(axis), float(np.dot(up_body, up_nav))
    q_tilt = np.array([0.0, 0.0, 0.0, 1.0]) if s < 1e-12 else rot.rotvec_exp(axis / s * np.arctan2(s, c))
    q_yaw = rot.rotvec_exp(up_nav * yaw_rad)
    return rot.quat_normalize(rot.quat_mul(q_yaw, q_tilt))


def calibrate_static(
    log,
    until_s: float,
    gravity_nav,
    lever_arm_m,
    yaw_rad: float,
    position_nav=None,
    sigma_floor_m: float = 0.02,
) -> StaticCalibration:
    """Calibrate from the samples with ``t < until_s`` of ``log`` (:class:`swarm.logs.reader.Log`)."""
    g = np.asarray(gravity_nav, dtype=float)
    sel = log.imu_t < until_s
    if sel.sum() < 10:
        raise LogError(
            f"log.toml: calibration.until_s = {until_s:g} s holds {int(sel.sum())} IMU samples; "
            "a static segment needs at least 10"
        )
    f = log.acc[sel].mean(axis=0)
    bg = log.gyro[sel].mean(axis=0)
    q = level_attitude(f, g, yaw_rad)
    ba = (np.linalg.norm(f) - np.linalg.norm(g)) * f / np.linalg.norm(f)
    m = len(log.anchors_nav)
    in_seg = log.uwb_t < until_s
    med = np.full(m, np.nan)
    mad = np.full(m, np.nan)
    cnt = np.zeros(m, dtype=np.int64)
    for a in range(m):
        z = log.uwb_range[in_seg & (log.uwb_anchor == a)]
        cnt[a] = len(z)
        if len(z):
            med[a] = np.median(z)
            mad[a] = 1.4826 * np.median(np.abs(z - med[a]))
    lever_nav = rot.quat_rotate(q, np.asarray(lever_arm_m, dtype=float))
    surveyed = position_nav is not None
    if surveyed:
        p = np.asarray(position_nav, dtype=float)
    else:
        have = {a: float(med[a]) for a in range(m) if cnt[a] > 0}
        if len(have) < 4:
            raise LogError(
                f"uwb.csv: {len(have)} anchors ranged in the static segment (t < {until_s:g} s); a fix "
                "needs 4, or give calibration.position_m"
            )
        p, _ = position_from_ranges(log.anchors_nav, have, lever_nav, log.anchors_nav.mean(axis=0))
    dist = np.linalg.norm(p + lever_nav - log.anchors_nav, axis=1)
    bias = med - dist
    sigma = np.where(cnt > 1, np.maximum(mad, sigma_floor_m), np.nan)
    return StaticCalibration(until_s, q, ba, bg, p, surveyed, bias, sigma, cnt)
