"""Landing guidance for a quadrotor (paper section VI-B): the energy-optimal path, the deviation that makes
the pad visible, the descent, and the switching rule that decides where to deviate.

Modes (as a PX4 or ArduPilot user knows them, mapped onto the paper's docking modes):

* ``CRUISE`` (the paper's APPROACH): the energy-optimal landing path of Morbidi, Cano & Lara 2016
  ("Minimum-energy path generation for a quadrotor UAV", ICRA), whose optimal landing trajectories are a
  long lateral glide followed by a short vertical descent (paper Fig. 9): a straight glide at
  ``cruise_speed_m_s`` from the start to ``glide_end_height_m`` above the pad, then down.
* ``DEVIATE`` (REORIENT): leave that path for the **viewpoint**, the point above the estimated pad from which
  the downward camera sees the pad despite the horizontal uncertainty: height
  ``3 sigma_h / tan(view_margin * half_fov)``, bounded to ``[view_height_min_m, view_height_max_m]`` (the
  board's detection range).
* ``DESCEND`` (ALIGN): over the pad, descending at ``descend_speed_m_s`` while within ``accept_radius_m``
  horizontally (PX4's ``PLD_HACC_RAD``), holding height otherwise; the pad must stay in view: after
  ``lost_timeout_s`` without a pad measurement it **climbs** ``retry_climb_m`` and deviates again
  (``PLD_BTOUT``, ``PLD_MAX_SRCH``), at most ``max_retries`` times, then **aborts**.
* ``FINAL`` (DOCK): below ``final_height_m`` above the pad, descending at ``final_speed_m_s``; a lost pad is
  tolerated (the camera is too close to see the markers).
* ``LANDED``: on the skids (estimated height and vertical speed), rotors stopped. ``ABORT``: climb to
  ``abort_height_m`` above the start of the descent and hold there: safe, never a landing off the pad.

Switching CRUISE -> DEVIATE -> DESCEND, by one of two policies (``decide``):

* **fixed**: deviate at the conservative horizontal distance ``fixed_deviation_m``; descend once at the
  viewpoint (within ``accept_radius_m`` of it) with the pad in view.
* **mdp**: paper Algorithm 1 with ``r`` the horizontal distance to the pad, adapted to landing. Where the
  docking rule divides by the attitude error still to correct, ``1 / ||q_e||`` (how much reorientation the
  approach needs), landing multiplies by the **visibility ratio** ``rho = footprint / (3 sigma_h)``: the
  camera's ground footprint radius at the glide's end height over the 3-sigma horizontal uncertainty (how
  surely the pad will be in view if the glide continues)::

      A11 = (r / r_t) (1 / (1 + d)) rho                            -> DEVIATE when A11 <= 0.4 (r2 <- r)
      A22 = (r / r2) / (1 + d), A23 = 1 - A22
      A32 = (sigma_h / sigma_ref) (r2 - r) / (r2 - r_d), A33 = 1 - A32
      pi2 = A23 / (A23 + A32)                                    -> DESCEND when pi2 <= 0.6 (r1 <- r)

  with the paper's thresholds, ``d`` the filter's consistency (RMS Mahalanobis distance of its recent
  measurements) and ``r_d = accept_radius_m``. Every ``A`` is clipped into ``[0, 1]`` as for docking
  (:mod:`swarm.core.mdp`); DESCEND also needs the pad in view (its first measurement), else a descent
  would run blind. Each pass is recorded (:class:`LandingDecision`).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from swarm.core import _landing_nb as nb
from swarm.core.mdp import nan_to_none
from swarm.errors import ConfigError


class LandingMode(enum.StrEnum):
    CRUISE = "CRUISE"
    DEVIATE = "DEVIATE"
    DESCEND = "DESCEND"
    FINAL = "FINAL"
    CLIMB = "CLIMB"
    LANDED = "LANDED"
    ABORT = "ABORT"


@dataclass(frozen=True)
class LandingGuidanceParams:
    """``[landing]``: every threshold of the landing guidance (module docstring)."""

    cruise_speed_m_s: float = 3.0
    glide_end_height_m: float = 1.5
    view_height_min_m: float = 3.0
    view_margin: float = 0.6
    """Fraction of the camera's half field of view the viewpoint may use."""
    descend_speed_m_s: float = 0.7
    final_height_m: float = 1.0
    final_speed_m_s: float = 0.3
    accept_radius_m: float = 0.3
    lost_timeout_s: float = 1.5
    max_retries: int = 2
    retry_climb_m: float = 2.0
    abort_height_m: float = 10.0
    view_height_max_m: float = 6.0
    """Highest viewpoint: within the camera's detection range of the board."""
    touchdown_height_m: float = 0.12
    """The skids are down when the estimated centre of mass is this high above the pad (gear + margin)."""
    touchdown_speed_m_s: float = 0.15
    touchdown_hold_s: float = 0.5
    fixed_deviation_m: float = 12.0
    """The fixed policy's horizontal distance of deviation (conservative)."""
    r_t_m: float = 25.0
    """Algorithm 1 runs within this horizontal distance of the pad."""
    a11_threshold: float = 0.4
    pi2_threshold: float = 0.6
    sigma_ref_m: float = 0.5
    """Algorithm 1's ``sigma_UWB``: the horizontal sigma of the navigation without the pad."""
    r1_init_m: float = 0.3
    r2_init_m: float = 1.0

    def __post_init__(self) -> None:
        for name in (
            "cruise_speed_m_s",
            "glide_end_height_m",
            "view_height_min_m",
            "view_margin",
            "descend_speed_m_s",
            "final_height_m",
            "final_speed_m_s",
            "accept_radius_m",
            "lost_timeout_s",
            "retry_climb_m",
            "abort_height_m",
            "touchdown_height_m",
            "touchdown_speed_m_s",
            "touchdown_hold_s",
            "fixed_deviation_m",
            "r_t_m",
            "sigma_ref_m",
            "r1_init_m",
            "r2_init_m",
            "view_height_max_m",
        ):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"landing.{name} must be a positive finite number, got {v!r}")
        if not (isinstance(self.max_retries, int) and self.max_retries >= 0):
            raise ConfigError(f"landing.max_retries must be an integer >= 0, got {self.max_retries!r}")
        if not 0 < self.view_margin <= 1:
            raise ConfigError(f"landing.view_margin must be in (0, 1], got {self.view_margin!r}")
        for name in ("a11_threshold", "pi2_threshold"):
            if not 0 < getattr(self, name) < 1:
                raise ConfigError(f"landing.{name} must be in (0, 1), got {getattr(self, name)!r}")
        if not self.r1_init_m >= self.accept_radius_m:
            raise ConfigError("landing.r1_init_m must be at least accept_radius_m")
        if not self.view_height_min_m <= self.view_height_max_m <= self.abort_height_m:
            raise ConfigError("landing: view_height_min_m <= view_height_max_m <= abort_height_m is required")


