"""A scenario: the composition of every module's and vehicle kind's parameters, loaded from one TOML file.

Each core module owns a frozen params dataclass (``EstimatorParams`` next to the estimator, ...); each
vehicle kind owns its tables (``[kinds.cubesat.dynamics]``, ``[kinds.ground.wheels]``, ...,
:mod:`swarm.kinds`). A :class:`Scenario` composes them, one TOML table each (``[estimator]``,
``[guidance]``, ``[kinds]``, ...), plus the vehicles (each naming its ``kind``), the anchors and the
simulation rates. ``swarm/scenarios/docking.toml`` is the paper's docking case;
:func:`load_scenario` reads a file or a bundled scenario by name and validates every field, naming the bad
one (:mod:`swarm.config`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from swarm.config import load_toml
from swarm.core.camera import CameraParams, MarkerParams
from swarm.core.estimator import EstimatorParams
from swarm.core.faults import FaultParams
from swarm.core.guidance import GuidanceParams, StationParams
from swarm.core.mdp import FixedParams, MdpParams
from swarm.core.sensors import AhrsParams, GyroParams, UwbParams
from swarm.core.tdoa_radio import TdoaParams
from swarm.errors import ConfigError
from swarm.kinds import KINDS, KindsParams, VehicleKind, check_docking_kind
from swarm.kinds.dispersions import DispersionParams
from swarm.navigation import NAVIGATORS, check_docking_navigator, navigator_name
from swarm.scenario_tables import InitialEstimateParams, MissionTable, check_mission, refuse_mission_key
from swarm.sensors.options import SensorsSpec, apply_sensor_profile

Vec3 = tuple[float, float, float]
SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"
"""The bundled scenarios (package data: a non-editable install has them too)."""
PAPER_ANCHORS_M: tuple[Vec3, ...] = ((1.0, -0.2, 0.5), (1.0, 0.2, -0.5), (-1.0, 0.2, -0.5), (-1.0, -0.2, 0.5))


@dataclass(frozen=True)
class VehicleSpec:
    """One vehicle of the scenario."""

    role: Literal["chaser", "target"]
    """A chaser docks on its target; a target keeps station."""
    position_m: Vec3
    """Initial centre-of-mass position in the navigation frame [m]."""
    euler_deg: Vec3
    """Initial attitude, Euler angles in the scenario's ``euler_seq`` [deg]. For a chaser this is also the
    mission attitude it keeps during APPROACH."""
    target: str | None = None
    """For a chaser: the id of the target it docks on."""
    kind: str = "cubesat"
    """The vehicle's kind (:data:`swarm.kinds.KINDS`: ``cubesat``, ``ground``; ``quadrotor`` is refused by
    the docking runners, :func:`swarm.kinds.check_docking_kind`); its tables are
    ``[kinds.<kind>]``."""
    navigation: str | None = None
    """The vehicle's filter (:data:`swarm.navigation.NAVIGATORS`); default: the one its kind's IMU calls
    for (:func:`swarm.navigation.navigator_name`). The docking runners run ``"mekf"`` only."""
    uwb_address: int | None = None
    """The UWB tag's address, which picks its TDMA slot (``uwb.tdma``): ``address % frame``; default the
    vehicle's index in ``[vehicles]``. Two tags whose addresses share a slot collide."""
    control_phase: int = 0
    """The tick of the vehicle's first control step: it controls on ticks ``k`` with ``(k - control_phase)
    % control period == 0`` (below the period; 0: on tick 0 and every period after). Independent vehicles'
    controller clocks are not in phase; an agent host of many vehicles spreads their control steps over the
    period instead of running them all on one tick (``swarm.stagger_control``). Until its first control
    step a vehicle's actuators are idle."""

    def __post_init__(self) -> None:
        a = self.uwb_address
        if a is not None and (isinstance(a, bool) or not isinstance(a, int) or not 0 <= a < 2**16):
            raise ConfigError(f"uwb_address must be an integer in 0..65535, got {a!r}")
        ph = self.control_phase
        if isinstance(ph, bool) or not isinstance(ph, int) or ph < 0:
            raise ConfigError(f"control_phase must be an integer >= 0, got {ph!r}")


