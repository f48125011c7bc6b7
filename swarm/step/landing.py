"""The landing tick (paper section VI-B; ``docs/architecture.md``, "The landing tick"): a world step that
flies every UAV's quadrotor truth and samples its sensors, an agent step that fuses them and decides the rotor
command, and the hold of that command, called in this order by every runner: the in-process simulation
(:mod:`swarm.sim.landing`) and the landing world and agent processes.

Per tick ``k`` (``t = k dt``), for each UAV not done:

1. **world** (:meth:`LandingWorld.step`): the truth advances by ``dt`` under the held command, then the
   sensors of tick ``k`` sample, in this order, from the UAV's own random stream: the IMU (the mean specific
   force and rate over ``(t - dt, t]``, stamped ``t - dt``, with biases and white noise), the UWB range to the
   next anchor (a UWB tick, within the anchors' reach), the GNSS fix (a GNSS tick), and the camera (a camera
   tick): the pad's marker corners in pixels, by corner projection with pixel noise or by rendering the
   image and detecting the ArUco markers in it; none when the pad is hidden or behind the camera.
2. **agent** (:meth:`LandingAgent.tick`): the IMU-driven filter takes the IMU sample, the range, the fix and
   the pad's pose from PnP of the corners; the guidance (fixed deviation or Algorithm 1) and the quadrotor
   controller give the rotor speeds, or the idle command once landed.
3. **world** (:meth:`LandingWorld.hold`): the rotors take the command; :func:`landing_done` says whether the
   UAV's run is over (landed for a second, or hovering at the abort height after an abort).

:func:`landing_setup` is what the seed decides for one UAV; both sides call it, so an agent process that has
no world starts from the same first estimate as the in-process agent.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from swarm.core import rotations as rot
from swarm.core.imu_filter import ImuFilter, ImuFilterParams
from swarm.core.landing import LandingGuidance, LandingMode
from swarm.core.pad_vision import Renderer, corner_frame, detect, estimate_pose, make_detector
from swarm.kinds.quadrotor import control as qc
from swarm.kinds.quadrotor import control_row, truth_row
from swarm.kinds.quadrotor import dynamics as qd
from swarm.landing_scenario import LandingScenario, Uav

R_BODY_CAM = rot.quat_to_matrix(np.array([1.0, 0.0, 0.0, 0.0]))
"""Camera to body of the downward camera: its optical axis (+z) along body -z."""


def _seeds(seed: int, index: int, stream: int) -> np.random.SeedSequence:
    """UAV ``index``'s stream: the one-UAV scenario's for index 0, so its runs did not change."""
    return np.random.SeedSequence([seed, stream] if index == 0 else [seed, stream, index])


@dataclass
class LandingSetup:
    """What the seed decides for one UAV (module docstring)."""

    uav: Uav
    start: np.ndarray
    yaw_rad: float
    pad: np.ndarray
    q_nav_pad: np.ndarray
    uwb_range_m: float
    accel_bias: np.ndarray
    gyro_bias: np.ndarray
    p0: np.ndarray
    q0: np.ndarray
    accel_bias0: np.ndarray
    gyro_bias0: np.ndarray
    rng: np.random.Generator
    """The sensors' stream, after the draws above."""


def landing_setup(sc: LandingScenario, seed: int, index: int) -> LandingSetup:
    uav = sc.uavs()[index]
    rng = np.random.default_rng(_seeds(seed, index, 15))
    start = np.asarray(uav.start_m, float)
    uwb_range = sc.uwb.max_range_m
    disp = sc.dispersions
    if disp.enabled:
        drng = np.random.default_rng(_seeds(seed, index, 16))
        start = start + drng.normal(0.0, 1.0, 3) * np.asarray(disp.start_sigma_m)
        start[2] = max(start[2], 2.0)
        uwb_range = float(drng.uniform(*disp.uwb_range_m))
    yaw = math.radians(uav.yaw_deg)
    q_start = rot.rotvec_exp(np.array([0.0, 0.0, yaw]))
    ba = rng.uniform(-sc.imu.accel_bias_m_s2, sc.imu.accel_bias_m_s2, 3)
    bg = rng.uniform(-sc.imu.gyro_bias_rad_s, sc.imu.gyro_bias_rad_s, 3)
    ini = sc.initial
    p0 = start + rng.normal(0.0, ini.sigma_position_m, 3)
    q0 = rot.quat_mul(q_start, rot.rotvec_exp(rng.normal(0.0, math.radians(ini.sigma_attitude_deg), 3)))
    ba0 = ba + rng.normal(0, ini.sigma_accel_bias_m_s2, 3)
    bg0 = bg + rng.normal(0, ini.sigma_gyro_bias_rad_s, 3)
    pad = np.asarray(uav.pad_m, float)
    q_nav_pad = rot.rotvec_exp(np.array([0.0, 0.0, math.radians(uav.pad_yaw_deg)]))
    return LandingSetup(uav, start, yaw, pad, q_nav_pad, uwb_range, ba, bg, p0, q0, ba0, bg0, rng)


