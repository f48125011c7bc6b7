"""How the dashboard draws each vehicle kind (docs/architecture.md, "Adding a kind", step 3).

A drawer adds a vehicle's parts under its ``truth`` frame (body axes, metres) and returns the node whose
colour follows the guidance mode. The geometry comes from the kind's own tables, so a scenario that changes
a wheel or a nozzle sees it drawn. A kind without a drawer is drawn as a box of the scenario's
``guidance.half_size_m``. The quadrotor (issue 15) has its drawer, :func:`draw_quadrotor`, which the landing
dashboard (:mod:`dashboard.landing`) calls; it is in :data:`DRAWERS` for the day the kind is registered.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import viser

from dashboard.mapping import wxyz_from_xyzw
from swarm.core import rotations as rot

Drawer = Callable[[viser.SceneApi, str, object, tuple[int, int, int]], object]
"""``(scene, prefix, kind, colour) -> the body node`` (:class:`swarm.kinds.base.VehicleKind` ``kind``)."""

_GREY = (70, 70, 70)
_Q_Y_TO_Z = rot.matrix_to_quat(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]))
"""A cylinder's axis is its local y: this turns it onto body z (a mast, a rotor disc)."""
_NOZZLE = (200, 200, 200)


def _box(scene: viser.SceneApi, prefix: str, size: float, color) -> object:
    return scene.add_box(f"{prefix}/body", color=color, dimensions=(size,) * 3, opacity=0.85)


def draw_box(scene: viser.SceneApi, prefix: str, size: float, color) -> object:
    """The fallback: a cube of side ``size`` [m]."""
    return _box(scene, prefix, size, color)


def draw_cubesat(scene: viser.SceneApi, prefix: str, kind, color) -> object:
    """A TPODS cube: the body, a dot at each of its ten nozzles (:mod:`swarm.core.thrusters`)."""
    from swarm.core.thrusters import nozzle_geometry

    p = kind.p
    body = _box(scene, prefix, 2.0 * p.thrusters.half_size_m, color)
    r, _ = nozzle_geometry(p.thrusters)
    for i, pos in enumerate(r):
        scene.add_icosphere(f"{prefix}/nozzle{i}", radius=0.006, color=_NOZZLE, position=tuple(pos),
                            cast_shadow=False)  # fmt: skip
    return body


def draw_ground(scene: viser.SceneApi, prefix: str, kind, color) -> object:
    """An MK-E module: the body on four mecanum wheels (cylinders along body y, at the contact points of
    :mod:`swarm.kinds.ground.dynamics`), and the UWB node on its mast."""
    p = kind.p
    h = p.body.half_size_m
    w = p.wheels
    body = _box(scene, prefix, 2.0 * h, color)
    # a cylinder's axis is its local y: it already lies along the body's y axis, the wheels' axles
    for i, (sx, sy) in enumerate(((1, 1), (1, -1), (-1, -1), (-1, 1))):  # front-left, front-right, ...
        centre = (sx * w.half_length_m, sy * (w.half_width_m + 0.01), -h + w.radius_m - 0.02)
        scene.add_cylinder(f"{prefix}/wheel{i + 1}", radius=w.radius_m, height=0.018, color=_GREY,
                           position=centre)  # fmt: skip
    tag = np.asarray(p.mounts.tag_lever_arm_body_m, dtype=float)
    base = np.array([tag[0], tag[1], h])
    length = max(float(tag[2] - h), 0.005)
    q_mast = _Q_Y_TO_Z
    mid = base.copy()
    mid[2] += length / 2
    scene.add_cylinder(f"{prefix}/mast", radius=0.003, height=length, color=_GREY, position=tuple(mid),
                       wxyz=wxyz_from_xyzw(q_mast))  # fmt: skip
    scene.add_icosphere(f"{prefix}/uwb_node", radius=0.008, color=(230, 126, 34), position=tuple(tag),
                        cast_shadow=False)  # fmt: skip
    return body


