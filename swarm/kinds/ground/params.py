"""Parameter tables of the ``ground`` kind: ``[kinds.ground.body]``, ``wheels``, ``control``, ``dispersions``.

The vehicle is the TPODS MK-E module on a table (paper section VI-A): a 10 cm cube on four 48 mm mecanum
wheels driven by N-20 gear motors. Every table is a frozen dataclass validated in ``__post_init__``; an
error names the full field and quotes the value (``kinds.ground.wheels.radius_m must be a positive number,
got -1.0``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarm.errors import ConfigError

__all__ = [
    "MAX_SLIP_SIGMA_FRAC",
    "MIN_TRACTION",
    "GroundBodyParams",
    "GroundControlParams",
    "GroundDispersionParams",
    "WheelParams",
    "slip_factors",
]

MAX_SLIP_SIGMA_FRAC = 0.2
"""Largest allowed ``wheel_slip_sigma_frac``."""

MIN_TRACTION = 0.05
"""Floor of a traction factor. A normal draw with ``|e| >= 0.95`` (4.75 sigma at the largest sigma, ~2e-6
per wheel) would otherwise leave a wheel with no or negative traction, which no real wheel has."""


def _is_real(v: object) -> bool:
    return (
        isinstance(v, int | float | np.floating | np.integer) and not isinstance(v, bool) and math.isfinite(v)
    )


def _check(table: str, obj: object, positive: tuple[str, ...], nonneg: tuple[str, ...] = ()) -> None:
    """Raise ConfigError naming ``kinds.ground.<table>.<field>`` for a field that is not finite and > 0
    (``positive``) or >= 0 (``nonneg``)."""
    for name in positive:
        v = getattr(obj, name)
        if not (_is_real(v) and v > 0):
            raise ConfigError(f"kinds.ground.{table}.{name} must be a positive number, got {v!r}")
    for name in nonneg:
        v = getattr(obj, name)
        if not (_is_real(v) and v >= 0):
            raise ConfigError(f"kinds.ground.{table}.{name} must be a non-negative number, got {v!r}")


@dataclass(frozen=True)
class GroundBodyParams:
    """The body of the ground module (table ``body``)."""

    mass_kg: float = 1.0
    """Total mass [kg]. The truth is kinematic and does not use it; the filter's known input is the
    force ``f = m a`` of the known acceleration (:class:`~swarm.kinds.ground.control.GroundCommand`)."""
    half_size_m: float = 0.05
    """Half the side of the cube [m] (keep-out, contact and drawing)."""
    height_sigma_m: float = 0.001
    """The filter's planar constraint: the table holds the module's centre at its start height, to this
    standard deviation [m] (table flatness, suspension)."""
    vertical_speed_sigma_m_s: float = 0.001
    """... and its vertical speed at zero, to this standard deviation [m/s]."""

    def __post_init__(self) -> None:
        _check("body", self, ("mass_kg", "half_size_m", "height_sigma_m", "vertical_speed_sigma_m_s"))


@dataclass(frozen=True)
class WheelParams:
    """The four mecanum wheels and their motors (table ``wheels``); geometry of Lynch & Park 2017
    sec. 13.2 (:mod:`swarm.kinds.ground.dynamics`)."""

    radius_m: float = 0.024
    """Wheel radius [m]: a 48 mm mecanum wheel."""
    half_length_m: float = 0.04
    """Distance of each wheel's contact point from the centre along body x [m] (Lynch & Park's ``l``)."""
    half_width_m: float = 0.055
    """Distance of each wheel's contact point from the centre along body y [m] (Lynch & Park's ``w``)."""
    max_speed_rad_s: float = 31.0
    """Largest wheel speed [rad/s] in either direction: an N-20 gear motor at ~300 rpm."""
    motor_time_constant_s: float = 0.05
    """Time constant ``tau`` [s] of the first-order lag from a wheel-speed command to the wheel speed."""

    def __post_init__(self) -> None:
        _check(
            "wheels",
            self,
            ("radius_m", "half_length_m", "half_width_m", "max_speed_rad_s", "motor_time_constant_s"),
        )


@dataclass(frozen=True)
class GroundControlParams:
    """Weights and limits of the ground controller (table ``control``;
    :class:`~swarm.kinds.ground.control.GroundController`).

    Per nav axis the LQR state is ``x = (p - p_ref [m], v - v_ref [m/s], integral of p - p_ref [m s])`` and
    the input the feedback part of the commanded velocity [m/s]; the cost is ``sum x^T Q x + R u^2`` with
    ``Q = diag(q_pos, q_vel, q_int)`` and ``R = r_vel``. With the default wheels (``tau = 0.05 s``) at
    10 Hz the defaults give ``K = (0.708 1/s, 0.039, 0.212 1/s^2)`` and closed-loop poles ``|z| = 0.966,
    0.966, 0.130`` (s-plane: wn 0.47 rad/s, zeta 0.74, and the motor lag's own pole, ~20 rad/s, nearly
    unmoved). In a closed loop on the truth (100 Hz, no noise, ``tests/kinds/test_ground_control.py``) a
    0.2 m step along a nav axis with a 30 deg yaw change settles within 2 mm in 11.0 s with 3.1 %
    overshoot (11.2 s and 4.4 % along the diagonal, where both axes overshoot), the yaw within 0.1 deg in
    5.2 s. The step's command meets the ``max_speed_m_s`` bound for the first ~0.7 s; the wheels peak at
    ~6.3 rad/s, a fifth of their limit. ``q_int`` is high on purpose: the step winds the integral up to
    its clamp (below), and a faster integrator mode returns the clamped area sooner; halving ``q_int``
    lengthens the settling time by ~2 s, and ``q_int = 0.1`` takes ~17 s.

    As in :class:`swarm.core.control.TranslationLqrParams`, a step winds the integral up while the error is
    large and the error must later overshoot by the same area; ``integral_limit_m_s`` bounds that area,
    trading the step overshoot (and its tail) against the largest constant velocity error the integral
    can cancel, ``K_i * integral_limit_m_s`` (~6.4 mm/s with the defaults).
    """

    rate_hz: float = 10.0
    """Controller rate [Hz]; the LQR is designed for the zero-order hold at this rate."""
    q_pos: float = 1.0
    """State weight on the position error [1/m^2]; must be > 0 (detectability of the integrator)."""
    q_vel: float = 1.0
    """State weight on the velocity error [s^2/m^2]."""
    q_int: float = 1.0
    """State weight on the integral of the position error [1/(m s)^2]; 0 disables integral action."""
    r_vel: float = 20.0
    """Input weight on the feedback velocity command [s^2/m^2]."""
    integral_limit_m_s: float = 0.03
    """Anti-windup clamp on each nav axis of the integrated position error [m s]."""
    max_speed_m_s: float = 0.1
    """Norm bound on the commanded body speed [m/s]; above it the xy command is scaled down, keeping its
    direction."""
    yaw_gain_1_s: float = 1.0
    """Proportional yaw gain [1/s]: ``wz = yaw_gain * (yaw_ref - yaw)``."""
    max_yaw_rate_rad_s: float = 0.5
    """Bound on the commanded yaw rate [rad/s]."""

    def __post_init__(self) -> None:
        _check(
            "control",
            self,
            ("rate_hz", "q_pos", "r_vel", "integral_limit_m_s", "max_speed_m_s", "yaw_gain_1_s",
             "max_yaw_rate_rad_s"),
            ("q_vel", "q_int"),
        )  # fmt: skip

    @property
    def dt_s(self) -> float:
        """Controller period [s]."""
        return 1.0 / self.rate_hz

    @property
    def integral_enabled(self) -> bool:
        """True unless ``q_int == 0``."""
        return self.q_int > 0.0


@dataclass(frozen=True)
class GroundDispersionParams:
    """Per-run dispersions of the ground kind (table ``dispersions``). Zero switches one off."""

    wheel_slip_sigma_frac: float = 0.0
    """Standard deviation of each wheel's slip ``e_i`` (fraction, at most ``MAX_SLIP_SIGMA_FRAC``): the
    wheel's traction factor is ``1 - |e_i|``, one draw per wheel and run with the scenario's distribution
    (:func:`slip_factors`)."""

    def __post_init__(self) -> None:
        v = self.wheel_slip_sigma_frac
        if not (_is_real(v) and 0.0 <= v <= MAX_SLIP_SIGMA_FRAC):
            raise ConfigError(
                f"kinds.ground.dispersions.wheel_slip_sigma_frac must be a number in "
                f"[0, {MAX_SLIP_SIGMA_FRAC}], got {v!r}"
            )


def slip_factors(sigma: float, distribution: str, rng: np.random.Generator) -> np.ndarray:
    """Traction factors (4,) of wheels 1..4 (front-left, front-right, rear-right, rear-left), in (0, 1].

    ``1 - |e_i|`` with ``e_i`` drawn from ``rng``: ``"normal"`` with standard deviation ``sigma``, or
    ``"uniform"`` on ``[-sqrt(3) sigma, sqrt(3) sigma]`` (the same standard deviation), floored at
    ``MIN_TRACTION``. ``sigma == 0`` returns ones and draws nothing, so switching slip off leaves the
    stream of ``rng`` untouched.
    """
    if not (_is_real(sigma) and sigma >= 0):
        raise ConfigError(f"kinds.ground.dispersions.wheel_slip_sigma_frac must be >= 0, got {sigma!r}")
    if distribution not in ("normal", "uniform"):
        raise ConfigError(f"distribution must be 'normal' or 'uniform', got {distribution!r}")
    if sigma == 0:
        return np.ones(4)
    if distribution == "uniform":
        half = math.sqrt(3.0) * sigma
        e = rng.uniform(-half, half, size=4)
    else:
        e = rng.normal(0.0, sigma, size=4)
    return np.maximum(1.0 - np.abs(e), MIN_TRACTION)
