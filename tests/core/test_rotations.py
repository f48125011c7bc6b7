"""Tests for swarm.core.rotations and its numba twin swarm.core._rot_nb.

Oracles: closed forms for a few fixed rotations, scipy.spatial.transform.Rotation (same scalar-last,
Hamilton convention) for random ones, group axioms, and rotations.py itself for the numba twins. The
samplers include near-identity (1e-12 .. 1e-5 rad) and near-180-degree (pi - 1e-9 .. pi) rotations on
purpose: that is where branches and cancellation live.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from swarm.core import _rot_nb
from swarm.core import rotations as rot

FAST = settings(max_examples=60, deadline=None)  # deadline=None: numba compiles on the first call

# ---------------------------------------------------------------------------------------------- samplers

_unit_axes = (
    st.tuples(*[st.floats(-1.0, 1.0)] * 3)
    .map(np.array)
    .filter(lambda a: np.linalg.norm(a) > 0.1)
    .map(lambda a: a / np.linalg.norm(a))
)
_near_identity_rad = st.floats(-12.0, -5.0).map(lambda e: 10.0**e)
_near_pi_rad = st.floats(0.0, 1e-9).map(lambda d: math.pi - d)
# Strictly below pi by more than rounding, so exp(phi) has w > 0 and log(exp(phi)) is phi, not -phi.
_below_pi_rad = st.floats(-12.0, -9.0).map(lambda e: math.pi - 10.0**e)
# Straddles both Taylor thresholds: exp at |phi| = 1e-3, log at tan(|phi| / 2) = 1e-3.
_near_taylor_threshold_rad = st.floats(0.5e-3, 4e-3)
ANGLES_RAD = st.one_of(st.floats(0.0, math.pi), _near_identity_rad, _near_taylor_threshold_rad, _near_pi_rad)


def _axis_angle_quat(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Closed form (axis sin(angle/2), cos(angle/2)), independent of the code under test."""
    return np.array([*(math.sin(0.5 * angle_rad) * axis), math.cos(0.5 * angle_rad)])


@st.composite
def unit_quats(draw: st.DrawFn) -> np.ndarray:
    """Unit quaternion of either sign; angle general, near 0, near the Taylor thresholds or near pi."""
    sign = draw(st.sampled_from([1.0, -1.0]))
    return sign * _axis_angle_quat(draw(_unit_axes), draw(ANGLES_RAD))


@st.composite
def rotvecs(draw: st.DrawFn, below_pi: bool = False) -> np.ndarray:
    """Rotation vector (rad): near 0, general, near pi; beyond pi too unless ``below_pi``."""
    near_0 = st.one_of(_near_identity_rad, _near_taylor_threshold_rad)
    if below_pi:
        angle = draw(st.one_of(near_0, st.floats(0.0, 3.0), _below_pi_rad))
    else:
        angle = draw(st.one_of(near_0, st.floats(0.0, 10.0), _near_pi_rad))
    return angle * draw(_unit_axes)


raw_quats = st.tuples(*[st.floats(-2.0, 2.0)] * 4).map(np.array).filter(lambda q: np.linalg.norm(q) > 0.1)
vectors = st.tuples(*[st.floats(-10.0, 10.0)] * 3).map(np.array)


def assert_same_rotation(a: np.ndarray, b: np.ndarray, atol: float = 2e-15) -> None:
    """Quaternions ``a`` and ``b`` equal up to sign (q and -q are the same rotation)."""
    a, b = np.asarray(a), np.asarray(b)
    sign = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0.0, -1.0, 1.0)
    np.testing.assert_allclose(a, sign * b, rtol=0.0, atol=atol)


# ------------------------------------------------------------------------------- fixed closed-form cases


def test_quat_rotate_90_deg_about_z_maps_x_to_y() -> None:
    q_ref_body = np.array([0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)])
    np.testing.assert_allclose(rot.quat_rotate(q_ref_body, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-16)


def test_quat_mul_composes_like_matrices_for_90_deg_z_then_x() -> None:
    q_z = np.array([0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)])
    q_x = np.array([math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])
    expected = rot.quat_to_matrix(q_z) @ rot.quat_to_matrix(q_x)
    np.testing.assert_allclose(rot.quat_to_matrix(rot.quat_mul(q_z, q_x)), expected, atol=1e-15)
    np.testing.assert_allclose(rot.quat_mul(q_z, q_x), [0.5, 0.5, 0.5, 0.5], atol=1e-16)


