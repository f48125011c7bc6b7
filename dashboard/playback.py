"""Playback of an MCAP recording in the dashboard (issue 16): ``swarm dashboard --open FILE.mcap``.

A recording (:func:`swarm.transport.recording.read_recording`) holds every message of a swarm's namespace,
byte for byte on its key, with log time = swarm time. :func:`load_recording` decodes, once, the messages of
the keys the live dashboard subscribes to (each vehicle's truth, estimate, guidance, vision and events, the
world's clock and events, the anchors, a TDoA radio's distance differences: :data:`DASHBOARD_KINDS`) with
the same :func:`~swarm.transport.messages.safe_decode`, and :class:`Timeline` feeds them to a
:class:`~dashboard.state.SwarmState` through :meth:`~dashboard.state.SwarmState.on_message`, the entry
point the live link uses: the scene and the panels are drawn from the same store by the same code, so
playback shows what live showed.

The state at time ``t`` is every message of log time ``<= t`` applied in log-time order. Forward (playing,
or a seek ahead) only the messages in between are applied. Backward (or forward past a checkpoint), the store
is restored from the latest **checkpoint** at or before ``t`` and the messages from there are applied: the
checkpoints (deep copies of the store every ``checkpoint_every`` messages, at most ``max_checkpoints`` of
them) are made in one pass over the whole recording when it is loaded, so a seek applies at most
``checkpoint_every`` messages, wherever it lands. Measured here on a 112 s lockstep docking (95 406
messages, 39 334 of them for the dashboard; 2 shared cores): reading the file 0.5 s, decoding 0.8 s, the
checkpoint pass 0.16 s (20 checkpoints, 0.2 ms each); then a seek anywhere 4 ms (median; 8 ms at most)
and a frame played at 10x ~0.5 ms.

Unlike live, where the dashboard samples the newest truth/estimate/guidance once per frame (Zenoh's
``RingChannel(1)``), playback applies every recorded sample: trails and plots hold the whole run at the
store's bounded density. Liveliness is not recorded (Zenoh's liveliness tokens are not samples of
``<ns>/**``): the process column reads ``unseen``.

:class:`Player` is the clock of the playback (play, pause, speed, seek; thread-safe, driven by the render
thread), :class:`PlaybackPanel` its Viser GUI: a time slider over the recording's swarm time, a play/pause
button and a speed choice.
"""

from __future__ import annotations

import ast
import bisect
import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from dashboard.state import SwarmState
from swarm.errors import ConfigError, LogError
from swarm.missions import DEFAULT_MISSION, MISSIONS, Mission, mission_of
from swarm.transport.keys import Keys
from swarm.transport.messages import (
    MESSAGE_FOR_KIND,
    Bundle,
    DropCounter,
    Message,
    TdoaBatch,
    VisionBatch,
    batch_rows,
    bundle_messages,
    safe_decode,
)

__all__ = [
    "DASHBOARD_KINDS",
    "SPEEDS",
    "PlaybackPanel",
    "Player",
    "Recording",
    "Timeline",
    "load_recording",
    "recorded_mission",
    "scenario_of",
]

_LOG = logging.getLogger("dashboard.playback")

DASHBOARD_KINDS = frozenset(
    {
        "truth",
        "estimate",
        "guidance",
        "vision",
        "world_vision",
        "event",
        "world_event",
        "world_clock",
        "anchors",
        "tdoa",
        "mothership_tdoa",
        "bundle",
    }
)
"""The key kinds (:meth:`swarm.transport.keys.Keys.parse`) the dashboard draws; the others (imu, uwb,
command, controls) are skipped. A ``world_vision`` batch (a swarm of agent hosts) is read as its frames,
each a ``vision`` of its vehicle, as the live dashboard reads it. A TDoA radio's distance differences
(``uwb.mode`` tdoa2/tdoa3: the Radio panel's rates, :mod:`dashboard.radio`) are read however they travelled,
as :class:`dashboard.link.SwarmLink` takes them: each ``tdoa`` of a vehicle, each entry of a
``mothership_tdoa`` batch (agent hosts), each ``Tdoa`` entry of a vehicle's lockstep ``bundle`` (a bundle's
other entries, imu and vision, are skipped), every one a ``tdoa`` item at its message's log time."""

SPEEDS: dict[str, float] = {"0.5x": 0.5, "1x": 1.0, "2x": 2.0, "5x": 5.0, "10x": 10.0, "50x": 50.0}
"""The playback speeds offered, as shown -> seconds of swarm time per second of wall time."""