@dataclass(frozen=True)
class SimParams:
    """Rates and limits of a simulated run."""

    imu_rate_hz: float = 100.0
    """Tick rate: the gyro rate and the world's integration step (paper sec. VI-A: IMU at 100 Hz)."""
    max_duration_s: float = 400.0
    """A run that has not docked by then ends undocked."""
    series_every: int = 10
    """Record one time-series sample every this many ticks."""

    def __post_init__(self) -> None:
        for name in ("imu_rate_hz", "max_duration_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"sim.{name} must be a positive number, got {v!r}")
        if self.series_every < 1:
            raise ConfigError(f"sim.series_every must be >= 1, got {self.series_every!r}")


@dataclass(frozen=True)
class AgentParams:
    """Health bookkeeping of an agent (feeds HOLD/ABORT and Algorithm 1's d)."""

    health_window_s: float = 1.0
    """Window of recent range updates for the rejection fraction and the Mahalanobis distance d [s]."""
    vision_recent_s: float = 0.5
    """Vision counts as available when an update was accepted this recently [s]."""
    uwb_with_vision: bool = False
    """Keep fusing UWB ranges while vision is available. Off by default: near the target the camera is
    "the primary measurement along with IMU measurements" (paper sec. VI-A), and a range ties the
    estimate to the mothership frame while docking needs it tied to the target."""
    latch_target_with_vision: bool = True
    """While vision is available, keep using the target estimate held when vision was acquired: the
    target keeps station (paper: "a stationary target"), and its published estimate jitters by
    millimetres with every range it fuses, which the 1 mm vision noise cannot absorb."""
    vision_target_cov: bool = False
    """Add the target's published position covariance to the vision noise. Off by default: as in the
    paper, marker positions are taken as known (sec. IV-D), so near the target the estimate and its
    covariance are relative to the target's estimated pose, which is what docking needs."""
    late_fusion_s: float = 0.03
    """A free-running agent process (``--clock realtime`` or ``scaled:N``) does not wait for a tick's range
    or camera frame: its estimate leaves once the gyro sample is in, and a range or frame that comes after
    it is fused before the next tick if it is at most this old [s] (simulated time), older ones dropped.
    Fusing a 30 ms old range at the current state errs by the distance flown meanwhile (0.6 mm at
    2 cm/s, against a range noise of centimetres). 0: none fused late. Lockstep and in-process runs wait
    for every sample of a tick and do not use it."""
    reinit_tdoa_rows: int = 64
    """A restarted agent on a TDoA radio (``uwb.mode`` tdoa2/tdoa3) re-initialises by multilateration over
    its last this many distance differences, once it has them and they name every anchor (~0.2 s of a
    TDoA3 tag's ~320 a second: the vehicle moves millimetres meanwhile; fewer rows, a noisier fix)."""
    wake_at_control: bool = False
    """A free-running agent alone in its process wakes twice per control period instead of at every gyro
    sample (as a ROS 2 node whose timers drain its subscriptions' queues): just after the tick before its
    control tick, to fuse the period's samples so far, and just after its control tick, to fuse that tick,
    decide and send its command. Its inputs wait in Zenoh's queues in between. ~5 times fewer wakes of a
    Python thread, the cost of a swarm of many processes on few cores (BENCHMARKS.md, "Two wakes per
    control period"); the estimates leave up to a control period late, so off by default. Lockstep and
    agent hosts of several ignore it."""
    wake_margin_s: float = 0.0005
    """With ``wake_at_control``: how long after a tick's gyro sample is expected (the earliest arrival seen
    lately) the agent wakes [s] (wall time); the control tick's sample not in by then is polled for every
    margin."""

    def __post_init__(self) -> None:
        for name in ("health_window_s", "vision_recent_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"agent.{name} must be a positive number, got {v!r}")
        if not (np.isfinite(self.late_fusion_s) and self.late_fusion_s >= 0):
            raise ConfigError(f"agent.late_fusion_s must be a number >= 0, got {self.late_fusion_s!r}")
        if not (isinstance(self.reinit_tdoa_rows, int) and self.reinit_tdoa_rows >= 4):
            raise ConfigError(
                f"agent.reinit_tdoa_rows must be an integer >= 4, got {self.reinit_tdoa_rows!r}"
            )
        if not isinstance(self.wake_at_control, bool):
            raise ConfigError(f"agent.wake_at_control must be true or false, got {self.wake_at_control!r}")
        if not (np.isfinite(self.wake_margin_s) and 0 < self.wake_margin_s <= 0.1):
            raise ConfigError(f"agent.wake_margin_s must be a number in (0, 0.1], got {self.wake_margin_s!r}")


@dataclass(frozen=True)
class SwarmParams:
    """How ``--agents N`` replicates the scenario's vehicles into N copies (:meth:`Scenario.with_pairs`)."""

    pair_spacing_m: float = 0.8
    """Distance between neighbouring copies [m]. With the paper's pair, 0.8 m keeps every chaser's path
    more than its target's keep-out radius away from the other copies' targets."""
    grid_axes: tuple[Vec3, Vec3] = ((0.70710678, -0.70710678, 0.0), (0.40824829, 0.40824829, -0.81649658))
    """The two axes of the square grid of copies, frame nav (unit, orthogonal): by default the plane
    perpendicular to the paper's line of approach (1, 1, 1), so copies sit beside each other's paths."""
    stagger_control: bool = False
    """Spread the copies' control steps over the control period: vehicle ``m`` of the copies (in order,
    chaser0, target0, chaser1, ...) gets ``control_phase = m % its control period``. Off: every vehicle
    controls on the ticks of the original. ``--agents 1`` makes no copies: the scenario's own phases hold.
    Independent vehicles' controllers are not in phase; in one agent host, 16 vehicles controlling on one
    tick need that tick's CPU 16 times over."""

    def __post_init__(self) -> None:
        if not (np.isfinite(self.pair_spacing_m) and self.pair_spacing_m > 0):
            raise ConfigError(f"swarm.pair_spacing_m must be a positive number, got {self.pair_spacing_m!r}")
        a = np.asarray(self.grid_axes, dtype=float)
        if a.shape != (2, 3) or not np.allclose(a @ a.T, np.eye(2), atol=1e-6):
            raise ConfigError(
                f"swarm.grid_axes must be two orthogonal unit 3-vectors, got {self.grid_axes!r}"
            )


# Filter tuning for the closed loop (issue 7; docs/results/faults-analysis/NEES.md has the numbers).
# Acceleration PSD: the filter predicts with the nozzles' achieved force B f turned by its estimated
# attitude, and the truth applies the same force turned by the true one (no thrust noise, quantisation or
# misalignment, nominal mass; [dispersions] off), so the truth's only unmodelled acceleration is the
# thrust-direction error of the attitude estimate error, a_err = -R [F_body x] dtheta / m. Measured tick by
# tick over 40 runs of each scenario and policy (faults-analysis/accel_error.py), its low-frequency PSD,
# S_a(0) = E[(int_0^T a_err dt)^2] / T (the q of a white acceleration, Bar-Shalom, Li & Kirubarajan 2001
# sec. 6.2, for which E[dv^2] = q T; the same for T = 2..20 s), is 3.5e-11..4.4e-11 m^2/s^3 over whole
# runs, dominated by the first seconds (2 deg initial attitude error while the controller accelerates),
# and 3e-12..1e-11 after them: q = 5e-11 covers the whole-run value. (It was 1e-6, "ten times the
# truth's": 2e4 times it, which made the position NEES 2.4 instead of 3 and the estimate noisier, so the
# controller fired more.) A scenario whose truth has more (mass or nozzle dispersions, a real vehicle)
# needs its own q: with 3 % mass and 0.5 deg nozzle errors the PSD is ~1e-8, and with q = 5e-11 8-18 % of
# such runs collide in the blind end of DOCK (NEES.md, table 4). Attitude: the gyro's Gauss-Markov bias
# (10 deg/h, tau 100 s) is absorbed as extra attitude random walk sigma_b sqrt(tau) ~ 5e-4 rad/sqrt(s).
DOCKING_ESTIMATOR = EstimatorParams(accel_psd_m2_s3=5e-11, attitude_rw_extra_rad_rts=5e-4)


def _paper_vehicles() -> dict[str, VehicleSpec]:
    return {
        "chaser": VehicleSpec("chaser", (0.0, 1.0, 0.0), (0.0, 0.0, 0.0), "target"),
        "target": VehicleSpec("target", (1.0, 2.0, 1.0), (-90.0, 0.0, -90.0)),
    }


@dataclass(frozen=True)
class Scenario:
    """Everything a run needs; defaults are the paper's docking scenario (Fig. 5, Table II)."""

    name: str = "docking"
    euler_seq: str = "xyz"
    """Euler convention of every ``euler_deg``, as scipy spells it: lowercase = extrinsic (about the fixed
    mothership axes, in that order), uppercase = intrinsic."""
    policy: Literal["fixed", "mdp"] = "mdp"
    """Default switching policy (the CLI's ``--policy`` overrides it)."""
    mission: MissionTable = field(default_factory=MissionTable)
    """``[mission]``: ``name = "docking"``, as a file without the table is read."""
    anchors_m: tuple[Vec3, ...] = PAPER_ANCHORS_M
    """UWB anchors fixed in the nav frame [m]: the mothership's (paper sec. III), a table's corners, ..."""
    vehicles: dict[str, VehicleSpec] = field(default_factory=_paper_vehicles)
    sim: SimParams = field(default_factory=SimParams)
    initial: InitialEstimateParams = field(default_factory=InitialEstimateParams)
    agent: AgentParams = field(default_factory=AgentParams)
    kinds: KindsParams = field(default_factory=KindsParams)
    """Each vehicle kind's tables (``[kinds.cubesat]``, ``[kinds.ground]``): dynamics, actuators,
    controller, sensor mounts, the kind's own dispersions."""
    gyro: GyroParams = field(default_factory=GyroParams)
    uwb: UwbParams = field(default_factory=UwbParams)
    tdoa: TdoaParams = field(default_factory=TdoaParams)
    """The TDoA radio's settings, used when ``uwb.mode`` is ``"tdoa2"`` or ``"tdoa3"`` (which then decides
    the radio's mode; this table's ``mode`` is not read): packet rates, air time, losses, clocks, the white
    noise of a difference."""
    ahrs: AhrsParams = field(default_factory=lambda: AhrsParams(enabled=True))
    """On: the hardware's VN-100 gives an attitude (paper sec. VI-A); the filter needs it to keep the
    target's and its own attitude good to the ~0.5 deg the 1 mm vision features demand."""
    camera: CameraParams = field(default_factory=CameraParams)
    """The camera's optics and model; where it sits is the vehicle kind's (``kinds.<kind>.mounts``)."""
    markers: MarkerParams = field(default_factory=MarkerParams)
    estimator: EstimatorParams = field(default_factory=lambda: DOCKING_ESTIMATOR)
    """The filter's tuning; its model of the tag and camera mounts is each vehicle kind's ``mounts``."""
    guidance: GuidanceParams = field(default_factory=GuidanceParams)
    station: StationParams = field(default_factory=StationParams)
    mdp: MdpParams = field(default_factory=lambda: MdpParams(r_d_m=0.10))
    """r_d: the centre-to-centre range at contact, two 10 cm cubes face to face."""
    fixed: FixedParams = field(default_factory=FixedParams)
    swarm: SwarmParams = field(default_factory=SwarmParams)
    dispersions: DispersionParams = field(default_factory=DispersionParams)
    """Run-to-run dispersions drawn from the seed (Monte Carlo); all off by default."""
    faults: FaultParams = field(default_factory=FaultParams)
    """Injected sensor faults (NLOS bursts, UWB dropouts, camera loss, gyro bias step), fixed in time or
    triggered by a guidance mode (:mod:`swarm.core.faults`); all off by default."""
    sensors: SensorsSpec = field(default_factory=SensorsSpec)
    """A sensor profile whose numbers fill the ``[uwb]`` and ``[gyro]`` options the file leaves out
    (:mod:`swarm.sensors.options`); read when the file is loaded."""

    def __post_init__(self) -> None:
        check_mission(self.mission, "docking")
        seq = self.euler_seq
        if len(seq) != 3 or not (set(seq) <= set("xyz") or set(seq) <= set("XYZ")):
            raise ConfigError(f"euler_seq must be three of x/y/z (all lower or all upper case), got {seq!r}")
        if len(self.anchors_m) < 1:
            raise ConfigError("anchors_m must list at least one anchor, got none")
        if not self.vehicles:
            raise ConfigError("vehicles must define at least one vehicle, got none")
        for vid, v in self.vehicles.items():
            if v.kind not in KINDS:
                raise ConfigError(f"vehicles.{vid}.kind must be one of {sorted(KINDS)}, got {v.kind!r}")
            check_docking_kind(vid, v.kind)
            nav = navigator_name(KINDS[v.kind].imu_measures, v.navigation, f"vehicles.{vid}")
            check_docking_navigator(vid, NAVIGATORS[nav])
            if v.role == "chaser":
                tgt = self.vehicles.get(v.target) if v.target is not None else None
                if tgt is None or tgt.role != "target":
                    raise ConfigError(
                        f"vehicles.{vid}.target must name a vehicle with role 'target', got {v.target!r}"
                    )
        kinds = {name: KINDS[name](getattr(self.kinds, name), self) for name in self.kinds_used}
        object.__setattr__(self, "_kinds", kinds)  # bound kind objects (not fields: no repr, no equality)

        rates = [("uwb.rate_hz", self.uwb.rate_hz), ("camera.rate_hz", self.camera.rate_hz),
                 ("ahrs.rate_hz", self.ahrs.rate_hz)]  # fmt: skip
        rates += [(k.control_rate_field, k.control_rate_hz) for k in kinds.values()]
        for name, rate in rates:
            ratio = self.sim.imu_rate_hz / rate
            if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
                raise ConfigError(
                    f"{name} must divide sim.imu_rate_hz ({self.sim.imu_rate_hz} Hz) evenly, got {rate!r}"
                )
        for vid, v in self.vehicles.items():
            if v.control_phase >= self.control_every(vid):
                raise ConfigError(
                    f"vehicles.{vid}.control_phase must be below its control period "
                    f"({self.control_every(vid)} ticks), got {v.control_phase!r}"
                )
        cube = kinds.get("cubesat")
        d = self.dispersions
        misalign = 0.0 if cube is None else cube.p.dispersions.thruster_misalignment_deg
        if (
            cube is not None
            and (d.mass_sigma_frac > 0 or misalign > 0)
            and (self.estimator.accel_psd_m2_s3 <= DOCKING_ESTIMATOR.accel_psd_m2_s3)
        ):
            warnings.warn(
                f"estimator.accel_psd_m2_s3 = {self.estimator.accel_psd_m2_s3!r} is sized for a truth "
                f"without thrust errors, but dispersions.mass_sigma_frac = {d.mass_sigma_frac!r} and "
                f"kinds.cubesat.dispersions.thruster_misalignment_deg = {misalign!r} add an "
                "acceleration the filter does not model: raise it to that truth's PSD (1e-8 for 3 % and "
                "0.5 deg), or the filter is overconfident (docs/results/faults-analysis/NEES.md, table 4)",
                UserWarning,
                stacklevel=3,  # the caller of the dataclass's __init__
            )
        if self.markers.half_size_m != self.guidance.half_size_m:
            raise ConfigError(
                "markers.half_size_m must equal guidance.half_size_m "
                f"({self.guidance.half_size_m!r}: one cube), "
                f"got {self.markers.half_size_m!r}"
            )
        e, e0 = self.estimator, EstimatorParams()
        for name, mount in _MOUNT_FIELDS.items():
            if tuple(getattr(e, name)) != tuple(getattr(e0, name)):
                raise ConfigError(
                    f"estimator.{name}: the filter's model of the mount is the vehicle kind's "
                    f"kinds.<kind>.mounts.{mount} (one source for the truth and the filter), got "
                    f"{getattr(e, name)!r}"
                )
        c, c0 = self.camera, CameraParams()
        for name, mount in (("pos_body_m", "camera_pos_body_m"), ("q_body_cam", "q_body_cam")):
            if tuple(getattr(c, name)) != tuple(getattr(c0, name)):
                raise ConfigError(
                    f"camera.{name}: where the camera sits is the vehicle kind's "
                    f"kinds.<kind>.mounts.{mount}, got {getattr(c, name)!r}"
                )
        for kind in kinds.values():
            kind.validate()

    # ---- derived ---------------------------------------------------------------------------------------
    @property
    def dt_s(self) -> float:
        return 1.0 / self.sim.imu_rate_hz

    def every(self, rate_hz: float) -> int:
        """Ticks between two events at ``rate_hz``."""
        return round(self.sim.imu_rate_hz / rate_hz)

    @property
    def chasers(self) -> list[str]:
        return [vid for vid, v in self.vehicles.items() if v.role == "chaser"]

    @property
    def kinds_used(self) -> list[str]:
        """The kinds of the scenario's vehicles, in vehicle order, each once."""
        return list(dict.fromkeys(v.kind for v in self.vehicles.values()))

    def kind(self, vehicle_id: str) -> VehicleKind:
        """The kind of ``vehicle_id``, bound to this scenario's ``[kinds.<kind>]`` tables."""
        return self._kinds[self.vehicles[vehicle_id].kind]

    def navigation(self, vehicle_id: str) -> str:
        """The name of ``vehicle_id``'s navigator (:data:`swarm.navigation.NAVIGATORS`)."""
        v = self.vehicles[vehicle_id]
        return navigator_name(KINDS[v.kind].imu_measures, v.navigation, f"vehicles.{vehicle_id}")

    def control_every(self, vehicle_id: str) -> int:
        """Ticks between two control steps of ``vehicle_id`` (its kind's controller rate)."""
        return self.every(self.kind(vehicle_id).control_rate_hz)

    def control_phase(self, vehicle_id: str) -> int:
        """The tick of the first control step of ``vehicle_id`` (``vehicles.<id>.control_phase``)."""
        return self.vehicles[vehicle_id].control_phase

    def estimator_for(self, vehicle_id: str) -> EstimatorParams:
        """The filter parameters of ``vehicle_id``: ``[estimator]`` with its kind's mounts as the model of
        the tag lever arm and the camera mounting."""
        from dataclasses import replace

        m = self.kind(vehicle_id).mounts
        return replace(self.estimator, lever_arm_body_m=m.tag_lever_arm_body_m,
                       camera_pos_body_m=m.camera_pos_body_m, q_body_cam=m.q_body_cam)  # fmt: skip

    def guidance_for(self, vehicle_id: str) -> GuidanceParams:
        """``[guidance]`` for ``vehicle_id``, its docked attitude that of its kind's docking port
        (:meth:`swarm.kinds.base.VehicleKind.q_target_chaser_docked`)."""
        cache = self.__dict__.setdefault("_guidance_for", {})
        name = self.vehicles[vehicle_id].kind
        if name not in cache:
            kind = self.kind(vehicle_id)
            cache[name] = self.guidance.with_port(kind.q_target_chaser_docked(self.guidance.docking_face))
        return cache[name]

    def camera_for(self, vehicle_id: str) -> CameraParams:
        """The camera of ``vehicle_id``: ``[camera]`` mounted where its kind's mounts say."""
        from dataclasses import replace

        m = self.kind(vehicle_id).mounts
        return replace(self.camera, pos_body_m=m.camera_pos_body_m, q_body_cam=m.q_body_cam)

    def with_pairs(self, n: int) -> Scenario:
        """This scenario with its vehicles copied ``n`` times (``swarm launch --agents N``): copy ``i`` of
        vehicle ``v`` is ``f"{v}{i}"`` (a chaser's target renamed alike), offset by a point of a square
        grid (``swarm.pair_spacing_m`` apart along ``swarm.grid_axes``, centred on the original). ``n = 1``
        returns the scenario unchanged, its ids included."""
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 64:
            raise ConfigError(f"--agents must be an integer in 1..64, got {n!r}")
        if n == 1:
            return self
        from dataclasses import replace

        side = int(np.ceil(np.sqrt(n)))
        axes = np.asarray(self.swarm.grid_axes, dtype=float)
        centre = (side - 1) / 2.0
        vehicles = {}
        for i in range(n):
            a, b = divmod(i, side)
            offset = self.swarm.pair_spacing_m * ((a - centre) * axes[0] + (b - centre) * axes[1])
            for vid, v in self.vehicles.items():
                pos = tuple(float(x) for x in np.asarray(v.position_m) + offset)
                target = None if v.target is None else f"{v.target}{i}"
                phase = (
                    len(vehicles) % self.control_every(vid) if self.swarm.stagger_control else v.control_phase
                )
                vehicles[f"{vid}{i}"] = replace(v, position_m=pos, target=target, control_phase=phase)
        return replace(self, vehicles=vehicles)

    def q0(self, vehicle_id: str) -> np.ndarray:
        """Initial attitude q_nav_body of a vehicle."""
        from swarm.core.rotations import euler_to_quat

        return euler_to_quat(np.radians(self.vehicles[vehicle_id].euler_deg), self.euler_seq)


_MOUNT_FIELDS = {
    "lever_arm_body_m": "tag_lever_arm_body_m",
    "camera_pos_body_m": "camera_pos_body_m",
    "q_body_cam": "q_body_cam",
}
"""``[estimator]`` fields that are the filter's model of a mount -> the field of ``kinds.<kind>.mounts``."""

LEGACY_KEYS = {
    ("dynamics",): ("kinds", "cubesat", "dynamics"),
    ("thrusters",): ("kinds", "cubesat", "thrusters"),
    ("attitude_control",): ("kinds", "cubesat", "attitude_control"),
    ("translation_control",): ("kinds", "cubesat", "translation_control"),
    ("tag_lever_arm_body_m",): ("kinds", "cubesat", "mounts", "tag_lever_arm_body_m"),
    ("camera", "pos_body_m"): ("kinds", "cubesat", "mounts", "camera_pos_body_m"),
    ("camera", "q_body_cam"): ("kinds", "cubesat", "mounts", "q_body_cam"),
    ("dispersions", "thruster_misalignment_deg"): (
        "kinds",
        "cubesat",
        "dispersions",
        "thruster_misalignment_deg",
    ),
}
"""Keys of the scenario format before vehicle kinds (issue 12), where every vehicle was a cube, and where
they live now. :func:`migrate_legacy` moves them, with a warning naming each."""


def migrate_legacy(data: dict, name: str = "scenario") -> dict:
    """``data`` (a parsed scenario) with the keys of :data:`LEGACY_KEYS` moved to their tables under
    ``[kinds.cubesat]``, and ``[estimator]``'s copies of the mounts dropped when they equal the mount they
    model; a FutureWarning lists what moved. A key given both ways is an error naming both. A file with a
    ``[kinds]`` table is of the current format and is left as it is."""
    if "kinds" in data:
        return data
    moved = []
    for old, new in LEGACY_KEYS.items():
        node = data
        for part in old[:-1]:
            node = node.get(part) if isinstance(node, dict) else None
        if not isinstance(node, dict) or old[-1] not in node:
            continue
        value = node.pop(old[-1])
        dst = data
        for part in new[:-1]:
            dst = dst.setdefault(part, {})
        if new[-1] in dst:
            raise ConfigError(f"{name}: {'.'.join(old)} and {'.'.join(new)} are the same field: give only "
                              f"{'.'.join(new)}")  # fmt: skip
        dst[new[-1]] = value
        moved.append(f"{'.'.join(old)} -> {'.'.join(new)}")
    est = data.get("estimator")
    if isinstance(est, dict):
        mounts = {**_mount_defaults(), **data.get("kinds", {}).get("cubesat", {}).get("mounts", {})}
        for field_name, mount in _MOUNT_FIELDS.items():
            if field_name in est and _same(est[field_name], mounts[mount]):
                est.pop(field_name)
                moved.append(
                    f"estimator.{field_name} (dropped: kinds.cubesat.mounts.{mount} is the filter's model)"
                )
    if moved:
        warnings.warn(f"{name}: keys of the scenario format before vehicle kinds moved: " + "; ".join(moved)
                      + " (docs/architecture.md)", FutureWarning, stacklevel=3)  # fmt: skip
    return data


def migrate_override_key(key: str) -> str:
    """An override's dotted key (``--set``) in the format before vehicle kinds, moved as
    :func:`migrate_legacy` moves a file's, with a FutureWarning; any other key as it is."""
    parts = tuple(key.split("."))
    for old, new in LEGACY_KEYS.items():
        if parts[: len(old)] == old:
            moved = ".".join(new + parts[len(old) :])
            msg = f"--set {key}: moved to {moved} (vehicle kinds, docs/architecture.md)"
            warnings.warn(msg, FutureWarning, stacklevel=4)
            return moved
    return key


def _mount_defaults() -> dict:
    from swarm.kinds.cubesat import CubesatParams

    m = CubesatParams().mounts
    return {"tag_lever_arm_body_m": m.tag_lever_arm_body_m, "camera_pos_body_m": m.camera_pos_body_m,
            "q_body_cam": m.q_body_cam}  # fmt: skip


def _same(a, b) -> bool:
    try:
        return tuple(float(x) for x in a) == tuple(float(x) for x in b)
    except (TypeError, ValueError):
        return False


def load_scenario(name_or_path: str | Path, overrides: dict | None = None) -> Scenario:
    """Load a scenario file, or a bundled one by name (``"docking"`` -> ``swarm/scenarios/docking.toml``).
    A file in the format before vehicle kinds is read too (:func:`migrate_legacy`)."""
    path = Path(name_or_path)
    if not path.suffix and not path.exists():
        path = SCENARIO_DIR / f"{name_or_path}.toml"

    def migrate(data: dict, name: str) -> dict:
        refuse_mission_key(data, name)
        return apply_sensor_profile(migrate_legacy(data, name), name, Scenario, overrides)

    return load_toml(Scenario, path, overrides=overrides, migrate=migrate, migrate_key=migrate_override_key)
