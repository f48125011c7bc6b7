"""Record a swarm to an MCAP file, read it back, re-publish it (issue 16: ``swarm record``, ``swarm replay
FILE.mcap``).

**Recording** (:class:`Recorder`): one Zenoh subscriber on ``<ns>/**`` (every key of the swarm,
``docs/protocol.md``) writes each sample, as it arrives, to an MCAP file through ``foxglove-sdk``: one
channel per key, topic = the key, ``message_encoding = "msgpack"`` (a schema named after the message type,
with no content: the wire schema is ``docs/protocol.md``), the payload byte for byte, and the Foxglove views
of :mod:`swarm.transport.foxglove_views` (``/tf``, ``/events``, ``/scene``). ``log_time`` (and
``publish_time``) is the **swarm time** of the message (its ``t_s`` field; a message without one, such as
``Anchors``, takes the latest swarm time seen). The world's ``run_start`` event
is written as MCAP metadata ``run`` (seed, scenario, clock, ...); the recorder's own facts (namespace,
package version) as metadata ``recorder``.

**Reading** (:func:`read_recording`): the plain ``mcap`` reader; a truncated or corrupt file is a
:class:`~swarm.errors.LogError` naming the file and the byte offset where reading stopped.

**Re-publishing** (:func:`replay_recording`): every message in ``log_time`` order (ties in file order), each
on its own key with the recorded bytes, paced at ``speed`` times the recorded swarm time (``inf``: as fast
as possible), optionally only some keys.
"""

from __future__ import annotations

import bisect
import fnmatch
import logging
import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack
import msgspec

from swarm.errors import LogError
from swarm.transport.messages import Bundle, safe_decode

_LOG = logging.getLogger("swarm.record")

ENCODING = "msgpack"
QUIET_S = 0.5
"""On stop, the recorder keeps recording until no sample has come for this long [s]: the samples still in
flight when it was asked to stop are in the file."""
FIFO_DEPTH = 1 << 16
"""Samples the recorder's channel holds before Zenoh waits for it (a FIFO: none is dropped)."""
IDLE_S = 0.02
"""The recorder's nap when its channel is empty [s]."""


class _Stamp(msgspec.Struct):
    t_s: Any = None
    tick: Any = None


_STAMP = msgspec.msgpack.Decoder(_Stamp)


def swarm_time_ns(payload: bytes, last_ns: int) -> int:
    """The ``t_s`` of a msgpack-map payload in ns, else ``last_ns`` (never raises: a garbage sample is
    recorded too, at the latest swarm time). msgspec reads the one field and skips the rest in C."""
    try:
        t = _STAMP.decode(payload).t_s
        if isinstance(t, int | float) and not isinstance(t, bool) and math.isfinite(t) and t >= 0:
            return round(t * 1e9)
    except Exception:  # anything on the wire, even garbage, is recorded as it came
        pass
    return last_ns


class Recorder:
    """Write every sample of ``<namespace>/**`` seen by ``session`` to ``path`` (module docstring).

    Zenoh queues the samples in a FIFO channel; :meth:`run` drains it and writes them on the calling
    thread until ``stop`` is set, then finishes the file (its summary and indexes), so the file is complete
    whenever the recorder stops cleanly (SIGINT, SIGTERM, the end of the run), with every sample that
    arrives until :data:`QUIET_S` passes without one."""

    def __init__(self, session, keys, path: str | Path, metadata: dict[str, str] | None = None) -> None:
        self.session, self.keys, self.path = session, keys, Path(path)
        self.metadata = dict(metadata or {})
        self.counts: dict[str, int] = {}
        self.run_end_seen = threading.Event()

    def run(self, stop: threading.Event, ready=None) -> dict[str, int]:
        import zenoh

        sink = McapSink(self.path, self.keys, self.metadata)
        # a FIFO channel, drained by this thread: no Python callback (and thread hand-off) per sample
        sub = self.session.declare_subscriber(self.keys.everything(), zenoh.handlers.FifoChannel(FIFO_DEPTH))
        if ready is not None:
            ready()
        quiet = time.monotonic()
        try:
            # after stop: everything received, and what is still in flight (until QUIET_S without a sample)
            while True:
                sample = sub.try_recv()
                if sample is None:
                    if stop.is_set() and time.monotonic() - quiet >= QUIET_S:
                        break
                    time.sleep(IDLE_S)
                    continue
                quiet = time.monotonic()
                sink.write(str(sample.key_expr), sample.payload.to_bytes())
                if sink.run_end_seen:
                    self.run_end_seen.set()
        finally:
            sub.undeclare()
            sink.close()
        self.counts = dict(sink.counts)
        return dict(self.counts)


