"""The range-error model in the paper's multiplicative EKF (swarm.core._ekf_nb, module docstring): a common
range offset, per-anchor offsets and per-anchor first-order Gauss-Markov terms as extra error states.

Each kernel is checked against a numpy reference written from the textbook equations (``F P F^T + Q`` with
the exact Gauss-Markov discretisation, the Joseph update on the joint state, the tandem's consider noise),
the range Jacobian against central differences, and a filter on simulated ranges with biased anchors for
what the model is for: honest covariance where the white-noise filter is overconfident."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from swarm.core import _ekf_nb as nb
from swarm.core.estimator import EstimatorParams, PoseEstimator, chi2_gate
from swarm.errors import ConfigError
from tests.core.test_estimator import boxplus, random_cov, random_quat, skew

ANCHORS = np.array(
    [[2.0, -2.0, 0.3], [2.0, 2.0, 2.5], [-2.0, 2.0, 0.3], [-2.0, -2.0, 2.5],
     [0.0, -2.5, 1.5], [2.5, 0.0, 0.4], [0.0, 2.5, 2.2], [-2.5, 0.0, 1.0]]
)  # fmt: skip
FULL = {"range_common_offset": True, "range_bias": True, "range_gm": True}
NOISY = {"accel_psd_m2_s3": 0.3, "gyro_arw_rad_rts": 0.02, "range_common_offset_rw": 0.05,
         "range_bias_rw": 0.07, "range_gm_sigma_m": 0.3, "range_gm_tau_s": 0.7}  # fmt: skip


def _params(structure: str, **kw) -> EstimatorParams:
    return EstimatorParams(structure=structure, **{**FULL, **NOISY, **kw})


def _random(rng, params: EstimatorParams, n_anchors: int):
    """A state with random extra states and a random SPD covariance (tandem: zero attitude cross blocks)."""
    m = params.n_extra(n_anchors)
    X = np.concatenate(
        [rng.uniform(-1, 1, 3), rng.normal(0, 0.5, 3), random_quat(rng), rng.normal(0, 0.2, m)]
    )
    P = random_cov(rng, np.r_[[0.3] * 3, [0.1] * 3, [0.05] * 3, [0.2] * m])
    if params.structure.value == "tandem":
        P[6:9, :6] = P[:6, 6:9] = 0.0
        P[6:9, 9:] = P[9:, 6:9] = 0.0
    return X, P


def _phi_q(params: EstimatorParams, n_anchors: int, dt: float):
    """Transition and noise of each extra state, from the model's definition (numpy)."""
    phi, q = [], []
    if params.range_common_offset:
        phi.append(1.0), q.append(params.range_common_offset_rw**2 * dt)
    if params.range_bias:
        phi += [1.0] * n_anchors
        q += [params.range_bias_rw**2 * dt] * n_anchors
    if params.range_gm:
        g = np.exp(-dt / params.range_gm_tau_s)
        phi += [g] * n_anchors
        q += [params.range_gm_sigma_m**2 * (1 - g * g)] * n_anchors
    return np.array(phi), np.array(q)


@pytest.mark.parametrize("structure", ["compounded", "tandem"])
def test_predict_is_F_P_Ft_plus_Q_with_the_extra_states(structure):
    rng = np.random.default_rng(5)
    params, na = _params(structure), 3
    X, P = _random(rng, params, na)
    w, a, dt = rng.normal(0, 2.0, 3), rng.normal(0, 1.0, 3), 0.2
    prm = params.param_vector(na)
    X1, P1 = X.copy(), P.copy()
    counts, book = np.zeros((3, nb.N_TYPES), dtype=np.int64), np.zeros(nb.N_STF)
    assert nb.predict_one(X1, P1, counts, book, w, a, dt, prm) == nb.ST_ACCEPTED
    n = P.shape[0]
    phi, q = _phi_q(params, na, dt)
    F = np.eye(n)
    F[:3, 3:6] = dt * np.eye(3)
    F[6:9, 6:9] = Rotation.from_rotvec(w * dt).as_matrix().T
    F[9:, 9:] = np.diag(phi)
    Q = np.zeros((n, n))
    qa, qt = params.accel_psd_m2_s3, params.gyro_arw_rad_rts**2 + params.attitude_rw_extra_rad_rts**2
    Q[:3, :3] = np.eye(3) * qa * dt**3 / 3
    Q[:3, 3:6] = Q[3:6, :3] = np.eye(3) * qa * dt**2 / 2
    Q[3:6, 3:6], Q[6:9, 6:9], Q[9:, 9:] = np.eye(3) * qa * dt, np.eye(3) * qt * dt, np.diag(q)
    expected = F @ P @ F.T + Q  # tandem: P's attitude cross blocks are zero, and so they stay
    np.testing.assert_allclose(P1, expected, rtol=1e-12, atol=1e-15)
    # the nominal extra states follow their model: offsets hold, Gauss-Markov terms decay
    np.testing.assert_allclose(X1[10:], phi * X[10:], rtol=1e-15)


