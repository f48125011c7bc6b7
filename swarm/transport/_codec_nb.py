"""The compiled covariance check of the codec (:data:`swarm.transport.declared._COV_KERNEL`): one pass over a
covariance where numpy takes some five array operations (an estimate's (9, 9) on every agent's tick).

Loaded only in a process that runs numba anyway (:func:`swarm.transport.declared.load_compiled`), so that
decoding messages (a viewer, a recorder) never imports numba.
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True)
def covariance(p, sym_rtol):
    """0 if the square float64 array ``p`` has finite entries, ``max|p - p.T| <= sym_rtol * max|p|`` and a
    diagonal >= 0 (numpy's test, computed exactly as numpy does: the differences, absolute values and
    maxima are exact), else 1 (the numpy checks decide, and name what fails)."""
    asym = 0.0
    amax = 0.0
    n = p.shape[0]
    for i in range(n):
        for j in range(n):
            x = p[i, j]
            if not math.isfinite(x):
                return 1
            amax = max(amax, abs(x))
            asym = max(asym, abs(x - p[j, i]))
        if p[i, i] < 0.0:
            return 1
    return 0 if asym <= sym_rtol * amax else 1