class McapSink:
    """An MCAP file being written (the module docstring's layout): :meth:`write` one sample as it is on the
    wire, ``log_time`` = its swarm time (``t_s``, else the latest seen), with its Foxglove views and, for the
    world's ``run_start`` and ``run_end`` events, MCAP metadata. The recorder writes what it hears; ``swarm
    sim --mcap`` writes what the in-process run's processes would have published."""

    def __init__(self, path: str | Path, keys, metadata: dict[str, str] | None = None) -> None:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            import foxglove
            from foxglove.mcap import MCAPCompression, MCAPWriteOptions

        from swarm.transport.foxglove_views import SwarmViews

        self.keys = keys
        self.ctx = foxglove.Context()
        options = MCAPWriteOptions(compression=MCAPCompression.Lz4, profile="")
        self.writer = foxglove.open_mcap(str(path), allow_overwrite=True, context=self.ctx,
                                         writer_options=options)  # fmt: skip
        self.writer.write_metadata("recorder", {"namespace": keys.namespace, **(metadata or {}),
                                                "version": package_version()})  # fmt: skip
        self.views = SwarmViews(self.ctx, keys)
        self.counts: dict[str, int] = {}
        self.last_ns = 0
        self.run_end_seen = False
        self._world_event = keys.world_event()

    def write(self, key: str, payload: bytes) -> None:
        entries = self._unbundled(key, payload)
        if entries is not None:  # each sample of a lockstep bundle on the key it stands for
            for entry_key, entry in entries:
                self.write(entry_key, entry)
            return
        self.last_ns = swarm_time_ns(payload, self.last_ns)
        self.views.handle(key, payload, self.last_ns)
        self.counts[key] = self.counts.get(key, 0) + 1
        if key == self._world_event:
            self._metadata(payload)

    def _unbundled(self, key: str, payload: bytes) -> list[tuple[str, bytes]] | None:
        """A valid ``Bundle``'s entries as ``(key, payload)``: each on the key its own message has
        (``agent/<id>/imu``, ``uwb``, ``vision``; ``world/truth``), so that a recording of a lockstep swarm
        has the channels of any other; ``None`` for any other sample (and a bundle that does not decode:
        recorded as it came)."""
        parsed = self.keys.parse(key)
        if parsed is None or parsed[0] not in ("bundle", "world_bundle"):
            return None
        bundle = safe_decode(payload, Bundle, key, self.views.drops)
        if bundle is None:
            return None
        vid = parsed[1]
        out = []
        for name, entry in zip(bundle.types, bundle.entries, strict=True):
            if name == "TruthBatch":
                out.append((self.keys.world_truth(), entry))
            elif vid is not None:
                out.append((getattr(self.keys, name.lower())(vid), entry))
        return out

    def _metadata(self, payload: bytes) -> None:
        try:
            ev = msgpack.unpackb(payload, raw=False)
        except Exception:  # a garbage event: recorded, not described
            return
        if (
            isinstance(ev, dict)
            and ev.get("kind") in ("run_start", "run_end")
            and isinstance(ev.get("data"), dict)
        ):
            self.writer.write_metadata(str(ev["kind"]), {str(k): str(v) for k, v in ev["data"].items()})
            if ev["kind"] == "run_end":
                self.run_end_seen = True

    def close(self) -> None:
        self.writer.close()


def check_mcap_path(path, what: str) -> Path:
    """``path`` as a recording to write: ConfigError naming ``what`` (the flag or argument) for a name
    without ``.mcap`` or a directory that does not exist. Every writer checks with this (``swarm record``,
    ``swarm launch --record``, ``swarm sim --mcap``)."""
    from swarm.errors import ConfigError

    p = Path(path)
    if p.suffix != ".mcap":
        raise ConfigError(f"{what}: the recording's name must end in .mcap, got {str(p)!r}")
    if not p.resolve().parent.is_dir():
        raise ConfigError(f"{what}: no such directory {str(p.parent)!r}")
    return p


def sim_sink(path, keys) -> McapSink:
    """The writer of ``swarm sim --mcap FILE`` (metadata ``recorder.source = "swarm sim"``), its path checked
    (:func:`check_mcap_path`)."""
    return McapSink(check_mcap_path(path, "--mcap"), keys, {"source": "swarm sim"})


