"""Tests for swarm.kinds.ground.dynamics: mecanum kinematics and the planar truth step.

Oracles: Lynch & Park 2017 eq. 13.5 built wheel by wheel from each wheel's position and roller angle, the
closed forms of the first-order lag (speed and its time integral) and of the constant-twist arc, numpy's
pseudo-inverse and scipy's Rotation; self-consistency (inverse then forward) last.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from swarm.kinds.ground.dynamics import (
    KP_HALF_LENGTH,
    KP_HALF_WIDTH,
    KP_MAX_SPEED,
    KP_N,
    KP_RADIUS,
    KP_SLIP,
    KP_TAU,
    S_N,
    U_N,
    ground_truth_row,
    ground_truth_step,
    mecanum_forward,
    mecanum_inverse,
)
from swarm.kinds.ground.params import WheelParams, slip_factors

WHEELS = WheelParams()
R, L, W = WHEELS.radius_m, WHEELS.half_length_m, WHEELS.half_width_m
TAU = WHEELS.motor_time_constant_s
DT = 0.01


def yaw_quat(psi: float) -> np.ndarray:
    return np.array([0.0, 0.0, math.sin(psi / 2), math.cos(psi / 2)])


def state(psi: float = 0.0, p=(0.0, 0.0, 0.0)) -> np.ndarray:
    x = np.zeros(13)
    x[0:3] = p
    x[6:10] = yaw_quat(psi)
    return x


def wheel_matrix_by_wheel(r: float, l: float, w: float) -> np.ndarray:
    """``H`` (4, 3) on ``(vx, vy, wz)`` from Lynch & Park eq. 13.5, wheel by wheel: wheel ``i`` at
    ``(x_i, y_i)`` with free rollers at ``gamma_i`` drives at ``((vx - wz y_i) + tan(gamma_i) (vy + wz x_i))
    / r`` (driving direction beta_i = 0)."""
    layout = [(l, w, -45.0), (l, -w, 45.0), (-l, -w, -45.0), (-l, w, 45.0)]  # FL, FR, RR, RL
    H = np.empty((4, 3))
    for i, (xi, yi, gamma) in enumerate(layout):
        t = math.tan(math.radians(gamma))
        H[i] = np.array([1.0, t, -yi + t * xi]) / r
    return H


def run(x, s, u, kp, n, dt=DT):
    effort = 0.0
    for _ in range(n):
        effort += ground_truth_step(x, s, u, kp, dt)
    return effort


# ---------------------------------------------------------------------------------------------- kinematics


def test_inverse_equals_lynch_park_wheel_by_wheel():
    rng = np.random.default_rng(1)
    H = wheel_matrix_by_wheel(R, L, W)
    for twist in rng.uniform(-0.3, 0.3, size=(50, 3)):
        np.testing.assert_allclose(mecanum_inverse(twist, R, L, W), H @ twist, rtol=0, atol=1e-12)


def test_forward_is_least_squares_inverse_of_wheel_matrix():
    rng = np.random.default_rng(2)
    H_pinv = np.linalg.pinv(wheel_matrix_by_wheel(R, L, W))
    for wheels in rng.uniform(-20.0, 20.0, size=(50, 4)):  # inconsistent speeds: a least-squares fit
        np.testing.assert_allclose(mecanum_forward(wheels, R, L, W), H_pinv @ wheels, rtol=0, atol=1e-12)


def test_inverse_forward_round_trip_on_random_twists():
    rng = np.random.default_rng(3)
    for twist in rng.uniform(-0.5, 0.5, size=(200, 3)):
        back = mecanum_forward(mecanum_inverse(twist, R, L, W), R, L, W)
        np.testing.assert_allclose(back, twist, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("twist", "signs"),
    [
        ((0.1, 0.0, 0.0), (1, 1, 1, 1)),  # forward: every wheel rolls forward
        ((0.0, 0.1, 0.0), (-1, 1, -1, 1)),  # left: front-right and rear-left forward
        ((0.0, 0.0, 0.5), (-1, 1, 1, -1)),  # counter-clockwise: left wheels back, right wheels forward
    ],
    ids=["forward", "left", "ccw"],
)
def test_wheel_speed_signs_of_pure_twists(twist, signs):
    wheels = mecanum_inverse(np.array(twist), R, L, W)
    np.testing.assert_array_equal(np.sign(wheels), signs)
    np.testing.assert_allclose(np.abs(wheels), np.abs(wheels[0]), rtol=1e-15)


# ---------------------------------------------------------------------------------------------- truth step


def test_truth_row_layout():
    slip = np.array([0.9, 0.8, 0.7, 0.6])
    kp = ground_truth_row(WHEELS, slip)
    assert kp.shape == (KP_N,)
    assert kp[KP_RADIUS] == R and kp[KP_HALF_LENGTH] == L and kp[KP_HALF_WIDTH] == W
    assert kp[KP_TAU] == TAU and kp[KP_MAX_SPEED] == WHEELS.max_speed_rad_s
    np.testing.assert_array_equal(kp[KP_SLIP : KP_SLIP + 4], slip)


@pytest.mark.parametrize("slip", [np.ones(3), np.array([1.0, 1.0, 0.0, 1.0]), np.array([1.0, 1.1, 1.0, 1.0])])
def test_truth_row_rejects_bad_slip(slip):
    with pytest.raises(ValueError, match="slip"):
        ground_truth_row(WHEELS, slip)


def test_wheel_speeds_follow_first_order_lag_closed_form():
    kp = ground_truth_row(WHEELS, np.ones(4))
    s0 = np.array([1.0, -2.0, 3.0, 0.5])
    u = np.array([5.0, 4.0, -6.0, 0.0])
    s, x = s0.copy(), state()
    n = 37
    run(x, s, u, kp, n)
    expected = u + (s0 - u) * math.exp(-n * DT / TAU)
    np.testing.assert_allclose(s, expected, rtol=0, atol=1e-12)


def test_straight_motion_is_integral_of_lagged_speed():
    """Forward command from rest: ``x(t) = r (u t - u tau (1 - exp(-t / tau)))``, exact (wz = 0)."""
    kp = ground_truth_row(WHEELS, np.ones(4))
    u, psi0 = 4.0, 0.7
    x, s = state(psi0), np.zeros(4)
    n = 23
    run(x, s, np.full(4, u), kp, n)
    t = n * DT
    dist = R * (u * t - u * TAU * (1.0 - math.exp(-t / TAU)))
    np.testing.assert_allclose(x[0:2], dist * np.array([math.cos(psi0), math.sin(psi0)]), rtol=0, atol=1e-14)


def test_velocity_is_twist_of_end_of_tick_wheel_speeds():
    kp = ground_truth_row(WHEELS, np.ones(4))
    u, psi0 = 4.0, -1.2
    x, s = state(psi0), np.zeros(4)
    ground_truth_step(x, s, np.full(4, u), kp, DT)
    speed = R * u * (1.0 - math.exp(-DT / TAU))
    np.testing.assert_allclose(x[3:6], speed * np.array([math.cos(psi0), math.sin(psi0), 0.0]), atol=1e-15)
    np.testing.assert_array_equal(x[10:13], 0.0)


def test_command_is_clipped_at_max_speed():
    kp = ground_truth_row(WHEELS, np.ones(4))
    limit = WHEELS.max_speed_rad_s
    u = np.array([100.0, -100.0, 0.5 * limit, -1e9])
    x, s = state(), np.zeros(4)
    ground_truth_step(x, s, u, kp, DT)
    held = np.array([limit, -limit, 0.5 * limit, -limit])
    np.testing.assert_allclose(s, held * (1.0 - math.exp(-DT / TAU)), rtol=1e-14)
    run(x, s, u, kp, 300)  # 3 s = 60 tau
    np.testing.assert_allclose(s, held, rtol=1e-12)


def test_slip_factors_scale_realised_twist():
    """Settled forward command ``w`` on every wheel, traction ``f``: Lynch & Park eq. 13.11 gives
    ``vx = r w sum(f) / 4``, ``vy = r w (-f1 + f2 - f3 + f4) / 4`` and
    ``wz = r w (-f1 + f2 + f3 - f4) / (4 (l + w))``."""
    f = np.array([0.9, 0.6, 0.8, 0.95])
    kp = ground_truth_row(WHEELS, f)
    w = 5.0
    x, s = state(), np.full(4, w)  # settled on the command: the twist is constant
    ground_truth_step(x, s, np.full(4, w), kp, DT)
    psi = 2.0 * math.atan2(x[8], x[9])
    v_body = Rotation.from_euler("z", psi).inv().apply(x[3:6])
    np.testing.assert_allclose(v_body[0], R * w * f.sum() / 4, rtol=1e-14)
    np.testing.assert_allclose(v_body[1], R * w * (-f[0] + f[1] - f[2] + f[3]) / 4, rtol=1e-13)
    wz = R * w * (-f[0] + f[1] + f[2] - f[3]) / (4 * (L + W))
    np.testing.assert_allclose(x[12], wz, rtol=1e-14)
    np.testing.assert_allclose(psi, wz * DT, rtol=1e-13)  # the pose moves with the slipping twist too


@pytest.mark.parametrize("wz", [0.5, 0.05, -1.3], ids=["turn", "slow-turn-taylor", "fast-cw"])
def test_constant_twist_follows_closed_form_arc(wz):
    """Wheels settled on a constant twist: the pose is the SE(2) exponential, exactly (Lynch & Park
    sec. 3.3.3): in the start body frame ``x = (vx sin(wz t) - vy (1 - cos(wz t))) / wz`` and
    ``y = (vx (1 - cos(wz t)) + vy sin(wz t)) / wz``."""
    vx, vy, psi0, p0 = 0.08, -0.03, 0.4, np.array([0.3, -0.2, 0.05])
    kp = ground_truth_row(WHEELS, np.ones(4))
    wheels = mecanum_inverse(np.array([vx, vy, wz]), R, L, W)
    x, s = state(psi0, p0), wheels.copy()
    n = 731
    run(x, s, wheels, kp, n)
    t = n * DT
    th = wz * t
    d_body = np.array(
        [vx * math.sin(th) - vy * (1 - math.cos(th)), vx * (1 - math.cos(th)) + vy * math.sin(th)]
    )
    d_nav = Rotation.from_euler("z", psi0).apply(np.append(d_body / wz, 0.0))
    np.testing.assert_allclose(x[0:3], p0 + d_nav, rtol=0, atol=1e-12)
    q_expected = Rotation.from_euler("z", psi0 + th)
    assert (Rotation.from_quat(x[6:10]) * q_expected.inv()).magnitude() < 1e-12


def test_motion_stays_planar():
    kp = ground_truth_row(WHEELS, np.array([0.9, 1.0, 0.7, 0.85]))
    rng = np.random.default_rng(4)
    x, s = state(2.5, (0.1, 0.2, 0.037)), np.zeros(4)
    for _ in range(50):
        u = rng.uniform(-40.0, 40.0, size=4)
        run(x, s, u, kp, 10)
        assert x[2] == 0.037
        assert x[5] == 0.0 and x[10] == 0.0 and x[11] == 0.0
        assert abs(np.linalg.norm(x[6:10]) - 1.0) < 1e-15
        roll_pitch = Rotation.from_quat(x[6:10]).as_euler("ZYX")[1:]
        np.testing.assert_allclose(roll_pitch, 0.0, atol=1e-15)


def test_roll_and_pitch_of_incoming_attitude_are_dropped():
    kp = ground_truth_row(WHEELS, np.ones(4))
    x, s = np.zeros(13), np.zeros(4)
    x[6:10] = Rotation.from_euler("ZYX", [0.8, 0.1, -0.2]).as_quat()
    ground_truth_step(x, s, np.zeros(4), kp, DT)
    np.testing.assert_allclose(x[6:10], yaw_quat(0.8), atol=1e-15)


def test_effort_is_wheel_travel():
    """Effort over ``t`` from speeds ``s0`` toward commands ``u`` of the same sign (no zero crossing):
    ``sum_i |u_i t + (s0_i - u_i) tau (1 - exp(-t / tau))|``, the integral of the lag's closed form."""
    kp = ground_truth_row(WHEELS, np.array([0.5, 0.6, 0.7, 0.8]))  # slip does not change wheel travel
    s0 = np.array([1.0, -2.0, 8.0, -0.5])
    u = np.array([5.0, -4.0, 2.0, -9.0])
    x, s = state(), s0.copy()
    n = 41
    effort = run(x, s, u, kp, n)
    t = n * DT
    expected = np.sum(np.abs(u * t + (s0 - u) * TAU * (1.0 - math.exp(-t / TAU))))
    np.testing.assert_allclose(effort, expected, rtol=1e-13)


