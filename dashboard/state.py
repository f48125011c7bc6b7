"""What the dashboard knows about the swarm: the latest message of each kind per vehicle, trails, time
series, events and liveliness, in one thread-safe store (:class:`SwarmState`), plus the bounded buffers
and the pacing logic the render loop uses. No Viser, no Zenoh.

Writers are Zenoh callback threads (events, anchors, liveliness, every TDoA slot) and the render thread
(the latest truth, estimate, guidance, vision and clock samples, polled from ring channels); the render
thread reads a :class:`Snapshot` once per frame. Every buffer is bounded, so memory stays flat over an
hour-long run: trails and series keep at most ``cap`` samples, thinning the whole history by half when full
(:class:`Trail`, :class:`Series`); the event log and mode timelines are fixed-length deques; the radio's
rates keep a window of swarm time (:mod:`dashboard.radio`).
"""

from __future__ import annotations

import copy
import math
import threading
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from dashboard.radio import RadioRates, RadioSnap
from swarm.transport.messages import Anchors, Clock, Estimate, Event, Guidance, Message, Tdoa, Truth, Vision

__all__ = [
    "AgentSnap",
    "AgentView",
    "FramePacer",
    "RateLimiter",
    "Series",
    "Snapshot",
    "SwarmState",
    "Trail",
    "is_new_run",
]

ALIVE, LOST, UNSEEN = "alive", "lost", "unseen"
"""Liveliness of a process as the dashboard shows it: token present, token gone, never seen."""


class Trail:
    """A vehicle's path: positions at least ``min_step_m`` apart, at most ``cap`` of them, ending at the
    newest position (the last point moves with the vehicle until it is ``min_step_m`` from the one before).

    When full, every other point is dropped (the newest kept) and the spacing doubles, so the trail covers
    the whole run at a uniform density in bounded memory: ``cap * 3`` floats, whatever the run's length.
    ``version`` changes whenever the points do (for the renderer's change detection).
    """

    def __init__(self, cap: int = 1000, min_step_m: float = 0.002) -> None:
        if not (isinstance(cap, int) and cap >= 4):
            raise ValueError(f"trail cap must be an integer >= 4, got {cap!r}")
        if not (math.isfinite(min_step_m) and min_step_m >= 0.0):
            raise ValueError(f"trail min_step_m must be finite and >= 0, got {min_step_m!r}")
        self.cap = cap
        self.base_step_m = float(min_step_m)
        self.min_step_m = float(min_step_m)
        self._buf = np.empty((cap, 3))
        self._n = 0
        self.version = 0

    def __len__(self) -> int:
        return self._n

    def add(self, p_nav: np.ndarray) -> bool:
        """Make ``p_nav`` (3,) [m] the trail's end: a new point if the current end is ``min_step_m`` or more
        from the point before it, else the end moves there. True if the trail changed."""
        p = np.asarray(p_nav, dtype=np.float64).reshape(3)
        n = self._n
        if n and np.array_equal(p, self._buf[n - 1]):
            return False
        if n >= 2 and float(np.linalg.norm(self._buf[n - 1] - self._buf[n - 2])) < self.min_step_m:
            self._buf[n - 1] = p
            self.version += 1
            return True
        if self._n == self.cap:
            keep = self._buf[self._n - 1 :: -2][::-1].copy()  # every other point, ending at the newest
            self._n = len(keep)
            self._buf[: self._n] = keep
            self.min_step_m = max(2.0 * self.min_step_m, 1e-6)
        self._buf[self._n] = p
        self._n += 1
        self.version += 1
        return True

    def points(self) -> np.ndarray:
        """The points (N, 3) [m], oldest first (a copy)."""
        return self._buf[: self._n].copy()

    def clear(self) -> None:
        """Forget every point (a new run)."""
        self._n = 0
        self.min_step_m = self.base_step_m
        self.version += 1


