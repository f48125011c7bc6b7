"""Controller of the ``ground`` kind: discrete LQR on the lagged velocity plant, yaw law, mecanum inverse.

The wheels' motors are speed-controlled, so the controller commands a body velocity rather than a force:
per nav axis the plant is the velocity command ``u`` through the motor lag (``tau``, the wheels' time
constant; the mecanum kinematics are linear, so the body twist lags its command exactly as each wheel
does, :mod:`swarm.kinds.ground.dynamics`)::

    dp/dt = v,   dv/dt = (u - v) / tau

The LQR (Ogata, "Discrete-time Control Systems", 2nd ed., 1995, ch. 8) acts on the zero-order-hold
discretisation of this plant at the controller rate, augmented with the integral of the position error, as
:func:`swarm.core.control.design_translation_lqr` does for the double integrator. The yaw is a
proportional law on the wrapped yaw error; the vehicle is planar, so only x, y and the yaw are controlled.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from swarm.core.control import dlqr
from swarm.errors import ConfigError
from swarm.kinds.ground.dynamics import _inverse4
from swarm.kinds.ground.params import GroundBodyParams, GroundControlParams, WheelParams

__all__ = ["GroundCommand", "GroundController", "GroundLqrDesign", "design_ground_lqr", "yaw_of"]

FloatArray = NDArray[np.float64]


def yaw_of(q_nav_body: ArrayLike) -> float:
    """Yaw [rad] in (-pi, pi] of the scalar-last quaternion ``q_nav_body`` (4,): the heading of body x in
    the nav xy plane, ``atan2(R10, R00)`` (the z angle of the z-y-x Euler sequence)."""
    x, y, z, w = (float(c) for c in q_nav_body)
    return math.atan2(2.0 * (x * y + z * w), 1.0 - 2.0 * (y * y + z * z))


def _wrap(angle: float) -> float:
    """``angle`` [rad] wrapped to (-pi, pi]."""
    a = math.remainder(angle, 2.0 * math.pi)  # in [-pi, pi]
    return math.pi if a == -math.pi else a


@dataclass(frozen=True, eq=False)
class GroundLqrDesign:
    """The per-axis discrete LQR of the ground controller, the same on nav x and y (read-only arrays).

    The per-axis state is ``(p - p_ref [m], v - v_ref [m/s], integral of p - p_ref [m s])`` and the input
    the feedback part of the velocity command [m/s].
    """

    K_axis: FloatArray
    """Gain (1, 3): ``u_fb = -K_axis x`` [1/s, 1, 1/s^2]; the integral gain is 0 when disabled."""
    A_d: FloatArray
    """Discrete state matrix (3, 3) of the augmented per-axis plant."""
    B_d: FloatArray
    """Discrete input matrix (3, 1)."""
    P: FloatArray
    """Riccati solution (3, 3) (zero row/column for the integral when it is disabled)."""
    closed_loop_eigs: FloatArray
    """Eigenvalues of ``A_d - B_d K_axis`` (3,) or, integral disabled, (2,) complex."""


@functools.lru_cache(maxsize=64)  # a pure function of frozen parameters; its arrays are read-only
def design_ground_lqr(control: GroundControlParams, wheels: WheelParams) -> GroundLqrDesign:
    """Per-axis LQR of the lagged velocity plant (module docstring) at ``T = control.dt_s``.

    With ``a = exp(-T / tau)``, the zero-order hold of ``dp/dt = v, dv/dt = (u - v) / tau`` over ``T``,
    augmented with the integral ``z`` of the position error (forward rectangle, as the controller
    accumulates it), is (Ogata 1995 ch. 8; ``tests/kinds/test_ground_control.py`` checks it against
    ``scipy.signal.cont2discrete``)::

        [p]+   [1  tau (1 - a)  0] [p]   [T - tau (1 - a)]
        [v]  = [0  a            0] [v] + [1 - a          ] u
        [z]    [T  0            1] [z]   [0              ]

    ``Q = diag(q_pos, q_vel, q_int)``, ``R = r_vel``; ``K`` and ``P`` come from
    :func:`swarm.core.control.dlqr`. With ``q_int = 0`` the integrator mode is unobservable in the cost, so
    the design drops it (as ``design_translation_lqr`` does) and the integral gain is 0.
    """
    T = control.dt_s
    tau = wheels.motor_time_constant_s
    a = math.exp(-T / tau)
    g = -math.expm1(-T / tau)  # 1 - a
    A = np.array([[1.0, tau * g, 0.0], [0.0, a, 0.0], [T, 0.0, 1.0]])
    B = np.array([[T - tau * g], [g], [0.0]])
    Q = np.diag([control.q_pos, control.q_vel, control.q_int])
    R = np.array([[control.r_vel]])
    n = 3 if control.integral_enabled else 2
    K_n, P_n = dlqr(A[:n, :n], B[:n], Q[:n, :n], R)
    K = np.zeros((1, 3))
    K[:, :n] = K_n
    P = np.zeros((3, 3))
    P[:n, :n] = P_n
    eigs = np.linalg.eigvals(A[:n, :n] - B[:n] @ K_n)
    for arr in (K, A, B, P, eigs):
        arr.setflags(write=False)
    return GroundLqrDesign(K_axis=K, A_d=A, B_d=B, P=P, closed_loop_eigs=eigs)


@dataclass(frozen=True, eq=False)
class GroundCommand:
    """Output of :meth:`GroundController.step`."""

    wheel_rad_s: FloatArray
    """Wheel-speed commands (4,) [rad/s] of wheels 1..4 (front-left, front-right, rear-right, rear-left),
    the actuator command ``u`` of the truth."""
    twist_body: FloatArray
    """The commanded body twist ``(vx [m/s], vy [m/s], wz [rad/s])`` (3,) after both limits:
    ``mecanum_forward(wheel_rad_s)``."""
    accel_body_known: FloatArray
    """The filter's known acceleration (3,) [m/s^2], body frame: the mean acceleration over the next
    control period of the lag response to the commanded body velocity (z = 0)."""
    saturated: bool
    """True when a wheel exceeded ``max_speed_rad_s`` and the four commands were scaled down."""


class GroundController:
    """Discrete LQR with feed-forward and integral action on the lagged velocity plant, a proportional yaw
    law and the mecanum inverse kinematics with saturation.

    Per step, per nav axis x and y (Ogata 1995 ch. 8, integral augmentation)::

        e_p = p - p_ref,  e_v = v - v_ref
        v_cmd = v_ref + tau a_ref - K [e_p, e_v, z]     # feed-forward + LQR feedback
        z  <- clip(z + e_p T, -z_max, z_max)            # integral of the position error, anti-windup

    The feed-forward ``v_ref + tau a_ref`` is the input that makes the lag plant follow the reference
    (``dv_ref/dt = (v_ref + tau a_ref - v_ref) / tau``): a reference generated by the lag plant from a
    held input (a constant velocity, say) is then an exact solution of the sampled closed loop, and the
    feedback only handles errors. The yaw law is ``wz = clip(k_psi wrap(psi_ref - psi), +-wz_max)``.

    The xy command is rotated into the body frame with the estimated yaw, bounded in norm to
    ``max_speed_m_s`` (keeping its direction) and mapped to wheel speeds by ``mecanum_inverse``. If a
    wheel exceeds ``max_speed_rad_s``, all four commands and the twist are scaled by one factor, which keeps
    the direction of motion and the ratio of turning to translating.

    The integral ``z`` (2,) is the only state: :meth:`reset` it when the reference changes mode.
    """

    def __init__(self, control: GroundControlParams, wheels: WheelParams, body: GroundBodyParams):
        """Design the LQR (:func:`design_ground_lqr`) for these tables."""
        for name, obj, cls in (
            ("control", control, GroundControlParams),
            ("wheels", wheels, WheelParams),
            ("body", body, GroundBodyParams),
        ):
            if not isinstance(obj, cls):
                raise ConfigError(f"kinds.ground.{name} must be a {cls.__name__}, got {type(obj).__name__}")
        self.control = control
        self.wheels = wheels
        self.body = body
        self.design = design_ground_lqr(control, wheels)
        self.integral_m_s = np.zeros(2)
        """Integrated position error ``z`` (2,) [m s] along nav x and y."""
        tau = wheels.motor_time_constant_s
        T = control.dt_s
        self._accel_gain = -math.expm1(-T / tau) / T  # (1 - exp(-T/tau)) / T [1/s]

    @property
    def K_axis(self) -> FloatArray:
        """Gain (1, 3) on ``(e_p, e_v, z)`` of one nav axis [1/s, 1, 1/s^2]."""
        return self.design.K_axis

    @property
    def A_d(self) -> FloatArray:
        """Discrete state matrix (3, 3) of one axis."""
        return self.design.A_d

    @property
    def B_d(self) -> FloatArray:
        """Discrete input matrix (3, 1) of one axis."""
        return self.design.B_d

    @property
    def closed_loop_eigs(self) -> FloatArray:
        """Eigenvalues of the closed loop of one axis."""
        return self.design.closed_loop_eigs

    def reset(self) -> None:
        """Zero the integral."""
        self.integral_m_s[:] = 0.0

    def zero_command(self) -> FloatArray:
        """The wheel-speed command (4,) [rad/s] that stops the wheels."""
        return np.zeros(4)

    @property
    def row(self) -> FloatArray:
        """The parameters as the compiled step reads them (:func:`ground_control_row`)."""
        return ground_control_row(self.control, self.wheels, self.design)

    def step(
        self,
        p_nav: ArrayLike,
        v_nav: ArrayLike,
        q_nav_body: ArrayLike,
        p_ref_nav: ArrayLike,
        v_ref_nav: ArrayLike,
        a_ref_nav: ArrayLike | None,
        q_ref_nav_body: ArrayLike,
        translate: bool = True,
        rotate: bool = True,
    ) -> GroundCommand:
        """The command of one control period; advances the integral (the compiled
        :func:`ground_control_step`, which the closed loop calls directly).

        Args:
            p_nav, v_nav: estimated position [m] and velocity [m/s] (3,), frame nav; z is ignored.
            q_nav_body: estimated attitude (4,), scalar-last, body -> nav; only its yaw is used.
            p_ref_nav, v_ref_nav, a_ref_nav: reference position [m], velocity [m/s] and acceleration
                [m/s^2] (3,), frame nav, z ignored; ``a_ref_nav`` None means zero.
            q_ref_nav_body: reference attitude (4,); only its yaw is used.
            translate: False: zero xy command and reset the integral.
            rotate: False: zero yaw rate.
        """
        p = _vec(p_nav, 3, "p_nav")
        v = _vec(v_nav, 3, "v_nav")
        q = _vec(q_nav_body, 4, "q_nav_body")
        p_ref = _vec(p_ref_nav, 3, "p_ref_nav")
        v_ref = _vec(v_ref_nav, 3, "v_ref_nav")
        a_ref = np.zeros(3) if a_ref_nav is None else _vec(a_ref_nav, 3, "a_ref_nav")
        q_ref = _vec(q_ref_nav_body, 4, "q_ref_nav_body")
        wheel, twist, accel = np.empty(4), np.empty(3), np.empty(3)
        saturated = ground_control_step(
            self.integral_m_s, self._row, p, v, q, p_ref, v_ref, a_ref, q_ref, bool(translate), bool(rotate),
            wheel, twist, accel,
        )  # fmt: skip
        return GroundCommand(wheel_rad_s=wheel, twist_body=twist, accel_body_known=accel, saturated=saturated)

    @property
    def _row(self) -> FloatArray:
        row = self.__dict__.get("_row_cache")
        if row is None:
            row = self.__dict__["_row_cache"] = self.row
        return row


# ---- the compiled step: parameter row (CP_*) and kernel ---------------------------------------------------
(CP_TAU, CP_DT, CP_KP, CP_KV, CP_KI, CP_ILIM, CP_YAW_GAIN, CP_MAX_YAW_RATE, CP_MAX_SPEED, CP_RADIUS,
 CP_HALF_LENGTH, CP_HALF_WIDTH, CP_MAX_WHEEL, CP_ACCEL_GAIN) = range(14)  # fmt: skip
CP_N = 14


def ground_control_row(
    control: GroundControlParams, wheels: WheelParams, design: GroundLqrDesign
) -> FloatArray:
    """The controller's parameters (CP_N,) for :func:`ground_control_step`: lag, period, the per-axis gains,
    the integral's limit (-1: no integral action), the yaw law, the speed limits, the wheel geometry and the
    known-acceleration gain ``(1 - exp(-T/tau)) / T``."""
    k_p, k_v, k_i = design.K_axis[0]
    tau, T = wheels.motor_time_constant_s, control.dt_s
    return np.array([
        tau, T, k_p, k_v, k_i, control.integral_limit_m_s if control.integral_enabled else -1.0,
        control.yaw_gain_1_s, control.max_yaw_rate_rad_s, control.max_speed_m_s, wheels.radius_m,
        wheels.half_length_m, wheels.half_width_m, wheels.max_speed_rad_s, -math.expm1(-T / tau) / T,
    ], dtype=np.float64)  # fmt: skip


@numba.njit(cache=True)
def _yaw(x, y, z, w):
    return math.atan2(2.0 * (x * y + z * w), 1.0 - 2.0 * (y * y + z * z))


@numba.njit(cache=True)
def _wrap_nb(angle):
    """``angle`` [rad] wrapped to (-pi, pi] (:func:`_wrap`)."""
    two_pi = 2.0 * math.pi
    a = angle - two_pi * np.rint(angle / two_pi)
    return math.pi if a <= -math.pi else a


@numba.njit(cache=True)
def ground_control_step(z, cp, p, v, q, p_ref, v_ref, a_ref, q_ref, translate, rotate, wheel, twist, accel):
    """One step of :class:`GroundController` (its docstring is the law) on the integral ``z`` (2,) and the
    parameters ``cp`` (:func:`ground_control_row`); writes the wheel commands (4,), the commanded body
    twist (3,) and the known body acceleration (3,); returns whether a wheel saturated."""
    qx, qy, qz, qw = q[0], q[1], q[2], q[3]
    psi = _yaw(qx, qy, qz, qw)
    c0 = 0.0
    c1 = 0.0
    if translate:
        tau = cp[CP_TAU]
        k_p, k_v, k_i = cp[CP_KP], cp[CP_KV], cp[CP_KI]
        e0, e1 = p[0] - p_ref[0], p[1] - p_ref[1]
        c0 = v_ref[0] + tau * a_ref[0] - (k_p * e0 + k_v * (v[0] - v_ref[0]) + k_i * z[0])
        c1 = v_ref[1] + tau * a_ref[1] - (k_p * e1 + k_v * (v[1] - v_ref[1]) + k_i * z[1])
        lim = cp[CP_ILIM]
        if lim >= 0.0:
            z[0] = min(max(z[0] + e0 * cp[CP_DT], -lim), lim)
            z[1] = min(max(z[1] + e1 * cp[CP_DT], -lim), lim)
    else:
        z[0] = 0.0
        z[1] = 0.0
    wz = 0.0
    if rotate:
        err = _wrap_nb(_yaw(q_ref[0], q_ref[1], q_ref[2], q_ref[3]) - psi)
        wz = min(max(cp[CP_YAW_GAIN] * err, -cp[CP_MAX_YAW_RATE]), cp[CP_MAX_YAW_RATE])
    cs, sn = math.cos(psi), math.sin(psi)
    vx = cs * c0 + sn * c1  # R(psi)^T v_cmd_nav
    vy = -sn * c0 + cs * c1
    speed = math.hypot(vx, vy)
    vmax = cp[CP_MAX_SPEED]
    if speed > vmax:
        vx, vy = vx * (vmax / speed), vy * (vmax / speed)
    u1, u2, u3, u4 = _inverse4(vx, vy, wz, cp[CP_RADIUS], cp[CP_HALF_LENGTH], cp[CP_HALF_WIDTH])
    peak = max(max(abs(u1), abs(u2)), max(abs(u3), abs(u4)))
    saturated = peak > cp[CP_MAX_WHEEL]
    if saturated:
        k = cp[CP_MAX_WHEEL] / peak
        u1, u2, u3, u4 = u1 * k, u2 * k, u3 * k, u4 * k
        vx, vy, wz = vx * k, vy * k, wz * k
    wheel[0], wheel[1], wheel[2], wheel[3] = u1, u2, u3, u4
    twist[0], twist[1], twist[2] = vx, vy, wz
    v0x = cs * v[0] + sn * v[1]  # estimated body velocity
    v0y = -sn * v[0] + cs * v[1]
    g = cp[CP_ACCEL_GAIN]
    accel[0], accel[1], accel[2] = (vx - v0x) * g, (vy - v0y) * g, 0.0
    return saturated


def _vec(a: ArrayLike, n: int, name: str) -> FloatArray:
    """``a`` as a float64 (n,), checked for shape and finiteness."""
    v = np.asarray(a, dtype=np.float64)
    if v.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {v!r}")
    return v
