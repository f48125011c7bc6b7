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

import numba
import numpy as np

from swarm.core import _guidance_nb as gnb
from swarm.core import rotations as rot
from swarm.errors import ConfigError
from swarm.kinds.base import (
    ACT_FORCE,
    ACT_FORCE_KNOWN,
    ACT_TORQUE,
    Mounts,
    TruthActuator,
    VehicleDispersion,
    VehicleKind,
)
from swarm.kinds.ground.control import (
    CP_HALF_LENGTH,
    CP_HALF_WIDTH,
    CP_RADIUS,
    design_ground_lqr,
    ground_control_row,
    ground_control_step,
)
from swarm.kinds.ground.control import CP_N as CP_CONTROL_N
from swarm.kinds.ground.dynamics import KP_MAX_SPEED, KP_N, S_N, U_N, _inverse4, ground_truth_row
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


@numba.njit(cache=True)
def ground_hold(u_cmd, s, u_held, kp):
    """Hold the wheel-speed commands ``u_cmd`` (4,) [rad/s], each clipped to the motors' speed, a non-finite
    one zero. Returns False when they equal the held ones (nothing written)."""
    limit = kp[KP_MAX_SPEED]
    same = True
    w = np.empty(U_N)
    for i in range(U_N):
        c = u_cmd[i]
        w[i] = 0.0 if not np.isfinite(c) else min(max(c, -limit), limit)
        same = same and w[i] == u_held[i]
    if same:
        return False
    for i in range(U_N):
        u_held[i] = w[i]
    return True


CP_MASS = CP_CONTROL_N
CP_N = CP_CONTROL_N + 1
CS_N = 2


@numba.njit(cache=True)
def ground_control(cs, cp, p, v, q, w, ref, translate, rotate, u, act):
    """One control step (:func:`swarm.kinds.ground.control.ground_control_step`) toward the reference row
    ``ref`` (``R_*``); the known force is the mass times the known acceleration, and the kind has no net
    force or torque to report (NaN)."""
    twist, accel = np.empty(3), np.empty(3)
    sat = ground_control_step(cs, cp, p, v, q, ref[gnb.R_P : gnb.R_P + 3], ref[gnb.R_V : gnb.R_V + 3],
                              ref[gnb.R_A : gnb.R_A + 3], ref[gnb.R_Q : gnb.R_Q + 4], translate, rotate, u,
                              twist, accel)  # fmt: skip
    for i in range(3):
        act[ACT_FORCE_KNOWN + i] = cp[CP_MASS] * accel[i]
        act[ACT_FORCE + i] = np.nan
        act[ACT_TORQUE + i] = np.nan
    return sat


@numba.njit(cache=True)
def ground_idle(cp, u, act):
    """Wheels stopped."""
    for i in range(U_N):
        u[i] = 0.0
    for i in range(3):
        act[ACT_FORCE_KNOWN + i] = 0.0
        act[ACT_FORCE + i] = np.nan
        act[ACT_TORQUE + i] = np.nan


@numba.njit(cache=True)
def ground_docked(cp, speed_m_s, u, act):
    """Creep forward (the port is the front face) at ``speed_m_s``: wheels stop on friction, so the last
    millimetres to the contact the estimate cannot resolve are driven, as a rover drives into its dock."""
    r, hl, hw = cp[CP_RADIUS], cp[CP_HALF_LENGTH], cp[CP_HALF_WIDTH]
    u[0], u[1], u[2], u[3] = _inverse4(speed_m_s, 0.0, 0.0, r, hl, hw)
    for i in range(3):
        act[ACT_FORCE_KNOWN + i] = 0.0
        act[ACT_FORCE + i] = np.nan
        act[ACT_TORQUE + i] = np.nan


class GroundKind(VehicleKind):
    """The wheeled module (module docstring)."""

    name = "ground"
    code = 1
    Params = GroundParams
    S_N = S_N
    U_N = U_N
    KP_N = KP_N
    CP_N = CP_N
    CS_N = CS_N
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

    def control_row(self) -> np.ndarray:
        p = self.p
        return np.append(ground_control_row(p.control, p.wheels, design_ground_lqr(p.control, p.wheels)),
                         p.body.mass_kg)  # fmt: skip


GroundTruth.code, GroundTruth.U_N = GroundKind.code, GroundKind.U_N
