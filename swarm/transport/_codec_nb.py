"""The compiled array checks of an estimate's sender fast path
(:func:`swarm.transport.messages.encode_estimate`).

Loaded on the first estimate encoded, so that decoding messages (a viewer, a recorder) never imports numba.
"""

from __future__ import annotations

import math

from numba import njit

PLAIN, SYMMETRIZE, REFERENCE = 0, 1, 2
""":func:`estimate_arrays`' verdicts: send as they are; send the covariance's symmetric part; leave the
decision to the message's own checks."""


@njit(cache=True)
def estimate_arrays(p, v, q, cov, sym_rtol, q_tol):
    """One pass over an estimate's float64 arrays ``p`` (3,), ``v`` (3,), ``q`` (4,) and ``cov`` (9, 9):
    :data:`REFERENCE` if an entry is not finite, a variance is negative or ``q``'s norm is not within half of
    ``q_tol`` of 1 (nearer the edge the message's own test decides); else :data:`SYMMETRIZE` if
    ``max|cov - cov.T| > sym_rtol * max|cov|`` (the message's own test, computed exactly as numpy does:
    the differences, absolute values and maxima are exact), else :data:`PLAIN`."""
    for i in range(3):
        if not (math.isfinite(p[i]) and math.isfinite(v[i])):
            return REFERENCE
    n2 = 0.0
    for i in range(4):
        if not math.isfinite(q[i]):
            return REFERENCE
        n2 += q[i] * q[i]
    if abs(math.sqrt(n2) - 1.0) > 0.5 * q_tol:
        return REFERENCE
    asym = 0.0
    amax = 0.0
    n = cov.shape[0]
    for i in range(n):
        for j in range(n):
            x = cov[i, j]
            if not math.isfinite(x):
                return REFERENCE
            amax = max(amax, abs(x))
            asym = max(asym, abs(x - cov[j, i]))
        if cov[i, i] < 0.0:
            return REFERENCE
    return SYMMETRIZE if asym > sym_rtol * amax else PLAIN
