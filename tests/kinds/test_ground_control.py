"""Tests for swarm.kinds.ground.control and the validation of swarm.kinds.ground.params.

Oracles: the zero-order hold from ``scipy.signal.cont2discrete`` and ``dlqr`` on matrices built here, the
closed form of the first-order lag (the known acceleration, a lag-plant reference), geometry of the
body-frame rotation, and closed loops of the controller on the compiled truth (``ground_truth_step``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from swarm.core.control import dlqr
from swarm.errors import ConfigError
from swarm.kinds.ground.control import GroundController, yaw_of
from swarm.kinds.ground.dynamics import ground_truth_row, ground_truth_step, mecanum_forward
from swarm.kinds.ground.params import (
    GroundBodyParams,
    GroundControlParams,
    GroundDispersionParams,
    WheelParams,
)

TRUTH_DT = 0.01
TICKS_PER_CONTROL = 10
ZERO3 = np.zeros(3)


def yaw_quat(psi: float) -> np.ndarray:
    return np.array([0.0, 0.0, math.sin(psi / 2), math.cos(psi / 2)])


def controller(control: GroundControlParams | None = None, wheels: WheelParams | None = None):
    return GroundController(control or GroundControlParams(), wheels or WheelParams(), GroundBodyParams())


def closed_loop_step(step_nav, yaw_ref_deg, t_end_s=30.0):
    """Controller at 10 Hz on the 100 Hz truth (no noise, no slip) from rest at the origin, yaw 0, to
    ``p_ref = step_nav`` and yaw ``yaw_ref_deg``. Returns the times (k,) [s], positions (k, 2) [m] and
    yaws (k,) [rad] after each truth tick, and whether any wheel command saturated."""
    ctl = controller()
    w = ctl.wheels
    kp = ground_truth_row(w, np.ones(4))
    x, s, u = np.zeros(13), np.zeros(4), np.zeros(4)
    x[9] = 1.0
    p_ref = np.array([*step_nav, 0.0])
    q_ref = yaw_quat(math.radians(yaw_ref_deg))
    ts, ps, yaws, saturated = [], [], [], False
    for k in range(round(t_end_s / TRUTH_DT)):
        if k % TICKS_PER_CONTROL == 0:
            cmd = ctl.step(x[0:3], x[3:6], x[6:10], p_ref, ZERO3, ZERO3, q_ref)
            u[:] = cmd.wheel_rad_s
            saturated |= cmd.saturated
        ground_truth_step(x, s, u, kp, TRUTH_DT)
        ts.append((k + 1) * TRUTH_DT)
        ps.append(x[0:2].copy())
        yaws.append(yaw_of(x[6:10]))
    return np.array(ts), np.array(ps), np.array(yaws), saturated


def settling_time(ts, err, band):
    """First time after which ``err`` stays within ``band``."""
    outside = np.nonzero(err > band)[0]
    return 0.0 if outside.size == 0 else ts[outside[-1]]


# ------------------------------------------------------------------------------------------------- design


def test_gains_equal_dlqr_on_cont2discrete_plant():
    cp, wheels = GroundControlParams(), WheelParams()
    tau, T = wheels.motor_time_constant_s, cp.dt_s
    Ac = np.array([[0.0, 1.0], [0.0, -1.0 / tau]])
    Bc = np.array([[0.0], [1.0 / tau]])
    Ad2, Bd2, *_ = scipy.signal.cont2discrete((Ac, Bc, np.eye(2), np.zeros((2, 1))), T, method="zoh")
    A = np.zeros((3, 3))
    A[:2, :2] = Ad2
    A[2, 0], A[2, 2] = T, 1.0  # z+ = z + T (p - p_ref)
    B = np.vstack([Bd2, [[0.0]]])
    K, _ = dlqr(A, B, np.diag([cp.q_pos, cp.q_vel, cp.q_int]), np.array([[cp.r_vel]]))
    ctl = controller(cp, wheels)
    np.testing.assert_allclose(ctl.A_d, A, rtol=0, atol=1e-14)
    np.testing.assert_allclose(ctl.B_d, B, rtol=0, atol=1e-14)
    np.testing.assert_allclose(ctl.K_axis, K, rtol=1e-10)


def test_closed_loop_eigenvalues_inside_unit_circle():
    ctl = controller()
    eigs = np.linalg.eigvals(ctl.A_d - ctl.B_d @ ctl.K_axis)
    np.testing.assert_allclose(np.sort_complex(ctl.closed_loop_eigs), np.sort_complex(eigs), atol=1e-12)
    assert np.all(np.abs(eigs) < 1.0)


def test_zero_integral_weight_drops_integrator():
    cp = GroundControlParams(q_int=0.0)
    ctl = controller(cp)
    K2, _ = dlqr(ctl.A_d[:2, :2], ctl.B_d[:2], np.diag([cp.q_pos, cp.q_vel]), np.array([[cp.r_vel]]))
    np.testing.assert_allclose(ctl.K_axis[0, :2], K2[0], rtol=1e-12)
    assert ctl.K_axis[0, 2] == 0.0
    assert ctl.closed_loop_eigs.shape == (2,)


# ---------------------------------------------------------------------------------------------- closed loop


@pytest.mark.parametrize(
    ("step_nav", "yaw_deg", "t_settle_max_s", "overshoot_max"),
    [((0.2, 0.0), 30.0, 11.5, 0.035), ((0.2 / math.sqrt(2), 0.2 / math.sqrt(2)), -30.0, 11.5, 0.048)],
    ids=["along-x", "diagonal"],
)
def test_closed_loop_settles_step_with_yaw_change(step_nav, yaw_deg, t_settle_max_s, overshoot_max):
    """GroundControlParams states: within 2 mm in 11.0 s (diagonal 11.2 s) with 3.1 % (4.4 %) overshoot,
    yaw within 0.1 deg in 5.2 s."""
    ts, ps, yaws, saturated = closed_loop_step(step_nav, yaw_deg)
    ref = np.asarray(step_nav)
    err = np.linalg.norm(ps - ref, axis=1)
    along = ps @ (ref / 0.2)
    assert settling_time(ts, err, 0.002) < t_settle_max_s
    assert (along.max() - 0.2) / 0.2 < overshoot_max
    yaw_err = np.abs(np.remainder(yaws - math.radians(yaw_deg) + math.pi, 2 * math.pi) - math.pi)
    assert settling_time(ts, yaw_err, math.radians(0.1)) < 5.5
    assert err[-1] < 1e-4
    assert not saturated


def test_lag_plant_reference_is_followed_exactly():
    """A reference generated by the lag plant from a held input ``u_ref`` per control period has
    ``v_ref + tau a_ref = u_ref`` at every sample; started on it, the loop stays on it (the feedback sees
    no error) and the truth, whose lag is exact, tracks it to rounding."""
    ctl = controller()
    tau, T = ctl.wheels.motor_time_constant_s, ctl.control.dt_s
    a = math.exp(-T / tau)
    kp = ground_truth_row(ctl.wheels, np.ones(4))
    psi = 0.6
    x, s, u = np.zeros(13), np.zeros(4), np.zeros(4)
    x[6:10] = yaw_quat(psi)
    p_ref, v_ref = np.zeros(3), np.zeros(3)
    for k in range(60):
        u_ref = np.array([0.05 * math.sin(0.3 * k), 0.04 * math.cos(0.2 * k), 0.0])
        a_ref = (u_ref - v_ref) / tau
        cmd = ctl.step(x[0:3], x[3:6], x[6:10], p_ref, v_ref, a_ref, yaw_quat(psi))
        u[:] = cmd.wheel_rad_s
        for _ in range(TICKS_PER_CONTROL):
            ground_truth_step(x, s, u, kp, TRUTH_DT)
        # closed form of the lag over one period from (p_ref, v_ref) with u_ref held
        p_ref = p_ref + u_ref * T + (v_ref - u_ref) * tau * (1.0 - a)
        v_ref = u_ref + (v_ref - u_ref) * a
        np.testing.assert_allclose(x[0:2], p_ref[:2], rtol=0, atol=1e-14)
        np.testing.assert_allclose(x[3:5], v_ref[:2], rtol=0, atol=1e-14)
    np.testing.assert_allclose(ctl.integral_m_s, 0.0, rtol=0, atol=1e-15)


def test_known_acceleration_equals_truth_mean_acceleration():
    """From rest without slip and without turning, the body velocity is exactly the lag of the commanded
    twist (the lag is integrated exactly per tick and the mecanum maps are linear and inverse to each
    other on consistent speeds), and the body axes stay fixed in nav. So the truth's mean acceleration over
    one control period, ``v(T) / T``, equals the known acceleration up to rounding: ten ticks of
    ``exp(-dt / tau)`` against one ``exp(-T / tau)`` differ by a few ulp, hence the 1e-12 tolerance on
    ~0.9 m/s^2."""
    ctl = controller()
    psi = math.radians(30.0)
    kp = ground_truth_row(ctl.wheels, np.ones(4))
    x, s = np.zeros(13), np.zeros(4)
    x[6:10] = yaw_quat(psi)
    cmd = ctl.step(x[0:3], x[3:6], x[6:10], np.array([0.3, -0.1, 0.0]), ZERO3, ZERO3, x[6:10], rotate=False)
    for _ in range(TICKS_PER_CONTROL):
        ground_truth_step(x, s, cmd.wheel_rad_s, kp, TRUTH_DT)
    c, sn = math.cos(psi), math.sin(psi)
    v_body = np.array([c * x[3] + sn * x[4], -sn * x[3] + c * x[4], x[5]])
    accel_truth = v_body / ctl.control.dt_s
    assert np.linalg.norm(cmd.accel_body_known) > 0.5  # a real command, not a trivial zero
    np.testing.assert_allclose(cmd.accel_body_known, accel_truth, rtol=0, atol=1e-12)


def test_known_acceleration_is_lag_response_from_estimated_velocity():
    ctl = controller()
    psi = -0.9
    v_nav = np.array([0.02, 0.01, 0.3])  # z is ignored
    cmd = ctl.step(ZERO3, v_nav, yaw_quat(psi), np.array([0.1, 0.05, 0.0]), ZERO3, ZERO3, yaw_quat(psi))
    c, sn = math.cos(psi), math.sin(psi)
    v0 = np.array([c * v_nav[0] + sn * v_nav[1], -sn * v_nav[0] + c * v_nav[1]])
    T, tau = ctl.control.dt_s, ctl.wheels.motor_time_constant_s
    expected = (cmd.twist_body[:2] - v0) * (1.0 - math.exp(-T / tau)) / T
    np.testing.assert_allclose(cmd.accel_body_known, [*expected, 0.0], rtol=1e-14, atol=1e-17)


# ------------------------------------------------------------------------------------------ command shaping


def test_command_is_rotated_into_body_frame():
    """Yaw 90 deg: a nav +x error (reference ahead along nav x) commands body -y."""
    ctl = controller()
    q = yaw_quat(math.pi / 2)
    cmd = ctl.step(ZERO3, ZERO3, q, np.array([0.01, 0.0, 0.0]), ZERO3, ZERO3, q)
    k_p = ctl.K_axis[0, 0]
    np.testing.assert_allclose(cmd.twist_body, [0.0, -k_p * 0.01, 0.0], atol=1e-15)
    np.testing.assert_allclose(
        mecanum_forward(cmd.wheel_rad_s, 0.024, 0.04, 0.055), cmd.twist_body, atol=1e-15
    )


def test_speed_bound_keeps_direction():
    ctl = controller()
    q = yaw_quat(0.3)
    err = np.array([3.0, -4.0, 0.0])  # far away: the LQR asks for far more than max_speed_m_s
    cmd = ctl.step(ZERO3, ZERO3, q, err, ZERO3, ZERO3, q)
    v = cmd.twist_body[:2]
    assert math.hypot(*v) == pytest.approx(ctl.control.max_speed_m_s, rel=1e-14)
    c, s = math.cos(0.3), math.sin(0.3)
    direction = np.array([c * 3.0 - s * 4.0, -s * 3.0 - c * 4.0]) / 5.0  # R(psi)^T err / |err|
    np.testing.assert_allclose(v / math.hypot(*v), direction, atol=1e-14)
    assert not cmd.saturated


def test_wheel_saturation_scales_all_wheels_and_keeps_direction():
    cp = GroundControlParams(max_speed_m_s=1.0, max_yaw_rate_rad_s=2.0)
    slow = WheelParams(max_speed_rad_s=2.0)
    fast = WheelParams(max_speed_rad_s=1e6)
    args = (ZERO3, ZERO3, yaw_quat(0.0), np.array([0.2, 0.15, 0.0]), ZERO3, ZERO3, yaw_quat(1.0))
    free = controller(cp, fast).step(*args)
    cmd = controller(cp, slow).step(*args)
    assert cmd.saturated and not free.saturated
    assert np.max(np.abs(cmd.wheel_rad_s)) == pytest.approx(2.0, rel=1e-14)
    scale = 2.0 / np.max(np.abs(free.wheel_rad_s))
    np.testing.assert_allclose(cmd.wheel_rad_s, scale * free.wheel_rad_s, rtol=1e-14)
    np.testing.assert_allclose(cmd.twist_body, scale * free.twist_body, rtol=1e-14)


@pytest.mark.parametrize(
    ("yaw_deg", "yaw_ref_deg", "wz_expected"),
    [(170.0, -170.0, math.radians(20.0)), (-170.0, 170.0, -math.radians(20.0)), (0.0, 90.0, 0.5)],
    ids=["wraps-ccw", "wraps-cw", "clipped"],
)
def test_yaw_rate_takes_short_way_and_is_clipped(yaw_deg, yaw_ref_deg, wz_expected):
    ctl = controller()
    q, q_ref = yaw_quat(math.radians(yaw_deg)), yaw_quat(math.radians(yaw_ref_deg))
    cmd = ctl.step(ZERO3, ZERO3, q, ZERO3, ZERO3, ZERO3, q_ref)
    assert cmd.twist_body[2] == pytest.approx(wz_expected, rel=1e-12)


def test_translate_false_zeroes_xy_and_resets_integral():
    ctl = controller()
    q = yaw_quat(0.0)
    ctl.step(ZERO3, ZERO3, q, np.array([0.1, 0.1, 0.0]), ZERO3, ZERO3, q)
    assert np.all(ctl.integral_m_s != 0.0)
    cmd = ctl.step(ZERO3, ZERO3, q, np.array([0.1, 0.1, 0.0]), ZERO3, ZERO3, yaw_quat(0.2), translate=False)
    np.testing.assert_array_equal(cmd.twist_body[:2], 0.0)
    assert cmd.twist_body[2] > 0.0
    np.testing.assert_array_equal(ctl.integral_m_s, 0.0)


def test_rotate_false_zeroes_yaw_rate():
    ctl = controller()
    cmd = ctl.step(
        ZERO3, ZERO3, yaw_quat(0.0), np.array([0.1, 0.0, 0.0]), ZERO3, ZERO3, yaw_quat(1.0), rotate=False
    )
    assert cmd.twist_body[2] == 0.0
    assert cmd.twist_body[0] > 0.0


def test_height_is_ignored():
    q = yaw_quat(0.4)
    a = controller().step(ZERO3, ZERO3, q, np.array([0.1, 0.0, 0.0]), ZERO3, ZERO3, q)
    b = controller().step(
        np.array([0.0, 0.0, 0.3]), np.array([0.0, 0.0, -0.2]), q, np.array([0.1, 0.0, 5.0]),
        np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 2.0]), q,
    )  # fmt: skip
    np.testing.assert_array_equal(a.wheel_rad_s, b.wheel_rad_s)
    np.testing.assert_array_equal(a.accel_body_known, b.accel_body_known)


def test_integral_is_clamped_and_reset():
    ctl = controller()
    q = yaw_quat(0.0)
    for _ in range(100):
        ctl.step(ZERO3, ZERO3, q, np.array([1.0, -1.0, 0.0]), ZERO3, ZERO3, q)
    lim = ctl.control.integral_limit_m_s
    np.testing.assert_array_equal(ctl.integral_m_s, [-lim, lim])
    ctl.reset()
    np.testing.assert_array_equal(ctl.integral_m_s, 0.0)
    np.testing.assert_array_equal(ctl.zero_command(), np.zeros(4))


# ------------------------------------------------------------------------------------------------- params


@pytest.mark.parametrize(
    ("cls", "table", "field"),
    [
        (GroundBodyParams, "body", "mass_kg"),
        (GroundBodyParams, "body", "half_size_m"),
        (WheelParams, "wheels", "radius_m"),
        (WheelParams, "wheels", "motor_time_constant_s"),
        (GroundControlParams, "control", "rate_hz"),
        (GroundControlParams, "control", "r_vel"),
        (GroundControlParams, "control", "max_speed_m_s"),
    ],
)
def test_config_error_names_field_and_value(cls, table, field):
    with pytest.raises(ConfigError) as exc:
        cls(**{field: -1.0})
    assert str(exc.value) == f"kinds.ground.{table}.{field} must be a positive number, got -1.0"


def test_config_error_names_non_negative_weight():
    with pytest.raises(
        ConfigError, match=r"kinds\.ground\.control\.q_int must be a non-negative number, got -1\.0"
    ):
        GroundControlParams(q_int=-1.0)


@pytest.mark.parametrize("value", [-1.0, 0.25, float("nan"), True])
def test_config_error_names_slip_sigma(value):
    with pytest.raises(ConfigError, match=r"kinds\.ground\.dispersions\.wheel_slip_sigma_frac .*got"):
        GroundDispersionParams(wheel_slip_sigma_frac=value)


def test_defaults_are_valid():
    for cls in (GroundBodyParams, WheelParams, GroundControlParams, GroundDispersionParams):
        cls()