def anchors_of(sc: LandingScenario) -> np.ndarray:
    return np.asarray(sc.uwb.anchors_m, float) if sc.uwb.enabled else np.zeros((0, 3))


@dataclass
class Rates:
    """Every how many ticks each sensor samples."""

    camera: int
    uwb: int
    gnss: int

    @classmethod
    def of(cls, sc: LandingScenario) -> Rates:
        dt = sc.dt_s
        return cls(
            max(1, round(1.0 / (sc.camera.rate_hz * dt))),
            max(1, round(1.0 / (sc.uwb.rate_hz * dt))),
            max(1, round(1.0 / (sc.gnss.rate_hz * dt))),
        )

    def uwb_tick(self, sc: LandingScenario, k: int) -> bool:
        return bool(sc.uwb.enabled and len(sc.uwb.anchors_m) and k % self.uwb == 0)

    def gnss_tick(self, sc: LandingScenario, k: int) -> bool:
        return bool(sc.gnss.enabled and k % self.gnss == 0)

    def camera_tick(self, k: int) -> bool:
        return k % self.camera == 0


@dataclass
class LandingInputs:
    """One UAV's samples of tick ``k`` (module docstring, step 1)."""

    k: int
    t: float
    gyro: np.ndarray
    """Rate [rad/s], body; the IMU sample is stamped ``t - dt``."""
    acc: np.ndarray
    """Specific force [m/s^2], body."""
    uwb: tuple[int, float] | None = None
    """(anchor index, range [m]) on a UWB tick within reach."""
    gnss: np.ndarray | None = None
    """Position fix [m], nav, on a GNSS tick."""
    camera: tuple[np.ndarray, np.ndarray] | None = None
    """On a camera tick: the detected marker ids (n,) and their corners (n, 4, 2) [px] (n = 0: nothing)."""


@dataclass
class LandingCommand:
    """The agent's answer to tick ``k``: rotor speeds (4,) [rad/s] and the guidance mode that gave them."""

    k: int
    u: np.ndarray
    mode: LandingMode


@dataclass
class _Truth:
    setup: LandingSetup
    x: np.ndarray
    s: np.ndarray
    held: np.ndarray
    next_anchor: int = 0
    energy_j: float = 0.0
    frames: int = 0
    landed_t: float | None = None
    done: bool = False
    end_k: int = 0


