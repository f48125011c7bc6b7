"""Tests for swarm.core.control: quaternion-feedback attitude law and discrete translation LQR.

Oracles: the scalar discrete Riccati equation solved by hand (a quadratic), the small-angle closed loop
of Wie & Barba (overshoot ``exp(-pi zeta / sqrt(1 - zeta^2))``), scipy (``cont2discrete`` for the ZOH,
``solve_discrete_lyapunov`` for the cost of a gain), closed-form steady states of the double integrator
under constant forces, and simulations written here: the exact ZOH double integrator for translation and
an RK4 rigid body (Euler's equation + quaternion kinematics) for attitude, independent of the code under
test and of any swarm.core.dynamics.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

from swarm.core import rotations as rot
from swarm.core.control import (
    AttitudeControlParams,
    TranslationController,
    TranslationLqrParams,
    attitude_torque,
    design_translation_lqr,
    dlqr,
)
from swarm.errors import ConfigError

MASS_KG = 1.2
INERTIA_KG_M2 = np.array([0.002, 0.002, 0.002])
FAST = settings(max_examples=60, deadline=None)

# ------------------------------------------------------------------------------------------- simulators


def simulate_translation(
    ctrl: TranslationController,
    p_ref_fn,
    t_end_s: float,
    disturbance_n=(0.0, 0.0, 0.0),
    feedforward: bool = True,
    p0=(0.0, 0.0, 0.0),
    v0=(0.0, 0.0, 0.0),
):
    """Exact zero-order-hold double integrator ``m dv/dt = F + d`` driven by ``ctrl`` at its rate.

    ``p_ref_fn(t) -> (p_ref, v_ref, a_ref)``. Returns times (k,), positions (k, 3) after each step,
    reference positions (k, 3) at those times and the commanded forces (k, 3).
    """
    dt = ctrl.params.dt_s
    d = np.asarray(disturbance_n, dtype=float)
    p, v = np.array(p0, dtype=float), np.array(v0, dtype=float)
    ts, ps, refs, forces = [], [], [], []
    for k in range(round(t_end_s / dt)):
        p_ref, v_ref, a_ref = p_ref_fn(k * dt)
        F = ctrl.step(p, v, p_ref, v_ref, a_ref if feedforward else None)
        a = (F + d) / ctrl.mass_kg
        p, v = p + v * dt + 0.5 * a * dt * dt, v + a * dt  # exact for a force held over the step
        ts.append((k + 1) * dt)
        ps.append(p)
        refs.append(p_ref_fn((k + 1) * dt)[0])
        forces.append(F)
    return np.array(ts), np.array(ps), np.array(refs), np.array(forces)


def constant_ref(p_ref):
    p_ref = np.asarray(p_ref, dtype=float)
    return lambda t: (p_ref, np.zeros(3), np.zeros(3))


def _rigid_body_rates(q, w, tau, inertia):
    """Quaternion kinematics ``dq/dt = q (x) (w, 0) / 2`` (body rates) and Euler's equation."""
    x, y, z, s = q
    wx, wy, wz = w
    q_dot = 0.5 * np.array(
        [
            s * wx + y * wz - z * wy,
            s * wy + z * wx - x * wz,
            s * wz + x * wy - y * wx,
            -(x * wx + y * wy + z * wz),
        ]
    )
    w_dot = (tau - np.cross(w, inertia * w)) / inertia
    return q_dot, w_dot


def simulate_attitude(q0, w0, q_ref, params, inertia=INERTIA_KG_M2, t_end_s=40.0, dt_ctrl_s=0.1, h_s=0.01):
    """RK4 rigid body with the torque of ``attitude_torque`` held over each controller period.

    Returns the error angle (deg) after every controller period (k,) and the commanded torques (k, 3).
    """
    q, w = np.array(q0, dtype=float), np.array(w0, dtype=float)
    n_sub = round(dt_ctrl_s / h_s)
    angles, torques = [], []
    for _ in range(round(t_end_s / dt_ctrl_s)):
        tau = attitude_torque(q, w, q_ref, None, inertia, params)
        for _ in range(n_sub):
            k1 = _rigid_body_rates(q, w, tau, inertia)
            k2 = _rigid_body_rates(q + 0.5 * h_s * k1[0], w + 0.5 * h_s * k1[1], tau, inertia)
            k3 = _rigid_body_rates(q + 0.5 * h_s * k2[0], w + 0.5 * h_s * k2[1], tau, inertia)
            k4 = _rigid_body_rates(q + h_s * k3[0], w + h_s * k3[1], tau, inertia)
            q = q + h_s / 6.0 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            w = w + h_s / 6.0 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            q = q / np.linalg.norm(q)
        angles.append(math.degrees(np.linalg.norm(rot.attitude_error(q_ref, q))))
        torques.append(tau)
    return np.array(angles), np.array(torques)


