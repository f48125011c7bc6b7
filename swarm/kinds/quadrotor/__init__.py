"""The ``quadrotor`` kind: a 1.5 kg X-frame quadrotor (paper section VI-B).

:mod:`.params` (its ``[kinds.quadrotor.*]`` tables), :mod:`.dynamics` (rigid body, rotor lag, drag,
gravity, ground contact, rotor power), :mod:`.control` (PX4's cascaded controller and the mixer): compiled
steps with the shapes of :mod:`swarm.kinds.base`. Its IMU measures specific force as well as rate, so its
filter is the IMU-driven one (:mod:`swarm.navigation`). Effort: the rotors' electrical energy [J].

The landing tick (:mod:`swarm.step.landing_nb`) flies it. The docking dispatch
(:mod:`swarm.kinds._dispatch`) has no branch for it yet: :meth:`QuadrotorKind.validate` refuses it in a
docking scenario, naming what is missing.
"""

from __future__ import annotations

import numpy as np

from swarm.core import rotations as rot
from swarm.kinds.base import Mounts, TruthActuator, VehicleDispersion, VehicleKind
from swarm.kinds.quadrotor import control as qc
from swarm.kinds.quadrotor import dynamics as qd
from swarm.kinds.quadrotor.control import control_row, quadrotor_control, quadrotor_idle
from swarm.kinds.quadrotor.dynamics import quadrotor_hold, quadrotor_truth_step, truth_row
from swarm.kinds.quadrotor.params import AirframeParams, ControlParams, QuadrotorParams

QUADROTOR_MOUNTS = Mounts((0.0, 0.0, 0.05), (0.0, 0.0, -0.05), (1.0, 0.0, 0.0, 0.0))
"""The UWB tag 5 cm above the centre of mass, the camera 5 cm below it looking down (camera +z along body
-z). The landing scenario's ``[uwb] lever_arm_m`` and ``[camera] pos_body_m`` default to these and are what
the landing tick reads."""


class QuadrotorTruth(TruthActuator):
    """One quadrotor's true rotors: :func:`truth_row` with its mass and inertia dispersions, at rest."""

    def __init__(self, p: QuadrotorParams, disp: VehicleDispersion) -> None:
        self.kp = truth_row(p.airframe, disp.mass_factor, disp.inertia_factor)
        self.s0 = np.zeros(qd.S_N)


class QuadrotorKind(VehicleKind):
    """The quadrotor (module docstring)."""

    name = "quadrotor"
    code = 2
    Params = QuadrotorParams
    S_N = qd.S_N
    U_N = qd.U_N
    KP_N = qd.KP_N
    CP_N = qc.CP_N
    CS_N = qc.CS_N
    planar = False
    imu_measures = frozenset({"gyro", "accelerometer"})
    effort_key = "energy_j"
    effort_unit = "J"
    effort_label = "rotor energy"
    target_effort_key = "target_energy_j"
    docking_missing = (
        "the docking tick has no quadrotor branch in swarm/kinds/_dispatch.py (truth, hold, and a control "
        "step from the guidance's acceleration command), and the docking agent's filter (the MEKF) models no "
        "gravity and no accelerometer"
    )

    @property
    def mounts(self) -> Mounts:
        return QUADROTOR_MOUNTS

    @property
    def mass_kg(self) -> float:
        return self.p.airframe.mass_kg

    control_rate_field = "kinds.quadrotor.control.rate_hz"

    @property
    def control_rate_hz(self) -> float:
        return self.p.control.rate_hz

    def q_target_chaser_docked(self, face: str) -> np.ndarray:
        """The chaser's +z along the face normal (its skids and downward camera against the face: upright on
        a ``+z`` face), its +x along the next target axis in x -> y -> z order."""
        n = np.zeros(3)
        axis = "xyz".index(face[1])
        n[axis] = 1.0 if face[0] == "+" else -1.0
        x_c = np.zeros(3)
        x_c[(axis + 1) % 3] = 1.0
        return rot.matrix_to_quat(np.column_stack([x_c, np.cross(n, x_c), n]))

    def truth(self, disp: VehicleDispersion) -> QuadrotorTruth:
        return QuadrotorTruth(self.p, disp)

    def control_row(self) -> np.ndarray:
        return control_row(self.p)


QuadrotorTruth.code, QuadrotorTruth.U_N = QuadrotorKind.code, QuadrotorKind.U_N


__all__ = [
    "QUADROTOR_MOUNTS",
    "AirframeParams",
    "ControlParams",
    "QuadrotorKind",
    "QuadrotorParams",
    "QuadrotorTruth",
    "control_row",
    "quadrotor_control",
    "quadrotor_hold",
    "quadrotor_idle",
    "quadrotor_truth_step",
    "truth_row",
]
