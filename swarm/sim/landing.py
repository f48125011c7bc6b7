"""One UAV precision landing in-process (paper section VI-B; ``swarm sim landing``).

A quadrotor (:mod:`swarm.kinds.quadrotor`) starts far from its pad and flies the landing guidance of
:mod:`swarm.core.landing` on its own estimate: the IMU-driven error-state filter
(:mod:`swarm.core.imu_filter`) propagated by its 6-axis IMU (biases, noise), corrected by UWB ranges to the
anchors around the pad when in range, and by the pad's pose from its downward camera
(:mod:`swarm.core.pad_vision`: the rendered image and ArUco detection, or the corner-projection mode)
whenever the pad is in view. Every tick (``dt_s``): the truth steps under the held rotor command, the IMU
samples, the radio and camera sample at their rates, the filter fuses, and the guidance and controller
decide the next command. The scenario is its own TOML file (``swarm/scenarios/landing.toml``,
:class:`LandingScenario`).

What this runner is not yet: the compiled one tick of the docking scenarios (:mod:`swarm.step.tick`), so
not ``swarm launch`` nor the dashboard; a Python loop at ~100x real time.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarm.config import load_toml
from swarm.core import rotations as rot
from swarm.core.imu_filter import ImuFilter, ImuFilterParams
from swarm.core.landing import LandingGuidance, LandingGuidanceParams, LandingMode
from swarm.core.pad_vision import (
    PadBoardParams,
    PadCameraParams,
    Renderer,
    corner_frame,
    detect,
    estimate_pose,
    make_detector,
)
from swarm.errors import ConfigError
from swarm.kinds.quadrotor import QuadrotorParams, control_row, truth_row
from swarm.kinds.quadrotor import control as qc
from swarm.kinds.quadrotor import dynamics as qd

Vec3 = tuple[float, float, float]
SCENARIO_DIR = Path(__file__).resolve().parents[1] / "scenarios"


@dataclass(frozen=True)
class LandingVehicle:
    """``[vehicle]``: where the UAV starts."""

    start_m: Vec3 = (25.0, 6.0, 8.0)
    yaw_deg: float = 180.0


@dataclass(frozen=True)
class PadSpec:
    """``[pad]``: the landing pad (surveyed: its position is known in nav)."""

    position_m: Vec3 = (0.0, 0.0, 0.0)
    yaw_deg: float = 0.0
    board: PadBoardParams = field(default_factory=PadBoardParams)


@dataclass(frozen=True)
class LandingCamera:
    """``[camera]``: the downward camera (``PadCameraParams``) and how the runner uses it."""

    mode: str = "corners"
    """``"corners"`` (Monte Carlo) or ``"rendered"`` (render, detect, PnP)."""
    rate_hz: float = 20.0
    pos_body_m: Vec3 = (0.0, 0.0, -0.05)
    intrinsics: PadCameraParams = field(default_factory=PadCameraParams)

    def __post_init__(self) -> None:
        if self.mode not in ("corners", "rendered"):
            raise ConfigError(f"camera.mode must be 'corners' or 'rendered', got {self.mode!r}")
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ConfigError(f"camera.rate_hz must be > 0, got {self.rate_hz!r}")


@dataclass(frozen=True)
class LandingImu:
    """``[imu]``: the 6-axis IMU at the tick rate; biases drawn per run, uniform in ``[-x, x]`` per axis,
    then known to the filter to its ``initial`` sigmas (a bias calibration on the ground)."""

    accel_noise: float = 0.01
    gyro_noise: float = 0.001
    accel_bias_m_s2: float = 0.02
    gyro_bias_rad_s: float = 0.002


@dataclass(frozen=True)
class LandingUwb:
    """``[uwb]``: anchors around the pad, ranged round-robin, only within ``max_range_m``."""

    enabled: bool = True
    anchors_m: tuple[Vec3, ...] = ((6.0, 6.0, 0.3), (-6.0, 6.0, 0.3), (-6.0, -6.0, 0.3), (6.0, -6.0, 2.5))
    rate_hz: float = 40.0
    sigma_m: float = 0.10
    max_range_m: float = 15.0
    lever_arm_m: Vec3 = (0.0, 0.0, 0.05)


@dataclass(frozen=True)
class LandingGnss:
    """``[gnss]``: a satellite receiver's position fixes, white noise (the "less accurate" navigation of the
    paper's approach phase; multipath and biases are not modelled)."""

    enabled: bool = True
    rate_hz: float = 5.0
    sigma_m: Vec3 = (1.0, 1.0, 1.5)


@dataclass(frozen=True)
class LandingInitial:
    """``[initial]``: the first estimate's errors (drawn) and sigmas."""

    sigma_position_m: float = 1.0
    """GNSS-class start."""
    sigma_velocity_m_s: float = 0.05
    sigma_attitude_deg: float = 1.0
    sigma_accel_bias_m_s2: float = 0.02
    sigma_gyro_bias_rad_s: float = 0.002


