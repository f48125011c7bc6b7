"""Guidance modes of the docking chaser and the station-keeping target (paper section V, Fig. 1, Fig. 4).

The chaser flies APPROACH (along the line of sight to the target, keeping its mission attitude), REORIENT
(turns to the docking attitude while still closing along the line of sight), ALIGN (goes to the alignment
point straight in front of the target's docking face, around the keep-out sphere) and DOCK (final approach
along the face normal to contact), then DOCKED. The switch radii ``r2`` (APPROACH -> REORIENT) and ``r1``
(REORIENT -> ALIGN) come from a switcher: fixed radii or Algorithm 1 (:mod:`swarm.core.mdp`). HOLD freezes
the reference while the estimate is not trustworthy (and at start, until the first estimate has
converged: "the chaser begins motion ... once the initial position is estimated with specified variance",
paper Fig. 8); ABORT backs away from the target when the estimate fails close in, or a HOLD lasts too long.

Everything here runs on *estimates*: the chaser's own and the target's published one, never the truth.
The reference is a carrot that moves toward the mode's goal at the mode's speed and never leads the
vehicle by more than ``max_lead_m``, so the LQR (section IV-B) tracks a smooth, feasible path.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numba import njit

from swarm.core import _guidance_nb as nb
from swarm.core import rotations as rot
from swarm.core._rot_nb import qconj, qlog, qmul, qnormalize, qrotate
from swarm.errors import ConfigError

FACES = ("+x", "-x", "+y", "-y", "+z", "-z")


def _norm(x) -> float:
    """Euclidean norm of a 1-D vector: what ``np.linalg.norm`` computes (``sqrt(x . x)``), bit for bit,
    without its per-call overhead (the guidance runs every control tick)."""
    x = np.asarray(x, dtype=np.float64)
    return math.sqrt(x.dot(x))


class Mode(enum.StrEnum):
    HOLD = "HOLD"
    APPROACH = "APPROACH"
    REORIENT = "REORIENT"
    ALIGN = "ALIGN"
    DOCK = "DOCK"
    DOCKED = "DOCKED"
    ABORT = "ABORT"
    STATION = "STATION"  # the target keeps station


CORRIDOR_MODES = (Mode.DOCK, Mode.DOCKED, Mode.ABORT)
"""Modes in which the chaser may be inside the keep-out sphere, within the docking corridor: docking, and
an ABORT backing out of it (it retreats along the line of sight from the target's centre, a ray that
stays at the same angle to the face normal, so a retreat from the corridor stays in it)."""


@dataclass(frozen=True)
class GuidanceParams:
    """Geometry, speeds and thresholds of the docking guidance (every number a scenario default)."""

    docking_face: str = "+x"
    """Target face to dock on, in the target body frame (one of +x, -x, +y, -y, +z, -z). The chaser docks
    with its bottom (-z) face, where its camera is."""
    half_size_m: float = 0.05
    """Half the side of a TPODS cube [m]; ports sit at the face centres, so centres are twice this apart
    at contact."""
    align_distance_m: float = 0.25
    """Distance of the alignment point from the target centre along the docking-face normal [m]."""
    keepout_radius_m: float = 0.15
    """Keep-out sphere around the target centre [m]: entered only in DOCK, inside the docking corridor."""
    keepout_margin_m: float = 0.03
    """Extra clearance the reference keeps outside the keep-out sphere [m]."""
    corridor_half_angle_deg: float = 12.0
    """Half-angle of the docking corridor around the face normal, apex at the target centre [deg]."""
    approach_speed_m_s: float = 0.02
    """Reference speed in APPROACH and REORIENT [m/s]."""
    align_speed_m_s: float = 0.015
    """Reference speed in ALIGN [m/s]."""
    dock_speed_m_s: float = 0.008
    """Reference speed in DOCK [m/s]."""
    abort_speed_m_s: float = 0.02
    """Reference speed while backing away in ABORT [m/s]."""
    max_lead_m: float = 0.05
    """The reference waits when it leads the estimated position by more than this [m]."""
    stop_decel_m_s2: float = 0.01
    """The APPROACH/REORIENT reference brakes into its stop point outside the keep-out sphere at this
    deceleration [m/s^2]: its speed is ``min(speed, sqrt(2 a d))`` at ``d`` from the stop point
    (``v^2 = 2 a d``), the deceleration fed forward to the LQR, so the reference's velocity is continuous.
    A reference that stopped dead from 2 cm/s let the chaser (lagging it, its integral wound up) overshoot
    by 17-26 mm into the 30 mm keep-out margin: 2 keep-out violations in 200 MDP runs of docking-faults
    (docs/results/faults-analysis). 0.01 m/s^2 is 12 % of the 0.083 m/s^2 the translation controller may
    command (0.1 N on 1.2 kg), so feedback keeps its authority; braking takes 2 s over 2 cm. Measured on
    those 200 runs: closest approach 160.1 mm (was 146.2), MDP docking 1.3 s longer; 0.004 and 0.002 gave
    163.7 / 166.8 mm for +3.9 / +8.1 s. The fixed radii switch to ALIGN before the braking begins."""
    align_tolerance_m: float = 0.02
    """ALIGN -> DOCK once within this distance of the alignment point [m] ..."""
    align_attitude_tolerance_rad: float = 0.05
    """... with at most this attitude error to the docking attitude [rad] ..."""
    align_speed_tolerance_m_s: float = 0.01
    """... and at most this speed [m/s]."""
    dock_overshoot_m: float = 0.01
    """The DOCK reference aims this far past port contact so that contact is made [m]."""
    contact_distance_m: float = 0.005
    """Docking contact: port-to-port gap along the face normal at most this [m] ..."""
    contact_lateral_m: float = 0.02
    """... lateral port offset at most this [m] ..."""
    contact_attitude_rad: float = 0.1
    """... attitude error to the docking attitude at most this [rad] ..."""
    contact_speed_m_s: float = 0.03
    """... and closing speed at most this [m/s]; a contact outside these is a collision."""
    hold_sigma_pos_m: float = 0.06
    """HOLD when the largest position standard deviation exceeds this [m] ..."""
    resume_sigma_pos_m: float = 0.04
    """... and resume below this (hysteresis) [m]."""
    hold_rejection_fraction: float = 0.5
    """HOLD when more than this fraction of the recent range updates was rejected."""
    hold_nis_mean: float = 8.0
    """HOLD when the mean normalised innovation squared of the recent ranges (each clipped at the gate,
    the square of Algorithm 1's d) exceeds this; resume at or below it. A consistent filter gives 1
    (chi-square, 1 dof); 10 % outliers clipped at the 99.99 % gate (15.1) give ~2.4; 8 flags innovations
    that pass the gate but are systematically large (a filter that has drifted)."""
    abort_after_hold_s: float = 30.0
    """A HOLD (after start) longer than this turns into ABORT [s]."""
    abort_retreat_m: float = 0.3
    """ABORT backs away to this distance beyond the keep-out sphere along the line of sight [m]."""
    retry_after_s: float = 5.0
    """An ABORT retries no sooner than this after it began, once backed away and healthy [s]."""
    arc_lookahead_rad: float = 0.05
    """Around the keep-out sphere the goal leads the reference by this arc [rad] (a carrot on the arc)."""
    max_retries: int = 1
    """After an ABORT the approach is retried this many times once the estimate is healthy again."""
    stall_timeout_s: float = 2.0
    """REORIENT held at the keep-out boundary this long without reaching r1 switches to ALIGN [s]."""
    dock_requires_vision: bool = False
    """ALIGN -> DOCK only with vision: at the alignment point without it (camera lost) the chaser waits
    there, and aborts after ``abort_after_hold_s``. Entering the corridor on a UWB-only estimate (~1-2 cm)
    can miss the 2 cm lateral contact tolerance (issue 7); off by default (the paper's guidance, and a
    camera that sees the target at the alignment point makes it moot), on in ``docking-faults.toml``."""

    def __post_init__(self) -> None:
        if self.docking_face not in FACES:
            raise ConfigError(f"guidance.docking_face must be one of {FACES}, got {self.docking_face!r}")
        for name in (
            "half_size_m", "align_distance_m", "keepout_radius_m", "approach_speed_m_s", "align_speed_m_s",
            "dock_speed_m_s", "abort_speed_m_s", "max_lead_m", "align_tolerance_m",
            "align_attitude_tolerance_rad", "align_speed_tolerance_m_s", "contact_distance_m",
            "contact_lateral_m", "contact_attitude_rad", "contact_speed_m_s", "hold_sigma_pos_m",
            "resume_sigma_pos_m", "abort_after_hold_s", "abort_retreat_m", "stall_timeout_s",
            "corridor_half_angle_deg", "retry_after_s", "arc_lookahead_rad", "hold_nis_mean",
            "stop_decel_m_s2",
        ):  # fmt: skip
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"guidance.{name} must be a positive number, got {v!r}")
        for name in ("keepout_margin_m", "dock_overshoot_m"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError(f"guidance.{name} must be a non-negative number, got {v!r}")
        if not isinstance(self.dock_requires_vision, bool):
            raise ConfigError(
                f"guidance.dock_requires_vision must be a bool, got {self.dock_requires_vision!r}"
            )
        if self.align_distance_m <= self.keepout_radius_m + self.keepout_margin_m:
            raise ConfigError(
                "guidance.align_distance_m must lie outside the keep-out sphere plus margin "
                f"({self.keepout_radius_m + self.keepout_margin_m} m), got {self.align_distance_m!r}"
            )
        if self.keepout_radius_m <= 2 * self.half_size_m:
            raise ConfigError(
                f"guidance.keepout_radius_m must exceed the docked centre distance {2 * self.half_size_m} m, "
                f"got {self.keepout_radius_m!r}"
            )
        if self.resume_sigma_pos_m > self.hold_sigma_pos_m:
            raise ConfigError(
                "guidance.resume_sigma_pos_m must not exceed hold_sigma_pos_m, "
                f"got {self.resume_sigma_pos_m!r}"
            )
        if not (0 < self.hold_rejection_fraction <= 1):
            raise ConfigError(
                f"guidance.hold_rejection_fraction must be in (0, 1], got {self.hold_rejection_fraction!r}"
            )
        if int(self.max_retries) != self.max_retries or self.max_retries < 0:
            raise ConfigError(
                f"guidance.max_retries must be a non-negative integer, got {self.max_retries!r}"
            )

    @cached_property
    def corridor_cos(self) -> float:
        """Cosine of the docking corridor's half-angle (inside when ``axial >= centre * corridor_cos``)."""
        return float(np.cos(np.radians(self.corridor_half_angle_deg)))

    @cached_property
    def face_normal_target(self) -> np.ndarray:
        """Outward unit normal of the docking face in the target body frame."""
        n = np.zeros(3)
        n["xyz".index(self.docking_face[1])] = 1.0 if self.docking_face[0] == "+" else -1.0
        return n

    def with_port(self, q_target_chaser_docked) -> GuidanceParams:
        """This guidance for a chaser whose docked attitude relative to the target is
        ``q_target_chaser_docked`` (scalar-last): its vehicle kind's port
        (:meth:`swarm.kinds.base.VehicleKind.q_target_chaser_docked`)."""
        g = dataclasses.replace(self)
        q = np.array(q_target_chaser_docked, dtype=float)
        q.setflags(write=False)
        g.__dict__["q_target_chaser_docked"] = q  # the cached property's slot, as cached_property fills it
        return g

    @cached_property
    def q_target_chaser_docked(self) -> np.ndarray:
        """Chaser attitude relative to the target when docked, scalar-last. By default a cube's: chaser +z
        along the face normal (its bottom face and camera against the docking face), chaser +x along the
        next target axis in x -> y -> z order (the port's clocking); :meth:`with_port` sets another kind's."""
        n = self.face_normal_target
        axis = "xyz".index(self.docking_face[1])
        x_c = np.zeros(3)
        x_c[(axis + 1) % 3] = 1.0
        y_c = np.cross(n, x_c)
        return rot.matrix_to_quat(np.column_stack([x_c, y_c, n]))


@dataclass(frozen=True)
class NavInput:
    """What the guidance knows at one evaluation (all estimates, frame nav)."""

    t_s: float
    p_nav: np.ndarray
    v_nav: np.ndarray
    q_nav_body: np.ndarray
    sigma_pos_max_m: float
    mahalanobis_d: float
    """Mahalanobis distance of the recent range innovations (RMS of sqrt(d^2)); Algorithm 1's d."""
    rejection_fraction: float
    """Fraction of the recent range updates rejected by the gate."""
    vision: bool
    """A vision update was accepted recently."""
    p_target_nav: np.ndarray
    q_nav_target: np.ndarray


@dataclass
class Reference:
    """Output of one guidance evaluation: the controllers' reference and the mode bookkeeping."""

    mode: Mode
    p_nav: np.ndarray
    v_nav: np.ndarray
    a_nav: np.ndarray
    q_nav_body: np.ndarray
    range_m: float
    events: list[dict] = field(default_factory=list)
    decision: object | None = None


def docking_geometry(
    p: GuidanceParams, p_target_nav, q_nav_target
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Face normal (nav), docked chaser centre (nav) and docking attitude q_nav_body for a target pose."""
    n_nav = rot.quat_rotate(q_nav_target, p.face_normal_target)
    p_docked = np.asarray(p_target_nav) + 2.0 * p.half_size_m * n_nav
    q_dock = rot.quat_normalize(rot.quat_mul(q_nav_target, p.q_target_chaser_docked))
    return n_nav, p_docked, q_dock


def contact_state(p: GuidanceParams, p_c, v_c, q_c, p_t, q_t, v_t=None) -> dict:
    """Port-to-port geometry of a chaser/target pair (used by the world on the truth): gap along the
    face normal, lateral offset, attitude error to the docking attitude and closing speed
    (:func:`pair_geometry`)."""
    f64 = np.float64
    g = pair_geometry(
        np.asarray(p_c, f64), np.asarray(v_c, f64), np.asarray(q_c, f64), np.asarray(p_t, f64),
        np.zeros(3) if v_t is None else np.asarray(v_t, f64), np.asarray(q_t, f64), p.face_normal_target,
        p.q_target_chaser_docked, p.half_size_m,
    )  # fmt: skip
    return {"gap_m": g[1], "lateral_m": g[2], "attitude_rad": g[3], "closing_m_s": g[4]}


@njit(cache=True)
def pair_geometry(p_c, v_c, q_c, p_t, v_t, q_t, n_target, q_tc, half):
    """``(centre, gap, lateral, attitude, closing, axial)`` of a chaser/target pair, frame nav: centre
    distance; with ``n`` the docking-face normal ``R(q_t) n_target`` and the docked chaser centre
    ``p_t + 2 half n``: the gap along ``n``, the lateral offset, the attitude error to the docking
    attitude ``q_t (x) q_tc``, the closing speed ``-(v_c - v_t) . n``, and ``axial = (p_c - p_t) . n``
    (inside the docking corridor when ``axial >= centre cos(half-angle)``). Compiled: the simulation
    checks it every tick."""
    n = qrotate(q_t, n_target)
    dx, dy, dz = p_c[0] - p_t[0], p_c[1] - p_t[1], p_c[2] - p_t[2]
    centre = np.sqrt(dx * dx + dy * dy + dz * dz)
    axial = dx * n[0] + dy * n[1] + dz * n[2]
    rx, ry, rz = dx - 2.0 * half * n[0], dy - 2.0 * half * n[1], dz - 2.0 * half * n[2]
    gap = rx * n[0] + ry * n[1] + rz * n[2]
    lx, ly, lz = rx - gap * n[0], ry - gap * n[1], rz - gap * n[2]
    lateral = np.sqrt(lx * lx + ly * ly + lz * lz)
    q_dock = qnormalize(qmul(q_t, q_tc))
    e = qlog(qmul(qconj(q_dock), q_c))
    att = np.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    closing = -((v_c[0] - v_t[0]) * n[0] + (v_c[1] - v_t[1]) * n[1] + (v_c[2] - v_t[2]) * n[2])
    return centre, gap, lateral, att, closing, axial


def in_corridor(p: GuidanceParams, p_c, p_t, n_nav) -> bool:
    rel = np.asarray(p_c) - np.asarray(p_t)
    r = _norm(rel)
    return bool(r > 0 and rel @ n_nav >= r * p.corridor_cos)


MODES = tuple(Mode)
"""The modes in the order of their codes in compiled code (:mod:`swarm.core._guidance_nb`, ``M_*``)."""


def guidance_row(p: GuidanceParams) -> np.ndarray:
    """The parameters of :class:`GuidanceParams` as the compiled guidance reads them (``GP_*``)."""
    row = np.zeros(nb.GP_N)
    row[: nb.GP_NORMAL] = (
        p.half_size_m, p.align_distance_m, p.keepout_radius_m, p.keepout_margin_m, p.corridor_cos,
        p.approach_speed_m_s, p.align_speed_m_s, p.dock_speed_m_s, p.abort_speed_m_s, p.max_lead_m,
        p.stop_decel_m_s2, p.align_tolerance_m, p.align_attitude_tolerance_rad, p.align_speed_tolerance_m_s,
        p.dock_overshoot_m, p.contact_distance_m, p.hold_sigma_pos_m, p.resume_sigma_pos_m,
        p.hold_rejection_fraction, p.hold_nis_mean, p.abort_after_hold_s, p.abort_retreat_m, p.retry_after_s,
        p.arc_lookahead_rad, p.max_retries, p.stall_timeout_s, float(p.dock_requires_vision),
    )  # fmt: skip
    row[nb.GP_NORMAL : nb.GP_NORMAL + 3] = p.face_normal_target
    row[nb.GP_QTC : nb.GP_QTC + 4] = p.q_target_chaser_docked
    return row


def reason_text(p: GuidanceParams, code: int, r: float, x: float) -> str:
    """The words of a mode switch's reason ``code`` (``RS_*``), at range ``r`` [m], quoting ``x``."""
    if code == nb.RS_CONVERGED:
        return f"initial estimate converged (sigma_pos={x:.3f} m)"
    if code == nb.RS_HEALTHY:
        return f"estimate healthy again (sigma_pos={x:.3f} m)"
    if code == nb.RS_HOLD_LONG:
        return f"HOLD longer than {p.abort_after_hold_s:.0f} s"
    if code == nb.RS_SIGMA:
        return f"estimate not trustworthy: sigma_pos={x:.3f} m > {p.hold_sigma_pos_m} m"
    if code == nb.RS_REJECTED:
        return f"estimate not trustworthy: {x:.0%} of recent ranges rejected"
    if code == nb.RS_NIS:
        return f"estimate not trustworthy: mean NIS of recent ranges {x:.1f} > {p.hold_nis_mean}"
    if code == nb.RS_DOCK_UNHEALTHY:
        return "estimate not trustworthy inside the keep-out sphere"
    if code == nb.RS_R2:
        return f"r={r:.3f} m <= r2={x:.3f} m"
    if code == nb.RS_SKIP_ALIGN:
        return f"ALIGN skipped: already in the docking corridor with vision (sigma_pos={x * 1000:.1f} mm)"
    if code == nb.RS_R1:
        return f"r={r:.3f} m <= r1={x:.3f} m"
    if code == nb.RS_STALL:
        return f"held at the keep-out boundary {p.stall_timeout_s:.0f} s above r1={x:.3f} m"
    if code == nb.RS_AT_ALIGN:
        return "at the alignment point"
    if code == nb.RS_NO_VISION:
        return f"no vision at the alignment point for {p.abort_after_hold_s:.0f} s"
    if code == nb.RS_GAP:
        return f"estimated port gap {x * 1000:.1f} mm"
    if code == nb.RS_RETRY:
        return f"retry {int(x)} after abort"
    raise ValueError(f"unknown reason code {code!r}")


class ChaserGuidance:
    """Mode logic and reference generation of the chaser (module docstring).

    ``switcher`` is a :class:`swarm.core.mdp.FixedSwitcher` or :class:`swarm.core.mdp.MdpSwitcher`: it is
    asked at every evaluation inside ``r_t`` and supplies ``r1_m`` and ``r2_m``.

    The state is the array :attr:`G` and one evaluation is the compiled
    :func:`swarm.core._guidance_nb.chaser_step`, which the compiled closed loop calls directly; a mode
    switch it makes waits in :attr:`EV` until :meth:`drain_events` puts it into words and :attr:`history`.
    """

    def __init__(self, params: GuidanceParams, switcher, q_mission_nav_body, p_start_nav) -> None:
        self.p = params
        self.switcher = switcher
        self.GP = guidance_row(params)
        self.G = np.zeros(nb.G_N)
        self.G[nb.G_MODE] = nb.M_HOLD
        self.G[nb.G_RESUME] = nb.M_APPROACH
        self.G[nb.G_PREF : nb.G_PREF + 3] = np.asarray(p_start_nav, dtype=float)
        self.G[nb.G_STALL] = np.nan
        self.G[nb.G_QMIS : nb.G_QMIS + 4] = rot.quat_normalize(np.asarray(q_mission_nav_body, dtype=float))
        self.EV = np.zeros((nb.EV_MAX, nb.EV_N))
        self.EV_n = np.zeros(1, dtype=np.int64)
        self.REF = np.zeros(nb.REF_N)
        self.history: list[dict] = []

    # ---- the state, by name ---------------------------------------------------------------------------
    @property
    def mode(self) -> Mode:
        return MODES[int(self.G[nb.G_MODE])]

    @property
    def resume_mode(self) -> Mode:
        """The mode a HOLD resumes."""
        return MODES[int(self.G[nb.G_RESUME])]

    @property
    def started(self) -> bool:
        """The initial estimate has converged once (the chaser began to move)."""
        return bool(self.G[nb.G_STARTED])

    @property
    def p_ref(self) -> np.ndarray:
        """The reference position (the carrot) [m], frame nav."""
        return self.G[nb.G_PREF : nb.G_PREF + 3].copy()

    @property
    def mode_since_s(self) -> float:
        return float(self.G[nb.G_SINCE])

    @property
    def stall_since_s(self) -> float | None:
        v = float(self.G[nb.G_STALL])
        return None if math.isnan(v) else v

    @property
    def retries(self) -> int:
        return int(self.G[nb.G_RETRIES])

    @property
    def q_mission(self) -> np.ndarray:
        return self.G[nb.G_QMIS : nb.G_QMIS + 4].copy()

    # ---- events ------------------------------------------------------------------------------------
    def drain_events(self) -> list[dict]:
        """The switches made since the last call, as event records (``t_s``, ``from``, ``to``,
        ``range_m``, ``reason``), also appended to :attr:`history`."""
        out = []
        for i in range(int(self.EV_n[0])):
            row = self.EV[i]
            r = float(row[nb.E_R])
            out.append({
                "t_s": float(row[nb.E_T]), "from": MODES[int(row[nb.E_FROM])].value,
                "to": MODES[int(row[nb.E_TO])].value, "range_m": r,
                "reason": reason_text(self.p, int(row[nb.E_REASON]), r, float(row[nb.E_X])),
            })  # fmt: skip
        self.EV_n[0] = 0
        self.history.extend(out)
        return out

    # ---- one evaluation -------------------------------------------------------------------------
    def step(self, nav: NavInput, dt: float) -> Reference:
        f64 = np.float64
        sw = self.switcher
        before = int(sw.staged_n[0])
        nb.chaser_step(
            self.G, self.GP, sw.SW, np.asarray(nav.p_nav, f64), np.asarray(nav.v_nav, f64),
            np.asarray(nav.q_nav_body, f64), float(nav.sigma_pos_max_m), float(nav.mahalanobis_d),
            float(nav.rejection_fraction), bool(nav.vision), np.asarray(nav.p_target_nav, f64),
            np.asarray(nav.q_nav_target, f64), float(nav.t_s), float(dt), self.REF, self.EV, self.EV_n,
            sw.staged, sw.staged_n,
        )  # fmt: skip
        decision = sw.drain() if int(sw.staged_n[0]) > before else None
        return reference_of(self.REF, self.drain_events(), decision)


def reference_of(REF: np.ndarray, events: list[dict], decision=None) -> Reference:
    """The :class:`Reference` of a compiled reference row (``R_*``)."""
    return Reference(
        mode=MODES[int(REF[nb.R_MODE])], p_nav=REF[nb.R_P : nb.R_P + 3].copy(),
        v_nav=REF[nb.R_V : nb.R_V + 3].copy(), a_nav=REF[nb.R_A : nb.R_A + 3].copy(),
        q_nav_body=REF[nb.R_Q : nb.R_Q + 4].copy(), range_m=float(REF[nb.R_RANGE]), events=events,
        decision=decision,
    )  # fmt: skip


@dataclass(frozen=True)
class StationParams:
    """Dead-band station keeping of a target (paper section III: "the stationary target TPODS"): it fires
    only when its estimate says, with statistical significance, that it has left the dead band, so a target
    being docked on holds still instead of chasing the errors of its own estimate."""

    deadband_m: float = 0.04
    """Translation control starts when the estimated position leaves this ball around the station [m]
    (and the offset is significant, :attr:`significance_probability`) ..."""
    settle_m: float = 0.01
    """... and stops once back within this [m] ..."""
    settle_speed_m_s: float = 0.002
    """... and slower than this [m/s] (hysteresis: no limit cycle at the dead-band edge)."""
    deadband_deg: float = 3.0
    """Attitude control starts above this estimated attitude error [deg] ..."""
    settle_deg: float = 0.5
    """... and stops below this [deg]."""
    converged_sigma_m: float = 0.02
    """No control at all until the estimate's largest position sigma is below this [m]: the filter has
    converged from its initial covariance at all. Whether the translation may act is then the significance
    test's call (:attr:`significance_probability`), not this threshold's."""
    significance_probability: float = 0.9999
    """Translation control starts only when the estimated offset from the station rejects "the target is
    at its station" at this probability: ``|dp|^2 / sigma_max^2 > chi2.ppf(p, 3)`` (:class:`StationKeeping`).
    The false-alarm probability per control step is at most ``1 - p``; 0.9999 is the estimator's own
    gate probability (paper section IV-D) and puts the test at 4.6 sigma: 1.1 cm at the target's
    steady-state 2.45 mm (docs/results/anchors-docking), well inside the 4 cm dead band (with the earlier,
    over-sized process noise: 3.9 cm at 8.4 mm)."""

    def __post_init__(self) -> None:
        for name in (
            "deadband_m",
            "settle_m",
            "settle_speed_m_s",
            "deadband_deg",
            "settle_deg",
            "converged_sigma_m",
        ):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError(f"station.{name} must be a non-negative number, got {v!r}")
        p = self.significance_probability
        if not (np.isfinite(p) and 0.0 < p < 1.0):
            raise ConfigError(f"station.significance_probability must be in (0, 1), got {p!r}")

    @cached_property
    def significance_sigmas(self) -> float:
        """Radius of the significance test in units of the largest position sigma: ``sqrt(chi2.ppf(p, 3))``
        (4.6 for p = 0.9999)."""
        from scipy.stats import chi2  # here, not at the top: ~0.26 s of CPU at a process start

        return float(np.sqrt(chi2.ppf(self.significance_probability, 3)))


class StationKeeping:
    """The target's guidance: hold the initial pose (mode STATION) with a dead band (:class:`StationParams`).
    :attr:`translate` and :attr:`rotate` say whether the controllers should act this step.

    Why a significance test. The target starts at its station, at rest (paper Fig. 5, section III), and in
    free flight nothing but its own thrust moves it. Its prior is therefore exact, ``p = p_station``, and
    only evidence should overturn it: the estimated offset ``dp = p_est - p_station`` must reject that
    hypothesis in a chi-square test before the target fires (Bar-Shalom, Li & Kirubarajan, *Estimation with
    Applications to Tracking and Navigation*, 2001, sections 1.5.2 and 5.4: under the hypothesis
    ``dp^T P^-1 dp`` is chi-square with 3 degrees of freedom for a consistent filter). With only the
    largest position sigma at hand, ``|dp|^2 / sigma_max^2 <= dp^T P^-1 dp`` (Rayleigh quotient, Horn &
    Johnson, *Matrix Analysis*, Theorem 4.2.2), so the test used, ``|dp| > sqrt(chi2.ppf(p, 3)) sigma_max``,
    can only err towards not firing. Together with the dead band the translation starts when
    ``|dp| > max(deadband_m, 4.6 sigma_max)``: the dead band can never be narrower than what the estimate
    resolves.

    This replaces the earlier gate on the covariance alone (start as soon as ``sigma_max < 2 cm``). About
    0.4 s after start that gate opened while the estimate still carried 3-6 cm of the 5 cm per-axis initial
    error: in 5-10 % of seeds the target "corrected" towards a wrong station, limit-cycled in its dead band
    and put its docking port 2-4 cm away from where the chaser had latched it (docs/results/README.md,
    section 2). The test would have held: at the first firing of each of the 35 seeds the offset was 2.1-3.1
    sigma_max (4.2 in one seed, at 5.9 s), against 4.59. A gate on the innovation statistics would not: the
    target's windowed range NIS is
    about 1 during that transient (the filter is consistent; the offset is just within its uncertainty),
    and a settling time would be a number tuned to one geometry and one set of noises, where the test
    scales with the filter's own covariance wherever the target is.
    """

    def __init__(self, p_nav, q_nav_body, params: StationParams | None = None) -> None:
        self.params = params or StationParams()
        self.SP = station_row(self.params)
        self.ST = np.zeros(nb.ST_N)
        self.ST[nb.ST_PREF : nb.ST_PREF + 3] = np.asarray(p_nav, dtype=float)
        self.ST[nb.ST_QREF : nb.ST_QREF + 4] = rot.quat_normalize(np.asarray(q_nav_body, dtype=float))
        self.REF = np.zeros(nb.REF_N)
        self.mode = Mode.STATION
        self.history: list[dict] = []

    @property
    def p_ref(self) -> np.ndarray:
        return self.ST[nb.ST_PREF : nb.ST_PREF + 3].copy()

    @property
    def q_ref(self) -> np.ndarray:
        return self.ST[nb.ST_QREF : nb.ST_QREF + 4].copy()

    @property
    def translate(self) -> bool:
        """Translation control acts this step."""
        return bool(self.ST[nb.ST_TRANSLATE])

    @property
    def rotate(self) -> bool:
        """Attitude control acts this step."""
        return bool(self.ST[nb.ST_ROTATE])

    def offset_significant(self, offset_m: float, sigma_pos_max_m: float) -> bool:
        """Whether an estimated offset ``offset_m`` [m] from the station rejects "at the station" given the
        largest position sigma ``sigma_pos_max_m`` [m] (the chi-square test of the class docstring)."""
        return offset_m > self.params.significance_sigmas * sigma_pos_max_m

    def step(self, nav: NavInput, dt: float) -> Reference:
        """One evaluation (the compiled :func:`swarm.core._guidance_nb.station_step`)."""
        f64 = np.float64
        nb.station_step(
            self.ST, self.SP, np.asarray(nav.p_nav, f64), np.asarray(nav.v_nav, f64),
            np.asarray(nav.q_nav_body, f64), float(nav.sigma_pos_max_m), self.REF,
        )  # fmt: skip
        return reference_of(self.REF, [])


def station_row(p: StationParams) -> np.ndarray:
    """The parameters of :class:`StationParams` as the compiled station keeping reads them (``SP_*``)."""
    return np.array([
        p.deadband_m, p.settle_m, p.settle_speed_m_s, np.radians(p.deadband_deg), np.radians(p.settle_deg),
        p.converged_sigma_m, p.significance_sigmas,
    ], dtype=np.float64)  # fmt: skip
