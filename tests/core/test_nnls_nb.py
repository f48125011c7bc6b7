"""Tests for the compiled NNLS of swarm.core.thrusters: ``nnls_nb`` and ``allocate_nb``.

Oracles: ``scipy.optimize.nnls`` (the same Lawson & Hanson algorithm; its ``x`` where the solution is
unique, its optimal value where it is not), the KKT conditions of ``min |A x - b|`` s.t. ``x >= 0``
(sufficient, the problem being convex), a brute-force search over supports for rank-deficient ``A``
(where scipy's own answer is unreliable: it accepts nearly dependent columns and returns ``x ~ 1e14``
with a wrong residual in a few problems per thousand), closed forms for the edge cases, and the Python
:func:`allocate` for :func:`allocate_nb`.
"""

from __future__ import annotations

import itertools
import math

import numba
import numpy as np
import pytest
from scipy.optimize import linprog, nnls

from swarm.core import thrusters as thr

PARAMS = thr.ThrusterParams()
B = thr.allocation_matrix(PARAMS)
F_MAX = PARAMS.max_thrust_n
WRENCH_SCALE = np.r_[np.ones(3), 0.03 * np.ones(3)]  # N and N m: torques ~ force x 3 cm


def _solve(A: np.ndarray, b: np.ndarray, maxiter: int = -1) -> tuple[np.ndarray, float, int]:
    A = np.ascontiguousarray(A, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    work, iwork = thr.nnls_workspace(*A.shape)
    x = np.full(A.shape[1], np.nan)  # nnls_nb must overwrite every entry
    rnorm = thr.nnls_nb(A, b, x, work, iwork, maxiter)
    return x, rnorm, int(iwork[0])


def _kkt_violation(A: np.ndarray, b: np.ndarray, x: np.ndarray) -> float:
    """Largest violation of ``x >= 0``, ``w <= 0`` where ``x = 0`` and ``w = 0`` where ``x > 0``
    (``w = A^T (b - A x)``), relative to the round-off scale of ``w``."""
    w = A.T @ (b - A @ x)
    anorm = np.linalg.norm(A, axis=0).max()
    scale = anorm * (np.linalg.norm(b) + anorm * np.abs(x).sum())
    if scale == 0.0:
        return float(np.abs(w).max(initial=0.0))
    on = x > 0
    return max(-x.min(initial=0.0), w[~on].max(initial=0.0), np.abs(w[on]).max(initial=0.0)) / scale


def _random_problem(rng: np.random.Generator, m: int, n: int, rank: int | None = None):
    A = rng.normal(size=(m, n)) if rank is None else rng.normal(size=(m, rank)) @ rng.normal(size=(rank, n))
    return A * 10.0 ** rng.uniform(-3, 3), rng.normal(size=m) * 10.0 ** rng.uniform(-3, 3)


def _brute_force_optimum(A: np.ndarray, b: np.ndarray, rank: int) -> float:
    """``min |A x - b|`` over ``x >= 0`` by trying every support of at most ``rank`` columns: some optimal
    ``x`` has linearly independent positive columns, and on those the least-squares fit is unique."""
    best = float(np.linalg.norm(b))
    for k in range(1, rank + 1):
        for support in itertools.combinations(range(A.shape[1]), k):
            As = A[:, support]
            y = np.linalg.lstsq(As, b, rcond=None)[0]
            if y.min() >= -1e-12 * np.abs(y).max():
                best = min(best, float(np.linalg.norm(As @ np.maximum(y, 0.0) - b)))
    return best


# ------------------------------------------------------------------------------------ (a) random problems


@pytest.mark.parametrize(("m", "n"), [(6, 6), (10, 4), (5, 1)])
def test_full_column_rank_matches_scipy_x(m: int, n: int) -> None:
    rng = np.random.default_rng(100 + 10 * m + n)
    n_active = 0
    for _ in range(200):
        A, b = _random_problem(rng, m, n)
        x, rnorm, status = _solve(A, b)
        xs, rs = nnls(A, b)
        assert status == 0
        assert np.all(x >= 0.0)
        assert np.abs(x - xs).max() <= 1e-9 * max(np.abs(xs).max(), 1e-300)
        assert rnorm == pytest.approx(rs, rel=1e-10, abs=1e-12 * np.linalg.norm(b))
        n_active += np.count_nonzero(x)
    assert 0 < n_active < 200 * n  # the bounds were active in some problems and not in all


@pytest.mark.parametrize(("m", "n"), [(6, 10), (4, 8), (6, 6)])
def test_optimal_value_matches_scipy_and_kkt_holds(m: int, n: int) -> None:
    rng = np.random.default_rng(200 + 10 * m + n)
    inexact = 0
    for _ in range(300):
        A, b = _random_problem(rng, m, n)
        x, rnorm, status = _solve(A, b)
        _, rs = nnls(A, b)
        bnorm = np.linalg.norm(b)
        assert status == 0
        # |b| is the scale: 0 <= optimum <= |b| (x = 0 is feasible), and scipy reports an exact fit as 0.
        assert abs(rnorm - rs) <= 1e-10 * bnorm
        assert rnorm == pytest.approx(np.linalg.norm(A @ x - b), rel=1e-12, abs=1e-14 * bnorm)
        assert _kkt_violation(A, b, x) <= 1e-12
        assert np.count_nonzero(x) <= min(m, n)
        inexact += rnorm > 1e-6 * bnorm
    assert inexact > 0  # some fits were not exact: the non-negativity constraints mattered


@pytest.mark.parametrize(("m", "n", "rank"), [(6, 10, 3), (10, 6, 4), (6, 6, 5)])
def test_rank_deficient_reaches_the_brute_force_optimum(m: int, n: int, rank: int) -> None:
    rng = np.random.default_rng(300 + 10 * m + n)
    for _ in range(25):
        A, b = _random_problem(rng, m, n, rank)
        x, rnorm, status = _solve(A, b)
        assert status == 0
        assert abs(rnorm - _brute_force_optimum(A, b, rank)) <= 1e-10 * np.linalg.norm(b)
        assert _kkt_violation(A, b, x) <= 1e-12
        assert np.count_nonzero(x) <= rank  # the passive columns stayed independent


def test_duplicated_and_parallel_columns_are_never_both_needed() -> None:
    rng = np.random.default_rng(4)
    for _ in range(50):
        A0 = rng.normal(size=(6, 5))
        A = np.hstack([A0, A0[:, ::-1] * rng.uniform(0.5, 2.0, 5)])  # column 9 - j parallel to j
        b = rng.normal(size=6)
        x, rnorm, _ = _solve(A, b)
        assert abs(rnorm - _brute_force_optimum(A0, b, 5)) <= 1e-10 * np.linalg.norm(b)
        assert _kkt_violation(A, b, x) <= 1e-12
        assert all(x[j] == 0.0 or x[9 - j] == 0.0 for j in range(5))


# --------------------------------------------------------------------------------------- (b) the cube


@pytest.mark.parametrize("face_axis", ["x", "y", "z"])
def test_cube_fits_every_wrench_exactly_with_at_most_six_nozzles(face_axis: str) -> None:
    Bf = thr.allocation_matrix(thr.ThrusterParams(face_axis=face_axis))
    rng = np.random.default_rng(ord(face_axis))
    wrenches = [Bf @ rng.uniform(0.0, F_MAX, 10) for _ in range(200)]  # achievable within the limit
    wrenches += [rng.normal(size=6) * WRENCH_SCALE * 10.0 ** rng.uniform(-4, 1) for _ in range(200)]
    for w in wrenches:
        x, rnorm, status = _solve(Bf, w)
        assert status == 0
        assert np.all(x >= 0.0)
        assert rnorm <= 1e-12
        assert np.linalg.norm(Bf @ x - w) <= 1e-12
        assert np.count_nonzero(x) <= 6


def test_cube_allocation_is_a_basic_solution_matching_scipy_in_value() -> None:
    rng = np.random.default_rng(9)
    for _ in range(200):
        w = rng.normal(size=6) * WRENCH_SCALE
        x, rnorm, _ = _solve(B, w)
        _, rs = nnls(B, w)
        assert abs(rnorm - rs) <= 1e-12 * np.linalg.norm(w)
        # both fit exactly; on the symmetric cube several basic solutions do, so x may differ from scipy's
        assert np.linalg.matrix_rank(B[:, x > 0]) == np.count_nonzero(x)


# ------------------------------------------------------------------------------- (c) allocate_nb


@pytest.mark.parametrize("limit", [F_MAX, math.inf])
def test_allocate_nb_equals_allocate(limit: float) -> None:
    rng = np.random.default_rng(12)
    saturated = 0
    f_out, wrench_out = np.empty(10), np.empty(6)
    for k in range(300):
        w = rng.normal(size=6) * WRENCH_SCALE * (0.02 if k % 2 else 2.0)  # half beyond 0.1 N nozzles
        a = thr.allocate(w, B, limit)
        sat = thr.allocate_nb(w, B, limit, f_out, wrench_out)
        assert sat == a.saturated
        np.testing.assert_allclose(f_out, a.thrusts_n, rtol=1e-14, atol=0.0)
        tol = 1e-15 * max(1.0, np.linalg.norm(w))  # B @ f summed in another order
        np.testing.assert_allclose(wrench_out, a.wrench_achieved, rtol=0.0, atol=tol)
        np.testing.assert_allclose(wrench_out, B @ f_out, rtol=0.0, atol=tol)
        saturated += sat
    if math.isinf(limit):
        assert saturated == 0
    else:
        assert 50 < saturated < 250  # both branches exercised
        # the saturated case against the scaling rule itself
        w = np.array([1.0, -0.5, 0.2, 0.01, -0.02, 0.005])
        assert thr.allocate_nb(w, B, limit, f_out, wrench_out)
        x, _, _ = _solve(B, w)
        np.testing.assert_allclose(f_out, x * (limit / x.max()), rtol=1e-15, atol=0.0)
        assert f_out.max() == pytest.approx(limit, rel=1e-15)
        np.testing.assert_allclose(wrench_out, w * (limit / x.max()), rtol=0.0, atol=1e-14)


@numba.njit(cache=True)
def _allocate_rows(W, B, limit, F):
    wrench_out = np.empty(6)
    n_sat = 0
    for k in range(W.shape[0]):
        n_sat += thr.allocate_nb(W[k], B, limit, F[k], wrench_out)
    return n_sat


def test_allocate_nb_is_callable_from_compiled_code() -> None:
    rng = np.random.default_rng(13)
    W = rng.normal(size=(20, 6)) * WRENCH_SCALE * 0.05
    F = np.empty((20, 10))
    n_sat = _allocate_rows(W, B, F_MAX, F)
    for k in range(20):
        a = thr.allocate(W[k], B, F_MAX)
        np.testing.assert_allclose(F[k], a.thrusts_n, rtol=1e-14, atol=0.0)
    assert n_sat == sum(thr.allocate(w, B, F_MAX).saturated for w in W)


def test_allocate_reports_the_nnls_residual_and_rejects_non_finite_B() -> None:
    A = np.zeros((6, 2))
    A[0, 0], A[1, 1] = 1.0, 1.0  # pushes along +x and +y only
    a = thr.allocate(np.array([-1.0, 2.0, 0.0, 0.0, 0.0, 3.0]), A, math.inf)
    np.testing.assert_array_equal(a.thrusts_n, [0.0, 2.0])
    assert a.residual == pytest.approx(math.sqrt(10.0), rel=1e-15)
    bad = B.copy()
    bad[4, 7] = np.inf
    with pytest.raises(ValueError, match="B must be finite"):
        thr.allocate(np.zeros(6), bad, F_MAX)


def test_allocate_nb_rejects_wrong_shapes() -> None:
    with pytest.raises(ValueError, match="allocate_nb"):
        thr.allocate_nb(np.zeros(6), B, F_MAX, np.empty(9), np.empty(6))
    with pytest.raises(ValueError, match="allocate_nb"):
        thr.allocate_nb(np.zeros(5), np.ascontiguousarray(B[:5]), F_MAX, np.empty(10), np.empty(6))


# -------------------------------------------------------------------------------------- (d) edge cases


def test_zero_right_hand_side_gives_zero() -> None:
    for A in (B, np.random.default_rng(1).normal(size=(4, 8)), np.zeros((3, 3))):
        x, rnorm, status = _solve(A, np.zeros(A.shape[0]))
        np.testing.assert_array_equal(x, np.zeros(A.shape[1]))
        assert rnorm == 0.0
        assert status == 0


def test_a_zero_column_stays_off_and_the_rest_is_solved() -> None:
    rng = np.random.default_rng(2)
    for _ in range(50):
        A = rng.normal(size=(6, 10))
        A[:, 4] = 0.0
        b = rng.normal(size=6)
        x, rnorm, _ = _solve(A, b)
        x_rest, r_rest, _ = _solve(np.delete(A, 4, axis=1), b)
        assert x[4] == 0.0
        np.testing.assert_array_equal(np.delete(x, 4), x_rest)
        assert rnorm == r_rest
        assert abs(rnorm - nnls(A, b)[1]) <= 1e-10 * np.linalg.norm(b)


def test_closed_forms_of_the_best_non_negative_fit() -> None:
    # scipy's documented example: x = (1.5, 1), |r| = sqrt(1/2); b < 0 in every direction: x = 0.
    A = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    x, rnorm, _ = _solve(A, np.array([2.0, 1.0, 1.0]))
    np.testing.assert_allclose(x, [1.5, 1.0], rtol=1e-15)
    assert rnorm == pytest.approx(math.sqrt(0.5), rel=1e-15)
    x, rnorm, _ = _solve(A, -np.ones(3))
    np.testing.assert_array_equal(x, [0.0, 0.0])
    assert rnorm == pytest.approx(math.sqrt(3.0), rel=1e-15)
    # six one-way thrusters along +e_i (not spanning): x = max(b, 0), |r| = |min(b, 0)|.
    rng = np.random.default_rng(3)
    for _ in range(50):
        b = rng.normal(size=6)
        x, rnorm, _ = _solve(np.eye(6), b)
        np.testing.assert_array_equal(x > 0.0, b > 0.0)
        np.testing.assert_allclose(x, np.maximum(b, 0.0), rtol=0.0, atol=1e-15 * np.linalg.norm(b))
        assert rnorm == pytest.approx(np.linalg.norm(np.minimum(b, 0.0)), rel=1e-14)


def test_cube_without_a_corner_nozzle_gives_the_best_fit_of_an_unreachable_wrench() -> None:
    Bl = np.ascontiguousarray(np.delete(B, 3, axis=1))  # no longer spans positively (thrusters module)
    # A wrench direction d no thrust combination has a component along: Bl^T d <= 0, from the LP
    # max 1^T s  s.t.  Bl^T d + s <= 0, -1 <= d <= 1, 0 <= s <= 1 (d = 0 only if Bl spanned positively).
    m, n = Bl.shape
    res = linprog(
        np.r_[np.zeros(m), -np.ones(n)],
        A_ub=np.hstack([Bl.T, np.eye(n)]),
        b_ub=np.zeros(n),
        bounds=[(-1.0, 1.0)] * m + [(0.0, 1.0)] * n,
        method="highs",
    )
    d = res.x[:m]
    assert res.status == 0 and np.all(Bl.T @ d <= 1e-12) and np.linalg.norm(d) > 0.1
    d = d * 0.01
    x, rnorm, _ = _solve(Bl, d)  # KKT at x = 0: every w_j = B_j . d <= 0
    np.testing.assert_array_equal(x, np.zeros(n))
    assert rnorm == pytest.approx(np.linalg.norm(d), rel=1e-15)
    # generic wrenches: the best fit (as scipy's) and, for some, no exact fit
    rng = np.random.default_rng(5)
    unreachable = 0
    for _ in range(200):
        w = rng.normal(size=6) * WRENCH_SCALE
        x, rnorm, _ = _solve(Bl, w)
        assert abs(rnorm - nnls(Bl, w)[1]) <= 1e-10 * np.linalg.norm(w)
        assert _kkt_violation(Bl, w, x) <= 1e-12
        unreachable += rnorm > 1e-6 * np.linalg.norm(w)
    assert unreachable > 20


def test_iteration_cap_returns_the_current_feasible_iterate() -> None:
    w = np.array([0.3, -0.2, 0.1, 0.004, -0.003, 0.002])
    x_opt, r_opt, status = _solve(B, w)
    assert status == 0 and np.count_nonzero(x_opt) == 6
    for cap in (1, 2, 3):
        x, rnorm, status = _solve(B, w, maxiter=cap)
        assert status == 1
        assert np.all(x >= 0.0)
        assert 0 < np.count_nonzero(x) <= cap
        assert rnorm == pytest.approx(np.linalg.norm(B @ x - w), rel=1e-12)
        assert r_opt < rnorm < np.linalg.norm(w)


def test_workspace_too_short_and_shape_mismatch_raise() -> None:
    work, iwork = thr.nnls_workspace(6, 10)
    x = np.empty(10)
    with pytest.raises(ValueError, match="too short"):
        thr.nnls_nb(B, np.zeros(6), x, work[:-1], iwork)
    with pytest.raises(ValueError, match="too short"):
        thr.nnls_nb(B, np.zeros(6), x, work, iwork[:-1])
    with pytest.raises(ValueError, match="shape"):
        thr.nnls_nb(B, np.zeros(5), x, work, iwork)
    # reuse of one workspace for many problems: no state leaks from one call to the next
    rng = np.random.default_rng(6)
    for _ in range(20):
        w = rng.normal(size=6)
        r1 = thr.nnls_nb(B, w, x, work, iwork)
        x1 = x.copy()
        fresh_x, fresh_r, _ = _solve(B, w)
        np.testing.assert_array_equal(x1, fresh_x)
        assert r1 == fresh_r