@dataclass
class LandingDecision:
    """One pass of the switching rule (module docstring), as recorded."""

    t_s: float
    mode: str
    r_m: float
    d: float
    sigma_h_m: float
    rho: float | None = None
    A11: float | None = None
    A22: float | None = None
    A23: float | None = None
    A32: float | None = None
    A33: float | None = None
    pi1: float | None = None
    pi2: float | None = None
    r1_m: float = 0.0
    r2_m: float = 0.0
    switched: bool = False

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Reference:
    """What the controller tracks: position, velocity, acceleration (nav) and heading quaternion."""

    p_nav: np.ndarray
    v_nav: np.ndarray
    a_nav: np.ndarray = field(default_factory=lambda: np.zeros(3))
    q_nav_body: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))


MODES = tuple(LandingMode)
"""The modes by their codes in the compiled guidance (``_landing_nb.L_*``)."""


def guidance_row(params: LandingGuidanceParams, policy: str, pad_nav, half_fov_rad: float,
                 gear_height_m: float) -> np.ndarray:  # fmt: skip
    """The compiled guidance's parameter vector ``GP`` (:mod:`swarm.core._landing_nb`)."""
    P = params
    GP = np.zeros(nb.GP_N)
    for i, x in (
        (nb.GP_CRUISE_V, P.cruise_speed_m_s), (nb.GP_GLIDE_H, P.glide_end_height_m),
        (nb.GP_VIEW_MIN, P.view_height_min_m), (nb.GP_DESCEND_V, P.descend_speed_m_s),
        (nb.GP_FINAL_H, P.final_height_m), (nb.GP_FINAL_V, P.final_speed_m_s),
        (nb.GP_ACCEPT, P.accept_radius_m), (nb.GP_LOST_T, P.lost_timeout_s),
        (nb.GP_MAX_RETRIES, P.max_retries), (nb.GP_RETRY_CLIMB, P.retry_climb_m),
        (nb.GP_ABORT_H, P.abort_height_m), (nb.GP_VIEW_MAX, P.view_height_max_m),
        (nb.GP_TOUCH_H, P.touchdown_height_m), (nb.GP_TOUCH_V, P.touchdown_speed_m_s),
        (nb.GP_TOUCH_HOLD, P.touchdown_hold_s), (nb.GP_FIXED_D, P.fixed_deviation_m), (nb.GP_R_T, P.r_t_m),
        (nb.GP_A11_THR, P.a11_threshold), (nb.GP_PI2_THR, P.pi2_threshold), (nb.GP_SIGMA_REF, P.sigma_ref_m),
    ):  # fmt: skip
        GP[i] = x
    GP[nb.GP_MDP] = 1.0 if policy == "mdp" else 0.0
    GP[nb.GP_TAN_VIEW] = math.tan(P.view_margin * half_fov_rad)
    GP[nb.GP_GEAR] = gear_height_m
    pad = np.asarray(pad_nav, dtype=float)
    GP[nb.GP_PAD : nb.GP_PAD + 3] = pad
    GP[nb.GP_GLIDE_END : nb.GP_GLIDE_END + 3] = pad + np.array([0.0, 0.0, P.glide_end_height_m])
    return GP