@dataclass(frozen=True)
class Recording:
    """The dashboard's messages of one MCAP recording, decoded, in log-time order."""

    path: Path
    namespace: str
    items: tuple[tuple[str, str | None, Message], ...]
    """``(kind, agent_id, message)`` per recorded message the dashboard draws (:data:`DASHBOARD_KINDS`)."""
    times_ns: tuple[int, ...]
    """Log time (= swarm time) of each item [ns], non-decreasing."""
    metadata: dict[str, dict[str, str]]
    """The MCAP metadata by name (``recorder``; ``run_start`` and ``run_end`` of the world's run)."""
    dropped: int
    """Recorded payloads that did not decode (counted, as live, and skipped)."""

    @property
    def start_s(self) -> float:
        """Swarm time of the first item [s]."""
        return self.times_ns[0] / 1e9

    @property
    def end_s(self) -> float:
        """Swarm time of the last item [s]."""
        return self.times_ns[-1] / 1e9

    @property
    def scenario_name(self) -> str | None:
        """The scenario the world ran (its ``run_start`` event), None if the recording has no ``run_start``
        (the recorder subscribed after the run started)."""
        return self.metadata.get("run_start", {}).get("scenario") or None

    @property
    def uwb_mode(self) -> str | None:
        """The recorded radio (the Radio panel's, :mod:`dashboard.radio`): the ``uwb_mode`` its ``run_start``
        names if any, else ``"tdoa"`` (TDoA, its variant not known) if it holds distance differences, else
        None (the scenario's: two-way ranging unless ``--set uwb.mode=...``)."""
        named = self.metadata.get("run_start", {}).get("uwb_mode")
        if named in ("twr", "tdoa2", "tdoa3"):
            return named
        return "tdoa" if any(kind == "tdoa" for kind, _, _ in self.items) else None

    @property
    def vehicle_ids(self) -> tuple[str, ...] | None:
        """The world's vehicles (its ``run_start`` event, written as a Python list by the recorder)."""
        text = self.metadata.get("run_start", {}).get("vehicles")
        try:
            ids = ast.literal_eval(text) if text else None
        except (ValueError, SyntaxError):
            return None
        return tuple(str(v) for v in ids) if isinstance(ids, list | tuple) else None


def load_recording(path: str | Path, default_namespace: str = "tpods") -> Recording:
    """The dashboard's messages of the MCAP file at ``path``, under the swarm's key namespace the recorder
    wrote in its metadata (``recorder``; ``default_namespace`` if it did not). LogError naming the file (and
    the byte offset for a truncated or corrupt file, :func:`~swarm.transport.recording.read_recording`), or
    if nothing in it is for the dashboard."""
    from swarm.transport.recording import read_recording

    p = Path(path)
    messages, metadata = read_recording(p)
    ns = metadata.get("recorder", {}).get("namespace") or default_namespace
    keys = Keys(ns)
    drops = DropCounter()
    items: list[tuple[str, str | None, Message]] = []
    times: list[int] = []
    parsed: dict[str, tuple[str, str | None] | None] = {}
    for m in messages:
        if m.key not in parsed:
            parsed[m.key] = keys.parse(m.key)
        kind_id = parsed[m.key]
        if kind_id is None or kind_id[0] not in DASHBOARD_KINDS:
            continue
        kind, agent_id = kind_id
        msg = safe_decode(m.payload, MESSAGE_FOR_KIND[kind], m.key, drops)
        if msg is None:
            continue
        if isinstance(msg, VisionBatch | TdoaBatch):
            rows = batch_rows(msg, m.key, drops)
        elif isinstance(msg, Bundle):
            tdoa = bundle_messages(msg, m.key, drops, ("Tdoa",)) if "Tdoa" in msg.types else []
            rows = [(agent_id, t) for t in tdoa]
        else:
            rows = [(agent_id, msg)]
        row_kind = {"world_vision": "vision", "mothership_tdoa": "tdoa", "bundle": "tdoa"}.get(kind, kind)
        for vid, row in rows:
            items.append((row_kind, vid, row))
            times.append(m.log_time_ns)
    drops.flush()
    if not items:
        raise LogError(
            f"{p}: no message for the dashboard under namespace {ns!r} "
            f"({len(messages)} messages on {len(parsed)} keys)"
        )
    return Recording(p, ns, tuple(items), tuple(times), metadata, drops.total)