def axis_angle_quat(axis, angle_rad):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return np.array([*(math.sin(0.5 * angle_rad) * axis), math.cos(0.5 * angle_rad)])


def settling_time_s(ts, err, band):
    """First time after which ``|err|`` stays within ``band``."""
    outside = np.nonzero(np.abs(err) > band)[0]
    return 0.0 if outside.size == 0 else ts[outside[-1]]


# ------------------------------------------------------------------------------------------------- LQR


@pytest.mark.parametrize(
    ("a", "b", "q", "r"),
    [(1.2, 0.5, 2.0, 0.3), (0.5, 1.0, 1.0, 1.0), (1.0, 0.1, 1.0, 50.0), (-1.5, -2.0, 0.7, 4.0)],
)
def test_dlqr_matches_hand_solved_scalar_riccati(a, b, q, r):
    # Scalar x+ = a x + b u: P = q + a^2 P - a^2 b^2 P^2 / (r + b^2 P) multiplies out to
    # b^2 P^2 + (r (1 - a^2) - q b^2) P - q r = 0, whose positive root is the stabilising solution;
    # K = a b P / (r + b^2 P) (the general K = (R + B^T P B)^-1 B^T P A with scalars).
    beta = r * (1.0 - a * a) - q * b * b
    P_hand = (-beta + math.sqrt(beta * beta + 4.0 * b * b * q * r)) / (2.0 * b * b)
    K_hand = a * b * P_hand / (r + b * b * P_hand)
    K, P = dlqr([[a]], [[b]], [[q]], [[r]])
    assert P.shape == (1, 1) and K.shape == (1, 1)
    assert P[0, 0] == pytest.approx(P_hand, rel=1e-10)
    assert K[0, 0] == pytest.approx(K_hand, rel=1e-10)
    assert abs(a - b * K[0, 0]) < 1.0


def test_zoh_plant_matches_scipy_cont2discrete():
    prm = TranslationLqrParams()
    design = design_translation_lqr(MASS_KG, prm)
    A_c = np.array([[0.0, 1.0], [0.0, 0.0]])
    B_c = np.array([[0.0], [1.0 / MASS_KG]])
    A_d, B_d, *_ = scipy.signal.cont2discrete((A_c, B_c, np.eye(2), np.zeros((2, 1))), prm.dt_s, "zoh")
    np.testing.assert_allclose(design.A_d[:2, :2], A_d, atol=1e-14)
    np.testing.assert_allclose(design.B_d[:2], B_d, atol=1e-14)
    # the integral row accumulates the position error over one period (forward rectangle)
    np.testing.assert_array_equal(design.A_d[2], [prm.dt_s, 0.0, 1.0])
    assert design.B_d[2, 0] == 0.0


@pytest.mark.parametrize(
    "params",
    [
        TranslationLqrParams(),
        TranslationLqrParams(q_int=0.0),
        TranslationLqrParams(q_pos=100.0, q_vel=0.0, q_int=10.0, r_force=1.0),
        TranslationLqrParams(rate_hz=50.0, r_force=1e4),
    ],
    ids=["defaults", "no-integral", "aggressive", "50Hz-gentle"],
)
def test_designed_closed_loop_is_stable(params):
    design = design_translation_lqr(MASS_KG, params)
    n = 3 if params.integral_enabled else 2
    eigs = np.linalg.eigvals(design.A_d[:n, :n] - design.B_d[:n] @ design.K_axis[:, :n])
    np.testing.assert_allclose(np.sort_complex(design.closed_loop_eigs), np.sort_complex(eigs), atol=1e-12)
    assert np.all(np.abs(eigs) < 1.0), f"|eig| = {np.abs(eigs)}"


