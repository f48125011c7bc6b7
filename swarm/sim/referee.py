"""The referee: what the truth says about a chaser and its target at one tick (keep-out, contact).

Called by the in-process simulation (:mod:`swarm.sim.docking`) and by the world process
(:mod:`swarm.world.process`) at the same point of each tick, so both runners judge a run alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarm.core import rotations as rot
from swarm.core.guidance import docking_geometry


@dataclass(frozen=True)
class Contact:
    """The chaser's port touched the target (or the cubes met): the run of this chaser is over."""

    docked: bool
    """Within the contact tolerances (``guidance.contact_*``): docked; otherwise a collision."""
    t_s: float
    contact: dict
    """Port-to-port geometry on the truth (:func:`swarm.core.guidance.contact_state`)."""
    position_error_m: float
    """Distance of the chaser's centre from its docked position on the target [m]."""
    attitude_error_rad: float
    """Angle between the chaser's attitude and its docked attitude [rad]."""
    range_m: float
    """Centre-to-centre distance [m]."""

    def event(self, from_mode: str) -> dict:
        """The mode-log entry of this contact (``"to"``: ``CONTACT`` or ``COLLISION``)."""
        reason = (
            "port contact within tolerance" if self.docked else f"contact outside tolerance {self.contact}"
        )
        to = "CONTACT" if self.docked else "COLLISION"
        return {"t_s": self.t_s, "from": from_mode, "to": to, "range_m": self.range_m, "reason": reason}


@dataclass(frozen=True)
class Call:
    """The referee's call on one pair at one tick."""

    centre_m: float
    """Centre-to-centre distance [m]."""
    keepout: bool
    """The chaser is inside the target's keep-out sphere where it may not be."""
    contact: Contact | None


def centre_distance(world, chaser: str, target: str) -> float:
    """True centre-to-centre distance of ``chaser`` and ``target``, with the arithmetic of
    :func:`swarm.core.guidance.pair_geometry` (the compiled loop's), so that its minimum over the ticks
    (``closest_approach_m``) is the same bit for bit in every runner."""
    d = world.x[chaser][0:3] - world.x[target][0:3]
    return math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])


def judge(world, g, chaser: str, target: str, docking: bool, t_s: float) -> Call:
    """Keep-out and contact of ``chaser`` on ``target`` in ``world`` at ``t_s``: neither is possible when the
    chaser is far (the common case, decided on the centre distance alone, which the call always carries).
    ``g`` is the scenario's :class:`~swarm.core.guidance.GuidanceParams`; ``docking`` whether the chaser's
    mode is DOCK/DOCKED (the corridor then is allowed)."""
    centre_m = centre_distance(world, chaser, target)
    if centre_m > g.keepout_radius_m + 2 * g.half_size_m:
        return Call(centre_m, False, None)
    keepout = world.keepout_violated(chaser, target, docking=docking)
    c = world.contact(chaser, target)
    # the chaser's docking face reaches the target's docking face (in front of it, the faces overlapping),
    # or the two cubes' centres come closer than a cube side: contact
    touching = (
        -2 * g.half_size_m <= c["gap_m"] <= g.contact_distance_m and c["lateral_m"] <= 2 * g.half_size_m
    )
    contact = None
    if touching or centre_m < 2 * g.half_size_m:
        ok = (
            c["lateral_m"] <= g.contact_lateral_m
            and c["attitude_rad"] <= g.contact_attitude_rad
            and c["closing_m_s"] <= g.contact_speed_m_s
        )
        xt, xc = world.x[target], world.x[chaser]
        _, p_docked, q_dock = docking_geometry(g, xt[0:3], xt[6:10])
        contact = Contact(
            docked=bool(ok), t_s=t_s, contact=c,
            position_error_m=float(np.linalg.norm(xc[0:3] - p_docked)),
            attitude_error_rad=float(np.linalg.norm(rot.attitude_error(q_dock, xc[6:10]))),
            range_m=float(np.linalg.norm(xc[0:3] - xt[0:3])),
        )  # fmt: skip
    return Call(centre_m, bool(keepout), contact)
