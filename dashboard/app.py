"""The Viser dashboard: the 3D scene and the GUI panels, drawn from :class:`~dashboard.state.SwarmState`
by one render thread.

Each frame (at most ``max_hz``, and slower when frames get expensive, :class:`~dashboard.state.FramePacer`)
the render thread polls the newest samples (:meth:`~dashboard.link.SwarmLink.poll`), takes one snapshot
and pushes to the browser only what changed since the previous frame, inside one ``server.atomic()``
block so the browser applies a frame at once. Poses follow every frame; trails, covariance shapes,
tables and plots, which cost more, at their own lower rates (``DashboardParams``). Measured here (viser
1.1.1, 2 shared cores under load, one browser connected): 16 pairs (32 vehicles) cost ~14 ms per frame
(median; decoding the newest samples included), so ~20 frames/s; one pair ~2 ms, 30 frames/s.

Scene (paper Fig. 1): the mothership's outline and UWB anchors (on a TDoA radio each labelled with its
packets a second as the tags hear them, :mod:`dashboard.radio`); each vehicle's true pose (a box in its
mode's colour, axes, label) and estimated pose (a wireframe box and axes), the 3-sigma position
covariance ellipsoid of the estimate, trails of both; each chaser's camera FOV cone, coloured by whether
its markers are in view; around each chaser's target its switch spheres ``r_t``, ``r2``, ``r1``, which
follow the MDP as it moves them, and the target's keep-out sphere.
"""

from __future__ import annotations

import contextlib
import logging
import math
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import viser
import zenoh

from dashboard import kinds, mapping, panels, radio
from dashboard import nodes as scene_nodes
from dashboard.faults import DOCKING, LANDING, FaultPanel
from dashboard.landing import LandingSceneView, frame_landing_scene, uav_vehicles
from dashboard.link import SwarmLink
from dashboard.nodes import set_if_changed as _set
from dashboard.playback import PlaybackPanel, Player, Recording, Timeline
from dashboard.state import AgentSnap, FramePacer, RateLimiter, Snapshot, SwarmState
from swarm.errors import ConfigError
from swarm.landing_scenario import LandingScenario
from swarm.missions import DEFAULT_MISSION, MISSIONS
from swarm.scenario import Scenario
from swarm.transport.keys import Keys
from swarm.transport.messages import DropCounter

__all__ = ["DashboardApp", "DashboardParams"]

_LOG = logging.getLogger("dashboard.app")


@dataclass(frozen=True)
class DashboardParams:
    """How the dashboard draws and how fast."""

    max_hz: float = 30.0
    """Most frames per second pushed to the browser."""
    max_busy: float = 0.5
    """Largest share of one core the render thread may use; heavier frames lower the frame rate."""
    trail_hz: float = 5.0
    """Trail updates per second (a trail is up to ``trail_cap`` points)."""
    panel_hz: float = 5.0
    """Table and text panel updates per second."""
    plot_hz: float = 2.0
    """Plot updates per second."""
    n_sigma: float = 3.0
    """Initial size of the covariance ellipsoids, in standard deviations (a GUI slider changes it)."""
    vision_recent_s: float = 0.5
    """A chaser's FOV cone shows markers "seen" for this long [s of swarm time] after a camera frame."""
    trail_cap: int = 1000
    """Most points per trail; the whole history is thinned by half when full."""
    trail_step_m: float = 0.002
    """Smallest spacing of trail points [m] (doubles at each thinning)."""
    series_cap: int = 600
    """Most samples per plotted time series."""
    rate_window_s: float = 2.0
    """The Radio panel's sliding window [s of swarm time]: the anchors' and the tags' rates are averaged
    over it (:mod:`dashboard.radio`; a TDoA3 anchor sends every 20-50 ms, so ~40-100 packets a window)."""

    def __post_init__(self) -> None:
        positive = ("max_hz", "trail_hz", "panel_hz", "plot_hz", "n_sigma", "vision_recent_s")
        positive += ("rate_window_s",)
        for name in positive:
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"dashboard.{name} must be a positive finite number, got {v!r}")
        if not (isinstance(self.max_busy, int | float) and 0 < self.max_busy <= 1):
            raise ConfigError(f"dashboard.max_busy must be in (0, 1], got {self.max_busy!r}")
        for name in ("trail_cap", "series_cap"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 4):
                raise ConfigError(f"dashboard.{name} must be an integer >= 4, got {v!r}")
        if not (isinstance(self.trail_step_m, int | float) and 0 <= self.trail_step_m < math.inf):
            raise ConfigError(f"dashboard.trail_step_m must be finite and >= 0, got {self.trail_step_m!r}")


