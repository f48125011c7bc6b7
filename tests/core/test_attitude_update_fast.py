"""The closed-form AHRS attitude update ``_ekf_nb.update_attitude_one`` against the generic path it replaces.

Oracle: ``_ekf_nb._update_attitude_generic``, the same measurement through the dense ``_update`` /
``_kalman_block`` (``np.linalg.solve``, dense Joseph form ``_sandwich(I - K H, P) + K R K^T``, ``_commit``).
The two must agree on the status, the counters and the book-keeping exactly, and on ``X`` and ``P`` to
rounding: the only arithmetic difference is the 3x3 inverse (adjugate against LAPACK's LU) and the order
of a few sums, ~1e-15 of each entry's scale ``sqrt(P_ii P_jj)`` over the cases below, so 1e-12 leaves three
orders of margin while a wrong block, sign or gain is off by far more. The scalar twins of the residual and
of the multiplicative reset are checked bit for bit against the array functions they copy.
"""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from swarm.core import _ekf_nb as nb

GATE3 = float(chi2.ppf(0.9999, 3))
P_RTOL = 1e-12  # of sqrt(P_ii P_jj)
X_ATOL = 1e-12
N_CASES = 150
KIND = nb.TYPE_ATTITUDE
# (underweight_left, beta): armed, only one of the two (so not applied), off
UNDERWEIGHTING = {"armed": (2.0, 0.5), "left_only": (3.0, 0.0), "beta_only": (0.0, 0.5), "off": (0.0, 0.0)}


def random_spd(rng: np.random.Generator, variances: np.ndarray) -> np.ndarray:
    """A correlated SPD matrix with the given diagonal."""
    n = len(variances)
    A = rng.normal(size=(n, n))
    C = A @ A.T + 0.5 * np.eye(n)
    d = np.sqrt(variances / np.diag(C))
    return C * np.outer(d, d)


def random_case(rng: np.random.Generator, tandem: bool):
    """``(X, P, q_meas, cov_body)``: variances log-uniform in 1e-4..1e-1 (position [m^2], velocity
    [m^2/s^2]) and 1e-6..1e-2 rad^2 (attitude), correlated; the tandem structure's zero cross blocks;
    an AHRS covariance of 1e-6..1e-3 rad^2 given slightly asymmetric (the kernel symmetrises it); and
    ``q_meas = q (x) exp(r)``, ``r ~ N(0, c^2 S)`` with ``c`` log-uniform in 0.3..12, so that about half
    the cases pass the 99.99 % gate, given with either sign and a norm in 0.8..1.3."""
    var = np.concatenate([10 ** rng.uniform(-4, -1, 6), 10 ** rng.uniform(-6, -2, 3)])
    P = random_spd(rng, var)
    if tandem:
        P[:6, 6:] = 0.0
        P[6:, :6] = 0.0
    q = Rotation.random(random_state=rng).as_quat()
    X = np.concatenate([rng.uniform(-1.0, 1.0, 3), rng.normal(0.0, 0.5, 3), q])
    cov = random_spd(rng, 10 ** rng.uniform(-6, -3, 3))
    B = rng.normal(size=(3, 3))
    cov_in = cov + 1e-3 * np.min(np.diag(cov)) * (B - B.T)
    S = P[6:, 6:] + cov
    r = np.linalg.cholesky(S) @ rng.normal(size=3) * 10 ** rng.uniform(np.log10(0.3), np.log10(12.0))
    q_meas = (Rotation.from_quat(q) * Rotation.from_rotvec(r)).as_quat()
    q_meas *= rng.choice([-1.0, 1.0]) * rng.uniform(0.8, 1.3)
    return X, P, q_meas, cov_in


def params(tandem: bool, beta: float = 0.0, ratio: float = 0.0) -> np.ndarray:
    prm = np.zeros(nb.N_PRM)
    prm[nb.PRM_TANDEM] = 1.0 if tandem else 0.0
    prm[nb.PRM_ATT_PSD] = 1e-6
    prm[nb.PRM_ACCEL_PSD] = 1e-4
    prm[nb.PRM_UW_BETA] = beta
    prm[nb.PRM_UW_GAP_S] = 0.5
    prm[nb.PRM_UW_COUNT] = 3.0
    prm[nb.PRM_UW_RATIO] = ratio
    return prm