def test_lqr_cost_matches_lyapunov_and_perturbed_gains_cost_more():
    # The cost of any stabilising gain K from x0 is x0^T P_K x0 with P_K from the Lyapunov equation
    # P_K = (A - BK)^T P_K (A - BK) + Q + K^T R K; at the LQR gain P_K is the Riccati P and is minimal.
    prm = TranslationLqrParams()
    d = design_translation_lqr(MASS_KG, prm)
    Q = np.diag([prm.q_pos, prm.q_vel, prm.q_int])

    def cost_matrix(K):
        Acl = d.A_d - d.B_d @ K
        return scipy.linalg.solve_discrete_lyapunov(Acl.T, Q + K.T * prm.r_force @ K)

    np.testing.assert_allclose(cost_matrix(d.K_axis), d.P, rtol=1e-8)
    rng = np.random.default_rng(1)
    for _ in range(20):
        K = d.K_axis * (1.0 + 0.05 * rng.standard_normal((1, 3)))
        assert np.trace(cost_matrix(K)) > np.trace(d.P)


def test_full_gain_is_the_per_axis_gain_on_each_axis():
    d = design_translation_lqr(MASS_KG, TranslationLqrParams())
    x = np.arange(9.0)  # (dp_x, dp_y, dp_z, dv_x, ..., z_z)
    expected = [d.K_axis[0] @ x[[i, 3 + i, 6 + i]] for i in range(3)]
    np.testing.assert_allclose(d.K @ x, expected, rtol=1e-14)


# ------------------------------------------------------------------------------------ translation control


def test_step_of_10_cm_settles_in_10_to_20_s_below_50_mN():
    ctrl = TranslationController(MASS_KG)
    ts, ps, _, forces = simulate_translation(ctrl, constant_ref([0.1, 0.0, 0.0]), 60.0)
    t_settle = settling_time_s(ts, ps[:, 0] - 0.1, 0.002)  # 2 % band
    assert 8.0 < t_settle < 20.0, f"settling time {t_settle:.1f} s"
    assert np.max(np.linalg.norm(forces, axis=1)) < 0.05
    assert abs(ps[-1, 0] - 0.1) < 1e-5


def test_integral_action_cancels_a_constant_disturbance():
    # 1 mN is below what the clamped integral can cancel (K_i * integral_limit_m_s ~ 1.8 mN).
    d = np.array([1e-3, -0.5e-3, 0.8e-3])
    ctrl = TranslationController(MASS_KG)
    _, ps, _, _ = simulate_translation(ctrl, constant_ref(np.zeros(3)), 150.0, disturbance_n=d)
    assert np.max(np.abs(ps[-1])) < 1e-6
    # in steady state the integral force balances the disturbance exactly: K_i z = d
    np.testing.assert_allclose(ctrl.design.K_axis[0, 2] * ctrl.integral_m_s, d, rtol=1e-4)


def test_without_integral_a_constant_disturbance_leaves_the_offset_d_over_kp():
    d = np.array([1e-3, -0.5e-3, 0.8e-3])
    ctrl = TranslationController(MASS_KG, TranslationLqrParams(q_int=0.0))
    _, ps, _, _ = simulate_translation(ctrl, constant_ref(np.zeros(3)), 150.0, disturbance_n=d)
    offset = d / ctrl.design.K_axis[0, 0]  # steady state of m a = -k_p e - k_v v + d with v = 0
    np.testing.assert_allclose(ps[-1], offset, rtol=1e-4)
    assert np.min(np.abs(ps[-1])) > 1e-3  # millimetres, not numerical noise
    np.testing.assert_array_equal(ctrl.integral_m_s, 0.0)


def test_integral_clamp_bounds_the_force_the_integral_can_build():
    # 5 mN exceeds the clamped integral's K_i * limit: the integrator sits at the clamp and the offset is
    # what proportional feedback leaves of the rest, (d - K_i * limit) / k_p.
    prm = TranslationLqrParams()
    d = np.array([5e-3, 0.0, 0.0])
    ctrl = TranslationController(MASS_KG, prm)
    _, ps, _, _ = simulate_translation(ctrl, constant_ref(np.zeros(3)), 150.0, disturbance_n=d)
    k_p, _, k_i = ctrl.design.K_axis[0]
    assert ctrl.integral_m_s[0] == prm.integral_limit_m_s  # position error > 0 winds it up to +limit
    assert ps[-1, 0] == pytest.approx((d[0] - k_i * prm.integral_limit_m_s) / k_p, rel=1e-4)


