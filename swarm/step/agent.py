"""The agent step: one vehicle's on-board software (estimator, switcher, guidance, its kind's controller).

:class:`VehicleAgent` is what runs inside an agent process (``python -m agents``), inside the in-process
simulation (:mod:`swarm.sim.docking`) and over a log in replay: each feeds it the same inputs in the same
order through :meth:`VehicleAgent.tick` and reads the same command, so one seed gives one trajectory in
every runner. It does no I/O.

Per tick ``k`` (the IMU period) :meth:`~VehicleAgent.tick` takes, in this order (docs/architecture.md, "The
one tick"): the target's published estimate of tick ``k - 1`` (a chaser), the gyro (+ AHRS) sample, the UWB
range, the camera frame; then, on the vehicle's control ticks, guidance, Algorithm 1 and the controller of
its kind, whose actuator command the world holds until the next control tick. The sensor part on the
filter's arrays is :func:`agent_sensors`, compiled; the in-process runner's fast path calls that very
function for the ticks without control or camera (:mod:`swarm.step.tick`). The chaser's guidance and vision
use the target's *published estimate*, never the truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from swarm.core import _ekf_nb as nb
from swarm.core import _guidance_nb as gnb
from swarm.core import rotations as rot
from swarm.core._rot_nb import qrotate
from swarm.core.camera import POSE_N, solve_pnp
from swarm.core.estimator import UpdateStatus, chi2_gate
from swarm.core.guidance import ChaserGuidance, Mode, Reference, StationKeeping, reference_of
from swarm.core.mdp import D_N, SW_N, make_switcher
from swarm.kinds._dispatch import Controller, control_step, docked_step, idle_step
from swarm.kinds.base import ACT_N
from swarm.navigation import NAVIGATORS


@dataclass
class TargetEstimate:
    """The target's published estimate as the chaser uses it (frame nav)."""

    t_s: float
    p_nav: np.ndarray
    q_nav_body: np.ndarray
    cov_pos: np.ndarray


@dataclass
class ControlOutput:
    """Output of one control step (the wire's message is :class:`swarm.transport.messages.Command`)."""

    t_s: float
    u: np.ndarray
    """The kind's actuator command (nozzle thrusts [N], wheel speeds [rad/s]), held until the next."""
    force_body_n: np.ndarray | None
    """Achieved net force (3,) [N], body frame, where the kind has one (the nozzles)."""
    torque_body_nm: np.ndarray | None
    """Achieved net torque (3,) [N m], body frame, where the kind has one."""
    saturated: bool
    reference: Reference
    events: list[dict] = field(default_factory=list)

    @property
    def thrusts_n(self) -> np.ndarray:
        """A cube's command: its nozzle thrusts [N] (``u``)."""
        return self.u


@dataclass
class AgentInputs:
    """Everything one agent takes at tick ``k`` (module docstring), ``None`` where a sample is absent."""

    tick: int
    t_s: float
    dt_s: float
    """Interval the gyro sample integrates over [s] (a free-running agent that skipped ticks: the gap)."""
    gyro_body: np.ndarray | None = None
    q_ahrs_nav_body: np.ndarray | None = None
    uwb: tuple[int, float] | None = None
    """``(anchor_id, range_m)`` of the tick's exchange; ``None`` without one or when the reply was lost."""
    vision: tuple[str, np.ndarray] | None = None
    """``(kind, data)`` of a camera frame that saw markers (``"features"`` (N, 3) or ``"pixels"`` (N, 2))."""
    target: TargetEstimate | None = None
    """A chaser's target estimate of tick ``k - 1``."""
    control: bool = True
    """False: take the inputs only, decide nothing (a chaser whose run is over)."""
    tdoa: np.ndarray | None = None
    """(K, 3) distance differences heard since the last UWB tick (``uwb.mode`` tdoa2/tdoa3): anchor ``A``,
    anchor ``B``, ``d_B - d_A`` [m]; ``None`` without any."""
    """False: take the inputs only, decide nothing (a chaser whose run is over)."""


