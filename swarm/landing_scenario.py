"""The landing scenario (paper section VI-B; ``swarm/scenarios/landing.toml``, ``landing-swarm.toml``): one
quadrotor and one pad (``[vehicle]``, ``[pad]``), or a fleet of them (``[[fleet]]``: one UAV per entry, each
with its own pad), the sensors, the estimator, the guidance and the per-run dispersions. The tick that flies
it is :mod:`swarm.step.landing`."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from swarm.config import load_toml
from swarm.core.imu_filter import ImuFilterParams, RobustParams
from swarm.core.landing import LandingGuidanceParams
from swarm.core.pad_vision import PadBoardParams, PadCameraParams
from swarm.core.range_error_params import RangeErrorParams
from swarm.core.range_errors import check_range_errors
from swarm.core.tdoa_radio import TdoaParams
from swarm.errors import ConfigError
from swarm.kinds import KINDS
from swarm.scenario_tables import InitialEstimateParams, MissionTable, check_mission, refuse_mission_key
from swarm.sensors.options import SensorsSpec, apply_sensor_profile

Vec3 = tuple[float, float, float]
SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"


def _check_positive(obj, names: tuple[str, ...], prefix: str = "") -> None:
    """ConfigError naming ``<prefix><name>`` and its value unless each of ``obj``'s fields ``names`` is a
    finite number > 0."""
    for name in names:
        v = getattr(obj, name)
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise ConfigError(f"{prefix}{name} must be a finite number > 0, got {v!r}")


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

    RENAMED: ClassVar[dict[str, tuple[str, float]]] = {
        "accel_noise": ("accel_noise_m_s2_rthz", 1.0),
        "gyro_noise": ("gyro_noise_rad_s_rthz", 1.0),
    }
    """Keys of older files and the names that replaced them (:mod:`swarm.config`)."""

    accel_noise_m_s2_rthz: float = 0.01
    """Accelerometer white-noise density [m/s^2/sqrt(Hz)], the sensor profiles' name."""
    gyro_noise_rad_s_rthz: float = 0.001
    """Gyro white-noise density, the angle random walk [rad/s/sqrt(Hz)], the sensor profiles' name."""
    accel_bias_m_s2: float = 0.02
    gyro_bias_rad_s: float = 0.002
    vibration_accel_m_s2: float = 0.0
    """Extra white spread of the accelerometer in flight (rotor vibration), a standard deviation per sample,
    not a density [m/s^2] (real Crazyflie: 0.095-0.12 in flight, 0.008-0.010 on the ground; 0: none)."""
    vibration_gyro_rad_s: float = 0.0
    """The same for the gyro [rad/s] (real Crazyflie: 0.03-0.05 in flight, 0.002-0.003 on the ground)."""

    def __post_init__(self) -> None:
        for name in ("vibration_accel_m_s2", "vibration_gyro_rad_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"imu.{name} must be a finite number >= 0, got {v!r}")


@dataclass(frozen=True)
class LandingUwb(RangeErrorParams):
    """``[uwb]``: anchors around the pad, ranged round-robin, only within ``max_range_m``, with the range
    errors of real flights (:class:`~swarm.core.range_error_params.RangeErrorParams`)."""

    enabled: bool = True
    mode: str = "twr"
    """``"twr"``: two-way ranging, one anchor per UWB tick (``rate_hz``, ``sigma_m``); ``"tdoa2"`` /
    ``"tdoa3"``: the Loco Positioning TDoA radio of the docking swarm (:class:`swarm.core.tdoa_radio.
    TdoaRadio`, the scenario's ``[tdoa]`` table): the anchors transmit, each UAV's tag only listens and
    hands its filter the distance differences it heard since the last UWB tick, only those whose two anchors
    are within ``max_range_m`` (the dispersed reach) of it."""
    anchors_m: tuple[Vec3, ...] = ((6.0, 6.0, 0.3), (-6.0, 6.0, 0.3), (-6.0, -6.0, 0.3), (6.0, -6.0, 2.5))
    rate_hz: float = 40.0
    sigma_m: float = 0.10
    max_range_m: float = 15.0
    lever_arm_m: Vec3 = (0.0, 0.0, 0.05)
    outlier_probability: float = 0.0
    """Probability that a range is an isolated outlier, long by an exponential excess."""
    outlier_excess_m: float = 1.0
    """The outliers' mean excess [m]."""

    def __post_init__(self) -> None:
        check_range_errors(self)
        if self.mode not in ("twr", "tdoa2", "tdoa3"):
            raise ConfigError(f"uwb.mode must be 'twr', 'tdoa2' or 'tdoa3', got {self.mode!r}")
        if not (isinstance(self.outlier_probability, int | float) and 0.0 <= self.outlier_probability <= 1.0):
            raise ConfigError(f"uwb.outlier_probability must be in [0, 1], got {self.outlier_probability!r}")
        _check_positive(self, ("outlier_excess_m",), "uwb.")


@dataclass(frozen=True)
class LandingGnss:
    """``[gnss]``: a satellite receiver's position fixes, white noise (the "less accurate" navigation of the
    paper's approach phase; multipath and biases are not modelled)."""

    enabled: bool = True
    rate_hz: float = 5.0
    sigma_m: Vec3 = (1.0, 1.0, 1.5)


@dataclass(frozen=True)
class LandingRangefinder:
    """``[rangefinder]``: a downward distance sensor (a lidar altimeter, PX4's ``distance_sensor``) at the
    body origin, pointing along body ``-z``: the distance to flat ground at the airframe's ``ground_z_m``
    (``(p_z - ground_z) / cos(tilt)``), white noise ``sigma_m``, a reading only within ``[min_range_m,
    max_range_m]`` and below ``max_tilt_deg`` (beyond, the sensor reports none)."""

    enabled: bool = False
    rate_hz: float = 20.0
    sigma_m: float = 0.03
    min_range_m: float = 0.1
    max_range_m: float = 12.0
    max_tilt_deg: float = 30.0

    def __post_init__(self) -> None:
        names = ("rate_hz", "sigma_m", "min_range_m", "max_range_m", "max_tilt_deg")
        _check_positive(self, names, "rangefinder.")
        if not self.min_range_m < self.max_range_m:
            lo, hi = self.min_range_m, self.max_range_m
            raise ConfigError(f"rangefinder.min_range_m must be below max_range_m = {hi!r}, got {lo!r}")
        if not self.max_tilt_deg < 90:
            raise ConfigError(f"rangefinder.max_tilt_deg must be below 90, got {self.max_tilt_deg!r}")


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
class LandingPlatform:
    """``[platform]``: the moving-platform landing (``landing-moving.toml``): the pad rides a ground robot
    that drives ``waypoints_m`` at ``speed_m_s`` (a kinematic path follower, :mod:`swarm.core.platform_path`)
    and shares its estimate of the pad with the UAV. The deck is at the ground's height (the quadrotor's
    contact with the ground is its contact with the deck); after the touchdown the UAV stays where it
    touched (the deck carrying it is not modelled): a landing is judged at the touchdown, on the pad
    (within ``pad_tolerance_m`` of the pad's centre) and slower than ``touchdown_speed_m_s`` relative to it.
    ``pad.position_m``'s height is the deck's; its x, y are the path's (``start_arc_m``)."""

    enabled: bool = False
    """False: a pad that stands still (``[pad]``), the other keys unused."""
    id: str = "robot"
    """The robot's id: it shares its estimate on ``<ns>/agent/<id>/estimate`` (docs/protocol.md)."""
    waypoints_m: tuple[tuple[float, float], ...] = ()
    """The path's waypoints (nav x, y) [m], at least two, no two consecutive alike."""
    closed: bool = True
    """The robot drives back from the last waypoint to the first and on (False: it stops at the last)."""
    speed_m_s: float = 0.3
    """The robot's constant speed along the path [m/s]."""
    start_arc_m: float = 0.0
    """Where on the path the robot is at t = 0, as a distance along it [m]; with ``[dispersions]`` enabled
    (a closed path), drawn uniform over the path's length instead."""
    share_estimate: bool = True
    """The robot shares its pad estimate (position, velocity); False: the UAV knows only where the pad was at
    t = 0 (a baseline that shows what the shared estimate buys)."""
    share_rate_hz: float = 10.0
    """How often the robot shares its estimate [Hz]; the UAV extrapolates it with its velocity in between."""
    share_sigma_m: float = 0.05
    """The shared position's error, white, per axis [m] (the robot's stated estimate noise; the UAV adds
    its variance to the camera's)."""
    share_sigma_m_s: float = 0.02
    """The shared velocity's error, white, per axis [m/s]."""
    touchdown_speed_m_s: float = 0.5
    """A touchdown is a landing only this slow (horizontal speed relative to the deck) [m/s]."""

    def __post_init__(self) -> None:
        if not self.enabled:
            return
        if not (isinstance(self.id, str) and ID_PATTERN.match(self.id)):
            raise ConfigError(f"platform.id must be 1-64 letters, digits, '_' or '-', got {self.id!r}")
        w = self.waypoints_m
        if len(w) < 2:
            got = [list(p) for p in w]
            raise ConfigError(f"platform.waypoints_m must list at least two waypoints, got {got!r}")
        for i, (a, b) in enumerate(zip(w, w[1:] + (w[:1] if self.closed else ()), strict=False)):
            if not all(math.isfinite(v) for v in (*a, *b)):
                raise ConfigError(f"platform.waypoints_m[{i}] must be finite, got {list(a)!r}")
            if tuple(a) == tuple(b):
                raise ConfigError(
                    f"platform.waypoints_m[{i}] and the next are the same point {list(a)!r} (a segment of "
                    "no length has no heading)"
                )
        _check_positive(self, ("speed_m_s", "share_rate_hz", "share_sigma_m", "share_sigma_m_s",
                               "touchdown_speed_m_s"), "platform.")  # fmt: skip
        if not (math.isfinite(self.start_arc_m) and self.start_arc_m >= 0):
            raise ConfigError(f"platform.start_arc_m must be a finite number >= 0, got {self.start_arc_m!r}")


QuadrotorParams = KINDS["quadrotor"].Params
"""The ``[kinds.quadrotor]`` tables, the registered kind's (:mod:`swarm.kinds`)."""


@dataclass(frozen=True)
class LandingKinds:
    quadrotor: QuadrotorParams = field(default_factory=QuadrotorParams)


ID_PATTERN = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


@dataclass(frozen=True)
class FleetUav:
    """``[[fleet]]``: one UAV of a swarm variant and the pad it lands on (its own; pads may not be shared)."""

    id: str
    start_m: Vec3
    pad_m: Vec3
    yaw_deg: float = 180.0
    pad_yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        if not (isinstance(self.id, str) and ID_PATTERN.match(self.id)):
            raise ConfigError(f"fleet.id must be 1-64 letters, digits, '_' or '-', got {self.id!r}")


@dataclass(frozen=True)
class Uav:
    """One UAV of a run, the single ``[vehicle]`` or a ``[[fleet]]`` entry: id, start, heading, pad."""

    index: int
    id: str
    start_m: Vec3
    yaw_deg: float
    pad_m: Vec3
    pad_yaw_deg: float


@dataclass(frozen=True)
class LandingScenario:
    """A landing scenario file (``swarm/scenarios/landing.toml``)."""

    mission: MissionTable = field(default_factory=lambda: MissionTable("landing"))
    """``[mission]``: ``name = "landing"``."""
    name: str = "landing"
    policy: str = "mdp"
    dt_s: float = 0.01
    max_duration_s: float = 90.0
    pad_tolerance_m: float = 0.25
    """A landing within this horizontal distance of the pad's centre is on the pad."""
    end_after_landed_s: float = 1.0
    """A UAV's run ends this long after its touchdown (the rotors stopped, the UAV settled) [s]."""
    abort_hold_tolerance_m: float = 0.3
    abort_hold_speed_m_s: float = 0.2
    """After an abort, a UAV's run ends once it hovers within ``abort_hold_tolerance_m`` of the abort height
    above its pad, slower than ``abort_hold_speed_m_s``."""
    vehicle: LandingVehicle = LandingVehicle()
    pad: PadSpec = PadSpec()
    camera: LandingCamera = LandingCamera()
    imu: LandingImu = LandingImu()
    uwb: LandingUwb = LandingUwb()
    gnss: LandingGnss = LandingGnss()
    rangefinder: LandingRangefinder = LandingRangefinder()
    initial: InitialEstimateParams = field(
        default_factory=lambda: InitialEstimateParams(
            sigma_position_m=1.0, sigma_velocity_m_s=0.05, sigma_attitude_deg=1.0
        )
    )
    """A GNSS-class start (the shared table, :mod:`swarm.scenario_tables`)."""
    estimator: ImuFilterParams = field(
        default_factory=lambda: ImuFilterParams(
            range_bias=False, range_common_offset=False, range_gm=False, range_bias_rw=0.01, huber_k=2.0
        )
    )
    landing: LandingGuidanceParams = field(default_factory=LandingGuidanceParams)
    faults: LandingFaults = LandingFaults()
    dispersions: LandingDispersions = LandingDispersions()
    kinds: LandingKinds = LandingKinds()
    fleet: tuple[FleetUav, ...] = ()
    """Several UAVs, each with its pad (``landing-swarm.toml``); empty: the one ``[vehicle]`` on ``[pad]``."""
    platform: LandingPlatform = LandingPlatform()
    """The pad on a moving ground robot (``landing-moving.toml``); disabled: a pad that stands still."""
    tdoa: TdoaParams = field(default_factory=TdoaParams)
    """The TDoA radio (``[tdoa]``, the docking scenario's table), used when ``uwb.mode`` is ``"tdoa2"`` or
    ``"tdoa3"`` (which then decides its ``mode``); its ``sigma_m`` is also the filter's prior on a
    difference's white noise."""
    robust: RobustParams = field(default_factory=lambda: RobustParams(cusum_k=2.0))
    """The robust TDoA update of log replay (``[robust]`` of log.toml; :func:`swarm.core._imu_nb.fuse_tdoa`:
    per-anchor NLOS CUSUM, per-pair noise adaptation, effective sample size), used on a TDoA radio; its
    CUSUM allowance 2.0 as a TDoA log's (:attr:`swarm.logs.reader.TdoaLog.cusum_k`: an anchor is in a
    quarter of the differences, 1.0 holds clean anchors out)."""
    sensors: SensorsSpec = field(default_factory=SensorsSpec)
    """A sensor profile whose numbers fill the ``[uwb]`` and ``[imu]`` options the file leaves out
    (:mod:`swarm.sensors.options`); read when the file is loaded."""

    def uavs(self) -> list[Uav]:
        """The run's UAVs in order (index 0 draws the one-UAV scenario's random streams)."""
        if not self.fleet:
            v, p = self.vehicle, self.pad
            if self.platform.enabled:  # the pad where the robot is at t = 0
                x, y, _, _, yaw = platform_pose(self, self.platform.start_arc_m, 0.0)
                pad_m, pad_yaw = (x, y, p.position_m[2]), p.yaw_deg + math.degrees(yaw)
                return [Uav(0, "uav", v.start_m, v.yaw_deg, pad_m, pad_yaw)]
            return [Uav(0, "uav", v.start_m, v.yaw_deg, p.position_m, p.yaw_deg)]
        return [Uav(i, f.id, f.start_m, f.yaw_deg, f.pad_m, f.pad_yaw_deg) for i, f in enumerate(self.fleet)]

    def __post_init__(self) -> None:
        ids = [f.id for f in self.fleet]
        if len(set(ids)) != len(ids):
            dup = next(i for i in ids if ids.count(i) > 1)
            raise ConfigError(f"fleet: UAV {dup!r} is listed twice")
        pads = [tuple(f.pad_m) for f in self.fleet]
        if len(set(pads)) != len(pads):
            raise ConfigError("fleet: two UAVs share a pad; give each its own pad_m")
        if self.platform.enabled and self.fleet:
            raise ConfigError("platform: a moving pad carries one UAV's pad; leave [[fleet]] out")
        check_mission(self.mission, "landing")
        if self.policy not in ("fixed", "mdp"):
            raise ConfigError(f"policy must be 'fixed' or 'mdp', got {self.policy!r}")
        if not (math.isfinite(self.dt_s) and 0 < self.dt_s <= 0.02):
            raise ConfigError(f"dt_s must be in (0, 0.02], got {self.dt_s!r}")
        _check_positive(self, ("end_after_landed_s", "abort_hold_tolerance_m", "abort_hold_speed_m_s"))
        if self.uwb.mode != "twr" and self.uwb.enabled and len(self.uwb.anchors_m) < 2:
            n = len(self.uwb.anchors_m)
            raise ConfigError(f"uwb.anchors_m: uwb.mode {self.uwb.mode!r} needs at least 2 anchors, got {n}")


def platform_path(sc: LandingScenario):
    """The robot's compiled path (:func:`swarm.core.platform_path.path_row`), or None without a platform."""
    from swarm.core.platform_path import path_row

    p = sc.platform
    return path_row(p.waypoints_m, p.closed, p.speed_m_s) if p.enabled else None


def platform_pose(sc: LandingScenario, start_arc_m: float, t_s: float) -> tuple[float, ...]:
    """The robot's ``(x, y, vx, vy, yaw)`` at ``t_s`` [s] from ``start_arc_m`` [m]
    (:mod:`swarm.core.platform_path`)."""
    from swarm.core.platform_path import path_pose

    return tuple(float(v) for v in path_pose(platform_path(sc), start_arc_m, t_s))


def _scenario_path(name_or_path) -> Path:
    """A scenario file, or a bundled one by name (as :func:`swarm.scenario.load_scenario` finds them)."""
    path = Path(name_or_path)
    return SCENARIO_DIR / f"{name_or_path}.toml" if not path.suffix and not path.exists() else path


def load_landing(name_or_path, overrides: dict | None = None) -> LandingScenario:
    def migrate(data: dict, name: str) -> dict:
        refuse_mission_key(data, name)
        return apply_sensor_profile(data, name, LandingScenario, overrides)

    return load_toml(LandingScenario, _scenario_path(name_or_path), overrides, migrate=migrate)