def recorded_mission(recording: Recording, scenario: str | None) -> Mission:
    """The mission to draw ``recording`` as: ``scenario``'s (a name or TOML file) if given, else the one
    its ``run_start`` names, else its recorded scenario's (:func:`swarm.missions.mission_of`). ConfigError
    for a recorded mission that is not registered."""
    recorded = recording.metadata.get("run_start", {}).get("mission")
    if scenario is None and recorded is not None:
        if recorded not in MISSIONS:
            raise ConfigError(
                f"{recording.path}: its run_start says mission = {recorded!r}, not a registered mission; "
                f"registered: {', '.join(sorted(MISSIONS))}"
            )
        return MISSIONS[recorded]
    return mission_of(scenario or recording.scenario_name or DEFAULT_MISSION)


def scenario_of(recording: Recording, scenario: str | None, overrides: dict | None = None):
    """The scenario to draw ``recording`` with: ``scenario`` (a name or TOML file) if given, else the one
    its ``run_start`` names (``docking`` if it has none, with a warning), loaded by its mission
    (:func:`recorded_mission`, :meth:`swarm.missions.Mission.playback_scenario`: a docking one is copied
    into as many pairs as the recorded vehicles are, ``swarm launch --agents N``). ConfigError if the
    recorded name is not a bundled scenario (a TOML file of the user's: pass it)."""
    name = scenario or recording.scenario_name
    if name is None:
        _LOG.warning("%s has no run_start (recorded after the run started): drawn as docking", recording.path)
        name = DEFAULT_MISSION
    try:
        mission = recorded_mission(recording, scenario)
        return mission.playback_scenario(name, overrides, recording.vehicle_ids)
    except ConfigError as exc:
        if scenario is None:
            raise ConfigError(
                f"{recording.path}: its scenario {name!r} cannot be loaded ({exc}); name its TOML file: "
                f"swarm dashboard SCENARIO --open {recording.path}"
            ) from None
        raise