class VehicleAgent:
    """Estimator + switcher + guidance + the kind's controller of one vehicle (module docstring).

    ``scenario`` is a :class:`swarm.scenario.Scenario`; ``vehicle_id`` names the vehicle in it;
    ``p0_nav``/``v0_nav``/``q0_nav_body`` is the initial estimate and ``cov0`` its covariance (9,).
    """

    def __init__(self, scenario, vehicle_id: str, p0_nav, v0_nav, q0_nav_body, cov0, policy: str) -> None:
        sc = scenario
        spec = sc.vehicles[vehicle_id]
        self.id = vehicle_id
        self.role = spec.role
        self.target_id = spec.target
        self.sc = sc
        self.kind = sc.kind(vehicle_id)
        self.mass_kg = float(self.kind.mass_kg)
        self.control_every = sc.control_every(vehicle_id)
        self.control_phase = sc.control_phase(vehicle_id)
        self.control_dt = self.control_every * sc.dt_s
        est_params = sc.estimator_for(vehicle_id)
        # the vehicle's navigator (swarm.navigation): the scenario admits the MEKF only, on whose arrays X, P,
        # counts, book (filter 0) the compiled steps below run
        self.est = NAVIGATORS[sc.navigation(vehicle_id)].for_docking(
            sc, vehicle_id, p0_nav, v0_nav, q0_nav_body, cov0
        )
        self.controller = Controller(self.kind)
        self.camera = sc.camera_for(vehicle_id)
        self.anchors = np.asarray(sc.anchors_m, dtype=float)
        self.markers_target = np.ascontiguousarray(sc.markers.markers(sc.guidance.docking_face), dtype=float)
        if self.role == "chaser":
            self.switcher = make_switcher(policy, sc.mdp, sc.fixed)
            q_mission = rot.euler_to_quat(np.radians(spec.euler_deg), sc.euler_seq)
            self.guidance = ChaserGuidance(sc.guidance_for(vehicle_id), self.switcher, q_mission, p0_nav)
        else:
            self.switcher = None
            q_nom = rot.euler_to_quat(np.radians(spec.euler_deg), sc.euler_seq)
            self.guidance = StationKeeping(spec.position_m, q_nom, sc.station)
        self.TGT = np.zeros(TG_N)
        """The target's estimate as the chaser uses it (``TG_*``; ``TG_HAS`` 0: none yet)."""
        self.w_body = np.zeros(3)  # latest gyro rate, for the rate damping of an attitude law
        self.f_body = np.zeros(3)  # the filter's known input: it predicts with R(q) f_body / m
        self.plane = np.zeros(3)  # [z0, sigma_z, sigma_vz] of a planar kind's constraint; sigma 0: none
        constraint = self.kind.plane_constraint()
        if constraint is not None:
            self.plane[:] = (spec.position_m[2], *constraint)
        window = max(1, round(sc.agent.health_window_s * sc.uwb.rate_hz))
        self._gate_1d = chi2_gate(1, sc.estimator.gate_probability)
        self._gate_3d = chi2_gate(3, sc.estimator.gate_probability)
        self._gate_6d = chi2_gate(6, sc.estimator.gate_probability)
        self._gate_features = chi2_gate(3 * len(self.markers_target), est_params.gate_probability)
        self._sigma_feature = float(est_params.sigma_feature_m)
        self._ahrs_cov = np.radians(sc.ahrs.sigma_deg) ** 2 * np.eye(3)
        self._sigma_range = float(sc.estimator.sigma_range_m)
        self._sigma_tdoa = float(sc.estimator.sigma_tdoa_m)
        # health windows of the recent ranges (a ring: [count, next]); see ``agent_uwb``
        self.h_ok = np.zeros(window, dtype=np.bool_)
        self.h_d2 = np.zeros(window)
        self.h_meta = np.zeros(2, dtype=np.int64)
        self._last_vision_s = -np.inf
        self.mode = self.guidance.mode
        self.last_command: ControlOutput | None = None
        self.t_s = 0.0
        # the compiled control step's arrays (agent_control); a role's unused ones are placeholders
        self.role_code = ROLE_CHASER if self.role == "chaser" else ROLE_TARGET
        g = self.guidance
        if isinstance(g, ChaserGuidance):
            self.G, self.GP, self.EV, self.EV_n = g.G, g.GP, g.EV, g.EV_n
            self.SW, self.DEC, self.DEC_n = self.switcher.SW, self.switcher.staged, self.switcher.staged_n
            self.ST, self.SP = np.zeros(gnb.ST_N), np.zeros(gnb.SP_N)
        else:
            self.G, self.GP = np.zeros(gnb.G_N), np.zeros(gnb.GP_N)
            self.EV, self.EV_n = np.zeros((1, gnb.EV_N)), np.zeros(1, dtype=np.int64)
            self.SW, self.DEC, self.DEC_n = np.zeros(SW_N), np.zeros((1, D_N)), np.zeros(1, dtype=np.int64)
            self.ST, self.SP = g.ST, g.SP
        self.CS, self.CP = self.controller.cs, self.controller.cp
        self.REF = np.zeros(gnb.REF_N)
        self.U = np.zeros(max(self.kind.U_N, 1))
        self.ACT = np.zeros(ACT_N)
        self.dock_speed = float(sc.guidance.dock_speed_m_s)

    # ---- the one step ---------------------------------------------------------------------------
    def tick(self, inp: AgentInputs) -> ControlOutput | None:
        """Tick ``inp.tick`` (module docstring): the inputs in order, then control on a control tick.
        Returns the new command on control ticks, else ``None`` (the last one is held)."""
        if inp.target is not None and self.role == "chaser":
            self.set_target_estimate(inp.target)
        if inp.gyro_body is not None:
            self.on_imu(inp.t_s, inp.dt_s, inp.gyro_body, inp.q_ahrs_nav_body)
        if inp.uwb is not None:
            self.on_uwb(*inp.uwb)
        if inp.tdoa is not None:
            self.on_tdoa(inp.tdoa)
        if inp.vision is not None:
            self.on_vision(inp.t_s, *inp.vision)
        return self.decide(inp.tick, inp.t_s) if inp.control else None

    def decide(self, tick: int, t_s: float) -> ControlOutput | None:
        """Guidance and control on tick ``tick`` if it is a control tick (its new command), else ``None``:
        the second half of :meth:`tick`, for a runner that publishes the estimate between the two (a
        free-running agent process)."""
        if self.is_control_tick(tick):
            return self.control(t_s, self.control_dt)
        return None

    def is_control_tick(self, tick: int) -> bool:
        """Whether this vehicle controls on tick ``tick``: every control period from its
        ``control_phase`` on (:class:`swarm.scenario.VehicleSpec`)."""
        return (tick - self.control_phase) % self.control_every == 0

    # ---- sensor inputs ------------------------------------------------------------------------------
    def on_imu(self, t_s: float, dt_s: float, gyro_body, q_ahrs_nav_body=None) -> int:
        """Propagate the filter with the gyro over ``dt_s`` (paper eq. 3) and the known acceleration of
        the command in force; fuse the AHRS attitude when the vehicle has one."""
        self.t_s = t_s
        gyro = np.ascontiguousarray(gyro_body, dtype=np.float64)
        has_ahrs = q_ahrs_nav_body is not None
        q = np.ascontiguousarray(q_ahrs_nav_body, dtype=np.float64) if has_ahrs else _NO_Q
        if gyro.shape != (3,) or q.shape != (4,):
            return int(UpdateStatus.REFUSED_INVALID)
        e = self.est
        return agent_imu(
            e.X[0], e.P[0], e.counts[0], e.book[0], e._prm, gyro, float(dt_s), self.f_body, self.mass_kg,
            self.w_body, has_ahrs, q, self._ahrs_cov, self._gate_3d, self.plane,
        )  # fmt: skip

    def on_uwb(self, anchor_id: int, range_m: float) -> int:
        """One two-way range to anchor ``anchor_id`` (index into the scenario's anchors)."""
        if not (0 <= int(anchor_id) < len(self.anchors)):
            return int(UpdateStatus.REFUSED_INVALID)
        if not self.sc.agent.uwb_with_vision and self.relative_nav:
            return int(UpdateStatus.SKIPPED)  # vision is the primary measurement near the target
        e = self.est
        return agent_uwb(
            e.X[0], e.P[0], e.counts[0], e.book[0], e._prm, self.anchors[int(anchor_id)], int(anchor_id),
            float(range_m), self._sigma_range, self._gate_1d, self.h_ok, self.h_d2, self.h_meta,
        )  # fmt: skip

    def on_tdoa(self, rows: np.ndarray) -> int:
        """The distance differences ``rows`` (K, 3) (:class:`AgentInputs`), each fused as one scalar update
        (:func:`swarm.core._ekf_nb.update_tdoa_one`) and entered in the health ring as a range is; skipped
        near the target as ranges are. Returns how many were accepted."""
        if not self.sc.agent.uwb_with_vision and self.relative_nav:
            return 0
        r = np.ascontiguousarray(rows, dtype=np.float64)
        if r.ndim != 2 or r.shape[1] != 3:
            return 0
        e = self.est
        return agent_tdoa(
            e.X[0], e.P[0], e.counts[0], e.book[0], e._prm, self.anchors, r, self._sigma_tdoa, self._gate_1d,
            self.h_ok, self.h_d2, self.h_meta,
        )  # fmt: skip

    def on_vision(self, t_s: float, kind: str, data: np.ndarray) -> int:
        """Vision of the target's docking-face markers: ``kind`` "features" (6, 3) marker positions in the
        camera frame [m] (the paper's model), "pixels" (6, 2) for PnP on board, or "pose" (43,) an on-board
        PnP's relative pose and covariance (:func:`agent_pose`)."""
        if self.target is None:
            return int(UpdateStatus.SKIPPED)
        tgt = self.target
        cov_t = tgt.cov_pos if self.sc.agent.vision_target_cov else np.zeros((3, 3))
        if kind == "features":
            f = np.ascontiguousarray(data, dtype=np.float64)
            if f.shape != self.markers_target.shape:
                return int(UpdateStatus.REFUSED_INVALID)
            e = self.est
            status = agent_features(
                e.X[0], e.P[0], e.counts[0], e.book[0], e._prm, self.TGT, f.reshape(-1),
                self.markers_target, self.sc.agent.vision_target_cov, self._sigma_feature, e._cam_pos,
                e._R_bc, self._gate_features,
            )  # fmt: skip
        elif kind == "pose":
            frame = np.ascontiguousarray(data, dtype=np.float64).reshape(-1)
            if frame.shape != (POSE_N,):
                return int(UpdateStatus.REFUSED_INVALID)
            e = self.est
            status = agent_pose(
                e.X[0], e.P[0], e.counts[0], e.book[0], e._prm, self.TGT, frame,
                self.sc.agent.vision_target_cov, e._cam_pos, e._R_bc, e._q_bc, self._gate_6d,
            )  # fmt: skip
        elif kind == "pixels":
            pnp = solve_pnp(np.asarray(data, dtype=float), self.markers_target, self.camera)
            if pnp is None:
                return int(UpdateStatus.REFUSED_INVALID)
            status = int(
                self.est.update_pose(
                    tgt.p_nav, tgt.q_nav_body, pnp.t_cam_m, pnp.q_cam_target, pnp.cov_cam, cov_t
                )[0]
            )
        else:
            return int(UpdateStatus.REFUSED_INVALID)
        if status == UpdateStatus.ACCEPTED:
            self._last_vision_s = t_s
        return status

    @property
    def vision_recent(self) -> bool:
        return self.t_s - self._last_vision_s <= self.sc.agent.vision_recent_s

    @property
    def docking_on_vision(self) -> bool:
        """In the final approach (DOCK, DOCKED) with vision acquired during it at some point."""
        return self.mode in (Mode.DOCK, Mode.DOCKED) and self._last_vision_s > -np.inf

    @property
    def relative_nav(self) -> bool:
        """Navigating relative to the target (:func:`relative_nav`)."""
        return relative_nav(
            self.t_s, self._last_vision_s, self.sc.agent.vision_recent_s, self.docking_on_vision
        )

    def published_cov(self) -> np.ndarray:
        """The 9 x 9 covariance this vehicle publishes: its filter's, with the position block in nav
        (:func:`absolute_cov_pos`: the target's uncertainty added while it navigates relative to it)."""
        P = self.est.covariance()
        absolute_cov_pos(self.est.P[0], self.TGT, self.role == "chaser" and self.relative_nav, P[:3, :3])
        return P

    @property
    def target(self) -> TargetEstimate | None:
        """The target's estimate this chaser uses (None before the first)."""
        T = self.TGT
        if T[TG_HAS] == 0.0:
            return None
        return TargetEstimate(
            float(T[TG_T]), T[TG_P : TG_P + 3].copy(), T[TG_Q : TG_Q + 4].copy(),
            T[TG_COV : TG_COV + 9].reshape(3, 3).copy(),
        )  # fmt: skip

    def set_target_estimate(self, est: TargetEstimate) -> None:
        """The target's latest published estimate; held fixed while vision is available when
        ``agent.latch_target_with_vision`` (see :class:`swarm.scenario.AgentParams`)."""
        if self.sc.agent.latch_target_with_vision and self.relative_nav and self.TGT[TG_HAS] != 0.0:
            return
        T = self.TGT
        T[TG_HAS] = 1.0
        T[TG_T] = est.t_s
        T[TG_P : TG_P + 3] = est.p_nav
        T[TG_Q : TG_Q + 4] = est.q_nav_body
        T[TG_COV : TG_COV + 9] = np.asarray(est.cov_pos, dtype=float).ravel()

    # ---- outputs ------------------------------------------------------------------------------------
    def estimate(self) -> TargetEstimate:
        """This vehicle's estimate in the form another agent consumes."""
        s = self.est.state()
        return TargetEstimate(self.t_s, s.p_nav, s.q_nav_body, self.est.covariance()[:3, :3].copy())

    @property
    def sigma_pos_max_m(self) -> float:
        return float(self.est.sigma_pos_max_m[0])

    @property
    def mahalanobis_d(self) -> float:
        """RMS Mahalanobis distance of the recent ranges, each clipped at the gate (Algorithm 1's d)."""
        return window_stats(self.h_ok, self.h_d2, self.h_meta)[0]

    @property
    def rejection_fraction(self) -> float:
        return window_stats(self.h_ok, self.h_d2, self.h_meta)[1]

    def control(self, t_s: float, dt_s: float) -> ControlOutput:
        """Guidance, switcher and the kind's controller on the current estimate (the compiled
        :func:`agent_control`); returns the command."""
        est = self.est
        sw = self.switcher
        staged = int(self.DEC_n[0])
        saturated = agent_control(
            self.role_code, self.kind.code, float(t_s), float(dt_s), est.X[0], est.P[0], self.h_ok,
            self.h_d2, self.h_meta, float(self._last_vision_s), float(self.sc.agent.vision_recent_s),
            self.w_body, self.f_body, self.TGT, self.G, self.GP, self.SW, self.DEC, self.DEC_n, self.EV,
            self.EV_n, self.ST, self.SP, self.CS, self.CP, self.REF, self.U, self.ACT, self.dock_speed,
        )  # fmt: skip
        return self.command_of(t_s, saturated, sw is not None and int(self.DEC_n[0]) > staged)

    def command_of(self, t_s: float, saturated: bool, decided: bool = False) -> ControlOutput:
        """The :class:`ControlOutput` of the compiled step's outputs (``REF``, ``U``, ``ACT``): its mode
        switches and Algorithm 1 pass (``decided``) put into records."""
        events = self.guidance.drain_events() if self.role_code == ROLE_CHASER else []
        decision = self.switcher.drain() if decided else None
        ref = reference_of(self.REF, events, decision)
        self.mode = ref.mode
        act = self.controller._actuation(self.U, self.ACT, saturated)
        cmd = ControlOutput(
            float(t_s), act.u, act.force_body_n, act.torque_body_nm, act.saturated, ref, list(events)
        )
        self.last_command = cmd
        return cmd


