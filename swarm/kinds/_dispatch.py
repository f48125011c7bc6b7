"""The compiled dispatch to each kind's steps (docs/architecture.md, "Vehicle kinds").

The compiled world and agent steps reach a vehicle's kind through these functions, which call the step of
the kind with that ``code``: its truth dynamics (:func:`truth_step`), how it holds a command
(:func:`hold_step`) and its controller (:func:`control_step`, :func:`idle_step`, :func:`docked_step`).
The arrays are described in :mod:`swarm.kinds.base`. A new kind adds one branch to each and one entry to
:data:`swarm.kinds.KINDS`; nothing outside this package changes. A registered kind without branches (the
``quadrotor``) declares ``docking_missing``, and docking scenarios refuse it.
"""

from __future__ import annotations

import numba
import numpy as np

from swarm.kinds.base import ACT_FORCE, ACT_N, ACT_TORQUE, Actuation, TruthActuator, VehicleKind
from swarm.kinds.cubesat import CubesatKind, cubesat_control, cubesat_hold, cubesat_idle, cubesat_truth_step
from swarm.kinds.ground import GroundKind, ground_control, ground_docked, ground_hold, ground_idle
from swarm.kinds.ground.dynamics import ground_truth_step

CUBESAT = CubesatKind.code
GROUND = GroundKind.code


@numba.njit(cache=True)
def truth_step(code, x, s, u, kp, dt):
    """Advance one vehicle of kind ``code`` by ``dt`` [s] in place: truth row ``x`` (13,), actuator state
    ``s`` under the held command ``u``, truth parameters ``kp`` (padded rows, :mod:`swarm.kinds.base`).
    Returns the tick's effort in the kind's unit (impulse [N s], wheel travel [rad], ...)."""
    if code == CUBESAT:
        return cubesat_truth_step(x, s, u, kp, dt)
    if code == GROUND:
        return ground_truth_step(x, s, u, kp, dt)
    return 0.0


@numba.njit(cache=True)
def hold_step(code, u_cmd, s, u_held, kp):
    """Hold the actuator command ``u_cmd`` from now on: ``u_held`` and what the truth step reads from ``s``,
    brought into the actuators' range. Returns False when nothing changed."""
    if code == CUBESAT:
        return cubesat_hold(u_cmd, s, u_held, kp)
    if code == GROUND:
        return ground_hold(u_cmd, s, u_held, kp)
    return False


@numba.njit(cache=True)
def control_step(code, cs, cp, p, v, q, w, ref, translate, rotate, u, act):
    """One control step of kind ``code`` on the estimate ``p``, ``v``, ``q`` and the latest gyro rate ``w``
    toward the guidance reference row ``ref`` (:mod:`swarm.core._guidance_nb`): writes the command ``u``
    and ``act``; returns whether an actuator limit scaled it down."""
    if code == CUBESAT:
        return cubesat_control(cs, cp, p, v, q, w, ref, translate, rotate, u, act)
    if code == GROUND:
        return ground_control(cs, cp, p, v, q, w, ref, translate, rotate, u, act)
    return False


@numba.njit(cache=True)
def idle_step(code, cp, u, act):
    """All actuators off."""
    if code == CUBESAT:
        cubesat_idle(cp, u, act)
    elif code == GROUND:
        ground_idle(cp, u, act)


@numba.njit(cache=True)
def docked_step(code, cp, speed_m_s, u, act):
    """The command once docked: a free flyer's actuators off, a wheeled vehicle creeping into the port."""
    if code == GROUND:
        ground_docked(cp, speed_m_s, u, act)
    else:
        idle_step(code, cp, u, act)