class LandingWorld:
    """The truth and the sensors of every UAV of a landing scenario (module docstring)."""

    def __init__(self, sc: LandingScenario, seed: int) -> None:
        self.sc, self.seed = sc, seed
        qp = sc.kinds.quadrotor
        self.air = qp.airframe
        self.kp = truth_row(self.air)
        self.rates = Rates.of(sc)
        self.anchors = anchors_of(sc)
        self.lever = np.asarray(sc.uwb.lever_arm_m, float)
        self.cam_pos = np.asarray(sc.camera.pos_body_m, float)
        self.gnss_sigma = np.asarray(sc.gnss.sigma_m, float)
        self.gnss_cov = np.diag(self.gnss_sigma**2)
        """The fixes' covariance, the receiver's claim (what the GNSS message carries)."""
        cam = sc.camera
        self.renderer = Renderer(sc.pad.board, cam.intrinsics) if cam.mode == "rendered" else None
        self.detector = make_detector(sc.pad.board) if cam.mode == "rendered" else None
        self.uavs: dict[str, _Truth] = {}
        for u in sc.uavs():
            st = landing_setup(sc, seed, u.index)
            x = np.zeros(13)
            x[0:3] = st.start
            x[6:10] = rot.rotvec_exp(np.array([0.0, 0.0, st.yaw_rad]))
            s = np.zeros(qd.S_N)
            s[0:4] = self.air.hover_omega_rad_s
            self.uavs[u.id] = _Truth(st, x, s, np.full(4, self.air.hover_omega_rad_s))

    def active(self) -> list[str]:
        return [i for i, u in self.uavs.items() if not u.done]

    def step(self, k: int) -> dict[str, LandingInputs]:
        """Step 1 of the tick for every UAV not done."""
        return {i: self._step_one(u, k) for i, u in self.uavs.items() if not u.done}

    def _step_one(self, u: _Truth, k: int) -> LandingInputs:
        sc, dt, x, st = self.sc, self.sc.dt_s, u.x, u.setup
        rng = st.rng
        t = k * dt
        v_before = x[3:6].copy()
        w_before = x[10:13].copy()
        u.energy_j += qd.quadrotor_truth_step(x, u.s, u.held, self.kp, dt)
        # what an ideal accelerometer integrates over the tick: the mean non-gravitational acceleration
        # (v(t) - v(t - dt)) / dt + g e_z (so the touchdown's stop too), body frame
        f_nav = (x[3:6] - v_before) / dt + np.array([0.0, 0.0, self.air.gravity_m_s2])
        f = rot.quat_rotate(rot.quat_conj(x[6:10]), f_nav) + st.accel_bias
        f += rng.normal(0.0, sc.imu.accel_noise / math.sqrt(dt), 3)
        w = 0.5 * (w_before + x[10:13]) + st.gyro_bias + rng.normal(0.0, sc.imu.gyro_noise / math.sqrt(dt), 3)
        inp = LandingInputs(k, t, w, f)
        if self.rates.uwb_tick(sc, k):
            a = u.next_anchor
            u.next_anchor = (u.next_anchor + 1) % len(self.anchors)
            tag = x[0:3] + rot.quat_rotate(x[6:10], self.lever)
            true_r = float(np.linalg.norm(tag - self.anchors[a]))
            if true_r <= st.uwb_range_m:
                inp.uwb = (a, true_r + rng.normal(0.0, sc.uwb.sigma_m))
        if self.rates.gnss_tick(sc, k):
            inp.gnss = x[0:3] + rng.normal(0.0, 1.0, 3) * self.gnss_sigma
        if self.rates.camera_tick(k):
            inp.camera = self._camera(u, t, rng)
        return inp

    def _camera(self, u: _Truth, t: float, rng) -> tuple[np.ndarray, np.ndarray]:
        sc, x, st = self.sc, u.x, u.setup
        f = sc.faults
        hidden = f.pad_hidden_always or (
            f.pad_hidden_from_s is not None
            and f.pad_hidden_from_s <= t < f.pad_hidden_from_s + f.pad_hidden_for_s
        )
        # the pad in the camera: X_cam = R_cam_nav (X_nav - p_cam)
        R_nav_body = rot.quat_to_matrix(x[6:10])
        p_cam = x[0:3] + R_nav_body @ self.cam_pos
        R_cam_nav = (R_nav_body @ R_BODY_CAM).T
        t_cam = R_cam_nav @ (st.pad - p_cam)
        q_cam_pad = rot.matrix_to_quat(R_cam_nav @ rot.quat_to_matrix(st.q_nav_pad))
        u.frames += 1
        if hidden or t_cam[2] <= 0.05:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 4, 2))
        board, intr = sc.pad.board, sc.camera.intrinsics
        if self.renderer is not None:
            ids, corners = detect(self.renderer.render(t_cam, q_cam_pad, rng), board, self.detector)
        else:
            ids, corners = corner_frame(board, intr, t_cam, q_cam_pad, rng)
        return np.asarray(ids, dtype=np.int64).reshape(-1), np.asarray(corners, dtype=float).reshape(-1, 4, 2)

    def hold(self, uav_id: str, cmd: LandingCommand) -> None:
        """Step 3: the rotors take the command; the UAV's run ends if :func:`landing_done` says so."""
        u = self.uavs[uav_id]
        qd.quadrotor_hold(cmd.u, u.s, u.held, self.kp)
        t = cmd.k * self.sc.dt_s
        if cmd.mode == LandingMode.LANDED and u.landed_t is None:
            u.landed_t = t
        if landing_done(self.sc, u.setup.pad, cmd.mode, u.landed_t, t, u.x):
            u.done, u.end_k = True, cmd.k

    def outcome(self, uav_id: str) -> dict:
        """The world's half of a UAV's summary: where and how it ended."""
        u = self.uavs[uav_id]
        on_ground = u.s[qd.S_GROUND] != 0.0
        return {
            "on_ground": bool(on_ground),
            "error_m": float(np.linalg.norm(u.x[0:2] - u.setup.pad[0:2])),
            "energy_j": float(u.energy_j),
            "pad_frames": u.frames,
            "start_m": [float(v) for v in u.setup.start],
            "uwb_range_m": u.setup.uwb_range_m,
        }


