"""Planar truth dynamics of the ``ground`` kind: mecanum kinematics, motor lag, saturation and slip.

The TPODS MK-E module rides on a table (paper section VI-A) on four mecanum wheels: wheel 1 front-left,
2 front-right, 3 rear-right, 4 rear-left, with contact points at ``(x_i, y_i) = (+l, +w), (+l, -w),
(-l, -w), (-l, +w)`` in the body frame (x forward, y left, z up) and free rollers at ``gamma_i = -45,
+45, -45, +45`` deg. Lynch & Park, "Modern Robotics", 2017, sec. 13.2, eq. 13.5 gives each wheel's
driving speed as ``u_i = ((vx - wz y_i) + tan(gamma_i) (vy + wz x_i)) / r``; for this layout that is
eq. 13.10, written here with the twist ordered ``(vx, vy, wz)`` (the book orders ``(wz, vx, vy)``)::

    [u1]         [1  -1  -(l + w)] [vx]
    [u2] = 1/r * [1   1   (l + w)] [vy]            u = H twist              (mecanum_inverse)
    [u3]         [1  -1   (l + w)] [wz]
    [u4]         [1   1  -(l + w)]

**Sign convention**: a positive wheel speed rolls that wheel forward (+x). Driving forward turns all four
wheels forward; moving left (+y) turns wheels 2 and 4 forward and 1 and 3 backward; turning
counter-clockwise seen from above (+wz) turns the left wheels (1, 4) backward and the right wheels (2, 3)
forward (``tests/kinds/test_ground_dynamics.py``). The columns of ``H`` are orthogonal, so its least-squares
inverse is ``H^T / diag(|columns|^2)``, Lynch & Park eq. 13.11::

    twist = r/4 * [[1, 1, 1, 1], [-1, 1, -1, 1], [-1, 1, 1, -1] / (l + w)] u     (mecanum_forward)

exact for wheel speeds in the range of ``H`` (consistent, no slip between them).

Truth step (:func:`ground_truth_step`, one tick of ``dt``): each wheel-speed command is clipped to the
motor's limit and held; each wheel follows it through a first-order lag ``ds/dt = (u - s) / tau``,
integrated exactly. A wheel's ground speed is its own speed times its traction factor (slip). The body
twist is ``mecanum_forward`` of the wheels' ground speeds, and the pose moves by the SE(2) exponential of
the tick's mean twist (Lynch & Park sec. 3.3.3; exact for a constant twist). The vehicle is planar: the
height ``x[2]`` is kept, the attitude is a yaw about nav z.

Arrays (float64; the world pads them to the widest kind, so only the leading entries are read):

* ``x`` (>= 13): ``[p_nav(3), v_nav(3), q_nav_body(4), w_body(3)]``, scalar-last quaternion;
* ``s`` (>= ``S_N``): actuator state, the wheels' actual speeds [rad/s] at ``S_WHEELS``;
* ``u`` (>= ``U_N``): the held wheel-speed commands [rad/s] of wheels 1..4;
* ``kp`` (>= ``KP_N``): the vehicle's truth parameters, :func:`ground_truth_row`.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from swarm.kinds.ground.params import WheelParams

__all__ = [
    "KP_HALF_LENGTH",
    "KP_HALF_WIDTH",
    "KP_MAX_SPEED",
    "KP_N",
    "KP_RADIUS",
    "KP_SLIP",
    "KP_TAU",
    "S_N",
    "S_WHEELS",
    "U_N",
    "ground_truth_row",
    "ground_truth_step",
    "mecanum_forward",
    "mecanum_inverse",
]

FloatArray = NDArray[np.float64]

KP_RADIUS = 0
"""Index in ``kp`` of the wheel radius [m]."""
KP_HALF_LENGTH = 1
"""Index in ``kp`` of the contact points' half length along body x [m]."""
KP_HALF_WIDTH = 2
"""Index in ``kp`` of the contact points' half width along body y [m]."""
KP_TAU = 3
"""Index in ``kp`` of the motor time constant [s]."""
KP_MAX_SPEED = 4
"""Index in ``kp`` of the wheel-speed limit [rad/s]."""
KP_SLIP = 5
"""First of 4 indices in ``kp``: the traction factors of wheels 1..4, in (0, 1]."""
KP_N = 9
"""Length of ``kp``."""

S_WHEELS = 0
"""First of 4 indices in ``s``: the actual speeds of wheels 1..4 [rad/s]."""
S_N = 4
"""Length of ``s``."""
U_N = 4
"""Length of ``u``: the wheel-speed commands of wheels 1..4 [rad/s]."""

# Below this |yaw increment| [rad] the SE(2) exponential's sin(t)/t and (1 - cos(t))/t use their Taylor
# series; the truncation error (t^6/5040) is below 1e-22 there.
_SE2_TAYLOR_THRESHOLD_RAD = 1e-3


# ---------------------------------------------------------------------------------------------- kinematics


