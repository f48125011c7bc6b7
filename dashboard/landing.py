"""The dashboard of a landing swarm (issue 15): ``swarm dashboard landing-swarm``, live or from a recording.

A landing scenario (:class:`swarm.landing_scenario.LandingScenario`, ``[mission] name = "landing"``) has UAVs
and pads instead of chasers and targets; the messages are the same (truth, estimate, guidance, vision, events,
the world's clock and events: docs/protocol.md, "Processes and topology"), stored by the same
:class:`~dashboard.state.SwarmState`. What differs is drawn here:

- each pad: a white square of the ArUco board's size (``[pad]`` ``board``) with its markers in black and
  an arrow along the pad's x axis (its heading), at the UAV's ``pad_m`` turned by ``pad_yaw_deg``; a
  moving pad (``[platform]``, ``landing-moving``) where its robot's shared estimate puts it (the robot's
  ``Estimate`` on ``agent/<platform.id>/estimate``: position and heading), the robot itself not drawn as a
  vehicle;
- the UWB anchors around the pads (from the scenario: a landing swarm has no mothership to ask); on a TDoA
  radio (``uwb.mode`` tdoa2/tdoa3) each labelled with its packets a second as the UAVs' tags hear them
  (:mod:`dashboard.radio`, as a docking swarm's; the Radio panel has the table);
- every UAV as a quadrotor (:func:`dashboard.kinds.draw_quadrotor`) in its guidance mode's colour, drawn
  :data:`DRAW_SCALE` times its size (a 0.45 m airframe would be a few pixels in a 60 m scene), its label,
  its true and estimated trails, its estimated pose (axes) and the estimate's covariance ellipsoid;
- its downward camera's frustum (the four image corners through the intrinsics, ``[camera]``), reaching
  down to the pad's plane, so that its footprint is what the camera sees: green when the latest camera
  frame detected pad markers (the Vision message's ``marker_ids`` not empty), yellow when the pad's centre
  projects into the image but nothing was detected (hidden, too small, not in this frame), red when the pad
  is out of the image.

Panels: a row per UAV (distance and altitude to its pad, pad markers seen, rotor energy), the selected
UAV's state and its distance to the pad. The pure functions (geometry, colours) are tested without a
server; :class:`LandingDrawer` is the landing mission's drawer (:mod:`dashboard.drawer`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
import viser

from dashboard import kinds, mapping, panels
from dashboard.drawer import (
    STALE,
    MissionDrawer,
    MissionScene,
    VehicleNodes,
    update_color,
    update_estimate,
    update_trails,
    update_truth,
)
from dashboard.faults import FaultMenu
from dashboard.panels import DASH, cell, fmt
from dashboard.state import AgentSnap, Snapshot
from swarm.core import rotations as rot
from swarm.core.pad_vision import PadBoardParams, PadCameraParams
from swarm.landing_scenario import LandingScenario, Uav
from swarm.step.landing import R_BODY_CAM
from swarm.transport.keys import check_id

__all__ = [
    "DRAW_SCALE",
    "EVERY_UAV",
    "LandingDrawer",
    "LandingSceneView",
    "camera_wxyz",
    "frame_landing_scene",
    "frustum_depth",
    "frustum_mesh",
    "frustum_state",
    "landing_table",
    "landing_uav_markdown",
    "pad_pixel",
    "pad_wxyz",
    "uav_vehicles",
]

DRAW_SCALE = 4.0
"""How much larger than life a UAV is drawn (its frame, not its camera frustum or its covariance)."""
FRUSTUM_MIN_M = 0.3
"""Shortest frustum drawn [m] (a UAV on its pad still shows its camera)."""
PAD_COLOR = (236, 240, 241)
MARKER_COLOR = (30, 30, 30)
EVERY_UAV = "every UAV"
"""The Faults panel's choice that sends ``vehicle = None`` (the landing world applies it to every UAV)."""
HINTS = {
    "camera_loss": "the UAV's camera sees no pad marker (the landing world applies it)",
    "uwb_dropout": "every UWB reply to the UAV is lost: no range (the landing world applies it)",
}
"""The Faults panel's line on each kind the landing world applies."""


