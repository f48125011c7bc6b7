"""How each agent's filter starts: from the truth with the ``[initial]`` error (a run from its start), or
from its own sensors (a restarted agent, a log).

:func:`initial_estimate` is what the in-process runner and an agent process of the same run both call, on
the same dispersed truth (:func:`swarm.step.world.initial_truth`) and the vehicle's ``init`` stream, so
their filters start bit for bit alike. :func:`position_from_ranges` is the range-only fix a vehicle makes
when it has no such start: least squares on one range to each anchor.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from swarm.core import rotations as rot
from swarm.step.streams import stream


def initial_estimate(sc, vehicle_index: int, x_true: np.ndarray, seed: int):
    """Initial estimate of a vehicle: truth plus N(0, sigma^2) from its ``init`` stream, and the
    covariance (9,) ``sigma^2`` (``[initial]``). A planar vehicle (a module on a table) knows its height,
    vertical speed, roll and pitch from the table it stands on: the same nine numbers are drawn and those
    errors are zero, their variances its kind's constraint's."""
    vid = list(sc.vehicles)[vehicle_index]
    sig = sc.initial.sigmas.copy()
    e = stream(seed, vehicle_index, "init").normal(size=9) * sig
    plane = sc.kind(vid).plane_constraint()
    if plane is not None:
        e[[2, 5, 6, 7]] = 0.0
        sig[2], sig[5] = plane
        sig[6] = sig[7] = np.radians(sc.ahrs.sigma_deg) if sc.ahrs.enabled else sig[6]
    p0 = x_true[0:3] + e[0:3]
    v0 = x_true[3:6] + e[3:6]
    q0 = rot.multiplicative_reset(x_true[6:10], -e[6:9])
    return p0, v0, q0, sig**2


def position_from_ranges(anchors_nav: np.ndarray, ranges: dict[int, float], lever_nav: np.ndarray, guess_nav):
    """Centre-of-mass position [m] (3,), frame nav, and its covariance factor ``(J^T J)^-1`` from one or
    more ranges to each of at least four anchors: nonlinear least squares (scipy ``least_squares``, soft-L1
    loss against an NLOS range) on ``|p + lever_nav - a_i| = rho_i``, started from ``guess_nav``.

    ``lever_nav`` is the tag's lever arm rotated into nav (``R(q) P1``). Coplanar anchors (the paper's four
    satisfy ``2 y + 0.8 z = 0``) leave a mirror solution across their plane: the start decides, and the
    scenario's start position of the vehicle lies on the side it flies on."""
    ids = sorted(ranges)
    A = anchors_nav[ids]
    rho = np.array([ranges[i] for i in ids])

    def residual(p):
        return np.linalg.norm(p + lever_nav - A, axis=1) - rho

    sol = least_squares(residual, np.asarray(guess_nav, dtype=float), loss="soft_l1", f_scale=0.05)
    J = sol.jac
    return sol.x, np.linalg.pinv(J.T @ J)