ROLE_CHASER = 0
ROLE_TARGET = 1

# the target's estimate as a chaser holds it (VehicleAgent.TGT)
TG_HAS, TG_T, TG_P, TG_Q, TG_COV = 0, 1, 2, 5, 9
TG_N = 18


@njit(cache=True)
def agent_control(role, code, t, dt, X, P, h_ok, h_d2, h_meta, last_vision, recent_s, w_body, f_body, TGT, G,
                  GP, SW, DEC, DEC_n, EV, EV_n, ST, SP, CS, CP, REF, U, ACT, dock_speed):  # fmt: skip
    """One control step of one agent at ``t`` [s] for a control period ``dt`` [s] (module docstring): the
    navigation input from the filter (``X``, ``P``), the health window and the last accepted vision; the
    chaser's guidance and Algorithm 1 (:func:`swarm.core._guidance_nb.chaser_step`, toward the target
    estimate ``TGT``; HOLD where it is without one) or the target's station keeping
    (:func:`~swarm.core._guidance_nb.station_step`); then its kind's controller
    (:func:`swarm.kinds._dispatch.control_step`; all off for a station keeper in its dead band, the kind's
    docked command once DOCKED), whose integral restarts on a mode switch. Writes the reference ``REF``,
    the command ``U``, ``ACT`` and the filter's known force ``f_body``; returns whether an actuator limit
    scaled the command down."""
    p = X[0:3].copy()
    v = X[3:6].copy()
    q = X[6:10].copy()
    lam = nb.max_eig_sym3(P[0, 0], P[0, 1], P[0, 2], P[1, 1], P[1, 2], P[2, 2])
    sigma = np.sqrt(max(lam, 0.0))
    ev0 = EV_n[0]
    if role == ROLE_CHASER:
        if TGT[TG_HAS] == 0.0:  # nothing to fly to yet: hold still
            gnb.hold_reference(p, q, REF)
        else:
            d, rej = window_stats(h_ok, h_d2, h_meta)
            vision = t - last_vision <= recent_s
            gnb.chaser_step(G, GP, SW, p, v, q, sigma, d, rej, vision, TGT[TG_P : TG_P + 3],
                            TGT[TG_Q : TG_Q + 4], t, dt, REF, EV, EV_n, DEC, DEC_n)  # fmt: skip
    else:
        gnb.station_step(ST, SP, p, v, q, sigma, REF)
    if EV_n[0] > ev0:
        CS[:] = 0.0
    mode = int(REF[gnb.R_MODE])
    translate = REF[gnb.R_TRANSLATE] != 0.0
    rotate = REF[gnb.R_ROTATE] != 0.0
    saturated = False
    if mode == gnb.M_DOCKED:  # the kind's last act: drift in (a cube) or drive in (a rover)
        docked_step(code, CP, dock_speed, U, ACT)
    elif role == ROLE_TARGET and not (translate or rotate):  # inside its dead band: actuators off
        CS[:] = 0.0
        idle_step(code, CP, U, ACT)
    else:
        saturated = control_step(code, CS, CP, p, v, q, w_body, REF, translate, rotate, U, ACT)
    for i in range(3):
        f_body[i] = ACT[i]
    return saturated


