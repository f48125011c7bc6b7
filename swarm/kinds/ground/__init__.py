"""The ``ground`` kind: the TPODS MK-E module on a table, on four mecanum wheels (paper sec. VI-A, Fig. 7).

Planar motion (x, y, yaw) in the nav frame, whose x-y plane is the table (z up). Truth: the wheels follow
their speed commands through a first-order motor lag, saturate at the motors' speed, slip by a per-run
traction factor, and move the body by the mecanum kinematics (:mod:`.dynamics`). Controller: a discrete
LQR on the lagged velocity plant with integral action, a yaw law and the inverse kinematics (:mod:`.control`).
Sensors: the VN-100 IMU and attitude at the body origin, a Loco Positioning UWB node on a mast, and a
forward-looking camera on the front (+x) face, which docks against the target's face. Effort: the wheel
travel ``sum_wheels |omega| dt`` [rad].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarm.core import rotations as rot
from swarm.errors import ConfigError
from swarm.kinds.base import Actuation, Controller, Mounts, TruthActuator, VehicleDispersion, VehicleKind
from swarm.kinds.ground.control import GroundController
from swarm.kinds.ground.dynamics import KP_N, S_N, U_N, ground_truth_row, mecanum_inverse
from swarm.kinds.ground.params import (
    GroundBodyParams,
    GroundControlParams,
    GroundDispersionParams,
    WheelParams,
    slip_factors,
)


def _ground_mounts() -> Mounts:
    # the Loco Positioning node on a 6 cm mast above the body origin, 2 cm behind it; the OpenMV camera at the
    # centre of the front (+x) face looking forward: camera z = body x, camera x = -body y, camera y = -body z
    return Mounts((-0.02, 0.0, 0.06), (0.05, 0.0, 0.0), (0.5, -0.5, 0.5, -0.5))


@dataclass(frozen=True)
class GroundParams:
    """The tables of ``[kinds.ground]``."""

    body: GroundBodyParams = field(default_factory=GroundBodyParams)
    wheels: WheelParams = field(default_factory=WheelParams)
    control: GroundControlParams = field(default_factory=GroundControlParams)
    """Its ``rate_hz`` is the vehicle's control rate."""
    mounts: Mounts = field(default_factory=_ground_mounts)
    dispersions: GroundDispersionParams = field(default_factory=GroundDispersionParams)


class GroundTruth(TruthActuator):
    """One module's true wheels: geometry, lag, speed limit and traction (slip) factors."""

    def __init__(self, p: GroundParams, disp: VehicleDispersion) -> None:
        self.kp = ground_truth_row(p.wheels, disp.kind.get("wheel_traction", np.ones(4)))
        self.s0 = np.zeros(S_N)
        self.limit = p.wheels.max_speed_rad_s

    def hold(self, u, s, u_held) -> bool:
        w = np.asarray(u, dtype=float)
        if w.shape != (U_N,):
            raise ValueError(f"a ground command is {U_N} wheel speeds, got shape {w.shape}")
        w = np.clip(np.where(np.isfinite(w), w, 0.0), -self.limit, self.limit)
        if np.array_equal(w, u_held[:U_N]):
            return False
        u_held[:U_N] = w
        return True


class GroundControl(Controller):
    """:class:`GroundController` behind the kind interface; the known force is ``m`` times its known
    acceleration."""

    def __init__(self, p: GroundParams) -> None:
        self.c = GroundController(p.control, p.wheels, p.body)
        self.rate_hz = p.control.rate_hz
        self.mass = p.body.mass_kg

    def step(self, p_nav, v_nav, q_nav_body, w_body, ref, translate: bool, rotate: bool) -> Actuation:
        cmd = self.c.step(p_nav, v_nav, q_nav_body, ref.p_nav, ref.v_nav, ref.a_nav, ref.q_nav_body,
                          translate=translate, rotate=rotate)  # fmt: skip
        return Actuation(cmd.wheel_rad_s, self.mass * cmd.accel_body_known, saturated=cmd.saturated)

    def reset(self) -> None:
        self.c.reset()

    def idle(self) -> Actuation:
        return Actuation(self.c.zero_command(), np.zeros(3))

    def docked(self, speed_m_s: float) -> Actuation:
        """Creep forward (the port is the front face) at ``speed_m_s``: wheels stop on friction, so the last
        millimetres to the contact the estimate cannot resolve are driven, as a rover drives into its dock."""
        w = self.c.wheels
        wheels = mecanum_inverse(np.array([speed_m_s, 0.0, 0.0]), w.radius_m, w.half_length_m, w.half_width_m)
        return Actuation(wheels, np.zeros(3))