def reason_text(params: LandingGuidanceParams, policy: str, code: int, a: float, b: float, c: float) -> str:
    """The words of a mode switch's reason ``code`` (``_landing_nb.RS_*``), quoting ``a``, ``b``, ``c``."""
    P = params
    no_view, lost = "no pad in view from the viewpoint", f"pad lost for {P.lost_timeout_s:g} s"
    if code == nb.RS_DEVIATE:
        return (
            f"{policy}: deviate at r = {a:.2f} m to a viewpoint {b:.1f} m above the pad (sigma_h {c:.2f} m)"
        )
    if code == nb.RS_DESCEND:
        return f"{policy}: descend at r = {a:.2f} m, pad in view"
    if code == nb.RS_FINAL:
        return f"below {P.final_height_m:g} m: final descent"
    if code in (nb.RS_CLIMB_NO_VIEW, nb.RS_CLIMB_LOST):
        why = no_view if code == nb.RS_CLIMB_NO_VIEW else lost
        return f"{why}: climb and retry ({int(a)} of {P.max_retries})"
    if code in (nb.RS_ABORT_NO_VIEW, nb.RS_ABORT_LOST):
        why = no_view if code == nb.RS_ABORT_NO_VIEW else lost
        return f"{why}; {P.max_retries} retries spent: abort, climb to {P.abort_height_m:g} m and hold"
    if code == nb.RS_CLIMBED:
        return "climbed: back to the viewpoint"
    if code == nb.RS_LANDED:
        return "on the skids: rotors stopped"
    raise ValueError(f"unknown landing reason code {code!r}")