_NO_Q = np.zeros(4)


@njit(cache=True)
def absolute_cov_pos(P_est, TGT, rel, out):
    """The covariance (3, 3) of the chaser's position in nav, into ``out``: while it navigates relative to
    its target (``rel``), its filter's position covariance is that of the position *relative to the
    target's estimate* it used (vision with millimetre noise, ranges off), and the target's estimate error
    is in its nav position whole: ``P_pos + P_target`` (a first-order consider covariance; the target
    estimate is latched while vision lasts, ``agent.latch_target_with_vision``, so that error is one
    constant). Otherwise its filter's own position covariance. Published in ``Estimate.cov`` and recorded
    in the series (the NEES against truth); guidance keeps the relative one, which is what docking needs."""
    for i in range(3):
        for j in range(3):
            out[i, j] = P_est[i, j]
    if rel and TGT[TG_HAS] != 0.0:
        for i in range(3):
            for j in range(3):
                out[i, j] += TGT[TG_COV + 3 * i + j]


@njit(cache=True)
def relative_nav(t_s, last_vision_s, recent_s, docking_on_vision):
    """Whether an agent navigates relative to its target at ``t_s``: a vision update was accepted within
    ``recent_s`` [s], or it docks on vision acquired during this final approach (the camera loses the
    markers in the last centimetres, which are flown on the IMU). Then its ranges are skipped unless
    ``agent.uwb_with_vision``."""
    return t_s - last_vision_s <= recent_s or docking_on_vision