@dataclass(frozen=True)
class LandingFaults:
    """``[faults]``: the pad hidden from the camera (an obstruction, a glare) in a window, or always."""

    pad_hidden_from_s: float | None = None
    pad_hidden_for_s: float = 0.0
    pad_hidden_always: bool = False


@dataclass(frozen=True)
class LandingDispersions:
    """``[dispersions]``: what varies from run to run of a campaign (all drawn from the run's seed)."""

    enabled: bool = False
    start_sigma_m: Vec3 = (3.0, 3.0, 1.0)
    """Start position, normal per axis [m]."""
    uwb_range_m: tuple[float, float] = (8.0, 30.0)
    """The anchors' reach, uniform in this interval [m]: from a pad seen by the anchors only in the last
    metres to one covered during the whole approach (the navigation quality the switching rule adapts to)."""


@dataclass(frozen=True)
class LandingKinds:
    quadrotor: QuadrotorParams = field(default_factory=QuadrotorParams)


@dataclass(frozen=True)
class LandingScenario:
    """A landing scenario file (``swarm/scenarios/landing.toml``)."""

    mission: str = "landing"
    name: str = "landing"
    policy: str = "mdp"
    dt_s: float = 0.01
    max_duration_s: float = 90.0
    pad_tolerance_m: float = 0.25
    """A landing within this horizontal distance of the pad's centre is on the pad."""
    vehicle: LandingVehicle = LandingVehicle()
    pad: PadSpec = PadSpec()
    camera: LandingCamera = LandingCamera()
    imu: LandingImu = LandingImu()
    uwb: LandingUwb = LandingUwb()
    gnss: LandingGnss = LandingGnss()
    initial: LandingInitial = LandingInitial()
    estimator: ImuFilterParams = field(default_factory=lambda: ImuFilterParams(range_bias=False, huber_k=2.0))
    landing: LandingGuidanceParams = field(default_factory=LandingGuidanceParams)
    faults: LandingFaults = LandingFaults()
    dispersions: LandingDispersions = LandingDispersions()
    kinds: LandingKinds = LandingKinds()

    def __post_init__(self) -> None:
        if self.mission != "landing":
            raise ConfigError(f"mission must be 'landing' for a landing scenario, got {self.mission!r}")
        if self.policy not in ("fixed", "mdp"):
            raise ConfigError(f"policy must be 'fixed' or 'mdp', got {self.policy!r}")
        if not (math.isfinite(self.dt_s) and 0 < self.dt_s <= 0.02):
            raise ConfigError(f"dt_s must be in (0, 0.02], got {self.dt_s!r}")


def _scenario_path(name_or_path) -> Path:
    """A scenario file, or a bundled one by name (as :func:`swarm.scenario.load_scenario` finds them)."""
    path = Path(name_or_path)
    return SCENARIO_DIR / f"{name_or_path}.toml" if not path.suffix and not path.exists() else path


def is_landing_scenario(name_or_path) -> bool:
    """Whether a scenario (a file, or a bundled one by name) is a landing one (``mission = "landing"``)."""
    import tomllib

    try:
        with open(_scenario_path(name_or_path), "rb") as fh:
            return tomllib.load(fh).get("mission") == "landing"
    except (OSError, tomllib.TOMLDecodeError):
        return False


def load_landing(name_or_path, overrides: dict | None = None) -> LandingScenario:
    return load_toml(LandingScenario, _scenario_path(name_or_path), overrides)


def _specific_force(v_before, x, dt: float, g: float) -> np.ndarray:
    """What an ideal accelerometer integrates over the tick: the mean non-gravitational acceleration
    ``(v(t) - v(t - dt)) / dt + g e_z`` (so the touchdown's stop too), body frame."""
    f_nav = (x[3:6] - v_before) / dt + np.array([0.0, 0.0, g])
    return rot.quat_rotate(rot.quat_conj(x[6:10]), f_nav)


