"""The ``quadrotor`` kind's controller: PX4's cascaded multicopter control, and the mixer.

One control step (:func:`quadrotor_control`), on the estimate ``p, v, q`` and the latest gyro rate ``w``,
toward the guidance reference ``(p_ref, v_ref, a_ref, q_ref)``:

1. **Position** (P): ``v_sp = v_ref + K_p (p_ref - p)``, horizontal speed and vertical speed bounded.
2. **Velocity** (PI with feed-forward): ``a_sp = a_ref + K_v (v_sp - v) + K_i int (v_sp - v) dt``, each
   integral's contribution bounded (anti-windup).
3. **Thrust vector**: ``F = m (a_sp + g e_z)``, its tilt from the vertical bounded by ``max_tilt_deg``
   (the horizontal part scaled down); the desired body z is ``F / |F|``, the desired heading that of
   ``q_ref``; the collective thrust is ``F`` projected on the current body z (PX4's
   ``thrustToAttitude``; Mellinger & Kumar 2011, eq. 6-8).
4. **Attitude** (P on the quaternion error, Brescianini, Hehn & D'Andrea 2013): ``q_e = q^-1 (x) q_d``
   with ``w_e >= 0``, ``w_sp = K_att 2 vec(q_e)`` (yaw with its own gain), bounded by ``max_rate_deg_s``.
5. **Rate** (P): ``tau = J K_rate (w_sp - w) + w x J w``.
6. **Mixer**: ``omega^2 = M^-1 [T, tau]``, each clipped to ``[omega_min^2, omega_max^2]``; the command is
   the speeds ``omega`` [rad/s]; a clipped rotor is a saturation.

Parameters ``cp`` (:func:`control_row`), state ``cs``: the velocity integrals (3) [m/s].
"""

from __future__ import annotations

import math

import numba
import numpy as np

from swarm.kinds.quadrotor.dynamics import U_N, mixer_matrix
from swarm.kinds.quadrotor.params import QuadrotorParams

(CP_MASS, CP_J, CP_G, CP_KP_XY, CP_KP_Z, CP_KV_XY, CP_KI_XY, CP_KV_Z, CP_KI_Z, CP_VMAX_XY, CP_VMAX_Z,
 CP_TILT, CP_ATT, CP_ATT_YAW, CP_RATE, CP_RATE_YAW, CP_WMAX_RATE, CP_INT_LIM, CP_DT, CP_KT, CP_OMIN, CP_OMAX,
 CP_MINV) = 0, 1, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24  # fmt: skip
CP_N = CP_MINV + 16
CS_INT = 0
CS_N = 3


def control_row(p: QuadrotorParams) -> np.ndarray:
    """The controller's parameters (``CP_N``,): nominal airframe (the controller does not know the
    dispersions), gains, limits and the inverse mixer."""
    a, c = p.airframe, p.control
    cp = np.zeros(CP_N)
    cp[CP_MASS] = a.mass_kg
    cp[CP_J : CP_J + 3] = a.inertia_kg_m2
    cp[CP_G] = a.gravity_m_s2
    cp[CP_KP_XY], cp[CP_KP_Z] = c.pos_gain_xy, c.pos_gain_z
    cp[CP_KV_XY], cp[CP_KI_XY], cp[CP_KV_Z], cp[CP_KI_Z] = (
        c.vel_gain_xy,
        c.vel_int_xy,
        c.vel_gain_z,
        c.vel_int_z,
    )
    cp[CP_VMAX_XY], cp[CP_VMAX_Z] = c.max_speed_xy_m_s, c.max_speed_z_m_s
    cp[CP_TILT] = math.radians(c.max_tilt_deg)
    cp[CP_ATT], cp[CP_ATT_YAW], cp[CP_RATE], cp[CP_RATE_YAW] = (
        c.att_gain,
        c.att_gain_yaw,
        c.rate_gain,
        c.rate_gain_yaw,
    )
    cp[CP_WMAX_RATE] = math.radians(c.max_rate_deg_s)
    cp[CP_INT_LIM] = c.int_limit_m_s2
    cp[CP_DT] = 1.0 / c.rate_hz
    cp[CP_KT], cp[CP_OMIN], cp[CP_OMAX] = a.thrust_coeff, a.omega_min_rad_s, a.omega_max_rad_s
    cp[CP_MINV : CP_MINV + 16] = np.linalg.inv(mixer_matrix(a)).ravel()
    return cp


