"""The counter-based normals of compiled sensor models (swarm.core._noise_nb)."""

from __future__ import annotations

import numpy as np
from scipy import stats

from swarm.core._noise_nb import mix64, noise_key, normals

N = 20000  # draws of 6: the 3-sigma band of a mean is +-0.021, of a variance +-0.03


def _draws(key, counters, width=6):
    out = np.empty((len(counters), width))
    for i, c in enumerate(counters):
        normals(np.uint64(key), c, out[i])
    return out


def test_the_draws_of_a_counter_are_a_pure_function_of_key_and_counter():
    k = np.uint64(noise_key(7, 2, 3))
    a, b = np.empty(6), np.empty(6)
    normals(k, 1234, a)
    normals(k, 1234, b)
    assert np.array_equal(a, b)
    normals(k, 1235, b)
    assert not np.array_equal(a, b)
    # every part of the key matters
    assert len({int(noise_key(s, v, st)) for s in (0, 1) for v in (0, 1) for st in (0, 1)}) == 8


def test_the_draws_are_standard_normal():
    x = _draws(noise_key(0, 0, 3), range(N))
    # 120000 draws: mean within 4 sigma (0.0115), variance within 4 sigma of sqrt(2/n) (0.016)
    assert abs(x.mean()) < 4 / np.sqrt(x.size)
    assert abs(x.var() - 1.0) < 4 * np.sqrt(2.0 / x.size)
    # per column too (each position of a frame's draw is N(0, 1))
    assert np.all(np.abs(x.mean(axis=0)) < 4 / np.sqrt(N))
    # Kolmogorov-Smirnov against N(0, 1): p > 1e-3 for a correct generator fails 1 run in 1000
    assert stats.kstest(x.ravel(), "norm").pvalue > 1e-3
    # the tails: the fraction beyond 3 sigma is 0.0027 (binomial sd 0.00015 at this n)
    tail = np.mean(np.abs(x) > 3.0)
    assert abs(tail - 0.0027) < 4 * np.sqrt(0.0027 / x.size)


def test_neighbouring_counters_keys_and_positions_are_uncorrelated():
    x = _draws(noise_key(5, 1, 3), range(N))
    y = _draws(noise_key(5, 2, 3), range(N))
    bound = 4 / np.sqrt(N)  # 4 sigma of a sample correlation of independent draws
    assert abs(np.corrcoef(x[:-1, 0], x[1:, 0])[0, 1]) < bound  # counter c and c + 1
    assert abs(np.corrcoef(x[:, 0], x[:, 1])[0, 1]) < bound  # the two draws of one Box-Muller pair
    assert abs(np.corrcoef(x[:, 1], x[:, 2])[0, 1]) < bound  # neighbouring pairs
    assert abs(np.corrcoef(x[:, 0], y[:, 0])[0, 1]) < bound  # two vehicles
    # and their squares (Box-Muller pairs share a radius: a broken pairing shows up here)
    assert abs(np.corrcoef(x[:, 0] ** 2, x[:, 1] ** 2)[0, 1]) < bound


def test_mix64_is_a_bijection_on_a_sample():
    xs = np.arange(100000, dtype=np.uint64)
    hs = {int(mix64(x)) for x in xs[:20000]}
    assert len(hs) == 20000