class Series:
    """Time series of ``width`` values, samples at least ``min_dt_s`` apart, at most ``cap`` of them, ending
    at the newest sample (the last one is replaced until it is ``min_dt_s`` after the one before); when
    full, every other sample is dropped and the spacing doubles (like :class:`Trail`). A value may be NaN
    (not available: uPlot draws a gap)."""

    def __init__(self, width: int, cap: int = 600, min_dt_s: float = 0.05) -> None:
        if not (isinstance(cap, int) and cap >= 4 and isinstance(width, int) and width >= 1):
            raise ValueError(f"series needs integer cap >= 4 and width >= 1, got {cap!r}, {width!r}")
        self.cap = cap
        self.base_dt_s = float(min_dt_s)
        self.min_dt_s = float(min_dt_s)
        self._t = np.empty(cap)
        self._v = np.empty((cap, width))
        self._n = 0
        self.version = 0

    def __len__(self) -> int:
        return self._n

    def add(self, t_s: float, values: Iterable[float | None]) -> bool:
        """Make ``(t_s, values)`` the newest sample (``None`` values become NaN): appended if the current last
        sample is ``min_dt_s`` or more after the one before it, else it replaces the last. A time earlier
        than the last one restarts the series (a new run). True if the series changed."""
        row = np.array([np.nan if v is None else float(v) for v in values])
        n = self._n
        if n and t_s < self._t[n - 1]:
            self.clear()
            n = 0
        if n and t_s == self._t[n - 1] and np.array_equal(row, self._v[n - 1], equal_nan=True):
            return False
        if n >= 2 and self._t[n - 1] - self._t[n - 2] < self.min_dt_s:
            self._t[n - 1], self._v[n - 1] = t_s, row
            self.version += 1
            return True
        if self._n == self.cap:
            idx = np.arange(self._n - 1, -1, -2)[::-1]
            self._t[: len(idx)], self._v[: len(idx)] = self._t[idx], self._v[idx]
            self._n = len(idx)
            self.min_dt_s *= 2.0
        self._t[self._n], self._v[self._n] = t_s, row
        self._n += 1
        self.version += 1
        return True

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """``(t (N,), values (N, width))``, copies."""
        return self._t[: self._n].copy(), self._v[: self._n].copy()

    def clear(self) -> None:
        self._n = 0
        self.min_dt_s = self.base_dt_s
        self.version += 1


class RateLimiter:
    """``due()`` is true at most ``hz`` times per second of ``clock`` (a monotonic clock in seconds)."""

    def __init__(self, hz: float, clock: Callable[[], float]) -> None:
        if not (math.isfinite(hz) and hz > 0):
            raise ValueError(f"rate must be a positive finite number of Hz, got {hz!r}")
        self.period_s = 1.0 / hz
        self._clock = clock
        self._next = -math.inf

    def due(self) -> bool:
        now = self._clock()
        if now < self._next:
            return False
        self._next = now + self.period_s
        return True


class FramePacer:
    """How long the render loop sleeps after a frame: at least what keeps it at ``max_hz`` or less, and at
    least what keeps its share of a core at ``max_busy`` or less, so that a heavy frame (many vehicles on
    a loaded machine) lowers the frame rate instead of starving the swarm's processes.

    ``delay(frame_s) = max(1 / max_hz - frame_s, frame_s * (1 / max_busy - 1), 0)``.
    """

    def __init__(self, max_hz: float = 30.0, max_busy: float = 0.5) -> None:
        if not (math.isfinite(max_hz) and max_hz > 0):
            raise ValueError(f"max_hz must be a positive finite number, got {max_hz!r}")
        if not (0.0 < max_busy <= 1.0):
            raise ValueError(f"max_busy must be in (0, 1], got {max_busy!r}")
        self.max_hz = float(max_hz)
        self.max_busy = float(max_busy)

    def delay(self, frame_s: float) -> float:
        return max(1.0 / self.max_hz - frame_s, frame_s * (1.0 / self.max_busy - 1.0), 0.0)


def is_new_run(previous: Clock | None, clock: Clock) -> bool:
    """Whether ``clock`` starts a new run after ``previous``: another seed, or the tick went back (a reset,
    or the world restarted)."""
    return previous is not None and (clock.seed != previous.seed or clock.tick < previous.tick)