@numba.njit(cache=True)
def _matrix_to_quat(R):
    """Shepperd's method; scalar-last."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        return np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    if R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2.0
        return np.array([0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s])
    if R[1, 1] > R[2, 2]:
        s = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2.0
        return np.array([(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s])
    s = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2.0
    return np.array([(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s])


@numba.njit(cache=True)
def mix(cp, T, tau, u):
    """Rotor speeds ``u`` (4,) [rad/s] for thrust ``T`` [N] and torque ``tau`` (3,) [N m] through the inverse
    mixer, clipped to the rotors' range; returns whether a rotor was clipped."""
    sat = False
    lo, hi = cp[CP_OMIN] ** 2, cp[CP_OMAX] ** 2
    for i in range(U_N):
        w2 = cp[CP_MINV + 4 * i] * T
        for j in range(3):
            w2 += cp[CP_MINV + 4 * i + 1 + j] * tau[j]
        if w2 < lo or w2 > hi:
            sat = True
            w2 = min(max(w2, lo), hi)
        u[i] = math.sqrt(w2)
    return sat


@numba.njit(cache=True)
def quadrotor_control(cs, cp, p, v, q, w, p_ref, v_ref, a_ref, q_ref, u, act):
    """One control step (module docstring): writes the rotor speeds ``u`` and ``act`` (the known body force
    ``(0, 0, T)`` and net force, the net torque); returns whether a rotor saturated."""
    m, g, dt = cp[CP_MASS], cp[CP_G], cp[CP_DT]
    # 1. position -> velocity setpoint (scalars throughout: no allocation but Rd's, qd's and tau's)
    kxy, kz = cp[CP_KP_XY], cp[CP_KP_Z]
    vsp0 = v_ref[0] + kxy * (p_ref[0] - p[0])
    vsp1 = v_ref[1] + kxy * (p_ref[1] - p[1])
    vsp2 = v_ref[2] + kz * (p_ref[2] - p[2])
    hxy = math.hypot(vsp0, vsp1)
    if hxy > cp[CP_VMAX_XY]:
        vsp0 *= cp[CP_VMAX_XY] / hxy
        vsp1 *= cp[CP_VMAX_XY] / hxy
    vsp2 = min(max(vsp2, -cp[CP_VMAX_Z]), cp[CP_VMAX_Z])
    # 2. velocity PI -> acceleration setpoint, 3. thrust vector
    F0 = F1 = F2 = 0.0
    for i in range(3):
        kv, ki = (cp[CP_KV_Z], cp[CP_KI_Z]) if i == 2 else (cp[CP_KV_XY], cp[CP_KI_XY])
        e = (vsp0 if i == 0 else (vsp1 if i == 1 else vsp2)) - v[i]
        cs[CS_INT + i] += e * dt
        if ki > 0.0:
            lim = cp[CP_INT_LIM] / ki
            cs[CS_INT + i] = min(max(cs[CS_INT + i], -lim), lim)
        f = m * (a_ref[i] + kv * e + ki * cs[CS_INT + i])
        if i == 0:
            F0 = f
        elif i == 1:
            F1 = f
        else:
            F2 = f
    F2 += m * g
    F2 = max(F2, 0.1 * m * g)  # never command thrust downwards
    horiz = math.hypot(F0, F1)
    max_h = F2 * math.tan(cp[CP_TILT])
    if horiz > max_h:
        F0 *= max_h / horiz
        F1 *= max_h / horiz
    nf = math.sqrt(F0**2 + F1**2 + F2**2)
    zd0, zd1, zd2 = F0 / nf, F1 / nf, F2 / nf
    # heading of the reference: its body x axis projected on the horizontal (_rotmat(q_ref)'s column 0)
    rx, ry, rz, rw = q_ref[0], q_ref[1], q_ref[2], q_ref[3]
    xc0, xc1, xc2 = 1 - 2 * (ry * ry + rz * rz), 2 * (rx * ry + rz * rw), 0.0
    if math.hypot(xc0, xc1) < 1e-6:
        xc0, xc1, xc2 = 1.0, 0.0, 0.0
    # yd = zd x xc, normalised; xd = yd x zd (np.cross's products and differences)
    yd0, yd1, yd2 = zd1 * xc2 - zd2 * xc1, zd2 * xc0 - zd0 * xc2, zd0 * xc1 - zd1 * xc0
    ny = math.sqrt(yd0**2 + yd1**2 + yd2**2)
    yd0, yd1, yd2 = yd0 / ny, yd1 / ny, yd2 / ny
    xd0, xd1, xd2 = yd1 * zd2 - yd2 * zd1, yd2 * zd0 - yd0 * zd2, yd0 * zd1 - yd1 * zd0
    Rd = np.empty((3, 3))
    Rd[0, 0], Rd[1, 0], Rd[2, 0] = xd0, xd1, xd2
    Rd[0, 1], Rd[1, 1], Rd[2, 1] = yd0, yd1, yd2
    Rd[0, 2], Rd[1, 2], Rd[2, 2] = zd0, zd1, zd2
    qd = _matrix_to_quat(Rd)
    # _rotmat(q)'s column 2: the body z axis in nav
    qx, qy, qz, qw = q[0], q[1], q[2], q[3]
    R02, R12, R22 = 2 * (qx * qz + qy * qw), 2 * (qy * qz - qx * qw), 1 - 2 * (qx * qx + qy * qy)
    T = F0 * R02 + F1 * R12 + F2 * R22
    T = max(T, 0.0)
    # 4. attitude error -> rate setpoint (body frame): q_e = q^-1 (x) q_d
    x1, y1, z1, w1 = -q[0], -q[1], -q[2], q[3]
    x2, y2, z2, w2 = qd[0], qd[1], qd[2], qd[3]
    ex = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    ey = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    ez = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2
    ew = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    sgn = 1.0 if ew >= 0.0 else -1.0
    wmax = cp[CP_WMAX_RATE]
    wsp0 = min(max(2.0 * sgn * ex * cp[CP_ATT], -wmax), wmax)
    wsp1 = min(max(2.0 * sgn * ey * cp[CP_ATT], -wmax), wmax)
    wsp2 = min(max(2.0 * sgn * ez * cp[CP_ATT_YAW], -wmax), wmax)
    # 5. rate -> torque
    J0, J1, J2 = cp[CP_J], cp[CP_J + 1], cp[CP_J + 2]
    w0_, w1_, w2_ = w[0], w[1], w[2]
    tau = np.empty(3)
    tau[0] = J0 * cp[CP_RATE] * (wsp0 - w0_)
    tau[1] = J1 * cp[CP_RATE] * (wsp1 - w1_)
    tau[2] = J2 * cp[CP_RATE_YAW] * (wsp2 - w2_)
    Jw0, Jw1, Jw2 = J0 * w0_, J1 * w1_, J2 * w2_
    tau[0] += w1_ * Jw2 - w2_ * Jw1
    tau[1] += w2_ * Jw0 - w0_ * Jw2
    tau[2] += w0_ * Jw1 - w1_ * Jw0
    # 6. mixer
    sat = mix(cp, T, tau, u)
    Ta = 0.0
    for i in range(U_N):
        Ta += cp[CP_KT] * u[i] * u[i]
    act[0], act[1], act[2] = 0.0, 0.0, Ta
    act[3], act[4], act[5] = 0.0, 0.0, Ta
    act[6], act[7], act[8] = tau[0], tau[1], tau[2]
    return sat


@numba.njit(cache=True)
def quadrotor_idle(cp, u, act):
    """Disarmed: every rotor stopped."""
    for i in range(U_N):
        u[i] = 0.0
    act[:] = 0.0