def package_version() -> str:
    """This package's version, as installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tpods-swarm")
    except PackageNotFoundError:
        return "unknown"


@dataclass(frozen=True)
class RecordedMessage:
    key: str
    log_time_ns: int
    publish_time_ns: int
    payload: bytes


def read_recording(path: str | Path) -> tuple[list[RecordedMessage], dict[str, dict[str, str]]]:
    """Every message of the MCAP file at ``path`` in ``log_time`` order (ties in file order), and its
    metadata by name. LogError naming the file and the byte offset if it is truncated or corrupt."""
    from mcap.reader import make_reader

    p = Path(path)
    try:
        fh = open(p, "rb")
    except OSError as exc:
        raise LogError(f"{p}: cannot read: {exc.strerror or exc}") from None
    with fh:
        try:
            reader = make_reader(fh)
            msgs = [
                RecordedMessage(ch.topic, m.log_time, m.publish_time, bytes(m.data))
                for _, ch, m in reader.iter_messages(log_time_order=False)
                if ch.message_encoding == ENCODING  # the swarm's keys, not the Foxglove views
            ]  # fmt: skip
            meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        except LogError:
            raise
        except Exception as exc:  # the mcap reader's errors: bad magic, short reads, bad records, CRC
            offset = fh.tell()
            raise LogError(f"{p}: not a complete MCAP recording: {type(exc).__name__}: {exc} "
                           f"(reading stopped at byte {offset} of {p.stat().st_size})") from None  # fmt: skip
    order = sorted(range(len(msgs)), key=lambda i: (msgs[i].log_time_ns, i))
    return [msgs[i] for i in order], meta


def _tick(payload: bytes) -> int | None:
    """The ``tick`` field of a msgpack-map payload, None if it has none (or is not a map)."""
    try:
        t = _STAMP.decode(payload).tick
    except Exception:  # a garbage sample has no tick
        return None
    return t if isinstance(t, int) and not isinstance(t, bool) and t >= 0 else None


def recorded_ticks(messages, key: str) -> list[int]:
    """The ticks of the recorded messages on ``key`` (e.g. an agent's commands: its control ticks)."""
    return [t for t in (_tick(m.payload) for m in messages if m.key == key) if t is not None]


class LockstepAck:
    """The lockstep barrier of a replay into one agent: the agent's ``command(k)`` says it has processed tick
    ``k`` (as the world's barrier, docs/protocol.md, "Clocks and lockstep"). An agent commands on its control
    ticks only: given the ticks of the recorded commands (``ticks``), the replay waits, before a message of
    tick ``k``, for the agent's command of the last of them before ``k`` (:meth:`due`), as the world does,
    and sends the ticks in between meanwhile; without ``ticks``, for ``command(k - 1)``."""

    def __init__(self, session, command_key: str, timeout_s: float = 30.0, ticks=None) -> None:
        self.done = -1
        self.timeout_s = timeout_s
        self.ticks = None if ticks is None else sorted(set(ticks))
        self._cond = threading.Condition()
        self._sub = session.declare_subscriber(command_key, self._on)

    def _on(self, sample) -> None:
        k = _tick(sample.payload.to_bytes())
        if k is not None:
            with self._cond:
                if k > self.done:
                    self.done = k
                    self._cond.notify_all()

    def due(self, k: int) -> int | None:
        """The tick whose command says the agent is through tick ``k``: ``k`` itself, or with recorded
        command ticks the last of them ``<= k`` (``None``: no command to wait for)."""
        if self.ticks is None:
            return k
        i = bisect.bisect_right(self.ticks, k)
        return self.ticks[i - 1] if i else None

    def wait(self, k: int, stop: threading.Event) -> None:
        """Until tick ``k`` is processed; LogError after ``timeout_s`` without it."""
        deadline = time.monotonic() + self.timeout_s
        with self._cond:
            while self.done < k and not stop.is_set():
                left = deadline - time.monotonic()
                if left <= 0:
                    raise LogError(f"replay: no command({k}) from the agent within {self.timeout_s:g} s "
                                   f"(its last: command({self.done}))")  # fmt: skip
                self._cond.wait(min(left, 0.1))


def replay_recording(
    messages: list[RecordedMessage],
    session,
    speed: float,
    stop: threading.Event,
    only: tuple[str, ...] = (),
    ack: LockstepAck | None = None,
) -> dict[str, int]:
    """Publish ``messages`` on their keys (module docstring); ``only``: key patterns (``fnmatch``, e.g.
    ``tpods/agent/chaser/imu`` or ``*/imu``) to keep. With ``ack`` (a lockstep replay into one agent), a
    message of tick ``k`` leaves only once the agent has sent the command of its last control tick before
    ``k`` (:meth:`LockstepAck.due`): nothing is sent faster than the agent takes it. Returns the count
    sent per key."""
    from swarm.transport.process import declare_reliable

    pubs: dict[str, object] = {}
    sent: dict[str, int] = {}
    chosen = [m for m in messages if not only or any(fnmatch.fnmatchcase(m.key, pat) for pat in only)]
    if not chosen:
        return sent
    t0 = chosen[0].log_time_ns
    start = time.monotonic()
    for m in chosen:
        if stop.is_set():
            break
        if math.isfinite(speed):
            due = start + (m.log_time_ns - t0) / 1e9 / speed
            delay = due - time.monotonic()
            if delay > 0:
                stop.wait(delay)
        if ack is not None:
            k = _tick(m.payload)
            due = ack.due(k - 1) if k is not None and k > 0 else None
            if due is not None:
                ack.wait(due, stop)
        pub = pubs.get(m.key)
        if pub is None:
            pub = pubs[m.key] = declare_reliable(session, m.key)
        pub.put(m.payload)
        sent[m.key] = sent.get(m.key, 0) + 1
    time.sleep(0.2)  # let the last samples leave before the session closes
    return sent
