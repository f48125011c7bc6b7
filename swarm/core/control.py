"""Attitude and translation controllers of one TPODS module, or of many at once (paper section IV-B).

Both act on the *estimated* state and run at the controller rate (``TranslationLqrParams.rate_hz``); their
outputs, a force ``F_nav`` [N] in the navigation frame and a torque ``tau_body`` [N m] in the body frame,
go to the thruster allocator, which maps them to nozzle thrusts and saturates.

* Attitude: quaternion feedback (Wie & Barba 1985, "Quaternion feedback for spacecraft large angle
  maneuvers", JGCD 8(3); Wie, "Space Vehicle Dynamics and Control", 2nd ed., sec. 7.3), acting on the
  quaternion error directly: no Euler angles and no other attitude parameters anywhere (paper IV-B).
* Translation: a discrete, steady-state LQR with feed-forward and integral action (Ogata, "Discrete-time
  Control Systems", 2nd ed., 1995, ch. 8) on the plant of paper eq. (1) linearised about a stationary point.
  At rest (``w = 0``, ``dw/dt = 0``) the lever-arm terms of eq. (1) vanish, and in the navigation frame
  (inertial for our purposes, no gravity) the centre of mass obeys ``m d2p/dt2 = F_nav``: per axis a double
  integrator, the same on all three axes, so one scalar-input design serves every axis.

Quaternions are scalar-last ``(x, y, z, w)`` with the Hamilton product, like ``scipy.spatial.transform``;
``q_nav_body`` maps body vectors into the navigation frame. Every function broadcasts over leading batch
axes; :class:`TranslationController` holds one integrator per vehicle of a batch of ``n``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numba
import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from swarm.core._rot_nb import qconj, qmul
from swarm.core.rotations import as_last, cross, quat_conj, quat_mul
from swarm.errors import ConfigError

__all__ = [
    "AttitudeControlParams",
    "LqrDesign",
    "TranslationController",
    "TranslationLqrParams",
    "attitude_torque",
    "design_translation_lqr",
    "dlqr",
    "saturate_norm",
]

FloatArray = NDArray[np.float64]


def _check(section: str, obj: object, positive: tuple[str, ...], nonneg: tuple[str, ...] = ()) -> None:
    """Raise ConfigError naming ``<section>.<field>`` for a field that is not finite and > 0 (>= 0)."""
    for name in positive:
        v = getattr(obj, name)
        if not (isinstance(v, int | float | np.floating | np.integer) and np.isfinite(v) and v > 0):
            raise ConfigError(f"{section}.{name} must be a positive finite number, got {v!r}")
    for name in nonneg:
        v = getattr(obj, name)
        if not (isinstance(v, int | float | np.floating | np.integer) and np.isfinite(v) and v >= 0):
            raise ConfigError(f"{section}.{name} must be a non-negative finite number, got {v!r}")


def saturate_norm(x: ArrayLike, limit: float) -> FloatArray:
    """``x`` scaled down, where its Euclidean norm over the last axis exceeds ``limit``, to that norm.

    Scaling the whole vector (rather than clipping each component) keeps its direction: an eigenaxis
    rotation stays an eigenaxis rotation and a force keeps pointing along the error (Wie 2008, sec. 7.3).
    """
    x = np.asarray(x, dtype=np.float64)
    n = np.linalg.norm(x, axis=-1, keepdims=True)
    return x * np.minimum(1.0, limit / np.maximum(n, np.finfo(float).tiny))


# ---------------------------------------------------------------------------------------------- attitude


@dataclass(frozen=True)
class AttitudeControlParams:
    """Gains of the quaternion-feedback attitude law (:func:`attitude_torque`).

    Linearised about zero error, ``q_e,vec ~ dtheta / 2``, so one axis obeys
    ``I d2(dtheta)/dt2 = -(kp / 2) dtheta - kd d(dtheta)/dt``: natural frequency ``wn = sqrt(kp / (2 I))``
    and damping ``zeta = kd / (2 I wn)``, i.e. ``kp = 2 I wn^2`` and ``kd = 2 zeta wn I`` (Wie & Barba 1985;
    Wie 2008 sec. 7.3). The defaults are :meth:`from_bandwidth` ``(wn = 0.5 rad/s, zeta = 0.9,
    I = 0.002 kg m^2)``: a 90-degree turn of the 10 cm, 1.2 kg cube settles within 1 deg in ~10.5 s
    (170 deg: ~12.5 s), peaking at ``kp sin(45 deg)`` ~0.7 mN m: slow and smooth, as proximity
    operations want.
    """

    kp_nm: float = 0.001
    """Proportional gain on the vector part of the quaternion error [N m] (2 I wn^2)."""
    kd_nms: float = 0.0018
    """Rate gain on ``w - w_ref`` [N m s] (2 zeta wn I)."""
    max_torque_nm: float = 0.002
    """Norm bound on the commanded torque [N m]; above it the torque is scaled down, keeping its axis.
    Well inside one nozzle's authority (0.1 N at a ~5 cm arm is ~5 mN m), leaving thrust for translation."""

    def __post_init__(self) -> None:
        _check("attitude_control", self, ("kp_nm", "kd_nms", "max_torque_nm"))

    @classmethod
    def from_bandwidth(
        cls, wn_rad_s: float, zeta: float, inertia_kg_m2: float, max_torque_nm: float = 0.002
    ) -> AttitudeControlParams:
        """Gains for natural frequency ``wn_rad_s`` [rad/s] and damping ratio ``zeta`` of the small-angle
        loop of a body with moment of inertia ``inertia_kg_m2`` [kg m^2]: ``kp = 2 I wn^2``,
        ``kd = 2 zeta wn I`` (class docstring)."""
        return cls(
            kp_nm=2.0 * inertia_kg_m2 * wn_rad_s**2,
            kd_nms=2.0 * zeta * wn_rad_s * inertia_kg_m2,
            max_torque_nm=max_torque_nm,
        )


