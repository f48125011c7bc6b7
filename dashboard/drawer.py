"""The one drawer interface of the dashboard (docs/architecture.md, "Missions"): what
:class:`dashboard.app.DashboardApp` asks of the mission it draws, and the scene-node updates every mission's
scene shares.

A mission names its drawer by dotted path (:attr:`swarm.missions.Mission.dashboard_drawer`,
``"dashboard.docking:DockingDrawer"``); :func:`drawer_of` builds it for a scenario. A
:class:`MissionDrawer` gives the store's vehicles and anchors, the 3D scene (a :class:`MissionScene`), the
agents table, the selected vehicle's panel and plot, and the Faults panel's menu (its kinds are the
mission's ``fault_menu``). The app draws nothing else mission-specific.

A vehicle's nodes (:class:`VehicleNodes`) have ``truth``, ``body``, ``estimate``, ``cov``, ``trail_truth``,
``trail_estimate`` and what was last pushed: ``truth_msg``, ``color``, ``estimate_msg``, ``cov_key``,
``trail_versions``; each update pushes to the browser only what changed."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
import viser

from dashboard import mapping
from dashboard.faults import FaultMenu
from dashboard.radio import RadioSnap
from dashboard.state import AgentSnap, Snapshot
from swarm.errors import ConfigError
from swarm.missions import DEFAULT_MISSION, MISSIONS, Mission, resolve

STALE = object()
"""What a node "last pushed" after :meth:`MissionScene.invalidate`: equal to nothing the store holds."""
ANCHOR_COLOR = (192, 57, 43)


def drawer_of(sc: Any) -> MissionDrawer:
    """The drawer of scenario ``sc``'s mission (its ``mission`` field: a name or a ``[mission]`` table;
    none: docking). ConfigError naming the mission if it has no drawer."""
    name = getattr(sc, "mission", DEFAULT_MISSION)
    mission = MISSIONS[getattr(name, "name", name)]
    if mission.dashboard_drawer is None:
        raise ConfigError(
            f"{getattr(sc, 'name', sc)!r}: mission {mission.name!r} has no dashboard drawer (its Mission "
            "names no dashboard_drawer); the dashboard cannot draw it"
        )
    return resolve(mission.dashboard_drawer)(sc, mission)


class MissionDrawer:
    """A mission's drawing, as :class:`dashboard.app.DashboardApp` asks for it. A subclass sets the class
    attributes, ``vehicles``, ``anchors_m`` and ``selectable`` and implements the methods."""

    title: ClassVar[str] = ""
    """What the GUI's title adds after "TPODS swarm" (``" · landing"``)."""
    selection: ClassVar[str] = "Chaser"
    """The GUI folder of the selected vehicle (its dropdown is labelled in lower case)."""
    status_roles: ClassVar[tuple[str, ...]] = ("world", "mothership")
    """The processes the status line reports."""
    plot_title: ClassVar[str] = ""
    plot_series: ClassVar[tuple[dict, ...]] = ()
    """The selected vehicle's plot: time, then the first ``len - 1`` columns of its range series (range,
    r1, r2, r_t: :class:`dashboard.state.AgentSnap`)."""
    mode_title: ClassVar[str] = ""
    """Title of the mode-timeline plot: the levels of :data:`dashboard.mapping.MODE_LEVELS`."""

    def __init__(self, sc: Any, mission: Mission) -> None:
        self.sc = sc
        self.faults = self.fault_menu(mission.fault_menu)
        """The Faults panel's menu: the mission's kinds, in this drawer's words."""
        self.vehicles: dict[str, tuple[str, str | None]] = {}
        """The store's vehicles: id -> (role, target)."""
        self.anchors_m = np.zeros((0, 3))
        self.selectable: list[str] = []
        """The vehicles the selection dropdown offers at start."""

    @classmethod
    def fault_menu(cls, kinds: Sequence[str]) -> FaultMenu:
        """The Faults panel's menu of ``kinds`` (the mission's ``fault_menu``)."""
        raise NotImplementedError

    def draw_scene(self, server: viser.ViserServer, params: Any) -> MissionScene:
        """Frame the scene (grid, initial camera) and return the scene view that draws each snapshot."""
        raise NotImplementedError

    def table(self, snap: Snapshot) -> str:
        """The Agents folder's markdown table."""
        raise NotImplementedError

    def selected_markdown(self, agent_id: str | None, a: AgentSnap | None) -> str:
        """The panel of the selected vehicle."""
        raise NotImplementedError