def landing_done(sc: LandingScenario, pad, mode: LandingMode, landed_t: float | None, t: float, x) -> bool:
    """A UAV's run is over: ``end_after_landed_s`` after its touchdown, or hovering (within
    ``abort_hold_tolerance_m``, under ``abort_hold_speed_m_s``) at the abort height above its pad after an
    abort."""
    if landed_t is not None and t - landed_t >= sc.end_after_landed_s:
        return True
    climb_to = float(pad[2]) + sc.landing.abort_height_m
    return bool(
        mode == LandingMode.ABORT
        and abs(x[2] - climb_to) < sc.abort_hold_tolerance_m
        and np.linalg.norm(x[3:6]) < sc.abort_hold_speed_m_s
    )


@dataclass
class _Series:
    t_s: list = field(default_factory=list)
    p_true_nav: list = field(default_factory=list)
    p_est_nav: list = field(default_factory=list)
    sigma_h_m: list = field(default_factory=list)
    mode: list = field(default_factory=list)
    pad_seen: list = field(default_factory=list)


class LandingAgent:
    """One UAV's on-board software (module docstring, step 2): filter, guidance, controller."""

    def __init__(self, sc: LandingScenario, seed: int, index: int, policy: str) -> None:
        self.sc, self.policy = sc, policy
        st = landing_setup(sc, seed, index)
        self.setup = st
        qp = sc.kinds.quadrotor
        air = qp.airframe
        self.cp = control_row(qp)
        self.dt = sc.dt_s
        self.rates = Rates.of(sc)
        anchors = anchors_of(sc)
        ini = sc.initial
        params = ImuFilterParams(
            **{
                **sc.estimator.__dict__,
                "lever_arm_m": tuple(sc.uwb.lever_arm_m),
                "gravity_nav": (0.0, 0.0, -air.gravity_m_s2),
                "range_bias": False,
                "accel_noise": sc.imu.accel_noise,
                "gyro_noise": sc.imu.gyro_noise,
            }
        )
        self.filt = ImuFilter.create(
            params,
            anchors if len(anchors) else np.zeros((1, 3)),
            st.p0,
            np.zeros(3),
            st.q0,
            0.0,
            sc.uwb.sigma_m,
            (
                ini.sigma_position_m,
                ini.sigma_velocity_m_s,
                math.radians(ini.sigma_attitude_deg),
                ini.sigma_accel_bias_m_s2,
                ini.sigma_gyro_bias_rad_s,
                0.1,
            ),
            accel_bias=st.accel_bias0,
            gyro_bias=st.gyro_bias0,
        )
        cam = sc.camera
        self.cam_pos = np.asarray(cam.pos_body_m, float)
        half_fov = math.atan(min(cam.intrinsics.cx_px, cam.intrinsics.cy_px) / cam.intrinsics.fx_px)
        self.guidance = LandingGuidance(sc.landing, policy, st.pad, st.start, half_fov, air.gear_height_m)
        self.cs, self.u, self.act = np.zeros(qc.CS_N), np.zeros(4), np.zeros(9)
        self.gnss_cov = np.diag(np.asarray(sc.gnss.sigma_m, float) ** 2)
        self.nis: deque = deque(maxlen=20)
        self.pad_seen: float | None = None
        self.detections = 0
        self.landed_t: float | None = None
        self.p_est = st.p0.copy()
        self.sigma_h = 0.0
        self.series = _Series()

    def tick(self, inp: LandingInputs, truth_p=None) -> LandingCommand:
        """Step 2 (module docstring): :meth:`fuse` the tick's samples, then :meth:`decide`; ``truth_p``, the
        true position (in process only), goes to the series."""
        self.fuse(inp)
        return self.decide(inp, truth_p)

    def fuse(self, inp: LandingInputs) -> None:
        """The filter's half of a tick: the IMU sample, then the range, the fix and the pad's pose from the
        camera's corners (PnP). A free-running agent that has fallen behind fuses the ticks it missed with
        this alone and decides only on the newest (:mod:`agents.landing`)."""
        sc, filt, t = self.sc, self.filt, inp.t
        filt.imu(t - self.dt, inp.gyro, inp.acc)
        if inp.uwb is not None:
            out = filt.update_range(t, inp.uwb[0], inp.uwb[1])
            if len(out) and out[0] != 2:
                self.nis.append(float(filt.last_d2[0]))
        if inp.gnss is not None:
            filt.update_position(t, inp.gnss, self.gnss_cov)
        if inp.camera is not None and len(inp.camera[0]):
            est = estimate_pose(inp.camera[0], inp.camera[1], sc.pad.board, sc.camera.intrinsics)
            if est is not None:
                out = filt.update_pad(
                    t, self.setup.pad, est.t_cam_m, est.cov_cam[:3, :3], self.cam_pos, R_BODY_CAM
                )
                if len(out) and out[0] == 0:
                    self.pad_seen = t
                    self.detections += 1
                    self.nis.append(float(filt.last_pad_d2[0]) / 3.0)

    def decide(self, inp: LandingInputs, truth_p=None) -> LandingCommand:
        """The guidance and control half of a tick, on the filter's estimate after :meth:`fuse`."""
        filt, t = self.filt, inp.t
        p_est, v_est = filt.p_nav[0].copy(), filt.v_nav[0].copy()
        sigma_h = math.sqrt(max(np.linalg.eigvalsh(filt.P[0, 0:2, 0:2])))
        d = math.sqrt(float(np.mean(self.nis))) if self.nis else 0.0
        g = self.guidance
        ref = g.step(t, p_est, v_est, sigma_h, d, self.pad_seen)
        if g.mode == LandingMode.LANDED:
            qc.quadrotor_idle(self.cp, self.u, self.act)
            self.landed_t = self.landed_t if self.landed_t is not None else t
        else:
            qc.quadrotor_control(
                self.cs, self.cp, p_est, v_est, filt.q_nav_body[0], inp.gyro - filt.gyro_bias[0],
                ref.p_nav, ref.v_nav, ref.a_nav, ref.q_nav_body, self.u, self.act,
            )  # fmt: skip
        self.p_est, self.sigma_h = p_est, sigma_h
        if truth_p is not None and inp.k % 10 == 0:
            s = self.series
            s.t_s.append(round(t, 4))
            s.p_true_nav.append(truth_p.tolist())
            s.p_est_nav.append(p_est.tolist())
            s.sigma_h_m.append(sigma_h)
            s.mode.append(str(g.mode))
            s.pad_seen.append(self.pad_seen is not None and t - self.pad_seen <= 0.2)
        return LandingCommand(inp.k, self.u.copy(), g.mode)

    def outcome(self) -> dict:
        """The agent's half of a UAV's summary: modes, decisions, deviation, detections."""
        g = self.guidance
        dev = g.deviation_point
        pad = self.setup.pad
        return {
            "final_mode": str(g.mode),
            "landing_time_s": float(self.landed_t) if self.landed_t is not None else None,
            "deviation_distance_m": float(np.linalg.norm(dev[:2] - pad[:2])) if dev is not None else None,
            "retries": g.retries,
            "pad_detections": self.detections,
            "modes": g.modes,
            "decisions": [dd.as_dict() for dd in g.decisions if dd.switched or self.policy == "mdp"],
        }