@njit(cache=True)
def agent_imu(
    X, P, ST_I, ST_F, PRM, gyro, dt, f_body, mass, w_body, has_ahrs, q_ahrs, ahrs_cov, gate3, plane
):
    """One IMU sample of one filter: predict with the gyro (paper eq. 3) and the known acceleration of the
    command in force, ``a_nav = R(q) f_body / m`` (the force acts along the body axes, expressed with the
    current attitude estimate); then the AHRS attitude when there is one; then, for a planar vehicle
    (``plane = [z0, sigma_z, sigma_vz]``, ``sigma_z > 0``), the table's constraint
    (:func:`swarm.core._ekf_nb.constrain_plane_one`). Keeps the latest finite gyro rate in ``w_body`` for
    the attitude law's rate damping. Returns the predict status."""
    if np.isfinite(gyro[0]) and np.isfinite(gyro[1]) and np.isfinite(gyro[2]):
        w_body[:] = gyro
    a = qrotate(X[6:10], f_body)
    for i in range(3):
        a[i] /= mass
    status = nb.predict_one(X, P, ST_I, ST_F, gyro, a, dt, PRM)
    if has_ahrs:
        nb.update_attitude_one(X, P, ST_I, ST_F, PRM, q_ahrs, ahrs_cov, gate3)
    if plane[1] > 0.0:
        nb.constrain_plane_one(X, P, PRM, plane[0], plane[1], plane[2])
    return status


