"""The dashboard's drawing of a docking swarm (paper Fig. 1): :class:`DockingDrawer`, named by the docking
mission's ``dashboard_drawer`` (:mod:`dashboard.drawer`).

Scene: the mothership's outline and UWB anchors; each vehicle's true pose (drawn as its kind,
:mod:`dashboard.kinds`, in its mode's colour, axes, label) and estimated pose (a wireframe box and axes),
the 3-sigma position covariance ellipsoid of the estimate, trails of both; each chaser's camera FOV cone,
coloured by whether its markers are in view; around each chaser's target its switch spheres ``r_t``,
``r2``, ``r1``, which follow the MDP as it moves them, and the target's keep-out sphere. Panels: the
agents table and the selected chaser's Algorithm 1 decision, range and switch radii.
"""

from __future__ import annotations

from collections.abc import Sequence

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
from dashboard.drawer import set_if_changed as _set
from dashboard.faults import EVERY_CHASER, FaultMenu
from dashboard.panels import DASH, cell, fmt
from dashboard.state import AgentSnap, Snapshot
from swarm.transport.messages import Guidance

__all__ = ["DockingDrawer", "DockingScene", "agents_table", "decision_markdown", "frame_docking_scene"]

HINTS = {
    "uwb_dropout": "every UWB exchange of every vehicle fails (the mothership applies it)",
    "nlos_burst": "each UWB exchange of every vehicle is an NLOS outlier with this probability (mothership)",
    "camera_loss": "the camera sees no marker (the world applies it; chasers only)",
    "gyro_bias_step": "a constant rate added to the gyro from the start on, for good (world)",
    "sensor_delay": (
        "imu and vision samples leave the world up to this late, so also out of order (world). "
        "Free-running clocks only (realtime, scaled:N): a lockstep world refuses it"
    ),
}
"""The Faults panel's line on each kind a docking world and its mothership apply."""


def frame_docking_scene(server: viser.ViserServer, sc) -> None:
    """A floor grid under the scenario's vehicles and anchors, and the initial camera looking at them."""
    vehicles = np.array([v.position_m for v in sc.vehicles.values()], dtype=float).reshape(-1, 3)
    pts = np.vstack([vehicles, np.array(sc.anchors_m, dtype=float).reshape(-1, 3)])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    extent = float(np.max(hi - lo))
    size = float(np.ceil(extent + 2.0))
    server.scene.add_grid(
        "/grid", width=size, height=size, cell_size=0.25, section_size=1.0, plane="xy",
        position=(*np.round(0.5 * (lo[:2] + hi[:2])).tolist(), float(lo[2]) - 0.25),
    )  # fmt: skip
    centre = vehicles.mean(axis=0) if len(vehicles) else pts.mean(axis=0)
    direction = np.array([-0.55, -1.0, 0.75])
    on_surface = kinds.draw_surface(server.scene, sc)  # a table under wheeled modules: frame it closer
    eye = centre + (1.1 if on_surface else 1.6) * max(extent, 1.0) * direction / np.linalg.norm(direction)
    server.initial_camera.position = tuple(eye)
    server.initial_camera.look_at = tuple(centre)


class _AgentNodes(VehicleNodes):
    """The scene nodes of one vehicle and what was last pushed to them."""

    def __init__(self, scene: viser.SceneApi, a: AgentSnap, sc) -> None:
        super().__init__()
        n = lambda part: mapping.node_name(a.agent_id, part)  # noqa: E731
        size = 2.0 * sc.guidance.half_size_m
        chaser = a.role == "chaser"
        self.truth = scene.add_frame(n("truth"), show_axes=False, visible=False)
        # drawn as what it is: its kind's drawer (dashboard/kinds.py); the body's colour follows the mode
        self.body = kinds.draw(scene, n("truth"), sc, a.agent_id, mapping.mode_color(None, a.role))
        scene.add_frame(n("truth/axes"), axes_length=1.5 * size, axes_radius=0.04 * size)
        scene.add_label(n("truth/label"), a.agent_id, position=(0.0, 0.0, 1.2 * size))
        self.fov = None
        if chaser:
            vertices, faces = mapping.fov_cone_mesh(sc.camera.fov_half_angle_deg, sc.camera.max_range_m)
            cam = sc.camera_for(a.agent_id) if a.agent_id in sc.vehicles else sc.camera
            pos, wxyz = mapping.camera_pose_in_body(cam.pos_body_m, cam.q_body_cam)
            self.fov = scene.add_mesh_simple(
                n("truth/fov"), vertices, faces, color=mapping.FOV_COLORS["out"], opacity=0.18,
                side="double", position=pos, wxyz=wxyz, cast_shadow=False, receive_shadow=False,
            )  # fmt: skip
        self.estimate = scene.add_frame(
            n("estimate"), axes_length=1.2 * size, axes_radius=0.025 * size, visible=False
        )
        scene.add_box(n("estimate/body"), color=(40, 40, 40), dimensions=(size,) * 3, wireframe=True)
        self.add_cov_and_trails(scene, f"/agents/{a.agent_id}", 0.25)
        self.radii: dict[str, viser.IcosphereHandle] = {}
        if chaser:
            for name in ("r_t", "r2", "r1"):
                self.radii[name] = scene.add_icosphere(
                    n(f"radii/{name}"), radius=1.0, color=mapping.RADII_COLORS[name], opacity=0.08,
                    subdivisions=3, visible=False, cast_shadow=False, receive_shadow=False,
                )  # fmt: skip
        self.keepout = None
        if a.role == "target":
            self.keepout = scene.add_icosphere(
                n("keepout"), radius=sc.guidance.keepout_radius_m, color=mapping.RADII_COLORS["keepout"],
                opacity=0.15, subdivisions=3, visible=False, cast_shadow=False, receive_shadow=False,
            )  # fmt: skip
        self.fov_state: str | None = None
        self.radii_key: object = None

    def stale(self) -> None:
        super().stale()
        self.radii_key = STALE
        self.fov_state = None


