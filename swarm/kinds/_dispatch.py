"""The compiled dispatch to each kind's truth step (docs/architecture.md, "Vehicle kinds").

The world's compiled loop (:func:`swarm.step.world.world_tick`) advances every vehicle through
:func:`truth_step`, which calls the step of the vehicle's kind by its ``code``. A new kind adds one branch
here and one entry to :data:`swarm.kinds.KINDS`; nothing outside this package changes.
"""

from __future__ import annotations

import numba

from swarm.kinds.cubesat import CubesatKind, cubesat_truth_step
from swarm.kinds.ground import GroundKind
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
