"""The agent host: the agents of one or several vehicles in one process, on one Zenoh session and one thread.

``swarm launch --vehicles-per-process N`` (``python -m agents --id a,b,...``) hosts several vehicles in one
process, as a ROS 2 component container hosts several nodes; a process per vehicle is a host of one. Keys,
liveliness tokens and supervision stay per vehicle (``docs/architecture.md``, "Agent hosts"). It steps
docking agents (:class:`agents.process.AgentProcess`) and landing UAVs' agents
(:class:`agents.landing.LandingAgentProcess`, ``python -m agents.landing``) alike.

What the host shares among its vehicles:

- **one thread steps them all.** Their tick assemblers share one condition: a Zenoh callback that keeps a
  message notifies it, and the host's loop looks at each vehicle's assembler with news, under one hold of
  the condition (:meth:`~swarm.transport.lockstep.AgentTickAssembler.poll_round`), and processes every tick
  that is ready, vehicle after vehicle: those that command on their tick first. Before, each vehicle had
  its own thread waiting on its own condition (and, free-running, waking every 2 ms to look for a late
  tick): 16 vehicles were 16 threads taking the GIL in turn. A
  free-running tick is ready once its ``imu`` is in, and a range or frame that comes after it is handed to
  the vehicle before its next tick (late fusion), so the loop sleeps until a message comes. A host of one
  vehicle (a process each) runs that round on the thread of the subscriber whose message made the tick
  ready instead (:meth:`AgentHost.on_news`): one thread hand-off less per tick;
- **one subscriber each** for the world's clock and events and for liveliness, whose messages go to every
  vehicle: the same for all of them, once per process instead of once per vehicle; and for the world's
  ``world/imu`` and ``world/vision`` batches and the mothership's ``mothership/uwb`` batch (sent for agent
  hosts), whose rows go to the vehicles they are for.

- **a target's estimate, handed over.** A chaser whose target is in the same host does not subscribe to the
  target's estimates: the target's agent hands it the message it publishes
  (:func:`~swarm.transport.messages.estimate_and_payload`), the values a subscriber would decode, without the
  round trip through Zenoh and the decoding (~20 us of the chaser's tick). The bytes are still published
  for every other subscriber.

Each vehicle keeps its own subscribers to its own sensors (and to its target's estimate, when the target is
in another process), its publishers and its token. An exception in one vehicle's step stops the host, which
exits 1: its supervisor restarts every vehicle it hosted, and they rejoin the run. A publication that fails
because the host's session closed while it stops (a round still running on a Zenoh thread) only ends its
rounds (:mod:`swarm.transport.stopping`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence

from swarm.transport.keys import Keys
from swarm.transport.messages import (
    Clock,
    CommandBatch,
    DropCounter,
    Event,
    ImuBatch,
    TdoaBatch,
    UwbBatch,
    VisionBatch,
    batch_rows,
    pack_entries,
)
from swarm.transport.process import declare_reliable
from swarm.transport.session import subscribe_decoded, watch_liveliness
from swarm.transport.stopping import Stopping, wait_for_stop

__all__ = ["IDLE_S", "SCAN_S", "AgentHost", "WakePlanner"]

_LOG = logging.getLogger("swarm.agent")

IDLE_S = 0.05
"""The longest the host's loop sleeps without a message [s]: how soon it sees a run's end drain out or a
vehicle's stalled lockstep tick."""

SCAN_S = 0.25
"""How often the host asks each vehicle whether its run is over while the world's clock runs [s] (a run
ends with the clock's ``stopped``, after which it asks every round; in between only a lockstep tick that
stalls for 5 s has something to say, :meth:`agents.process.AgentProcess.done`)."""


