"""The ``cubesat`` kind: the 6-DOF TPODS cube with ten cold-gas nozzles (paper sections II and IV-B).

Truth: the rigid body of paper eq. (1)-(2) (:func:`swarm.core.dynamics.propagate`, RK4) under the body
wrench of the held nozzle thrusts. Controller: the discrete translation LQR with feed-forward and integral
action and the Wie & Barba quaternion-feedback attitude law (:mod:`swarm.core.control`), the wrench
allocated to non-negative nozzle thrusts (:func:`swarm.core.thrusters.allocate`). The filter's known
input is the achieved thrust force, ``a_nav = R(q) f_body / m``. Effort: the total impulse
``sum_nozzles |f| dt`` [N s] (the paper's Table II).

Arrays of the compiled truth step (:mod:`swarm.kinds.base`): ``s = [F_body (3) N, tau_body (3) N m,
sum of thrusts N]`` (the held wrench, computed once per command), ``u`` the ten thrusts [N], ``kp = [mass
kg, Ixx, Iyy, Izz kg m^2, largest RK4 sub-step s]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from swarm.core import rotations as rot
from swarm.core.control import (
    AttitudeControlParams,
    TranslationController,
    TranslationLqrParams,
    attitude_torque,
)
from swarm.core.dynamics import RigidBodyParams, propagate
from swarm.core.thrusters import N_NOZZLES, ThrusterParams, allocate, allocation_matrix, nozzle_geometry
from swarm.errors import ConfigError
from swarm.kinds.base import Actuation, Controller, Mounts, TruthActuator, VehicleDispersion, VehicleKind

KP_MASS, KP_IXX, KP_IZZ, KP_HMAX = 0, 1, 3, 4
S_FORCE, S_TORQUE, S_THRUST_SUM = 0, 3, 6


@dataclass(frozen=True)
class CubesatDispersionParams:
    """The cubesat's own run-to-run dispersions (the shared ones are the scenario's ``[dispersions]``)."""

    thruster_misalignment_deg: float = 0.0
    """Each nozzle's true thrust direction turned by a rotation vector with this standard deviation per
    axis [deg], per vehicle and run; the allocation keeps the nominal directions."""

    def __post_init__(self) -> None:
        v = self.thruster_misalignment_deg
        if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
            raise ConfigError(
                f"dispersions.thruster_misalignment_deg must be a non-negative finite number, got {v!r}"
            )


def _cube_mounts() -> Mounts:
    # the paper's tag P1 = (0.05, 0.05, 0) m (sec. III); the camera on the bottom face (Fig. 5), looking -z
    return Mounts((0.05, 0.05, 0.0), (0.0, 0.0, -0.05), (1.0, 0.0, 0.0, 0.0))


@dataclass(frozen=True)
class CubesatParams:
    """The tables of ``[kinds.cubesat]``."""

    dynamics: RigidBodyParams = field(default_factory=RigidBodyParams)
    thrusters: ThrusterParams = field(default_factory=ThrusterParams)
    attitude_control: AttitudeControlParams = field(default_factory=AttitudeControlParams)
    translation_control: TranslationLqrParams = field(default_factory=TranslationLqrParams)
    """Its ``rate_hz`` is the vehicle's control rate."""
    mounts: Mounts = field(default_factory=_cube_mounts)
    dispersions: CubesatDispersionParams = field(default_factory=CubesatDispersionParams)


@numba.njit(cache=True)
def cubesat_truth_step(x, s, u, kp, dt):
    """One tick of a cube (module docstring): ``x`` advanced in place under the held wrench ``s``;
    returns the impulse ``sum |f| dt`` [N s] of the tick."""
    y = propagate(x, s[S_FORCE : S_FORCE + 3], s[S_TORQUE : S_TORQUE + 3], dt, kp[KP_MASS],
                  kp[KP_IXX : KP_IZZ + 1], kp[KP_HMAX])  # fmt: skip
    x[:13] = y
    return s[S_THRUST_SUM] * dt


class CubesatTruth(TruthActuator):
    """One cube's true nozzles: their (possibly misaligned) directions and the thrust limit."""

    def __init__(self, p: CubesatParams, disp: VehicleDispersion) -> None:
        d = p.dynamics
        self.kp = np.array([d.mass_kg, *d.inertia_diag_kgm2, d.integration_step_s])
        self.kp[KP_MASS] *= disp.mass_factor
        self.kp[KP_IXX : KP_IZZ + 1] *= disp.inertia_factor
        self.s0 = np.zeros(CubesatKind.S_N)
        self.max_thrust = p.thrusters.max_thrust_n
        rotvec = disp.kind.get("thruster_rotvec_rad")
        if rotvec is None:
            self.B = allocation_matrix(p.thrusters)
        else:
            r, dirs = nozzle_geometry(p.thrusters)
            d_true = rot.quat_rotate(rot.rotvec_exp(rotvec), dirs)
            self.B = np.vstack([d_true.T, np.cross(r, d_true).T])

    def hold(self, u, s, u_held) -> bool:
        f = np.asarray(u, dtype=float)
        if f.shape != (N_NOZZLES,):
            raise ValueError(f"a cubesat command is {N_NOZZLES} nozzle thrusts, got shape {f.shape}")
        if s[S_THRUST_SUM] == 0.0 and not f.any():
            return False  # still all off: nothing to recompute
        f = np.clip(f, 0.0, self.max_thrust)
        f = np.where(np.isfinite(f), f, 0.0)
        u_held[:N_NOZZLES] = f
        s[S_FORCE : S_TORQUE + 3] = self.B @ f
        s[S_THRUST_SUM] = float(np.sum(f))
        return True