def test_padded_arrays_use_leading_entries_only():
    kp = ground_truth_row(WHEELS, np.array([0.9, 1.0, 0.8, 1.0]))
    u = np.array([3.0, -7.0, 2.0, 11.0])
    x, s = state(0.3), np.array([1.0, 2.0, 3.0, 4.0])
    xp, sp = np.append(x, [7.0, 8.0]), np.append(s, [9.0, 9.0, 9.0])
    up, kpp = np.append(u, [-5.0, 5.0]), np.append(kp, [42.0, -1.0])
    e = ground_truth_step(x, s, u, kp, DT)
    ep = ground_truth_step(xp, sp, up, kpp, DT)
    assert e == ep
    np.testing.assert_array_equal(xp[:13], x)
    np.testing.assert_array_equal(sp[:S_N], s)
    np.testing.assert_array_equal(xp[13:], [7.0, 8.0])
    np.testing.assert_array_equal(sp[S_N:], [9.0, 9.0, 9.0])
    assert U_N == 4


# ---------------------------------------------------------------------------------------------- slip draws


def test_slip_factors_draw_nothing_when_sigma_is_zero():
    rng = np.random.default_rng(5)
    before = rng.bit_generator.state
    np.testing.assert_array_equal(slip_factors(0.0, "normal", rng), np.ones(4))
    assert rng.bit_generator.state == before


@pytest.mark.parametrize("distribution", ["normal", "uniform"])
def test_slip_factors_are_one_minus_abs_draw_in_unit_interval(distribution):
    sigma = 0.2
    f = np.concatenate([slip_factors(sigma, distribution, np.random.default_rng(k)) for k in range(500)])
    assert np.all(f > 0.0) and np.all(f <= 1.0)
    assert f.min() < 1.0 - sigma  # the draws do reach past one sigma
    rng = np.random.default_rng(6)
    if distribution == "normal":
        e = rng.normal(0.0, sigma, size=4)
    else:
        e = rng.uniform(-math.sqrt(3) * sigma, math.sqrt(3) * sigma, size=4)
    np.testing.assert_array_equal(
        slip_factors(sigma, distribution, np.random.default_rng(6)), 1.0 - np.abs(e)
    )
