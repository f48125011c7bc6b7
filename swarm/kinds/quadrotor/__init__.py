"""The ``quadrotor`` vehicle kind's physics and controller (issue 15, paper section VI-B).

:mod:`.params` (its ``[kinds.quadrotor.*]`` tables), :mod:`.dynamics` (rigid body, rotor lag, drag,
gravity, ground contact, rotor power), :mod:`.control` (PX4's cascaded controller and the mixer). These are
compiled steps with the shapes of docs/architecture.md, "Vehicle kinds", flown by the compiled
landing tick (:mod:`swarm.step.landing_nb`). It is not registered in :data:`swarm.kinds.KINDS`: the
docking runners' filter takes no gravity and no accelerometer (the quadrotor's is the IMU-driven filter of
:mod:`swarm.core.imu_filter`), and the docking tick has no landing guidance.
"""

from swarm.kinds.quadrotor.control import control_row, quadrotor_control, quadrotor_idle
from swarm.kinds.quadrotor.dynamics import quadrotor_hold, quadrotor_truth_step, truth_row
from swarm.kinds.quadrotor.params import AirframeParams, ControlParams, QuadrotorParams

__all__ = [
    "AirframeParams",
    "ControlParams",
    "QuadrotorParams",
    "control_row",
    "quadrotor_control",
    "quadrotor_hold",
    "quadrotor_idle",
    "quadrotor_truth_step",
    "truth_row",
]