def book(uw_left: float = 0.0):
    ST_I = np.zeros((3, nb.N_TYPES), dtype=np.int64)
    ST_I[:, KIND] = [5, 2, 1]  # counters continue from earlier updates
    ST_F = np.zeros(nb.N_STF)
    ST_F[nb.STF_SINCE] = 0.3
    ST_F[nb.STF_UW_LEFT] = uw_left
    ST_F[nb.STF_D2 : nb.STF_D2 + nb.N_TYPES] = [1.0, 2.0, 3.0, 4.0, 5.0]
    return ST_I, ST_F


def run(fn, X, P, ST_I, ST_F, prm, q_meas, cov, gate):
    """``fn`` on copies: ``(status, X, P, ST_I, ST_F)`` after the call."""
    X, P, ST_I, ST_F = X.copy(), P.copy(), ST_I.copy(), ST_F.copy()
    status = fn(X, P, ST_I, ST_F, prm, q_meas, cov, gate)
    return status, X, P, ST_I, ST_F


def assert_same(fast, ref):
    s1, X1, P1, I1, F1 = fast
    s2, X2, P2, I2, F2 = ref
    assert s1 == s2
    np.testing.assert_array_equal(I1, I2)
    # book-keeping exactly; last d2 to rounding; the tail from STF_WORK is scratch
    np.testing.assert_array_equal(F1[: nb.STF_D2], F2[: nb.STF_D2])
    np.testing.assert_allclose(F1[nb.STF_D2 : nb.STF_WORK], F2[nb.STF_D2 : nb.STF_WORK], rtol=1e-12, atol=0)
    np.testing.assert_allclose(X1, X2, rtol=0, atol=X_ATOL)
    scale = np.sqrt(np.outer(np.diag(P2), np.diag(P2)))
    assert np.all(np.abs(P1 - P2) <= P_RTOL * scale), np.max(np.abs(P1 - P2) / scale)


@pytest.mark.parametrize("uw", list(UNDERWEIGHTING))
@pytest.mark.parametrize("structure", ["tandem", "compounded"])
def test_fast_update_equals_generic(structure, uw):
    """Random states, measurements and noises, accepted and gated out, underweighting armed or not (and
    where armed, applied or not by the ``tr(H P H^T) > ratio tr(R)`` test): the same outcome."""
    tandem = structure == "tandem"
    uw_left, beta = UNDERWEIGHTING[uw]
    rng = np.random.default_rng(10 * tandem + list(UNDERWEIGHTING).index(uw))
    seen = {nb.ST_ACCEPTED: 0, nb.ST_REJECTED: 0}
    underweighted = 0
    for _ in range(N_CASES):
        X, P, q_meas, cov = random_case(rng, tandem)
        ratio = rng.choice([0.1, 1.0, 30.0])
        prm = params(tandem, beta, ratio)
        gate = GATE3 if rng.uniform() < 0.8 else np.inf
        ST_I, ST_F = book(uw_left)
        fast = run(nb.update_attitude_one, X, P, ST_I, ST_F, prm, q_meas, cov, gate)
        ref = run(nb._update_attitude_generic, X, P, ST_I, ST_F, prm, q_meas, cov, gate)
        assert_same(fast, ref)
        status, X1, P1, I1, F1 = fast
        seen[status] += 1
        scale = np.sqrt(np.outer(np.diag(P1), np.diag(P1)))
        assert np.all(np.abs(P1 - P1.T) <= 1e-14 * scale)
        assert np.all(np.linalg.eigvalsh(0.5 * (P1 + P1.T)) > 0.0)
        if status == nb.ST_ACCEPTED:
            assert F1[nb.STF_SINCE] == 0.0
            assert F1[nb.STF_UW_LEFT] == max(uw_left - 1.0, 0.0)
            assert I1[nb.COUNT_ACCEPTED, KIND] == ST_I[nb.COUNT_ACCEPTED, KIND] + 1
            if tandem:  # the translation filter is untouched
                np.testing.assert_array_equal(X1[:6], X[:6])
                np.testing.assert_array_equal(P1[:6, :6], P[:6, :6])
                np.testing.assert_array_equal(P1[:6, 6:], 0.0)
            sym_cov = 0.5 * (cov + cov.T)
            applied = uw_left > 0 and beta > 0 and np.trace(P[6:, 6:]) > ratio * np.trace(sym_cov)
            if applied:  # the underweighted gain really differs from the plain one
                underweighted += 1
                plain = run(nb._update_attitude_generic, X, P, ST_I, ST_F, params(tandem), q_meas, cov, gate)
                assert np.max(np.abs(plain[2] - P1)) > 1e-6 * np.max(np.abs(P1[6:, 6:]))
        else:
            assert F1[nb.STF_SINCE] == ST_F[nb.STF_SINCE]
            assert F1[nb.STF_UW_LEFT] == uw_left
            np.testing.assert_array_equal(X1, X)
            np.testing.assert_array_equal(P1, P)
    assert seen[nb.ST_ACCEPTED] > 0.2 * N_CASES
    assert seen[nb.ST_REJECTED] > 0.2 * N_CASES
    if uw == "armed":
        assert underweighted > 0.1 * N_CASES


