"""Lockstep bookkeeping of the distributed swarm: which messages make up tick ``k``, and when to step.

``docs/protocol.md`` section "Clocks and lockstep" is the contract, and
:meth:`swarm.sim.docking.DockingSim.run` the in-process tick order it reproduces:

- an agent processes tick ``k`` (``k = 1, 2, ...``, consecutive) once it has ``imu(k)``, ``uwb(k)`` on its
  UWB slots (``k % uwb_every == 0``) and, for a chaser, its target's ``estimate(k - 1)``. The world
  publishes ``vision(k)`` before ``imu(k)`` on one session and one wildcard subscriber delivers them in
  order, so ``imu(k)`` closes the world's part of tick ``k``: a vision frame of tick ``k`` arriving after
  it is late and not used (:class:`AgentTickAssembler`);
- the world steps to ``k + 1`` once every live agent's ``command(k)`` has arrived, or a timeout has passed
  (:class:`CommandBarrier`).

Both classes are pure logic (no Zenoh): Zenoh callbacks, each on its own thread, feed them decoded
messages; the process's main loop blocks on :meth:`AgentTickAssembler.next_tick` or
:meth:`CommandBarrier.wait`. Every method is thread-safe. Messages that do not fit (an old tick, a
duplicate, a tick too far ahead) are dropped and counted, never raised into a callback.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

from swarm.errors import ConfigError
from swarm.transport.keys import check_id
from swarm.transport.messages import Command, Estimate, Imu, Message, Uwb, Vision

__all__ = ["AgentTickAssembler", "CommandBarrier", "TickInputs"]

DEFAULT_MAX_AHEAD = 1000
"""Messages more than this many ticks ahead of the next expected tick are dropped (bounds memory)."""


def _check_timeout(timeout_s: float | None) -> float | None:
    if timeout_s is None:
        return None
    if not (isinstance(timeout_s, int | float) and timeout_s >= 0 and not math.isnan(timeout_s)):
        raise ConfigError(f"lockstep.timeout_s must be a number >= 0 or None, got {timeout_s!r}")
    return float(timeout_s)


def _check_int(value: object, name: str, lo: int) -> int:
    if not (isinstance(value, int) and not isinstance(value, bool) and value >= lo):
        raise ConfigError(f"lockstep.{name} must be an integer >= {lo}, got {value!r}")
    return value


def _wait(cond: threading.Condition, ready, timeout_s: float | None) -> bool:
    """``cond.wait_for(ready, timeout_s)`` (``cond`` held), on the monotonic clock."""
    if timeout_s is None:
        return cond.wait_for(ready)
    deadline = time.monotonic() + timeout_s
    while not ready():
        left = deadline - time.monotonic()
        if left <= 0:
            return False
        cond.wait(left)
    return True


@dataclass(frozen=True)
class TickInputs:
    """Everything one agent processes at tick ``k``, in the order of ``DockingSim.run``."""

    tick: int
    """Tick ``k`` (>= 1)."""
    imu: Imu
    """``imu(k)``: gyro (+ AHRS) sample."""
    vision: Vision | None = None
    """``vision(k)`` if the world published one (it arrives before ``imu(k)``), else ``None``."""
    uwb: Uwb | None = None
    """``uwb(k)`` on UWB slots (``k % uwb_every == 0``; its ``range_m`` is ``None`` when the reply was
    lost), ``None`` on other ticks."""
    target_estimate: Estimate | None = None
    """For a chaser, its target's estimate of tick ``k - 1``; ``None`` for a non-chaser."""


class _Frame:
    __slots__ = ("imu", "uwb", "vision")

    def __init__(self) -> None:
        self.imu: Imu | None = None
        self.uwb: Uwb | None = None
        self.vision: Vision | None = None


