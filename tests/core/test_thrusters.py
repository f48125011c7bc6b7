"""Tests for swarm.core.thrusters: nozzle layout, allocation matrix, NNLS allocation, total impulse.

Oracles: the geometry's written description (module docstring), closed-form wrenches of nozzle pairs,
scipy.optimize.nnls and linprog for reachability and positive spanning (Davis 1954), and hand sums.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import linprog, nnls

from swarm.core import thrusters as thr
from swarm.errors import ConfigError

PARAMS = thr.ThrusterParams()
B = thr.allocation_matrix(PARAMS)
F_MAX = PARAMS.max_thrust_n
AXES = {"x": (0, 1, 2), "y": (1, 2, 0), "z": (2, 0, 1)}


def _unit_wrenches() -> list[np.ndarray]:
    return [s * e for e in np.eye(6) for s in (1.0, -1.0)]


@pytest.mark.parametrize("face_axis", ["x", "y", "z"])
def test_nozzles_sit_on_two_opposite_faces_with_an_x_of_corners(face_axis: str) -> None:
    p = thr.ThrusterParams(face_axis=face_axis)
    r, d = thr.nozzle_geometry(p)
    i_n, i_a, i_b = AXES[face_axis]
    h, c = p.half_size_m, p.corner_offset_m
    assert r.shape == d.shape == (10, 3)
    np.testing.assert_allclose(r[:5, i_n], h, rtol=0, atol=1e-15)
    np.testing.assert_allclose(r[5:, i_n], -h, rtol=0, atol=1e-15)
    for face in (0, 5):
        np.testing.assert_allclose(r[face, [i_a, i_b]], 0.0, atol=1e-15)  # centre nozzle
        corners = r[face + 1 : face + 5][:, [i_a, i_b]]
        np.testing.assert_allclose(corners, c * np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]), atol=1e-15)


@pytest.mark.parametrize("face_axis", ["x", "y", "z"])
def test_thrust_directions_are_unit_canted_and_swirled_as_described(face_axis: str) -> None:
    p = thr.ThrusterParams(face_axis=face_axis, cant_deg=25.0, swirl_deg=40.0)
    r, d = thr.nozzle_geometry(p)
    i_n = AXES[face_axis][0]
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=0, atol=1e-15)
    for face, sign in ((0, 1.0), (5, -1.0)):
        n = sign * np.eye(3)[i_n]
        np.testing.assert_allclose(d[face], -n, atol=1e-15)  # centre: straight into the face
        for k in range(4):
            dk, rk = d[face + 1 + k], r[face + 1 + k]
            assert math.degrees(math.acos(-dk @ n)) == pytest.approx(25.0, abs=1e-12)
            e_r = (rk - (rk @ n) * n) / np.linalg.norm(rk - (rk @ n) * n)
            e_t = np.cross(n, e_r)
            in_plane = dk - (dk @ n) * n
            # Angle from the face-centre direction -e_r towards +e_t, signed: + - + - around the face.
            swirl = math.degrees(math.atan2(in_plane @ e_t, -(in_plane @ e_r)))
            assert swirl == pytest.approx(40.0 * (-1.0) ** k, abs=1e-12)


def test_allocation_matrix_columns_are_force_and_moment_about_the_centre_of_mass() -> None:
    r, d = thr.nozzle_geometry(PARAMS)
    for i in range(10):
        np.testing.assert_allclose(B[:3, i], d[i], atol=1e-15)
        np.testing.assert_allclose(B[3:, i], np.cross(r[i], d[i]), atol=1e-15)


def test_a_diagonal_corner_pair_gives_pure_push_and_roll() -> None:
    # Closed form from the module docstring: -2 cos(cant) n and roll 2 s sin(cant) sin(swirl) sqrt(2) c n.
    cant, swirl, c = math.radians(30.0), math.radians(45.0), 0.035
    roll = 2.0 * math.sin(cant) * math.sin(swirl) * math.sqrt(2.0) * c
    for pair, s in (([1, 3], 1.0), ([2, 4], -1.0), ([6, 8], 1.0), ([7, 9], -1.0)):
        f = np.zeros(10)
        f[pair] = 1.0
        n_sign = 1.0 if pair[0] < 5 else -1.0
        expected = n_sign * np.array([-2.0 * math.cos(cant), 0, 0, s * roll, 0, 0])
        np.testing.assert_allclose(B @ f, expected, atol=1e-15)


def test_y_face_layout_is_the_x_layout_rotated_cyclically() -> None:
    P = np.zeros((3, 3))
    P[1, 0] = P[2, 1] = P[0, 2] = 1.0  # x -> y, y -> z, z -> x: a proper rotation
    B_y = thr.allocation_matrix(thr.ThrusterParams(face_axis="y"))
    np.testing.assert_allclose(B_y, np.vstack([P @ B[:3], P @ B[3:]]), atol=1e-15)


def test_every_unit_wrench_is_reachable_with_non_negative_thrusts() -> None:
    for w in _unit_wrenches():
        f, residual = nnls(B, w)
        assert residual < 1e-9, f"unit wrench {w} unreachable, residual {residual}"
        assert np.all(f >= 0)


def test_origin_is_strictly_inside_the_conic_hull_by_linprog() -> None:
    # max t s.t. B f = 0, t <= f_i <= 1: t > 0 means a strictly positive f with B f = 0 exists. With
    # rank 6 that is positive spanning (Davis 1954).
    cost = np.r_[np.zeros(10), -1.0]
    res = linprog(
        cost,
        A_ub=np.hstack([-np.eye(10), np.ones((10, 1))]),
        b_ub=np.zeros(10),
        A_eq=np.hstack([B, np.zeros((6, 1))]),
        b_eq=np.zeros(6),
        bounds=[(0.0, 1.0)] * 10 + [(None, None)],
    )
    assert res.status == 0
    assert -res.fun > 0.5  # all ten nozzles equally: B 1 = 0, so t = 1
    assert np.linalg.matrix_rank(B) == 6


def test_spans_positively_detects_a_lost_corner_nozzle_but_not_a_lost_centre_nozzle() -> None:
    assert thr.spans_positively(B)
    assert not thr.spans_positively(np.delete(B, 3, axis=1))
    assert thr.spans_positively(np.delete(B, 0, axis=1))


def test_reachable_wrench_is_reproduced_exactly_without_saturation() -> None:
    rng = np.random.default_rng(20240603)
    for _ in range(200):
        w = B @ rng.uniform(0.0, F_MAX, 10)
        a = thr.allocate(w, B, math.inf)
        assert not a.saturated
        assert a.residual < 1e-12
        np.testing.assert_allclose(a.wrench_achieved, w, rtol=0, atol=1e-12)
        np.testing.assert_allclose(B @ a.thrusts_n, w, rtol=0, atol=1e-12)


def test_small_wrench_is_met_within_the_limit() -> None:
    w = np.array([0.01, -0.005, 0.002, 1e-4, -2e-4, 5e-5])
    a = thr.allocate(w, B, F_MAX)
    assert not a.saturated
    assert a.thrusts_n.max() <= F_MAX
    np.testing.assert_allclose(a.wrench_achieved, w, rtol=0, atol=1e-12)


def test_thrusts_are_never_negative_and_never_above_the_limit() -> None:
    rng = np.random.default_rng(7)
    for scale in (1e-3, 0.1, 1.0, 100.0):
        for _ in range(50):
            w = rng.normal(size=6) * scale * np.r_[np.ones(3), 0.03 * np.ones(3)]
            a = thr.allocate(w, B, F_MAX)
            assert np.all(a.thrusts_n >= 0.0)
            assert np.all(a.thrusts_n <= F_MAX * (1.0 + 1e-12))
            np.testing.assert_allclose(a.wrench_achieved, B @ a.thrusts_n, atol=1e-15)


def test_saturation_keeps_the_achieved_wrench_parallel_to_the_request() -> None:
    rng = np.random.default_rng(11)
    for _ in range(50):
        w = rng.normal(size=6) * np.r_[np.ones(3), 0.03 * np.ones(3)] * 10.0  # far beyond 0.1 N nozzles
        a = thr.allocate(w, B, F_MAX)
        assert a.saturated
        assert a.thrusts_n.max() == pytest.approx(F_MAX, rel=1e-15)
        unit_request = w / np.linalg.norm(w)
        unit_achieved = a.wrench_achieved / np.linalg.norm(a.wrench_achieved)
        np.testing.assert_allclose(unit_achieved, unit_request, rtol=0, atol=1e-12)
        assert np.linalg.norm(a.wrench_achieved) < np.linalg.norm(w)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((np.zeros(5), B, 0.1), r"wrench_body must have shape \(6,\)"),
        ((np.full(6, np.nan), B, 0.1), r"wrench_body must be finite"),
        ((np.zeros(6), B[:5], 0.1), r"B must have shape \(6, n\)"),
        ((np.zeros(6), B, 0.0), r"max_thrust_n must be positive"),
    ],
)
def test_allocate_rejects_bad_input_naming_the_argument(args: tuple, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        thr.allocate(*args)


def test_total_impulse_of_a_known_history_equals_the_hand_sum() -> None:
    history = np.zeros((3, 10))
    history[0, 0] = 0.1
    history[1, [1, 3]] = 0.05
    history[2, :] = 0.02
    # 0.1 * 0.01 + 2 * 0.05 * 0.01 + 10 * 0.02 * 0.01 = 0.001 + 0.001 + 0.002
    assert thr.total_impulse(history, 0.01) == pytest.approx(0.004, rel=1e-14)
    # Per-row durations: 0.1 * 0.02 + 0.1 * 0.01 + 0.2 * 0.005 = 0.002 + 0.001 + 0.001
    assert thr.total_impulse(history, [0.02, 0.01, 0.005]) == pytest.approx(0.004, rel=1e-14)
    assert thr.total_impulse(history[1], 0.5) == pytest.approx(0.05, rel=1e-14)


def test_total_impulse_rejects_mismatched_durations() -> None:
    with pytest.raises(ValueError, match=r"dt_s must be a scalar or have shape \(3,\)"):
        thr.total_impulse(np.zeros((3, 10)), [0.01, 0.01])


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("face_axis", "w"),
        ("half_size_m", 0.0),
        ("corner_offset_m", -0.01),
        ("corner_offset_m", 0.06),  # off the 5 cm face
        ("cant_deg", 0.0),
        ("cant_deg", 90.0),
        ("swirl_deg", float("nan")),
        ("max_thrust_n", float("inf")),
    ],
)
def test_invalid_params_raise_config_error_naming_the_field(field: str, value: object) -> None:
    with pytest.raises(ConfigError, match=rf"thrusters\.{field}"):
        thr.ThrusterParams(**{field: value})