@pytest.mark.parametrize(
    ("axis", "expected"),
    [
        ([1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
        ([0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 0.0]),
        ([0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 0.0]),
        ([math.sqrt(0.5), -math.sqrt(0.5), 0.0], [math.sqrt(0.5), -math.sqrt(0.5), 0.0, 0.0]),
    ],
)
def test_matrix_to_quat_of_exact_180_deg_rotation(axis: list[float], expected: list[float]) -> None:
    n = np.array(axis)
    R = 2.0 * np.outer(n, n) - np.eye(3)  # Rodrigues at theta = pi
    assert_same_rotation(rot.matrix_to_quat(R), expected, atol=1e-15)


def test_skew_matches_cross_product() -> None:
    a, b = np.array([1.0, -2.0, 3.0]), np.array([0.5, 4.0, -1.5])
    np.testing.assert_array_equal(rot.skew(a) @ b, np.cross(a, b))
    np.testing.assert_array_equal(rot.skew(a), -rot.skew(a).T)


def test_exp_of_zero_is_exactly_identity() -> None:
    np.testing.assert_array_equal(rot.rotvec_exp(np.zeros(3)), rot.IDENTITY_QUAT)
    np.testing.assert_array_equal(rot.rotvec_exp(np.zeros((2, 3))), np.tile(rot.IDENTITY_QUAT, (2, 1)))
    np.testing.assert_array_equal(_rot_nb.qexp(np.zeros(3)), rot.IDENTITY_QUAT)


def test_log_of_identity_is_exactly_zero() -> None:
    np.testing.assert_array_equal(rot.quat_log(rot.IDENTITY_QUAT), np.zeros(3))
    np.testing.assert_array_equal(rot.quat_log(-rot.IDENTITY_QUAT), np.zeros(3))


def test_euler_zyx_intrinsic_is_yaw_then_pitch_then_roll() -> None:
    yaw, pitch, roll = 0.3, -0.2, 1.1
    q_z = _axis_angle_quat(np.array([0.0, 0.0, 1.0]), yaw)
    q_y = _axis_angle_quat(np.array([0.0, 1.0, 0.0]), pitch)
    q_x = _axis_angle_quat(np.array([1.0, 0.0, 0.0]), roll)
    expected = rot.quat_mul(rot.quat_mul(q_z, q_y), q_x)
    assert_same_rotation(rot.euler_to_quat([yaw, pitch, roll], "ZYX"), expected)
    assert_same_rotation(rot.euler_to_quat([roll, pitch, yaw], "xyz"), expected)


# --------------------------------------------------------------------------------- scipy as the oracle


@FAST
@given(unit_quats(), unit_quats())
def test_quat_mul_matches_scipy_composition(p: np.ndarray, q: np.ndarray) -> None:
    expected = (Rotation.from_quat(p) * Rotation.from_quat(q)).as_quat()
    assert_same_rotation(rot.quat_mul(p, q), expected)


@FAST
@given(unit_quats())
def test_quat_conj_matches_scipy_inverse(q: np.ndarray) -> None:
    assert_same_rotation(rot.quat_conj(q), Rotation.from_quat(q).inv().as_quat())


@FAST
@given(unit_quats(), vectors)
def test_quat_rotate_matches_scipy_apply(q: np.ndarray, v: np.ndarray) -> None:
    np.testing.assert_allclose(rot.quat_rotate(q, v), Rotation.from_quat(q).apply(v), rtol=0, atol=1e-14)


@FAST
@given(raw_quats, vectors)
def test_quat_rotate_equals_matrix_product_for_non_unit_quat(q: np.ndarray, v: np.ndarray) -> None:
    np.testing.assert_allclose(rot.quat_rotate(q, v), rot.quat_to_matrix(q) @ v, rtol=0, atol=1e-13)


@FAST
@given(st.one_of(unit_quats(), raw_quats))
def test_quat_to_matrix_matches_scipy(q: np.ndarray) -> None:
    np.testing.assert_allclose(rot.quat_to_matrix(q), Rotation.from_quat(q).as_matrix(), rtol=0, atol=2e-15)


@FAST
@given(unit_quats())
def test_matrix_to_quat_matches_scipy(q: np.ndarray) -> None:
    R = Rotation.from_quat(q).as_matrix()
    assert_same_rotation(rot.matrix_to_quat(R), Rotation.from_matrix(R).as_quat())


@FAST
@given(unit_quats())
def test_matrix_to_quat_inverts_quat_to_matrix_canonically(q: np.ndarray) -> None:
    q_back = rot.matrix_to_quat(rot.quat_to_matrix(q))
    assert q_back[3] >= 0.0
    assert_same_rotation(q_back, q)


@FAST
@given(rotvecs())
def test_rotvec_exp_matches_scipy(phi: np.ndarray) -> None:
    assert_same_rotation(rot.rotvec_exp(phi), Rotation.from_rotvec(phi).as_quat())


@FAST
@given(unit_quats())
def test_quat_log_matches_scipy(q: np.ndarray) -> None:
    phi, expected = rot.quat_log(q), Rotation.from_quat(q).as_rotvec()
    # the angle is at most pi, up to the rounding of the norm of a 3-vector (a few ulps of pi)
    assert np.linalg.norm(phi) <= math.pi * (1.0 + 4.0 * np.finfo(float).eps)
    if abs(q[3]) < 1e-12 and np.dot(phi, expected) < 0.0:
        expected = -expected  # at 180 deg, +pi and -pi about the axis are the same rotation
    np.testing.assert_allclose(phi, expected, rtol=0, atol=4e-15)
    np.testing.assert_allclose(phi, expected, rtol=1e-14, atol=1e-300)


# ------------------------------------------------------------------------------------ exp / log branches


@FAST
@given(rotvecs(below_pi=True))
def test_log_inverts_exp_below_pi(phi: np.ndarray) -> None:
    err = np.linalg.norm(rot.quat_log(rot.rotvec_exp(phi)) - phi)
    assert err <= 2e-15 * np.linalg.norm(phi), f"log(exp(phi)) is off by {err:.3g} for |phi|={phi}"


@FAST
@given(_unit_axes)
def test_exp_taylor_branch_is_continuous_at_threshold(axis: np.ndarray) -> None:
    thr = rot.EXP_TAYLOR_THRESHOLD_RAD
    t_below, t_above = thr * (1.0 - 1e-12), thr * (1.0 + 1e-12)
    phi_below, phi_above = t_below * axis, t_above * axis
    assert np.sum(phi_below * phi_below) < thr**2 <= np.sum(phi_above * phi_above), "not straddling"
    q_below, q_above = rot.rotvec_exp(phi_below), rot.rotvec_exp(phi_above)
    # Compare sin(t/2)/t (vector part / t) and cos(t/2); either branch wrong shows at ~1e-8.
    np.testing.assert_allclose(q_below[:3] / t_below, q_above[:3] / t_above, rtol=0, atol=1e-14)
    np.testing.assert_allclose(q_below[3], q_above[3], rtol=0, atol=1e-14)


@FAST
@given(_unit_axes)
def test_log_taylor_branch_is_continuous_at_threshold(axis: np.ndarray) -> None:
    thr = rot.LOG_TAYLOR_THRESHOLD  # on tan(theta/2) = |vector part| / w
    t_below, t_above = (2.0 * math.atan(thr * (1.0 + s)) for s in (-1e-12, 1e-12))
    q_below, q_above = _axis_angle_quat(axis, t_below), _axis_angle_quat(axis, t_above)
    assert np.sum(q_below[:3] ** 2) < thr**2 * q_below[3] ** 2, "below sample not in the Taylor branch"
    assert np.sum(q_above[:3] ** 2) >= thr**2 * q_above[3] ** 2, "above sample in the Taylor branch"
    # log(q) / theta is the unit axis on both sides; a wrong series coefficient shows at >= 1e-13.
    axis_below, axis_above = rot.quat_log(q_below) / t_below, rot.quat_log(q_above) / t_above
    np.testing.assert_allclose(axis_below, axis_above, rtol=0, atol=1e-14)
    np.testing.assert_allclose(axis_below, axis, rtol=0, atol=1e-14)


_EXTENDED = np.finfo(np.longdouble).eps < 1e-18
_EPS = np.finfo(np.float64).eps
_grid_rng = np.random.default_rng(7)
_GRID_AXES = _grid_rng.normal(size=(600, 3))
_GRID_AXES /= np.linalg.norm(_GRID_AXES, axis=1, keepdims=True)
_STRADDLE = np.concatenate([1.0 - np.geomspace(1e-15, 1e-2, 100), 1.0 + np.geomspace(1e-15, 1e-2, 100)])


def _exp_reference(phi: np.ndarray) -> np.ndarray:
    """Closed-form exp in extended precision (x87 long double, eps 1.1e-19)."""
    p = phi.astype(np.longdouble)
    t = np.sqrt(np.sum(p * p, axis=-1, keepdims=True))
    return np.concatenate([np.sin(t / 2) / t * p, np.cos(t / 2)], axis=-1)


@pytest.mark.skipif(not _EXTENDED, reason="needs an extended-precision long double as reference")
def test_rotvec_exp_is_accurate_to_two_ulp_around_its_taylor_branch() -> None:
    thr = rot.EXP_TAYLOR_THRESHOLD_RAD
    angles = np.concatenate([np.geomspace(1e-12, 1e-1, 400), thr * _STRADDLE])
    phi = angles[:, None] * _GRID_AXES
    ref = _exp_reference(phi)
    np.testing.assert_allclose(rot.rotvec_exp(phi), ref.astype(np.float64), rtol=2 * _EPS, atol=0)


@pytest.mark.skipif(not _EXTENDED, reason="needs an extended-precision long double as reference")
def test_quat_log_is_accurate_to_two_ulp_near_0_and_180_deg() -> None:
    thr = rot.LOG_TAYLOR_THRESHOLD
    near_thr = 2.0 * np.arctan(thr * _STRADDLE)  # tan(angle / 2) = |vector part| / w straddles thr
    angles = np.concatenate(
        [np.geomspace(1e-12, 1e-1, 200), near_thr, math.pi - np.geomspace(1e-12, 1e-1, 200)]
    )
    q = rot.rotvec_exp(angles[:, None] * _GRID_AXES)
    ql = q.astype(np.longdouble)
    n = np.sqrt(np.sum(ql[:, :3] ** 2, axis=-1, keepdims=True))
    ref = 2 * np.arctan2(n, ql[:, 3:]) / n * ql[:, :3]
    np.testing.assert_allclose(rot.quat_log(q), ref.astype(np.float64), rtol=2 * _EPS, atol=0)


# ---------------------------------------------------------------------------------------- group axioms


@FAST
@given(unit_quats(), unit_quats(), unit_quats())
def test_quat_mul_is_associative(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> None:
    left = rot.quat_mul(rot.quat_mul(p, q), r)
    right = rot.quat_mul(p, rot.quat_mul(q, r))
    np.testing.assert_allclose(left, right, rtol=0, atol=2e-15)


@FAST
@given(unit_quats())
def test_quat_times_its_conjugate_is_identity(q: np.ndarray) -> None:
    np.testing.assert_allclose(rot.quat_mul(q, rot.quat_conj(q)), rot.IDENTITY_QUAT, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rot.quat_mul(rot.quat_conj(q), q), rot.IDENTITY_QUAT, rtol=0, atol=1e-15)


@FAST
@given(raw_quats)
def test_identity_is_neutral_on_both_sides(q: np.ndarray) -> None:
    np.testing.assert_array_equal(rot.quat_mul(rot.IDENTITY_QUAT, q), q)
    np.testing.assert_array_equal(rot.quat_mul(q, rot.IDENTITY_QUAT), q)


# ---------------------------------------------------------------------- MEKF error and reset (Markley 2003)


@FAST
@given(unit_quats(), rotvecs(below_pi=True))
def test_attitude_error_recovers_the_reset_increment(q: np.ndarray, phi: np.ndarray) -> None:
    q_reset = rot.multiplicative_reset(q, phi)
    np.testing.assert_allclose(rot.attitude_error(q, q_reset), phi, rtol=0, atol=1e-14)


@FAST
@given(unit_quats(), rotvecs(below_pi=True))
def test_attitude_error_is_a_body_frame_rotation_vector(q: np.ndarray, phi: np.ndarray) -> None:
    # R(q_reset) = R(q) R(exp(phi)): the error acts on the body side, as in Markley 2003.
    R_expected = Rotation.from_quat(q).as_matrix() @ Rotation.from_rotvec(phi).as_matrix()
    R_reset = rot.quat_to_matrix(rot.multiplicative_reset(q, phi))
    np.testing.assert_allclose(R_reset, R_expected, rtol=0, atol=1e-14)


@FAST
@given(unit_quats())
def test_attitude_error_of_equal_quats_is_zero(q: np.ndarray) -> None:
    np.testing.assert_allclose(rot.attitude_error(q, q), np.zeros(3), rtol=0, atol=1e-16)
    np.testing.assert_allclose(rot.attitude_error(q, -q), np.zeros(3), rtol=0, atol=1e-16)


@pytest.mark.filterwarnings("ignore:Gimbal lock detected:UserWarning")
@FAST
@given(unit_quats())
def test_euler_round_trip_matches_scipy(q: np.ndarray) -> None:
    angles = rot.quat_to_euler(q, "ZYX")
    np.testing.assert_allclose(angles, Rotation.from_quat(q).as_euler("ZYX"), rtol=0, atol=1e-15)
    if abs(angles[1]) < 1.5:  # away from gimbal lock
        assert_same_rotation(rot.euler_to_quat(angles, "ZYX"), q, atol=1e-14)


# ------------------------------------------------------------------------------------------ batch axes

_rng = np.random.default_rng(20240601)
_Q = rot.quat_normalize(_rng.normal(size=(5, 7, 4)))
_P = rot.quat_normalize(_rng.normal(size=(5, 7, 4)))
_V = _rng.normal(size=(5, 7, 3))
_M = rot.quat_to_matrix(_P)

BATCH_CASES = {
    "quat_mul": (rot.quat_mul, (_P, _Q)),
    "quat_conj": (rot.quat_conj, (_Q,)),
    "quat_normalize": (rot.quat_normalize, (3.0 * _Q,)),
    "quat_canonical": (rot.quat_canonical, (_Q,)),
    "quat_rotate": (rot.quat_rotate, (_Q, _V)),
    "quat_to_matrix": (rot.quat_to_matrix, (_Q,)),
    "matrix_to_quat": (rot.matrix_to_quat, (_M,)),
    "skew": (rot.skew, (_V,)),
    "rotvec_exp": (rot.rotvec_exp, (_V,)),
    "quat_log": (rot.quat_log, (_Q,)),
    "attitude_error": (rot.attitude_error, (_P, _Q)),
    "multiplicative_reset": (rot.multiplicative_reset, (_Q, _V)),
    "euler_to_quat": (lambda a: rot.euler_to_quat(a, "XYZ"), (_V,)),
    "quat_to_euler": (lambda q: rot.quat_to_euler(q, "zyx"), (_Q,)),
}


@pytest.mark.parametrize("name", list(BATCH_CASES))
def test_batch_of_shape_5_7_equals_loop(name: str) -> None:
    fn, args = BATCH_CASES[name]
    batched = fn(*args)
    looped = np.array([[fn(*(a[i, j] for a in args)) for j in range(7)] for i in range(5)])
    assert batched.shape == looped.shape
    np.testing.assert_allclose(batched, looped, rtol=0, atol=1e-15, err_msg=name)


def test_quat_mul_broadcasts_leading_axes() -> None:
    out = rot.quat_mul(_P[:, :1], _Q[0])  # (5, 1, 4) x (7, 4) -> (5, 7, 4)
    assert out.shape == (5, 7, 4)
    np.testing.assert_allclose(out[2, 3], rot.quat_mul(_P[2, 0], _Q[0, 3]), rtol=0, atol=0)


# ------------------------------------------------------------------------------------ numba twins


def test_nb_thresholds_match_rotations() -> None:
    assert _rot_nb._EXP_TAYLOR_THRESHOLD_RAD == rot.EXP_TAYLOR_THRESHOLD_RAD
    assert _rot_nb._LOG_TAYLOR_THRESHOLD == rot.LOG_TAYLOR_THRESHOLD


_KINDS = {"quat": unit_quats(), "raw_quat": raw_quats, "rotvec": rotvecs(), "vec": vectors}
TWINS = [
    (_rot_nb.qmul, rot.quat_mul, ("quat", "quat")),
    (_rot_nb.qconj, rot.quat_conj, ("quat",)),
    (_rot_nb.qnormalize, rot.quat_normalize, ("raw_quat",)),
    (_rot_nb.qexp, rot.rotvec_exp, ("rotvec",)),
    (_rot_nb.qlog, rot.quat_log, ("quat",)),
    (_rot_nb.qmat, rot.quat_to_matrix, ("quat",)),
    (_rot_nb.skew3, rot.skew, ("vec",)),
    (_rot_nb.qrotate, rot.quat_rotate, ("quat", "vec")),
]


@pytest.mark.parametrize(("nb_fn", "np_fn", "kinds"), TWINS, ids=[t[0].__name__ for t in TWINS])
@FAST
@given(data=st.data())
def test_nb_twin_equals_rotations(nb_fn, np_fn, kinds: tuple[str, ...], data: st.DataObject) -> None:
    args = [data.draw(_KINDS[k], label=k) for k in kinds]
    expected = np_fn(*args)
    got = nb_fn(*args)
    assert got.shape == expected.shape
    np.testing.assert_allclose(got, expected, rtol=2 * _EPS, atol=0)  # same formulas: within an ulp or two


def test_nb_exp_and_log_equal_rotations_across_their_taylor_thresholds() -> None:
    log_thr_rad = 2.0 * math.atan(rot.LOG_TAYLOR_THRESHOLD)
    angles = np.concatenate([rot.EXP_TAYLOR_THRESHOLD_RAD * _STRADDLE, log_thr_rad * _STRADDLE])
    phi = angles[:, None] * _GRID_AXES[: len(angles)]
    q_nb = np.array([_rot_nb.qexp(p) for p in phi])
    np.testing.assert_allclose(q_nb, rot.rotvec_exp(phi), rtol=2 * _EPS, atol=0)
    phi_nb = np.array([_rot_nb.qlog(q) for q in q_nb])
    np.testing.assert_allclose(phi_nb, rot.quat_log(q_nb), rtol=2 * _EPS, atol=0)


# ------------------------------------------------------------------------------------- input checks

_I = rot.IDENTITY_QUAT
BAD_SHAPES = [
    (rot.quat_mul, (np.zeros(3), _I), "p", "(..., 4)", "(3,)"),
    (rot.quat_mul, (_I, np.zeros((2, 5))), "q", "(..., 4)", "(2, 5)"),
    (rot.quat_conj, (1.0,), "q", "(..., 4)", "()"),
    (rot.quat_normalize, (np.zeros(3),), "q", "(..., 4)", "(3,)"),
    (rot.quat_canonical, (np.zeros(5),), "q", "(..., 4)", "(5,)"),
    (rot.quat_rotate, (np.zeros(3), np.zeros(3)), "q", "(..., 4)", "(3,)"),
    (rot.quat_rotate, (_I, np.zeros(4)), "v", "(..., 3)", "(4,)"),
    (rot.quat_to_matrix, (np.zeros((3, 3)),), "q", "(..., 4)", "(3, 3)"),
    (rot.matrix_to_quat, (np.zeros(4),), "R", "(..., 3, 3)", "(4,)"),
    (rot.skew, (np.zeros(4),), "v", "(..., 3)", "(4,)"),
    (rot.rotvec_exp, (np.zeros(4),), "phi", "(..., 3)", "(4,)"),
    (rot.quat_log, (np.zeros(3),), "q", "(..., 4)", "(3,)"),
    (rot.attitude_error, (np.zeros(3), _I), "q_ref", "(..., 4)", "(3,)"),
    (rot.attitude_error, (_I, np.zeros(3)), "q", "(..., 4)", "(3,)"),
    (rot.multiplicative_reset, (_I, np.zeros(4)), "dtheta", "(..., 3)", "(4,)"),
    (rot.euler_to_quat, (np.zeros(2), "xyz"), "angles_rad", "(..., 3)", "(2,)"),
    (rot.quat_to_euler, (np.zeros(3), "xyz"), "q", "(..., 4)", "(3,)"),
]


@pytest.mark.parametrize(
    ("fn", "args", "name", "want", "got"), BAD_SHAPES, ids=[f"{b[0].__name__}-{b[2]}" for b in BAD_SHAPES]
)
def test_wrong_shape_raises_value_error_naming_argument(fn, args, name: str, want: str, got: str) -> None:
    with pytest.raises(ValueError, match=f"^{re.escape(f'{name} must have shape {want}, got {got}')}$"):
        fn(*args)
