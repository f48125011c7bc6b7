"""Position from UWB ranges alone: the fix a filter starts from, or re-initialises from after a divergence.

Used by a restarted agent (:mod:`agents.process`), by the IMU-driven filter's recovery
(:mod:`swarm.core.imu_filter`) and by the log calibration (:mod:`swarm.logs.calibrate`).
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