class Parts:
    """Several nodes coloured as one: the node a drawer returns when the mode's colour is on more than one
    part (``parts.color = rgb`` sets every part's)."""

    def __init__(self, handles: list, color) -> None:
        self.handles = handles
        self._color = tuple(color)

    @property
    def color(self):
        return self._color

    @color.setter
    def color(self, value) -> None:
        self._color = tuple(value)
        for h in self.handles:
            h.color = self._color


def draw_quadrotor(scene: viser.SceneApi, prefix: str, kind, color) -> Parts:
    """A quadrotor (``swarm.kinds.quadrotor``, an X frame): a hub, two arms along the diagonals and a rotor
    disc at each hub, where :func:`swarm.kinds.quadrotor.dynamics.rotor_positions` puts the rotors of
    ``kind.p.airframe.arm_m``. The hub and the arms take the mode's colour; the discs stay grey."""
    from swarm.kinds.quadrotor.dynamics import rotor_positions

    arm = float(kind.p.airframe.arm_m)
    r = rotor_positions(arm)
    disc = 0.45 * arm  # a 10-inch propeller on a 0.225 m arm: radius 0.127 m
    hub = scene.add_box(f"{prefix}/body", color=color, dimensions=(0.5 * arm, 0.5 * arm, 0.2 * arm),
                        opacity=0.9)  # fmt: skip
    handles = [hub]
    # an arm from rotor a to the opposite rotor b, through the hub
    for i, (a, b) in enumerate(((0, 2), (1, 3))):
        d = r[a] - r[b]
        yaw = float(np.arctan2(d[1], d[0]))
        q = rot.rotvec_exp(np.array([0.0, 0.0, yaw - np.pi / 2]))  # local y onto the diagonal
        arm_node = scene.add_cylinder(f"{prefix}/arm{i + 1}", radius=0.04 * arm, height=2.0 * arm,
                                      color=color, wxyz=wxyz_from_xyzw(q))  # fmt: skip
        handles.append(arm_node)
    for i, pos in enumerate(r):
        # a disc: a flat cylinder whose axis (local y) is body z
        scene.add_cylinder(f"{prefix}/rotor{i + 1}", radius=disc, height=0.02 * arm, color=_NOZZLE,
                           position=(float(pos[0]), float(pos[1]), 0.06 * arm), opacity=0.7,
                           wxyz=wxyz_from_xyzw(_Q_Y_TO_Z))  # fmt: skip
    return Parts(handles, color)


def draw_surface(scene: viser.SceneApi, sc) -> bool:
    """The surface planar vehicles stand on (a table): a slab under their bodies over the anchors' and
    vehicles' footprint, 10 cm beyond it. Drawn when some vehicle's kind is planar; True if drawn."""
    planar = [v for v in sc.vehicles if sc.kind(v).planar]
    if not planar:
        return False
    pts = np.vstack([np.asarray(sc.anchors_m, dtype=float).reshape(-1, 3),
                     np.array([sc.vehicles[v].position_m for v in sc.vehicles], dtype=float)])  # fmt: skip
    lo, hi = pts[:, :2].min(axis=0) - 0.1, pts[:, :2].max(axis=0) + 0.1
    top = min(sc.vehicles[v].position_m[2] - sc.kind(v).p.body.half_size_m for v in planar)
    thick = 0.02
    scene.add_box("/surface", color=(196, 164, 132), dimensions=(*(hi - lo), thick),
                  position=(*(0.5 * (lo + hi)), top - thick / 2), opacity=0.9)  # fmt: skip
    return True


DRAWERS: dict[str, Drawer] = {"cubesat": draw_cubesat, "ground": draw_ground, "quadrotor": draw_quadrotor}
"""Drawer of each kind that has one (the others: :func:`draw_box`)."""


def draw(scene: viser.SceneApi, prefix: str, sc, vehicle_id: str, color) -> object:
    """Draw ``vehicle_id`` of scenario ``sc`` under ``prefix`` as what its kind is; the body node."""
    if vehicle_id in sc.vehicles:
        kind = sc.kind(vehicle_id)
        drawer = DRAWERS.get(kind.name)
        if drawer is not None:
            return drawer(scene, prefix, kind, color)
    return draw_box(scene, prefix, 2.0 * sc.guidance.half_size_m, color)
