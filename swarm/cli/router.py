"""``swarm router --listen ENDPOINT``: a Zenoh router for a swarm spread over several machines.

A Python Zenoh session in router mode (docs/protocol.md, "Processes and topology"): clients that connect
to it form a star instead of the full mesh peers gossip into; it routes, stamps timestamps and enforces
whatever TLS, authentication and access control its ``--zenoh-config`` file sets. It costs one hop
(measured peer to peer RTT 109 us, through the router 253 us). The standard ``zenohd`` is a drop-in
replacement.

Once listening it prints one line, ``router listening on <endpoint> ...``, on stdout (flushed), so that a
launcher or a test can wait for it; it then runs until SIGINT or SIGTERM, closes its session and exits 0.
Multicast scouting is off unless ``--multicast-scouting``. One router serves any number of swarms: they
differ by key namespace. ``--cpu-latency 0`` holds the CPU wake-up latency request of ``swarm launch`` on the
router's machine (:mod:`swarm.cpu_latency`): the RTT through a router halved with it here (BENCHMARKS.md,
"Warm CPUs on request").
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

from swarm import cpu_latency
from swarm.errors import SwarmError
from swarm.stacks import enable_stack_dumps
from swarm.transport.session import (
    add_zenoh_arguments,
    listen_endpoints,
    make_config,
    open_session,
    zenoh_args_from,
)

_LOG = logging.getLogger("swarm.cli.router")  # not __name__: "__main__" under python -m

READY_PREFIX = "router listening on "
"""Start of the line printed once the router listens; the endpoints follow, separated by spaces."""

_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_DESCRIPTION = (
    "Run a Zenoh router (a Python session in router mode) that swarm processes on other machines connect "
    "to in client mode. Prints 'router listening on <endpoints>' once up; runs until SIGINT or SIGTERM."
)


def _add_arguments(p: argparse.ArgumentParser) -> None:
    add_zenoh_arguments(p, mode=False)
    cpu_latency.add_argument(p)  # a router on a machine of its own forwards every tick's messages
    p.epilog = (
        "Without --listen: the config file's endpoints, else tcp/[::]:7447 (every interface). "
        "--connect links this router to other routers."
    )


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "router",
        help="run a Zenoh router that clients on other machines connect to",
        description=_DESCRIPTION,
    )
    _add_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace, stop: threading.Event | None = None) -> int:
    """Run the router of the parsed ``args`` until ``stop`` is set; with ``stop=None`` (the command line),
    until SIGINT or SIGTERM, whose handlers it installs in the main thread and restores on return. Returns
    0 after a clean close; ConfigError / SwarmError if the session cannot be configured or opened."""
    zargs = zenoh_args_from(args, mode="router")
    endpoints = listen_endpoints(make_config(zargs))
    previous: dict[int, object] = {}
    if stop is None:
        stop = threading.Event()
        event = stop

        def on_signal(signum: int, _frame: object) -> None:
            _LOG.info("router: %s, closing", signal.Signals(signum).name)
            event.set()

        for sig in _STOP_SIGNALS:
            previous[sig] = signal.signal(sig, on_signal)
    try:
        with cpu_latency.hold(getattr(args, "cpu_latency", None)), open_session(zargs) as session:
            print(READY_PREFIX + " ".join(endpoints), flush=True)
            _LOG.info("router %s up (connect %s)", session.zid(), list(zargs.connect) or "-")
            while not stop.wait(1.0):
                pass
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)  # type: ignore[arg-type]
    _LOG.info("router closed")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m swarm.cli.router``: the same as ``swarm router``."""
    enable_stack_dumps()  # kill -USR1: every thread's stack on stderr (swarm/stacks.py)
    parser = argparse.ArgumentParser(prog="swarm router", description=_DESCRIPTION)
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    _add_arguments(parser)
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        return run(args)
    except SwarmError as exc:
        print(f"swarm router: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
