"""The IMU-driven error-state filter (swarm.core.imu_filter, swarm.core._imu_nb): Jacobians against finite
differences, propagation against an exact trajectory, timestamps, refusals, batch == single."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.core import _imu_nb as nb
from swarm.core import rotations as rot
from swarm.core.imu_filter import ImuFilter, ImuFilterParams, divergence_limits
from swarm.logs.synthetic import SyntheticSpec, truth_at

ANCHORS = np.array([[-4.0, -3.0, 0.2], [4.0, -3.0, 0.2], [4.0, 3.0, 2.8], [-4.0, 3.0, 2.8]])
PARAMS = ImuFilterParams(lever_arm_m=(0.05, -0.02, 0.03))


def _state(rng, m=4):
    X = np.zeros(16 + m)
    X[0:3] = rng.normal(size=3)
    X[3:6] = rng.normal(size=3)
    X[6:10] = rot.quat_normalize(rng.normal(size=4))
    X[10:13] = rng.normal(size=3) * 0.1
    X[13:16] = rng.normal(size=3) * 0.01
    X[16:] = rng.uniform(0.2, 0.5, m)
    return X


def _plus(X, dx):
    """X (+) dx: the error-state perturbation (local attitude error)."""
    Y = X.copy()
    Y[0:6] += dx[0:6]
    Y[6:10] = rot.quat_mul(X[6:10], rot.rotvec_exp(dx[6:9]))
    Y[10:16] += dx[9:15]
    Y[16:] += dx[15:]
    return Y


def _minus(Y, X):
    """Y (-) X: the error state taking X to Y."""
    d = np.zeros(len(X) - 1)
    d[0:6] = Y[0:6] - X[0:6]
    d[6:9] = rot.quat_log(rot.quat_mul(rot.quat_conj(X[6:10]), Y[6:10]))
    d[9:15] = Y[10:16] - X[10:16]
    d[15:] = Y[16:] - X[16:]
    return d


def _propagate(X, gyro, acc, dt):
    Y = X.copy()
    P = np.eye(len(X) - 1)
    nb.predict_one(Y, P, gyro, acc, dt, PARAMS.vector())
    return Y


@pytest.mark.parametrize("seed", range(3))
def test_the_error_state_transition_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    X = _state(rng)
    gyro, acc, dt = rng.normal(size=3), rng.normal(size=3) + np.array([0, 0, 9.81]), 0.01
    F = np.empty((15, 15))
    nb.transition(X, gyro, acc, dt, F)
    Y0 = _propagate(X, gyro, acc, dt)
    eps = 1e-6
    for k in range(15):
        dx = np.zeros(len(X) - 1)
        dx[k] = eps
        col = _minus(_propagate(_plus(X, dx), gyro, acc, dt), Y0)[:15] / eps
        # first order in dt (Sola 2017 sec. 5.4.3 truncates the transition there): the O(dt^2) terms remain
        np.testing.assert_allclose(col, F[:, k], atol=5 * dt * dt, err_msg=f"column {k}")


@pytest.mark.parametrize("seed", range(3))
def test_the_in_place_covariance_propagation_is_f_p_f_transpose_plus_q(seed):
    """predict_one applies F_x block by block in place; against the dense F P F^T + Q of transition()."""
    rng = np.random.default_rng(seed)
    X = _state(rng)
    A = rng.normal(size=(19, 19))
    P = A @ A.T
    gyro, acc, dt = rng.normal(size=3), rng.normal(size=3) + np.array([0, 0, 9.81]), 0.004
    F = np.eye(19)
    nb.transition(X, gyro, acc, dt, F[:15, :15])
    prm = PARAMS.vector()
    q = (
        np.concatenate(
            [
                np.zeros(3),
                np.full(3, prm[nb.PRM_SIG_A] ** 2),
                np.full(3, prm[nb.PRM_SIG_G] ** 2),
                np.full(3, prm[nb.PRM_SIG_BA] ** 2),
                np.full(3, prm[nb.PRM_SIG_BG] ** 2),
                np.full(4, prm[nb.PRM_SIG_RB] ** 2),
            ]
        )
        * dt
    )
    want = F @ P @ F.T + np.diag(q)
    got = P.copy()
    assert nb.predict_one(X.copy(), got, gyro, acc, dt, prm)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    assert np.array_equal(got, got.T)


@pytest.mark.parametrize("seed", range(3))
def test_the_range_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    X = _state(rng)
    lever = np.array(PARAMS.lever_arm_m)
    for a in range(len(ANCHORS)):
        H = np.empty(len(X) - 1)
        h0 = nb.range_row(X, ANCHORS[a], 15 + a, lever, H)
        eps = 1e-7
        fd = np.empty_like(H)
        for k in range(len(H)):
            dx = np.zeros(len(H))
            dx[k] = eps
            fd[k] = (nb.range_row(_plus(X, dx), ANCHORS[a], 15 + a, lever, np.empty_like(H)) - h0) / eps
        np.testing.assert_allclose(H, fd, atol=1e-6)


def test_noise_free_imu_propagation_follows_the_true_trajectory():
    """Gravity, specific force and the attitude convention together: 10 s of exact 1 kHz IMU samples from
    the synthetic flight integrate back onto its trajectory (the error is the zero-order hold's)."""
    spec = SyntheticSpec()
    t = np.arange(4.0, 14.0, 0.001)  # through the take-off: accelerations, tilts and turns
    p, v, q, w, f = truth_at(spec, t)
    filt = ImuFilter.create(PARAMS, ANCHORS, p[0], v[0], q[0], t[0], 0.05)
    for k in range(len(t)):
        filt.imu(t[k], w[k], f[k])
    assert np.linalg.norm(filt.p_nav[0] - p[-1]) < 0.02  # m, after 10 s of dead reckoning
    assert np.linalg.norm(filt.v_nav[0] - v[-1]) < 0.005
    assert np.degrees(np.linalg.norm(rot.attitude_error(q[-1], filt.q_nav_body[0]))) < 0.05


def _filter(n=1):
    f = ImuFilter.create(
        PARAMS, ANCHORS, np.array([0.0, 0.0, 1.0]), np.zeros(3), np.array([0, 0, 0, 1.0]), 0.0, 0.05
    )
    if n > 1:
        f = ImuFilter(PARAMS, ANCHORS, np.repeat(f.X, n, 0), np.repeat(f.P, n, 0), 0.0, 0.05)
    return f


def test_samples_older_than_the_filter_are_dropped_and_counted():
    f = _filter()
    assert f.imu(0.01, np.zeros(3), [0, 0, 9.81])
    assert f.imu(0.02, np.zeros(3), [0, 0, 9.81])
    X = f.X.copy()
    assert not f.imu(0.015, np.zeros(3), [0, 0, 9.81])
    assert len(f.update_range(0.019, 0, 5.0)) == 0
    assert f.dropped == 2 and np.array_equal(f.X, X)
    assert len(f.update_range(0.025, 0, 5.0)) == 1 and f.t == 0.025  # predicted to the range's own time


def test_non_finite_inputs_never_reach_the_state():
    f = _filter()
    f.imu(0.0, np.zeros(3), [0, 0, 9.81])
    f.imu(0.01, [np.nan, 0, 0], [0, 0, 9.81])  # held: the next prediction refuses it
    f.imu(0.02, np.zeros(3), [0, 0, 9.81])
    assert f.imu_refused == 1
    assert f.update_range(0.03, 1, np.inf)[0] == nb.REFUSED and f.counts[1, nb.REFUSED] == 1
    # a vector fix (GNSS, the pad) with a non-finite component is refused, distance 0, state untouched
    X, P = f.X.copy(), f.P.copy()
    assert f.update_position(0.03, [1.0, np.nan, 0.0], np.eye(3))[0] == nb.REFUSED
    out = f.update_pad(0.03, np.zeros(3), [0.0, 0.0, np.inf], np.eye(3), np.zeros(3), np.eye(3))
    assert out[0] == nb.REFUSED and f.last_pad_d2[0] == 0.0
    assert np.array_equal(f.X, X) and np.array_equal(f.P, P)
    assert np.isfinite(f.X).all() and np.isfinite(f.P).all()


def test_a_batch_steps_each_filter_exactly_as_alone():
    rng = np.random.default_rng(5)
    batch = _filter(3)
    alone = [_filter() for _ in range(3)]
    for k in range(200):
        t = 0.001 * (k + 1)
        gyro, acc = rng.normal(size=3) * 0.1, rng.normal(size=3) + np.array([0, 0, 9.81])
        batch.imu(t, gyro, acc)
        for f in alone:
            f.imu(t, gyro, acc)
        if k % 12 == 0:
            z = rng.uniform(3.0, 6.0, 3)
            out = batch.update_range(t + 0.0005, k % 4, z)
            for i, f in enumerate(alone):
                assert f.update_range(t + 0.0005, k % 4, z[i])[0] == out[i]
    for i, f in enumerate(alone):
        assert np.array_equal(batch.X[i], f.X[0]) and np.array_equal(batch.P[i], f.P[0])


def test_a_range_far_outside_the_gate_is_rejected_and_a_moderate_outlier_underweighted():
    f = _filter()
    f.imu(0.0, np.zeros(3), [0, 0, 9.81])
    h = nb.range_row(f.X[0], ANCHORS[0], 15, np.array(PARAMS.lever_arm_m), np.empty(19))
    assert f.update_range(0.001, 0, h + 50.0)[0] == nb.REJECTED
    g = _filter()
    g.imu(0.0, np.zeros(3), [0, 0, 9.81])
    plain = ImuFilter(
        ImuFilterParams(lever_arm_m=PARAMS.lever_arm_m, huber_k=0.0), ANCHORS, g.X, g.P, 0.0, 0.05
    )
    plain.imu(0.0, np.zeros(3), [0, 0, 9.81])
    sigma = np.sqrt(g.P[0, 0, 0] + 0.05**2)
    for filt in (g, plain):
        assert filt.update_range(0.001, 0, h + 2.5 * sigma)[0] == nb.ACCEPTED  # inside the gate, beyond k = 2
    moved_huber = np.linalg.norm(g.p_nav[0] - [0, 0, 1.0])
    moved_plain = np.linalg.norm(plain.p_nav[0] - [0, 0, 1.0])
    assert moved_huber < moved_plain  # bounded influence


def test_divergence_limits_are_the_chi_square_quantiles_of_the_mean():
    from scipy.stats import chi2

    lim = divergence_limits(50, 1e-6)
    assert lim[50] == pytest.approx(chi2.ppf(1 - 1e-6, 50) / 50)
    assert lim[1] > lim[10] > lim[50] > 1.0  # fewer ranges, more spread


@pytest.mark.parametrize(
    "field, value",
    [
        ("gate_probability", 1.0),
        ("window", 2),
        ("huber_k", -1.0),
        ("gravity_nav", (0.0, 0.0, 0.0)),
        ("accel_noise", float("nan")),
    ],
)
def test_bad_parameters_are_refused_naming_the_field(field, value):
    from swarm.errors import ConfigError

    with pytest.raises(ConfigError, match=rf"^estimator\.{field}"):
        ImuFilterParams(**{field: value})


@pytest.mark.parametrize("seed", range(3))
def test_the_pad_measurement_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    X = _state(rng)
    p_pad = X[0:3] + rng.normal(size=3) * 2.0
    cam = np.array([0.02, -0.01, -0.05])
    R_bc = rot.quat_to_matrix(rot.quat_normalize(rng.normal(size=4)))
    H = np.empty((3, len(X) - 1))
    t0 = nb.pad_row(X, p_pad, cam, R_bc, H)
    # the model itself: the pad in the camera frame
    R = rot.quat_to_matrix(X[6:10])
    np.testing.assert_allclose(t0, R_bc.T @ (R.T @ (p_pad - X[0:3]) - cam), atol=1e-12)
    eps = 1e-7
    fd = np.empty_like(H)
    for k in range(H.shape[1]):
        dx = np.zeros(H.shape[1])
        dx[k] = eps
        fd[:, k] = (nb.pad_row(_plus(X, dx), p_pad, cam, R_bc, np.empty_like(H)) - t0) / eps
    np.testing.assert_allclose(H, fd, atol=1e-6)


@pytest.mark.parametrize("seed", range(3))
def test_the_rangefinder_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    X = _state(rng)
    X[2] = 3.0 + rng.uniform(0.0, 5.0)  # above the ground
    tilt = rot.rotvec_exp(np.r_[rng.normal(0.0, 0.3, 2), rng.uniform(-3, 3)])  # up to ~30 deg, any heading
    X[6:10] = tilt
    ground = -0.2
    H = np.empty((1, len(X) - 1))
    h0 = nb.height_row(X, ground, H)
    # the model itself: the ray along body -z meets the plane z = ground at this distance
    down = rot.quat_to_matrix(X[6:10]) @ np.array([0.0, 0.0, -1.0])
    assert abs((X[2] + h0 * down[2]) - ground) < 1e-12
    eps = 1e-7
    fd = np.empty(H.shape[1])
    for k in range(H.shape[1]):
        dx = np.zeros(H.shape[1])
        dx[k] = eps
        fd[k] = (nb.height_row(_plus(X, dx), ground, np.empty_like(H)) - h0) / eps
    np.testing.assert_allclose(H[0], fd, atol=1e-6)


def test_a_rangefinder_reading_corrects_the_height_and_a_tilted_one_is_refused():
    rng = np.random.default_rng(4)
    X = _state(rng)
    X[2], X[6:10] = 5.0, np.array([0.0, 0.0, 0.0, 1.0])  # level, 5 m up
    P = np.eye(len(X) - 1) * 0.01
    P[2, 2] = 1.0  # 1 m of height uncertainty
    out = np.zeros(2)
    gate = 10.83  # chi-square(1) at 0.999
    assert nb.update_height_one(X, P, 0.0, 4.5, 0.03, np.cos(np.radians(30)), gate, out) == nb.ACCEPTED
    assert abs(X[2] - 4.5) < 0.01 and P[2, 2] < 0.03**2 * 1.01  # the reading's sigma, nearly all of it kept
    Xt = X.copy()
    Xt[6:10] = rot.rotvec_exp(np.array([np.radians(40), 0.0, 0.0]))  # past the 30 deg limit
    Pt = P.copy()
    assert nb.update_height_one(Xt, Pt, 0.0, 9.0, 0.03, np.cos(np.radians(30)), gate, out) == nb.REFUSED
    assert np.array_equal(Pt, P) and Xt[2] == X[2]  # nothing changed
