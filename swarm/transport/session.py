"""Zenoh sessions of the swarm: command-line flags, configuration, opening, and decoded subscriptions.

Every process opens its session through this module, so that a user configures all of them the same way
(docs/protocol.md, the zenoh-python examples' shared ``--mode/--connect/--listen/--config`` helper):

- on one machine, peers with explicit loopback endpoints (``--listen tcp/127.0.0.1:7447`` on one,
  ``--connect tcp/127.0.0.1:7447`` on the others);
- across machines, ``--mode client --connect tcp/<router>:7447`` and one ``swarm router``;
- anything else (TLS, user/password, access control, timeouts) in Zenoh's own JSON5 file,
  ``--zenoh-config FILE``.

Precedence: a flag given on the command line beats the file, the file beats this module's defaults
(multicast scouting off, see :func:`make_config`), and those beat Zenoh's defaults.

Measured here (BENCHMARKS.md and this module's tests, eclipse-zenoh 1.10.2): multicast scouting adds
0.5 s to every open and can join strangers, so it is off unless asked; a router also waits
``scouting/delay`` (0.5 s by default) at open for scouting answers that cannot come without multicast, so
that delay is 0 when multicast scouting is off; peer and client sessions on loopback open in ~1-4 ms.

Zenoh runs subscriber callbacks on its own threads, one per subscriber: a handler given to
:func:`subscribe_decoded` or :func:`watch_liveliness` must be thread-safe (hand the message to the main
loop through a queue). A process with a callback subscriber that does not close its session hangs at
interpreter exit: always ``with open_session(args) as session:``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import re
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import msgpack
import zenoh

from swarm.errors import ConfigError, SwarmError
from swarm.transport.keys import Keys
from swarm.transport.messages import MESSAGE_FOR_KIND, DropCounter, Message, safe_decode

__all__ = [
    "LEAN_RUNTIME",
    "MODES",
    "QUEUE_CAPACITY",
    "HandlerErrors",
    "QueuedSubscriber",
    "ZenohArgs",
    "add_zenoh_arguments",
    "check_endpoint",
    "declare_liveliness",
    "free_loopback_endpoint",
    "listen_endpoints",
    "make_config",
    "open_session",
    "subscribe_decoded",
    "watch_liveliness",
    "zenoh_args_from",
]

_LOG = logging.getLogger(__name__)

MODES: tuple[str, ...] = ("peer", "client", "router")
"""Zenoh session modes."""

_PROTO = re.compile(r"[a-z][a-z0-9_-]*")  # tcp, udp, tls, quic, ws, unixsock-stream, serial, vsock ...
_HOST_PORT_PROTOS = frozenset({"tcp", "udp", "tls", "quic", "ws", "wss"})  # address is <host>:<port>
_ZENOH_SOURCE = re.compile(r"\s+at /\S+\.rs:\d+\.?\s*$")  # the Rust source location ending a ZError


def _zerror_text(exc: BaseException) -> str:
    """A ZError's message without the Rust source location it ends with."""
    return _ZENOH_SOURCE.sub("", str(exc)).strip()


# ---------------------------------------------------------------------------------------------- arguments


def check_endpoint(value: object, flag: str, *, listen: bool = False) -> str:
    """``value`` if it is a Zenoh endpoint ``<proto>/<address>[?<metadata>][#<config>]``, else ConfigError
    naming ``flag`` and the value. For ``tcp udp tls quic ws wss`` the address must end in ``:<port>``
    (1-65535; 0, "any free port", only for a listen endpoint). Zenoh checks the rest when it opens."""
    example = "(e.g. tcp/127.0.0.1:7447)"
    if not isinstance(value, str) or "/" not in value or any(c.isspace() for c in value):
        raise ConfigError(f"{flag} endpoint must look like <proto>/<address> {example}, got {value!r}")
    proto, _, rest = value.partition("/")
    address = re.split(r"[?#]", rest, maxsplit=1)[0]
    if not _PROTO.fullmatch(proto) or address == "":
        raise ConfigError(f"{flag} endpoint must look like <proto>/<address> {example}, got {value!r}")
    if proto in _HOST_PORT_PROTOS:
        host, sep, port = address.rpartition(":")
        lo = 0 if listen else 1
        if not (sep and host and port.isdigit() and lo <= int(port) <= 65535):
            raise ConfigError(
                f"{flag} endpoint must be {proto}/<host>:<port> with a port in {lo}..65535 {example}, "
                f"got {value!r}"
            )
    return value


