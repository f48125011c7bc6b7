"""Counter-based Gaussian noise for compiled sensor models: each draw is a pure function of a key and a
counter, so a sensor sample depends on nothing but (run seed, vehicle, tick).

A stream generator (numpy's ``Generator``) has a state that every runner must carry in the same order and
that a checkpoint must save; a counter-based generator has none (Salmon, Moraes, Dror & Shaw 2011,
"Parallel random numbers: as easy as 1, 2, 3", SC'11). Here the bijection is SplitMix64's finaliser
(Steele, Lea & Flood 2014, "Fast splittable pseudorandom number generators", OOPSLA; the output function
of Java's ``SplittableRandom``), applied twice to ``(key, counter, index)``, and the normals come from
the Box-Muller transform of two 53-bit uniforms (Box & Muller 1958). ``tests/core/test_noise_nb.py``
checks the moments, a Kolmogorov-Smirnov test against N(0, 1) and the independence of neighbouring
counters and keys.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TWO_M53 = 1.0 / 9007199254740992.0  # 2^-53


@njit(cache=True)
def mix64(x):
    """SplitMix64's finaliser of ``x + golden``: a bijection of 64-bit integers whose outputs for
    consecutive inputs are statistically independent (module docstring)."""
    z = np.uint64(x) + _GOLDEN
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True)
def noise_key(seed, vehicle, stream):
    """The key of one vehicle's sensor ``stream`` (a small integer naming the sensor) in run ``seed``."""
    return mix64(mix64(mix64(np.uint64(seed)) ^ np.uint64(vehicle)) ^ np.uint64(stream))


@njit(cache=True)
def normals(key, counter, out):
    """Fill ``out`` with independent N(0, 1) draws, the ones of ``(key, counter)`` (e.g. a tick)."""
    base = mix64(np.uint64(key) ^ mix64(np.uint64(counter)))
    n = out.shape[0]
    i = 0
    while i < n:
        h1 = mix64(base + np.uint64(i))
        h2 = mix64(base + np.uint64(i + 1))
        u1 = (float(h1 >> _S11) + 1.0) * _TWO_M53  # (0, 1]
        u2 = float(h2 >> _S11) * _TWO_M53  # [0, 1)
        r = math.sqrt(-2.0 * math.log(u1))
        out[i] = r * math.cos(2.0 * math.pi * u2)
        if i + 1 < n:
            out[i + 1] = r * math.sin(2.0 * math.pi * u2)
        i += 2