class VehicleNodes:
    """One vehicle's scene nodes and what was last pushed to them (None: nothing yet)."""

    def __init__(self) -> None:
        self.truth_msg: object = None
        self.estimate_msg: object = None
        self.cov_key: object = None
        self.color: object = None
        self.trail_versions: tuple[int, int] | None = None

    def add_cov_and_trails(self, scene: viser.SceneApi, base: str, opacity: float) -> None:
        """The covariance ellipsoid and the true and estimated trails under ``base``."""
        self.cov = scene.add_icosphere(
            f"{base}/cov", radius=1.0, color=(52, 73, 94), opacity=opacity, subdivisions=2, visible=False,
            cast_shadow=False, receive_shadow=False,
        )  # fmt: skip
        empty = np.zeros((1, 2, 3))
        self.trail_truth = scene.add_line_segments(
            f"{base}/trail/truth", empty, (90, 90, 90), thickness=2.0, thickness_units="screen", visible=False
        )
        self.trail_estimate = scene.add_line_segments(
            f"{base}/trail/estimate", empty, (52, 152, 219), thickness=1.5, thickness_units="screen",
            visible=False,
        )  # fmt: skip

    def stale(self) -> None:
        """Push everything again at the next update."""
        self.truth_msg = self.estimate_msg = self.cov_key = self.color = STALE
        self.trail_versions = None


class MissionScene:
    """A mission's 3D scene: the anchors (on a TDoA radio each labelled with its packets a second as the tags
    hear them, :mod:`dashboard.radio`) and each vehicle's nodes on first sight. A subclass implements
    :meth:`add_vehicle` and :meth:`update_vehicle`; vehicles in ``hidden`` are not drawn."""

    ANCHOR_RADIUS_M: ClassVar[float] = 0.03
    ANCHOR_LABEL_Z_M: ClassVar[float] = 0.06

    def __init__(self, server: viser.ViserServer, sc: Any, params: Any) -> None:
        self.server = server
        self.sc = sc
        self.params = params
        self.nodes: dict[str, Any] = {}
        self.hidden: frozenset[str] = frozenset()
        self.n_sigma = params.n_sigma
        self.show_trails = True
        self._anchors_version: int | None = None
        self._anchor_nodes: list[object] = []
        self._anchor_labels: dict[int, viser.LabelHandle] = {}
        self._run: int | None = None

    def add_vehicle(self, a: AgentSnap) -> VehicleNodes:
        raise NotImplementedError

    def update_vehicle(self, nodes: Any, a: AgentSnap, snap: Snapshot, trails_due: bool) -> None:
        raise NotImplementedError

    def _draw_anchors(self, ids: tuple[int, ...], positions: np.ndarray) -> None:
        for node in self._anchor_nodes:
            node.remove()  # type: ignore[attr-defined]
        self._anchor_nodes = []
        self._anchor_labels = {}
        scene = self.server.scene
        for anchor_id, p in zip(ids, positions, strict=True):
            name = mapping.anchor_node(anchor_id)
            self._anchor_nodes.append(
                scene.add_icosphere(name, radius=self.ANCHOR_RADIUS_M, color=ANCHOR_COLOR, position=tuple(p))
            )
            label = f"{name}/label"  # a child: removed with its anchor
            position = (0.0, 0.0, self.ANCHOR_LABEL_Z_M)
            self._anchor_labels[anchor_id] = scene.add_label(label, f"anchor {anchor_id}", position=position)

    def _label_anchors(self, rates: RadioSnap) -> None:
        """On a TDoA radio, each anchor's label says its packets a second (the best tag's)."""
        if rates.mode == "twr":
            return
        heard = rates.anchor_hz()
        for anchor_id, label in self._anchor_labels.items():
            hz = heard.get(anchor_id)
            set_if_changed(label, "text", f"anchor {anchor_id}" + ("" if hz is None else f" · {hz:.0f}/s"))

    def update(self, snap: Snapshot, trails_due: bool) -> None:
        if snap.anchors_version != self._anchors_version:
            self._anchors_version = snap.anchors_version
            self._draw_anchors(*snap.anchors)
        if snap.radio is not None:
            self._label_anchors(snap.radio)
        new_run = snap.run != self._run
        self._run = snap.run
        for agent_id, a in snap.agents.items():
            if agent_id in self.hidden:
                continue
            nodes = self.nodes.get(agent_id)
            if nodes is None:
                nodes = self.nodes[agent_id] = self.add_vehicle(a)
            self.update_vehicle(nodes, a, snap, trails_due or new_run)

    def invalidate(self) -> None:
        """Push everything again at the next frame (the store was restored: a playback's backward seek, after
        which a message or a trail version may equal one drawn before for a different time)."""
        self._anchors_version = None
        self._run = None
        for nodes in list(self.nodes.values()):
            nodes.stale()

    def set_show_trails(self, show: bool) -> None:
        """Show or hide every trail (their history is kept): all are pushed again at the next trail frame."""
        self.show_trails = show
        for nodes in list(self.nodes.values()):
            nodes.trail_versions = None

    def trail_versions(self) -> dict[str, tuple[int, int]]:
        return {k: n.trail_versions for k, n in self.nodes.items() if n.trail_versions is not None}