class AgentTickAssembler:
    """Collects one agent's sensor messages (and its target's estimates) into complete ticks.

    Feed it from the Zenoh callbacks with :meth:`add`; the agent's loop calls :meth:`next_tick`. Counters
    (read-only properties, cumulative across :meth:`reset`): ``stale`` (a tick already processed),
    ``duplicates`` (a second message of one kind for a pending tick; the first one is kept), ``future``
    (more than ``max_ahead`` ticks ahead), ``late`` (``vision(k)`` after ``imu(k)``), ``unexpected``
    (``uwb`` off the UWB slots, or a message from another vehicle than expected).
    """

    def __init__(
        self,
        agent_id: str,
        is_chaser: bool,
        target_id: str | None,
        uwb_every: int,
        max_ahead: int = DEFAULT_MAX_AHEAD,
    ) -> None:
        """``agent_id``: this vehicle; ``is_chaser``: whether each tick needs the target's estimate;
        ``target_id``: the target's agent id (required for a chaser); ``uwb_every``: ticks between two
        UWB slots of this vehicle (``uwb(k)`` is expected when ``k % uwb_every == 0``); ``max_ahead``:
        ticks beyond the next expected one that are still buffered."""
        self.agent_id = check_id(agent_id)
        self.is_chaser = bool(is_chaser)
        self.target_id = check_id(target_id, "target id") if (is_chaser or target_id is not None) else None
        self.uwb_every = _check_int(uwb_every, "uwb_every", 1)
        self.max_ahead = _check_int(max_ahead, "max_ahead", 0)
        self._cond = threading.Condition()
        self._next = 1  # the tick next_tick returns next
        self._base = 1  # first tick since construction / reset: imu arrived for every tick in [base, next)
        self._frames: dict[int, _Frame] = {}
        self._estimates: dict[int, Estimate] = {}  # by the estimate's own tick
        self._closed = False
        self._counts = dict.fromkeys(("stale", "duplicates", "future", "late", "unexpected"), 0)

    # ------------------------------------------------------------------------------ producers

    def add(self, msg: Message, source_id: str | None = None) -> bool:
        """Hand over one decoded message; ``True`` if it was kept for a tick, ``False`` if dropped (and
        counted). ``source_id`` is the vehicle of the message's key when known: it must be this agent
        for ``Imu``/``Uwb``/``Vision`` and the target for ``Estimate``. Never raises on a message."""
        with self._cond:
            if isinstance(msg, Estimate):
                kept = self._add_estimate(msg, source_id)
            elif isinstance(msg, Imu | Uwb | Vision):
                kept = self._add_sensor(msg, source_id)
            else:
                self._counts["unexpected"] += 1
                return False
            if kept:
                self._cond.notify_all()
            return kept

    def _add_estimate(self, msg: Estimate, source_id: str | None) -> bool:
        if not self.is_chaser or (source_id is not None and source_id != self.target_id):
            self._counts["unexpected"] += 1
            return False
        k = msg.tick + 1  # the tick that uses it
        if k < self._next:
            self._counts["stale"] += 1
            return False
        if k > self._next + self.max_ahead:
            self._counts["future"] += 1
            return False
        if msg.tick in self._estimates:
            self._counts["duplicates"] += 1
            return False
        self._estimates[msg.tick] = msg
        return True

    def _add_sensor(self, msg: Imu | Uwb | Vision, source_id: str | None) -> bool:
        k = msg.tick
        if source_id is not None and source_id != self.agent_id:
            self._counts["unexpected"] += 1
            return False
        if k < self._next:
            # imu(k) was consumed for every tick in [base, next): a vision frame there came after it
            late = isinstance(msg, Vision) and k >= self._base
            self._counts["late" if late else "stale"] += 1
            return False
        if k > self._next + self.max_ahead:
            self._counts["future"] += 1
            return False
        if isinstance(msg, Uwb) and k % self.uwb_every:
            self._counts["unexpected"] += 1
            return False
        frame = self._frames.get(k)
        if frame is None:
            frame = self._frames[k] = _Frame()
        if isinstance(msg, Imu):
            slot = "imu"
        elif isinstance(msg, Uwb):
            slot = "uwb"
        else:
            slot = "vision"
            if frame.imu is not None:  # imu(k) closed the world's part of tick k
                self._counts["late"] += 1
                return False
        if getattr(frame, slot) is not None:
            self._counts["duplicates"] += 1
            return False
        setattr(frame, slot, msg)
        return True

    # ------------------------------------------------------------------------------ consumer

    def _missing(self) -> list[str]:
        k = self._next
        frame = self._frames.get(k)
        out = []
        if frame is None or frame.imu is None:
            out.append("imu")
        if k % self.uwb_every == 0 and (frame is None or frame.uwb is None):
            out.append("uwb")
        if self.is_chaser and (k - 1) not in self._estimates:
            out.append("estimate")
        return out

    def next_tick(self, timeout_s: float | None = None) -> TickInputs | None:
        """Block until tick ``k`` (the next expected) is complete and return its inputs, advancing to
        ``k + 1``; ``None`` if ``timeout_s`` [s] passed first (``None``: wait forever) or after
        :meth:`close`, consuming nothing."""
        timeout_s = _check_timeout(timeout_s)
        with self._cond:
            if not _wait(self._cond, lambda: self._closed or not self._missing(), timeout_s):
                return None
            if self._closed:
                return None
            k = self._next
            frame = self._frames.pop(k)
            est = self._estimates.pop(k - 1, None)
            self._next = k + 1
            return TickInputs(tick=k, imu=frame.imu, vision=frame.vision, uwb=frame.uwb, target_estimate=est)

    def reset(self, k: int) -> None:
        """Resynchronise (this agent restarted mid-run): the next tick returned is ``k`` (>= 1); buffered
        messages of earlier ticks (estimates of ticks before ``k - 1``) are discarded."""
        k = _check_int(k, "tick", 1)
        with self._cond:
            self._next = self._base = k
            self._frames = {t: f for t, f in self._frames.items() if t >= k}
            self._estimates = {t: e for t, e in self._estimates.items() if t >= k - 1}
            self._cond.notify_all()

    def close(self) -> None:
        """Wake every :meth:`next_tick` (they return ``None``), e.g. at shutdown."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    # ------------------------------------------------------------------------------ state

    @property
    def next_expected(self) -> int:
        """The tick :meth:`next_tick` returns next."""
        with self._cond:
            return self._next

    def waiting_for(self) -> list[str]:
        """What the next tick still lacks, among ``"imu"``, ``"uwb"``, ``"estimate"`` (for a timeout log)."""
        with self._cond:
            return self._missing()

    def counts(self) -> dict[str, int]:
        """A snapshot of the drop counters."""
        with self._cond:
            return dict(self._counts)

    @property
    def stale(self) -> int:
        """Messages of ticks already processed (or skipped by :meth:`reset`)."""
        return self.counts()["stale"]

    @property
    def duplicates(self) -> int:
        """Second messages of one kind for one pending tick (the first is kept)."""
        return self.counts()["duplicates"]

    @property
    def future(self) -> int:
        """Messages more than ``max_ahead`` ticks ahead of the next expected tick."""
        return self.counts()["future"]

    @property
    def late(self) -> int:
        """``vision(k)`` frames that arrived after ``imu(k)`` (not part of tick ``k``)."""
        return self.counts()["late"]

    @property
    def unexpected(self) -> int:
        """``uwb`` off this vehicle's UWB slots, messages of another vehicle, other message types."""
        return self.counts()["unexpected"]