def _frame_the_scene(server: viser.ViserServer, sc: Scenario) -> None:
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


class _AgentNodes:
    """The scene nodes of one vehicle and what was last pushed to them."""

    def __init__(self, scene: viser.SceneApi, a: AgentSnap, sc: Scenario) -> None:
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
        self.cov = scene.add_icosphere(
            n("cov"), radius=1.0, color=(52, 73, 94), opacity=0.25, subdivisions=2, visible=False,
            cast_shadow=False, receive_shadow=False,
        )  # fmt: skip
        empty = np.zeros((1, 2, 3))
        self.trail_truth = scene.add_line_segments(
            n("trail/truth"), empty, (90, 90, 90), thickness=2.0, thickness_units="screen", visible=False
        )
        self.trail_estimate = scene.add_line_segments(
            n("trail/estimate"), empty, (52, 152, 219), thickness=1.5, thickness_units="screen", visible=False
        )
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
        # what was pushed last (None: nothing yet)
        self.truth_msg: object = None
        self.estimate_msg: object = None
        self.cov_key: object = None
        self.color: object = None
        self.fov_state: str | None = None
        self.radii_key: object = None
        self.trail_versions: tuple[int, int] | None = None


class SceneView:
    """The 3D scene, created at start (mothership, anchors, grid) and per vehicle on first sight."""

    def __init__(self, server: viser.ViserServer, sc: Scenario, params: DashboardParams) -> None:
        self.server = server
        self.sc = sc
        self.params = params
        self.nodes: dict[str, _AgentNodes] = {}
        self.n_sigma = params.n_sigma
        self.show_trails = True
        self._anchors_version: int | None = None
        self._anchor_nodes: list[object] = []
        self._anchor_labels: dict[int, viser.LabelHandle] = {}
        self._run: int | None = None
        self._outline = None

    def _draw_anchors(self, ids: tuple[int, ...], positions: np.ndarray) -> None:
        for node in self._anchor_nodes:
            node.remove()  # type: ignore[attr-defined]
        self._anchor_nodes = []
        self._anchor_labels = {}
        scene = self.server.scene
        segments = mapping.mothership_outline(positions)
        if self._outline is None:
            self._outline = scene.add_line_segments(
                "/mothership/outline", segments, (60, 60, 60), thickness=2.0, thickness_units="screen"
            )
        else:
            self._outline.points = segments.astype(np.float32)
        for anchor_id, p in zip(ids, positions, strict=True):
            self._anchor_nodes.append(
                scene.add_icosphere(
                    mapping.anchor_node(anchor_id), radius=0.03, color=(192, 57, 43), position=tuple(p)
                )
            )
            label = f"{mapping.anchor_node(anchor_id)}/label"  # a child: removed with its anchor
            text = f"anchor {anchor_id}"
            self._anchor_labels[anchor_id] = scene.add_label(label, text, position=(0, 0, 0.06))

    def _label_anchors(self, rates: radio.RadioSnap) -> None:
        """On a TDoA radio, each anchor's label says its packets a second (the best tag's)."""
        if rates.mode == "twr":
            return
        heard = rates.anchor_hz()
        for anchor_id, label in self._anchor_labels.items():
            hz = heard.get(anchor_id)
            _set(label, "text", f"anchor {anchor_id}" + ("" if hz is None else f" · {hz:.0f}/s"))

    def update(self, snap: Snapshot, trails_due: bool) -> None:
        if snap.anchors_version != self._anchors_version:
            self._anchors_version = snap.anchors_version
            self._draw_anchors(*snap.anchors)
        if snap.radio is not None:
            self._label_anchors(snap.radio)
        new_run = snap.run != self._run
        self._run = snap.run
        for agent_id, a in snap.agents.items():
            nodes = self.nodes.get(agent_id)
            if nodes is None:
                nodes = self.nodes[agent_id] = _AgentNodes(self.server.scene, a, self.sc)
            self._update_agent(nodes, a, snap, trails_due or new_run)

    def invalidate(self) -> None:
        """Push everything again at the next frame (the store was restored: a playback's backward seek, after
        which a message or a trail version may equal one drawn before for a different time)."""
        self._anchors_version = None
        self._run = None
        for nodes in list(self.nodes.values()):
            nodes.truth_msg = nodes.estimate_msg = nodes.cov_key = nodes.color = nodes.radii_key = _STALE
            nodes.fov_state = None
            nodes.trail_versions = None

    def set_show_trails(self, show: bool) -> None:
        """Show or hide every trail (their history is kept): all are pushed again at the next trail frame."""
        self.show_trails = show
        for nodes in list(self.nodes.values()):
            nodes.trail_versions = None

    def trail_versions(self) -> dict[str, tuple[int, int]]:
        return {k: n.trail_versions for k, n in self.nodes.items() if n.trail_versions is not None}

    def _update_agent(self, nodes: _AgentNodes, a: AgentSnap, snap: Snapshot, trails_due: bool) -> None:
        if scene_nodes.update_truth(nodes, a) and nodes.keepout is not None:
            if a.truth is not None:
                nodes.keepout.position = a.truth.p_nav
            _set(nodes.keepout, "visible", a.truth is not None)
        scene_nodes.update_color(nodes, a, a.role)
        scene_nodes.update_estimate(nodes, a, self.n_sigma, trails_due)
        if nodes.fov is not None:
            self._update_fov(nodes, a, snap)
        if nodes.radii:
            self._update_radii(nodes, a, snap)
        if trails_due and a.truth_trail is not None:
            scene_nodes.update_trails(nodes, a, self.show_trails)

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


