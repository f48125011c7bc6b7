"""The mothership process: the anchor registry and the simulated UWB radio network, over Zenoh.

- Anchors: published once on ``mothership/anchors`` when the process is up (and every
  ``anchors_every_s``), and answered to any query on that key (``session.get``), so a late joiner asks.
- Radio network: the radio step, :class:`swarm.step.radio.UwbNetwork` (one round-robin radio per vehicle,
  the sensor model of :mod:`swarm.core.sensors`). From the world's ``truth`` of every vehicle at a UWB
  slot tick ``k`` it publishes one ``uwb(k)`` per vehicle, with ``range_m`` nil when the reply was lost, so
  a lockstep agent knows not to wait; on a TDMA channel (``uwb.tdma``) only for the tags whose slot came in
  that tick (an idle tag's agent expects none: :func:`swarm.step.radio.exchange_ticks`). With ``uwb.mode``
  tdoa2/tdoa3 it publishes instead one ``Tdoa`` per vehicle and slot on ``agent/<id>/tdoa`` (the
  differences its tag heard since the last slot, possibly none), ``TdoaBatch`` messages on
  ``mothership/tdoa`` for agent hosts, ``Tdoa`` entries in a lockstep bundle. It takes the
  truths of a tick as one ``TruthBatch`` on ``world/truth``; for agent hosts (``--batch``) it sends a
  slot's ranges as one ``UwbBatch`` on ``mothership/uwb``. A lockstep world's truths of several ticks
  come as one ``Bundle`` on ``world/bundle``; the ranges of its slots then leave as one ``Bundle`` per
  vehicle on ``agent/<id>/bundle``.
  Slots are processed in tick order: the radios' random streams are consumed exactly as in the in-process
  simulation (same seed, same ranges). The truths of a slot already served (a resumed world publishes the
  ticks some process may lack again) are ignored, counted in ``served_again``: a slot is served once.
- Faults: none of its own. Each truth carries its tag's radio environment at that tick (``uwb_lost``,
  ``nlos_probability``: the world's fault schedule, fixed, mode-triggered and run-time windows alike),
  and the radios apply it, as the in-process radio step does.
- While the world is gone (its liveliness token went) it says so and serves nothing: no truth, no range.
- A stop (its own SIGINT/SIGTERM, or the launcher's ``stopping`` event on ``world/event``) is no fault: the
  world's going is then logged as a stop, and a slot's ranges that its closing session no longer takes are
  not an error (:mod:`swarm.transport.stopping`).
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np
import zenoh

from swarm.step.radio import UwbNetwork
from swarm.transport.keys import Keys
from swarm.transport.messages import (
    Anchors,
    Bundle,
    Clock,
    DropCounter,
    Event,
    Truth,
    TruthBatch,
    bundle_messages,
    encode,
    pack_bundle,
)
from swarm.transport.process import PROCESS_NOISE_BLOCK, declare_reliable, print_ready
from swarm.transport.session import declare_liveliness, subscribe_decoded, watch_liveliness
from swarm.transport.stopping import Stopping, process_name
from swarm.transport.wire import tdoa_slot, tdoa_slot_batch, uwb_slot, uwb_slot_batch

_LOG = logging.getLogger("swarm.mothership")


class MothershipProcess:
    """Anchor services and radio network of one run (module docstring)."""

    def __init__(
        self,
        scenario,
        seed: int,
        session,
        keys: Keys,
        stop: threading.Event,
        anchors_every_s: float = 1.0,
        rejoin: bool = False,
        batch: bool = False,
    ) -> None:
        """``batch``: every vehicle's range of a slot sent in one ``mothership/uwb`` message (agent hosts,
        docs/protocol.md "Rates"), not one per vehicle. The world's truths come as ``world/truth``
        batches either way."""
        self.sc, self.seed, self.session, self.keys, self.stop = scenario, seed, session, keys, stop
        self.batch = batch
        self.anchors_every_s = anchors_every_s
        self.ids = list(scenario.vehicles)
        self.index = {v: i for i, v in enumerate(self.ids)}
        self.network = UwbNetwork(scenario, seed)
        self.network.noise_block = PROCESS_NOISE_BLOCK
        self.every = self.network.every
        self.drops = DropCounter()
        self._lock = threading.Lock()  # the truths' callback serves the slots (_take)
        self._failure: Exception | None = None  # a slot's exception, raised by run()
        self.anchors_msg = Anchors(tuple(range(len(scenario.anchors_m))), np.asarray(scenario.anchors_m))
        self._pending: dict[int, dict[str, Truth]] = {}
        # tick 0 has no exchange: the first range is at the first slot >= 1; a restarted mothership (rejoin)
        # starts at the slot after the first truth it sees (that slot's truths may have come before it)
        self._next_slot: int | None = None if rejoin else self.every
        self.slots = 0
        self.served_again = 0  # truth batches of slots already served (a resumed world's): ignored
        self._world_stopped = False  # the world's last Clock said "stopped": its run is over
        self.stopping = Stopping(stop)  # the swarm stops: the world's going is no loss, a failed put no error

    def _on_truth_batch(self, key: str, msg: TruthBatch, out: dict | None = None) -> None:
        """A tick's truths of every vehicle (``world/truth``): each vehicle's, as its own key would have
        brought it (a vehicle not of this scenario counted and dropped)."""

        def rows():
            for i, vid in enumerate(msg.ids):
                if vid in self.index:
                    yield vid, msg.sample(vid, i)
                else:
                    self.drops.drop(key, f"truth: {vid!r} is not a vehicle of this scenario")

        self._serve(msg.tick, rows(), out)

    def _on_bundle(self, key: str, msg: Bundle) -> None:
        """A lockstep world's truth batches of several ticks (``world/bundle``): each served as a
        ``world/truth`` batch, and the ranges of its slots sent as one ``agent/<id>/bundle`` per vehicle
        (docs/protocol.md, "Bundles")."""
        out: dict[str, list[tuple[str, bytes, int]]] = {}
        for batch in bundle_messages(msg, key, self.drops, ("TruthBatch",)):
            self._on_truth_batch(key, batch, out)  # type: ignore[arg-type]
        try:
            for vid, entries in out.items():
                for payload in pack_bundle(entries):
                    self.pub_bundle[vid].put(payload)
        except Exception as exc:
            if not self.stopping.quiet(exc):  # (its session closing while it stops: no error)
                raise

    def _serve(self, tick: int, truths, out: dict | None = None) -> None:
        """Tick ``tick``'s ``(vehicle, truth)`` pairs (an iterable, taken only on a UWB slot tick) into the
        slots (:meth:`_take`), under the lock; a failure is kept for :meth:`run` to raise. ``out``: the
        ranges go there, per vehicle, as bundle entries, instead of out at once."""
        if tick % self.every or tick == 0 or self._failure is not None:
            return
        try:
            with self._lock:
                if self._next_slot is not None and tick < self._next_slot:
                    # not an invalid message: a resumed world publishes again the ticks some process may
                    # lack (swarm.world.process.unconfirmed_ticks), those served already among them
                    self.served_again += 1
                    _LOG.debug("truths of tick %d: its UWB slot was already served", tick)
                    return
                for vid, truth in truths:
                    self._take(vid, truth, out)
        except Exception as exc:  # a bug in the radio step: the process fails, its supervisor restarts it
            if self.stopping.quiet(exc):  # its session closing while it stops: no error, nothing to restart
                return
            _LOG.exception("UWB slot failed")
            self._failure = exc

    def _take(self, vid: str, msg: Truth, out: dict | None = None) -> None:
        """One slot tick's truth, on the subscriber's thread (a hand-off per truth to the main thread cost
        more than the slot itself, and sat on the lockstep's path); serves every slot it completes."""
        if self._next_slot is None:
            self._next_slot = msg.tick + self.every
            _LOG.info("mothership rejoins the run: ranges from tick %d on", self._next_slot)
        if msg.tick < self._next_slot:  # the rest of a rejoining mothership's first tick: not its slot
            return
        slot = self._pending.setdefault(msg.tick, {})
        slot[vid] = msg
        # slots complete in tick order (the world steps in order); serve every complete one
        while len(self._pending.get(self._next_slot, ())) == len(self.ids):
            self._slot(self._next_slot, self._pending.pop(self._next_slot), out)
            self._next_slot += self.every
        if len(self._pending) > 1000:  # a vehicle's truth never came: skip its slot, say so
            oldest = min(self._pending)
            _LOG.warning("UWB slot %d incomplete after 1000 newer slots: skipped", oldest)
            del self._pending[oldest]
            self._next_slot = min(self._pending)

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            query.reply(self.keys.anchors(), encode(self.anchors_msg))
        except Exception as exc:  # a query must never kill the queryable's thread
            if not self.stopping.quiet(exc):
                _LOG.warning("anchors query not answered: %s", exc)

    def _on_clock(self, _key: str, msg: Clock) -> None:
        # the world's clock says whether its going is the end of a run (it publishes "stopped" after
        # run_end, then exits) or a loss: only a loss is worth a warning
        self._world_stopped = msg.state == "stopped" and msg.tick > 0
        if self._world_stopped:
            _LOG.debug("world stopped at tick %d", msg.tick)

    def _on_world_event(self, _key: str, msg: Event) -> None:
        self.stopping.hear(msg.kind)  # the launcher's stopping: the world's going is a stop

    def _on_alive(self, role: str, pid: str, alive: bool) -> None:
        if role == "world":
            name = process_name(role, pid)
            if alive:
                _LOG.info("%s is alive", name)
            elif self._world_stopped:
                _LOG.info("%s gone after the end of its run", name)
            else:
                self.stopping.gone(_LOG, name, "%s lost; no truth, so no ranges, until it is back", name)

    def _slot(self, k: int, truths: dict[str, Truth], out: dict | None = None) -> None:
        X = np.zeros((len(self.ids), 13))
        lost = np.zeros(len(self.ids), dtype=np.bool_)
        p_nlos = np.zeros(len(self.ids))
        for vid, m in truths.items():
            i = self.index[vid]
            X[i, 0:3], X[i, 3:6], X[i, 6:10], X[i, 10:13] = m.p_nav, m.v_nav, m.q_nav_body, m.w_body
            lost[i], p_nlos[i] = m.uwb_lost, m.nlos_probability
        t = k * self.sc.dt_s
        self.network.step(k, t, X, lost, p_nlos)
        if self.network.tdoa is not None:
            self._tdoa_slot(k, t, out)
        elif out is not None:  # a bundle's slot: the ranges go out with the bundle's others
            for vid, payload in uwb_slot(self.network, self.ids, k, t):
                out.setdefault(vid, []).append(("Uwb", payload, k))
        elif self.batch:
            payload = uwb_slot_batch(self.network, self.ids, k, t)
            if payload is not None:  # (every tag idle on a TDMA channel: nothing to send)
                self.pub_uwb_batch.put(payload)
        else:
            for vid, payload in uwb_slot(self.network, self.ids, k, t):
                self.pub_uwb[vid].put(payload)
        self.slots += 1

    def _tdoa_slot(self, k: int, t: float, out: dict | None) -> None:
        """``uwb.mode`` tdoa2/tdoa3: each vehicle's distance differences of the slot, one ``Tdoa`` each
        (none heard: no rows), on ``agent/<id>/tdoa``, in its bundle, or in ``mothership/tdoa`` batches."""
        if out is not None:
            for vid, payload in tdoa_slot(self.network, self.ids, k, t):
                out.setdefault(vid, []).append(("Tdoa", payload, k))
        elif self.batch:
            for payload in tdoa_slot_batch(self.network, self.ids, k, t):
                self.pub_tdoa_batch.put(payload)
        else:
            for vid, payload in tdoa_slot(self.network, self.ids, k, t):
                self.pub_tdoa[vid].put(payload)

    def run(self) -> None:
        k = self.keys
        X = np.zeros((len(self.ids), 13))
        X[:, 9] = 1.0  # identity attitudes
        UwbNetwork(self.sc, self.seed).step(self.every, 0.0, X)  # compile (or load) the kernel before "ready"
        self.network.reserve_noise(1)  # and the first slot's noise drawn (the same samples as at its step)
        # a slot's ranges are a burst: batched beyond one pair (docs/protocol.md, "QoS")
        self.pub_uwb = {v: declare_reliable(self.session, k.uwb(v), len(self.ids) <= 2) for v in self.ids}
        self.pub_uwb_batch = declare_reliable(self.session, k.mothership_uwb(), len(self.ids) <= 2)
        if self.network.tdoa is not None:  # uwb.mode tdoa2/tdoa3: differences, not ranges
            n = len(self.ids)
            self.pub_tdoa = {v: declare_reliable(self.session, k.tdoa(v), n <= 2) for v in self.ids}
            self.pub_tdoa_batch = declare_reliable(self.session, k.mothership_tdoa(), len(self.ids) <= 2)
        self.pub_bundle = {
            v: declare_reliable(self.session, k.bundle(v), len(self.ids) <= 2) for v in self.ids
        }
        pub_anchors = declare_reliable(self.session, k.anchors(), express=False)
        self._queryable = self.session.declare_queryable(k.anchors(), self._on_query)
        # a slot's truths in one world/truth batch (not agent/*/truth: the world sends those to a viewer
        # only, while one matches; 32 vehicles: 50 messages a second instead of 1600)
        subscribe_decoded(self.session, k.world_truth(), TruthBatch, self._on_truth_batch, self.drops)
        # a lockstep world's ticks up to its next awaited command in one message (docs/protocol.md, "Bundles")
        subscribe_decoded(self.session, k.world_bundle(), Bundle, self._on_bundle, self.drops)
        subscribe_decoded(self.session, k.world_clock(), Clock, self._on_clock, self.drops)
        subscribe_decoded(self.session, k.world_event(), Event, self._on_world_event, self.drops)
        watch_liveliness(self.session, k, self._on_alive, history=False)
        self._token = declare_liveliness(self.session, k, "mothership", "mothership")
        print_ready("mothership", "mothership")
        payload = encode(self.anchors_msg)
        pub_anchors.put(payload)
        last_anchors = time.monotonic()
        while not self.stop.wait(min(0.1, self.anchors_every_s)) and self._failure is None:
            now = time.monotonic()
            if now - last_anchors >= self.anchors_every_s:
                pub_anchors.put(payload)
                last_anchors = now
        self.drops.flush()
        if self.served_again:
            _LOG.info("%d UWB slots served; %d truth batches of slots already served ignored (a resumed "
                      "world's ticks published again)", self.slots, self.served_again)  # fmt: skip
        if self._failure is not None:
            raise self._failure
