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
from swarm.core import rotations as rot
from swarm.core._rot_nb import qrotate
from swarm.core.camera import solve_pnp
from swarm.core.estimator import PoseEstimator, UpdateStatus, chi2_gate
from swarm.core.guidance import ChaserGuidance, Mode, NavInput, Reference, StationKeeping
from swarm.core.mdp import make_switcher


@dataclass
class TargetEstimate:
    """The target's published estimate as the chaser uses it (frame nav)."""

    t_s: float
    p_nav: np.ndarray
    q_nav_body: np.ndarray
    cov_pos: np.ndarray


@dataclass
class Command:
    """Output of one control step."""

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
        self.control_dt = self.control_every * sc.dt_s
        est_params = sc.estimator_for(vehicle_id)
        self.est = PoseEstimator.create(est_params, p0_nav, v0_nav, q0_nav_body, cov0)
        self.controller = self.kind.controller()
        self.camera = sc.camera_for(vehicle_id)
        self.anchors = np.asarray(sc.anchors_m, dtype=float)
        self.markers_target = sc.markers.markers(sc.guidance.docking_face)
        if self.role == "chaser":
            self.switcher = make_switcher(policy, sc.mdp, sc.fixed)
            q_mission = rot.euler_to_quat(np.radians(spec.euler_deg), sc.euler_seq)
            self.guidance = ChaserGuidance(sc.guidance_for(vehicle_id), self.switcher, q_mission, p0_nav)
        else:
            self.switcher = None
            q_nom = rot.euler_to_quat(np.radians(spec.euler_deg), sc.euler_seq)
            self.guidance = StationKeeping(spec.position_m, q_nom, sc.station)
        self.target: TargetEstimate | None = None
        self.w_body = np.zeros(3)  # latest gyro rate, for the rate damping of an attitude law
        self.f_body = np.zeros(3)  # the filter's known input: it predicts with R(q) f_body / m
        self.plane = np.zeros(3)  # [z0, sigma_z, sigma_vz] of a planar kind's constraint; sigma 0: none
        constraint = self.kind.plane_constraint()
        if constraint is not None:
            self.plane[:] = (spec.position_m[2], *constraint)
        window = max(1, round(sc.agent.health_window_s * sc.uwb.rate_hz))
        self._gate_1d = chi2_gate(1, sc.estimator.gate_probability)
        self._gate_3d = chi2_gate(3, sc.estimator.gate_probability)
        self._ahrs_cov = np.radians(sc.ahrs.sigma_deg) ** 2 * np.eye(3)
        self._sigma_range = float(sc.estimator.sigma_range_m)
        # health windows of the recent ranges (a ring: [count, next]); see ``agent_uwb``
        self.h_ok = np.zeros(window, dtype=np.bool_)
        self.h_d2 = np.zeros(window)
        self.h_meta = np.zeros(2, dtype=np.int64)
        self._last_vision_s = -np.inf
        self.mode = self.guidance.mode
        self.last_command: Command | None = None
        self.t_s = 0.0

    # ---- the one step ---------------------------------------------------------------------------
    def tick(self, inp: AgentInputs) -> Command | None:
        """Tick ``inp.tick`` (module docstring): the inputs in order, then control on a control tick.
        Returns the new command on control ticks, else ``None`` (the last one is held)."""
        if inp.target is not None and self.role == "chaser":
            self.set_target_estimate(inp.target)
        if inp.gyro_body is not None:
            self.on_imu(inp.t_s, inp.dt_s, inp.gyro_body, inp.q_ahrs_nav_body)
        if inp.uwb is not None:
            self.on_uwb(*inp.uwb)
        if inp.vision is not None:
            self.on_vision(inp.t_s, *inp.vision)
        if inp.control and inp.tick % self.control_every == 0:
            return self.control(inp.t_s, self.control_dt)
        return None

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
            e.X[0], e.P[0], e.counts[0], e.book[0], e._prm, self.anchors[int(anchor_id)], float(range_m),
            self._sigma_range, self._gate_1d, self.h_ok, self.h_d2, self.h_meta,
        )  # fmt: skip

    def on_vision(self, t_s: float, kind: str, data: np.ndarray) -> int:
        """Vision of the target's docking-face markers: ``kind`` "features" (6, 3) marker positions in the
        camera frame [m] (the paper's model) or "pixels" (6, 2) for PnP on board."""
        if self.target is None:
            return int(UpdateStatus.SKIPPED)
        tgt = self.target
        cov_t = tgt.cov_pos if self.sc.agent.vision_target_cov else np.zeros((3, 3))
        if kind == "features":
            markers_nav = tgt.p_nav + rot.quat_rotate(tgt.q_nav_body, self.markers_target)
            status = int(self.est.update_features(markers_nav, data, target_cov_nav=cov_t)[0])
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

    def set_target_estimate(self, est: TargetEstimate) -> None:
        """The target's latest published estimate; held fixed while vision is available when
        ``agent.latch_target_with_vision`` (see :class:`swarm.scenario.AgentParams`)."""
        if self.sc.agent.latch_target_with_vision and self.relative_nav and self.target is not None:
            return
        self.target = est

    # ---- outputs ------------------------------------------------------------------------------------
    def estimate(self) -> TargetEstimate:
        """This vehicle's estimate in the form another agent consumes."""
        return TargetEstimate(
            self.t_s, self.est.p_nav[0].copy(), self.est.q_nav_body[0].copy(), self.est.P[0, :3, :3].copy()
        )

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

    def control(self, t_s: float, dt_s: float) -> Command:
        """Guidance, switcher and the kind's controller on the current estimate; returns the command."""
        est = self.est
        p, v, q = est.p_nav[0].copy(), est.v_nav[0].copy(), est.q_nav_body[0].copy()
        tgt = self.target
        nav = NavInput(
            t_s=t_s,
            p_nav=p,
            v_nav=v,
            q_nav_body=q,
            sigma_pos_max_m=self.sigma_pos_max_m,
            # the target's station keeping reads neither: spare it the two window means
            mahalanobis_d=self.mahalanobis_d if self.role == "chaser" else 0.0,
            rejection_fraction=self.rejection_fraction if self.role == "chaser" else 0.0,
            vision=self.vision_recent,
            p_target_nav=tgt.p_nav if tgt is not None else p,
            q_nav_target=tgt.q_nav_body if tgt is not None else q,
        )
        if self.role == "chaser" and tgt is None:  # nothing to fly to yet: hold still
            ref = Reference(Mode.HOLD, p, np.zeros(3), np.zeros(3), q, 0.0)
        else:
            ref = self.guidance.step(nav, dt_s)
        if ref.events:
            self.controller.reset()
        self.mode = ref.mode
        station = self.guidance if isinstance(self.guidance, StationKeeping) else None
        idle = station is not None and not (station.translate or station.rotate)
        if ref.mode is Mode.DOCKED:  # the kind's last act: drift in (a cube) or drive in (a rover)
            act = self.controller.docked(self.sc.guidance.dock_speed_m_s)
        elif idle:  # a target inside its dead band: actuators off
            self.controller.reset()
            act = self.controller.idle()
        else:
            translate = station is None or station.translate
            rotate = station is None or station.rotate
            act = self.controller.step(p, v, q, self.w_body, ref, translate, rotate)
        self.f_body[:] = act.f_body_known_n
        cmd = Command(t_s, act.u, act.force_body_n, act.torque_body_nm, act.saturated, ref, list(ref.events))
        self.last_command = cmd
        return cmd


_NO_Q = np.zeros(4)


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
def agent_uwb(X, P, ST_I, ST_F, PRM, anchor_nav, range_m, sigma_m, gate1, h_ok, h_d2, h_meta):
    """One UWB range of one filter; a gated outcome (accepted or rejected) enters the health ring:
    accepted or not, and the squared Mahalanobis distance clipped at the gate (Algorithm 1's d)."""
    status = nb.update_range_one(X, P, ST_I, ST_F, PRM, anchor_nav, range_m, sigma_m, gate1)
    if status == nb.ST_ACCEPTED or status == nb.ST_REJECTED:
        i = h_meta[1]
        h_ok[i] = status == nb.ST_ACCEPTED
        h_d2[i] = min(ST_F[nb.STF_D2 + nb.TYPE_RANGE], gate1)
        h_meta[1] = (i + 1) % h_ok.shape[0]
        h_meta[0] = min(h_meta[0] + 1, h_ok.shape[0])
    return status


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