class GroundKind(VehicleKind):
    """The wheeled module (module docstring)."""

    name = "ground"
    code = 1
    Params = GroundParams
    S_N = S_N
    U_N = U_N
    KP_N = KP_N
    planar = True
    effort_key = "wheel_travel_rad"
    effort_unit = "rad"
    effort_label = "wheel travel"
    target_effort_key = "target_wheel_travel_rad"

    def validate(self) -> None:
        g = self.sc.guidance
        if self.p.body.half_size_m != g.half_size_m:
            raise ConfigError(
                "kinds.ground.body.half_size_m must equal guidance.half_size_m "
                f"({g.half_size_m!r}: one module size), got {self.p.body.half_size_m!r}"
            )
        if g.docking_face[1] == "z":
            raise ConfigError(
                "guidance.docking_face must be a side face (+x, -x, +y, -y) for ground vehicles, which dock "
                f"front face to face on the table, got {g.docking_face!r}"
            )
        for vid, v in self.sc.vehicles.items():
            if v.kind != self.name:
                continue
            q = self.sc.q0(vid)
            if abs(q[0]) > 1e-9 or abs(q[1]) > 1e-9:
                raise ConfigError(
                    f"vehicles.{vid}.euler_deg must be a rotation about the table's normal (z) only for a "
                    f"ground vehicle, got {tuple(v.euler_deg)!r}"
                )

    @property
    def mounts(self) -> Mounts:
        return self.p.mounts

    @property
    def mass_kg(self) -> float:
        return self.p.body.mass_kg

    control_rate_field = "kinds.ground.control.rate_hz"

    @property
    def control_rate_hz(self) -> float:
        return self.p.control.rate_hz

    def q_target_chaser_docked(self, face: str) -> np.ndarray:
        """The chaser's front (+x) axis into the target's face (along minus its outward normal), the two
        bodies' z axes both up (the table's normal)."""
        n = np.zeros(3)
        n["xyz".index(face[1])] = 1.0 if face[0] == "+" else -1.0
        x_c = -n
        z_c = np.array([0.0, 0.0, 1.0])
        y_c = np.cross(z_c, x_c)
        return rot.matrix_to_quat(np.column_stack([x_c, y_c, z_c]))

    def truth(self, disp: VehicleDispersion) -> GroundTruth:
        return GroundTruth(self.p, disp)

    def draw_dispersion(self, seed: int, vehicle_index: int, distribution: str) -> dict[str, np.ndarray]:
        from swarm.kinds.dispersions import dispersion_rng

        sigma = self.p.dispersions.wheel_slip_sigma_frac
        if sigma <= 0:
            return {}
        rng = dispersion_rng(seed, "wheel_slip", vehicle_index)
        return {"wheel_traction": slip_factors(sigma, distribution, rng)}

    def dispersion_enabled(self) -> bool:
        return self.p.dispersions.wheel_slip_sigma_frac > 0

    @staticmethod
    def dispersion_columns(extra: dict[str, np.ndarray]) -> dict[str, float]:
        t = extra.get("wheel_traction", np.ones(4))
        return {f"disp_wheel_traction_{i + 1}": float(t[i]) for i in range(4)}

    def plane_constraint(self) -> tuple[float, float]:
        b = self.p.body
        return b.height_sigma_m, b.vertical_speed_sigma_m_s

    def controller(self) -> GroundControl:
        return GroundControl(self.p)