class DockingScene(MissionScene):
    """The 3D scene of a docking swarm (module docstring): the mothership's outline with its anchors, each
    vehicle on first sight."""

    def __init__(self, server: viser.ViserServer, sc, params) -> None:
        super().__init__(server, sc, params)
        self._outline = None

    def _draw_anchors(self, ids: tuple[int, ...], positions: np.ndarray) -> None:
        segments = mapping.mothership_outline(positions)
        if self._outline is None:
            self._outline = self.server.scene.add_line_segments(
                "/mothership/outline", segments, (60, 60, 60), thickness=2.0, thickness_units="screen"
            )
        else:
            self._outline.points = segments.astype(np.float32)
        super()._draw_anchors(ids, positions)

    def add_vehicle(self, a: AgentSnap) -> _AgentNodes:
        return _AgentNodes(self.server.scene, a, self.sc)

    def update_vehicle(self, nodes: _AgentNodes, a: AgentSnap, snap: Snapshot, trails_due: bool) -> None:
        if update_truth(nodes, a) and nodes.keepout is not None:
            if a.truth is not None:
                nodes.keepout.position = a.truth.p_nav
            _set(nodes.keepout, "visible", a.truth is not None)
        update_color(nodes, a, a.role)
        update_estimate(nodes, a, self.n_sigma, trails_due)
        if nodes.fov is not None:
            self._update_fov(nodes, a, snap)
        if nodes.radii:
            self._update_radii(nodes, a, snap)
        if trails_due and a.truth_trail is not None:
            update_trails(nodes, a, self.show_trails)

    def _update_fov(self, nodes: _AgentNodes, a: AgentSnap, snap: Snapshot) -> None:
        target = snap.agents.get(a.target) if a.target is not None else None
        in_cone = False
        if a.truth is not None and target is not None and target.truth is not None:
            cam = self.sc.camera_for(a.agent_id) if a.agent_id in self.sc.vehicles else self.sc.camera
            in_cone = mapping.target_in_cone(
                a.truth.p_nav, a.truth.q_nav_body, target.truth.p_nav, cam.pos_body_m, cam.q_body_cam,
                cam.fov_half_angle_deg, cam.min_range_m, cam.max_range_m,
            )  # fmt: skip
        state = mapping.fov_state(a.vision_t_s, a.latest_t_s(), in_cone, self.params.vision_recent_s)
        if state != nodes.fov_state:
            nodes.fov_state = state
            assert nodes.fov is not None
            nodes.fov.color = mapping.FOV_COLORS[state]

    def _update_radii(self, nodes: _AgentNodes, a: AgentSnap, snap: Snapshot) -> None:
        target = snap.agents.get(a.target) if a.target is not None else None
        centre = None
        if target is not None:
            src = target.truth if target.truth is not None else target.estimate
            centre = None if src is None else tuple(float(x) for x in src.p_nav)
        g = a.guidance
        radii = mapping.radii_of(g.r_t_m, g.r2_m, g.r1_m) if g is not None else dict.fromkeys(nodes.radii)
        key = (centre, tuple(radii.values()))
        if key == nodes.radii_key:
            return
        nodes.radii_key = key
        for name, handle in nodes.radii.items():
            r = radii[name]
            if r is None or centre is None:
                _set(handle, "visible", False)
            else:
                handle.position = centre
                handle.scale = r
                _set(handle, "visible", True)