class Timeline:
    """Brings ``state`` to any time of ``recording`` (module docstring). ``make_state`` makes an empty store
    like ``state`` was when given (the checkpoint pass runs on one). Use from one thread."""

    def __init__(
        self,
        recording: Recording,
        state: SwarmState,
        make_state: Callable[[], SwarmState],
        checkpoint_every: int = 2000,
        max_checkpoints: int = 50,
    ) -> None:
        if not (isinstance(checkpoint_every, int) and checkpoint_every >= 1):
            raise ValueError(f"checkpoint_every must be a positive integer, got {checkpoint_every!r}")
        self.recording = recording
        self.state = state
        self._items = recording.items
        self._times = recording.times_ns
        # memory: a checkpoint holds every vehicle's trail and series buffers (~70 kB a vehicle)
        checkpoint_every = max(checkpoint_every, -(-len(self._items) // max(1, max_checkpoints)))
        scratch = make_state()
        self._checkpoints: list[tuple[int, dict]] = []
        for i, (kind, agent_id, msg) in enumerate(self._items):
            if i % checkpoint_every == 0:
                self._checkpoints.append((i, scratch.checkpoint()))
            scratch.on_message(kind, agent_id, msg)
        self._checkpoint_index = [i for i, _ in self._checkpoints]
        self.cursor = 0
        """How many items ``state`` holds (the first ``cursor`` in log-time order)."""
        self.t_s = recording.start_s
        """The time ``state`` shows [s]."""
        self.seek(self.t_s)

    @property
    def checkpoints(self) -> int:
        return len(self._checkpoints)

    def index_at(self, t_s: float) -> int:
        """How many items have a log time ``<= t_s``."""
        return bisect.bisect_right(self._times, round(t_s * 1e9))

    def seek(self, t_s: float) -> bool:
        """Make ``state`` the recording at time ``t_s`` [s] (clamped to the recording); True if the store was
        restored from a checkpoint (a seek backward, or forward past a checkpoint: what was drawn must be
        drawn again)."""
        t_s = min(max(float(t_s), self.recording.start_s), self.recording.end_s)
        target = self.index_at(t_s)
        restored = False
        k = bisect.bisect_right(self._checkpoint_index, target) - 1
        if target < self.cursor or self._checkpoint_index[k] > self.cursor:
            start, cp = self._checkpoints[k]
            self.state.restore(cp)
            self.cursor = start
            restored = True
        for kind, agent_id, msg in self._items[self.cursor : target]:
            self.state.on_message(kind, agent_id, msg)
        self.cursor = target
        self.t_s = t_s
        return restored


class Player:
    """The playback clock: where in the recording the dashboard is, whether it plays and how fast.

    The GUI (Viser's threads) calls :meth:`play`, :meth:`pause`, :meth:`toggle`, :meth:`set_speed` and
    :meth:`seek`; the render thread calls :meth:`advance` once per frame, which moves the timeline to the
    time now: the last seek, plus the wall time since then times the speed while playing. Playing stops at
    the end of the recording; play from the end starts again from the beginning."""

    def __init__(self, timeline: Timeline, clock: Callable[[], float] = time.monotonic) -> None:
        self.timeline = timeline
        self.start_s = timeline.recording.start_s
        self.end_s = timeline.recording.end_s
        self._clock = clock
        self._lock = threading.Lock()
        self._playing = False
        self._speed = 1.0
        self._t0 = timeline.t_s
        """Playback time [s] at wall time ``_wall0``."""
        self._wall0 = clock()

    def _now(self) -> float:
        t = self._t0 + (self._clock() - self._wall0) * self._speed if self._playing else self._t0
        return min(max(t, self.start_s), self.end_s)

    def _anchor(self, t_s: float) -> None:
        self._t0, self._wall0 = t_s, self._clock()

    @property
    def playing(self) -> bool:
        with self._lock:
            return self._playing

    @property
    def speed(self) -> float:
        with self._lock:
            return self._speed

    def now_s(self) -> float:
        """The playback time now [s] (the timeline reaches it at the next :meth:`advance`)."""
        with self._lock:
            return self._now()

    def play(self) -> None:
        with self._lock:
            t = self._now()
            self._anchor(self.start_s if t >= self.end_s else t)
            self._playing = True

    def pause(self) -> None:
        with self._lock:
            self._anchor(self._now())
            self._playing = False

    def toggle(self) -> None:
        (self.pause if self.playing else self.play)()

    def set_speed(self, speed: float) -> None:
        if not (math.isfinite(speed) and speed > 0):
            raise ConfigError(f"playback speed must be a positive finite number, got {speed!r}")
        with self._lock:
            self._anchor(self._now())
            self._speed = float(speed)

    def seek(self, t_s: float) -> None:
        """Go to ``t_s`` [s] (clamped to the recording); playing goes on from there."""
        with self._lock:
            self._anchor(min(max(float(t_s), self.start_s), self.end_s))

    def advance(self) -> bool:
        """Move the timeline to the time now (render thread); True if its store was restored from a
        checkpoint (a backward seek)."""
        with self._lock:
            t = self._now()
            if self._playing and t >= self.end_s:
                self._anchor(self.end_s)
                self._playing = False
        if t == self.timeline.t_s:
            return False
        return self.timeline.seek(t)


class PlaybackPanel:
    """The Playback folder of the GUI: what is played, the time slider (swarm time [s]), Play/Pause and the
    speed. A slider moved in a browser seeks; while playing, the slider follows the playback."""

    def __init__(
        self, gui, player: Player, recording: Recording, speeds: Sequence[str] = tuple(SPEEDS)
    ) -> None:
        self.player = player
        start, end = recording.start_s, recording.end_s
        run = recording.metadata.get("run_start", {})
        what = f"**{recording.path.name}**"
        if run:
            what += " · " + " · ".join(f"{k} {run.get(k, '?')}" for k in ("scenario", "seed", "clock"))
        with gui.add_folder("Playback"):
            self.info = gui.add_markdown(f"{what}  \n{len(recording.items)} messages, {end - start:.2f} s")
            self.slider = gui.add_slider(
                "t [s]", min=round(start, 2), max=round(max(end, start + 0.01), 2), step=0.01,
                initial_value=round(start, 2),
            )  # fmt: skip
            self.button = gui.add_button("Play", color="green")
            self.speed = gui.add_dropdown("speed", tuple(speeds), initial_value="1x")
            self.time = gui.add_markdown("")

        @self.slider.on_update
        def _(event) -> None:
            if event.client is not None:  # a browser moved it (the render thread's own updates: no client)
                player.seek(float(self.slider.value))

        @self.button.on_click
        def _(_event) -> None:
            player.toggle()
            self.update()

        @self.speed.on_update
        def _(_event) -> None:
            player.set_speed(SPEEDS[str(self.speed.value)])

        self.update()

    def update(self) -> None:
        """Show the playback's time and state (the render thread, at the panel rate)."""
        p = self.player
        t = p.timeline.t_s
        playing = p.playing
        value = round(t, 2)
        if abs(float(self.slider.value) - value) > 0.005:
            self.slider.value = value
        label = "Pause" if playing else "Play"
        if self.button.label != label:
            self.button.label = label
            self.button.color = "yellow" if playing else "green"
        text = f"t = {t:.2f} s of {p.end_s:.2f} s · {'playing' if playing else 'paused'} at {p.speed:g}x"
        if self.time.content != text:
            self.time.content = text
