"""How each agent's filter starts: from the truth with the ``[initial]`` error (a run from its start), or
from its own sensors (a restarted agent, a log).

:func:`initial_estimate` is what the in-process runner and an agent process of the same run both call, on
the same dispersed truth (:func:`swarm.step.world.initial_truth`) and the vehicle's ``init`` stream, so
their filters start bit for bit alike. A vehicle without such a start (a restarted agent, a log) fixes its
position from ranges alone: :func:`swarm.core.ranging.position_from_ranges`.
"""

from __future__ import annotations

import numpy as np

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
