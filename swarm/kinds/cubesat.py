"""The ``cubesat`` kind: the 6-DOF TPODS cube with ten cold-gas nozzles (paper sections II and IV-B).

Truth: the rigid body of paper eq. (1)-(2) (:func:`swarm.core.dynamics.propagate`, RK4) under the body
wrench of the held nozzle thrusts. Controller: the discrete translation LQR with feed-forward and integral
action and the Wie & Barba quaternion-feedback attitude law (:mod:`swarm.core.control`), the wrench
allocated to non-negative nozzle thrusts (:func:`swarm.core.thrusters.allocate`). The filter's known
input is the achieved thrust force, ``a_nav = R(q) f_body / m``. Effort: the total impulse
``sum_nozzles |f| dt`` [N s] (the paper's Table II).

Arrays of the compiled steps (:mod:`swarm.kinds.base`): ``s = [F_body (3) N, tau_body (3) N m, sum of
thrusts N]`` (the held wrench, computed once per command by :func:`cubesat_hold`), ``u`` the ten thrusts
[N], ``kp = [mass kg, Ixx, Iyy, Izz kg m^2, largest RK4 sub-step s, thrust limit N, the true wrench per
newton of each nozzle B (6 x 10, row-major)]``; the controller's ``cp`` (``CP_*``) and its state ``cs``,
the translation integral (3,) [m s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from swarm.core import _guidance_nb as gnb
from swarm.core import rotations as rot
from swarm.core._rot_nb import qconj, qrotate
from swarm.core.control import (
    AttitudeControlParams,
    TranslationLqrParams,
    _attitude_torque1,
    _lqr_step1,
    design_translation_lqr,
)
from swarm.core.dynamics import RigidBodyParams, propagate
from swarm.core.thrusters import N_NOZZLES, ThrusterParams, allocate_nb, allocation_matrix, nozzle_geometry
from swarm.errors import ConfigError
from swarm.kinds.base import ACT_N, Mounts, TruthActuator, VehicleDispersion, VehicleKind

KP_MASS, KP_IXX, KP_IZZ, KP_HMAX, KP_UMAX, KP_B = 0, 1, 3, 4, 5, 6
KP_N = KP_B + 6 * N_NOZZLES
S_FORCE, S_TORQUE, S_THRUST_SUM = 0, 3, 6
(CP_MASS, CP_KP, CP_KV, CP_KI, CP_DT, CP_ILIM, CP_FMAX, CP_INERTIA, CP_ATT_KP, CP_ATT_KD, CP_TMAX, CP_UMAX,
 CP_B) = (0, 1, 2, 3, 4, 5, 6, 7, 10, 11, 12, 13, 14)  # fmt: skip
CP_N = CP_B + 6 * N_NOZZLES
CS_N = 3


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


@numba.njit(cache=True)
def cubesat_hold(u_cmd, s, u_held, kp):
    """Hold the nozzle thrusts ``u_cmd`` (10,) [N]: each clipped to ``[0, limit]`` (a nozzle cannot pull), a
    non-finite one off; ``s`` gets the true wrench ``B f`` and the sum of thrusts. Returns False when all
    were off and stay off (nothing written)."""
    any_on = False
    for i in range(N_NOZZLES):
        if u_cmd[i] != 0.0:
            any_on = True
    if s[S_THRUST_SUM] == 0.0 and not any_on:
        return False
    umax = kp[KP_UMAX]
    total = 0.0
    for i in range(N_NOZZLES):
        f = u_cmd[i]
        f = 0.0 if math.isnan(f) else min(max(f, 0.0), umax)
        u_held[i] = f
        total += f
    for r in range(6):
        acc = 0.0
        for i in range(N_NOZZLES):
            acc += kp[KP_B + r * N_NOZZLES + i] * u_held[i]
        s[S_FORCE + r] = acc
    s[S_THRUST_SUM] = total
    return True


class CubesatTruth(TruthActuator):
    """One cube's true nozzles: their (possibly misaligned) directions and the thrust limit."""

    def __init__(self, p: CubesatParams, disp: VehicleDispersion) -> None:
        d = p.dynamics
        self.kp = np.zeros(KP_N)
        self.kp[: KP_HMAX + 1] = [d.mass_kg, *d.inertia_diag_kgm2, d.integration_step_s]
        self.kp[KP_MASS] *= disp.mass_factor
        self.kp[KP_IXX : KP_IZZ + 1] *= disp.inertia_factor
        self.kp[KP_UMAX] = p.thrusters.max_thrust_n
        self.s0 = np.zeros(CubesatKind.S_N)
        rotvec = disp.kind.get("thruster_rotvec_rad")
        if rotvec is None:
            B = allocation_matrix(p.thrusters)
        else:
            r, dirs = nozzle_geometry(p.thrusters)
            d_true = rot.quat_rotate(rot.rotvec_exp(rotvec), dirs)
            B = np.vstack([d_true.T, np.cross(r, d_true).T])
        self.kp[KP_B:] = B.ravel()

    @property
    def B(self) -> np.ndarray:
        """The true wrench per newton of each nozzle (6, 10)."""
        return self.kp[KP_B:].reshape(6, N_NOZZLES)


