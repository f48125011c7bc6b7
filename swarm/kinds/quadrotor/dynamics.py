"""Truth dynamics of the ``quadrotor`` kind: rigid body, four rotors with first-order lag, linear drag,
gravity, ground contact; and the rotor power model.

Body frame x forward, y left, z up; nav z up (gravity ``-g`` along nav z). X frame: rotor ``i`` at
``r_i = arm (cos a_i, sin a_i, 0)`` with ``a = 45, -45, -135, 135`` deg (front-left, front-right,
rear-right, rear-left); rotor ``i`` pushes ``T_i = k_T omega_i^2`` along body z and its drag torques the
body by ``d_i k_Q omega_i^2`` about body z, ``d = (+1, -1, +1, -1)`` (diagonal pairs spin alike). The
wrench (Mahony, Kumar & Corke 2012, "Multirotor aerial vehicles", IEEE RAM 19(3), eq. 5-7)::

    [T, tau_x, tau_y, tau_z]^T = M [omega_1^2, ..., omega_4^2]^T,
    M = [[k_T] * 4, k_T y_i, -k_T x_i, k_Q d_i]                           (mixer_matrix)

Equations of motion (Newton-Euler): ``p' = v``, ``m v' = R(q) (0, 0, T) - m g e_z - R D R^T v`` (linear
drag ``D`` in the body axes), ``q' = q (x) (0, w) / 2``, ``J w' = tau - w x J w``; integrated by RK4 in
``substeps`` steps per tick, each rotor following its held speed command through the lag ``tau``
(exactly: ``omega += (omega_cmd - omega) (1 - exp(-h / tau))``) and held constant within a step.

Ground contact: the skids touch the ground when the centre of mass is ``gear_height_m`` above it. A
vehicle that reaches it moving down stops (an inelastic, non-sliding touchdown) and stays until its
thrust exceeds its weight; on the ground its rates are zero. The tick's effort is the rotors' electrical
energy ``sum k_Q omega_i^3 / efficiency * h`` [J].

Arrays (padded rows, :mod:`swarm.kinds.base`): ``x`` (13) the truth row; ``s`` (``S_N``): the rotors'
actual speeds [rad/s] and an on-ground flag; ``u`` (``U_N``): the held speed commands [rad/s];
``kp`` (``KP_N``): :func:`truth_row`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from swarm.core._fma_nb import matvec3, tmatvec3
from swarm.kinds.quadrotor.params import AirframeParams

U_N = 4
S_ROTORS, S_GROUND = 0, 4
S_N = 5
(KP_MASS, KP_J, KP_KT, KP_KQ, KP_TAU, KP_WMIN, KP_WMAX, KP_DRAG, KP_EFF, KP_G, KP_GROUND, KP_GEAR, KP_SUB,
 KP_MIX) = 0, 1, 4, 5, 6, 7, 8, 9, 12, 13, 14, 15, 16, 17  # fmt: skip
KP_N = KP_MIX + 16  # the mixer matrix M (4 x 4, row-major)

_ANGLES = np.radians([45.0, -45.0, -135.0, 135.0])
SPIN = np.array([1.0, -1.0, 1.0, -1.0])


def rotor_positions(arm_m: float) -> np.ndarray:
    """Rotor hubs (4, 3) in the body frame [m]."""
    return np.column_stack([arm_m * np.cos(_ANGLES), arm_m * np.sin(_ANGLES), np.zeros(4)])


def mixer_matrix(a: AirframeParams) -> np.ndarray:
    """``M`` (4, 4) of the module docstring: squared rotor speeds to ``[T, tau_x, tau_y, tau_z]``."""
    r = rotor_positions(a.arm_m)
    return np.vstack([np.full(4, a.thrust_coeff), a.thrust_coeff * r[:, 1], -a.thrust_coeff * r[:, 0],
                      a.torque_coeff * SPIN])  # fmt: skip


def truth_row(a: AirframeParams, mass_factor: float = 1.0, inertia_factor=(1.0, 1.0, 1.0)) -> np.ndarray:
    """The truth parameters ``kp`` (``KP_N``,) of one vehicle, with its mass and inertia dispersions."""
    kp = np.zeros(KP_N)
    kp[KP_MASS] = a.mass_kg * mass_factor
    kp[KP_J : KP_J + 3] = np.asarray(a.inertia_kg_m2) * np.asarray(inertia_factor)
    kp[KP_KT], kp[KP_KQ], kp[KP_TAU] = a.thrust_coeff, a.torque_coeff, a.rotor_tau_s
    kp[KP_WMIN], kp[KP_WMAX] = a.omega_min_rad_s, a.omega_max_rad_s
    kp[KP_DRAG : KP_DRAG + 3] = a.drag_n_s_m
    kp[KP_EFF], kp[KP_G], kp[KP_GROUND], kp[KP_GEAR] = (
        a.efficiency,
        a.gravity_m_s2,
        a.ground_z_m,
        a.gear_height_m,
    )
    kp[KP_SUB] = a.substeps
    kp[KP_MIX : KP_MIX + 16] = mixer_matrix(a).ravel()
    return kp


@numba.njit(cache=True)
def _rotmat(q):
    x, y, z, w = q[0], q[1], q[2], q[3]
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


@numba.njit(cache=True)
def _derivative(x, T, t0, t1, t2, kp, out):
    """``dx/dt`` of the truth row under thrust ``T`` [N] and body torque ``(t0, t1, t2)`` [N m]. In registers:
    the rotation's products are those ``R.T @ v`` and ``R @ f`` computed on the BLAS, to the bit
    (:mod:`swarm.core._fma_nb`)."""
    qx, qy, qz, qw = x[6], x[7], x[8], x[9]
    # _rotmat's entries
    r00, r01, r02 = 1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)
    r10, r11, r12 = 2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)
    r20, r21, r22 = 2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)
    m = kp[KP_MASS]
    v0, v1, v2 = x[3], x[4], x[5]
    vb0 = tmatvec3(r00, r10, r20, v0, v1, v2)  # R^T v
    vb1 = tmatvec3(r01, r11, r21, v0, v1, v2)
    vb2 = tmatvec3(r02, r12, r22, v0, v1, v2)
    f0, f1, f2 = -kp[KP_DRAG] * vb0, -kp[KP_DRAG + 1] * vb1, T - kp[KP_DRAG + 2] * vb2
    out[0], out[1], out[2] = v0, v1, v2
    out[3] = matvec3(r00, r01, r02, f0, f1, f2) / m  # R f / m
    out[4] = matvec3(r10, r11, r12, f0, f1, f2) / m
    out[5] = matvec3(r20, r21, r22, f0, f1, f2) / m - kp[KP_G]
    w0, w1, w2 = x[10], x[11], x[12]
    out[6] = 0.5 * (qw * w0 + qy * w2 - qz * w1)
    out[7] = 0.5 * (qw * w1 + qz * w0 - qx * w2)
    out[8] = 0.5 * (qw * w2 + qx * w1 - qy * w0)
    out[9] = -0.5 * (qx * w0 + qy * w1 + qz * w2)
    J0, J1, J2 = kp[KP_J], kp[KP_J + 1], kp[KP_J + 2]
    Jw0, Jw1, Jw2 = J0 * w0, J1 * w1, J2 * w2
    out[10] = (t0 - (w1 * Jw2 - w2 * Jw1)) / J0
    out[11] = (t1 - (w2 * Jw0 - w0 * Jw2)) / J1
    out[12] = (t2 - (w0 * Jw1 - w1 * Jw0)) / J2


@numba.njit(cache=True)
def quadrotor_truth_step(x, s, u, kp, dt):
    """Advance one quadrotor by ``dt`` [s] in place (module docstring); returns the tick's electrical
    energy [J]."""
    n = int(kp[KP_SUB])
    h = dt / n
    decay = 1.0 - math.exp(-h / kp[KP_TAU])
    work = np.empty((5, 13))  # one allocation a tick: the four RK4 slopes and the stage
    k1, k2, k3, k4, tmp = work[0], work[1], work[2], work[3], work[4]
    energy = 0.0
    floor = kp[KP_GROUND] + kp[KP_GEAR]
    h2, h6 = 0.5 * h, h / 6.0
    for _ in range(n):
        w2_0 = w2_1 = w2_2 = w2_3 = 0.0
        for i in range(4):
            cmd = min(max(u[i], 0.0), kp[KP_WMAX])
            s[S_ROTORS + i] += (cmd - s[S_ROTORS + i]) * decay
            om = s[S_ROTORS + i]
            if i == 0:
                w2_0 = om * om
            elif i == 1:
                w2_1 = om * om
            elif i == 2:
                w2_2 = om * om
            else:
                w2_3 = om * om
            energy += kp[KP_KQ] * om * om * om / kp[KP_EFF] * h
        # wr = M w2, summed from 0.0 column by column as the loop over a zeroed array did
        M = KP_MIX
        T = 0.0 + kp[M] * w2_0 + kp[M + 1] * w2_1 + kp[M + 2] * w2_2 + kp[M + 3] * w2_3
        t0 = 0.0 + kp[M + 4] * w2_0 + kp[M + 5] * w2_1 + kp[M + 6] * w2_2 + kp[M + 7] * w2_3
        t1 = 0.0 + kp[M + 8] * w2_0 + kp[M + 9] * w2_1 + kp[M + 10] * w2_2 + kp[M + 11] * w2_3
        t2 = 0.0 + kp[M + 12] * w2_0 + kp[M + 13] * w2_1 + kp[M + 14] * w2_2 + kp[M + 15] * w2_3
        if s[S_GROUND] != 0.0 and T <= kp[KP_MASS] * kp[KP_G]:
            x[3:6] = 0.0  # resting on its skids
            x[10:13] = 0.0
            continue
        _derivative(x, T, t0, t1, t2, kp, k1)
        for i in range(13):
            tmp[i] = x[i] + h2 * k1[i]
        _derivative(tmp, T, t0, t1, t2, kp, k2)
        for i in range(13):
            tmp[i] = x[i] + h2 * k2[i]
        _derivative(tmp, T, t0, t1, t2, kp, k3)
        for i in range(13):
            tmp[i] = x[i] + h * k3[i]
        _derivative(tmp, T, t0, t1, t2, kp, k4)
        for i in range(13):
            x[i] += h6 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        nq = math.sqrt(x[6] * x[6] + x[7] * x[7] + x[8] * x[8] + x[9] * x[9])
        for i in range(6, 10):
            x[i] /= nq
        if x[2] <= floor:
            x[2] = floor
            if x[5] < 0.0 or s[S_GROUND] != 0.0:
                x[3:6] = 0.0
                x[10:13] = 0.0
            s[S_GROUND] = 1.0
        else:
            s[S_GROUND] = 0.0
    return energy


@numba.njit(cache=True)
def quadrotor_hold(u_cmd, s, u_held, kp):
    """Hold rotor speed commands, clipped to ``[0, omega_max]`` (0 for a non-finite entry)."""
    changed = False
    for i in range(U_N):
        v = u_cmd[i]
        v = min(max(v, 0.0), kp[KP_WMAX]) if np.isfinite(v) else 0.0
        if v != u_held[i]:
            changed = True
        u_held[i] = v
    return changed
