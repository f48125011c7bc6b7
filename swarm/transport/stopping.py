"""A clean stop: the swarm's processes stop on SIGINT or SIGTERM without errors, tracebacks or false alarms.

A stop is not a fault. When ``swarm launch`` stops a swarm (Ctrl-C, SIGTERM, the end of a run, the next
run of ``--repeat``), it does so in an order that no process can mistake for a failure
(docs/protocol.md, "Stopping a swarm"):

0. it kills the processes still starting (no ready line yet: no token, no run state, and no signal
   handled while their kernels load);
1. it announces the stop: a ``stopping`` :class:`~swarm.transport.messages.Event` on ``world/event``
   (``{"why": ...}``), which every process that watches a peer hears (the agents, the mothership, the
   dashboard);
2. :data:`ANNOUNCE_S` later, it stops the world (SIGTERM), the source of every tick: once it is gone
   nothing more flows, so no process is left waiting for a sample or a command; the world ends its run
   (``run_end`` ``stopped``, clock ``stopped``) and closes its session;
3. then every other process (the mothership, the agents, the dashboard) at once.

A process that is stopping (:class:`Stopping`: its own stop signal, or the launcher's announcement) says
that a peer's going is a stop, at INFO (``world stopped``), not a loss; and a publication that fails
because its own session closed meanwhile (a Zenoh callback thread still publishing while the main thread
closes the session raises ``zenoh.ZError``) is no error then (:meth:`Stopping.quiet`). Without a stop, a
peer that goes is lost: a SIGKILLed or hung process keeps today's warnings and its restart.

**Ctrl-C in a terminal** sends SIGINT to the terminal's foreground process group. The launcher starts
each child in a session of its own (:mod:`swarm.cli.supervisor`), so only the launcher gets it, and it
stops the swarm in the order above. A child that gets a SIGINT all the same (a wrapper that forwards the
signal to every process, ``kill -INT`` of each group) while the launcher that started it is alive
(:func:`launched`) leaves the stop to the launcher: it is stopping from then on (quiet), and stops at the
launcher's SIGTERM, in the swarm's order; a second SIGINT, or :data:`LEFT_TO_LAUNCHER_S` without one,
stops it at once. A process started by hand stops at its first SIGINT, as before.
"""

from __future__ import annotations

import logging
import os
import signal
import threading

import zenoh

__all__ = [
    "ANNOUNCE_S",
    "LAUNCHER_ENV",
    "LEFT_TO_LAUNCHER_S",
    "SIGNAL_POLL_S",
    "STOPPING",
    "StopFlag",
    "Stopping",
    "install_stop_signals",
    "launched",
    "process_name",
    "wait_for_stop",
]

_LOG = logging.getLogger("swarm.stop")

STOPPING = "stopping"
"""The kind of the launcher's :class:`~swarm.transport.messages.Event` on ``world/event`` that announces a
stop (``data``: ``{"why": "SIGINT" | "SIGTERM" | "run over" | "next run" | ...}``). Event kinds are an open
set: receivers that do not know it ignore it (no schema version change, docs/protocol.md)."""

ANNOUNCE_S = 0.2
"""How long the launcher waits between its ``stopping`` event and the first SIGTERM [s]: the event crosses
loopback in well under a millisecond, but each receiver takes it on a Python thread of its own, which a
loaded two-core machine may run tens of milliseconds later; the stop itself takes longer than this."""

SIGNAL_POLL_S = 0.1
"""The longest a main thread waiting for its stop flag stays blocked at once [s] (:func:`wait_for_stop`)."""

LAUNCHER_ENV = "SWARM_LAUNCHER_PID"
"""The environment variable in which the launcher gives its children its pid (:func:`launched`)."""

LEFT_TO_LAUNCHER_S = 15.0
"""A launched child that got SIGINT stops by itself after this long [s] if its launcher has not stopped it
(it stops the world first, waits up to its grace for it, then the rest: a few seconds)."""


def process_name(role: str, process_id: str) -> str:
    """How a log line names a process: its role, and its id when that says more (``world``, ``world w1``,
    ``agent chaser``), never ``world world``."""
    return role if process_id in ("", role) else f"{role} {process_id}"