def cubesat_control_row(p: CubesatParams) -> np.ndarray:
    """The controller's parameters (CP_N,): the LQR's (nominal mass, gains, period, integral limit or -1,
    force bound), the attitude law's (nominal inertia, gains, torque bound), the thrust limit and the
    nominal allocation matrix (the controller does not know the dispersions)."""
    tc, ac = p.translation_control, p.attitude_control
    k_p, k_v, k_i = design_translation_lqr(p.dynamics.mass_kg, tc).K_axis[0]
    cp = np.zeros(CP_N)
    cp[:CP_B] = [
        p.dynamics.mass_kg, k_p, k_v, k_i, tc.dt_s, tc.integral_limit_m_s if tc.integral_enabled else -1.0,
        tc.max_force_n, *p.dynamics.inertia_diag_kgm2, ac.kp_nm, ac.kd_nms, ac.max_torque_nm,
        p.thrusters.max_thrust_n,
    ]  # fmt: skip
    cp[CP_B:] = allocation_matrix(p.thrusters).ravel()
    return cp


_ZERO3 = np.zeros(3)


@numba.njit(cache=True)
def cubesat_control(cs, cp, p, v, q, w, ref, translate, rotate, u, act):
    """One control step (module docstring): the LQR force ``F_nav`` and the quaternion-feedback torque
    toward the reference row ``ref`` (:mod:`swarm.core._guidance_nb`, ``R_*``), ``translate`` / ``rotate``
    False: none (and the integral ``cs`` reset); the body wrench allocated to the nozzles (``u``). Writes
    ``act`` = [known force = achieved force (3), achieved force (3), achieved torque (3)] and returns
    whether the thrust limit scaled the command down."""
    F = _lqr_step1(p, v, ref[gnb.R_P : gnb.R_P + 3], ref[gnb.R_V : gnb.R_V + 3],
                   ref[gnb.R_A : gnb.R_A + 3], cs, cp[CP_MASS], cp[CP_KP], cp[CP_KV], cp[CP_KI], cp[CP_DT],
                   cp[CP_ILIM], cp[CP_FMAX])  # fmt: skip
    tau = _attitude_torque1(q, w, ref[gnb.R_Q : gnb.R_Q + 4], _ZERO3, cp[CP_INERTIA : CP_INERTIA + 3],
                            cp[CP_ATT_KP], cp[CP_ATT_KD], cp[CP_TMAX])  # fmt: skip
    if not translate:  # a station keeper inside its dead band: hold still on this axis set
        for i in range(3):
            F[i] = 0.0
            cs[i] = 0.0
    if not rotate:
        for i in range(3):
            tau[i] = 0.0
    f_body = qrotate(qconj(q), F)
    wrench = np.empty(6)
    wrench[0:3] = f_body
    wrench[3:6] = tau
    achieved = np.empty(6)
    B = cp[CP_B:].reshape((6, N_NOZZLES))
    saturated = allocate_nb(wrench, B, cp[CP_UMAX], u[:N_NOZZLES], achieved)
    act[0:3] = achieved[0:3]
    act[3:6] = achieved[0:3]
    act[6:9] = achieved[3:6]
    return saturated


@numba.njit(cache=True)
def cubesat_idle(cp, u, act):
    """All nozzles off."""
    for i in range(N_NOZZLES):
        u[i] = 0.0
    for i in range(ACT_N):
        act[i] = 0.0


class CubesatKind(VehicleKind):
    """The TPODS cube (module docstring)."""

    name = "cubesat"
    code = 0
    Params = CubesatParams
    S_N = 7
    U_N = N_NOZZLES
    KP_N = KP_N
    CP_N = CP_N
    CS_N = CS_N
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

    def control_row(self) -> np.ndarray:
        return cubesat_control_row(self.p)


CubesatTruth.code, CubesatTruth.U_N = CubesatKind.code, CubesatKind.U_N