class AgentHost:
    """Runs :class:`agents.process.AgentProcess` objects that share ``session`` and one condition."""

    def __init__(self, procs: Sequence, session, keys: Keys, stop: threading.Event) -> None:
        if not procs:
            raise ValueError("an agent host needs at least one vehicle")
        self.procs = list(procs)
        conds = {id(p.assembler.cond) for p in self.procs}
        readies = {id(p.assembler.ready) for p in self.procs}
        if len(conds) != 1 or len(readies) != 1 or self.procs[0].assembler.ready is None:
            raise ValueError("the vehicles of one host share one condition and one ready set (cond=, ready=)")
        self.cond, self.ready = self.procs[0].assembler.cond, self.procs[0].assembler.ready
        self.session, self.keys, self.stop = session, keys, stop
        self.stopping = Stopping(stop)  # one for its vehicles (the launcher's stopping event, a signal)
        for p in self.procs:
            p.stopping = self.stopping
        clock = {p.clock for p in self.procs}
        if len(clock) != 1:
            raise ValueError(f"the vehicles of one host share its clock, got {sorted(map(str, clock))}")
        self.clock = clock.pop()
        # lockstep waits for complete ticks only; free-running, a tick goes as soon as its imu is in, and
        # the range or frame that comes after it is fused before the next tick (late fusion)
        self.grace_s = None if self.clock.lockstep else 0.0
        # a chaser whose target is hosted here takes its estimates from the target's agent, not from Zenoh
        by_id = {p.id: p for p in self.procs}
        for p in self.procs:
            target = by_id.get(p.target_id) if p.chaser else None
            if target is not None:
                p.target_local = True
                target.local_chasers.append(p)
        self.shared_drops = DropCounter()
        # a host of one vehicle steps it on the thread of the subscriber whose message made its tick ready
        # (Zenoh gives each subscriber a Python thread of its own); a host of several keeps one thread for
        # all, since its subscribers' callbacks run on Zenoh's receiving threads, which must not be held
        self.inline = len(self.procs) == 1
        self._round_lock = threading.Lock()  # one round at a time, whichever thread runs it
        self._kick = threading.Event()  # inline: wakes the loop's thread (a round failed)
        self._by_asm = {p.assembler: p for p in self.procs}
        self._by_id = by_id
        self._live: list = []
        self._ending = False  # the world's clock stopped: every round asks which runs are over
        self._scan_at = 0.0  # ... and before that, every SCAN_S from here
        self._ended = False
        self._failure: BaseException | None = None
        if self.inline:
            self.procs[0].on_news = self.on_news
        # a free-running host of several sends the commands of a round in one CommandBatch (docs/protocol.md,
        # "Rates"): the world takes them at its next tick, and saves a fifth of its CPU at 128 vehicles. In
        # lockstep the world decodes each command while the host steps the next vehicle, and waits for the
        # last: batched, the two no longer overlap (32 vehicles in hosts of 16: 3.6x against 4.3-5.0x)
        self._commands: list[tuple[str, bytes]] = []
        self._pub_commands = None
        self.batch_commands = not self.inline and not self.clock.lockstep and self.procs[0].batched
        if self.batch_commands:
            for p in self.procs:
                p.command_sink = self._commands

    # ------------------------------------------------------------------------------ shared subscribers

    # a host of one (inline) steps what these made ready (the run's start, a lost mothership's ranges no
    # longer awaited) on their thread too, as a sensor's callback does, instead of at the loop's next look

    def _on_clock(self, key: str, msg: Clock) -> None:
        for p in self.procs:
            p._on_clock(key, msg)
        if msg.state == "stopped":
            self._ending = True
        if self.inline:
            self.on_news()

    def _on_batch(
        self, key: str, msg: ImuBatch | UwbBatch | TdoaBatch | VisionBatch, published_ns: int | None = None
    ) -> None:
        """The world's imu (``world/imu``) or camera frames (``world/vision``), or the mothership's ranges
        (``mothership/uwb``; differences: ``mothership/tdoa``), of every vehicle, sent for agent hosts
        (``--batch``): each hosted vehicle's row, as its own key would have brought it (a host of one steps
        it here, :meth:`AgentProcess._on_sensor`; an imu with the batch's publication stamp); a frame that
        does not decode is counted (:attr:`shared_drops`) and loses no other vehicle's."""
        for vid, sample in batch_rows(msg, key, self.shared_drops, self._by_id):
            self._by_id[vid]._on_sensor(key, sample, published_ns)

    def _send_commands(self) -> None:
        """The commands the round's vehicles decided so far, to the world in one message (or a few)."""
        entries = self._commands[:]
        del self._commands[:]  # the list the vehicles append to: emptied, not replaced
        for payload in pack_entries(entries, CommandBatch):
            self._pub_commands.put(payload)

    def _on_world_event(self, key: str, msg: Event) -> None:
        for p in self.procs:
            p._on_world_event(key, msg)

    def _on_alive(self, role: str, pid: str, alive: bool) -> None:
        for p in self.procs:
            p._on_alive(role, pid, alive)
        if self.inline:
            self.on_news()

    # ------------------------------------------------------------------------------ the loop

    def run(self) -> None:
        """Open every vehicle, subscribe the shared keys, announce the vehicles, step them until each one's
        run is over (or ``stop``), publish their summaries, then stay up (liveliness, dashboard) until
        ``stop``."""
        for p in self.procs:
            p.open(shared=False)
        k = self.keys
        if self.batch_commands:  # batched, as the world's samples are: one message to the world per round
            self._pub_commands = declare_reliable(self.session, k.commands(self.procs[0].id), express=False)
        watch_liveliness(self.session, k, self._on_alive, history=any(p.rejoin for p in self.procs))
        if self.procs[0].batched:  # (a landing UAV's agent takes its own keys only: agents.landing)
            self._subscribe_batches()
        subscribe_decoded(self.session, k.world_event(), Event, self._on_world_event, self.shared_drops)
        for p in self.procs:
            p.announce()
        try:
            ended = self._loop()
            if ended:
                wait_for_stop(self.stop)  # stay up (liveliness, dashboard) until told to stop
        finally:
            self.shared_drops.flush()
            for p in self.procs:
                p.drops.flush()

    def _subscribe_batches(self) -> None:
        """The world's clock, and the batches of the world and the mothership (docking)."""
        k = self.keys
        subscribe_decoded(self.session, k.world_clock(), Clock, self._on_clock, self.shared_drops)
        direct = not self.inline  # as the vehicles' own sensor subscribers (AgentProcess.open)
        subscribe_decoded(self.session, k.world_imu(), ImuBatch, self._on_batch, self.shared_drops,
                          direct=direct, stamped=True)  # fmt: skip
        subscribe_decoded(self.session, k.mothership_uwb(), UwbBatch, self._on_batch, self.shared_drops,
                          direct=direct)  # fmt: skip
        if any(p.tdoa for p in self.procs):  # uwb.mode tdoa2/tdoa3: a slot's differences (mothership/tdoa)
            subscribe_decoded(self.session, k.mothership_tdoa(), TdoaBatch, self._on_batch, self.shared_drops,
                              direct=direct)  # fmt: skip
        subscribe_decoded(self.session, k.world_vision(), VisionBatch, self._on_batch, self.shared_drops,
                          direct=direct)  # fmt: skip

    def _loop(self) -> bool:
        """Step the vehicles until every run is over or ``stop``; ``True`` if some run ended (a summary).

        Each round (:meth:`_round`) polls only the vehicles whose assembler has news (the shared ``ready``
        set), processes what is ready outside the lock (a free-running vehicle's late ranges and frames,
        then its tick), and retires the vehicles whose run is over. No tick has a deadline: lockstep takes
        complete ticks, free-running a tick once its ``imu`` is in (late fusion).

        A host of several vehicles runs its rounds on this thread, which sleeps until a message or
        :data:`IDLE_S`. A host of one (:attr:`inline`) runs them on the subscriber's thread whose message
        made a tick ready (:meth:`on_news`), and this thread only looks every :data:`IDLE_S` for what no
        message brings (a run's end, a stalled tick), and raises what a round raised there."""
        self._live = list(self.procs)
        self.ready.update(self._by_asm)
        if self.inline and self.procs[0].wake_at_control:
            threading.Thread(target=self._pace, name="pacer", daemon=True).start()
        while self._live and not self.stop.is_set():
            if self._failure is not None:
                raise self._failure
            if self.inline:
                self._kick.wait(IDLE_S)
                self._kick.clear()
                self._drain()
                continue
            try:
                with self._round_lock:
                    did = self._round()
            except Exception as exc:
                if not self.stopping.quiet(exc):  # (its session closing while it stops: no error)
                    raise
                break
            if not did:
                with self.cond:
                    if not self.ready:
                        self.cond.wait(IDLE_S)
        if self._failure is not None:
            raise self._failure
        return self._ended

    def _pace(self) -> None:
        """``agent.wake_at_control`` (a free-running host of one): wake when :class:`WakePlanner` says, take
        every input from the queues, run the rounds; poll while the control tick's imu is not in."""
        p = self.procs[0]
        plan = WakePlanner(p.dt / p.clock.factor, p.sc.agent.wake_margin_s, p.next_control_tick)
        try:
            while self._live and not self.stop.is_set() and self._failure is None:
                wake = plan.next(p.newest_imu, time.monotonic())
                now = time.monotonic()
                if wake > now:
                    self.stop.wait(min(wake - now, IDLE_S))
                    if time.monotonic() < wake:
                        continue  # (woken for a stop, or waited IDLE_S: look again)
                polled = 0
                while True:
                    now = time.monotonic()
                    p.drain_inputs()
                    self.on_news()
                    if plan.took(p.newest_imu, now, polled) or self.stop.is_set() or not self._live:
                        break
                    polled += 1
                    self.stop.wait(plan.poll_s())  # the control tick's imu not in yet
        except BaseException as exc:  # kept for the loop's thread to raise (the host exits 1)
            if not self.stopping.quiet(exc):  # (its session closing while it stops: no error)
                self._failure = exc
            self._kick.set()

    def on_news(self) -> None:
        """A vehicle's subscriber callback kept a message (:attr:`inline` hosts): if it made a tick ready,
        run the rounds here, on the callback's thread, instead of waking the loop's thread (one thread
        hand-off less per tick: ~30 us of CPU and of latency each, ``swarm bench transport``)."""
        if self.ready:  # this thread's own message made a tick ready (added under the condition)
            self._drain()

    def _drain(self) -> None:
        """Rounds until none processes anything, unless another thread is running them: that one looks
        again once it lets go (so a tick made ready meanwhile is never left behind). A round's exception
        is kept for the loop's thread to raise (the host exits 1, its supervisor restarts it)."""
        while self._live and self._failure is None and not self.stop.is_set():
            if not self._round_lock.acquire(blocking=False):
                return  # the holder re-checks ``ready`` after it releases
            try:
                while self._live and self._round():
                    pass
            except BaseException as exc:
                if not self.stopping.quiet(exc):  # (its session closing while it stops: no error)
                    self._failure = exc
                self._kick.set()
                return
            finally:
                self._round_lock.release()
            with self.cond:
                if not self.ready:
                    return

    def _round(self) -> bool:
        """One pass over the vehicles with news, under :attr:`_round_lock`; ``True`` if it processed any.

        The shared condition is taken once for the whole look (each assembler's
        :meth:`~swarm.transport.lockstep.AgentTickAssembler.poll_round`), and a vehicle is looked at again
        in the next round only if a further tick of it may be ready already. Which vehicles' runs are over
        is asked after the world's clock stopped (:meth:`_on_clock`), and otherwise every
        :data:`SCAN_S` (a lockstep tick that stalls is logged from there)."""
        live, cond, ready, grace = self._live, self.cond, self.ready, self.grace_s
        batch = []
        with cond:
            news = set(ready)
            ready.clear()
            for p in live:  # in host order: the same order every round
                a = p.assembler
                if a not in news or not p.ticking():
                    continue
                late, inp, more = a.poll_round(grace)  # late: always none in lockstep
                if more:
                    ready.add(a)  # a further tick is ready already: the next round takes it
                if late or inp is not None:
                    batch.append((p, late, inp))
        # the vehicles that command on their tick first (host order otherwise: the sort is stable)
        batch.sort(key=_commands_last)
        for i, (p, late, inp) in enumerate(batch):  # the round's commands first: the world waits for them
            try:
                if late:
                    p.fuse_late(late)  # free-running: before the tick that follows theirs
                if inp is not None:
                    p.process(inp)
            except Exception as exc:
                if not self.stopping.quiet(exc):
                    _LOG.exception("%s: agent failed at tick %s", p.id, "late" if inp is None else inp.tick)
                raise
            if self._commands and (i + 1 == len(batch) or _commands_last(batch[i + 1])):
                self._send_commands()  # the last vehicle that commands on its tick is stepped
        for p, _late, inp in batch:  # then the estimates: a chaser uses its target's a tick later
            if inp is None:
                continue
            try:
                p.flush()
            except Exception as exc:
                if not self.stopping.quiet(exc):
                    _LOG.exception("%s: agent failed publishing its estimate of tick %d", p.id, inp.tick)
                raise
        now = time.monotonic()
        if self._ending or now >= self._scan_at:
            self._scan_at = now + SCAN_S
            for p in [p for p in live if p.done(now)]:
                self._ended = p.finish() or self._ended
                live.remove(p)
        return bool(batch)


