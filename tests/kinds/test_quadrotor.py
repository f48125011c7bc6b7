"""The quadrotor kind's physics and controller (issue 15 must-shows: hover trim, a step within the stated
overshoot and time, hover energy equal to the rotor power model), plus ground contact and the mixer."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.core import rotations as rot
from swarm.errors import ConfigError
from swarm.kinds.quadrotor import AirframeParams, ControlParams, QuadrotorParams, control_row, truth_row
from swarm.kinds.quadrotor import control as C
from swarm.kinds.quadrotor import dynamics as D

P = QuadrotorParams()
A = P.airframe
KP = truth_row(A)
CP = control_row(P)
DT = 1.0 / P.control.rate_hz
LEVEL = np.array([0.0, 0.0, 0.0, 1.0])


def state(p=(0.0, 0.0, 2.0), q=LEVEL, w=(0.0, 0.0, 0.0)):
    x = np.zeros(13)
    x[0:3], x[6:10], x[10:13] = p, q, w
    return x


def fly(x, p_ref, seconds, q_ref=LEVEL, rotors=None):
    """Closed loop on the true state at the control rate: the trajectory (n, 13) and the energy [J]."""
    s = np.zeros(D.S_N)
    s[:4] = A.hover_omega_rad_s if rotors is None else rotors
    u, held, cs, act = np.zeros(4), np.zeros(4), np.zeros(C.CS_N), np.zeros(9)
    out, energy = [], 0.0
    for _ in range(round(seconds / DT)):
        C.quadrotor_control(cs, CP, x[0:3], x[3:6], x[6:10], x[10:13], np.asarray(p_ref, float), np.zeros(3),
                            np.zeros(3), np.asarray(q_ref, float), u, act)  # fmt: skip
        D.quadrotor_hold(u, s, held, KP)
        energy += D.quadrotor_truth_step(x, s, held, KP, DT)
        out.append(x.copy())
    return np.array(out), energy


def test_thrust_equals_weight_at_the_trim_rotor_speed_and_the_hover_holds():
    M = D.mixer_matrix(A)
    wrench = M @ np.full(4, A.hover_omega_rad_s**2)
    assert wrench[0] == pytest.approx(A.mass_kg * A.gravity_m_s2, rel=1e-12)
    np.testing.assert_allclose(wrench[1:], 0.0, atol=1e-12)  # no torque: the X frame is balanced
    x, s = state(), np.zeros(D.S_N)
    s[:4] = A.hover_omega_rad_s
    held = np.full(4, A.hover_omega_rad_s)
    for _ in range(1000):  # 10 s open loop at the trim speed
        D.quadrotor_truth_step(x, s, held, KP, DT)
    np.testing.assert_allclose(x[0:3], [0.0, 0.0, 2.0], atol=1e-6)


def test_hover_energy_equals_the_rotor_power_model():
    _, energy = fly(state(), (0.0, 0.0, 2.0), 10.0)
    assert energy == pytest.approx(A.hover_power_w * 10.0, rel=1e-6)
    assert 100.0 < A.hover_power_w < 300.0  # 1.5 kg on 10-inch props: ~115 W/kg


@pytest.mark.parametrize("step", [(1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)])
def test_a_position_step_settles_within_the_stated_overshoot_and_time(step):
    c = P.control
    start = np.array([0.0, 0.0, 2.0])
    x, _ = fly(state(start), start + step, c.spec_step_settle_s + 2.0)
    axis = int(np.flatnonzero(step)[0])
    sign = np.sign(step[axis])
    travel = sign * (x[:, axis] - start[axis])  # along the step, 0 -> 1
    assert travel.max() <= 1.0 + c.spec_step_overshoot
    t = np.arange(1, len(x) + 1) * DT
    outside = np.abs(travel - 1.0) > 0.05
    assert t[outside].max() <= c.spec_step_settle_s
    others = [i for i in range(3) if i != axis]
    assert np.abs(x[:, others] - start[others]).max() < 0.05  # the other axes stay put


def test_a_tilted_spinning_start_is_levelled_and_a_yaw_step_reached():
    q0 = rot.rotvec_exp(np.radians([25.0, -15.0, 0.0]))
    x, _ = fly(state(q=q0, w=(2.0, -1.0, 1.0)), (0.0, 0.0, 2.0), 1.5)
    tilt = np.degrees(np.arccos(np.clip(rot.quat_rotate(x[-1, 6:10], np.array([0.0, 0.0, 1.0]))[2], -1, 1)))
    assert tilt < 2.0 and abs(x[-1, 2] - 2.0) < 0.3
    q90 = rot.rotvec_exp(np.radians([0.0, 0.0, 90.0]))
    x, _ = fly(state(), (0.0, 0.0, 2.0), 4.0, q_ref=q90)
    err = np.degrees(np.linalg.norm(rot.attitude_error(q90, x[-1, 6:10])))
    assert err < 1.0


def test_ground_contact_a_falling_vehicle_rests_on_its_skids_and_takes_off_again():
    floor = A.ground_z_m + A.gear_height_m
    x, s = state((0.0, 0.0, 1.0)), np.zeros(D.S_N)
    held = np.zeros(4)  # rotors off: it falls
    zs = []
    for _ in range(200):
        D.quadrotor_truth_step(x, s, held, KP, DT)
        zs.append(x[2])
    assert min(zs) >= floor and x[2] == floor and np.all(x[3:6] == 0.0) and s[D.S_GROUND] == 1.0
    out, _ = fly(x, (0.0, 0.0, 1.0), 4.0, rotors=0.0)  # the controller lifts it off
    assert abs(out[-1, 2] - 1.0) < 0.05


def test_the_mixer_inverts_the_wrench_and_flags_saturation():
    u, wrench_in = np.zeros(4), np.array([16.0, 0.05, -0.03, 0.01])
    assert not C.mix(CP, wrench_in[0], wrench_in[1:], u)
    np.testing.assert_allclose(D.mixer_matrix(A) @ u**2, wrench_in, rtol=1e-10)
    assert C.mix(CP, 100.0, np.zeros(3), u)  # beyond four rotors at top speed
    assert np.all(u == A.omega_max_rad_s)


def test_bad_tables_are_refused_naming_the_field():
    with pytest.raises(ConfigError, match=r"^kinds\.quadrotor\.airframe\.mass_kg"):
        AirframeParams(mass_kg=-1.0)
    with pytest.raises(
        ConfigError, match=r"^kinds\.quadrotor\.airframe: the rotors at omega_max_rad_s cannot lift"
    ):
        AirframeParams(omega_max_rad_s=300.0)
    with pytest.raises(ConfigError, match=r"^kinds\.quadrotor\.control\.max_tilt_deg"):
        ControlParams(max_tilt_deg=85.0)
