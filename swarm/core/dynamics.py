"""6-DOF rigid-body truth dynamics of one TPODS module in the navigation frame (paper eqs. 1-2).

State (13,): ``x = [p_nav(3), v_nav(3), q_nav_body(4), w_body(3)]``: centre-of-mass position [m] and velocity
[m/s] in the navigation frame ``nav`` (the paper's mothership frame ``c``, stationary and inertial for our
purposes), the attitude quaternion mapping body vectors into ``nav`` (scalar-last ``(x, y, z, w)``,
Hamilton product, like ``scipy.spatial.transform.Rotation``) and the body angular rate relative to
``nav``, in the body frame [rad/s]. Inputs are the thrust force ``F_body`` [N] and the torque about the
centre of mass ``tau_body`` [N m], both in the body frame: cold-gas nozzles are fixed to the body, so their
force turns with it.

Equations of motion (``R = R(q_nav_body)``, ``I = diag(inertia_diag)`` the principal inertia):

* translation: ``m dv_nav/dt = R F_body``, ``dp_nav/dt = v_nav`` (Newton's second law for the centre of mass);
* rotation: Euler's equation in the body frame, ``I dw_body/dt = tau_body - w_body x I w_body``
  (Schaub & Junkins, *Analytical Mechanics of Space Systems*, ch. 4). Paper eq. (2) writes the same law in
  the mothership frame: ``I_0 w_dot = I_0 D I_1^-1 [N_1 - D^T w x I_1 D^T w]``, with ``D = R`` the
  body -> nav rotation, ``w = D w_body`` and ``N_1 = tau_body``; ``I_0`` cancels and ``D^T w_dot_nav`` is
  our ``dw_body/dt`` (the two frames' derivatives of ``w`` agree because ``w x w = 0``);
* attitude kinematics: ``dq/dt = 1/2 q (x) [w_body, 0]`` (Sola 2017, "Quaternion kinematics for the
  error-state Kalman filter", time derivative with local rates).

The UWB tag sits at ``P1`` in the body frame, off the centre of mass, so its motion couples rotation and
translation: :func:`tag_position` and :func:`tag_acceleration` (paper eq. 1).

Integration is classical fourth-order Runge-Kutta (Hairer, Norsett & Wanner, *Solving ODEs I*, sec. II.1)
over ``ceil(dt / h_max)`` equal sub-steps, renormalising ``q`` after each sub-step. With the default
1 ms sub-step a torque-free asymmetric spin at ~1 rad/s conserves rotational energy and the inertial
angular momentum to ~1e-13 relative over 100 s (``tests/core/test_dynamics.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from swarm.core.rotations import quat_rotate
from swarm.errors import ConfigError

__all__ = [
    "STATE_DIM",
    "RigidBodyParams",
    "derivative",
    "propagate",
    "step",
    "tag_acceleration",
    "tag_position",
]

STATE_DIM = 13
"""Length of the truth state ``[p_nav(3), v_nav(3), q_nav_body(4), w_body(3)]``."""

FloatArray = NDArray[np.float64]

_DEFAULT_MASS_KG = 1.2
_DEFAULT_SIDE_M = 0.10
# Solid cube of side s: I = m s^2 / 6 about each principal axis through the centre.
_DEFAULT_INERTIA_KGM2 = _DEFAULT_MASS_KG * _DEFAULT_SIDE_M**2 / 6.0


@dataclass(frozen=True)
class RigidBodyParams:
    """Mass properties of one TPODS module and the truth integrator's step."""

    mass_kg: float = _DEFAULT_MASS_KG
    """Total mass [kg]; default a 10 cm TPODS cube of 1.2 kg."""
    inertia_diag_kgm2: tuple[float, float, float] = (
        _DEFAULT_INERTIA_KGM2,
        _DEFAULT_INERTIA_KGM2,
        _DEFAULT_INERTIA_KGM2,
    )
    """Principal moments of inertia about the body axes through the centre of mass [kg m^2]; default the
    solid 10 cm cube, ``m s^2 / 6 = 0.002`` each. A scenario may make them slightly unequal."""
    integration_step_s: float = 0.01
    """Largest RK4 sub-step [s]; :func:`propagate` splits each call into equal sub-steps no longer."""

    def __post_init__(self) -> None:
        for name in ("mass_kg", "integration_step_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v > 0):
                raise ConfigError(f"rigid_body.{name} must be a positive finite number, got {v!r}")
        inertia = np.asarray(self.inertia_diag_kgm2, dtype=float)
        if inertia.shape != (3,) or not np.all(np.isfinite(inertia)) or not np.all(inertia > 0):
            raise ConfigError(
                "rigid_body.inertia_diag_kgm2 must be 3 positive finite numbers, "
                f"got {self.inertia_diag_kgm2!r}"
            )
        # A real mass distribution has I_i <= I_j + I_k (equality for a flat plate); allow rounding.
        total = float(np.sum(inertia))
        if np.any(2.0 * inertia > total * (1.0 + 1e-12)):
            raise ConfigError(
                "rigid_body.inertia_diag_kgm2 must satisfy the triangle inequality I_i <= I_j + I_k, "
                f"got {self.inertia_diag_kgm2!r}"
            )
        object.__setattr__(self, "inertia_diag_kgm2", tuple(float(v) for v in inertia))

    @property
    def inertia_diag(self) -> FloatArray:
        """Principal moments as a fresh float64 array (3,) [kg m^2]."""
        return np.array(self.inertia_diag_kgm2, dtype=np.float64)


@numba.njit(cache=True)
def _derivative_into(
    x: np.ndarray,
    F_body: np.ndarray,
    tau_body: np.ndarray,
    mass: float,
    inertia_diag: np.ndarray,
    out: np.ndarray,
) -> None:
    """Write the derivative of ``x`` into ``out`` (13,); scalar arithmetic, no allocation (hot path)."""
    qx, qy, qz, qw = x[6], x[7], x[8], x[9]
    wx, wy, wz = x[10], x[11], x[12]
    # R(q) F_body, R scaled by 2 / |q|^2 so it is a rotation for any q != 0 (as _rot_nb.qrotate).
    s = 2.0 / (qx * qx + qy * qy + qz * qz + qw * qw)
    fx, fy, fz = F_body[0], F_body[1], F_body[2]
    cx = qy * fz - qz * fy  # c = u x F, d = u x c, u = (qx, qy, qz)
    cy = qz * fx - qx * fz
    cz = qx * fy - qy * fx
    dx = qy * cz - qz * cy
    dy = qz * cx - qx * cz
    dz = qx * cy - qy * cx
    out[0] = x[3]
    out[1] = x[4]
    out[2] = x[5]
    out[3] = (fx + s * (qw * cx + dx)) / mass
    out[4] = (fy + s * (qw * cy + dy)) / mass
    out[5] = (fz + s * (qw * cz + dz)) / mass
    # 1/2 q (x) [w, 0] (Hamilton product written out, as _rot_nb.qmul with a zero scalar part)
    out[6] = 0.5 * (qw * wx + (qy * wz - qz * wy))
    out[7] = 0.5 * (qw * wy + (qz * wx - qx * wz))
    out[8] = 0.5 * (qw * wz + (qx * wy - qy * wx))
    out[9] = -0.5 * (qx * wx + qy * wy + qz * wz)
    # Euler: I w_dot = tau - w x (I w)
    Iw0 = inertia_diag[0] * wx
    Iw1 = inertia_diag[1] * wy
    Iw2 = inertia_diag[2] * wz
    out[10] = (tau_body[0] - (wy * Iw2 - wz * Iw1)) / inertia_diag[0]
    out[11] = (tau_body[1] - (wz * Iw0 - wx * Iw2)) / inertia_diag[1]
    out[12] = (tau_body[2] - (wx * Iw1 - wy * Iw0)) / inertia_diag[2]


@numba.njit(cache=True)
def derivative(
    x: np.ndarray, F_body: np.ndarray, tau_body: np.ndarray, mass: float, inertia_diag: np.ndarray
) -> np.ndarray:
    """Time derivative (13,) of the state ``x`` (13,) under body force ``F_body`` [N] and torque
    ``tau_body`` [N m] (both (3,), body frame), ``mass`` [kg], principal inertia ``inertia_diag`` (3,)
    [kg m^2]. Layout ``[v_nav, a_nav, q_dot, w_dot_body]``; the equations are in the module docstring.

    ``q`` need not be unit: ``R`` is scaled by ``2 / |q|^2``, so it is a rotation for any ``q != 0``.
    """
    out = np.empty(STATE_DIM)
    _derivative_into(x, F_body, tau_body, mass, inertia_diag, out)
    return out


@numba.njit(cache=True)
def propagate(
    x: np.ndarray,
    F_body: np.ndarray,
    tau_body: np.ndarray,
    dt: float,
    mass: float,
    inertia_diag: np.ndarray,
    h_max: float,
) -> np.ndarray:
    """State (13,) after ``dt`` [s] from ``x`` (13,), force ``F_body`` [N] and torque ``tau_body`` [N m]
    held constant in the body frame (zero-order hold of the thruster command, turning with the body).

    Classical RK4 over ``n = ceil(dt / h_max)`` (to 1e-9) equal sub-steps of ``dt / n``, ``h_max`` [s]
    > 0, with ``q`` renormalised after each sub-step. ``mass`` [kg], ``inertia_diag`` (3,) [kg m^2].
    ``dt == 0`` returns a copy. Inputs are float64 arrays, unchecked (:func:`step` is the checked wrapper).
    """
    if dt < 0.0 or not h_max > 0.0:
        raise ValueError("propagate: dt must be >= 0 and h_max > 0")
    y = x.copy()
    if dt == 0.0:
        return y
    # The 1e-9 slack keeps rounding (0.07 / 0.001 = 70.00000000000001) from adding a sub-step.
    n = max(1, math.ceil(dt / h_max - 1e-9))
    h = dt / n
    k1 = np.empty(STATE_DIM)
    k2 = np.empty(STATE_DIM)
    k3 = np.empty(STATE_DIM)
    k4 = np.empty(STATE_DIM)
    tmp = np.empty(STATE_DIM)
    for _ in range(n):
        _derivative_into(y, F_body, tau_body, mass, inertia_diag, k1)
        for i in range(STATE_DIM):
            tmp[i] = y[i] + 0.5 * h * k1[i]
        _derivative_into(tmp, F_body, tau_body, mass, inertia_diag, k2)
        for i in range(STATE_DIM):
            tmp[i] = y[i] + 0.5 * h * k2[i]
        _derivative_into(tmp, F_body, tau_body, mass, inertia_diag, k3)
        for i in range(STATE_DIM):
            tmp[i] = y[i] + h * k3[i]
        _derivative_into(tmp, F_body, tau_body, mass, inertia_diag, k4)
        for i in range(STATE_DIM):
            y[i] += (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        qn = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
        for i in range(6, 10):
            y[i] /= qn
    return y


def _vec(a: ArrayLike, n: int, name: str) -> FloatArray:
    """``a`` as a fresh contiguous float64 (n,), checked for shape and finiteness."""
    v = np.array(a, dtype=np.float64)
    if v.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {v!r}")
    return v


def step(
    x: ArrayLike, F_body: ArrayLike, tau_body: ArrayLike, dt_s: float, params: RigidBodyParams
) -> FloatArray:
    """Checked wrapper of :func:`propagate`: state (13,) after ``dt_s`` [s] >= 0.

    ``x`` (13,) ``[p_nav, v_nav, q_nav_body, w_body]`` (``q`` must be unit to 1e-6), ``F_body`` (3,) [N] and
    ``tau_body`` (3,) [N m] in the body frame, held constant over ``dt_s``. Raises ``ValueError`` on bad
    shapes, non-finite values, a non-unit quaternion or a negative step.
    """
    xv = _vec(x, STATE_DIM, "x")
    if abs(np.linalg.norm(xv[6:10]) - 1.0) > 1e-6:
        raise ValueError(f"x[6:10] must be a unit quaternion, got {xv[6:10]!r}")
    F = _vec(F_body, 3, "F_body")
    tau = _vec(tau_body, 3, "tau_body")
    dt = float(dt_s)
    if not (math.isfinite(dt) and dt >= 0.0):
        raise ValueError(f"dt_s must be a non-negative finite number, got {dt_s!r}")
    return propagate(xv, F, tau, dt, float(params.mass_kg), params.inertia_diag, params.integration_step_s)


def tag_position(x: ArrayLike, lever_body: ArrayLike) -> FloatArray:
    """Position of a body-fixed point (the UWB tag) in ``nav`` [m], shape ``(..., 3)``.

    ``p_tag = p_nav + R(q_nav_body) P1`` (paper sec. II and Fig. 2: ``rho_ij = rho + D P1``). ``x`` is
    ``(..., 13)`` states, ``lever_body`` the point ``P1`` (3,) in the body frame [m] (paper: (0.05, 0.05, 0)).
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 0 or x.shape[-1] != STATE_DIM:
        raise ValueError(f"x must have shape (..., {STATE_DIM}), got {x.shape}")
    lever = _vec(lever_body, 3, "lever_body")
    return x[..., 0:3] + quat_rotate(x[..., 6:10], lever)


def tag_acceleration(
    x: ArrayLike, wdot_body: ArrayLike, a_nav: ArrayLike, lever_body: ArrayLike
) -> FloatArray:
    """Inertial acceleration of the body-fixed point ``P1`` in ``nav`` [m/s^2], shape (3,) (paper eq. 1).

    ``a_tag = a_nav + R(q) (w_dot x P1 + w x (w x P1))`` with ``w = w_body`` from ``x`` (13,) [rad/s],
    ``wdot_body`` (3,) its time derivative [rad/s^2] (body frame), ``a_nav`` (3,) the centre-of-mass
    acceleration in ``nav`` [m/s^2] and ``lever_body`` (3,) [m]. Paper eq. (1) writes the bracket with the
    vectors in ``c``; rotating it into the body frame, where ``P1`` is constant, gives this form.
    """
    xv = _vec(x, STATE_DIM, "x")
    wdot = _vec(wdot_body, 3, "wdot_body")
    a = _vec(a_nav, 3, "a_nav")
    lever = _vec(lever_body, 3, "lever_body")
    w = xv[10:13]
    rel_body = np.cross(wdot, lever) + np.cross(w, np.cross(w, lever))
    return a + quat_rotate(xv[6:10], rel_body)