class GuiView:
    """The control panel: run status and controls, agents table, the radio's rates (:mod:`dashboard.radio`),
    the selected chaser's decision panel and plots, the event log, the Faults panel
    (:class:`~dashboard.faults.FaultPanel`), and view settings.

    With ``link=None`` (a recording's playback, ``player`` given) nothing commands a swarm: the Playback
    folder (:class:`~dashboard.playback.PlaybackPanel`) replaces the run controls, and the Faults panel only
    lists the recorded faults."""

    def __init__(
        self,
        server: viser.ViserServer,
        link: SwarmLink | None,
        chasers: list[str],
        vehicles: list[str],
        scene: SceneView,
        state: SwarmState,
        player: tuple[Player, Recording] | None = None,
        landing: LandingScenario | None = None,
    ) -> None:
        gui = server.gui
        self.landing = landing
        self.pads = {u.id: u.pad_m for u in landing.uavs()} if landing is not None else {}
        title = "#### TPODS swarm" + (" · landing" if landing is not None else "")
        gui.add_markdown(title + (" · playback" if link is None else ""))
        self.status = gui.add_markdown("**no clock yet**")
        self.buttons = {}
        self.playback = None
        if player is not None:
            self.playback = PlaybackPanel(gui, *player)
        if link is not None:
            self._send = link.send
            with gui.add_folder("Run"):
                for label, command, color in (
                    ("Pause", "pause", "yellow"),
                    ("Resume", "resume", "green"),
                    ("Reset", "reset", "gray"),
                    ("New seed", "new_seed", "blue"),
                ):
                    button = gui.add_button(label, color=color)
                    button.on_click(self._make_handler(command))
                    self.buttons[command] = button
                self.sent = gui.add_markdown("")
        with gui.add_folder("Agents"):
            self.table = gui.add_markdown("no agents yet")
        with gui.add_folder("Radio"):
            self.radio = gui.add_markdown(radio.radio_markdown(None))
        with gui.add_folder("UAV" if landing is not None else "Chaser"):
            options = chasers or ["-"]
            label = "uav" if landing is not None else "chaser"
            self.chaser = gui.add_dropdown(label, options, initial_value=options[0])
            self.decision = gui.add_markdown("")
            axes_x = {"x": {"time": False, "auto": True}}
            if landing is not None:  # no switch radii: the distance to the pad only
                series = ({"label": "t [s]"}, {"label": "to pad [m]", "stroke": "#2c3e50", "width": 2})
                title, mode_title = "distance to the pad", LANDING_MODE_TITLE
            else:
                series = (
                    {"label": "t [s]"},
                    {"label": "range [m]", "stroke": "#2c3e50", "width": 2},
                    {"label": "r1 [m]", "stroke": "#9b59b6", "width": 2},
                    {"label": "r2 [m]", "stroke": "#f39c12", "width": 2},
                    {"label": "r_t [m]", "stroke": "#3498db", "width": 1},
                )
                title, mode_title = "range and switch radii", DOCKING_MODE_TITLE
            self.radii_plot = gui.add_uplot(
                (np.zeros(1), *(np.full(1, np.nan) for _ in series[1:])),
                series,
                title=title,
                scales=axes_x,
                aspect=1.6,
            )
            self.mode_plot = gui.add_uplot(
                (np.zeros(1), np.full(1, np.nan)),
                ({"label": "t [s]"}, {"label": "mode", "stroke": "#27ae60", "width": 2}),
                title=mode_title,
                scales={**axes_x, "y": {"auto": False, "range": (-1.5, 5.5)}},
                aspect=2.2,
            )
            self.modes = gui.add_markdown("")
        with gui.add_folder("Events"):
            self.events = gui.add_markdown("no events yet")
        # the faults the world takes: a landing world's two kinds, on one UAV or every UAV
        menu = LANDING if landing is not None else DOCKING
        send, listening = (link.send_fault, link.listeners) if link is not None else (None, lambda: False)
        self.faults = FaultPanel(gui, send, listening, vehicles, menu)
        with gui.add_folder("View", expand_by_default=False):
            sigma = gui.add_slider("ellipsoid σ", min=1.0, max=5.0, step=0.5, initial_value=scene.n_sigma)
            trails = gui.add_checkbox("trails", initial_value=True)
            clear = gui.add_button("Clear trails")

        @sigma.on_update
        def _(_event: object) -> None:
            scene.n_sigma = float(sigma.value)

        @trails.on_update
        def _(_event: object) -> None:
            scene.set_show_trails(bool(trails.value))

        @clear.on_click
        def _(_event: object) -> None:
            state.clear_trails()

        self._plot_key: object = None
        self._events_version: int | None = None

    def invalidate(self) -> None:
        """Push the event log, the fault log and the plots again at their next update (the store was
        restored, :meth:`SceneView.invalidate`)."""
        self._events_version = None
        self._plot_key = None
        self.faults.invalidate()

    def _make_handler(self, command: str) -> Callable[[object], None]:
        def on_click(_event: object) -> None:
            self.press(command)

        return on_click

    def press(self, command: str) -> None:
        """What a click on a run-control button does: send ``command`` to the world over Zenoh."""
        try:
            self._send(command)
            self.sent.content = f"sent **{command}** at {time.strftime('%H:%M:%S')}"
        except Exception as exc:  # a closed session at shutdown: say so, never raise into Viser
            self.sent.content = f"could not send {command}: {exc}"
            _LOG.warning("could not send run control %s: %s", command, exc)

    def update_panels(self, snap: Snapshot, dropped: int) -> None:
        if self.landing is not None:
            _set(self.status, "content", panels.status_markdown(snap, dropped, roles=("world",)))
            _set(self.table, "content", panels.landing_table(snap, self.pads))
        else:
            _set(self.status, "content", panels.status_markdown(snap, dropped))
            _set(self.table, "content", panels.agents_table(snap))
        chasers = [k for k, a in snap.agents.items() if a.role != "target" and a.guidance is not None]
        known = list(self.chaser.options)
        if chasers and any(c not in known for c in chasers):
            self.chaser.options = sorted(
                {c for c in known if c != "-"} | set(chasers), key=panels.natural_key
            )
        if snap.radio is not None:
            _set(self.radio, "content", radio.radio_markdown(snap.radio, panels.natural_key))
        selected = snap.agents.get(self.chaser.value)
        if self.landing is not None:
            text = panels.landing_uav_markdown(self.chaser.value, selected, self.pads)
        else:
            text = panels.decision_markdown(self.chaser.value, selected.guidance if selected else None)
        _set(self.decision, "content", text)
        _set(self.modes, "content", panels.modes_markdown(selected.modes if selected else ()))
        if snap.events_version != self._events_version:
            self._events_version = snap.events_version
            uwb_network = self.faults.menu.uwb_network  # how the event log words a UWB fault
            _set(self.events, "content", panels.events_markdown(snap.events, uwb_network=uwb_network))
        self.faults.update(snap)
        if self.playback is not None:
            self.playback.update()

    def update_plots(self, snap: Snapshot) -> None:
        selected = snap.agents.get(self.chaser.value)
        if selected is None:
            return
        key = (selected.agent_id, selected.radii_version, len(selected.modes))
        if key == self._plot_key:
            return
        self._plot_key = key
        t, v = selected.radii_t, selected.radii_v
        if len(t) >= 1:
            width = 1 if self.landing is not None else v.shape[1]
            self.radii_plot.data = (t, *(v[:, i] for i in range(width)))
        t_end = float(t[-1]) if len(t) else None
        self.mode_plot.data = panels.mode_steps(selected.modes, t_end)