def attitude_torque(
    q_nav_body: ArrayLike,
    w_body: ArrayLike,
    q_ref_nav_body: ArrayLike,
    w_ref_body: ArrayLike | None,
    inertia_diag: ArrayLike,
    params: AttitudeControlParams,
) -> FloatArray:
    """Quaternion-feedback torque ``tau_body`` [N m], body frame, shape ``(..., 3)``.

    ``q_e = q_ref^-1 (x) q`` is the body-frame error (``q = q_ref (x) q_e``, as in
    ``rotations.attitude_error``) and

        ``tau = -kp sgn(q_e,w) q_e,vec - kd (w - w_ref) + w x (I w)``,

    scaled down to ``params.max_torque_nm`` in norm. Wie & Barba 1985 (quaternion feedback with
    gyroscopic decoupling; Wie 2008 sec. 7.3): the ``w x I w`` term cancels the gyroscopic
    coupling of Euler's equation ``I dw/dt + w x I w = tau`` (paper eq. 2), so the loop is the linear
    ``I dw/dt = -kp sgn(q_e,w) q_e,vec - kd (w - w_ref)``. ``q_e`` and ``-q_e`` are the same rotation;
    ``sgn(q_e,w)`` (taken +1 at exactly 180 deg) makes the law act on the representative with
    ``q_e,w >= 0``, i.e. turn the short way round, and makes the torque the same for ``q_ref`` and
    ``-q_ref``.

    Args:
        q_nav_body: estimated attitude, unit quaternion (..., 4), scalar-last, body -> mothership.
        w_body: estimated body rate (..., 3) [rad/s], body frame.
        q_ref_nav_body: reference attitude, unit quaternion (..., 4), body -> mothership.
        w_ref_body: reference rate (..., 3) [rad/s] expressed in the current body frame, or None for
            zero (a regulator). No angular-acceleration feed-forward is applied.
        inertia_diag: principal moments of inertia (3,) or (..., 3) [kg m^2], body axes.
        params: gains and torque bound.
    """
    if (
        _single3(w_body, inertia_diag)
        and _single4(q_nav_body, q_ref_nav_body)
        and (w_ref_body is None or _single3(w_ref_body))
        and inertia_diag[0] > 0
        and inertia_diag[1] > 0
        and inertia_diag[2] > 0
    ):
        w_ref = _ZERO3 if w_ref_body is None else w_ref_body
        return _attitude_torque1(q_nav_body, w_body, q_ref_nav_body, w_ref, inertia_diag, params.kp_nm,
                                 params.kd_nms, params.max_torque_nm)  # fmt: skip
    q = as_last(q_nav_body, 4, "q_nav_body")
    w = as_last(w_body, 3, "w_body")
    q_ref = as_last(q_ref_nav_body, 4, "q_ref_nav_body")
    w_ref = np.zeros(3) if w_ref_body is None else as_last(w_ref_body, 3, "w_ref_body")
    inertia = as_last(inertia_diag, 3, "inertia_diag")
    if not np.all(inertia > 0):
        raise ValueError(f"inertia_diag must be positive, got {inertia}")
    q_e = quat_mul(quat_conj(q_ref), q)
    sign = np.where(q_e[..., 3:] < 0.0, -1.0, 1.0)
    Iw = inertia * w
    gyro = cross(w, Iw)  # written out: np.cross costs ~15 us on 3-vectors
    tau = -params.kp_nm * sign * q_e[..., :3] - params.kd_nms * (w - w_ref) + gyro
    return saturate_norm(tau, params.max_torque_nm)