def set_if_changed(handle: object, attr: str, value: object) -> None:
    """Assign only when the value changed (each assignment is a message to every browser)."""
    if getattr(handle, attr) != value:
        setattr(handle, attr, value)


def update_truth(nodes, a: AgentSnap) -> bool:
    """The true pose's frame; True if the truth changed since the last push."""
    if a.truth is nodes.truth_msg:
        return False
    nodes.truth_msg = a.truth
    if a.truth is not None:
        nodes.truth.position, nodes.truth.wxyz = mapping.pose_wxyz(a.truth.p_nav, a.truth.q_nav_body)
    set_if_changed(nodes.truth, "visible", a.truth is not None)
    return True


def update_color(nodes, a: AgentSnap, role: str | None) -> None:
    """The body in the colour of its guidance mode."""
    color = mapping.mode_color(a.guidance.mode if a.guidance is not None else None, role)
    if color != nodes.color:
        nodes.color = color
        nodes.body.color = color


def update_estimate(nodes, a: AgentSnap, n_sigma: float, shapes_due: bool) -> None:
    """The estimate's frame and its covariance ellipsoid. The covariance changes slowly: the ellipsoid's shape
    (an eigen-decomposition and two messages per vehicle) follows when ``shapes_due`` (the trail rate), and
    at once for a first estimate or a new sigma."""
    est = a.estimate
    if est is not nodes.estimate_msg:
        nodes.estimate_msg = est
        set_if_changed(nodes.estimate, "visible", est is not None)
        set_if_changed(nodes.cov, "visible", est is not None)
        if est is not None:
            nodes.estimate.position, nodes.estimate.wxyz = mapping.pose_wxyz(est.p_nav, est.q_nav_body)
            nodes.cov.position = est.p_nav
        else:
            nodes.cov_key = None
    if est is not None and (shapes_due or nodes.cov_key != n_sigma):
        nodes.cov_key = n_sigma
        radii, wxyz = mapping.covariance_ellipsoid(est.cov[:3, :3], n_sigma)
        nodes.cov.wxyz = wxyz
        nodes.cov.scale = tuple(float(r) for r in radii)


def update_trails(nodes, a: AgentSnap, show: bool) -> None:
    """The true and estimated trails (at the trail rate)."""
    nodes.trail_versions = a.trail_versions
    for handle, pts in ((nodes.trail_truth, a.truth_trail), (nodes.trail_estimate, a.estimate_trail)):
        if pts is None or len(pts) < 2 or not show:
            set_if_changed(handle, "visible", False)
        else:
            handle.points = np.stack([pts[:-1], pts[1:]], axis=1).astype(np.float32)
            set_if_changed(handle, "visible", True)