def hold(actuator: TruthActuator, u, s: np.ndarray, u_held: np.ndarray) -> bool:
    """Hold command ``u`` on one vehicle's true actuators from now on: write what the compiled step reads
    into the vehicle's rows ``s`` and ``u_held`` (padded, in place). A command outside the actuators' range
    is brought into it (a nozzle cannot pull, a wheel cannot exceed its speed); a non-finite entry counts
    as zero. Returns False when nothing changed (then nothing was written). :func:`hold_step`, which the
    compiled closed loop calls directly, with the command's length checked."""
    f = np.ascontiguousarray(u, dtype=np.float64)
    if f.shape != (actuator.U_N,):
        raise ValueError(f"a command of this kind has {actuator.U_N} entries, got shape {f.shape}")
    return bool(hold_step(actuator.code, f, s, u_held, actuator.kp))


class Controller:
    """A kind's controller and allocation: from the estimate and the guidance's reference to actuators;
    the compiled steps of :mod:`swarm.kinds._dispatch` over the controller's state ``cs`` and parameters
    ``cp`` (what the compiled closed loop calls directly)."""

    def __init__(self, kind: VehicleKind) -> None:
        self.code = kind.code
        self.rate_hz = kind.control_rate_hz
        self.U_N = kind.U_N
        self.cp = np.ascontiguousarray(kind.control_row(), dtype=np.float64)
        self.cs = np.zeros(kind.CS_N)

    def _actuation(self, u: np.ndarray, act: np.ndarray, saturated: bool = False) -> Actuation:
        force = act[ACT_FORCE : ACT_FORCE + 3]
        torque = act[ACT_TORQUE : ACT_TORQUE + 3]
        return Actuation(
            u[: self.U_N].copy(), act[:3].copy(), force.copy() if np.isfinite(force).all() else None,
            torque.copy() if np.isfinite(torque).all() else None, bool(saturated),
        )  # fmt: skip

    def step(self, p_nav, v_nav, q_nav_body, w_body, ref, translate: bool, rotate: bool) -> Actuation:
        """One control step on the estimate (``p_nav`` [m], ``v_nav`` [m/s], ``q_nav_body``, ``w_body`` the
        latest gyro rate [rad/s]) towards ``ref`` (:class:`swarm.core.guidance.Reference`). ``translate`` /
        ``rotate`` False: no translation / attitude control this step (a station keeper in its dead
        band)."""
        from swarm.core import _guidance_nb as gnb

        f64 = np.float64
        row = np.zeros(gnb.REF_N)
        row[gnb.R_P : gnb.R_P + 3] = ref.p_nav
        row[gnb.R_V : gnb.R_V + 3] = ref.v_nav
        row[gnb.R_A : gnb.R_A + 3] = ref.a_nav
        row[gnb.R_Q : gnb.R_Q + 4] = ref.q_nav_body
        u, act = np.zeros(max(self.U_N, 1)), np.zeros(ACT_N)
        sat = control_step(
            self.code, self.cs, self.cp, np.asarray(p_nav, f64), np.asarray(v_nav, f64),
            np.asarray(q_nav_body, f64), np.asarray(w_body, f64), row, bool(translate), bool(rotate), u, act,
        )  # fmt: skip
        return self._actuation(u, act, sat)

    def reset(self) -> None:
        """Forget the integral state (the reference jumped: a new guidance mode)."""
        self.cs[:] = 0.0

    def idle(self) -> Actuation:
        """All actuators off."""
        u, act = np.zeros(max(self.U_N, 1)), np.zeros(ACT_N)
        idle_step(self.code, self.cp, u, act)
        return self._actuation(u, act)

    def docked(self, speed_m_s: float) -> Actuation:
        """The command once the guidance believes the port is in contact (DOCKED): a free flyer's actuators
        off (it drifts the last millimetres into the port); a vehicle held by friction keeps pushing its
        port forward at ``speed_m_s`` until the contact stops it."""
        u, act = np.zeros(max(self.U_N, 1)), np.zeros(ACT_N)
        docked_step(self.code, self.cp, float(speed_m_s), u, act)
        return self._actuation(u, act)