@dataclass
class AgentView:
    """Everything known about one vehicle (mutable; owned by :class:`SwarmState`, read through snapshots)."""

    agent_id: str
    role: str
    """``chaser``, ``target``, or ``?`` for a vehicle that is not in the scenario."""
    target: str | None
    truth: Truth | None = None
    estimate: Estimate | None = None
    guidance: Guidance | None = None
    vision_t_s: float | None = None
    """Time of the latest camera frame with markers."""
    vision_rows: int | None = None
    """Rows (detected markers, or a landing pad's marker corners) of the latest camera frame; None before
    the first."""
    alive: str = UNSEEN
    truth_trail: Trail = field(default_factory=Trail)
    estimate_trail: Trail = field(default_factory=Trail)
    modes: deque = field(default_factory=lambda: deque(maxlen=200))
    """Mode timeline: ``(t_s, mode, range_m, reason)``, a new entry for each change."""
    radii: Series = field(default_factory=lambda: Series(4))
    """``t_s`` -> ``(range_m, r1_m, r2_m, r_t_m)``."""

    def latest_t_s(self) -> float | None:
        ts = [m.t_s for m in (self.truth, self.estimate, self.guidance) if m is not None]
        return max(ts) if ts else None

    def note_mode(self, t_s: float, mode: str, range_m: float | None, reason: str) -> None:
        if not self.modes or self.modes[-1][1] != mode:
            self.modes.append((t_s, mode, range_m, reason))

    def clear_run(self) -> None:
        self.truth_trail.clear()
        self.estimate_trail.clear()
        self.modes.clear()
        self.radii.clear()
        self.vision_t_s = None
        self.vision_rows = None
        self.truth = self.estimate = self.guidance = None


@dataclass(frozen=True)
class AgentSnap:
    """One vehicle in a :class:`Snapshot`: messages are immutable, arrays are copies."""

    agent_id: str
    role: str
    target: str | None
    truth: Truth | None
    estimate: Estimate | None
    guidance: Guidance | None
    vision_t_s: float | None
    alive: str
    truth_trail: np.ndarray | None
    """(N, 3) points if the trail changed since the caller's ``trail_versions``, else ``None``."""
    estimate_trail: np.ndarray | None
    trail_versions: tuple[int, int]
    modes: tuple[tuple[float, str, float | None, str], ...]
    radii_t: np.ndarray
    radii_v: np.ndarray
    radii_version: int
    vision_rows: int | None = None
    """Rows of the latest camera frame (:attr:`AgentView.vision_rows`)."""

    def latest_t_s(self) -> float | None:
        """The latest swarm time [s] heard from this vehicle (truth, estimate or guidance)."""
        ts = [m.t_s for m in (self.truth, self.estimate, self.guidance) if m is not None]
        return max(ts) if ts else None


@dataclass(frozen=True)
class Snapshot:
    """The swarm as the render thread sees it for one frame."""

    agents: dict[str, AgentSnap]
    clock: Clock | None
    run: int
    """Number of new runs seen (reset, new seed, world restarted): the renderer clears what it drew."""
    processes: dict[tuple[str, str], str]
    """Liveliness of every process seen, ``(role, id) -> alive/lost``."""
    anchors: tuple[tuple[int, ...], np.ndarray]
    anchors_version: int
    events: tuple[tuple[str, Event], ...]
    """Newest last: ``(agent_id, event)``; run events under the id ``world``, UWB network events under
    ``mothership``."""
    events_version: int
    faults: tuple[tuple[str, Event], ...] = ()
    """Run-time faults applied (``fault``) or refused (``fault_refused``), newest last: ``(source,
    event)`` with source ``world`` or ``mothership``."""
    faults_version: int = 0
    clock_mode: str | None = None
    """The world's clock (``lockstep``, ``realtime``, ``scaled:N``) from its latest ``run_start``; None
    before the dashboard saw one."""
    radio: RadioSnap | None = None
    """The radio's rates (:mod:`dashboard.radio`), when the frame asked for them (the panels' frames)."""