# ------------------------------------------------------------------------------------------- translation


@dataclass(frozen=True)
class TranslationLqrParams:
    """Weights and limits of the discrete translation LQR (:func:`design_translation_lqr`).

    The cost is ``sum_k x_k^T Q x_k + R u_k^2`` per axis with ``x = (p - p_ref, v - v_ref, integral of
    p - p_ref)`` and ``u`` the feedback force, ``Q = diag(q_pos, q_vel, q_int)``, ``R = r_force``. For a
    1.2 kg module at 10 Hz the defaults give ``K = (0.375 N/m, 0.988 N s/m, 0.061 N/(m s))``, closed-loop
    poles ``|z| = 0.976, 0.976, 0.965`` (s-plane: wn 0.38 rad/s, zeta 0.63, and a real pole at 0.36 rad/s),
    and settle a 0.1 m step within 2 mm in ~12 s with a peak force of ~38 mN: slow, smooth proximity
    operations with margin below ``max_force_n``.

    A step makes the integral wind up while the error is large; since the integrator settles back to the
    same value, the error must later overshoot by the same area. ``integral_limit_m_s`` bounds that area,
    so it trades the step overshoot (~8 % with the defaults) against the largest constant force the
    integral can cancel, ``K_i * integral_limit_m_s`` (~1.8 mN with the defaults). References shaped by
    guidance, with feed-forward, keep the error and hence the windup small.
    """

    rate_hz: float = 10.0
    """Controller rate [Hz]; the LQR is designed for the zero-order hold at this rate."""
    q_pos: float = 1.0
    """State weight on the position error [1/m^2]; must be > 0 (detectability of the integrator)."""
    q_vel: float = 5.0
    """State weight on the velocity error [s^2/m^2]."""
    q_int: float = 0.2
    """State weight on the integral of the position error [1/(m s)^2]; 0 disables integral action."""
    r_force: float = 50.0
    """Input weight on the feedback force [1/N^2]."""
    max_force_n: float = 0.1
    """Norm bound on the commanded force [N]; above it the force is scaled down, keeping its direction."""
    integral_limit_m_s: float = 0.03
    """Anti-windup clamp on each axis of the integrated position error [m s]."""

    def __post_init__(self) -> None:
        _check(
            "translation_control",
            self,
            ("rate_hz", "q_pos", "r_force", "max_force_n", "integral_limit_m_s"),
            ("q_vel", "q_int"),
        )

    @property
    def dt_s(self) -> float:
        """Controller period [s]."""
        return 1.0 / self.rate_hz

    @property
    def integral_enabled(self) -> bool:
        """True unless ``q_int == 0``."""
        return self.q_int > 0.0


@dataclass(frozen=True, eq=False)
class LqrDesign:
    """A per-axis discrete LQR design, the same on the three axes (read-only arrays).

    The per-axis state is ``(p - p_ref [m], v - v_ref [m/s], integral of p - p_ref [m s])``.
    """

    K_axis: FloatArray
    """Gain (1, 3): ``u = -K_axis x`` [N/m, N s/m, N/(m s)]; the integral gain is 0 when disabled."""
    A_d: FloatArray
    """Discrete state matrix (3, 3) of the augmented per-axis plant."""
    B_d: FloatArray
    """Discrete input matrix (3, 1) [per N]."""
    P: FloatArray
    """Riccati solution (3, 3) (zero row/column for the integral when it is disabled)."""
    closed_loop_eigs: FloatArray
    """Eigenvalues of the closed loop ``A_d - B_d K_axis`` of the designed plant (3,) or (2,) complex."""

    @property
    def K(self) -> FloatArray:
        """Full gain (3, 9) on ``(dp_nav(3), dv_nav(3), integral_nav(3))``: ``F_fb = -K x``."""
        return np.kron(self.K_axis, np.eye(3))