def test_feedforward_tracks_a_constant_acceleration_reference_better():
    # p_ref = a t^2 / 2 obeys the double integrator, so with feed-forward m a_ref it is an exact solution
    # of the closed loop (zero error from matching initial conditions); feedback alone lags behind.
    a = np.array([2e-3, -1e-3, 1.5e-3])  # m/s^2: 2.4 mN on x for 1.2 kg

    def ref(t):
        return 0.5 * a * t * t, a * t, a

    errors = {}
    for ff in (True, False):
        ctrl = TranslationController(MASS_KG)
        _, ps, refs, _ = simulate_translation(ctrl, ref, 30.0, feedforward=ff)
        errors[ff] = np.max(np.linalg.norm(ps - refs, axis=1))
    assert errors[True] < 1e-9
    assert errors[False] > 1e-3


@FAST
@given(
    e_p=st.tuples(*[st.floats(-50.0, 50.0)] * 3),
    e_v=st.tuples(*[st.floats(-5.0, 5.0)] * 3),
    a_ref=st.tuples(*[st.floats(-1.0, 1.0)] * 3),
)
def test_force_is_saturated_by_scaling_to_max_force(e_p, e_v, a_ref):
    prm = TranslationLqrParams()
    ctrl = TranslationController(MASS_KG, prm)
    unsat = (
        MASS_KG * np.array(a_ref)
        - ctrl.design.K_axis[0, 0] * np.array(e_p)
        - ctrl.design.K_axis[0, 1] * np.array(e_v)
    )
    F = ctrl.step(e_p, e_v, np.zeros(3), np.zeros(3), a_ref)
    assert np.linalg.norm(F) <= prm.max_force_n * (1.0 + 1e-12)
    if np.linalg.norm(unsat) > prm.max_force_n:
        # same direction as the unsaturated command, at the bound
        np.testing.assert_allclose(F, unsat * prm.max_force_n / np.linalg.norm(unsat), atol=1e-15)
    else:
        np.testing.assert_allclose(F, unsat, atol=1e-15)


def test_large_step_never_commands_more_than_max_force():
    prm = TranslationLqrParams()
    _, ps, _, forces = simulate_translation(
        TranslationController(MASS_KG, prm), constant_ref([2.0, -1.0, 0.5]), 120.0
    )
    assert np.max(np.linalg.norm(forces, axis=1)) <= prm.max_force_n * (1.0 + 1e-12)
    assert np.max(np.abs(ps[-1] - [2.0, -1.0, 0.5])) < 1e-3


def test_reset_zeroes_the_integrator_of_the_masked_vehicles():
    ctrl = TranslationController(MASS_KG, n=3)
    for _ in range(5):
        ctrl.step(np.ones((3, 3)), np.zeros(3), np.zeros(3), np.zeros(3))
    assert np.all(ctrl.integral_m_s != 0.0)
    ctrl.reset(mask=[True, False, True])
    np.testing.assert_array_equal(ctrl.integral_m_s[[0, 2]], 0.0)
    assert np.all(ctrl.integral_m_s[1] != 0.0)
    ctrl.reset()
    np.testing.assert_array_equal(ctrl.integral_m_s, 0.0)


def test_batch_of_vehicles_matches_vehicles_run_one_by_one():
    rng = np.random.default_rng(7)
    p, v, p_ref = rng.normal(size=(3, 4, 3)) * 0.1
    batch = TranslationController(MASS_KG, n=4)
    singles = [TranslationController(MASS_KG) for _ in range(4)]
    for _ in range(3):
        F = batch.step(p, v, p_ref, np.zeros(3), np.zeros(3))
        for i, c in enumerate(singles):
            np.testing.assert_allclose(F[i], c.step(p[i], v[i], p_ref[i], np.zeros(3)), rtol=1e-15)


# ------------------------------------------------------------------------------------------- attitude


def test_default_attitude_gains_are_wn_0p5_zeta_0p9_for_the_cube():
    prm = AttitudeControlParams.from_bandwidth(0.5, 0.9, 0.002)
    assert prm.kp_nm == pytest.approx(2 * 0.002 * 0.5**2)
    assert prm.kd_nms == pytest.approx(2 * 0.9 * 0.5 * 0.002)
    default = AttitudeControlParams()
    assert (default.kp_nm, default.kd_nms) == pytest.approx((prm.kp_nm, prm.kd_nms), rel=1e-12)