class LandingGuidance:
    """The guidance of one quadrotor landing on one pad (module docstring): the arrays of the compiled
    guidance (:mod:`swarm.core._landing_nb`), its switches and passes as records. ``step`` once per control
    tick, or the compiled agent tick calls :func:`~swarm.core._landing_nb.landing_step` on :attr:`G` and the
    others and then :meth:`drain`."""

    EV_ROWS = 16
    DEC_ROWS = 64

    def __init__(
        self,
        params: LandingGuidanceParams,
        policy: str,
        pad_nav,
        start_nav,
        half_fov_rad: float,
        gear_height_m: float,
    ) -> None:
        if policy not in ("fixed", "mdp"):
            raise ConfigError(f"policy must be 'fixed' or 'mdp', got {policy!r}")
        self.p, self.policy = params, policy
        self.pad = np.asarray(pad_nav, dtype=float)
        self.start = np.asarray(start_nav, dtype=float)
        self.GP = guidance_row(params, policy, self.pad, half_fov_rad, gear_height_m)
        self.G = np.full(nb.G_N, np.nan)
        self.G[nb.G_MODE], self.G[nb.G_RETRIES] = nb.L_CRUISE, 0.0
        self.G[nb.G_R1], self.G[nb.G_R2] = params.r1_init_m, params.r2_init_m
        self.REF = np.zeros(nb.REF_N)
        self.EV, self.EV_n = np.zeros((self.EV_ROWS, nb.EV_N)), np.zeros(1, dtype=np.int64)
        self.DEC, self.DEC_n = np.zeros((self.DEC_ROWS, nb.DEC_N)), np.zeros(1, dtype=np.int64)
        self.decisions: list[LandingDecision] = []
        self.modes: list[dict] = []

    @property
    def mode(self) -> LandingMode:
        return MODES[int(self.G[nb.G_MODE])]

    @property
    def retries(self) -> int:
        return int(self.G[nb.G_RETRIES])

    @property
    def r1(self) -> float:
        return float(self.G[nb.G_R1])

    @property
    def r2(self) -> float:
        return float(self.G[nb.G_R2])

    def _point(self, i: int) -> np.ndarray | None:
        x = self.G[i : i + 3]
        return None if math.isnan(x[0]) else x.copy()

    @property
    def deviation_point(self) -> np.ndarray | None:
        return self._point(nb.G_DEV)

    @property
    def viewpoint(self) -> np.ndarray | None:
        return self._point(nb.G_VIEW)

    def view_height(self, sigma_h: float) -> float:
        """The viewpoint's height above the pad for a horizontal sigma ``sigma_h`` [m]."""
        return float(nb.view_height(self.GP, float(sigma_h)))

    def drain(self) -> None:
        """Turn the switches and passes the kernel left in ``EV`` and ``DEC`` into records."""
        for row in self.EV[: self.EV_n[0]]:
            self.modes.append(
                {
                    "t_s": float(row[nb.E_T]),
                    "from": str(MODES[int(row[nb.E_FROM])]),
                    "mode": str(MODES[int(row[nb.E_TO])]),
                    "reason": reason_text(
                        self.p, self.policy, int(row[nb.E_REASON]), *row[nb.E_A : nb.E_C + 1]
                    ),
                    "p_est_nav": [float(x) for x in row[nb.E_P : nb.E_P + 3]],
                }
            )
        self.EV_n[0] = 0
        for row in self.DEC[: self.DEC_n[0]]:
            self.decisions.append(
                LandingDecision(
                    float(row[nb.D_T]), str(MODES[int(row[nb.D_MODE])]),
                    float(row[nb.D_R]), float(row[nb.D_D]),
                    float(row[nb.D_SIGMA]), *(nan_to_none(x) for x in row[nb.D_RHO : nb.D_PI2 + 1]),
                    r1_m=float(row[nb.D_R1]), r2_m=float(row[nb.D_R2]), switched=bool(row[nb.D_SWITCHED]),
                )
            )  # fmt: skip
        self.DEC_n[0] = 0

    def step(
        self, t: float, p: np.ndarray, v: np.ndarray, sigma_h: float, d: float, pad_seen_s: float | None
    ) -> Reference:
        """The reference at time ``t`` [s] from the estimate ``p``, ``v`` (nav), its horizontal sigma
        ``sigma_h`` [m], the filter's consistency ``d`` and the time of the last pad measurement (None:
        never)."""
        seen = math.nan if pad_seen_s is None else float(pad_seen_s)
        nb.landing_step(self.G, self.GP, float(t), np.asarray(p, float), np.asarray(v, float), float(sigma_h),
                        float(d), seen, self.REF, self.EV, self.EV_n, self.DEC, self.DEC_n)  # fmt: skip
        self.drain()
        return Reference(self.REF[nb.R_P : nb.R_P + 3].copy(), self.REF[nb.R_V : nb.R_V + 3].copy())
