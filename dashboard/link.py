"""The dashboard's Zenoh side: it subscribes, watches liveliness and sends the operator's controls (run
controls on ``control/run``, faults on ``control/fault``); it never runs estimator or guidance code.

The world publishes each vehicle's truth every tick, and agents their estimate and guidance every tick:
in lockstep that is thousands of samples per second, far more than a browser can show. Those
latest-value topics (truth, estimate, guidance, vision of each vehicle, the world clock, and the world's
``world/vision`` batches of a swarm of agent hosts) are
subscribed with a Zenoh ``RingChannel(1)``: Zenoh keeps only the newest sample of each key, in Rust, and
calls no Python per sample; the render loop takes it with :meth:`SwarmLink.poll` once per frame and
decodes only that one (BENCHMARKS.md: ``RingChannel(1)`` suits latest-value topics). So the
dashboard's cost follows its frame rate, not the swarm's tick rate. Topics where every sample counts,
events (mode transitions, contact, loss; the run's and the UWB network's, faults applied or refused),
anchors, liveliness and, on a TDoA radio, the tags' distance differences (``agent/<id>/tdoa``, the
``mothership/tdoa`` batches and the ``Tdoa`` entries of lockstep bundles: the radio's rates count every
slot, :mod:`dashboard.radio`) use callbacks
(:func:`~swarm.transport.session.subscribe_decoded`, :func:`~swarm.transport.session.watch_liveliness`).

Every payload is decoded with :func:`~swarm.transport.messages.safe_decode`: an invalid one is counted
per key in the :class:`~swarm.transport.messages.DropCounter` and logged at a limited rate, never raised.
"""

from __future__ import annotations

import logging
import threading

import zenoh

from dashboard.state import SwarmState
from swarm.transport.keys import Keys
from swarm.transport.messages import (
    Anchors,
    Bundle,
    Clock,
    DropCounter,
    Estimate,
    Event,
    Fault,
    Guidance,
    Message,
    RunControl,
    Tdoa,
    TdoaBatch,
    Truth,
    Vision,
    VisionBatch,
    batch_rows,
    bundle_messages,
    encode,
    safe_decode,
)
from swarm.transport.session import declare_liveliness, subscribe_decoded, watch_liveliness
from swarm.transport.stopping import STOPPING, process_name

__all__ = ["LATEST_KINDS", "SwarmLink"]

_LOG = logging.getLogger("dashboard.link")

LATEST_KINDS: dict[str, type[Message]] = {
    "truth": Truth,
    "estimate": Estimate,
    "guidance": Guidance,
    "vision": Vision,
}
"""Per-vehicle topics of which only the newest sample matters to the dashboard."""

VISION_BATCHES = 4
"""The ``world/vision`` batches (of an agent hosts' swarm) the dashboard keeps between two frames: the
newest; one batch holds a tick's frames of up to 134 chasers (225 with marker features rather than
poses; ``swarm.transport.messages.pack_entries``)."""


def _control_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """Reliable and blocking: a user's click must reach the world (never dropped under congestion)."""
    return session.declare_publisher(
        key,
        reliability=zenoh.Reliability.RELIABLE,
        congestion_control=zenoh.CongestionControl.BLOCK,
        encoding=zenoh.Encoding("application/msgpack"),
    )