def run_landing(
    sc: LandingScenario, policy: str | None = None, seed: int = 0, record_series: bool = True
) -> dict:
    """Fly one landing (module docstring); the summary of ``swarm sim landing --json``."""
    policy = policy or sc.policy
    rng = np.random.default_rng(np.random.SeedSequence([seed, 15]))
    qp = sc.kinds.quadrotor
    air = qp.airframe
    kp, cp = truth_row(air), control_row(qp)
    dt = sc.dt_s
    pad = np.asarray(sc.pad.position_m, float)
    q_nav_pad = rot.rotvec_exp(np.array([0.0, 0.0, math.radians(sc.pad.yaw_deg)]))
    # truth, with the run's dispersions
    disp = sc.dispersions
    start = np.asarray(sc.vehicle.start_m, float)
    uwb_range = sc.uwb.max_range_m
    if disp.enabled:
        drng = np.random.default_rng(np.random.SeedSequence([seed, 16]))
        start = start + drng.normal(0.0, 1.0, 3) * np.asarray(disp.start_sigma_m)
        start[2] = max(start[2], 2.0)
        uwb_range = float(drng.uniform(*disp.uwb_range_m))
    x = np.zeros(13)
    x[0:3] = start
    x[6:10] = rot.rotvec_exp(np.array([0.0, 0.0, math.radians(sc.vehicle.yaw_deg)]))
    s = np.zeros(qd.S_N)
    s[0:4] = air.hover_omega_rad_s
    held = np.full(4, air.hover_omega_rad_s)
    ba = rng.uniform(-sc.imu.accel_bias_m_s2, sc.imu.accel_bias_m_s2, 3)
    bg = rng.uniform(-sc.imu.gyro_bias_rad_s, sc.imu.gyro_bias_rad_s, 3)
    # estimate
    ini = sc.initial
    anchors = np.asarray(sc.uwb.anchors_m, float) if sc.uwb.enabled else np.zeros((0, 3))
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
    p0 = x[0:3] + rng.normal(0.0, ini.sigma_position_m, 3)
    q0 = rot.quat_mul(x[6:10], rot.rotvec_exp(rng.normal(0.0, math.radians(ini.sigma_attitude_deg), 3)))
    filt = ImuFilter.create(
        params,
        anchors if len(anchors) else np.zeros((1, 3)),
        p0,
        x[3:6],
        q0,
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
        accel_bias=ba + rng.normal(0, ini.sigma_accel_bias_m_s2, 3),
        gyro_bias=bg + rng.normal(0, ini.sigma_gyro_bias_rad_s, 3),
    )
    cam = sc.camera
    R_bc = rot.quat_to_matrix(np.array([1.0, 0.0, 0.0, 0.0]))  # optical axis along body -z: downward
    cam_pos = np.asarray(cam.pos_body_m, float)
    half_fov = math.atan(min(cam.intrinsics.cx_px, cam.intrinsics.cy_px) / cam.intrinsics.fx_px)
    guidance = LandingGuidance(sc.landing, policy, pad, x[0:3], half_fov, air.gear_height_m)
    renderer = Renderer(sc.pad.board, cam.intrinsics) if cam.mode == "rendered" else None
    detector = make_detector(sc.pad.board) if cam.mode == "rendered" else None
    cs, u, act = np.zeros(qc.CS_N), np.zeros(4), np.zeros(9)
    cam_every = max(1, round(1.0 / (cam.rate_hz * dt)))
    uwb_every = max(1, round(1.0 / (sc.uwb.rate_hz * dt)))
    gnss_every = max(1, round(1.0 / (sc.gnss.rate_hz * dt)))
    gnss_cov = np.diag(np.asarray(sc.gnss.sigma_m, float) ** 2)
    nis = deque(maxlen=20)
    pad_seen: float | None = None
    energy = 0.0
    n_ticks = round(sc.max_duration_s / dt)
    series: dict[str, list] = {
        "t_s": [],
        "p_true_nav": [],
        "p_est_nav": [],
        "sigma_h_m": [],
        "mode": [],
        "pad_seen": [],
    }
    frames = detections = 0
    landed_t = None
    next_anchor = 0
    t0_wall = time.perf_counter()
    k = 0
    for k in range(1, n_ticks + 1):
        t = k * dt
        v_before = x[3:6].copy()
        w_before = x[10:13].copy()
        energy += qd.quadrotor_truth_step(x, s, held, kp, dt)
        # the IMU's sample of this tick: means over (t - dt, t], stamped at the start of that interval (the
        # filter holds a sample over the interval after its stamp)
        f = _specific_force(v_before, x, dt, air.gravity_m_s2) + ba
        f += rng.normal(0.0, sc.imu.accel_noise / math.sqrt(dt), 3)
        w = 0.5 * (w_before + x[10:13]) + bg + rng.normal(0.0, sc.imu.gyro_noise / math.sqrt(dt), 3)
        filt.imu(t - dt, w, f)
        if len(anchors) and k % uwb_every == 0:
            a = next_anchor
            next_anchor = (next_anchor + 1) % len(anchors)
            tag = x[0:3] + rot.quat_rotate(x[6:10], np.asarray(sc.uwb.lever_arm_m, float))
            true_r = float(np.linalg.norm(tag - anchors[a]))
            if true_r <= uwb_range:
                out = filt.update_range(t, a, true_r + rng.normal(0.0, sc.uwb.sigma_m))
                if len(out) and out[0] != 2:
                    nis.append(float(filt.last_d2[0]))
        if sc.gnss.enabled and k % gnss_every == 0:
            filt.update_position(t, x[0:3] + rng.normal(0.0, 1.0, 3) * np.asarray(sc.gnss.sigma_m), gnss_cov)
        if k % cam_every == 0:
            hidden = sc.faults.pad_hidden_always or (
                sc.faults.pad_hidden_from_s is not None
                and sc.faults.pad_hidden_from_s
                <= t
                < sc.faults.pad_hidden_from_s + sc.faults.pad_hidden_for_s
            )
            # the pad in the camera: X_cam = R_cam_nav (X_nav - p_cam)
            R_nav_body = rot.quat_to_matrix(x[6:10])
            p_cam = x[0:3] + R_nav_body @ cam_pos
            R_cam_nav = (R_nav_body @ R_bc).T
            t_cam = R_cam_nav @ (pad - p_cam)
            q_cam_pad = rot.matrix_to_quat(R_cam_nav @ rot.quat_to_matrix(q_nav_pad))
            frames += 1
            if not hidden and t_cam[2] > 0.05:
                if renderer is not None:
                    ids, corners = detect(renderer.render(t_cam, q_cam_pad, rng), sc.pad.board, detector)
                else:
                    ids, corners = corner_frame(sc.pad.board, cam.intrinsics, t_cam, q_cam_pad, rng)
                est = estimate_pose(ids, corners, sc.pad.board, cam.intrinsics)
                if est is not None:
                    out = filt.update_pad(t, pad, est.t_cam_m, est.cov_cam[:3, :3], cam_pos, R_bc)
                    if len(out) and out[0] == 0:
                        pad_seen = t
                        detections += 1
                        nis.append(float(filt.last_pad_d2[0]) / 3.0)
        p_est, v_est = filt.p_nav[0].copy(), filt.v_nav[0].copy()
        sigma_h = math.sqrt(max(np.linalg.eigvalsh(filt.P[0, 0:2, 0:2])))
        d = math.sqrt(float(np.mean(nis))) if nis else 0.0
        ref = guidance.step(t, p_est, v_est, sigma_h, d, pad_seen)
        if guidance.mode == LandingMode.LANDED:
            qc.quadrotor_idle(cp, u, act)
            landed_t = landed_t if landed_t is not None else t
        else:
            qc.quadrotor_control(
                cs,
                cp,
                p_est,
                v_est,
                filt.q_nav_body[0],
                w - filt.gyro_bias[0],
                ref.p_nav,
                ref.v_nav,
                ref.a_nav,
                ref.q_nav_body,
                u,
                act,
            )
        qd.quadrotor_hold(u, s, held, kp)
        if record_series and k % 10 == 0:
            series["t_s"].append(round(t, 4))
            series["p_true_nav"].append(x[0:3].tolist())
            series["p_est_nav"].append(p_est.tolist())
            series["sigma_h_m"].append(sigma_h)
            series["mode"].append(str(guidance.mode))
            series["pad_seen"].append(pad_seen is not None and t - pad_seen <= 0.2)
        if landed_t is not None and t - landed_t >= 1.0:
            break
        if (
            guidance.mode == LandingMode.ABORT
            and abs(x[2] - guidance._climb_to) < 0.3
            and np.linalg.norm(x[3:6]) < 0.2
        ):
            break
    wall = time.perf_counter() - t0_wall
    on_ground = s[qd.S_GROUND] != 0.0
    err = float(np.linalg.norm(x[0:2] - pad[0:2]))
    landed = bool(guidance.mode == LandingMode.LANDED and on_ground)
    dev = guidance.deviation_point
    out = {
        "scenario": sc.name,
        "policy": policy,
        "seed": seed,
        "camera_mode": cam.mode,
        "landed": landed and err <= sc.pad_tolerance_m,
        "landed_off_pad": bool(on_ground and err > sc.pad_tolerance_m),
        "aborted": bool(guidance.mode == LandingMode.ABORT),
        "final_mode": str(guidance.mode),
        "landing_error_m": err if landed else None,
        "landing_time_s": float(landed_t) if landed_t is not None else None,
        "energy_j": float(energy),
        "deviation_distance_m": float(np.linalg.norm(dev[:2] - pad[:2])) if dev is not None else None,
        "retries": guidance.retries,
        "start_m": [float(v) for v in start],
        "uwb_range_m": uwb_range,
        "pad_frames": frames,
        "pad_detections": detections,
        "sim_time_s": round(k * dt, 4),
        "wall_s": wall,
        "realtime_factor": k * dt / wall if wall > 0 else None,
        "modes": guidance.modes,
        "decisions": [dd.as_dict() for dd in guidance.decisions if dd.switched or policy == "mdp"],
    }
    if record_series:
        out["series"] = series
    return out
