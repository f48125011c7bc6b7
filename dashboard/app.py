"""The Viser dashboard: the 3D scene and the GUI panels, drawn from :class:`~dashboard.state.SwarmState`
by one render thread.

Each frame (at most ``max_hz``, and slower when frames get expensive, :class:`~dashboard.state.FramePacer`)
the render thread polls the newest samples (:meth:`~dashboard.link.SwarmLink.poll`), takes one snapshot
and pushes to the browser only what changed since the previous frame, inside one ``server.atomic()``
block so the browser applies a frame at once. Poses follow every frame; trails, covariance shapes,
tables and plots, which cost more, at their own lower rates (``DashboardParams``). Measured here (viser
1.1.1, 2 shared cores under load, one browser connected): 16 pairs (32 vehicles) cost ~14 ms per frame
(median; decoding the newest samples included), so ~20 frames/s; one pair ~2 ms, 30 frames/s.

What is drawn is the scenario's mission's: the app asks its drawer (:func:`dashboard.drawer.drawer_of`)
for the store's vehicles, the scene, the agents table, the selected vehicle's panel and plot, and the
Faults panel's menu (:mod:`dashboard.docking`, :mod:`dashboard.landing`).
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
from typing import Any

import numpy as np
import viser
import zenoh

from dashboard import panels, radio
from dashboard.drawer import MissionDrawer, MissionScene, drawer_of
from dashboard.drawer import set_if_changed as _set
from dashboard.faults import FaultPanel
from dashboard.link import SwarmLink
from dashboard.playback import PlaybackPanel, Player, Recording, Timeline
from dashboard.state import FramePacer, RateLimiter, Snapshot, SwarmState
from swarm.errors import ConfigError
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
        drawer: MissionDrawer,
        scene: MissionScene,
        state: SwarmState,
        player: tuple[Player, Recording] | None = None,
    ) -> None:
        gui = server.gui
        self.drawer = drawer
        gui.add_markdown("#### TPODS swarm" + drawer.title + (" · playback" if link is None else ""))
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
        with gui.add_folder(drawer.selection):
            options = drawer.selectable or ["-"]
            self.chaser = gui.add_dropdown(drawer.selection.lower(), options, initial_value=options[0])
            self.decision = gui.add_markdown("")
            axes_x = {"x": {"time": False, "auto": True}}
            series = drawer.plot_series
            self.radii_plot = gui.add_uplot(
                (np.zeros(1), *(np.full(1, np.nan) for _ in series[1:])),
                series,
                title=drawer.plot_title,
                scales=axes_x,
                aspect=1.6,
            )
            self.mode_plot = gui.add_uplot(
                (np.zeros(1), np.full(1, np.nan)),
                ({"label": "t [s]"}, {"label": "mode", "stroke": "#27ae60", "width": 2}),
                title=drawer.mode_title,
                scales={**axes_x, "y": {"auto": False, "range": (-1.5, 5.5)}},
                aspect=2.2,
            )
            self.modes = gui.add_markdown("")
        with gui.add_folder("Events"):
            self.events = gui.add_markdown("no events yet")
        send, listening = (link.send_fault, link.listeners) if link is not None else (None, lambda: False)
        self.faults = FaultPanel(gui, send, listening, list(drawer.vehicles), drawer.faults)
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
        restored, :meth:`~dashboard.drawer.MissionScene.invalidate`)."""
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
        _set(self.status, "content", panels.status_markdown(snap, dropped, self.drawer.status_roles))
        _set(self.table, "content", self.drawer.table(snap))
        chasers = [k for k, a in snap.agents.items() if a.role != "target" and a.guidance is not None]
        known = list(self.chaser.options)
        if chasers and any(c not in known for c in chasers):
            self.chaser.options = sorted(
                {c for c in known if c != "-"} | set(chasers), key=panels.natural_key
            )
        if snap.radio is not None:
            _set(self.radio, "content", radio.radio_markdown(snap.radio, panels.natural_key))
        selected = snap.agents.get(self.chaser.value)
        _set(self.decision, "content", self.drawer.selected_markdown(self.chaser.value, selected))
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
            self.radii_plot.data = (t, *(v[:, i] for i in range(len(self.drawer.plot_series) - 1)))
        t_end = float(t[-1]) if len(t) else None
        self.mode_plot.data = panels.mode_steps(selected.modes, t_end)


class DashboardApp:
    """The dashboard of one swarm: a Viser server on ``host:port`` drawing what ``session`` hears under
    ``keys``'s namespace, or, with ``recording`` (and ``session=None``), a recording's playback
    (:mod:`dashboard.playback`: no Zenoh at all). ``start()`` starts the render thread; ``close()`` stops
    it, the Zenoh side and the server (the caller closes ``session``)."""

    def __init__(
        self,
        sc: Any,
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
        drawer = drawer_of(sc)  # its mission's (ConfigError if it has none)
        uwb_mode = sc.uwb.mode
        if recording is not None and uwb_mode == "twr":  # a recorded TDoA run drawn with its bundled scenario
            uwb_mode = recording.uwb_mode or "twr"

        def make_state() -> SwarmState:
            return SwarmState(
                drawer.vehicles,
                drawer.anchors_m,
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
            self.scene = drawer.draw_scene(self.server, self.params)
            playback = None if self.player is None else (self.player, recording)
            self.gui = GuiView(self.server, self.link, drawer, self.scene, self.state, playback)
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
