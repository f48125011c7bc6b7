"""Parameter tables of the ``quadrotor`` kind (``[kinds.quadrotor.*]``): a 1.5 kg X-frame quadrotor of the
F450 class with 10-inch propellers, the paper's section VI-B vehicle."""

from __future__ import annotations

import math
from dataclasses import dataclass

from swarm.errors import ConfigError


def _positive(section: str, obj, *names: str) -> None:
    for name in names:
        v = getattr(obj, name)
        if not (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v > 0):
            raise ConfigError(f"kinds.quadrotor.{section}.{name} must be a positive finite number, got {v!r}")


@dataclass(frozen=True)
class AirframeParams:
    """``[kinds.quadrotor.airframe]``: rigid body, rotors, drag (body x forward, y left, z up; rotors 1
    front-left, 2 front-right, 3 rear-right, 4 rear-left on the diagonals of an X frame)."""

    mass_kg: float = 1.5
    inertia_kg_m2: tuple[float, float, float] = (0.0123, 0.0123, 0.0224)
    """Principal moments about body x, y, z [kg m^2]."""
    arm_m: float = 0.225
    """Rotor hub to centre of mass [m]."""
    thrust_coeff: float = 1.2e-5
    """``k_T``: a rotor's thrust is ``k_T omega^2`` [N / (rad/s)^2]."""
    torque_coeff: float = 1.8e-7
    """``k_Q``: its drag torque about the rotor axis ``k_Q omega^2`` [N m / (rad/s)^2]."""
    rotor_tau_s: float = 0.03
    """Rotor speed first-order time constant [s] (motor and ESC)."""
    omega_min_rad_s: float = 100.0
    """Idle speed of an armed rotor [rad/s]."""
    omega_max_rad_s: float = 1100.0
    """Top speed [rad/s] (thrust-to-weight ~3.9 with the defaults)."""
    drag_n_s_m: tuple[float, float, float] = (0.3, 0.3, 0.5)
    """Linear drag along body x, y, z [N / (m/s)] (blade flapping and induced drag, Mahony et al. 2012)."""
    efficiency: float = 0.7
    """Electrical to shaft power of motor and ESC: a rotor draws ``k_Q omega^3 / efficiency`` [W]."""
    gravity_m_s2: float = 9.81
    """Gravity along nav -z [m/s^2]."""
    ground_z_m: float = 0.0
    """Height of the ground (the pad's surface) in nav [m]."""
    gear_height_m: float = 0.05
    """Centre of mass above the skids when standing [m]."""
    substeps: int = 4
    """RK4 steps per tick of the truth."""

    def __post_init__(self) -> None:
        _positive("airframe", self, "mass_kg", "arm_m", "thrust_coeff", "torque_coeff", "rotor_tau_s",
                  "omega_max_rad_s", "efficiency", "gravity_m_s2", "gear_height_m")  # fmt: skip
        for name in ("inertia_kg_m2", "drag_n_s_m"):
            v = getattr(self, name)
            if (
                len(v) != 3
                or not all(math.isfinite(x) and x >= 0 for x in v)
                or (name == "inertia_kg_m2" and min(v) <= 0)
            ):
                raise ConfigError(
                    f"kinds.quadrotor.airframe.{name} must be three finite numbers >= 0 (> 0 for inertia), "
                    f"got {v!r}"
                )
        if not 0 <= self.omega_min_rad_s < self.omega_max_rad_s:
            raise ConfigError(
                "kinds.quadrotor.airframe.omega_min_rad_s must be in [0, omega_max_rad_s), "
                f"got {self.omega_min_rad_s!r}"
            )
        if self.efficiency > 1:
            raise ConfigError(
                f"kinds.quadrotor.airframe.efficiency must be in (0, 1], got {self.efficiency!r}"
            )
        if 4 * self.thrust_coeff * self.omega_max_rad_s**2 <= self.mass_kg * self.gravity_m_s2:
            raise ConfigError("kinds.quadrotor.airframe: the rotors at omega_max_rad_s cannot lift mass_kg")
        if not (isinstance(self.substeps, int) and 1 <= self.substeps <= 64):
            raise ConfigError(
                f"kinds.quadrotor.airframe.substeps must be an integer in [1, 64], got {self.substeps!r}"
            )

    @property
    def hover_omega_rad_s(self) -> float:
        """The trim rotor speed: four rotors carry the weight."""
        return math.sqrt(self.mass_kg * self.gravity_m_s2 / (4.0 * self.thrust_coeff))

    @property
    def hover_power_w(self) -> float:
        """Electrical power in a hover [W] (the rotor power model at the trim speed)."""
        return 4.0 * self.torque_coeff * self.hover_omega_rad_s**3 / self.efficiency


@dataclass(frozen=True)
class ControlParams:
    """``[kinds.quadrotor.control]``: the cascaded controller of PX4's multicopter stack (position P ->
    velocity PID -> thrust vector and attitude -> attitude P on the quaternion error -> rate P -> torque),
    at the vehicle's control rate."""

    rate_hz: float = 100.0
    pos_gain_xy: float = 1.0
    """Position error to velocity setpoint [1/s] (``MPC_XY_P``)."""
    pos_gain_z: float = 1.2
    vel_gain_xy: float = 2.0
    """Velocity error to acceleration [1/s] (``MPC_XY_VEL_P_ACC``)."""
    vel_int_xy: float = 0.4
    """[1/s^2] (``MPC_XY_VEL_I_ACC``)."""
    vel_gain_z: float = 4.0
    vel_int_z: float = 2.0
    max_speed_xy_m_s: float = 3.0
    max_speed_z_m_s: float = 1.5
    max_tilt_deg: float = 30.0
    att_gain: float = 6.0
    """Attitude error to rate setpoint [1/s] (``MC_ROLL_P``)."""
    att_gain_yaw: float = 2.8
    rate_gain: float = 18.0
    """Rate error to angular acceleration [1/s]."""
    rate_gain_yaw: float = 6.0
    max_rate_deg_s: float = 220.0
    int_limit_m_s2: float = 3.0
    """Bound on each velocity integral's acceleration [m/s^2]."""
    spec_step_overshoot: float = 0.10
    """The step response this tuning is specified to meet, on the true state: a 1 m position step
    overshoots by at most this fraction ... (tests/kinds/test_quadrotor.py)."""
    spec_step_settle_s: float = 3.0
    """... and stays within 5 % of the step after this long [s]."""

    def __post_init__(self) -> None:
        _positive("control", self, "rate_hz", "pos_gain_xy", "pos_gain_z", "vel_gain_xy", "vel_gain_z",
                  "max_speed_xy_m_s", "max_speed_z_m_s", "max_tilt_deg", "att_gain", "att_gain_yaw",
                  "rate_gain", "rate_gain_yaw", "max_rate_deg_s", "int_limit_m_s2", "spec_step_overshoot",
                  "spec_step_settle_s")  # fmt: skip
        for name in ("vel_int_xy", "vel_int_z"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ConfigError(f"kinds.quadrotor.control.{name} must be >= 0, got {getattr(self, name)!r}")
        if self.max_tilt_deg >= 80:
            raise ConfigError(
                f"kinds.quadrotor.control.max_tilt_deg must be below 80, got {self.max_tilt_deg!r}"
            )


@dataclass(frozen=True)
class QuadrotorParams:
    """``[kinds.quadrotor]``."""

    airframe: AirframeParams = AirframeParams()
    control: ControlParams = ControlParams()