def agents_table(snap: Snapshot) -> str:
    """Markdown table, one row per vehicle: role, mode, estimated range to its target [m], largest position
    sigma [cm], rejected measurements, and whether its agent process is alive (``alive``, ``lost``, or
    ``unseen`` before its liveliness token ever appeared)."""
    lines = [
        "| agent | role | mode | range [m] | σ [cm] | rejected | agent process |",
        "|---|---|---|---|---|---|---|",
    ]
    for agent_id in sorted(snap.agents, key=panels.natural_key):
        a = snap.agents[agent_id]
        g = a.guidance
        role = a.role
        mode = g.mode if g is not None else DASH
        rng = fmt(g.range_m if g is not None else None, 3)
        sigma = fmt(a.estimate.sigma_pos_max_m if a.estimate is not None else None, 2, 100.0)
        cells = (agent_id, role, mode, rng, sigma, panels.rejected_text(a), a.alive)
        lines.append("| " + " | ".join(cell(c) for c in cells) + " |")
    return "\n".join(lines)


_MATRIX_KEYS = (("A11", None, None), (None, "A22", "A23"), (None, "A32", "A33"))


def decision_markdown(agent_id: str | None, guidance: Guidance | None) -> str:
    """The latest pass of Algorithm 1 of chaser ``agent_id``: the transition probabilities ``A_ij`` between
    APPROACH (1), REORIENT (2) and ALIGN (3), the steady state ``pi`` of the REORIENT/ALIGN chain, and the
    inputs (``r``, ``d``, ``||q_e||``, ``sigma``) and radii after the pass (paper section V, Algorithm 1)."""
    if agent_id is None:
        return "no chaser"
    if guidance is None:
        return f"**{agent_id}**: no guidance yet"
    head = (
        f"**{agent_id}** · {guidance.mode} · r = {fmt(guidance.range_m)} m · "
        f"r2 = {fmt(guidance.r2_m)} m · r1 = {fmt(guidance.r1_m)} m"
    )
    d = guidance.decision
    if d is None:
        return f"{head}  \nno Algorithm 1 pass yet (outside r_t, or the fixed policy)"
    rows = ["| A | 1 | 2 | 3 |", "|---|---|---|---|"]
    for i, keys in enumerate(_MATRIX_KEYS, start=1):
        rows.append(f"| {i} | " + " | ".join(DASH if k is None else fmt(d.get(k)) for k in keys) + " |")
    inputs = (
        f"pass at t = {fmt(d.get('t_s'), 2)} s, r = {fmt(d.get('r_m'))} m  \n"
        f"π1 = {fmt(d.get('pi1'))} · π2 = {fmt(d.get('pi2'))}  \n"
        f"d = {fmt(d.get('d'), 2)} · ‖q_e‖ = {fmt(d.get('qe_vec_norm'), 3)} · "
        f"σ_pos = {fmt(d.get('sigma_pos_max_m'), 2, 100.0)} cm · "
        f"σ_uwb = {fmt(d.get('sigma_uwb_m'), 2, 100.0)} cm  \n"
        f"r_t = {fmt(d.get('r_t_m'))} m · r_d = {fmt(d.get('r_d_m'))} m → "
        f"r2 = {fmt(d.get('r2_m'))} m, r1 = {fmt(d.get('r1_m'))} m"
    )
    reason = f"  \n_{cell(guidance.reason)}_" if guidance.reason else ""
    return f"{head}\n\n" + "\n".join(rows) + f"\n\n{inputs}{reason}"


class DockingDrawer(MissionDrawer):
    """A docking swarm: chasers and targets, the mothership's anchors, Algorithm 1's decisions."""

    plot_title = "range and switch radii"
    plot_series = (
        {"label": "t [s]"},
        {"label": "range [m]", "stroke": "#2c3e50", "width": 2},
        {"label": "r1 [m]", "stroke": "#9b59b6", "width": 2},
        {"label": "r2 [m]", "stroke": "#f39c12", "width": 2},
        {"label": "r_t [m]", "stroke": "#3498db", "width": 1},
    )
    mode_title = "mode: -1 ABORT · 0 HOLD · 1 APPROACH · 2 REORIENT · 3 ALIGN · 4 DOCK · 5 DOCKED"

    def __init__(self, sc, mission) -> None:
        super().__init__(sc, mission)
        self.vehicles = {k: (v.role, v.target) for k, v in sc.vehicles.items()}
        self.anchors_m = np.array(sc.anchors_m, dtype=float)
        chasers = (k for k, v in sc.vehicles.items() if v.role == "chaser")
        self.selectable = sorted(chasers, key=panels.natural_key)

    @classmethod
    def fault_menu(cls, kinds: Sequence[str]) -> FaultMenu:
        """The world's camera, gyro and delay faults on one chaser or every chaser; the mothership's UWB
        faults on the whole radio network."""
        return FaultMenu(tuple(kinds), HINTS, EVERY_CHASER, uwb_network=True, appliers="world or mothership")

    def draw_scene(self, server: viser.ViserServer, params) -> DockingScene:
        frame_docking_scene(server, self.sc)
        return DockingScene(server, self.sc, params)

    def table(self, snap: Snapshot) -> str:
        return agents_table(snap)

    def selected_markdown(self, agent_id: str | None, a: AgentSnap | None) -> str:
        return decision_markdown(agent_id, a.guidance if a else None)