def _endpoints(value: object, flag: str, listen: bool) -> tuple[str, ...]:
    if value is None:
        return ()
    if isinstance(value, str) or not isinstance(value, Iterable):
        raise ConfigError(f"{flag} must be a sequence of endpoints, got {value!r}")
    return tuple(check_endpoint(v, flag, listen=listen) for v in value)


@dataclass(frozen=True)
class ZenohArgs:
    """How to open a process's Zenoh session: the ``--mode --connect --listen --zenoh-config
    --multicast-scouting`` flags of every ``swarm`` process (:func:`add_zenoh_arguments`)."""

    mode: str | None = None
    """``"peer"``, ``"client"`` or ``"router"``; ``None``: the config file's mode, else Zenoh's (peer)."""
    connect: tuple[str, ...] = ()
    """Endpoints to connect to, ``<proto>/<address>`` (``tcp/127.0.0.1:7447``): a client's router, or the
    peers a peer dials. Empty: the config file's, else none."""
    listen: tuple[str, ...] = ()
    """Endpoints to listen on, ``<proto>/<address>`` (port 0: any free port). Empty: the config file's, else
    Zenoh's default (``tcp/[::]:0`` for a peer, ``tcp/[::]:7447`` for a router, none for a client)."""
    config_file: str | None = None
    """Zenoh's own configuration file (``.json5``, ``.json`` or ``.yaml``) to start from: TLS, user/password
    authentication, access control, timeouts. ``None``: Zenoh's defaults."""
    multicast_scouting: bool = False
    """Find peers and routers by UDP multicast. Off unless asked (or enabled by the config file): it adds
    0.5 s to every open and can join strangers' sessions (BENCHMARKS.md)."""
    lease_ms: int | None = None
    """Link lease ``transport/link/tx/lease`` [ms]: a hung (not killed) process's liveliness tokens vanish
    for its watchers after about this long. Set it on both ends (2000 gives ~1.5 s, BENCHMARKS.md).
    ``None``: the config file's, else Zenoh's 10000."""

    def __post_init__(self) -> None:
        if self.mode is not None and self.mode not in MODES:
            raise ConfigError(f"--mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        object.__setattr__(self, "connect", _endpoints(self.connect, "--connect", listen=False))
        object.__setattr__(self, "listen", _endpoints(self.listen, "--listen", listen=True))
        if self.config_file is not None:
            if not isinstance(self.config_file, str | Path) or str(self.config_file) == "":
                raise ConfigError(f"--zenoh-config must be a file path, got {self.config_file!r}")
            object.__setattr__(self, "config_file", str(self.config_file))
        if not isinstance(self.multicast_scouting, bool):
            raise ConfigError(f"--multicast-scouting must be a bool, got {self.multicast_scouting!r}")
        lease = self.lease_ms
        if lease is not None and (isinstance(lease, bool) or not isinstance(lease, int) or lease <= 0):
            raise ConfigError(f"transport.lease_ms must be an integer > 0 or None, got {lease!r}")


def add_zenoh_arguments(parser: argparse.ArgumentParser, *, mode: bool = True) -> None:
    """Add ``--mode`` (unless ``mode=False``, for a command whose mode is fixed), ``--connect`` and
    ``--listen`` (repeatable), ``--zenoh-config FILE`` and ``--multicast-scouting`` to ``parser``, in a
    group of their own (or in ``parser`` itself if it is a group already: argparse deprecates nesting them);
    read them back with :func:`zenoh_args_from`."""
    nested = isinstance(parser, argparse._ArgumentGroup)
    g = parser if nested else parser.add_argument_group("Zenoh session")
    if mode:
        g.add_argument(
            "--mode", choices=MODES, default=None, help="session mode (default: the config file's, else peer)"
        )
    g.add_argument(
        "--connect",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)",
    )
    g.add_argument(
        "--listen",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help="endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)",
    )
    g.add_argument(
        "--zenoh-config",
        default=None,
        metavar="FILE",
        help="Zenoh JSON5 configuration file (TLS, auth, access control); flags override it",
    )
    g.add_argument(
        "--multicast-scouting",
        action="store_true",
        default=False,
        help="discover peers/routers by UDP multicast (off by default: +0.5 s per open, joins strangers)",
    )