class CommandBarrier:
    """The world's side of the lockstep: waits for every live agent's ``command(k)`` before stepping.

    :meth:`add` (from the Zenoh callbacks) records commands; :meth:`wait` (the world's loop) returns when
    every live agent's command of tick ``k`` is in or the timeout passed, listing the missing agents (the
    world logs them and holds their previous command). Counters: ``stale`` (a tick already released),
    ``duplicates`` (the first command of an agent and tick is kept), ``future`` (more than ``max_ahead``
    ticks ahead), ``unknown`` (an agent id not given at construction).
    """

    def __init__(self, agent_ids, max_ahead: int = DEFAULT_MAX_AHEAD) -> None:
        """``agent_ids``: every agent that may send commands, all live at first; ``max_ahead``: ticks
        beyond the next one waited for that are still buffered."""
        ids = tuple(check_id(a) for a in agent_ids)
        if len(set(ids)) != len(ids):
            raise ConfigError(f"lockstep.agent_ids must be distinct, got {ids!r}")
        self.agent_ids = ids
        self.max_ahead = _check_int(max_ahead, "max_ahead", 0)
        self._cond = threading.Condition()
        self._live = frozenset(ids)
        self._floor = 0  # commands of ticks below it were released (or skipped)
        self._commands: dict[int, dict[str, Command]] = {}
        self._counts = dict.fromkeys(("stale", "duplicates", "future", "unknown"), 0)

    def add(self, agent_id: str, cmd: Command) -> bool:
        """Record ``command(k)`` of ``agent_id``; ``True`` if kept, ``False`` if dropped (and counted)."""
        with self._cond:
            if agent_id not in self.agent_ids:
                self._counts["unknown"] += 1
                return False
            k = cmd.tick
            if k < self._floor:
                self._counts["stale"] += 1
                return False
            if k > self._floor + self.max_ahead:
                self._counts["future"] += 1
                return False
            tick = self._commands.setdefault(k, {})
            if agent_id in tick:
                self._counts["duplicates"] += 1
                return False
            tick[agent_id] = cmd
            self._cond.notify_all()
            return True

    def set_live(self, ids) -> None:
        """The agents whose commands :meth:`wait` waits for (after a liveliness change): a subset of
        ``agent_ids``. Shrinking the set releases a wait that only lacked the removed agents."""
        live = frozenset(ids)
        unknown = sorted(live - set(self.agent_ids))
        if unknown:
            raise ConfigError(f"lockstep.live ids must be among {self.agent_ids}, got unknown {unknown}")
        with self._cond:
            self._live = live
            self._cond.notify_all()

    @property
    def live(self) -> frozenset[str]:
        """The agents waited for."""
        with self._cond:
            return self._live

    def wait(self, k: int, timeout_s: float | None = None) -> tuple[dict[str, Command], list[str]]:
        """Block until every live agent's ``command(k)`` arrived or ``timeout_s`` [s] passed (``None``:
        forever). Returns ``(commands, missing)``: the commands of tick ``k`` by agent id (live or not),
        and the live agents without one, in ``agent_ids`` order. Releases tick ``k``: later commands of
        ticks ``<= k`` are stale."""
        k = _check_int(k, "tick", 0)
        timeout_s = _check_timeout(timeout_s)
        with self._cond:
            if k < self._floor:
                raise ConfigError(f"lockstep.tick {k} was already released (next is {self._floor})")

            def complete() -> bool:
                return self._live <= self._commands.get(k, {}).keys()

            _wait(self._cond, complete, timeout_s)
            commands = self._commands.pop(k, {})
            missing = [a for a in self.agent_ids if a in self._live and a not in commands]
            self._floor = k + 1
            self._commands = {t: c for t, c in self._commands.items() if t > k}
            return commands, missing

    def reset(self, k: int = 0) -> None:
        """Start over at tick ``k`` (a new run): buffered commands are discarded."""
        k = _check_int(k, "tick", 0)
        with self._cond:
            self._floor = k
            self._commands = {}
            self._cond.notify_all()

    def counts(self) -> dict[str, int]:
        """A snapshot of the drop counters."""
        with self._cond:
            return dict(self._counts)

    @property
    def stale(self) -> int:
        """Commands of ticks already released."""
        return self.counts()["stale"]

    @property
    def duplicates(self) -> int:
        """Second commands of one agent for one tick."""
        return self.counts()["duplicates"]

    @property
    def future(self) -> int:
        """Commands more than ``max_ahead`` ticks ahead."""
        return self.counts()["future"]

    @property
    def unknown(self) -> int:
        """Commands of agents not in ``agent_ids``."""
        return self.counts()["unknown"]