def _commands_last(entry: tuple) -> bool:
    """Sort key of a round's ``(vehicle, late, inputs)``: ``False`` (first) for a tick on which the vehicle
    sends a command. A host of many vehicles steps them one after the other (~4 ms for 64); the world
    waits for the commands (lockstep) or flies the newest come by the next tick (free-running), while the
    other vehicles' ticks only publish estimates. So with staggered controllers a host of 64 sends its
    tick's few commands within a fraction of a millisecond, not after up to 63 other vehicles' steps.
    Each vehicle's tick is the same in any order: its inputs were taken before the round steps any."""
    p, _late, inp = entry
    return inp is None or not p.commands_at(inp.tick)


class WakePlanner:
    """When a free-running agent alone in its process wakes with ``agent.wake_at_control``
    (:meth:`AgentHost._pace`): twice per control period. First just after the tick before the control
    tick is due (the *fusing* wake: the period's ticks so far are fused then, off the command's path; it
    does not wait for a sample not in yet), then just after the control tick is due (the *control* wake:
    its tick alone, the decision and the command; it polls until the tick's imu is in).

    When a tick's imu comes is learnt from the wakes, not from the drains' times alone (a wake that comes
    late sees every sample in and learns little): the imu of tick ``k`` is expected at ``offset + k
    period``. A control wake that finds its imu not in yet polls for it every ``margin`` and sets
    ``offset`` from when it came; one that finds it in already moves ``offset`` a margin earlier, so that the
    wakes keep probing for the arrival; and every wake bounds it by the newest imu it took, which came
    before it (a wake ticks late learns it at once). Until the first imu it looks every :data:`IDLE_S` /
    10; that imu's arrival is the first guess (a look every margin there, 32 processes polling at 2 kHz at
    a run's start, made the world's first ticks later, and more of them late). Times are
    ``time.monotonic()`` [s]; ``next_control_tick(newest)`` is the vehicle's first control tick after the
    newest imu taken (:meth:`agents.process.AgentProcess.next_control_tick`)."""

    def __init__(self, period_s: float, margin_s: float, next_control_tick) -> None:
        self.period, self.margin = period_s, margin_s
        self._next_control = next_control_tick
        self.offset: float | None = None
        self.fused_for: int | None = None  # the control tick whose period's fusing wake was had
        self.due = self.target = 0

    def next(self, newest: int | None, now: float) -> float:
        """When the next wake is (the tick it is for: :attr:`target`)."""
        self.due = due = self._next_control()
        fusing = newest is not None and newest < due - 1 and self.fused_for != due
        self.target = due - 1 if fusing else due
        if self.offset is None:
            return now + self.poll_s()
        return self.offset + self.target * self.period + self.margin

    def took(self, newest: int | None, now: float, polled: int) -> bool:
        """A wake took its inputs at ``now`` (the newest imu then: ``newest``) after ``polled`` polls:
        whether it is done (no further poll)."""
        if self.target < self.due:
            self.fused_for = self.due
        if newest is None:
            return False
        if self.offset is None:  # a first guess, late by up to a look: the wake is planned anew
            self.offset = now - newest * self.period
            return True
        self.offset = min(self.offset, now - newest * self.period)  # it came before now
        got = newest >= self.target
        if got and self.target == self.due:
            if polled:  # the newest came within the last margin
                self.offset = now - self.margin / 2 - newest * self.period
            else:  # it was in already: look a margin earlier next time
                self.offset -= self.margin
        return got or self.target < self.due

    def poll_s(self) -> float:
        """How long to wait before looking again for a sample not in yet."""
        return self.margin if self.offset is not None else IDLE_S / 10
