"""Lockstep bookkeeping of the distributed swarm: which messages make up tick ``k``, and when to step.

``docs/protocol.md`` section "Clocks and lockstep" is the contract, and
:meth:`swarm.sim.docking.DockingSim.run` the in-process tick order it reproduces:

- an agent processes tick ``k`` once it has ``imu(k)``, ``uwb(k)`` (or ``tdoa(k)``, ``uwb.mode``
  tdoa2/tdoa3) on its UWB slots
  (``k % uwb_every == 0``; on a TDMA channel only those with its tag's exchange), ``vision(k)`` on its
  camera slots (``k % vision_every == 0``; the camera reports every frame, with zero markers when it saw
  none) and, for a chaser, its target's ``estimate(k - 1)``
  (``estimate(0)`` at ticks 0 and 1). Tick 0 has no sensor samples: the agent only publishes its initial
  estimate and command. Every input of a tick is *expected*, so the tick is complete whatever the order
  in which Zenoh's callback threads deliver them (:class:`AgentTickAssembler`);
- the world steps to ``k + 1`` once every live agent's ``command(k)`` has arrived, or a timeout has passed
  (:class:`CommandBarrier`).

Both classes are pure logic (no Zenoh): Zenoh callbacks feed them decoded messages; the agent host's loop
polls its vehicles' assemblers (:meth:`AgentTickAssembler.poll`, waiting on their shared condition), the
world's loop waits on :meth:`CommandBarrier.wait`; :meth:`AgentTickAssembler.next_tick` is the same rule
for a consumer of one assembler. Every method
is thread-safe. Messages that do not fit (an old tick, a duplicate, a tick too far ahead) are dropped and
counted, never raised into a callback.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from swarm.errors import ConfigError
from swarm.transport.keys import check_id
from swarm.transport.messages import Command, Estimate, Imu, Message, Tdoa, Uwb, Vision

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


def period_phase(read) -> tuple[int, int]:
    """``(period, phase)`` of one element of a ``reads`` tuple: a period ``e`` (the ticks ``k % e == 0``)
    or a pair ``(e, phase)`` (the ticks ``(k - phase) % e == 0``, a staggered control clock)."""
    return (read, 0) if isinstance(read, int) else (read[0], read[1])


def reads_target(reads: tuple | None, k: int) -> bool:
    """Whether a chaser's tick ``k`` reads its target's estimate (``estimate(k - 1)``; tick 0 the initial
    one): every tick if ``reads`` is ``None``, else the ticks of its periods (:func:`period_phase`; tick 0
    among them).
    ``reads`` is :func:`~swarm.transport.wire.target_reads`'s; the target sends by the same rule
    (:func:`~swarm.transport.wire.estimate_read`)."""
    if reads is None or k == 0:
        return True
    for r in reads:  # a loop, not any() over a generator: a chaser asks every tick
        if (k % r == 0) if type(r) is int else ((k - r[1]) % r[0] == 0):
            return True
    return False


def _check_read(read: object) -> int | tuple[int, int]:
    """One element of ``target_reads``: a period >= 1, or ``(period, phase)`` with ``0 <= phase < period``."""
    if isinstance(read, tuple | list) and len(read) == 2:
        e = _check_int(read[0], "target_reads period", 1)
        ph = _check_int(read[1], "target_reads phase", 0)
        if ph >= e:
            raise ConfigError(f"lockstep.target_reads phase must be below its period, got {tuple(read)!r}")
        return (e, ph)
    return _check_int(read, "target_reads", 1)


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
    """Tick ``k`` (>= 0)."""
    imu: Imu | None = None
    """``imu(k)``: gyro (+ AHRS) sample; ``None`` at tick 0 (no sample yet)."""
    vision: Vision | None = None
    """``vision(k)`` on camera slots (possibly with zero markers), else ``None``."""
    uwb: Uwb | Tdoa | None = None
    """``uwb(k)`` on UWB slots (``range_m`` ``None`` when the reply was lost), else ``None``; with
    ``uwb.mode`` tdoa2/tdoa3, ``tdoa(k)`` (its distance differences, possibly none) in its place."""
    target_estimate: Estimate | None = None
    """For a chaser, its target's estimate of tick ``k - 1`` (of tick 0 at tick 0); while the target is
    lost, its latest estimate (held), ``None`` if there never was one. ``None`` for a non-chaser."""


class _Frame:
    __slots__ = ("imu", "t_imu", "uwb", "vision")

    def __init__(self) -> None:
        self.imu: Imu | None = None
        self.uwb: Uwb | Tdoa | None = None  # a Tdoa on a TDoA radio (it takes the range's place)
        self.vision: Vision | None = None
        self.t_imu = 0.0  # when the imu arrived (time.monotonic): a free-running tick's grace starts then


class AgentTickAssembler:
    """Collects one agent's sensor messages (and its target's estimates) into complete ticks.

    Feed it from the Zenoh callbacks with :meth:`add`; the agent's loop calls :meth:`next_tick`.

    ``start=0`` begins with tick 0 (a run from its start). ``start=None`` *joins* a run in progress (a
    restarted agent): the first ``imu(j)`` received fixes the start at ``j + 1`` (tick ``j`` may have lost
    inputs that came before the subscription), and messages of earlier ticks are dropped as stale.

    The target's estimates are required while the target is live (:meth:`set_target_live`); once it is
    lost, ticks complete without them and carry its latest estimate; when it is back, they are required
    again from the first estimate it publishes.

    Counters (:meth:`counts`, cumulative): ``stale`` (a tick already processed), ``duplicates`` (a second
    message of one kind for a pending tick; the first is kept), ``future`` (more than ``max_ahead`` ticks
    ahead), ``unexpected`` (``uwb``/``vision`` off this vehicle's slots, a message of another vehicle, a
    message type an agent does not take), ``incomplete`` (a free-running tick taken without all of its
    inputs, or skipped without its ``imu``), ``late`` (late fusion: kept for :meth:`take_late`).
    """

    def __init__(
        self,
        agent_id: str,
        is_chaser: bool,
        target_id: str | None,
        uwb_every: int,
        vision_every: int | None = None,
        start: int | None = 0,
        max_ahead: int = DEFAULT_MAX_AHEAD,
        wait_for_target: bool = True,
        cond: threading.Condition | None = None,
        ready: set | None = None,
        target_reads: tuple[int, ...] | None = None,
        late_ticks: int | None = None,
        uwb_slots: Callable[[int], bool] | None = None,
    ) -> None:
        """``agent_id``: this vehicle; ``is_chaser``: whether ticks need the target's estimates;
        ``target_id``: the target's agent id (required for a chaser); ``uwb_every``: ticks between two UWB
        slots (``uwb(k)`` expected when ``k % uwb_every == 0``, ``k >= 1``); ``vision_every``: ticks between
        two camera frames of this vehicle (``None``: no camera); ``start``: the first tick (``None``: join
        at the first ``imu``); ``max_ahead``: ticks beyond the next expected one that are still buffered;
        ``wait_for_target``: ``False`` (a free-running clock) never waits for the target's estimate, each
        tick carrying the newest one up to tick ``k - 1``; ``cond``: the condition this assembler notifies
        when a message is kept (default its own): an agent host shares one among its vehicles, so that one
        thread waits for a tick of any of them (:meth:`poll`); ``ready``: a set, shared with them as well,
        to which this assembler adds itself when it notifies, so that the host polls only those;
        ``target_reads``: a chaser's ticks that read the target's estimate, the multiples of these periods
        (:func:`~swarm.transport.wire.target_reads`; ``None``: every tick): only those wait for it;
        ``late_ticks``: a free-running agent's late fusion (``None``: off, the lockstep rule). With it, a tick
        is ready for :meth:`poll` as soon as its ``imu`` is in (the estimator does not wait for a range or a
        frame), and a ``uwb``/``vision`` of a tick already taken, at most ``late_ticks`` ticks before the
        next one, is kept for :meth:`take_late` (counted ``late``) instead of dropped as stale;
        ``uwb_slots``: of the UWB slot ticks, those with an exchange of this tag (a TDMA channel:
        :func:`~swarm.step.radio.exchange_ticks`; ``None``: all): only those expect a ``uwb``."""
        self.agent_id = check_id(agent_id)
        self.is_chaser = bool(is_chaser)
        self.target_id = check_id(target_id, "target id") if (is_chaser or target_id is not None) else None
        self.uwb_every = _check_int(uwb_every, "uwb_every", 1)
        self.uwb_slots = uwb_slots
        self.vision_every = None if vision_every is None else _check_int(vision_every, "vision_every", 1)
        self.max_ahead = _check_int(max_ahead, "max_ahead", 0)
        self.target_reads = None if target_reads is None else tuple(_check_read(r) for r in target_reads)
        self._cond = threading.Condition() if cond is None else cond
        self._ready = ready
        self._next: int | None = None if start is None else _check_int(start, "start", 0)
        self._frames: dict[int, _Frame] = {}
        self._estimates: dict[int, Estimate] = {}  # by the estimate's own tick
        self._held: Estimate | None = None  # the newest target estimate handed out
        self._target_live = bool(wait_for_target)
        self._uwb_live = True
        self._uwb_from = 0  # uwb of ticks >= this are required (while the mothership is live)
        self._target_from = 0  # estimates of ticks >= this are required (while the target is live)
        self.late_ticks = None if late_ticks is None else _check_int(late_ticks, "late_ticks", 0)
        self._late: list[Uwb | Vision] = []  # measurements of ticks already taken, for take_late
        self._taken: dict[int, set[str]] = {}  # late fusion: the recent ticks taken, and the slots they had
        self._closed = False
        self._counts = dict.fromkeys(("stale", "duplicates", "future", "unexpected", "incomplete", "late"), 0)

    # ------------------------------------------------------------------------------ producers

    def add(self, msg: Message, source_id: str | None = None) -> bool:
        """Hand over one decoded message; ``True`` if it was kept for a tick, ``False`` if dropped (and
        counted). ``source_id`` is the vehicle of the message's key when known: it must be this agent
        for ``Imu``/``Uwb``/``Vision`` and the target for ``Estimate``. Never raises on a message."""
        with self._cond:
            if isinstance(msg, Estimate):
                kept = self._add_estimate(msg, source_id)
            elif isinstance(msg, Imu | Uwb | Tdoa | Vision):
                kept = self._add_sensor(msg, source_id)
            else:
                self._counts["unexpected"] += 1
                return False
            # only news a consumer acts on wakes it: the next tick complete, or an imu (a free-running
            # tick's grace starts, or a lost tick is skipped); not every message of a tick
            if kept and (isinstance(msg, Imu) or self._late or not self._missing()):
                self._notify()
            return kept

    def _notify(self) -> None:
        if self._ready is not None:
            self._ready.add(self)
        self._cond.notify_all()

    def _window(self, k: int) -> str | None:
        """Why a message of tick ``k`` cannot be kept (``"stale"``/``"future"``), else ``None``."""
        if self._next is None:  # joining: keep a bounded window until the first imu fixes the start
            newest = max(self._frames, default=k)
            return "future" if abs(k - newest) > self.max_ahead else None
        if k < self._next:
            return "stale"
        if k > self._next + self.max_ahead:
            return "future"
        return None

    def _add_estimate(self, msg: Estimate, source_id: str | None) -> bool:
        if not self.is_chaser or (source_id is not None and source_id != self.target_id):
            self._counts["unexpected"] += 1
            return False
        if self._next is not None and msg.tick < self._next - 1:
            self._counts["stale"] += 1
            return False
        if self._next is not None and msg.tick + 1 > self._next + self.max_ahead:  # used by tick + 1
            self._counts["future"] += 1
            return False
        if msg.tick in self._estimates or (self._held is not None and msg.tick <= self._held.tick):
            self._counts["duplicates" if msg.tick in self._estimates else "stale"] += 1
            return False
        if self._target_live and self._target_from < 0:  # the first estimate since the target came back
            self._target_from = msg.tick
        self._estimates[msg.tick] = msg
        if len(self._estimates) > self.max_ahead + 2:  # joining, or a target far ahead: keep the newest
            del self._estimates[min(self._estimates)]
        return True

    def _add_sensor(self, msg: Imu | Uwb | Tdoa | Vision, source_id: str | None) -> bool:
        k = msg.tick
        if source_id is not None and source_id != self.agent_id:
            self._counts["unexpected"] += 1
            return False
        if isinstance(msg, Uwb | Tdoa) and not self._uwb_tick(k):
            self._counts["unexpected"] += 1
            return False
        if isinstance(msg, Vision) and (self.vision_every is None or k == 0 or k % self.vision_every):
            self._counts["unexpected"] += 1
            return False
        why = self._window(k)
        if why == "stale" and isinstance(msg, Uwb | Tdoa) and self._uwb_live and self._uwb_from < 0:
            # the mothership (back, or found by a joining agent) serves its slots in tick order: its first
            # range came after its tick was taken without one, so every tick from the next waits for its
            # range (else each later range could lose the same race: a lockstep world's ticks come in a
            # bundle before the bundle of their ranges, docs/protocol.md "Bundles")
            self._uwb_from = self._next if self._next is not None else k + 1
        if why == "stale" and k in self._taken and not isinstance(msg, Imu):
            return self._add_late(msg)
        if why is not None:
            self._counts[why] += 1
            return False
        if self._next is None and isinstance(msg, Imu):  # joining: this imu fixes the start
            self._next = k + 1
            self._counts["stale"] += sum(1 for t in self._frames if t <= k) + 1
            self._frames = {t: f for t, f in self._frames.items() if t > k}
            self._estimates = {t: e for t, e in self._estimates.items() if t >= k}
            # the target may have published estimate(k) before our subscription reached it: wait for
            # its estimates only once one has arrived
            self._target_from = min(self._estimates, default=-1)
            return False
        frame = self._frames.get(k)
        if frame is None:
            frame = self._frames[k] = _Frame()
        slot = "imu" if isinstance(msg, Imu) else ("uwb" if isinstance(msg, Uwb | Tdoa) else "vision")
        if getattr(frame, slot) is not None:
            self._counts["duplicates"] += 1
            return False
        setattr(frame, slot, msg)
        if slot == "imu":
            frame.t_imu = time.monotonic()
        if slot == "uwb" and self._uwb_from < 0:  # the first range since the mothership came back
            self._uwb_from = k
        return True

    def _add_late(self, msg: Uwb | Tdoa | Vision) -> bool:
        """A range (or differences) or frame of tick ``k``, taken already without it (late fusion,
        ``_cond`` held)."""
        had = self._taken[msg.tick]
        slot = "uwb" if isinstance(msg, Uwb | Tdoa) else "vision"
        if slot in had:
            self._counts["duplicates"] += 1
            return False
        had.add(slot)
        self._late.append(msg)
        self._counts["late"] += 1
        return True

    # ------------------------------------------------------------------------------ consumer

    def _needed_estimate(self, k: int) -> int | None:
        """The tick of the target estimate tick ``k`` waits for, or ``None`` if it waits for none."""
        if not self.is_chaser or not self._target_live or self._target_from < 0:
            return None
        if not reads_target(self.target_reads, k):
            return None  # a tick that does not read the target's estimate (its target sends none for it)
        need = max(k - 1, 0)
        return need if need >= self._target_from else None

    def _uwb_tick(self, k: int) -> bool:
        """Whether tick ``k`` has an exchange of this tag: a UWB slot tick (``k >= 1``) and, on a TDMA
        channel, one of its slots."""
        return k > 0 and k % self.uwb_every == 0 and (self.uwb_slots is None or self.uwb_slots(k))

    def _missing(self) -> list[str]:
        k = self._next
        if k is None:
            return ["imu"]
        out = []
        if k > 0:
            frame = self._frames.get(k)
            if frame is None or frame.imu is None:
                out.append("imu")
            needs_uwb = self._uwb_live and self._uwb_from >= 0 and k >= self._uwb_from
            if needs_uwb and self._uwb_tick(k) and (frame is None or frame.uwb is None):
                out.append("uwb")
            if self.vision_every is not None and k % self.vision_every == 0:
                if frame is None or frame.vision is None:
                    out.append("vision")
        need = self._needed_estimate(k)
        held = self._held.tick if self._held is not None else -1
        if need is not None and need not in self._estimates and held < need:
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
            return self._take()

    def _take(self) -> TickInputs:
        """Tick ``k = next`` with what it has (``_cond`` held): pops its frame and the target estimates up
        to tick ``k - 1`` (the newest is held), advances to ``k + 1``."""
        k = self._next
        assert k is not None
        frame = self._frames.pop(k, None) or _Frame()
        est = None
        if self.is_chaser:
            usable = [t for t in self._estimates if t <= max(k - 1, 0)]
            if usable:
                self._held = self._estimates[max(usable)]
                for t in usable:
                    del self._estimates[t]
            est = self._held
        self._next = k + 1
        if self.late_ticks is not None:  # late fusion: remember what the recent ticks had
            self._taken[k] = {s for s in ("uwb", "vision") if getattr(frame, s) is not None}
            for t in [t for t in self._taken if t < self._next - self.late_ticks]:
                del self._taken[t]
        return TickInputs(tick=k, imu=frame.imu, vision=frame.vision, uwb=frame.uwb, target_estimate=est)

    def poll(
        self, grace_s: float | None = None, now: float | None = None
    ) -> tuple[TickInputs | None, float | None]:
        """Without blocking: ``(inputs, None)`` if a tick is ready (taken, as :meth:`next_tick` takes it),
        else ``(None, due)``, ``due`` the monotonic time at which one will be (``None``: when a message
        comes).

        ``grace_s=None`` is the lockstep rule: only a complete tick is ready. A number is a free-running
        clock's: tick ``k`` is also ready, without what it lacks (counted ``incomplete``), ``grace_s``
        after its ``imu`` arrived; and a tick whose ``imu`` never came is skipped (counted ``incomplete``)
        as soon as a later ``imu`` is in (one publisher, reliable and in order: it is lost). The wait is
        thus a deadline per tick, not a polling period. With late fusion (``late_ticks``) there is no
        wait: a tick is ready once its ``imu`` is in, and what comes after it goes to :meth:`take_late`."""
        with self._cond:
            return self._poll(grace_s, now)

    def poll_round(
        self, grace_s: float | None = None
    ) -> tuple[Sequence[Uwb | Vision], TickInputs | None, bool]:
        """The agent host's look at this vehicle in one of its rounds, with :attr:`cond` **held by the
        caller** (the host takes it once for all of its vehicles): ``(late, inputs, more)``, the late ranges
        and frames (:meth:`take_late`), the tick ready now as :meth:`poll` takes it (``None``: none), and
        whether a further tick may be ready already (the host looks again in its next round; ``False``
        means :meth:`poll` would return no tick until a message comes)."""
        late: Sequence[Uwb | Vision] = self._late
        if late:
            self._late = []
        else:
            late = ()  # not the list itself: a message kept meanwhile must not reach this round's caller
        inputs = self._poll(grace_s, None)[0]
        return late, inputs, inputs is not None and self._ready_now(grace_s)

    def _ready_now(self, grace_s: float | None) -> bool:
        """Whether :meth:`poll` with ``grace_s`` may take a tick now (``_cond`` held): the next tick is
        complete, or, free-running, an ``imu`` of it or of a later tick is in (a tick within its grace
        answers ``True`` too; :meth:`poll` then says when it is due)."""
        if self._closed or self._next is None:
            return False
        if not self._missing():
            return True
        if grace_s is None:
            return False
        nxt = self._next
        return any(f.imu is not None for t, f in self._frames.items() if t >= nxt)

    def _poll(self, grace_s: float | None, now: float | None) -> tuple[TickInputs | None, float | None]:
        """:meth:`poll` with ``_cond`` held."""
        if self._closed or self._next is None:
            return None, None
        if not self._missing():
            return self._take(), None
        if grace_s is None:
            return None, None
        k = self._next
        frame = self._frames.get(k)
        if k > 0 and (frame is None or frame.imu is None):
            later = [t for t, f in self._frames.items() if t > k and f.imu is not None]
            if not later:
                return None, None
            self._counts["incomplete"] += 1  # tick k, without its imu, is skipped
            self._skip_to(min(later))
            if not self._missing():
                return self._take(), None
            frame = self._frames[self._next]
        if self.late_ticks is not None:
            return self._take(), None  # late fusion: its imu is in; what it lacks is fused when it comes
        due = (frame.t_imu if frame is not None else 0.0) + grace_s
        if (time.monotonic() if now is None else now) >= due:
            self._counts["incomplete"] += 1
            return self._take(), None
        return None, due

    def take_late(self) -> list[Uwb | Vision]:
        """Late fusion (``late_ticks``): the ranges and frames that came after their tick was taken, in
        order of arrival, each once; the consumer fuses them before the next tick it takes."""
        with self._cond:
            late, self._late = self._late, []
            return late

    def wake(self) -> None:
        """Wake a thread waiting on :attr:`cond` (the agent host's loop, or :meth:`next_tick`): something
        outside the assembler changed, the run started or ended."""
        with self._cond:
            self._notify()

    def _skip_to(self, k: int) -> None:
        """Make tick ``k`` the next one, dropping the frames of the ticks before it (``_cond`` held)."""
        self._next = k
        for t in [t for t in self._frames if t < k]:
            del self._frames[t]

    def set_uwb_live(self, live: bool) -> None:
        """The mothership (the ranges' source) was seen lost (``False``: ticks stop waiting for ``uwb``) or
        back (``True``: they wait again from the first range it sends)."""
        with self._cond:
            if bool(live) == self._uwb_live:
                return
            self._uwb_live = bool(live)
            if live:
                self._uwb_from = -1  # set by the next uwb that arrives
            self._notify()

    def set_target_live(self, live: bool) -> None:
        """The target's agent was seen lost (``False``: ticks stop waiting for its estimates) or back
        (``True``: they wait again from the first estimate it publishes)."""
        with self._cond:
            if bool(live) == self._target_live:
                return
            self._target_live = bool(live)
            if live:
                self._target_from = -1  # set by the next estimate that arrives
            self._notify()

    def close(self) -> None:
        """Wake every :meth:`next_tick` (they return ``None``), e.g. at shutdown."""
        with self._cond:
            self._closed = True
            self._notify()

    # ------------------------------------------------------------------------------ state

    @property
    def cond(self) -> threading.Condition:
        """The condition this assembler notifies (shared by an agent host's vehicles)."""
        return self._cond

    @property
    def ready(self) -> set | None:
        """The set it adds itself to when it notifies (shared by an agent host's vehicles), or ``None``."""
        return self._ready

    @property
    def next_expected(self) -> int | None:
        """The tick :meth:`next_tick` returns next (``None`` while joining, before the first ``imu``)."""
        with self._cond:
            return self._next

    def waiting_for(self) -> list[str]:
        """What the next tick still lacks, among ``"imu"``, ``"uwb"``, ``"vision"``, ``"estimate"`` (for a
        timeout log)."""
        with self._cond:
            return self._missing()

    def counts(self) -> dict[str, int]:
        """A snapshot of the drop counters."""
        with self._cond:
            return dict(self._counts)


class CommandBarrier:
    """The world's side of the lockstep: waits for every live agent's ``command(k)`` before stepping, on
    the ticks that agent commands.

    An agent commands on its control ticks only, ``(k - phase[agent]) % every[agent] == 0`` (its kind's
    controller rate, from its ``control_phase``),
    and the world holds that command until the next: on the ticks in between nobody has anything new to
    say, so the world does not wait for anyone (docs/protocol.md, "Rates"). The world then steps up to a
    control period ahead of the agents, which work through the buffered ticks while it steps: the two
    overlap instead of taking turns.

    :meth:`add` (from the Zenoh callbacks) records commands; :meth:`wait` (the world's loop) returns when
    every live agent due at tick ``k`` has its command of tick ``k`` in, or the timeout passed, listing the
    missing agents (the world logs them and idles their actuators). Counters: ``stale`` (a tick already
    released), ``duplicates`` (the first command of an agent and tick is kept), ``future`` (more than
    ``max_ahead`` ticks ahead), ``unknown`` (an agent id not given at construction).
    """

    def __init__(
        self,
        agent_ids,
        max_ahead: int = DEFAULT_MAX_AHEAD,
        every: dict | None = None,
        phase: dict | None = None,
    ) -> None:
        """``agent_ids``: every agent that may send commands, all live at first; ``max_ahead``: ticks
        beyond the next one waited for that are still buffered; ``every``: each agent's command period
        [ticks] (``None``, or an agent not in it: every tick); ``phase``: each agent's first command tick
        (its ``control_phase``, below its period; default 0): it commands on ``(k - phase) % every == 0``."""
        ids = tuple(check_id(a) for a in agent_ids)
        if len(set(ids)) != len(ids):
            raise ConfigError(f"lockstep.agent_ids must be distinct, got {ids!r}")
        self.agent_ids = ids
        self.max_ahead = _check_int(max_ahead, "max_ahead", 0)
        every = dict(every or {})
        unknown = sorted(set(every) - set(ids))
        if unknown:
            raise ConfigError(f"lockstep.every names agents not among {ids}: {unknown}")
        self.every = {a: _check_int(every.get(a, 1), f"lockstep.every[{a}]", 1) for a in ids}
        phase = dict(phase or {})
        unknown = sorted(set(phase) - set(ids))
        if unknown:
            raise ConfigError(f"lockstep.phase names agents not among {ids}: {unknown}")
        self.phase = {a: _check_int(phase.get(a, 0), f"lockstep.phase[{a}]", 0) for a in ids}
        late = sorted(a for a in ids if self.phase[a] >= self.every[a])
        if late:
            raise ConfigError(f"lockstep.phase must be below each agent's period, got it not for {late}")
        self._period = math.lcm(*self.every.values()) if ids else 1  # the pattern of due agents repeats
        self._due_cache: dict[tuple[frozenset, int], frozenset] = {}
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
            if self._due(k) <= tick.keys():  # only a complete tick wakes the world (not each of 32 commands)
                self._cond.notify_all()
            return True

    def _due(self, k: int) -> frozenset[str]:
        """The live agents that command at tick ``k`` (``_cond`` held)."""
        key = (self._live, k % self._period)
        due = self._due_cache.get(key)
        if due is None:
            due = self._due_cache[key] = frozenset(
                a for a in self._live if (k - self.phase[a]) % self.every[a] == 0
            )
        return due

    def due(self, k: int) -> frozenset[str]:
        """The live agents whose ``command(k)`` the world waits for: those for which ``k`` is a control
        tick."""
        with self._cond:
            return self._due(k)

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
        """Block until every live agent due at ``k`` (:meth:`due`) has its ``command(k)`` in, or
        ``timeout_s`` [s] passed (``None``: forever). Returns ``(commands, missing)``: the commands of tick
        ``k`` by agent id (live or not, due or not), and the due agents without one, in ``agent_ids``
        order. Releases tick ``k``: later commands of ticks ``<= k`` are stale."""
        k = _check_int(k, "tick", 0)
        timeout_s = _check_timeout(timeout_s)
        with self._cond:
            if k < self._floor:
                raise ConfigError(f"lockstep.tick {k} was already released (next is {self._floor})")

            def complete() -> bool:
                return self._due(k) <= self._commands.get(k, {}).keys()

            _wait(self._cond, complete, timeout_s)
            commands = self._commands.pop(k, {})
            due = self._due(k)
            missing = [a for a in self.agent_ids if a in due and a not in commands]
            self._floor = k + 1
            self._commands = {t: c for t, c in self._commands.items() if t > k}
            return commands, missing

    def poll(self, k: int, timeout_s: float | None = None) -> bool:
        """Whether every due live agent's ``command(k)`` is in, waiting up to ``timeout_s`` [s] for it; unlike
        :meth:`wait` it releases nothing (a world loop polls in slices to stay responsive)."""
        timeout_s = _check_timeout(timeout_s)
        with self._cond:
            return _wait(self._cond, lambda: self._due(k) <= self._commands.get(k, {}).keys(), timeout_s)

    @property
    def next_tick(self) -> int:
        """The lowest tick not yet released: commands of earlier ticks are stale."""
        with self._cond:
            return self._floor

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