@numba.njit(cache=True)
def _inverse4(vx, vy, wz, radius, half_length, half_width):
    """Wheel speeds ``u1..u4`` [rad/s] of the twist ``(vx, vy, wz)`` as scalars (Lynch & Park eq. 13.10)."""
    k = (half_length + half_width) * wz
    return (vx - vy - k) / radius, (vx + vy + k) / radius, (vx - vy + k) / radius, (vx + vy - k) / radius


@numba.njit(cache=True)
def _forward3(u1, u2, u3, u4, radius, half_length, half_width):
    """Body twist ``(vx, vy, wz)`` of wheel speeds ``u1..u4`` as scalars (Lynch & Park eq. 13.11)."""
    q = 0.25 * radius
    return (
        q * (u1 + u2 + u3 + u4),
        q * (-u1 + u2 - u3 + u4),
        q * (-u1 + u2 + u3 - u4) / (half_length + half_width),
    )


@numba.njit(cache=True)
def mecanum_inverse(twist: np.ndarray, radius: float, half_length: float, half_width: float) -> np.ndarray:
    """Wheel speeds (4,) [rad/s] of wheels 1..4 that realise the body twist (Lynch & Park eq. 13.10).

    Args:
        twist: ``(vx, vy, wz)`` (>= 3,): body-frame velocity of the centre [m/s, m/s] and yaw rate [rad/s].
        radius: wheel radius [m].
        half_length, half_width: contact points' offsets along body x and y [m].
    """
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = _inverse4(twist[0], twist[1], twist[2], radius, half_length, half_width)
    return out


@numba.njit(cache=True)
def mecanum_forward(wheels: np.ndarray, radius: float, half_length: float, half_width: float) -> np.ndarray:
    """Body twist ``(vx, vy, wz)`` (3,) [m/s, m/s, rad/s] of wheel speeds (>= 4,) [rad/s] of wheels 1..4.

    The least-squares inverse of :func:`mecanum_inverse` (Lynch & Park eq. 13.11): exact for consistent
    wheel speeds, the best fit (the four wheels' rolling constraints cannot all hold) otherwise.
    ``radius``, ``half_length``, ``half_width`` [m] as in :func:`mecanum_inverse`.
    """
    out = np.empty(3)
    out[0], out[1], out[2] = _forward3(
        wheels[0], wheels[1], wheels[2], wheels[3], radius, half_length, half_width
    )
    return out


# ---------------------------------------------------------------------------------------------- truth step


@numba.njit(cache=True)
def _lag(command, speed, limit, decay, mean_gain):
    """Mean and end-of-tick speed of one wheel at ``speed`` following ``command`` clipped to ``+-limit``
    through the exact first-order lag (:func:`ground_truth_step`)."""
    c = min(max(command, -limit), limit)
    d = speed - c
    return c + d * mean_gain, c + d * decay


def ground_truth_row(wheels: WheelParams, slip: ArrayLike) -> FloatArray:
    """The truth parameters ``kp`` (KP_N,) of one vehicle: wheel geometry, lag, limit and ``slip`` (4,),
    the traction factors of wheels 1..4 in (0, 1] (``params.slip_factors``)."""
    f = np.asarray(slip, dtype=np.float64)
    if f.shape != (4,):
        raise ValueError(f"slip must have shape (4,), got {f.shape}")
    if not (np.all(np.isfinite(f)) and np.all(f > 0.0) and np.all(f <= 1.0)):
        raise ValueError(f"slip factors must be in (0, 1], got {f!r}")
    kp = np.empty(KP_N)
    kp[KP_RADIUS] = wheels.radius_m
    kp[KP_HALF_LENGTH] = wheels.half_length_m
    kp[KP_HALF_WIDTH] = wheels.half_width_m
    kp[KP_TAU] = wheels.motor_time_constant_s
    kp[KP_MAX_SPEED] = wheels.max_speed_rad_s
    kp[KP_SLIP : KP_SLIP + 4] = f
    return kp