@pytest.mark.parametrize("structure", ["tandem", "compounded"])
def test_sequence_with_predictions_equals_generic(structure):
    """A run of predictions and 100 Hz attitude updates, a 1 s gap arming underweighting (counted down
    over three updates) and a few outliers: the fast and generic filters stay together."""
    tandem = structure == "tandem"
    rng = np.random.default_rng(7)
    X0, P0, _, _ = random_case(rng, tandem)
    prm = params(tandem, beta=0.5, ratio=0.1)
    states = [(X0.copy(), P0.copy(), *book()) for _ in range(2)]
    cov = np.diag([2e-5, 3e-5, 1e-4])
    q_true = X0[6:].copy()
    for k in range(300):
        w = rng.normal(0.0, 0.3, 3)
        a = rng.normal(0.0, 0.1, 3)
        dt = 1.0 if k == 100 else 0.01
        q_true = (Rotation.from_quat(q_true) * Rotation.from_rotvec(w * dt)).as_quat()
        noise = rng.normal(0.0, 0.005, 3) if k % 37 else rng.normal(0.0, 0.5, 3)
        q_meas = (Rotation.from_quat(q_true) * Rotation.from_rotvec(noise)).as_quat()
        out = []
        fns = (nb.update_attitude_one, nb._update_attitude_generic)
        for fn, (X, P, ST_I, ST_F) in zip(fns, states, strict=True):
            nb.predict_one(X, P, ST_I, ST_F, w, a, dt, prm)
            out.append(fn(X, P, ST_I, ST_F, prm, q_meas, cov, GATE3))
        assert out[0] == out[1]
        (X1, P1, I1, F1), (X2, P2, I2, F2) = states
        np.testing.assert_array_equal(I1, I2)
        np.testing.assert_array_equal(F1[: nb.STF_D2], F2[: nb.STF_D2])
        np.testing.assert_allclose(X1, X2, rtol=0, atol=X_ATOL)
        scale = np.sqrt(np.outer(np.diag(P2), np.diag(P2)))
        assert np.all(np.abs(P1 - P2) <= P_RTOL * scale)
    I1 = states[0][2]
    assert I1[nb.COUNT_REJECTED, KIND] > 0 and I1[nb.COUNT_ACCEPTED, KIND] > 250


@pytest.mark.parametrize("structure", ["tandem", "compounded"])
@pytest.mark.parametrize(
    ("q_meas", "cov", "status"),
    [
        ([0.0, 0.0, np.nan, 1.0], np.eye(3), nb.ST_REFUSED_NONFINITE),
        ([0.0, 0.0, 0.0, 1.0], np.diag([1e-4, np.inf, 1e-4]), nb.ST_REFUSED_NONFINITE),
        ([0.0, 0.0, 0.0, 0.7], 1e-4 * np.eye(3), nb.ST_REFUSED_INVALID),  # |q|^2 < 0.5
        ([0.0, 1.0, 0.0, 1.0001], 1e-4 * np.eye(3), nb.ST_REFUSED_INVALID),  # |q|^2 > 2
        ([1.0, 0.0, 0.0, 0.0], -1.0 * np.eye(3), nb.ST_REFUSED_INVALID),  # d2 < 0
    ],
)
def test_refused_inputs_as_generic(structure, q_meas, cov, status):
    tandem = structure == "tandem"
    X, P, _, _ = random_case(np.random.default_rng(3), tandem)
    args = (X, P, *book(), params(tandem), np.array(q_meas), np.array(cov), GATE3)
    fast = run(nb.update_attitude_one, *args)
    assert fast[0] == status
    assert_same(fast, run(nb._update_attitude_generic, *args))
    np.testing.assert_array_equal(fast[1], X)
    np.testing.assert_array_equal(fast[2], P)


