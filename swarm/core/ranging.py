"""Position from UWB ranges, or from TDoA distance differences, alone: the fix a filter starts from, or
re-initialises from after a divergence.

Used by a restarted agent (:mod:`agents.process`: ranges on a two-way-ranging radio, differences on a TDoA
one), by the IMU-driven filter's recovery (:mod:`swarm.core.imu_filter`) and by the log calibration
(:mod:`swarm.logs.calibrate`).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares


def position_from_ranges(
    anchors_nav: np.ndarray,
    ranges: dict[int, float],
    lever_nav: np.ndarray,
    guess_nav,
    f_scale_m: float = 0.05,
):
    """Centre-of-mass position [m] (3,), frame nav, and its covariance factor ``(J^T J)^-1`` from one or
    more ranges to each of at least four anchors: nonlinear least squares (scipy ``least_squares``, soft-L1
    loss with scale ``f_scale_m`` against an NLOS range) on ``|p + lever_nav - a_i| = rho_i``, started from
    ``guess_nav``. Multiply the factor by the range variance for the position covariance.

    ``lever_nav`` is the tag's lever arm rotated into nav (``R(q) P1``). Coplanar anchors (the paper's four
    satisfy ``2 y + 0.8 z = 0``) leave a mirror solution across their plane: the start decides, and the
    scenario's start position of the vehicle lies on the side it flies on."""
    ids = sorted(ranges)
    A = anchors_nav[ids]
    rho = np.array([ranges[i] for i in ids])

    def residual(p):
        return np.linalg.norm(p + lever_nav - A, axis=1) - rho

    sol = least_squares(residual, np.asarray(guess_nav, dtype=float), loss="soft_l1", f_scale=f_scale_m)
    J = sol.jac
    return sol.x, np.linalg.pinv(J.T @ J)


def position_from_tdoa(
    anchors_nav: np.ndarray,
    rows: np.ndarray,
    lever_nav: np.ndarray,
    guess_nav,
    f_scale_m: float = 0.05,
):
    """Centre-of-mass position [m] (3,), frame nav, and its covariance factor ``(J^T J)^-1`` from distance
    differences alone: hyperbolic multilateration (Foy 1976, Taylor-series position estimation; here
    nonlinear least squares, scipy ``least_squares`` with a soft-L1 loss of scale ``f_scale_m`` against an
    NLOS packet) on ``|t - a_B| - |t - a_A| = d`` with ``t = p + lever_nav`` (the TDoA measurement model of
    :func:`swarm.core._ekf_nb.update_tdoa_one`), started from ``guess_nav``. ``rows`` (K, 3) are anchor
    ``A``, anchor ``B`` and ``d`` [m]. Multiply the factor by the difference variance for the covariance.

    A difference fixes the tag on one sheet of a hyperboloid; three independent ones (four anchors) fix a
    point. Anchors that leave a direction nearly unseen (the paper's four, almost coplanar) leave it with a
    large factor: the caller's covariance says so, it is not an error. Raises ``ValueError`` when the rows
    name fewer than four anchors, or a row is not finite or names an anchor twice or out of range."""
    r = np.asarray(rows, dtype=float).reshape(-1, 3)
    if not np.all(np.isfinite(r)):
        raise ValueError("position_from_tdoa: a row is not finite")
    a, b = r[:, 0].astype(int), r[:, 1].astype(int)
    n = len(anchors_nav)
    if np.any(a == b) or np.any((a < 0) | (a >= n) | (b < 0) | (b >= n)):
        raise ValueError(f"position_from_tdoa: anchor ids must be distinct and in 0..{n - 1}")
    if len(np.union1d(a, b)) < 4:
        raise ValueError(f"position_from_tdoa: {len(np.union1d(a, b))} anchors heard; a 3-D fix needs 4")
    A, B, d = anchors_nav[a], anchors_nav[b], r[:, 2]

    def residual(p):
        t = p + lever_nav
        return np.linalg.norm(t - B, axis=1) - np.linalg.norm(t - A, axis=1) - d

    sol = least_squares(residual, np.asarray(guess_nav, dtype=float), loss="soft_l1", f_scale=f_scale_m)
    J = sol.jac
    return sol.x, np.linalg.pinv(J.T @ J)