def uav_vehicles(sc: LandingScenario) -> dict[str, tuple[str, str | None]]:
    """The store's vehicles of a landing scenario: every UAV, role ``uav``, no target."""
    return {u.id: ("uav", None) for u in sc.uavs()}


def camera_wxyz() -> np.ndarray:
    """Viser orientation of the downward camera frame (OpenCV: +z optical axis) in the body frame:
    ``R_BODY_CAM`` of the landing tick (:mod:`swarm.step.landing`), body -z looking down."""
    return mapping.wxyz_from_xyzw(rot.matrix_to_quat(R_BODY_CAM))


def frustum_mesh(cam: PadCameraParams, depth_m: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The camera's view pyramid in the camera frame (OpenCV), apex at the optical centre, base at
    ``z = depth_m``: the four image corners ``(0, 0)``, ``(w, 0)``, ``(w, h)``, ``(0, h)`` [px] back-projected
    through the pinhole ``x = (u - c_x) / f_x z``, ``y = (v - c_y) / f_y z`` (distortion left out: it bends
    the edges by a few pixels). Returns vertices (5, 3) float32 (apex, then the corners) and faces (6, 3)
    uint32 (four sides and the base)."""
    if not (math.isfinite(depth_m) and depth_m > 0):
        raise ValueError(f"depth_m must be a positive finite number, got {depth_m!r}")
    corners = [(0.0, 0.0), (cam.width_px, 0.0), (cam.width_px, cam.height_px), (0.0, cam.height_px)]
    base = [((u - cam.cx_px) / cam.fx_px * depth_m, (v - cam.cy_px) / cam.fy_px * depth_m, depth_m)
            for u, v in corners]  # fmt: skip
    vertices = np.array([(0.0, 0.0, 0.0), *base], dtype=np.float32)
    faces = np.array([(0, 1, 2), (0, 2, 3), (0, 3, 4), (0, 4, 1), (1, 3, 2), (1, 4, 3)], dtype=np.uint32)
    return vertices, faces


def pad_pixel(
    p_nav: np.ndarray,
    q_nav_body: np.ndarray,
    pad_nav: np.ndarray,
    cam_pos_body_m: np.ndarray,
    cam: PadCameraParams,
) -> tuple[float, float] | None:
    """Where the pad's centre ``pad_nav`` (3,) [m] projects in the downward camera's image [px] of a UAV at
    ``p_nav`` with attitude ``q_nav_body`` (x, y, z, w), its camera at ``cam_pos_body_m`` (3,) [m] in the
    body frame; None if the pad is behind the camera or outside the image (pinhole, no distortion).
    ``p_cam = R_body_cam^T (R_nav_body^T (pad - p) - cam_pos)``."""
    r_nav_body = rot.quat_to_matrix(np.asarray(q_nav_body, dtype=np.float64))
    d_body = r_nav_body.T @ (np.asarray(pad_nav, float) - np.asarray(p_nav, float))
    p_cam = R_BODY_CAM.T @ (d_body - np.asarray(cam_pos_body_m, dtype=np.float64))
    if p_cam[2] <= 1e-6:
        return None
    u = cam.fx_px * p_cam[0] / p_cam[2] + cam.cx_px
    v = cam.fy_px * p_cam[1] / p_cam[2] + cam.cy_px
    if not (0.0 <= u <= cam.width_px and 0.0 <= v <= cam.height_px):
        return None
    return float(u), float(v)


def frustum_state(marker_rows: int | None, pad_in_image: bool) -> str:
    """Key of :data:`dashboard.mapping.FOV_COLORS` for a UAV's camera: ``seen`` if its latest camera frame
    (``marker_rows``: rows of that Vision message, None before the first) detected pad markers, else
    ``in_cone`` if the pad's centre is in the image, else ``out``."""
    if marker_rows:
        return "seen"
    return "in_cone" if pad_in_image else "out"


def frustum_depth(z_nav_m: float, pad_z_m: float) -> float:
    """How far down the frustum reaches [m]: to the pad's plane, at least :data:`FRUSTUM_MIN_M`."""
    return max(float(z_nav_m) - float(pad_z_m), FRUSTUM_MIN_M)


def pad_wxyz(pad_yaw_deg: float) -> np.ndarray:
    """Viser orientation of a pad turned by ``pad_yaw_deg`` about nav z (as the landing tick turns it)."""
    return mapping.wxyz_from_xyzw(rot.rotvec_exp(np.array([0.0, 0.0, math.radians(pad_yaw_deg)])))


def frame_landing_scene(server: viser.ViserServer, sc: LandingScenario) -> None:
    """A floor grid (1 m cells) under the UAVs' starts, the pads and the anchors, and the initial camera
    looking at their centre from the south-west, above."""
    uavs = sc.uavs()
    pts = np.vstack([np.array([u.start_m for u in uavs], float), np.array([u.pad_m for u in uavs], float),
                     np.asarray(sc.uwb.anchors_m, float).reshape(-1, 3)])  # fmt: skip
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    extent = float(np.max(hi - lo))
    size = float(np.ceil(extent + 4.0))
    ground = min(u.pad_m[2] for u in uavs)
    server.scene.add_grid(
        "/grid", width=size, height=size, cell_size=1.0, section_size=5.0, plane="xy",
        position=(*np.round(0.5 * (lo[:2] + hi[:2])).tolist(), float(ground) - 0.01),
    )  # fmt: skip
    centre = 0.5 * (lo + hi)
    direction = np.array([-0.55, -1.0, 0.9])
    eye = centre + 0.8 * max(extent, 1.0) * direction / np.linalg.norm(direction)
    server.initial_camera.position = tuple(eye)
    server.initial_camera.look_at = tuple(centre)


def _draw_pad(scene: viser.SceneApi, uav: Uav, board: PadBoardParams):
    """A pad (module docstring) under ``/pads/<uav>``: the board's square with a margin, its markers, the
    heading arrow and a label; its frame's handle (a moving pad's moves)."""
    name = f"/pads/{check_id(uav.id)}"
    frame = scene.add_frame(name, show_axes=False, position=tuple(float(x) for x in uav.pad_m),
                            wxyz=pad_wxyz(uav.pad_yaw_deg))  # fmt: skip
    half = board.half_extent_m
    side = 2.0 * half + 0.2
    scene.add_box(f"{name}/board", color=PAD_COLOR, dimensions=(side, side, 0.02), position=(0.0, 0.0, 0.01))
    _, centres, sizes = board.markers
    for i, (c, s) in enumerate(zip(centres, sizes, strict=True)):
        scene.add_box(f"{name}/marker{i}", color=MARKER_COLOR, dimensions=(s, s, 0.005),
                      position=(float(c[0]), float(c[1]), 0.0225))  # fmt: skip
    tip = half + 0.6
    arrow = np.array([[[half, 0.0, 0.03], [tip, 0.0, 0.03]], [[tip, 0.0, 0.03], [tip - 0.2, 0.12, 0.03]],
                      [[tip, 0.0, 0.03], [tip - 0.2, -0.12, 0.03]]])  # fmt: skip
    scene.add_line_segments(f"{name}/heading", arrow, (192, 57, 43), thickness=3.0, thickness_units="screen")
    scene.add_label(f"{name}/label", f"pad {uav.id}", position=(0.0, -half - 0.3, 0.05))
    return frame


class _UavNodes(VehicleNodes):
    """The scene nodes of one UAV and what was last pushed to them."""

    def __init__(self, scene: viser.SceneApi, a: AgentSnap, sc: LandingScenario) -> None:
        super().__init__()
        base = f"/uavs/{check_id(a.agent_id)}"
        self.truth = scene.add_frame(f"{base}/truth", show_axes=False, visible=False)
        scene.add_frame(f"{base}/truth/quad", show_axes=False, scale=DRAW_SCALE)
        quad = _QuadKind(sc)
        self.body = kinds.draw_quadrotor(scene, f"{base}/truth/quad", quad, mapping.mode_color(None, "uav"))
        scene.add_label(f"{base}/truth/label", a.agent_id, position=(0.0, 0.0, 1.5))
        vertices, faces = frustum_mesh(sc.camera.intrinsics)
        self.fov = scene.add_mesh_simple(
            f"{base}/truth/fov", vertices, faces, color=mapping.FOV_COLORS["out"], opacity=0.2, side="double",
            position=tuple(float(x) for x in sc.camera.pos_body_m), wxyz=camera_wxyz(), cast_shadow=False,
            receive_shadow=False,
        )  # fmt: skip
        self.estimate = scene.add_frame(f"{base}/estimate", axes_length=1.0, axes_radius=0.04, visible=False)
        self.add_cov_and_trails(scene, base, 0.2)
        self.fov_key: object = None

    def stale(self) -> None:
        super().stale()
        self.fov_key = STALE


class _QuadKind:
    """What :func:`dashboard.kinds.draw_quadrotor` reads of a kind (``.p``): the scenario's quadrotor."""

    def __init__(self, sc: LandingScenario) -> None:
        self.p = sc.kinds.quadrotor


class LandingSceneView(MissionScene):
    """The 3D scene of a landing swarm (module docstring): pads and anchors at start, each UAV on first
    sight."""

    ANCHOR_RADIUS_M = 0.25
    ANCHOR_LABEL_Z_M = 0.5

    def __init__(self, server: viser.ViserServer, sc: LandingScenario, params) -> None:
        super().__init__(server, sc, params)
        self.uavs = {u.id: u for u in sc.uavs()}
        self.pad_frames = {u.id: _draw_pad(server.scene, u, sc.pad.board) for u in self.uavs.values()}
        pf = sc.platform
        self.platform_id = pf.id if pf.enabled else None
        """A moving pad's robot: its estimate moves the (one) pad, it is not drawn as a UAV."""
        self.hidden = frozenset({self.platform_id} - {None})
        self.pad_now: dict[str, np.ndarray] = {}
        """Each moving pad where its robot's latest estimate puts it (nav) [m]."""
        self._platform_msg: object = None

    def update(self, snap: Snapshot, trails_due: bool) -> None:
        robot = snap.agents.get(self.platform_id) if self.platform_id is not None else None
        if robot is not None:  # first: the UAVs' frustums look for the pad where it is now
            self._move_pad(robot)
        super().update(snap, trails_due)

    def add_vehicle(self, a: AgentSnap) -> _UavNodes:
        return _UavNodes(self.server.scene, a, self.sc)

    def _move_pad(self, a: AgentSnap) -> None:
        """The moving pad to its robot's latest estimate: the position at the deck's height, the heading."""
        msg = a.estimate
        if msg is None or msg is self._platform_msg:
            return
        self._platform_msg = msg
        for uid, frame in self.pad_frames.items():  # (a moving pad carries the one UAV's pad)
            p = np.array([msg.p_nav[0], msg.p_nav[1], self.uavs[uid].pad_m[2]])
            self.pad_now[uid] = p
            frame.position = tuple(float(x) for x in p)
            frame.wxyz = mapping.wxyz_from_xyzw(msg.q_nav_body)

    def invalidate(self) -> None:
        """Push everything again at the next frame (a playback's backward seek)."""
        self._platform_msg = None
        super().invalidate()

    def update_vehicle(self, nodes: _UavNodes, a: AgentSnap, snap: Snapshot, trails_due: bool) -> None:
        uav = self.uavs.get(a.agent_id)
        update_truth(nodes, a)
        update_color(nodes, a, "uav")
        update_estimate(nodes, a, self.n_sigma, trails_due)
        if a.truth is not None and uav is not None:
            cam = self.sc.camera
            pad = self.pad_now.get(uav.id, np.asarray(uav.pad_m, float))
            in_image = pad_pixel(a.truth.p_nav, a.truth.q_nav_body, pad, np.asarray(cam.pos_body_m, float),
                                 cam.intrinsics) is not None  # fmt: skip
            state = frustum_state(a.vision_rows, in_image)
            depth = round(frustum_depth(a.truth.p_nav[2], uav.pad_m[2]), 2)
            key = (state, depth)
            if key != nodes.fov_key:
                nodes.fov_key = key
                nodes.fov.color = mapping.FOV_COLORS[state]
                nodes.fov.scale = depth
        if trails_due and a.truth_trail is not None:
            update_trails(nodes, a, self.show_trails)


def _pad_markers(a: AgentSnap) -> str:
    """Pad markers in the UAV's latest camera frame (its rows are marker corners, four a marker)."""
    return DASH if a.vision_rows is None else str(a.vision_rows // 4)


def _altitude(a: AgentSnap, pads: Mapping[str, Sequence[float]]) -> float | None:
    pad = pads.get(a.agent_id)
    return None if a.truth is None or pad is None else float(a.truth.p_nav[2]) - float(pad[2])


def landing_table(snap: Snapshot, pads: Mapping[str, Sequence[float]]) -> str:
    """Markdown table of a landing swarm, one row per UAV: mode, estimated horizontal distance to its pad
    [m] (the guidance's ``range_m``), true altitude above its pad [m] (``pads``: each UAV's pad position),
    largest position sigma [cm], pad markers detected in its latest camera frame, rotor energy so far [kJ]
    (``Truth.effort`` of a quadrotor, J), and whether its agent process is alive."""
    lines = [
        "| UAV | mode | to pad [m] | altitude [m] | σ [cm] | pad markers | energy [kJ] | agent process |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for agent_id in sorted(snap.agents, key=panels.natural_key):
        if agent_id not in pads:  # (a moving pad's robot shares its estimate: not a UAV)
            continue
        a = snap.agents[agent_id]
        g = a.guidance
        cells = (
            agent_id,
            g.mode if g is not None else DASH,
            fmt(g.range_m if g is not None else None, 2),
            fmt(_altitude(a, pads), 2),
            fmt(a.estimate.sigma_pos_max_m if a.estimate is not None else None, 1, 100.0),
            _pad_markers(a),
            fmt(a.truth.effort if a.truth is not None else None, 2, 1e-3),
            a.alive,
        )
        lines.append("| " + " | ".join(cell(c) for c in cells) + " |")
    return "\n".join(lines)


def landing_uav_markdown(
    agent_id: str | None, a: AgentSnap | None, pads: Mapping[str, Sequence[float]]
) -> str:
    """The selected UAV of a landing: mode, distance to its pad, altitude, speed, energy, the pad markers of
    its latest camera frame and the reason of its latest mode switch."""
    if agent_id is None or a is None:
        return "no UAV"
    g = a.guidance
    if g is None and a.truth is None:
        return f"**{agent_id}**: nothing heard yet"
    speed = float(np.linalg.norm(a.truth.v_nav)) if a.truth is not None else None
    energy = fmt(a.truth.effort if a.truth is not None else None, 2, 1e-3)
    text = (
        f"**{agent_id}** · {g.mode if g is not None else DASH} · {fmt(g.range_m if g else None, 2)} m to "
        f"its pad  \naltitude {fmt(_altitude(a, pads), 2)} m · speed {fmt(speed, 2)} m/s · energy {energy} "
        f"kJ · pad markers in the latest frame {_pad_markers(a)}"
    )
    return text + (f"  \n_{cell(g.reason)}_" if g is not None and g.reason else "")


class LandingDrawer(MissionDrawer):
    """A landing swarm: UAVs and their pads, the anchors around them, no mothership."""

    title = " · landing"
    selection = "UAV"
    status_roles = ("world",)
    plot_title = "distance to the pad"
    plot_series = ({"label": "t [s]"}, {"label": "to pad [m]", "stroke": "#2c3e50", "width": 2})
    mode_title = "mode: -1 ABORT · 1 CRUISE · 2 DEVIATE, CLIMB · 3 DESCEND · 4 FINAL · 5 LANDED"

    def __init__(self, sc: LandingScenario, mission) -> None:
        super().__init__(sc, mission)
        self.vehicles = uav_vehicles(sc)
        self.anchors_m = np.array(sc.uwb.anchors_m, dtype=float)
        self.selectable = sorted(self.vehicles, key=panels.natural_key)
        self.pads = {u.id: u.pad_m for u in sc.uavs()}

    @classmethod
    def fault_menu(cls, kinds) -> FaultMenu:
        """The landing world's faults, each on one UAV or every UAV (a UWB dropout too), for a window."""
        return FaultMenu(tuple(kinds), HINTS, EVERY_UAV, uwb_network=False, appliers="world")

    def draw_scene(self, server: viser.ViserServer, params) -> LandingSceneView:
        frame_landing_scene(server, self.sc)
        return LandingSceneView(server, self.sc, params)

    def table(self, snap: Snapshot) -> str:
        return landing_table(snap, self.pads)

    def selected_markdown(self, agent_id: str | None, a: AgentSnap | None) -> str:
        return landing_uav_markdown(agent_id, a, self.pads)