class SwarmLink:
    """Subscriptions, liveliness and the control publishers of one dashboard, feeding ``state``.

    ``poll()`` (render thread) takes the newest sample of every latest-value topic; callbacks (Zenoh threads)
    handle events, anchors and liveliness. ``send()`` publishes a RunControl and ``send_fault()`` a Fault
    (reliable, block: a user's click must reach the world and the mothership). The anchors are also asked for
    with ``get`` in a background thread until one reply comes (a ``get`` right after the mothership declares
    its queryable can get no reply: BENCHMARKS.md), in case the dashboard starts after they were
    published. With ``tdoa`` (the scenario's ``uwb.mode`` is tdoa2/tdoa3) every ``Tdoa`` goes to the store,
    however it travels.
    """

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        state: SwarmState,
        drops: DropCounter,
        process_id: str = "dashboard",
        anchors_retry_s: float = 1.0,
        tdoa: bool = False,
    ) -> None:
        self.session = session
        self.keys = keys
        self.state = state
        self.drops = drops
        self._stop = threading.Event()
        # the launcher's stopping event (until the next run's start): a process's going is then a stop
        self._stopping = threading.Event()
        # before the first subscription: a callback may run as soon as its subscriber is declared (a restarted
        # dashboard met the mothership's periodic anchors there: AttributeError in _on_anchors, logged)
        self._have_anchors = threading.Event()
        self._rings: list[tuple[str, str, type[Message], zenoh.Subscriber]] = []
        # a lockstep world sends a chaser's frames in the bundles of its ticks (docs/protocol.md, "Bundles"):
        # the newest bundle's newest frame is the newest frame
        self._bundles: list[tuple[str, zenoh.Subscriber]] = []
        self._clock = session.declare_subscriber(keys.world_clock(), zenoh.handlers.RingChannel(1))
        # a swarm of agent hosts sends the chasers' frames of a tick in world/vision batches (one, or a few
        # for a large swarm): the newest few are kept, so a tick's every batch is there when the frame looks
        self._vision = session.declare_subscriber(
            keys.world_vision(), zenoh.handlers.RingChannel(VISION_BATCHES)
        )
        self._add_vehicles(state.take_new_agents())
        subscribe_decoded(session, keys.agent_all("event"), Event, self._on_event, drops)
        subscribe_decoded(session, keys.world_event(), Event, self._on_world_event, drops)
        subscribe_decoded(session, keys.anchors(), Anchors, self._on_anchors, drops)
        if tdoa:  # every slot counts (a lockstep bundle's too: the newest-only rings above serve the frames)
            subscribe_decoded(session, keys.agent_all("tdoa"), Tdoa, self._on_tdoa, drops)
            subscribe_decoded(session, keys.mothership_tdoa(), TdoaBatch, self._on_tdoa_batch, drops)
            subscribe_decoded(session, keys.agent_all("bundle"), Bundle, self._on_bundle_tdoa, drops)
        watch_liveliness(session, keys, self._on_liveliness)
        self._run_pub = _control_publisher(session, keys.run_control())
        self._fault_pub = _control_publisher(session, keys.fault())
        self._token = declare_liveliness(session, keys, "dashboard", process_id)
        self._anchors_thread = threading.Thread(
            target=self._fetch_anchors, args=(anchors_retry_s,), name="dashboard-anchors", daemon=True
        )
        self._anchors_thread.start()

    # ---------------------------------------------------------------------------------- render thread

    def _add_vehicles(self, agent_ids: list[str]) -> None:
        for agent_id in agent_ids:
            for kind, cls in LATEST_KINDS.items():
                key = getattr(self.keys, kind)(agent_id)
                sub = self.session.declare_subscriber(key, zenoh.handlers.RingChannel(1))
                self._rings.append((agent_id, kind, cls, sub))
            ring = zenoh.handlers.RingChannel(1)
            self._bundles.append(
                (agent_id, self.session.declare_subscriber(self.keys.bundle(agent_id), ring))
            )
            _LOG.debug("subscribed to vehicle %s", agent_id)

    def poll(self) -> int:
        """Take the newest sample of every latest-value topic into the state; returns how many were new.
        Call from one thread (the render loop). Also subscribes to vehicles seen for the first time."""
        self._add_vehicles(self.state.take_new_agents())
        n = 0
        sample = self._clock.try_recv()
        if sample is not None and sample.kind == zenoh.SampleKind.PUT:
            clock = safe_decode(sample.payload, Clock, str(sample.key_expr), self.drops)
            if clock is not None:
                n += 1
                if self.state.on_message("world_clock", None, clock):
                    _LOG.info("new run: seed %d (tick %d)", clock.seed, clock.tick)
        for _ in range(VISION_BATCHES):
            sample = self._vision.try_recv()
            if sample is None:
                break
            if sample.kind != zenoh.SampleKind.PUT:
                continue
            key = str(sample.key_expr)
            batch = safe_decode(sample.payload, VisionBatch, key, self.drops)
            for agent_id, frame in [] if batch is None else batch_rows(batch, key, self.drops):
                n += 1
                self.state.on_message("vision", agent_id, frame)
        for agent_id, sub in self._bundles:
            sample = sub.try_recv()
            if sample is None or sample.kind != zenoh.SampleKind.PUT:
                continue
            key = str(sample.key_expr)
            bundle = safe_decode(sample.payload, Bundle, key, self.drops)
            frames = [] if bundle is None else bundle_messages(bundle, key, self.drops, ("Vision",))
            if frames:
                n += 1
                self.state.on_message("vision", agent_id, frames[-1])
        for agent_id, kind, cls, sub in self._rings:
            sample = sub.try_recv()
            if sample is None or sample.kind != zenoh.SampleKind.PUT:
                continue
            msg = safe_decode(sample.payload, cls, str(sample.key_expr), self.drops)
            if msg is None:
                continue
            n += 1
            self.state.on_message(kind, agent_id, msg)
        return n

    # ---------------------------------------------------------------------------------- any thread

    def send(self, command: str, seed: int | None = None) -> RunControl:
        """Publish ``RunControl(command, seed)`` on ``<ns>/control/run``; returns the message sent.
        MessageError for an unknown command."""
        msg = RunControl(command=command, seed=seed)
        self._run_pub.put(encode(msg))
        _LOG.info("sent run control %s%s", command, "" if seed is None else f" (seed {seed})")
        return msg

    def send_fault(self, msg: Fault) -> Fault:
        """Publish ``msg`` (already validated: it is a :class:`Fault`) on ``<ns>/control/fault``; returns it.
        The world and the mothership answer with ``fault`` / ``fault_refused`` events (:meth:`poll` does not
        wait for them: they arrive in the fault log)."""
        self._fault_pub.put(encode(msg))
        _LOG.info("sent fault %s (vehicle %s)", msg.kind, msg.vehicle or "every chaser")
        return msg

    def listeners(self) -> bool:
        """Whether anyone (the world, the mothership) subscribes to ``control/fault`` now."""
        return bool(self._fault_pub.matching_status.matching)

    def close(self) -> None:
        """Stop the anchors thread. The subscriptions end when the session closes."""
        self._stop.set()
        self._anchors_thread.join(timeout=5.0)

    # ---------------------------------------------------------------------------------- Zenoh threads

    def _on_event(self, key: str, msg: Event) -> None:
        parsed = self.keys.parse(key)
        if parsed is not None and parsed[1] is not None:
            self.state.on_message("event", parsed[1], msg)

    def _on_tdoa(self, key: str, msg: Tdoa) -> None:
        parsed = self.keys.parse(key)
        if parsed is not None and parsed[1] is not None:
            self.state.on_message("tdoa", parsed[1], msg)

    def _on_tdoa_batch(self, key: str, batch: TdoaBatch) -> None:
        for vid, msg in batch_rows(batch, key, self.drops):
            self.state.on_message("tdoa", vid, msg)

    def _on_bundle_tdoa(self, key: str, bundle: Bundle) -> None:
        if "Tdoa" not in bundle.types:  # the world's bundles of this vehicle (imu, vision)
            return
        parsed = self.keys.parse(key)
        if parsed is not None and parsed[1] is not None:
            for msg in bundle_messages(bundle, key, self.drops, ("Tdoa",)):
                self.state.on_message("tdoa", parsed[1], msg)

    def _on_world_event(self, _key: str, msg: Event) -> None:
        if msg.kind == STOPPING:  # (swarm.transport.stopping)
            self._stopping.set()
        elif msg.kind == "run_start":  # the next run's processes
            self._stopping.clear()
        self.state.on_message("world_event", None, msg)

    def _on_anchors(self, _key: str, msg: Anchors) -> None:
        self.state.on_message("anchors", None, msg)
        self._have_anchors.set()

    def _on_liveliness(self, role: str, process_id: str, alive: bool) -> None:
        change = self.state.on_liveliness(role, process_id, alive)
        if change is not None:
            stopped = not alive and (self._stopping.is_set() or self._stop.is_set())
            _LOG.info("%s %s", process_name(role, process_id), "stopped" if stopped else change)

    def _fetch_anchors(self, retry_s: float) -> None:
        key = self.keys.anchors()
        while not (self._stop.is_set() or self._have_anchors.is_set()):
            try:
                for reply in self.session.get(key, timeout=retry_s):
                    if reply.ok is not None:
                        msg = safe_decode(reply.ok.payload, Anchors, key, self.drops)
                        if msg is not None:
                            self._on_anchors(key, msg)
            except Exception as exc:  # the session closing under us ends the thread
                if self._stop.is_set():
                    return
                _LOG.debug("anchors get failed: %s", exc)
            self._stop.wait(retry_s)
