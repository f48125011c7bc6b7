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

from swarm.core.mdp import reorient_align_probabilities, stationary_2state
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


def _toward(
    p: np.ndarray, goal: np.ndarray, speed: float, gain: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """A reference that flies from ``p`` straight to ``goal`` at ``speed``, slowing in
    (``v = gain * distance``)."""
    d = goal - p
    dist = float(np.linalg.norm(d))
    if dist < 1e-9:
        return goal.copy(), np.zeros(3)
    v = d / dist * min(speed, gain * dist)
    return p.copy(), v


class LandingGuidance:
    """The guidance of one quadrotor landing on one pad (module docstring). ``step`` once per control tick."""

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
        self.glide_end = self.pad + np.array([0.0, 0.0, params.glide_end_height_m])
        self.tan_view = math.tan(params.view_margin * half_fov_rad)
        self.gear = gear_height_m
        self.mode = LandingMode.CRUISE
        self.r1, self.r2 = params.r1_init_m, params.r2_init_m
        self.retries = 0
        self.decisions: list[LandingDecision] = []
        self.modes: list[dict] = []
        self.deviation_point: np.ndarray | None = None
        self.viewpoint: np.ndarray | None = None
        self._hold: np.ndarray | None = None
        self._touch_since: float | None = None
        self._climb_to: float | None = None
        self._at_view: float | None = None

    # ---- helpers ---------------------------------------------------------------------------------
    def _switch(self, t: float, mode: LandingMode, p: np.ndarray, reason: str) -> None:
        self.modes.append(
            {
                "t_s": float(t),
                "from": str(self.mode),
                "mode": str(mode),
                "reason": reason,
                "p_est_nav": [float(x) for x in p],
            }
        )
        self.mode = mode

    def view_height(self, sigma_h: float) -> float:
        """The viewpoint's height above the pad for a horizontal sigma ``sigma_h`` [m]."""
        h = 3.0 * sigma_h / self.tan_view
        return float(min(max(h, self.p.view_height_min_m), self.p.view_height_max_m))

    def _decide(self, t, p, r, d, sigma_h) -> bool:
        """One pass of the switching rule in CRUISE or DEVIATE; True to switch to the next mode."""
        P = self.p
        rec = LandingDecision(
            float(t), str(self.mode), float(r), float(d), float(sigma_h), r1_m=self.r1, r2_m=self.r2
        )
        switch = False
        if self.policy == "fixed":
            if self.mode == LandingMode.CRUISE:
                switch = r <= P.fixed_deviation_m
            else:
                switch = float(np.linalg.norm(p[:2] - self.viewpoint[:2])) <= P.accept_radius_m
            rec.switched = switch
            if switch:
                self.decisions.append(rec)
            return switch
        if r > P.r_t_m:
            return False
        if self.mode == LandingMode.CRUISE:
            footprint = P.glide_end_height_m * self.tan_view
            rho = footprint / max(3.0 * sigma_h, 1e-9)
            a11 = min(max((r / P.r_t_m) * (1.0 / (1.0 + d)) * rho, 0.0), 1.0)
            rec.rho, rec.A11 = float(rho), float(a11)
            if a11 <= P.a11_threshold:
                self.r2 = float(r)
                switch = True
        else:
            a22, a23, a32, a33 = reorient_align_probabilities(
                float(r), float(self.r2), float(d), float(sigma_h), P.sigma_ref_m, P.accept_radius_m
            )
            rec.A22, rec.A23, rec.A32, rec.A33 = a22, a23, a32, a33
            pi = stationary_2state(a23, a32)
            if pi is not None:
                rec.pi1, rec.pi2 = pi
                if pi[1] <= P.pi2_threshold:
                    self.r1 = float(r)
            switch = r <= self.r1
        rec.r1_m, rec.r2_m, rec.switched = self.r1, self.r2, switch
        self.decisions.append(rec)
        return switch

    def _lost(self, t, p, v, sigma_h, d, pad_seen_s, why: str) -> Reference:
        """The target is lost: climb and retry, or abort after ``max_retries``."""
        P = self.p
        self.retries += 1
        if self.retries > P.max_retries:
            self._climb_to = self.pad[2] + P.abort_height_m
            self._switch(
                t,
                LandingMode.ABORT,
                p,
                f"{why}; {P.max_retries} retries spent: abort, climb to {P.abort_height_m:g} m and hold",
            )
        else:
            self._climb_to = min(p[2] + P.retry_climb_m, self.pad[2] + P.abort_height_m)
            self._switch(
                t, LandingMode.CLIMB, p, f"{why}: climb and retry ({self.retries} of {P.max_retries})"
            )
        self._hold = p.copy()
        return self.step(t, p, v, sigma_h, d, pad_seen_s)

    # ---- one control step ------------------------------------------------------------------------
    def step(
        self, t: float, p: np.ndarray, v: np.ndarray, sigma_h: float, d: float, pad_seen_s: float | None
    ) -> Reference:
        """The reference at time ``t`` [s] from the estimate ``p``, ``v`` (nav), its horizontal sigma
        ``sigma_h`` [m], the filter's consistency ``d`` and the time of the last pad measurement (None:
        never)."""
        P = self.p
        r = float(np.linalg.norm(p[:2] - self.pad[:2]))
        height = float(p[2] - self.pad[2])
        seen = pad_seen_s is not None and t - pad_seen_s <= P.lost_timeout_s
        m = self.mode
        if m == LandingMode.CRUISE:
            if self._decide(t, p, r, d, sigma_h):
                self.deviation_point = p.copy()
                self.viewpoint = self.pad + np.array([0.0, 0.0, self.view_height(sigma_h)])
                self._switch(
                    t,
                    LandingMode.DEVIATE,
                    p,
                    f"{self.policy}: deviate at r = {r:.2f} m to a viewpoint "
                    f"{self.viewpoint[2] - self.pad[2]:.1f} m above the pad (sigma_h {sigma_h:.2f} m)",
                )
                return self.step(t, p, v, sigma_h, d, pad_seen_s)
            goal = self.glide_end if r > 0.5 else self.pad + np.array([0.0, 0.0, self.gear])
            speed = P.cruise_speed_m_s if r > 0.5 else P.descend_speed_m_s
            _, vref = _toward(p, goal, speed, gain=0.8)
            return Reference(p.copy(), vref)
        if m == LandingMode.DEVIATE:
            if seen and self._decide(t, p, r, d, sigma_h):
                self._switch(
                    t, LandingMode.DESCEND, p, f"{self.policy}: descend at r = {r:.2f} m, pad in view"
                )
                return self.step(t, p, v, sigma_h, d, pad_seen_s)
            at_view = float(np.linalg.norm(p - self.viewpoint)) <= max(P.accept_radius_m, 0.3)
            if at_view and not seen:
                self._at_view = t if self._at_view is None else self._at_view
                if t - self._at_view >= P.lost_timeout_s:  # at the viewpoint and still no pad: a lost target
                    self._at_view = None
                    return self._lost(t, p, v, sigma_h, d, pad_seen_s, "no pad in view from the viewpoint")
            else:
                self._at_view = None
            _, vref = _toward(p, self.viewpoint, P.cruise_speed_m_s, gain=0.8)
            return Reference(p.copy(), vref)
        if m == LandingMode.DESCEND:
            if height <= P.final_height_m:
                self._switch(t, LandingMode.FINAL, p, f"below {P.final_height_m:g} m: final descent")
                return self.step(t, p, v, sigma_h, d, pad_seen_s)
            if not seen:
                return self._lost(t, p, v, sigma_h, d, pad_seen_s, f"pad lost for {P.lost_timeout_s:g} s")
            vref = np.zeros(3)
            e = self.pad[:2] - p[:2]
            vref[:2] = e * 1.0
            n = float(np.linalg.norm(vref[:2]))
            if n > P.cruise_speed_m_s:
                vref[:2] *= P.cruise_speed_m_s / n
            if r <= P.accept_radius_m:
                vref[2] = -P.descend_speed_m_s
            return Reference(p.copy(), vref)
        if m == LandingMode.FINAL:
            if height <= P.touchdown_height_m and abs(v[2]) <= P.touchdown_speed_m_s:
                self._touch_since = t if self._touch_since is None else self._touch_since
                if t - self._touch_since >= P.touchdown_hold_s:
                    self._switch(t, LandingMode.LANDED, p, "on the skids: rotors stopped")
            else:
                self._touch_since = None
            vref = np.zeros(3)
            vref[:2] = (self.pad[:2] - p[:2]) * 1.0
            vref[2] = -P.final_speed_m_s
            return Reference(p.copy(), vref)
        if m == LandingMode.CLIMB:
            if p[2] >= self._climb_to - 0.1:
                self.viewpoint = self.pad + np.array(
                    [0.0, 0.0, max(self.view_height(sigma_h), p[2] - self.pad[2])]
                )
                self._switch(t, LandingMode.DEVIATE, p, "climbed: back to the viewpoint")
                return self.step(t, p, v, sigma_h, d, pad_seen_s)
            return Reference(np.array([self._hold[0], self._hold[1], self._climb_to]), np.zeros(3))
        if m == LandingMode.ABORT:
            return Reference(np.array([self._hold[0], self._hold[1], self._climb_to]), np.zeros(3))
        return Reference(p.copy(), np.zeros(3))  # LANDED