DOCKING_MODE_TITLE = "mode: -1 ABORT · 0 HOLD · 1 APPROACH · 2 REORIENT · 3 ALIGN · 4 DOCK · 5 DOCKED"
LANDING_MODE_TITLE = "mode: -1 ABORT · 1 CRUISE · 2 DEVIATE, CLIMB · 3 DESCEND · 4 FINAL · 5 LANDED"
"""Titles of the mode-timeline plot: the levels of :data:`dashboard.mapping.MODE_LEVELS`."""

_STALE = object()
"""What a scene node "last pushed" after :meth:`SceneView.invalidate`: equal to nothing the store holds."""


class DashboardApp:
    """The dashboard of one swarm: a Viser server on ``host:port`` drawing what ``session`` hears under
    ``keys``'s namespace, or, with ``recording`` (and ``session=None``), a recording's playback
    (:mod:`dashboard.playback`: no Zenoh at all). ``start()`` starts the render thread; ``close()`` stops
    it, the Zenoh side and the server (the caller closes ``session``)."""

    def __init__(
        self,
        sc: Scenario | LandingScenario,
        session: zenoh.Session | None,
        keys: Keys,
        host: str = "localhost",
        port: int = 8080,
        params: DashboardParams | None = None,
        process_id: str = "dashboard",
        recording: Recording | None = None,
    ) -> None:
        if (session is None) == (recording is None):
            raise ValueError("a DashboardApp draws either a Zenoh session or a recording")
        self.params = params if params is not None else DashboardParams()
        self.drops = DropCounter()
        drawer = MISSIONS[getattr(sc, "mission", DEFAULT_MISSION)].dashboard_drawer  # Scenario: no field
        landing = sc if drawer == "landing" else None
        if landing is not None:
            vehicles = uav_vehicles(landing)
            anchors = np.array(landing.uwb.anchors_m, dtype=float)
        else:
            vehicles = {k: (v.role, v.target) for k, v in sc.vehicles.items()}
            anchors = np.array(sc.anchors_m, dtype=float)
        uwb_mode = sc.uwb.mode
        if recording is not None and uwb_mode == "twr":  # a recorded TDoA run drawn with its bundled scenario
            uwb_mode = recording.uwb_mode or "twr"

        def make_state() -> SwarmState:
            return SwarmState(
                vehicles,
                anchors,
                trail_cap=self.params.trail_cap,
                trail_step_m=self.params.trail_step_m,
                series_cap=self.params.series_cap,
                uwb_mode=uwb_mode,
                rate_window_s=self.params.rate_window_s,
            )

        self.state = make_state()
        self.link: SwarmLink | None = None
        self.player: Player | None = None
        if recording is not None:  # before the server: a long pass over the file, nothing served meanwhile
            self.player = Player(Timeline(recording, self.state, make_state))
        with contextlib.redirect_stdout(sys.stderr):  # Viser's banner: stdout is for the ready line
            self.server = viser.ViserServer(host=host, port=port, verbose=False)
        try:
            self.server.gui.configure_theme(control_width="large", show_logo=False, show_share_button=False)
            if session is not None:
                self.link = SwarmLink(
                    session, keys, self.state, self.drops, process_id=process_id, tdoa=uwb_mode != "twr"
                )
            self.scene: SceneView | LandingSceneView
            if landing is not None:
                frame_landing_scene(self.server, landing)
                self.scene = LandingSceneView(self.server, landing, self.params)
                chasers = sorted(vehicles, key=panels.natural_key)
            else:
                _frame_the_scene(self.server, sc)
                self.scene = SceneView(self.server, sc, self.params)
                chasers = sorted(
                    (k for k, v in sc.vehicles.items() if v.role == "chaser"), key=panels.natural_key
                )
            playback = None if self.player is None else (self.player, recording)
            self.gui = GuiView(
                self.server, self.link, chasers, list(vehicles), self.scene, self.state, playback, landing
            )
        except BaseException:
            with contextlib.redirect_stdout(sys.stderr):
                self.server.stop()
            raise
        clock = time.monotonic
        self._trails = RateLimiter(self.params.trail_hz, clock)
        self._panels = RateLimiter(self.params.panel_hz, clock)
        self._plots = RateLimiter(self.params.plot_hz, clock)
        self._pacer = FramePacer(self.params.max_hz, self.params.max_busy)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="dashboard-render", daemon=True)
        self.frames = 0
        self._frame_errors = 0

    @property
    def port(self) -> int:
        """The port actually served (Viser takes the next free one if the requested port is busy)."""
        return self.server.get_port()

    def frame(self) -> None:
        """One frame: poll Zenoh (or move the playback), snapshot, push the changes to every browser as one
        atomic update."""
        if self.player is not None:
            if self.player.advance():
                self.scene.invalidate()
                self.gui.invalidate()
        else:
            assert self.link is not None
            self.link.poll()
        panels_due = self._panels.due()
        snap = self.state.snapshot(self.scene.trail_versions(), radio=panels_due)
        with self.server.atomic():
            self.scene.update(snap, self._trails.due())
            if panels_due:
                self.gui.update_panels(snap, self.drops.total)
            if self._plots.due():
                self.gui.update_plots(snap)
        self.frames += 1

    def _run(self) -> None:
        while not self._stop.is_set():
            t0 = time.perf_counter()
            try:
                self.frame()
            except Exception:  # a bad frame must not end the dashboard: log (rate-limited) and go on
                self._frame_errors += 1
                if self._frame_errors in (1, 10, 100) or self._frame_errors % 1000 == 0:
                    _LOG.exception("render frame failed (%d so far)", self._frame_errors)
            self._stop.wait(self._pacer.delay(time.perf_counter() - t0))

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        if self.link is not None:
            self.link.close()
        self.drops.flush()
        with contextlib.redirect_stdout(sys.stderr):
            self.server.stop()