@njit(cache=True)
def agent_uwb(X, P, ST_I, ST_F, PRM, anchor_nav, anchor_idx, range_m, sigma_m, gate1, h_ok, h_d2, h_meta):
    """One UWB range of one filter to anchor ``anchor_idx`` at ``anchor_nav`` (its range-error terms enter
    when the filter has them); a gated outcome (accepted or rejected) enters the health ring: accepted or
    not, and the squared Mahalanobis distance clipped at the gate (Algorithm 1's d)."""
    status = nb.update_range_anchor_one(
        X, P, ST_I, ST_F, PRM, anchor_nav, anchor_idx, range_m, sigma_m, gate1
    )
    health_push(status, ST_F, gate1, h_ok, h_d2, h_meta)
    return status


@njit(cache=True)
def health_push(status, ST_F, gate1, h_ok, h_d2, h_meta):
    """A gated UWB outcome (accepted or rejected; a refusal is not one) into the health ring: accepted or
    not, and its squared Mahalanobis distance clipped at the gate (Algorithm 1's d)."""
    if status == nb.ST_ACCEPTED or status == nb.ST_REJECTED:
        i = h_meta[1]
        h_ok[i] = status == nb.ST_ACCEPTED
        h_d2[i] = min(ST_F[nb.STF_D2 + nb.TYPE_RANGE], gate1)
        h_meta[1] = (i + 1) % h_ok.shape[0]
        h_meta[0] = min(h_meta[0] + 1, h_ok.shape[0])