@numba.njit(cache=True)
def ground_truth_step(x: np.ndarray, s: np.ndarray, u: np.ndarray, kp: np.ndarray, dt: float) -> float:
    """Advance the truth ``x`` and wheel speeds ``s`` of one ground vehicle by ``dt`` [s] > 0, in place.

    Returns the effort increment [rad]: the wheel travel ``sum_i |s_mean_i| dt`` of the tick.

    Per wheel ``i`` (``c_i`` the command ``u_i`` clipped to ``+-kp[KP_MAX_SPEED]``, ``a = exp(-dt/tau)``),
    the exact solution of ``ds/dt = (c - s) / tau`` for the held command and its mean over the tick::

        s_i(t + dt) = c_i + (s_i - c_i) a
        s_mean_i    = c_i + (s_i - c_i) tau (1 - a) / dt

    The mean body twist is ``mecanum_forward(f_i s_mean_i)`` (``f_i`` the traction factors). With yaw
    ``psi`` and ``dpsi = wz dt``, the pose moves by the SE(2) exponential of the mean twist times ``dt``::

        p_nav[:2] += R(psi) V(dpsi) (vx, vy) dt,   V = [[sin d / d, -(1 - cos d) / d],
        psi       += dpsi                                [(1 - cos d) / d, sin d / d]]

    The twist is linear in the wheel speeds, so the yaw increment is exact, and so is the translation when
    ``wz`` is zero. Otherwise, while the wheels are still settling, the twist changes within the tick and
    the mean-twist exponential misses the correlation of speed and heading: an error of about
    ``|wz| |dv| dt^2 / 12`` per tick for a velocity change ``dv`` over the tick (~1e-7 m in a 10 ms tick of
    a 0.5 rad/s turn whose speed changes by 0.02 m/s), and none once the wheels have settled.

    Planarity: ``x[2]`` is kept; ``psi`` is the yaw of the incoming ``q`` (``atan2(R10, R00)``) and the new
    attitude is the pure yaw ``(0, 0, sin(psi/2), cos(psi/2))``, so any roll or pitch in the incoming ``q``
    is dropped. At the end of the tick ``v_nav = R(psi) (vx, vy, 0)`` and ``w_body = (0, 0, wz)`` of the
    twist of the end-of-tick wheel speeds (times their traction factors).

    Args:
        x: truth row (>= 13,), ``[p_nav, v_nav, q_nav_body, w_body]``, updated in place.
        s: wheel speeds (>= S_N,) [rad/s], updated in place.
        u: held wheel-speed commands (>= U_N,) [rad/s].
        kp: truth parameters (>= KP_N,), :func:`ground_truth_row`.
        dt: tick [s].
    """
    radius = kp[KP_RADIUS]
    half_length = kp[KP_HALF_LENGTH]
    half_width = kp[KP_HALF_WIDTH]
    tau = kp[KP_TAU]
    limit = kp[KP_MAX_SPEED]
    decay = math.exp(-dt / tau)
    mean_gain = -math.expm1(-dt / tau) * tau / dt  # tau (1 - a) / dt without cancellation for small dt
    f0, f1, f2, f3 = kp[KP_SLIP], kp[KP_SLIP + 1], kp[KP_SLIP + 2], kp[KP_SLIP + 3]
    m0, e0 = _lag(u[0], s[S_WHEELS], limit, decay, mean_gain)
    m1, e1 = _lag(u[1], s[S_WHEELS + 1], limit, decay, mean_gain)
    m2, e2 = _lag(u[2], s[S_WHEELS + 2], limit, decay, mean_gain)
    m3, e3 = _lag(u[3], s[S_WHEELS + 3], limit, decay, mean_gain)
    s[S_WHEELS], s[S_WHEELS + 1], s[S_WHEELS + 2], s[S_WHEELS + 3] = e0, e1, e2, e3
    effort = (abs(m0) + abs(m1) + abs(m2) + abs(m3)) * dt
    # the wheels' ground speeds: their own speeds times their traction factors
    m0, m1, m2, m3 = f0 * m0, f1 * m1, f2 * m2, f3 * m3
    e0, e1, e2, e3 = f0 * e0, f1 * e1, f2 * e2, f3 * e3
    vx, vy, wz = _forward3(m0, m1, m2, m3, radius, half_length, half_width)

    qx, qy, qz, qw = x[6], x[7], x[8], x[9]
    psi = math.atan2(2.0 * (qx * qy + qz * qw), 1.0 - 2.0 * (qy * qy + qz * qz))
    dpsi = wz * dt
    if abs(dpsi) < _SE2_TAYLOR_THRESHOLD_RAD:
        d2 = dpsi * dpsi
        sin_d = 1.0 - d2 / 6.0 + d2 * d2 / 120.0  # sin(d) / d
        cos_d = dpsi * (0.5 - d2 / 24.0 + d2 * d2 / 720.0)  # (1 - cos(d)) / d
    else:
        sin_d = math.sin(dpsi) / dpsi
        cos_d = (1.0 - math.cos(dpsi)) / dpsi
    bx = (sin_d * vx - cos_d * vy) * dt  # displacement in the start-of-tick body frame [m]
    by = (cos_d * vx + sin_d * vy) * dt
    c0, s0 = math.cos(psi), math.sin(psi)
    x[0] += c0 * bx - s0 * by
    x[1] += s0 * bx + c0 * by

    psi += dpsi
    half = 0.5 * psi
    x[6] = 0.0
    x[7] = 0.0
    x[8] = math.sin(half)
    x[9] = math.cos(half)
    evx, evy, ewz = _forward3(e0, e1, e2, e3, radius, half_length, half_width)
    c1, s1 = math.cos(psi), math.sin(psi)
    x[3] = c1 * evx - s1 * evy
    x[4] = s1 * evx + c1 * evy
    x[5] = 0.0
    x[10] = 0.0
    x[11] = 0.0
    x[12] = ewz
    return effort