class SwarmState:
    """Thread-safe latest-value store of the swarm (module docstring). ``vehicles`` maps each scenario
    vehicle id to ``(role, target)``; vehicles not in it are added as they appear (role ``?``).
    ``uwb_mode`` (the scenario's ``uwb.mode``) and ``rate_window_s`` set the radio's rates
    (:class:`~dashboard.radio.RadioRates`)."""

    def __init__(
        self,
        vehicles: Mapping[str, tuple[str, str | None]],
        anchors_nav: np.ndarray,
        trail_cap: int = 1000,
        trail_step_m: float = 0.002,
        series_cap: int = 600,
        events_cap: int = 100,
        faults_cap: int = 20,
        max_agents: int = 256,
        uwb_mode: str = "twr",
        rate_window_s: float = 2.0,
    ) -> None:
        self._lock = threading.Lock()
        self._trail = (trail_cap, trail_step_m)
        self._series_cap = series_cap
        self._max_agents = max_agents
        self.agents: dict[str, AgentView] = {}
        self._new_agents: list[str] = []
        for agent_id, (role, target) in vehicles.items():
            self._add(agent_id, role, target)
        a = np.asarray(anchors_nav, dtype=np.float64).reshape(-1, 3)
        self._anchors: tuple[tuple[int, ...], np.ndarray] = (tuple(range(len(a))), a)
        self._anchors_version = 0
        self.clock: Clock | None = None
        self.run = 0
        self._processes: dict[tuple[str, str], str] = {}
        self._events: deque[tuple[str, Event]] = deque(maxlen=events_cap)
        self._events_version = 0
        self._faults: deque[tuple[str, Event]] = deque(maxlen=faults_cap)
        self._faults_version = 0
        self.clock_mode: str | None = None
        self.radio = RadioRates(uwb_mode, rate_window_s, max_agents)

    def _add(self, agent_id: str, role: str, target: str | None) -> AgentView | None:
        if agent_id in self.agents:
            return self.agents[agent_id]
        if len(self.agents) >= self._max_agents:  # a flood of invented ids cannot grow memory
            return None
        view = AgentView(
            agent_id,
            role,
            target,
            truth_trail=Trail(*self._trail),
            estimate_trail=Trail(*self._trail),
            radii=Series(4, self._series_cap),
        )
        self.agents[agent_id] = view
        self._new_agents.append(agent_id)
        return view

    def take_new_agents(self) -> list[str]:
        """Vehicles added since the last call (the Zenoh side subscribes to their topics)."""
        with self._lock:
            out, self._new_agents = self._new_agents, []
        return out

    # ---------------------------------------------------------------------------------- writers

    def on_truth(self, agent_id: str, msg: Truth) -> None:
        with self._lock:
            view = self._add(agent_id, "?", None)
            if view is None:
                return
            if view.truth is not None and msg.t_s < view.truth.t_s:
                view.truth_trail.clear()
            view.truth = msg
            view.truth_trail.add(msg.p_nav)

    def on_estimate(self, agent_id: str, msg: Estimate) -> None:
        with self._lock:
            view = self._add(agent_id, "?", None)
            if view is None:
                return
            if view.estimate is not None and msg.t_s < view.estimate.t_s:
                view.estimate_trail.clear()
            view.estimate = msg
            view.estimate_trail.add(msg.p_nav)
            self.radio.on_counts(agent_id, msg.t_s, msg.counts)

    def on_tdoa(self, agent_id: str, msg: Tdoa) -> None:
        """A tag's distance differences of one UWB slot (every one heard counts: the anchors' and the tags'
        rates, :class:`~dashboard.radio.RadioRates`)."""
        with self._lock:
            if self._add(agent_id, "?", None) is not None:
                self.radio.on_tdoa(agent_id, msg)

    def on_guidance(self, agent_id: str, msg: Guidance) -> None:
        with self._lock:
            view = self._add(agent_id, "?", None)
            if view is None:
                return
            if view.guidance is not None and msg.t_s < view.guidance.t_s:
                view.modes.clear()
            view.guidance = msg
            view.note_mode(msg.t_s, msg.mode, msg.range_m, msg.reason)
            view.radii.add(msg.t_s, (msg.range_m, msg.r1_m, msg.r2_m, msg.r_t_m))

    def on_vision(self, agent_id: str, msg: Vision) -> None:
        """A camera frame: its time if it measured markers (a camera reports every frame, docs/protocol.md
        "Vision": a frame without a marker says only that the camera works), and its number of rows."""
        with self._lock:
            view = self._add(agent_id, "?", None)
            if view is None:
                return
            view.vision_rows = len(msg.marker_ids)
            if len(msg.marker_ids) > 0:
                view.vision_t_s = msg.t_s

    def on_event(self, agent_id: str, msg: Event) -> None:
        with self._lock:
            self._events.append((agent_id, msg))
            self._events_version += 1
            view = self.agents.get(agent_id)
            if view is not None and msg.kind == "mode" and isinstance(msg.data.get("to"), str):
                rng = msg.data.get("range_m")
                reason = msg.data.get("reason")
                view.note_mode(
                    msg.t_s,
                    msg.data["to"],
                    float(rng) if isinstance(rng, int | float) else None,
                    reason if isinstance(reason, str) else "",
                )

    def on_run_event(self, source: str, msg: Event) -> None:
        """An event of the run (``world/event``, ``source`` ``world``): into the event log; a fault applied
        or refused also into the fault log; a ``run_start`` names the world's clock."""
        with self._lock:
            self._events.append((source, msg))
            self._events_version += 1
            if msg.kind in ("fault", "fault_refused"):
                self._faults.append((source, msg))
                self._faults_version += 1
            elif msg.kind == "run_start" and isinstance(msg.data.get("clock"), str):
                self.clock_mode = msg.data["clock"]

    def on_clock(self, msg: Clock) -> bool:
        """Store the world's clock; True (and every vehicle's run data cleared) if it starts a new run."""
        with self._lock:
            new = is_new_run(self.clock, msg)
            if new:
                self.run += 1
                for view in self.agents.values():
                    view.clear_run()
                self.radio.clear()
            self.clock = msg
            return new

    def on_anchors(self, msg: Anchors) -> None:
        with self._lock:
            self._anchors = (tuple(msg.anchor_ids), msg.positions_nav.copy())
            self._anchors_version += 1

    def on_liveliness(self, role: str, process_id: str, alive: bool) -> str | None:
        """Record a token appearing (``alive``) or going; returns the new state if it changed."""
        with self._lock:
            key = (role, process_id)
            before = self._processes.get(key, UNSEEN)
            after = ALIVE if alive else (LOST if before != UNSEEN else UNSEEN)
            if after == UNSEEN:
                return None
            if len(self._processes) >= 4 * self._max_agents and key not in self._processes:
                return None
            self._processes[key] = after
            if role == "agent":
                view = self._add(process_id, "?", None)
                if view is not None:
                    view.alive = after
            return after if after != before else None

    def on_message(self, kind: str, agent_id: str | None, msg: Message) -> bool:
        """One decoded message into the store, by the kind of its key
        (:meth:`swarm.transport.keys.Keys.parse`: ``truth``, ``estimate``, ``guidance``, ``vision``,
        ``tdoa`` and ``event`` of vehicle ``agent_id``; ``world_event``, ``world_clock``, ``anchors``): the
        one entry point of the live link (:mod:`dashboard.link`) and of a recording's playback
        (:mod:`dashboard.playback`), so that playback shows what live shows. Other kinds are ignored. True if
        the message is a clock that starts a new run."""
        if agent_id is not None:
            if kind == "truth":
                self.on_truth(agent_id, msg)  # type: ignore[arg-type]
            elif kind == "estimate":
                self.on_estimate(agent_id, msg)  # type: ignore[arg-type]
            elif kind == "guidance":
                self.on_guidance(agent_id, msg)  # type: ignore[arg-type]
            elif kind == "vision":
                self.on_vision(agent_id, msg)  # type: ignore[arg-type]
            elif kind == "tdoa":
                self.on_tdoa(agent_id, msg)  # type: ignore[arg-type]
            elif kind == "event":
                self.on_event(agent_id, msg)  # type: ignore[arg-type]
        elif kind == "world_clock":
            return self.on_clock(msg)  # type: ignore[arg-type]
        elif kind == "world_event":
            self.on_run_event("world", msg)  # type: ignore[arg-type]
        elif kind == "anchors":
            self.on_anchors(msg)  # type: ignore[arg-type]
        return False

    def checkpoint(self) -> dict:
        """A deep copy of everything the store holds, for :meth:`restore` (a playback's seek)."""
        with self._lock:
            data = {k: v for k, v in self.__dict__.items() if k != "_lock"}
            return copy.deepcopy(data, _immutable_memo(data))

    def restore(self, checkpoint: dict) -> None:
        """Make the store what it was at :meth:`checkpoint` (which stays usable for another restore)."""
        data = copy.deepcopy(checkpoint, _immutable_memo(checkpoint))
        with self._lock:
            self.__dict__.update(data)

    def clear_trails(self) -> None:
        with self._lock:
            for view in self.agents.values():
                view.truth_trail.clear()
                view.estimate_trail.clear()

    # ---------------------------------------------------------------------------------- reader

    def snapshot(
        self, trail_versions: Mapping[str, tuple[int, int]] | None = None, radio: bool = False
    ) -> Snapshot:
        """A consistent copy for one frame. Trails are copied only for vehicles whose ``(truth, estimate)``
        trail versions differ from ``trail_versions`` (what the caller last drew); the radio's rates only
        with ``radio`` (a panel frame)."""
        seen = trail_versions or {}
        with self._lock:
            now = self.clock.t_s if self.clock is not None else None
            agents = {}
            for agent_id, v in self.agents.items():
                versions = (v.truth_trail.version, v.estimate_trail.version)
                changed = seen.get(agent_id) != versions
                rt, rv = v.radii.arrays()
                agents[agent_id] = AgentSnap(
                    agent_id=agent_id,
                    role=v.role,
                    target=v.target,
                    truth=v.truth,
                    estimate=v.estimate,
                    guidance=v.guidance,
                    vision_t_s=v.vision_t_s,
                    alive=v.alive,
                    truth_trail=v.truth_trail.points() if changed else None,
                    estimate_trail=v.estimate_trail.points() if changed else None,
                    trail_versions=versions,
                    modes=tuple(v.modes),
                    radii_t=rt,
                    radii_v=rv,
                    radii_version=v.radii.version,
                    vision_rows=v.vision_rows,
                )
            return Snapshot(
                agents=agents,
                clock=self.clock,
                run=self.run,
                processes=dict(self._processes),
                anchors=(self._anchors[0], self._anchors[1].copy()),
                anchors_version=self._anchors_version,
                events=tuple(self._events),
                events_version=self._events_version,
                faults=tuple(self._faults),
                faults_version=self._faults_version,
                clock_mode=self.clock_mode,
                radio=self.radio.snapshot(self._anchors[0], now) if radio else None,
            )


def _immutable_memo(data: dict) -> dict[int, object]:
    """A ``deepcopy`` memo that shares the messages (frozen, never changed after decoding) instead of copying
    them: a checkpoint copies only the store's own containers."""
    memo: dict[int, object] = {}

    def share(value: object) -> None:
        if isinstance(value, Message):
            memo[id(value)] = value

    for view in data.get("agents", {}).values():
        for msg in (view.truth, view.estimate, view.guidance):
            share(msg)
    for name in ("clock", "_events", "_faults"):
        value = data.get(name)
        if isinstance(value, deque):
            for _, ev in value:
                share(ev)
        else:
            share(value)
    return memo