def landing_summary(sc: LandingScenario, policy: str, seed: int, world_half: dict, agent_half: dict,
                    end_k: int, wall: float) -> dict:  # fmt: skip
    """One UAV's summary (``swarm sim landing --json``) from the world's half (:meth:`LandingWorld.outcome`:
    where it ended) and the agent's (:meth:`LandingAgent.outcome`), in process or gathered over Zenoh."""
    w, a = world_half, agent_half
    landed = bool(a["final_mode"] == "LANDED" and w["on_ground"])
    return {
        "scenario": sc.name,
        "policy": policy,
        "seed": seed,
        "camera_mode": sc.camera.mode,
        "landed": landed and w["error_m"] <= sc.pad_tolerance_m,
        "landed_off_pad": bool(w["on_ground"] and w["error_m"] > sc.pad_tolerance_m),
        "aborted": a["final_mode"] == "ABORT",
        "final_mode": a["final_mode"],
        "landing_error_m": w["error_m"] if landed else None,
        "landing_time_s": a["landing_time_s"],
        "energy_j": w["energy_j"],
        "deviation_distance_m": a["deviation_distance_m"],
        "retries": a["retries"],
        "start_m": w["start_m"],
        "uwb_range_m": w["uwb_range_m"],
        "pad_frames": w["pad_frames"],
        "pad_detections": a["pad_detections"],
        "sim_time_s": round(end_k * sc.dt_s, 4),
        "wall_s": wall,
        "realtime_factor": end_k * sc.dt_s / wall if wall > 0 else None,
        "modes": a["modes"],
        "decisions": a["decisions"],
    }
