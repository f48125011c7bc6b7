"""The vehicle-kind plug-in interface (docs/architecture.md, "Vehicle kinds").

A kind is what differs between a CubeSat module, a wheeled module on a table and a quadrotor: its truth
dynamics and actuators, its controller and allocation, where its sensors sit, how it docks. Everything
else (the estimator, guidance and Algorithm 1, the sensors' noise models, the radio network, the referee,
the runners) is shared and reaches a kind only through :class:`VehicleKind` and the padded arrays of the
compiled world loop:

* ``x`` (13,): the truth row ``[p_nav, v_nav, q_nav_body (x, y, z, w), w_body]``, the same for every kind;
* ``s`` (``S_N``,): the kind's actuator state (a cubesat's held body wrench, a rover's wheel speeds);
* ``u`` (``U_N``,): the held actuator command (nozzle thrusts [N], wheel speeds [rad/s]);
* ``kp`` (``KP_N``,): the kind's truth parameters of that vehicle, dispersions applied;
* ``cp`` (``CP_N``,): its controller's parameters (nominal: the controller does not know the dispersions),
  ``cs`` (``CS_N``,) the controller's state (integrals);
* ``act`` (:data:`ACT_N`,): what a control step achieved, ``[known force (3) N, net force (3) N, net torque
  (3) N m]`` in the body frame, NaN where the kind has no such quantity.

The compiled dispatch (:mod:`swarm.kinds._dispatch`) reaches every kind's steps by its ``code``:
``truth_step(code, x, s, u, kp, dt)`` advances one vehicle by one tick, ``hold_step(code, u_cmd, s,
u_held, kp)`` holds a new command, ``control_step(code, cs, cp, p, v, q, w, ref, translate, rotate, u,
act)`` is one control step toward a guidance reference, ``idle_step`` and ``docked_step`` the commands
with all actuators off and once docked.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from swarm.errors import ConfigError

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def _finite_vec(section: str, name: str, value, n: int) -> tuple[float, ...]:
    try:
        v = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        raise ConfigError(f"{section}.{name} must be {n} finite numbers, got {value!r}") from None
    if len(v) != n or not all(math.isfinite(x) for x in v):
        raise ConfigError(f"{section}.{name} must be {n} finite numbers, got {value!r}")
    return v


@dataclass(frozen=True)
class Mounts:
    """Where a vehicle's sensors sit on its body, body frame. The truth's sensors and the filter's
    measurement models both use these (one source, no copy to keep equal)."""

    tag_lever_arm_body_m: Vec3 = (0.05, 0.05, 0.0)
    """UWB tag antenna from the centre of mass [m] (paper sec. III's ``P1``)."""
    camera_pos_body_m: Vec3 = (0.0, 0.0, -0.05)
    """Camera optical centre from the centre of mass [m]."""
    q_body_cam: Quat = (1.0, 0.0, 0.0, 0.0)
    """Camera attitude, scalar-last, mapping OpenCV camera-frame vectors (+z optical axis, +x right, +y down)
    into the body frame."""

    def __post_init__(self) -> None:
        for name, n in (("tag_lever_arm_body_m", 3), ("camera_pos_body_m", 3), ("q_body_cam", 4)):
            object.__setattr__(self, name, _finite_vec("mounts", name, getattr(self, name), n))
        norm = math.sqrt(sum(c * c for c in self.q_body_cam))
        if abs(norm - 1.0) > 1e-6:
            raise ConfigError(f"mounts.q_body_cam must be a unit quaternion, got {self.q_body_cam!r}")

    @property
    def camera_axis_body(self) -> np.ndarray:
        """The optical axis (unit, body frame)."""
        from swarm.core.rotations import quat_rotate

        return quat_rotate(np.asarray(self.q_body_cam, dtype=float), np.array([0.0, 0.0, 1.0]))


ACT_FORCE_KNOWN, ACT_FORCE, ACT_TORQUE = 0, 3, 6
ACT_N = 9


@dataclass
class Actuation:
    """What a kind's controller decided at one control tick."""

    u: np.ndarray
    """The actuator command (``VehicleKind.U_N``,) in the kind's units, held by the world until the next."""
    f_body_known_n: np.ndarray
    """(3,) the force [N] the filter takes as its known input, body frame: it predicts with ``R(q) f / m``."""
    force_body_n: np.ndarray | None = None
    """(3,) net body force the command produces [N], where the kind has one (the nozzles)."""
    torque_body_nm: np.ndarray | None = None
    """(3,) net body torque about the centre of mass [N m], where the kind has one."""
    saturated: bool = False
    """An actuator limit scaled the command down."""


@dataclass
class VehicleDispersion:
    """One vehicle's run-to-run dispersions, as drawn (:mod:`swarm.kinds.dispersions`)."""

    position_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity_m_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    attitude_rad: np.ndarray = field(default_factory=lambda: np.zeros(3))
    mass_factor: float = 1.0
    inertia_factor: np.ndarray = field(default_factory=lambda: np.ones(3))
    kind: dict[str, np.ndarray] = field(default_factory=dict)
    """The kind's own draws (nozzle misalignment, wheel slip), named by the kind."""


class TruthActuator:
    """The truth side of one vehicle's actuators: its compiled parameters and how a command is held."""

    code: int
    """The kind's code (:attr:`VehicleKind.code`)."""
    kp: np.ndarray
    """(KP_N,) truth parameters for the kind's compiled steps (dispersions applied)."""
    s0: np.ndarray
    """(S_N,) actuator state at tick 0."""
    U_N: int


class VehicleKind(ABC):
    """One kind of vehicle (module docstring); instances are bound to a scenario's parameters."""

    name: ClassVar[str]
    """The kind's name in scenario files (``[vehicles.X] kind = "..."``) and its table ``[kinds.<name>]``."""
    code: ClassVar[int]
    """Its number in the compiled dispatch (:mod:`swarm.kinds._dispatch`)."""
    Params: ClassVar[type]
    """Its parameter tables: a frozen dataclass, the TOML table ``[kinds.<name>]``."""
    S_N: ClassVar[int]
    U_N: ClassVar[int]
    KP_N: ClassVar[int]
    CP_N: ClassVar[int]
    CS_N: ClassVar[int]
    planar: ClassVar[bool] = False
    """Moves in the nav x-y plane only (x, y, yaw): the filter then fuses a height and vertical-velocity
    constraint, and the initial dispersions act in the plane."""
    imu_measures: ClassVar[frozenset[str]] = frozenset({"gyro"})
    """What its IMU measures: ``"gyro"`` (rate), and ``"accelerometer"`` (specific force) where the world
    models one. It picks the vehicle's filter (:func:`swarm.navigation.navigator_name`)."""
    docking_missing: ClassVar[str | None] = None
    """What the docking runners lack to fly this kind, for the refusal of a docking scenario that names it
    (:func:`swarm.kinds.check_docking_kind`); None: they fly it."""
    effort_key: ClassVar[str]
    """Name of the kind's effort metric in run summaries (``total_impulse_ns``, ``wheel_travel_rad``)."""
    effort_unit: ClassVar[str]
    effort_label: ClassVar[str]
    """The effort metric's name in reports (``total impulse``)."""
    target_effort_key: ClassVar[str]
    """Its campaign column for the chaser's target (``target_impulse_ns``)."""

    def __init__(self, params, scenario) -> None:
        self.p = params
        self.sc = scenario

    # ---- scenario-level ----------------------------------------------------------------------------
    def validate(self) -> None:  # noqa: B027 - optional hook
        """Checks across the kind's tables and the scenario's; ConfigError naming the field."""

    @property
    @abstractmethod
    def mounts(self) -> Mounts: ...

    @property
    @abstractmethod
    def mass_kg(self) -> float:
        """Nominal mass [kg]: the filter's known input is ``f / m``."""

    control_rate_field: ClassVar[str]
    """The dotted scenario field of :attr:`control_rate_hz`, for error messages."""

    @property
    @abstractmethod
    def control_rate_hz(self) -> float:
        """The rate of the kind's controller [Hz]: the vehicle's control ticks (it divides the IMU rate)."""

    @abstractmethod
    def q_target_chaser_docked(self, face: str) -> np.ndarray:
        """Attitude of a docked chaser of this kind relative to its target (q_target_chaser, scalar-last),
        docking on the target's ``face`` (``"+x"``, ... in the target body frame)."""

    # ---- truth (world) -------------------------------------------------------------------------------
    @abstractmethod
    def truth(self, disp: VehicleDispersion) -> TruthActuator:
        """One vehicle's truth actuator model with its dispersions."""

    def constrain_initial(self, x: np.ndarray) -> None:  # noqa: B027 - optional hook
        """Bring an initial truth row (13,) onto the kind's degrees of freedom, in place."""

    def draw_dispersion(self, seed: int, vehicle_index: int, distribution: str) -> dict[str, np.ndarray]:
        """The kind's own run-to-run draws for one vehicle (nothing by default)."""
        return {}

    def dispersion_enabled(self) -> bool:
        """Whether any of the kind's own dispersions is on."""
        return False

    @staticmethod
    def dispersion_columns(extra: dict[str, np.ndarray]) -> dict[str, float]:
        """The kind's own draws of one vehicle as flat campaign-CSV columns (``disp_*``)."""
        return {}

    # ---- agent ---------------------------------------------------------------------------------------
    def plane_constraint(self) -> tuple[float, float] | None:
        """For a planar kind, the standard deviations ``(sigma_z [m], sigma_vz [m/s])`` of the filter's
        height and vertical-velocity constraint (:func:`swarm.core._ekf_nb.constrain_plane_one`); None
        for a vehicle free in 3-D."""
        return None

    @abstractmethod
    def control_row(self) -> np.ndarray:
        """The controller's parameters (``CP_N``,) as the kind's compiled control step reads them."""