class CubesatController(Controller):
    """Translation LQR + quaternion-feedback attitude law + nozzle allocation (paper sec. IV-B)."""

    def __init__(self, p: CubesatParams) -> None:
        self.p = p
        self.rate_hz = p.translation_control.rate_hz
        self.translation = TranslationController(p.dynamics.mass_kg, p.translation_control)
        self.inertia = np.asarray(p.dynamics.inertia_diag_kgm2, dtype=float)
        self.B = allocation_matrix(p.thrusters)
        self.max_thrust = p.thrusters.max_thrust_n

    def step(self, p_nav, v_nav, q_nav_body, w_body, ref, translate: bool, rotate: bool) -> Actuation:
        F_nav = self.translation.step(p_nav, v_nav, ref.p_nav, ref.v_nav, ref.a_nav)
        tau = attitude_torque(q_nav_body, w_body, ref.q_nav_body, None, self.inertia, self.p.attitude_control)
        if not translate:  # a station keeper inside its dead band: hold still on this axis set
            F_nav = np.zeros(3)
            self.translation.reset()
        if not rotate:
            tau = np.zeros(3)
        F_body = rot.quat_rotate(rot.quat_conj(q_nav_body), F_nav)
        alloc = allocate(np.concatenate([F_body, tau]), self.B, self.max_thrust)
        w = alloc.wrench_achieved
        return Actuation(alloc.thrusts_n, w[:3], w[:3], w[3:], bool(alloc.saturated))

    def reset(self) -> None:
        self.translation.reset()

    def idle(self) -> Actuation:
        z = np.zeros(3)
        return Actuation(np.zeros(self.B.shape[1]), z, z.copy(), z.copy(), False)


class CubesatKind(VehicleKind):
    """The TPODS cube (module docstring)."""

    name = "cubesat"
    code = 0
    Params = CubesatParams
    S_N = 7
    U_N = N_NOZZLES
    KP_N = 5
    planar = False
    effort_key = "total_impulse_ns"
    effort_unit = "N s"
    effort_label = "total impulse"
    target_effort_key = "target_impulse_ns"

    def validate(self) -> None:
        g = self.sc.guidance
        if self.p.thrusters.half_size_m != g.half_size_m:
            raise ConfigError(
                "kinds.cubesat.thrusters.half_size_m must equal guidance.half_size_m "
                f"({g.half_size_m!r}: the nozzles sit on the same cube), got {self.p.thrusters.half_size_m!r}"
            )

    @property
    def mounts(self) -> Mounts:
        return self.p.mounts

    @property
    def mass_kg(self) -> float:
        return self.p.dynamics.mass_kg

    control_rate_field = "kinds.cubesat.translation_control.rate_hz"

    @property
    def control_rate_hz(self) -> float:
        return self.p.translation_control.rate_hz

    def q_target_chaser_docked(self, face: str) -> np.ndarray:
        """The chaser's +z along the face normal (its bottom face and camera against the docking face), its
        +x along the next target axis in x -> y -> z order (the port's clocking)."""
        n = np.zeros(3)
        axis = "xyz".index(face[1])
        n[axis] = 1.0 if face[0] == "+" else -1.0
        x_c = np.zeros(3)
        x_c[(axis + 1) % 3] = 1.0
        y_c = np.cross(n, x_c)
        return rot.matrix_to_quat(np.column_stack([x_c, y_c, n]))

    def truth(self, disp: VehicleDispersion) -> CubesatTruth:
        return CubesatTruth(self.p, disp)

    def draw_dispersion(self, seed: int, vehicle_index: int, distribution: str) -> dict[str, np.ndarray]:
        from swarm.kinds.dispersions import dispersion_rng, draw

        sigma = math.radians(self.p.dispersions.thruster_misalignment_deg)
        if sigma <= 0:
            return {}
        rng = dispersion_rng(seed, "thrusters", vehicle_index)
        return {"thruster_rotvec_rad": draw(rng, sigma, 3 * N_NOZZLES, distribution).reshape(N_NOZZLES, 3)}

    def dispersion_enabled(self) -> bool:
        return self.p.dispersions.thruster_misalignment_deg > 0

    @staticmethod
    def dispersion_columns(extra: dict[str, np.ndarray]) -> dict[str, float]:
        rv = extra.get("thruster_rotvec_rad")
        rms = 0.0 if rv is None else float(np.sqrt(np.mean(np.sum(rv**2, axis=1))))
        return {"disp_thruster_rms_rad": rms}

    def controller(self) -> CubesatController:
        return CubesatController(self.p)