def dlqr(A: ArrayLike, B: ArrayLike, Q: ArrayLike, R: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Steady-state discrete LQR: gain ``K`` and Riccati solution ``P`` for ``x+ = A x + B u``.

    Minimises ``sum x^T Q x + u^T R u`` with ``u = -K x``, ``K = (R + B^T P B)^-1 B^T P A`` and ``P`` the
    stabilising solution of ``P = A^T P A - A^T P B (R + B^T P B)^-1 B^T P A + Q`` (Ogata 1995 ch. 8,
    steady-state quadratic optimal control), from ``scipy.linalg.solve_discrete_are``.
    """
    A = np.atleast_2d(np.asarray(A, dtype=np.float64))
    B = np.atleast_2d(np.asarray(B, dtype=np.float64))
    Q = np.atleast_2d(np.asarray(Q, dtype=np.float64))
    R = np.atleast_2d(np.asarray(R, dtype=np.float64))
    P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    return K, P


def _readonly(*arrays: FloatArray) -> None:
    for a in arrays:
        a.setflags(write=False)


@functools.lru_cache(maxsize=64)  # a pure function of frozen parameters; its arrays are read-only
def design_translation_lqr(mass_kg: float, params: TranslationLqrParams) -> LqrDesign:
    """Per-axis LQR for the translation of a module of mass ``mass_kg`` [kg] (module docstring).

    The zero-order-hold discretisation of the double integrator ``m d2p/dt2 = u`` over ``T = dt_s``,
    augmented with the integral ``z`` of the position error (forward rectangle, as the controller
    accumulates it), is (Ogata 1995 ch. 8; ``tests/core/test_control.py`` checks the ZOH against
    ``scipy.signal.cont2discrete``)::

        [p]+   [1  T  0] [p]   [T^2 / (2m)]
        [v]  = [0  1  0] [v] + [T / m     ] u
        [z]    [T  0  1] [z]   [0         ]

    ``K`` and ``P`` come from :func:`dlqr`. With ``q_int = 0`` the integrator mode is unobservable in the
    cost (its eigenvalue 1 would stay put), so the design drops it: ``K`` is the 2-state ``(p, v)`` LQR and
    the integral gain is 0.
    """
    if not (np.isfinite(mass_kg) and mass_kg > 0):
        raise ConfigError(f"mass_kg must be a positive finite number, got {mass_kg!r}")
    T = params.dt_s
    A = np.array([[1.0, T, 0.0], [0.0, 1.0, 0.0], [T, 0.0, 1.0]])
    B = np.array([[0.5 * T * T / mass_kg], [T / mass_kg], [0.0]])
    Q = np.diag([params.q_pos, params.q_vel, params.q_int])
    R = np.array([[params.r_force]])
    n = 3 if params.integral_enabled else 2
    K_n, P_n = dlqr(A[:n, :n], B[:n], Q[:n, :n], R)
    K = np.zeros((1, 3))
    K[:, :n] = K_n
    P = np.zeros((3, 3))
    P[:n, :n] = P_n
    eigs = np.linalg.eigvals(A[:n, :n] - B[:n] @ K_n)
    _readonly(K, A, B, P, eigs)
    return LqrDesign(K_axis=K, A_d=A, B_d=B, P=P, closed_loop_eigs=eigs)


class TranslationController:
    """Discrete LQR translation control with feed-forward and integral action (paper IV-B).

    Per step, for every vehicle ``i`` of the batch (Ogata 1995 ch. 8, integral augmentation)::

        e_p = p - p_ref,  e_v = v - v_ref
        F   = sat(m a_ref - K [e_p, e_v, z])           # feed-forward m a_ref + LQR feedback
        z  <- clip(z + e_p T, -z_max, z_max)           # integral of the position error, anti-windup

    ``sat`` scales ``F`` down to ``max_force_n`` in norm. The feed-forward makes a reference that obeys
    the double integrator (``d2 p_ref / dt2 = a_ref``) an exact solution of the closed loop, so the
    feedback only handles errors; the integral ``z`` rejects constant unmeasured forces (paper IV-B and its
    ref. [27], Dorato, Fortuna & Muscato 1992). ``z`` is the only state: :meth:`reset` it when the
    guidance mode (and with it the reference) changes.
    """

    def __init__(self, mass_kg: float, params: TranslationLqrParams | None = None, n: int | None = None):
        """``mass_kg`` [kg]; ``n`` vehicles sharing the design (``None``: one vehicle, arrays (3,))."""
        self.params = TranslationLqrParams() if params is None else params
        self.mass_kg = float(mass_kg)
        self.design = design_translation_lqr(self.mass_kg, self.params)
        if n is not None and (int(n) != n or n < 1):
            raise ValueError(f"n must be a positive integer or None, got {n!r}")
        self._shape = (3,) if n is None else (int(n), 3)
        self.integral_m_s = np.zeros(self._shape)
        """Integrated position error ``z`` (3,) or (n, 3) [m s], navigation frame."""

    def reset(self, mask: ArrayLike | None = None) -> None:
        """Zero the integrator of every vehicle, or of those where the boolean ``mask`` (n,) is True."""
        if mask is None:
            self.integral_m_s[...] = 0.0
        else:
            self.integral_m_s[np.asarray(mask, dtype=bool)] = 0.0

    def step(
        self,
        p_nav: ArrayLike,
        v_nav: ArrayLike,
        p_ref_nav: ArrayLike,
        v_ref_nav: ArrayLike,
        a_ref_nav: ArrayLike | None = None,
    ) -> FloatArray:
        """Force command ``F_nav`` [N], mothership frame, shape (3,) or (n, 3); advances the integrator.

        Args:
            p_nav, v_nav: estimated centre-of-mass position [m] and velocity [m/s], frame nav.
            p_ref_nav, v_ref_nav: reference position [m] and velocity [m/s], frame nav.
            a_ref_nav: reference acceleration [m/s^2], frame nav, for the feed-forward (None: zero).
        Inputs broadcast against the controller's batch shape.
        """
        if (
            self._shape == (3,)
            and _single3(p_nav, v_nav, p_ref_nav, v_ref_nav)
            and (a_ref_nav is None or _single3(a_ref_nav))
        ):
            k_p, k_v, k_i = self.design.K_axis[0]
            a_ref = _ZERO3 if a_ref_nav is None else a_ref_nav
            lim = self.params.integral_limit_m_s if self.params.integral_enabled else -1.0
            return _lqr_step1(
                p_nav, v_nav, p_ref_nav, v_ref_nav, a_ref, self.integral_m_s, self.mass_kg, k_p, k_v, k_i,
                self.params.dt_s, lim, self.params.max_force_n,
            )  # fmt: skip
        e_p = np.broadcast_to(as_last(p_nav, 3, "p_nav") - as_last(p_ref_nav, 3, "p_ref_nav"), self._shape)
        e_v = np.broadcast_to(as_last(v_nav, 3, "v_nav") - as_last(v_ref_nav, 3, "v_ref_nav"), self._shape)
        a_ref = np.zeros(3) if a_ref_nav is None else as_last(a_ref_nav, 3, "a_ref_nav")
        k_p, k_v, k_i = self.design.K_axis[0]
        F = self.mass_kg * a_ref - (k_p * e_p + k_v * e_v + k_i * self.integral_m_s)
        if self.params.integral_enabled:
            lim = self.params.integral_limit_m_s
            self.integral_m_s = np.clip(self.integral_m_s + e_p * self.params.dt_s, -lim, lim)
        return saturate_norm(F, self.params.max_force_n)


# ---- compiled single-vehicle paths (the same arithmetic as above, without numpy's per-call overhead) ----
_ZERO3 = np.zeros(3)


def _single3(*arrays) -> bool:
    return all(type(a) is np.ndarray and a.shape == (3,) and a.dtype == np.float64 for a in arrays)


def _single4(*arrays) -> bool:
    return all(type(a) is np.ndarray and a.shape == (4,) and a.dtype == np.float64 for a in arrays)


@numba.njit(cache=True)
def _saturate1(x, limit):
    n = np.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
    if n > limit:
        s = limit / n
        for i in range(3):
            x[i] *= s
    return x


@numba.njit(cache=True)
def _attitude_torque1(q, w, q_ref, w_ref, inertia, kp, kd, max_torque):
    """:func:`attitude_torque` for one vehicle (same law and saturation)."""
    q_e = qmul(qconj(q_ref), q)
    sign = -1.0 if q_e[3] < 0.0 else 1.0
    tau = np.empty(3)
    iw0, iw1, iw2 = inertia[0] * w[0], inertia[1] * w[1], inertia[2] * w[2]
    gyro = (w[1] * iw2 - w[2] * iw1, w[2] * iw0 - w[0] * iw2, w[0] * iw1 - w[1] * iw0)
    for i in range(3):
        tau[i] = -kp * sign * q_e[i] - kd * (w[i] - w_ref[i]) + gyro[i]
    return _saturate1(tau, max_torque)


@numba.njit(cache=True)
def _lqr_step1(p, v, p_ref, v_ref, a_ref, z, mass, k_p, k_v, k_i, dt, lim, max_force):
    """:meth:`TranslationController.step` for one vehicle: ``F = sat(m a_ref - K [e_p, e_v, z])`` and
    the clamped integral update (``lim < 0``: integral action off)."""
    F = np.empty(3)
    for i in range(3):
        e_p = p[i] - p_ref[i]
        e_v = v[i] - v_ref[i]
        F[i] = mass * a_ref[i] - (k_p * e_p + k_v * e_v + k_i * z[i])
        if lim >= 0.0:
            z[i] = min(max(z[i] + e_p * dt, -lim), lim)
    return _saturate1(F, max_force)