def zenoh_args_from(namespace: argparse.Namespace, *, mode: str | None = None) -> ZenohArgs:
    """The :class:`ZenohArgs` of parsed :func:`add_zenoh_arguments` flags; ``mode`` fixes the mode (a
    command without ``--mode``). ConfigError names the bad flag and value."""
    return ZenohArgs(
        mode=mode if mode is not None else getattr(namespace, "mode", None),
        connect=tuple(namespace.connect or ()),
        listen=tuple(namespace.listen or ()),
        config_file=namespace.zenoh_config,
        multicast_scouting=bool(namespace.multicast_scouting),
    )


# ------------------------------------------------------------------------------------------ config, open


def _insert(config: zenoh.Config, key: str, value: object, flag: str) -> None:
    try:
        config.insert_json5(key, json.dumps(value))
    except zenoh.ZError as exc:
        raise ConfigError(f"{flag}: Zenoh refused {key} = {value!r}: {_zerror_text(exc)}") from None


def _is_set(config: zenoh.Config, key: str) -> bool:
    return json.loads(config.get_json(key)) is not None


def make_config(args: ZenohArgs) -> zenoh.Config:
    """The Zenoh configuration of ``args``: the file (if any), then these keys.

    - ``mode``: ``args.mode``, if given.
    - ``connect/endpoints``: ``args.connect``, if not empty (replaces the file's list).
    - ``listen/endpoints``: ``args.listen``, if not empty (replaces the file's list).
    - ``scouting/multicast/enabled``: ``true`` if ``args.multicast_scouting``; else ``false`` unless the
      file set it.
    - ``scouting/delay`` [ms]: ``0`` when multicast scouting ends up off and the file does not set it. It is
      how long a router's open waits for scouting answers (500 ms by default, measured), pointless
      without multicast.
    - ``transport/link/tx/lease`` [ms]: ``args.lease_ms``, if given.
    - ``transport/shared_memory/enabled``: ``false`` unless the file configures ``shared_memory``
      (below, and BENCHMARKS.md, "Zenoh's shared memory off").

    ConfigError names the file when it cannot be read or parsed, and the flag when Zenoh refuses a value.
    """
    shm_configured = False
    if args.config_file is None:
        config = zenoh.Config()
    else:
        path = Path(args.config_file)
        if not path.is_file():
            raise ConfigError(f"--zenoh-config: no such file {str(path)!r}")
        try:
            config = zenoh.Config.from_file(str(path))
        except zenoh.ZError as exc:
            raise ConfigError(f"--zenoh-config: cannot load {str(path)!r}: {_zerror_text(exc)}") from None
        # (Zenoh's default is true, so whether the file set it shows in its text only)
        shm_configured = "shared_memory" in path.read_text(errors="replace")
    if args.mode is not None:
        _insert(config, "mode", args.mode, "--mode")
    if args.connect:
        _insert(config, "connect/endpoints", list(args.connect), "--connect")
    if args.listen:
        _insert(config, "listen/endpoints", list(args.listen), "--listen")
    if args.multicast_scouting:
        _insert(config, "scouting/multicast/enabled", True, "--multicast-scouting")
    elif not _is_set(config, "scouting/multicast/enabled"):
        _insert(config, "scouting/multicast/enabled", False, "--multicast-scouting")
    multicast = json.loads(config.get_json("scouting/multicast/enabled"))
    if multicast is False and not _is_set(config, "scouting/delay"):
        _insert(config, "scouting/delay", 0, "--multicast-scouting")
    if args.lease_ms is not None:
        _insert(config, "transport/link/tx/lease", args.lease_ms, "transport.lease_ms")
    if not shm_configured:
        # Zenoh 1.x has its shared-memory transport on by default, "lazy": a session sets up its 16 MiB pool
        # and maps its peers' segments at the first message over 3 kB it sends or takes, in a run's first
        # ticks (the world's batches and bundles). 32 processes on two cores then zeroed pages for tens of
        # milliseconds at once (perf: clear_page_erms), the world stepped its first ticks up to 180 ms late,
        # and 1.2-2.8 % of a 10 s run's vehicle-ticks were late, nearly all in its first 50 ticks; with it
        # off, 0.1-0.45 %. Our messages are a few kilobytes, which loopback TCP carries as cheaply
        _insert(config, "transport/shared_memory/enabled", False, "--zenoh-config")
    return config