@njit(cache=True)
def agent_tdoa(X, P, ST_I, ST_F, PRM, anchors, rows, sigma_m, gate1, h_ok, h_d2, h_meta):
    """The distance differences ``rows`` (K, 3) of one filter (:meth:`VehicleAgent.on_tdoa`): a row naming an
    anchor the scenario does not have is refused and counted; each gated outcome enters the health ring as
    :func:`agent_uwb`'s does. Returns the number accepted."""
    m = anchors.shape[0]
    accepted = 0
    for k in range(rows.shape[0]):
        fa, fb = rows[k, 0], rows[k, 1]
        if not (0.0 <= fa < m and 0.0 <= fb < m and fa == int(fa) and fb == int(fb)):
            ST_I[nb.COUNT_REFUSED, nb.TYPE_RANGE] += 1
            continue
        ia, ib = int(fa), int(fb)
        z = rows[k, 2]
        a, b = anchors[ia], anchors[ib]
        status = nb.update_tdoa_one(X, P, ST_I, ST_F, PRM, a, b, ia, ib, z, sigma_m, gate1)
        health_push(status, ST_F, gate1, h_ok, h_d2, h_meta)
        accepted += status == nb.ST_ACCEPTED
    return accepted


@njit(cache=True)
def window_stats(h_ok, h_d2, h_meta):
    """``(d, rejection_fraction)`` of the health ring (:func:`agent_uwb`): the RMS of the recent
    Mahalanobis distances (each clipped at the gate; Algorithm 1's d) and the fraction rejected; zeros
    when no range has been gated yet."""
    count = h_meta[0]
    if count == 0:
        return 0.0, 0.0
    s_d2 = 0.0
    n_ok = 0
    for i in range(count):
        s_d2 += h_d2[i]
        n_ok += 1 if h_ok[i] else 0
    return np.sqrt(s_d2 / count), 1.0 - n_ok / count