@FAST
@given(
    q_ref=st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(lambda q: np.linalg.norm(q) > 0.1),
    phi=st.tuples(*[st.floats(-3.0, 3.0)] * 3).filter(lambda p: 1e-6 < np.linalg.norm(p) < 3.1),
)
def test_torque_at_rest_is_minus_kp_sin_half_angle_about_the_body_error_axis(q_ref, phi):
    # q = q_ref (x) exp(phi) (body-frame error, as rotations.attitude_error) at w = 0 with equal inertias:
    # tau = -kp sin(|phi| / 2) phi / |phi| exactly (the vector part of exp(phi)).
    prm = AttitudeControlParams(max_torque_nm=1.0)
    q_ref = rot.quat_normalize(np.array(q_ref))
    phi = np.array(phi)
    q = rot.quat_mul(q_ref, rot.rotvec_exp(phi))
    angle = np.linalg.norm(phi)
    expected = -prm.kp_nm * math.sin(0.5 * angle) * phi / angle
    tau = attitude_torque(q, np.zeros(3), q_ref, None, INERTIA_KG_M2, prm)
    np.testing.assert_allclose(tau, expected, atol=1e-15)


def test_zero_error_leaves_only_the_gyroscopic_compensation():
    inertia = np.array([0.002, 0.003, 0.0025])
    w = np.array([0.1, -0.2, 0.05])
    q = rot.quat_normalize(np.array([0.1, 0.2, -0.3, 0.9]))
    tau = attitude_torque(q, w, q, w, inertia, AttitudeControlParams())
    np.testing.assert_allclose(tau, np.cross(w, inertia * w), atol=1e-18)
    assert np.linalg.norm(tau) > 1e-5


def test_small_angle_loop_overshoot_matches_the_design_damping():
    # kp = 2 I wn^2, kd = 2 zeta wn I make the linearised loop a 2nd-order system: a step of 0.5 deg from
    # rest overshoots by exp(-pi zeta / sqrt(1 - zeta^2)) = 37.2 % for zeta = 0.3. The controller runs at
    # 100 Hz here (wn T = 0.005) so sampling shifts the overshoot by well under 1 %.
    zeta, wn = 0.3, 0.5
    prm = AttitudeControlParams.from_bandwidth(wn, zeta, 0.002)
    axis = np.array([0.0, 0.0, 1.0])
    q0 = axis_angle_quat(axis, math.radians(0.5))
    angles, _ = simulate_attitude(
        q0, np.zeros(3), rot.IDENTITY_QUAT, prm, t_end_s=15.0, dt_ctrl_s=0.01, h_s=0.01
    )
    # the first crossing ends near t = pi / wn_d ~ 6.6 s; the error angle is |theta|, so look after the
    # first zero for the largest excursion, i.e. the overshoot
    first_zero = np.argmin(angles[: int(9.0 / 0.01)])
    overshoot = angles[first_zero:].max() / 0.5
    assert overshoot == pytest.approx(math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), abs=0.01)


def test_converges_from_170_degrees_with_torque_within_max():
    prm = AttitudeControlParams()
    q_ref = rot.quat_normalize(np.array([0.2, -0.4, 0.1, 0.8]))
    q0 = rot.quat_mul(q_ref, axis_angle_quat([1.0, 2.0, -3.0], math.radians(170.0)))
    angles, torques = simulate_attitude(q0, np.zeros(3), q_ref, prm, t_end_s=40.0)
    assert angles[0] == pytest.approx(170.0, abs=2.0)
    assert angles[-1] < 0.01
    assert settling_time_s(np.arange(1, angles.size + 1) * 0.1, angles, 1.0) < 20.0
    assert np.max(np.linalg.norm(torques, axis=1)) <= prm.max_torque_nm * (1.0 + 1e-12)


def test_ninety_degree_turn_settles_in_10_to_20_s():
    angles, _ = simulate_attitude(
        axis_angle_quat([0.0, 1.0, 0.0], math.radians(90.0)),
        np.zeros(3),
        rot.IDENTITY_QUAT,
        AttitudeControlParams(),
    )
    t_settle = settling_time_s(np.arange(1, angles.size + 1) * 0.1, angles, 1.0)
    assert 8.0 < t_settle < 20.0, f"settling time {t_settle:.1f} s"


def test_q_ref_and_minus_q_ref_give_the_same_torque():
    q = axis_angle_quat([0.3, -1.0, 0.2], 2.5)
    q_ref = axis_angle_quat([1.0, 0.5, 0.0], -0.7)
    w = np.array([0.02, -0.01, 0.03])
    prm = AttitudeControlParams()
    tau = attitude_torque(q, w, q_ref, None, INERTIA_KG_M2, prm)
    np.testing.assert_allclose(attitude_torque(q, w, -q_ref, None, INERTIA_KG_M2, prm), tau, atol=1e-18)
    np.testing.assert_allclose(attitude_torque(-q, w, q_ref, None, INERTIA_KG_M2, prm), tau, atol=1e-18)