def listen_endpoints(config: zenoh.Config) -> tuple[str, ...]:
    """The endpoints a session opened with ``config`` listens on: the configured list, or Zenoh's default
    for the configured mode (its per-mode map)."""
    value = json.loads(config.get_json("listen/endpoints"))
    if isinstance(value, dict):
        mode = json.loads(config.get_json("mode")) or "peer"
        value = value.get(mode) or []
    return tuple(value)


def free_loopback_endpoint() -> str:
    """``tcp/127.0.0.1:<port>`` with a port that was free a moment ago (the OS picks it)."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


LEAN_RUNTIME = (
    "(rx: (handover: app), acc: (handover: app), app: (worker_threads: 1), "
    "tx: (worker_threads: 1), net: (worker_threads: 1))"
)
"""The Zenoh runtime of every swarm process but ``swarm router``, unless ``ZENOH_RUNTIME`` is set: Zenoh's
receiving and accepting tasks run on its application runtime, and each runtime has one worker thread. A
message then crosses fewer threads between the socket and our callback. Measured here (BENCHMARKS.md,
"Zenoh's runtime, one worker"): one pair in lockstep 8.3-8.4x -> 9.3-10.6x real time, sensor-to-estimate
p99 1.9 -> 1.1-1.8 ms. A router in general keeps Zenoh's defaults: with one worker it forwarded a replay at
full speed slower than it came, so a recorder stopped at the replay's end missed a third of it. The
launcher's router carries the paced ticks of its own swarm, where lean measured faster, so it asks for it
(``open_session(..., lean=True)``). Handing ``tx`` or ``net`` over as well stalls a session (measured), so
they keep their own thread."""


def _zenoh_runtime(mode: str, lean: bool | None = None) -> tuple[str | None, bool]:
    """The ``ZENOH_RUNTIME`` for this process's first session in ``mode``, and whether it is ours to put in
    the environment: the environment's if set (the user's choice, ``'()'`` for Zenoh's defaults; not ours),
    else :data:`LEAN_RUNTIME` if ``lean`` (``None``: unless ``mode`` is a router; ours), else ``None``
    (Zenoh's defaults)."""
    user = os.environ.get("ZENOH_RUNTIME")
    if user is not None:
        return user, False
    if lean is None:
        lean = mode != "router"
    return (LEAN_RUNTIME, True) if lean else (None, False)


def open_session(args: ZenohArgs, lean: bool | None = None) -> zenoh.Session:
    """A Zenoh session opened with :func:`make_config` ``(args)``. Use it as a context manager, which closes
    it (``with open_session(args) as session:``), or close it in a ``finally``.

    Zenoh reads ``ZENOH_RUNTIME`` once per process, at its first session: that one runs
    :func:`_zenoh_runtime` ``(mode, lean)``'s, put in the environment only while Zenoh opens it, so that a
    child process (an agent the launcher starts) chooses its own by its own mode. ConfigError for a bad
    file or value, or a ``ZENOH_RUNTIME`` that Zenoh cannot parse; SwarmError naming the mode and endpoints
    when Zenoh cannot open (a client that reaches no router, a listen port in use)."""
    config = make_config(args)
    mode = json.loads(config.get_json("mode")) or "peer"
    runtime, ours = _zenoh_runtime(mode, lean)
    if ours:
        os.environ["ZENOH_RUNTIME"] = runtime
    try:
        session = zenoh.open(config)
    except zenoh.ZError as exc:
        where = f"connect {list(args.connect) or '-'}, listen {list(args.listen) or '-'}"
        raise SwarmError(f"cannot open a Zenoh {mode} session ({where}): {_zerror_text(exc)}") from None
    except BaseException as exc:  # a bad ZENOH_RUNTIME: Zenoh panics (PanicException, a BaseException)
        if type(exc).__name__ != "PanicException":
            raise
        raise ConfigError(f"Zenoh cannot open a session with ZENOH_RUNTIME={runtime!r}: {exc}") from None
    finally:
        if ours:
            del os.environ["ZENOH_RUNTIME"]
    _LOG.debug("zenoh session %s open with %s", session.zid(), args)
    return session


# ------------------------------------------------------------------------------------------ subscriptions


class HandlerErrors:
    """Rate-limited log of the exceptions a callback handler raised: the first one with its traceback at
    once, then at most one line per ``log_interval_s`` with the number since the previous line.
    Thread-safe; never raises."""

    def __init__(self, what: str, log_interval_s: float = 10.0, logger: logging.Logger | None = None) -> None:
        ok = isinstance(log_interval_s, int | float) and log_interval_s > 0 and math.isfinite(log_interval_s)
        if not ok:
            raise ConfigError(f"transport.log_interval_s must be a finite number > 0, got {log_interval_s!r}")
        self.what = what
        self.log_interval_s = float(log_interval_s)
        self._log = logger if logger is not None else _LOG
        self._lock = threading.Lock()
        self._total = 0
        self._pending = 0
        self._last_log_s: float | None = None

    def record(self, exc: BaseException) -> None:
        """Count ``exc`` (raised by the handler) and log it if this log's interval has passed."""
        try:
            now = time.monotonic()
            with self._lock:
                self._total += 1
                self._pending += 1
                if self._last_log_s is not None and now - self._last_log_s < self.log_interval_s:
                    return
                pending, total, first = self._pending, self._total, self._last_log_s is None
                self._pending, self._last_log_s = 0, now
            self._log.error(
                "%s raised %d time%s (total %d); last: %s: %s",
                self.what, pending, "" if pending == 1 else "s", total, type(exc).__name__, exc,
                exc_info=exc if first else None,
            )  # fmt: skip
        except Exception:  # logging itself failed: nothing more can be done on a Zenoh thread
            pass

    @property
    def total(self) -> int:
        """Exceptions raised so far."""
        with self._lock:
            return self._total


M = TypeVar("M", bound=Message)


def published_ns(sample: zenoh.Sample) -> int | None:
    """When ``sample`` was published [ns since the epoch, as ``time.time_ns()``]: its Zenoh timestamp (the
    publisher's hybrid logical clock at its ``put``, present when its session has ``timestamping`` on),
    ``None`` if its publisher did not stamp it."""
    ts = sample.timestamp
    return None if ts is None else ts.get_time_as_ntp64().as_nanos()


IMU_STAMP = "imu_published_ns"
"""The field of an estimate's Zenoh attachment (docs/protocol.md, "Estimate"): the publication stamp of the
``imu`` it was computed from [ns since the epoch] (:func:`published_ns` of that sample)."""


_IMU_STAMP_HEAD = b"\x81" + msgpack.packb(IMU_STAMP) + b"\xcf"  # a map of one entry, its value a uint 64


def imu_stamp_attachment(imu_ns: int) -> bytes:
    """An estimate's attachment: ``{"imu_published_ns": imu_ns}`` in msgpack (the value always as a uint 64,
    which any msgpack reader takes; built without a packer: it is on the estimate's path)."""
    return _IMU_STAMP_HEAD + imu_ns.to_bytes(8, "big")


def attached_imu_ns(sample: zenoh.Sample) -> int | None:
    """The ``imu_published_ns`` an estimate's sample carries as its attachment; ``None`` without one, or for
    one of anybody else's making (not a msgpack map with that field an integer in 0 .. 2^64 - 1)."""
    att = sample.attachment
    if att is None:
        return None
    try:
        obj = msgpack.unpackb(bytes(att))
    except Exception:
        return None
    ns = obj.get(IMU_STAMP) if isinstance(obj, dict) else None
    return ns if type(ns) is int and 0 <= ns < 2**64 else None


def _decoding(
    key: str,
    msg_type: type[M] | Keys,
    handler: Callable[..., Any],
    counter: DropCounter,
    log_interval_s: float,
    stamped: bool = False,
) -> Callable[[zenoh.Sample], None]:
    """The sample handler of :func:`subscribe_decoded` and :class:`QueuedSubscriber`: decode, count and drop
    what is invalid, hand the rest to ``handler`` (with ``stamped``, also the sample's :func:`published_ns`);
    never raises."""
    name = getattr(handler, "__qualname__", handler)
    errors = HandlerErrors(f"handler {name!s} on {key}", log_interval_s)
    if isinstance(msg_type, Keys):
        keys = msg_type

        def expected_type(key_str: str) -> type[Message] | None:
            parsed = keys.parse(key_str)
            return None if parsed is None else MESSAGE_FOR_KIND.get(parsed[0])

    elif isinstance(msg_type, type) and issubclass(msg_type, Message):
        fixed: type[Message] = msg_type

        def expected_type(key_str: str) -> type[Message] | None:
            return fixed

    else:
        raise TypeError(f"msg_type must be a Message class or a Keys, got {msg_type!r}")

    def on_sample(sample: zenoh.Sample) -> None:
        try:
            if sample.kind != zenoh.SampleKind.PUT:
                return
            key_str = str(sample.key_expr)
            cls = expected_type(key_str)
            if cls is None:
                counter.drop(key_str, "key: no message type is defined for this key")
                return
            msg = safe_decode(sample.payload, cls, key_str, counter)
            if msg is None:
                return
            if stamped:
                handler(key_str, msg, published_ns(sample))
            else:
                handler(key_str, msg)
        except Exception as exc:
            errors.record(exc)

    return on_sample


def subscribe_decoded(
    session: zenoh.Session,
    key: str,
    msg_type: type[M] | Keys,
    handler: Callable[[str, M], Any],
    counter: DropCounter,
    *,
    remote_only: bool = False,
    log_interval_s: float = 10.0,
    direct: bool = False,
    stamped: bool = False,
) -> zenoh.Subscriber:
    """Declare a callback subscriber on ``key`` (wildcards allowed) that hands valid messages to ``handler``.

    The callback decodes each sample with :func:`~swarm.transport.messages.safe_decode`: an invalid
    payload is counted in ``counter`` under its key (and logged at a limited rate) and never reaches the
    handler. ``handler(key, msg)`` gets the sample's key as a ``str`` and the decoded message, on Zenoh's
    thread for this subscriber (one thread per subscriber: samples of one publisher arrive in order; make
    the handler thread-safe). An exception from the handler is logged through :class:`HandlerErrors`
    (rate-limited) and later samples are still delivered; nothing is raised into Zenoh.

    ``msg_type`` is the message class expected on every key, or a :class:`~swarm.transport.keys.Keys`:
    then each sample's type comes from its key (``Keys.parse`` and ``MESSAGE_FOR_KIND``), for one
    wildcard subscriber such as ``keys.agent_topics(agent_id)``; a key outside the protocol is counted as
    a drop. ``remote_only`` ignores this session's own publications (``Locality.REMOTE``). DELETE samples
    carry no message and are ignored. Undeclared when the session closes (or by ``.undeclare()``).

    ``direct`` runs the callback on Zenoh's receiving thread (``Callback(indirect=False)``) instead of a
    Python thread of its own: for a process with many subscribers (an agent host) whose handlers are short
    and never block. One subscriber's samples still arrive in order.

    ``stamped`` calls ``handler(key, msg, published_ns)`` instead, with the sample's publication stamp
    (:func:`published_ns`; ``None`` when its publisher does not stamp).
    """
    on_sample = _decoding(key, msg_type, handler, counter, log_interval_s, stamped)
    origin = zenoh.Locality.REMOTE if remote_only else None
    callback = zenoh.handlers.Callback(on_sample, indirect=False) if direct else on_sample
    return session.declare_subscriber(key, callback, allowed_origin=origin)


QUEUE_CAPACITY = 256
"""Samples a :class:`QueuedSubscriber` keeps until drained; past that the oldest goes. At 100 samples a
second (an estimate every tick) that is 2.5 s without a drain: an agent's ranges, frames and target
estimates are stale by then."""


class QueuedSubscriber:
    """A subscriber whose samples wait in Zenoh's own queue until :meth:`drain`, which decodes them as
    :func:`subscribe_decoded` does and hands the valid ones to ``handler`` on the caller's thread.

    A callback subscriber wakes a Python thread of its own for every sample (the "wake tax" of BENCHMARKS.md
    on this VM: tens of microseconds each, and the GIL taken from whatever runs). Samples that are used
    only when something else comes need no such wake: a free-running agent fuses its ranges, frames and
    target estimates at its next ``imu`` (late fusion), so it drains them there. The queue is a ring of
    ``capacity`` samples (``zenoh.handlers.RingChannel``): a full one drops its oldest instead of blocking
    Zenoh's receiving thread. Thread-safe: Zenoh fills the queue on its own thread."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        msg_type: type[M] | Keys,
        handler: Callable[[str, M], Any],
        counter: DropCounter,
        *,
        capacity: int = QUEUE_CAPACITY,
        log_interval_s: float = 10.0,
        stamped: bool = False,
    ) -> None:
        """``stamped``: as :func:`subscribe_decoded`'s."""
        if not isinstance(capacity, int) or capacity < 1:
            raise ConfigError(f"a queued subscriber's capacity must be an integer >= 1, got {capacity!r}")
        self._on_sample = _decoding(key, msg_type, handler, counter, log_interval_s, stamped)
        self._sub = session.declare_subscriber(key, zenoh.handlers.RingChannel(capacity))

    def drain(self) -> int:
        """Hand every sample waiting to the handler, oldest first; the number taken. Never raises (a
        subscriber whose session closed has nothing waiting)."""
        n = 0
        while True:
            try:
                sample = self._sub.try_recv()
            except zenoh.ZError:  # undeclared, or its session closed
                return n
            if sample is None:
                return n
            self._on_sample(sample)
            n += 1

    def undeclare(self) -> None:
        self._sub.undeclare()


def declare_liveliness(
    session: zenoh.Session, keys: Keys, role: str, process_id: str
) -> zenoh.LivelinessToken:
    """Declare this process's liveliness token ``<ns>/alive/<role>/<id>`` (docs/protocol.md).

    **Keep the returned token** (``token = declare_liveliness(...)``): Zenoh undeclares it as soon as
    Python drops it (measured; a callback subscriber, by contrast, lives until its session closes). It
    then lives until ``.undeclare()`` or until the session closes, or, for a process that dies, until its
    links drop (milliseconds after a kill, about a lease after a hang). ConfigError for a role or id that
    is not one key chunk."""
    return session.liveliness().declare_token(keys.alive(role, process_id))


def watch_liveliness(
    session: zenoh.Session,
    keys: Keys,
    on_change: Callable[[str, str, bool], Any],
    *,
    history: bool = True,
    log_interval_s: float = 10.0,
) -> zenoh.Subscriber:
    """Watch every liveliness token of ``keys``'s swarm: ``on_change(role, process_id, alive)`` with
    ``alive`` True when a token appears (a join) and False when it goes (a loss), on a Zenoh thread.
    ``history`` also reports the tokens declared before this call. Keys that are not ``<ns>/alive/<role>/
    <id>`` are ignored; handler exceptions are logged (rate-limited), never raised into Zenoh."""
    name = getattr(on_change, "__qualname__", on_change)
    errors = HandlerErrors(f"liveliness handler {name!s}", log_interval_s)

    def on_sample(sample: zenoh.Sample) -> None:
        try:
            parsed = keys.parse_alive(str(sample.key_expr))
            if parsed is None:
                _LOG.debug("ignoring liveliness key %s", sample.key_expr)
                return
            on_change(parsed[0], parsed[1], sample.kind == zenoh.SampleKind.PUT)
        except Exception as exc:
            errors.record(exc)

    return session.liveliness().declare_subscriber(keys.alive_all(), on_sample, history=history)