@njit(cache=True)
def agent_features(X, P, ST_I, ST_F, PRM, TGT, frame, markers_t, use_target_cov, sigma, cam_pos, R_bc, gate):
    """A ``"features"`` camera frame (the paper's model: ``frame`` (3 N,) the N markers' positions in the
    camera frame, marker by marker) fused against the markers placed by the target estimate ``TGT``
    (``p_t + R(q_t) m``; its position covariance counted when ``use_target_cov``;
    :func:`swarm.core._ekf_nb.update_features_one`). Returns the update status."""
    cov_t = np.zeros((3, 3))
    if use_target_cov:
        for i in range(3):
            for j in range(3):
                cov_t[i, j] = TGT[TG_COV + 3 * i + j]
    n = markers_t.shape[0]
    mk = np.empty((n, 3))
    f = np.empty((n, 3))
    q_t = TGT[TG_Q : TG_Q + 4].copy()
    for m in range(n):
        r = qrotate(q_t, markers_t[m])
        for i in range(3):
            mk[m, i] = TGT[TG_P + i] + r[i]
            f[m, i] = frame[3 * m + i]
    return nb.update_features_one(X, P, ST_I, ST_F, PRM, mk, f, sigma, cov_t, cam_pos, R_bc, gate)


@njit(cache=True)
def agent_pose(X, P, ST_I, ST_F, PRM, TGT, frame, use_target_cov, cam_pos, R_bc, q_bc, gate6):
    """A ``"pose"`` camera frame (:func:`swarm.core.camera.pose_frame`: the target's pose in the camera frame
    and its covariance) fused against the target estimate ``TGT`` (its position covariance counted when
    ``use_target_cov``; :func:`swarm.core._ekf_nb.update_pose_one`). Returns the update status."""
    cov_t = np.zeros((3, 3))
    if use_target_cov:
        for i in range(3):
            for j in range(3):
                cov_t[i, j] = TGT[TG_COV + 3 * i + j]
    cov = np.empty((6, 6))
    for i in range(6):
        for j in range(6):
            cov[i, j] = frame[7 + 6 * i + j]
    p_t, q_t = TGT[TG_P : TG_P + 3].copy(), TGT[TG_Q : TG_Q + 4].copy()
    t_cam, q_cam = frame[0:3].copy(), frame[3:7].copy()
    return nb.update_pose_one(
        X, P, ST_I, ST_F, PRM, p_t, q_t, t_cam, q_cam, cov, cov_t, cam_pos, R_bc, q_bc, gate6
    )
