"""Position fixes from UWB alone (swarm.core.ranging): the multilateration a restarted TDoA tag starts
from."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from swarm.core.ranging import position_from_ranges, position_from_tdoa

CUBE = np.array(list(itertools.product([-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0])))
LEVER = np.array([0.02, -0.01, 0.05])


def _rows(anchors, tag, pairs, rng=None, sigma=0.0):
    """Distance differences ``|t - a_B| - |t - a_A|`` (B minus A, the Crazyflie's ``distanceDiff``)."""
    a, b = np.array(pairs).T
    d = np.linalg.norm(tag - anchors[b], axis=1) - np.linalg.norm(tag - anchors[a], axis=1)
    if rng is not None:
        d = d + rng.normal(0.0, sigma, len(d))
    return np.column_stack([a, b, d])


def _tdoa3_pairs(rng, n, n_anchors):
    """``n`` pairs as a TDoA3 tag hears them: two different anchors, at random."""
    out = []
    while len(out) < n:
        a, b = rng.integers(0, n_anchors, 2)
        if a != b:
            out.append((int(a), int(b)))
    return out


def test_exact_differences_give_the_position_back_with_the_lever_arm_removed():
    rng = np.random.default_rng(0)
    p = np.array([0.3, -0.4, 0.2])
    rows = _rows(CUBE, p + LEVER, _tdoa3_pairs(rng, 40, 8))
    got, F = position_from_tdoa(CUBE, rows, LEVER, guess_nav=[0.0, 0.0, 0.0])
    assert np.allclose(got, p, atol=1e-6)
    assert F.shape == (3, 3) and np.all(np.linalg.eigvalsh(F) > 0)


def test_noisy_differences_scatter_as_the_factor_says():
    """Over 200 seeded fixes from 64 differences of sigma 0.05 m, the mean squared error along each axis is
    the factor's diagonal times sigma^2 to within 30 % (the sampling error of 200 squared normals is ~10 %
    of the mean; the factor is the linearised Cramer-Rao bound, exact to first order at 5 cm noise)."""
    rng = np.random.default_rng(1)
    p, sigma = np.array([0.2, 0.1, -0.3]), 0.05
    err, diag = [], []
    for _ in range(200):
        rows = _rows(CUBE, p + LEVER, _tdoa3_pairs(rng, 64, 8), rng, sigma)
        got, F = position_from_tdoa(CUBE, rows, LEVER, guess_nav=np.zeros(3), f_scale_m=10.0)  # plain LS
        err.append(got - p)
        diag.append(np.diag(F) * sigma**2)
    ratio = np.mean(np.square(err), axis=0) / np.mean(diag, axis=0)
    assert np.all((ratio > 0.7) & (ratio < 1.3)), ratio


def test_an_outlier_is_bounded_by_the_soft_l1_loss():
    """One NLOS packet 1 m long among 63 clean differences moves the fix by under 2 cm; plain least squares
    (a scale far above the residuals) moves it by more than twice that."""
    rng = np.random.default_rng(2)
    p = np.array([-0.2, 0.3, 0.1])
    rows = _rows(CUBE, p, _tdoa3_pairs(rng, 64, 8), rng, 0.005)
    rows[5, 2] += 1.0
    robust, _ = position_from_tdoa(CUBE, rows, np.zeros(3), np.zeros(3))
    plain, _ = position_from_tdoa(CUBE, rows, np.zeros(3), np.zeros(3), f_scale_m=100.0)
    assert np.linalg.norm(robust - p) < 0.02
    assert np.linalg.norm(plain - p) > 2 * np.linalg.norm(robust - p)


def test_the_papers_four_anchors_leave_a_direction_nearly_unseen():
    """The paper's anchors (y within +-0.2 m) hardly see y in differences: the factor along y is many times
    the others, which the restarted agent's covariance carries (it holds), while ranges to the same anchors
    see it (the factor of position_from_ranges)."""
    paper = np.array([[-0.5, 0.2, -0.5], [0.5, 0.2, -0.5], [-0.5, -0.2, 0.5], [0.5, -0.2, 0.5]])
    p = np.array([0.1, 1.5, 0.0])
    rows = _rows(paper, p, list(itertools.permutations(range(4), 2)))
    _, F = position_from_tdoa(paper, rows, np.zeros(3), p + 0.1)
    ranges = {i: float(np.linalg.norm(p - a)) for i, a in enumerate(paper)}
    _, G = position_from_ranges(paper, ranges, np.zeros(3), p + 0.1)
    assert F[1, 1] > 10 * max(F[0, 0], F[2, 2])
    assert F[1, 1] > 10 * G[1, 1]


@pytest.mark.parametrize(
    "rows, match",
    [
        ([[0, 1, 0.1], [1, 2, 0.1], [0, 2, 0.2]], "3 anchors heard"),
        ([[0, 0, 0.1], [1, 2, 0.1], [2, 3, 0.2]], "distinct"),
        ([[0, 9, 0.1], [1, 2, 0.1], [2, 3, 0.2]], "in 0..7"),
        ([[0, 1, float("nan")], [1, 2, 0.1], [2, 3, 0.2]], "not finite"),
    ],
)
def test_rows_that_cannot_fix_a_position_are_refused(rows, match):
    with pytest.raises(ValueError, match=match):
        position_from_tdoa(CUBE, np.array(rows), np.zeros(3), np.zeros(3))