def test_gauss_markov_variance_follows_its_closed_form_and_offsets_walk():
    """From zero variance, ``sigma^2 (1 - exp(-2 t / tau))`` at any step size (the discretisation is
    exact), and an offset's random walk ``rw^2 t``."""
    params, na = _params("tandem"), 2
    est = PoseEstimator.create(
        params, np.zeros(3), np.zeros(3), [0, 0, 0, 1.0], np.full(9, 1e-2), n_anchors=na
    )
    est.P[0, 9:, 9:] = 0.0
    t = 0.0
    for dt in (0.01, 0.3, 0.05, 1.7, 0.2):
        est.predict(np.zeros(3), np.zeros(3), dt)
        t += dt
    d = np.diag(est.P[0])
    s, tau = params.range_gm_sigma_m, params.range_gm_tau_s
    np.testing.assert_allclose(d[-na:], s**2 * (1 - np.exp(-2 * t / tau)), rtol=1e-12)
    np.testing.assert_allclose(d[10 : 10 + na], params.range_bias_rw**2 * t, rtol=1e-12)
    np.testing.assert_allclose(d[9], params.range_common_offset_rw**2 * t, rtol=1e-12)


def _boxplus_ext(X, dx):
    out = X.copy()
    out[:10] = boxplus(X[:10], dx[:9])
    out[10:] += dx[9:]
    return out


def test_range_jacobian_with_extra_states_matches_central_differences():
    rng = np.random.default_rng(8)
    params, na = _params("compounded"), len(ANCHORS)
    prm = params.param_vector(na)
    for _ in range(20):
        X, _ = _random(rng, params, na)
        j = int(rng.integers(na))
        h, H = nb.range_extra_model(X, prm, ANCHORS[j], j)
        tag = X[:3] + Rotation.from_quat(X[6:10]).apply(params.lever_arm_body_m)
        geometric = np.linalg.norm(tag - ANCHORS[j])
        ic, io, ig = nb.re_index(prm, j)
        assert h == pytest.approx(geometric + X[ic + 1] + X[io + 1] + X[ig + 1], rel=1e-12)
        n, step = len(H), 1e-6
        fd = np.zeros(n)
        for i in range(n):
            e = np.zeros(n)
            e[i] = step
            plus = nb.range_extra_model(_boxplus_ext(X, e), prm, ANCHORS[j], j)[0]
            minus = nb.range_extra_model(_boxplus_ext(X, -e), prm, ANCHORS[j], j)[0]
            fd[i] = (plus - minus) / (2 * step)
        np.testing.assert_allclose(fd, H, atol=1e-7)
        # exactly three extra entries, all 1: the common term, this anchor's offset and its Gauss-Markov term
        assert sorted(np.flatnonzero(H[9:]) + 9) == sorted([ic, io, ig]) and np.all(H[[ic, io, ig]] == 1.0)


@pytest.mark.parametrize("structure", ["compounded", "tandem"])
def test_range_update_is_the_joseph_update_of_the_joint_state(structure):
    rng = np.random.default_rng(9)
    params, na = _params(structure), len(ANCHORS)
    prm = params.param_vector(na)
    X, P = _random(rng, params, na)
    j, sigma = 5, 0.05
    h, H = nb.range_extra_model(X, prm, ANCHORS[j], j)
    z = h + 0.03
    X1, P1 = X.copy(), P.copy()
    counts, book = np.zeros((3, nb.N_TYPES), dtype=np.int64), np.zeros(nb.N_STF)
    st = nb.update_range_anchor_one(X1, P1, counts, book, prm, ANCHORS[j], j, z, sigma, np.inf)
    assert st == nb.ST_ACCEPTED
    Xn, Pn, S = _joseph_reference(structure, X, P, H, z - h, sigma)
    np.testing.assert_allclose(X1, Xn, rtol=0, atol=1e-12)
    np.testing.assert_allclose(P1, Pn, rtol=1e-10, atol=1e-14)
    assert book[nb.STF_D2 + nb.TYPE_RANGE] == pytest.approx((z - h) ** 2 / S, rel=1e-12)