@pytest.mark.parametrize("structure", ["tandem", "compounded"])
def test_non_finite_covariance_outside_the_attitude_block(structure):
    """A NaN in the translation block. The generic path raises ``LinAlgError`` (its dense products
    ``0 * NaN`` carry the NaN into ``S``). The fast compounded update refuses the measurement, its result
    being non-finite (ST_REFUSED_INVALID, d2 recorded, nothing changed); the fast tandem attitude filter
    never reads the translation block (``H_t = 0``) and updates as the generic path does with a finite
    translation block, leaving the NaN where it is."""
    tandem = structure == "tandem"
    X, P, _, cov = random_case(np.random.default_rng(4), tandem)
    q_meas = (Rotation.from_quat(X[6:]) * Rotation.from_rotvec([0.01, 0.0, 0.0])).as_quat()
    P_nan = P.copy()
    P_nan[1, 2] = P_nan[2, 1] = np.nan
    ST_I, ST_F = book()
    fast = run(nb.update_attitude_one, X, P_nan, ST_I, ST_F, params(tandem), q_meas, cov, np.inf)
    with pytest.raises(np.linalg.LinAlgError):
        run(nb._update_attitude_generic, X, P_nan, ST_I, ST_F, params(tandem), q_meas, cov, np.inf)
    ref = run(nb._update_attitude_generic, X, P, ST_I, ST_F, params(tandem), q_meas, cov, np.inf)
    np.testing.assert_allclose(fast[4][nb.STF_D2 + KIND], ref[4][nb.STF_D2 + KIND], rtol=1e-12)
    if tandem:
        assert np.isnan(fast[2][1, 2]) and np.isnan(fast[2][2, 1])
        fast[2][1, 2] = fast[2][2, 1] = P[1, 2]
        assert_same(fast, ref)
    else:
        assert fast[0] == nb.ST_REFUSED_INVALID
        assert fast[3][nb.COUNT_REFUSED, KIND] == ST_I[nb.COUNT_REFUSED, KIND] + 1
        np.testing.assert_array_equal(fast[1], X)
        np.testing.assert_array_equal(fast[2], P_nan)


@pytest.mark.parametrize("structure", ["tandem", "compounded"])
@pytest.mark.parametrize("case", ["nan_attitude_block", "singular_S"])
def test_unusable_innovation_covariance_is_refused(structure, case):
    """Where ``np.linalg.solve`` in the generic path raises (a non-finite or exactly singular ``S``), the
    fast update refuses the measurement (ST_REFUSED_INVALID, non-finite d2 recorded) and changes nothing."""
    tandem = structure == "tandem"
    X, P, q_meas, cov = random_case(np.random.default_rng(5), tandem)
    if case == "nan_attitude_block":
        P[7, 7] = np.nan
    else:
        P[6:, :] = 0.0
        P[:, 6:] = 0.0
        cov = np.zeros((3, 3))
    ST_I, ST_F = book()
    fast = run(nb.update_attitude_one, X, P, ST_I, ST_F, params(tandem), q_meas, cov, GATE3)
    assert fast[0] == nb.ST_REFUSED_INVALID
    assert fast[3][nb.COUNT_REFUSED, KIND] == ST_I[nb.COUNT_REFUSED, KIND] + 1
    assert not np.isfinite(fast[4][nb.STF_D2 + KIND])
    np.testing.assert_array_equal(fast[1], X)
    np.testing.assert_array_equal(fast[2], P)
    with pytest.raises(np.linalg.LinAlgError):
        run(nb._update_attitude_generic, X, P, ST_I, ST_F, params(tandem), q_meas, cov, GATE3)