@pytest.mark.parametrize(("angle_deg", "sign"), [(170.0, -1.0), (190.0, +1.0)])
def test_torque_turns_the_short_way(angle_deg, sign):
    # An error of 190 deg about n is 170 deg about -n: the short way back is to keep turning about +n.
    n = np.array([0.0, 0.6, 0.8])
    q = axis_angle_quat(n, math.radians(angle_deg))
    tau = attitude_torque(q, np.zeros(3), rot.IDENTITY_QUAT, None, INERTIA_KG_M2, AttitudeControlParams())
    assert np.dot(tau, n) * sign > 0.0
    np.testing.assert_allclose(np.cross(tau, n), 0.0, atol=1e-15)


def test_rotation_from_190_degrees_never_passes_through_180():
    # Without the sign(q_e,w) term the law would take the 190-degree way, through 180 deg of error.
    angles, _ = simulate_attitude(
        axis_angle_quat([1.0, 0.0, 0.0], math.radians(190.0)),
        np.zeros(3),
        rot.IDENTITY_QUAT,
        AttitudeControlParams(),
    )
    assert angles.max() < 170.0 + 1e-6
    assert angles[-1] < 0.01


def test_spinning_unequal_body_keeps_torque_within_a_tight_max():
    prm = AttitudeControlParams(max_torque_nm=3e-4)
    inertia = np.array([0.0018, 0.0022, 0.0025])
    angles, torques = simulate_attitude(
        axis_angle_quat([1.0, 1.0, 0.0], math.radians(120.0)),
        np.array([0.3, -0.2, 0.25]),
        rot.IDENTITY_QUAT,
        prm,
        inertia=inertia,
        t_end_s=60.0,
    )
    norms = np.linalg.norm(torques, axis=1)
    assert np.max(norms) <= prm.max_torque_nm * (1.0 + 1e-12)
    assert np.max(norms) == pytest.approx(prm.max_torque_nm)  # the bound was active, so this tested it
    assert angles[-1] < 0.1


def test_attitude_torque_broadcasts_over_a_batch():
    rng = np.random.default_rng(3)
    q = rot.quat_normalize(rng.normal(size=(5, 4)))
    w = 0.1 * rng.normal(size=(5, 3))
    q_ref = rot.quat_normalize(rng.normal(size=(5, 4)))
    prm = AttitudeControlParams()
    batch = attitude_torque(q, w, q_ref, None, INERTIA_KG_M2, prm)
    for i in range(5):
        np.testing.assert_allclose(batch[i], attitude_torque(q[i], w[i], q_ref[i], None, INERTIA_KG_M2, prm))


# ------------------------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("cls", "section", "field", "value"),
    [
        (AttitudeControlParams, "attitude_control", "kp_nm", 0.0),
        (AttitudeControlParams, "attitude_control", "kd_nms", -1.0),
        (AttitudeControlParams, "attitude_control", "max_torque_nm", float("nan")),
        (TranslationLqrParams, "translation_control", "rate_hz", 0.0),
        (TranslationLqrParams, "translation_control", "q_pos", 0.0),
        (TranslationLqrParams, "translation_control", "q_vel", -1.0),
        (TranslationLqrParams, "translation_control", "q_int", float("inf")),
        (TranslationLqrParams, "translation_control", "r_force", 0.0),
        (TranslationLqrParams, "translation_control", "max_force_n", -0.1),
        (TranslationLqrParams, "translation_control", "integral_limit_m_s", "big"),
    ],
)
def test_invalid_params_raise_config_error_naming_the_field(cls, section, field, value):
    with pytest.raises(ConfigError, match=rf"^{section}\.{field} must be .*got {value!r}"):
        cls(**{field: value})


def test_invalid_mass_raises_config_error():
    with pytest.raises(ConfigError, match="mass_kg"):
        design_translation_lqr(0.0, TranslationLqrParams())


def test_wrong_shapes_are_named():
    with pytest.raises(ValueError, match="q_ref_nav_body"):
        attitude_torque(
            rot.IDENTITY_QUAT, np.zeros(3), np.zeros(3), None, INERTIA_KG_M2, AttitudeControlParams()
        )
    with pytest.raises(ValueError, match="p_ref_nav"):
        TranslationController(MASS_KG).step(np.zeros(3), np.zeros(3), np.zeros(2), np.zeros(3))