def _joseph_reference(structure, X, P, H, nu, sigma):
    """The textbook scalar update of the joint state (numpy): ``(X+, P+, S)``. Compounded: every state;
    tandem: the translation and extra states, with the attitude filter's uncertainty as extra noise (the
    consider treatment). Joseph form, then the multiplicative attitude reset."""
    n = len(P)
    idx = np.arange(n) if structure == "compounded" else np.r_[0:6, 9:n]
    r = sigma**2
    if structure == "tandem":
        r += H[6:9] @ P[6:9, 6:9] @ H[6:9]
    Pi, Hi = P[np.ix_(idx, idx)], H[idx]
    S = Hi @ Pi @ Hi + r
    K = Pi @ Hi / S
    A = np.eye(len(idx)) - np.outer(K, Hi)
    Pn = P.copy()
    Pn[np.ix_(idx, idx)] = A @ Pi @ A.T + r * np.outer(K, K)
    dx = np.zeros(n)
    dx[idx] = K * nu
    G = np.eye(n)
    G[6:9, 6:9] -= 0.5 * skew(dx[6:9])
    return _boxplus_ext(X, dx), G @ Pn @ G.T, S


@pytest.mark.parametrize("structure", ["compounded", "tandem"])
def test_vision_and_attitude_updates_leave_uncorrelated_extra_states_alone(structure):
    """Extra states uncorrelated with the core: a feature, pose or attitude update moves the core exactly as
    the 9-state filter does and leaves the extra states and their covariance as they were."""
    from tests.core.test_estimator import measurements

    rng = np.random.default_rng(10)
    params, na = _params(structure), 4
    X, P = _random(rng, params, na)
    P[:9, 9:] = P[9:, :9] = 0.0
    core = PoseEstimator(EstimatorParams(structure=structure), X[None, :10].copy(), P[None, :9, :9].copy())
    ext = PoseEstimator(params, X[None].copy(), P[None].copy(), na)
    kw = measurements(X[:10], core.params, rng, noisy=True)
    for name in ("update_features", "update_pose", "update_attitude"):
        a, b = getattr(core, name)(**kw[name]), getattr(ext, name)(**kw[name])
        assert a[0] == b[0] == nb.ST_ACCEPTED, name
        np.testing.assert_allclose(ext.X[0, :10], core.X[0], rtol=0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(ext.P[0, :9, :9], core.P[0], rtol=1e-9, atol=1e-15, err_msg=name)
        np.testing.assert_array_equal(ext.X[0, 10:], X[10:])
        np.testing.assert_array_equal(ext.P[0, 9:, 9:], P[9:, 9:])
        np.testing.assert_array_equal(ext.P[0, :9, 9:], 0.0)


def test_without_the_model_the_filter_is_the_nine_state_one():
    params = EstimatorParams()
    assert params.n_extra(8) == 0 and params.param_vector(8).shape == (nb.N_PRM,)
    est = PoseEstimator.create(
        params, np.zeros(3), np.zeros(3), [0, 0, 0, 1.0], np.full(9, 1e-2), n_anchors=8
    )
    assert est.X.shape == (1, 10) and est.P.shape == (1, 9, 9)
    full = EstimatorParams(**FULL)
    assert full.n_extra(8) == 17 and full.n_extra(0) == 0


BAD = [
    ("range_gm_tau_s", 0.0),
    ("range_bias_rw", -1.0),
    ("range_gm", "yes"),
    ("sigma_range_offset_m", float("nan")),
]


@pytest.mark.parametrize("field,value", BAD)
def test_bad_settings_are_refused_naming_the_field(field, value):
    with pytest.raises(ConfigError, match=f"estimator.{field}"):
        EstimatorParams(**{field: value})


def _static_run(params: EstimatorParams, seed: int, n_steps: int = 3000):
    """A vehicle at rest among 8 anchors, ranged round-robin at 50 Hz, with the errors of a real radio:
    a common offset of -0.3 m, per-anchor offsets of 0.08 m spread, a Gauss-Markov term per anchor and white
    noise. Returns (position error, its covariance) at the end."""
    rng = np.random.default_rng(seed)
    na, dt, sigma = len(ANCHORS), 0.02, 0.02
    p = np.array([0.2, -0.3, 1.1])
    offset = -0.3 + rng.normal(0, 0.08, na)
    s_gm, tau = 0.03, 2.0
    g = rng.normal(0, s_gm, na)
    est = PoseEstimator.create(params, p + rng.normal(0, 0.1, 3), np.zeros(3), [0, 0, 0, 1.0],
                               np.r_[[0.1**2] * 3, [0.01**2] * 3, [0.02**2] * 3], n_anchors=na)  # fmt: skip
    X, P, C, B, prm = est.X[0], est.P[0], est.counts[0], est.book[0], est._prm
    gate = chi2_gate(1, params.gate_probability)
    lever = np.asarray(params.lever_arm_body_m)
    phi = np.exp(-dt / tau)
    for k in range(n_steps):
        g = phi * g + rng.normal(0, s_gm * np.sqrt(1 - phi * phi), na)
        nb.predict_one(X, P, C, B, np.zeros(3), np.zeros(3), dt, prm)
        j = k % na
        z = np.linalg.norm(p + lever - ANCHORS[j]) + offset[j] + g[j] + rng.normal(0, sigma)
        nb.update_range_anchor_one(X, P, C, B, prm, ANCHORS[j], j, z, sigma, gate)
    return X[:3] - p, P[:3, :3]


def test_with_biased_anchors_the_model_keeps_the_covariance_honest_where_white_noise_does_not():
    """Over 8 seeded static runs, the normalised error squared (NEES, 3 dof) of the white-noise filter is
    far out of its chi-square band (offsets of 0.3 m against a 2 cm sigma), the full model's is inside a
    band that 8 runs of a consistent filter leave with probability < 1e-3 (chi-square with 24 dof: the
    sum of 8 NEES below 55) and its error is smaller."""
    nees_w, nees_m, err_w, err_m = [], [], [], []
    for seed in range(8):
        e, C = _static_run(EstimatorParams(sigma_range_m=0.02), seed)
        nees_w.append(e @ np.linalg.solve(C, e)), err_w.append(np.linalg.norm(e))
        e, C = _static_run(EstimatorParams(sigma_range_m=0.02, range_gm_sigma_m=0.03, range_gm_tau_s=2.0,
                                           sigma_range_offset_m=0.1, **FULL), seed)  # fmt: skip
        nees_m.append(e @ np.linalg.solve(C, e)), err_m.append(np.linalg.norm(e))
    assert sum(nees_w) > 55.0, nees_w
    assert sum(nees_m) < 55.0, nees_m
    assert np.median(err_m) < np.median(err_w), (err_m, err_w)


# ---- TDoA: a distance difference between two anchors (issue 45) ------------------------------------------


@pytest.mark.parametrize("model", [{}, FULL])
def test_tdoa_jacobian_matches_central_differences_and_the_common_offset_cancels(model):
    rng = np.random.default_rng(21)
    params = EstimatorParams(structure="compounded", **model)
    na = len(ANCHORS)
    prm = params.param_vector(na)
    for _ in range(20):
        X, _ = _random(rng, params, na)
        ia, ib = rng.choice(na, 2, replace=False)
        h, H = nb.tdoa_model(X, prm, ANCHORS[ia], ANCHORS[ib], ia, ib)
        tag = X[:3] + Rotation.from_quat(X[6:10]).apply(params.lever_arm_body_m)
        geo = np.linalg.norm(tag - ANCHORS[ib]) - np.linalg.norm(tag - ANCHORS[ia])
        if model:
            _, io_b, ig_b = nb.re_index(prm, ib)
            _, io_a, ig_a = nb.re_index(prm, ia)
            geo += X[io_b + 1] + X[ig_b + 1] - X[io_a + 1] - X[ig_a + 1]
            assert H[nb.re_index(prm, ia)[0]] == 0.0  # the common offset is in neither difference
        assert h == pytest.approx(geo, rel=1e-12, abs=1e-12)
        n, step = len(H), 1e-6
        fd = np.zeros(n)
        for i in range(n):
            e = np.zeros(n)
            e[i] = step
            plus = nb.tdoa_model(_boxplus_ext(X, e), prm, ANCHORS[ia], ANCHORS[ib], ia, ib)[0]
            minus = nb.tdoa_model(_boxplus_ext(X, -e), prm, ANCHORS[ia], ANCHORS[ib], ia, ib)[0]
            fd[i] = (plus - minus) / (2 * step)
        np.testing.assert_allclose(fd, H, atol=1e-7)


@pytest.mark.parametrize("structure", ["compounded", "tandem"])
def test_tdoa_update_is_the_joseph_update_of_the_joint_state(structure):
    rng = np.random.default_rng(22)
    params, na = _params(structure), len(ANCHORS)
    prm = params.param_vector(na)
    X, P = _random(rng, params, na)
    ia, ib, sigma = 2, 6, 0.1
    h, H = nb.tdoa_model(X, prm, ANCHORS[ia], ANCHORS[ib], ia, ib)
    z = h - 0.05
    X1, P1 = X.copy(), P.copy()
    counts, book = np.zeros((3, nb.N_TYPES), dtype=np.int64), np.zeros(nb.N_STF)
    st = nb.update_tdoa_one(X1, P1, counts, book, prm, ANCHORS[ia], ANCHORS[ib], ia, ib, z, sigma, np.inf)
    assert st == nb.ST_ACCEPTED and counts[nb.COUNT_ACCEPTED, nb.TYPE_RANGE] == 1
    Xn, Pn, _ = _joseph_reference(structure, X, P, H, z - h, sigma)
    np.testing.assert_allclose(X1, Xn, rtol=0, atol=1e-12)
    np.testing.assert_allclose(P1, Pn, rtol=1e-10, atol=1e-14)


def test_tdoa_update_of_the_nine_state_filter_equals_the_extended_one_without_extras():
    """Without the range-error model the 9-state kernel path gives what the general path gives."""
    rng = np.random.default_rng(23)
    X, P = _random(rng, EstimatorParams(structure="tandem"), 0)
    prm = EstimatorParams(structure="tandem").param_vector(0)
    ia, ib = 0, 3
    h, H = nb.tdoa_model(X, prm, ANCHORS[ia], ANCHORS[ib], ia, ib)
    X1, P1 = X.copy(), P.copy()
    counts, book = np.zeros((3, nb.N_TYPES), dtype=np.int64), np.zeros(nb.N_STF)
    nb.update_tdoa_one(X1, P1, counts, book, prm, ANCHORS[ia], ANCHORS[ib], ia, ib, h + 0.02, 0.05, np.inf)
    X2, P2 = X.copy(), P.copy()
    nb._update_scalar_extra(X2, P2, counts, book, prm, nb.TYPE_RANGE, H, 0.02, 0.05**2, np.inf)
    np.testing.assert_allclose(X1, X2, rtol=0, atol=1e-14)
    np.testing.assert_allclose(P1, P2, rtol=1e-12, atol=1e-16)


@pytest.mark.parametrize(
    ("ia", "ib", "z", "status"),
    [
        (1, 1, 0.1, nb.ST_REFUSED_INVALID),
        (0, 1, 50.0, nb.ST_REFUSED_INVALID),
        (0, 1, np.nan, nb.ST_REFUSED_NONFINITE),
    ],
)
def test_a_tdoa_with_the_same_anchor_twice_too_long_or_not_finite_is_refused_and_counted(ia, ib, z, status):
    params = EstimatorParams()
    est = PoseEstimator.create(params, np.zeros(3), np.zeros(3), [0, 0, 0, 1.0], np.full(9, 1e-2))
    X0, P0 = est.X[0].copy(), est.P[0].copy()
    st = nb.update_tdoa_one(
        est.X[0],
        est.P[0],
        est.counts[0],
        est.book[0],
        est._prm,
        ANCHORS[ia],
        ANCHORS[ib],
        ia,
        ib,
        z,
        0.1,
        9.0,
    )
    assert st == status and est.counts[0, nb.COUNT_REFUSED, nb.TYPE_RANGE] == 1
    np.testing.assert_array_equal(est.X[0], X0)
    np.testing.assert_array_equal(est.P[0], P0)