@pytest.mark.parametrize("structure", ["tandem", "compounded"])
def test_entries_beyond_the_bound_go_to_the_generic_path(structure):
    """Huge (finite) entries, where a closed-form product could overflow: the generic path's result, bit
    for bit."""
    tandem = structure == "tandem"
    X, P, q_meas, cov = random_case(np.random.default_rng(6), tandem)
    if tandem:
        cov = 1e101 * np.eye(3)  # R beyond the bound
        q_meas = X[6:].copy()
    else:
        P[:3, :] *= 1e60
        P[:, :3] *= 1e60  # position variances ~1e117
    args = (X, P, *book(), params(tandem), q_meas, cov, np.inf)
    fast = run(nb.update_attitude_one, *args)
    ref = run(nb._update_attitude_generic, *args)
    assert fast[0] == ref[0] == nb.ST_ACCEPTED
    for a, b in zip(fast[1:4], ref[1:4], strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(fast[4][: nb.STF_WORK], ref[4][: nb.STF_WORK])  # the tail is scratch


def test_scalar_twins_are_bit_identical():
    """``_attitude_residual3`` is ``attitude_residual``'s residual and ``_reset_attitude3_noalloc`` is
    ``_reset_attitude3``, bit for bit, on both branches of the log and exp series, either hemisphere."""
    rng = np.random.default_rng(8)
    for k in range(400):
        X, P, _, _ = random_case(rng, tandem=False)
        angle = [1e-9, 1e-4, 5e-4, 2e-3, 0.3, 3.0][k % 6]
        r = rng.normal(size=3)
        r *= angle / np.linalg.norm(r)
        q_meas = (Rotation.from_quat(X[6:]) * Rotation.from_rotvec(r)).as_quat()
        q_meas *= rng.choice([-1.0, 1.0]) * rng.uniform(0.8, 1.3)
        nu, _ = nb.attitude_residual(X, q_meas)
        assert nb._attitude_residual3(X, q_meas) == tuple(nu)
        X1, P1, X2, P2 = X.copy(), P.copy(), X.copy(), P.copy()
        nb._reset_attitude3(X1, P1, *r)
        nb._reset_attitude3_noalloc(X2, P2, *r)
        np.testing.assert_array_equal(X1, X2)
        np.testing.assert_array_equal(P1, P2)


@njit
def _no_op(X, P, ST_I, ST_F, PRM, q_meas, cov, gate):
    return 0


@pytest.mark.parametrize("structure", ["tandem", "compounded"])
def test_no_heap_allocation_per_update(structure):
    """Numba's runtime allocation counters: a call of the update allocates what a call of a function doing
    nothing with the same arguments does (their boxing), so nothing of its own; the generic path did."""
    nrt = pytest.importorskip("numba.core.runtime._nrt_python")
    from numba.core.runtime import rtsys

    tandem = structure == "tandem"
    X, P, _, cov = random_case(np.random.default_rng(9), tandem)
    q_meas = (Rotation.from_quat(X[6:]) * Rotation.from_rotvec([1e-3, -2e-3, 5e-4])).as_quat()
    ST_I, ST_F = book()
    args = (X, P, ST_I, ST_F, params(tandem), q_meas, cov, np.inf)
    fns = (_no_op, nb.update_attitude_one, nb._update_attitude_generic)
    for fn in fns:
        fn(*args)  # compiled
    was_enabled = nrt.memsys_stats_enabled()
    nrt.memsys_enable_stats()
    try:
        counts = []
        for fn in fns:
            before = rtsys.get_allocation_stats()
            fn(*args)
            after = rtsys.get_allocation_stats()
            counts.append((after.alloc - before.alloc, after.mi_alloc - before.mi_alloc))
    finally:
        if not was_enabled:
            nrt.memsys_disable_stats()
    assert counts[1] == counts[0]
    assert counts[2][0] > counts[0][0]  # the counters do see the generic path's temporaries
    assert ST_I[nb.COUNT_ACCEPTED, KIND] == 5 + 4  # the two updates called twice each ran, accepted