def launched() -> bool:
    """Whether this process was started by a launcher that is still its parent (:data:`LAUNCHER_ENV`)."""
    return os.environ.get(LAUNCHER_ENV) == str(os.getppid())


def wait_for_stop(stop: threading.Event, alive=None) -> None:
    """Block the main thread until ``stop`` is set (or ``alive()``, when given, is false), in waits of
    :data:`SIGNAL_POLL_S`, never in one.

    A signal may be delivered to any thread of the process, and a Zenoh process has many native ones; the
    C handler then only notes it, and Python runs the handler (which sets ``stop``) on the main thread the
    next time that thread runs Python code. A main thread blocked in one ``stop.wait()`` never does: the
    process sat out its launcher's grace and was SIGKILLed (seen: ``agent/chaser did not stop within 3.0 s``
    on a loaded machine, its main thread in ``stop.wait()``)."""
    while not stop.wait(SIGNAL_POLL_S):
        if alive is not None and not alive():
            return


class StopFlag(threading.Event):
    """A process's stop flag (set: stop now), with :attr:`told`: its swarm is stopping (a SIGINT left to the
    launcher, or the launcher's announcement heard), which every :class:`Stopping` made from it shares."""

    def __init__(self) -> None:
        super().__init__()
        self.told = threading.Event()


class Stopping:
    """Whether the swarm of this process is stopping: its ``stop`` flag is set, or it was told
    (:meth:`tell`: the launcher's ``stopping`` event, or a SIGINT left to the launcher). Thread-safe.

    Made from a :class:`StopFlag`, it shares the flag's :attr:`~StopFlag.told` (the signal handler's); from
    a plain ``threading.Event`` (a process run in a test) it has its own."""

    def __init__(self, stop: threading.Event) -> None:
        self.stop = stop
        self.told: threading.Event = getattr(stop, "told", None) or threading.Event()

    def __bool__(self) -> bool:
        return self.stop.is_set() or self.told.is_set()

    def tell(self) -> None:
        self.told.set()

    def hear(self, kind: str) -> bool:
        """An event of ``kind`` on ``world/event``: the launcher's :data:`STOPPING` tells; whether it did."""
        if kind != STOPPING:
            return False
        self.tell()
        return True

    def quiet(self, exc: BaseException) -> bool:
        """Whether ``exc`` is a publication into this process's closing session while it stops (a
        ``zenoh.ZError`` once stopping): no error, only a debug line. Any other exception, or a ZError in a
        running swarm, is what it was before."""
        if isinstance(exc, zenoh.ZError) and self:
            _LOG.debug("not published while stopping: %s", exc)
            return True
        return False

    def gone(self, log: logging.Logger, name: str, lost: str, *args: object) -> bool:
        """Log that peer ``name`` went: ``<name> stopped`` at INFO while stopping, else ``lost % args`` at
        WARNING (a loss). Whether it was a stop."""
        if self:
            log.info("%s stopped (the swarm is stopping)", name)
            return True
        log.warning(lost, *args)
        return False


def install_stop_signals(stop: threading.Event, log: logging.Logger | None = None) -> dict[int, object]:
    """SIGTERM sets ``stop``; SIGINT too, unless this process is :func:`launched`: then it is told that its
    swarm is stopping (``stop.told``, a :class:`StopFlag`'s) and the launcher, which got the same Ctrl-C,
    stops it in the swarm's order (module docstring); a second SIGINT, or :data:`LEFT_TO_LAUNCHER_S`
    without the launcher's SIGTERM, sets ``stop``. Main thread only; returns the previous handlers."""
    log = log if log is not None else _LOG
    told = getattr(stop, "told", None)
    fallback: list[threading.Timer] = []

    def on_signal(signum: int, _frame: object) -> None:
        name = signal.Signals(signum).name
        if signum == signal.SIGINT and told is not None and not fallback and launched():
            told.set()
            log.info("%s: the launcher stops the swarm, this process in its turn", name)
            timer = threading.Timer(LEFT_TO_LAUNCHER_S, stop.set)
            timer.daemon = True
            timer.start()
            fallback.append(timer)
            return
        if not stop.is_set():
            log.info("%s: stopping", name)
        stop.set()

    return {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
