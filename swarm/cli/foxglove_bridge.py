"""``swarm foxglove``: serve a running swarm to Foxglove over its WebSocket protocol (issue 16).

Subscribes to every key of the swarm's namespace and logs each sample on a Foxglove channel of that key
(``msgpack``), plus the views of ``swarm/transport/foxglove_views.py`` (``/tf`` poses, ``/events`` log,
``/scene`` anchors), through ``foxglove-sdk``'s WebSocket server. Open Foxglove, "Open connection",
Foxglove WebSocket, ``ws://HOST:PORT``. Prints ``foxglove bridge on ws://HOST:PORT`` once serving; runs
until SIGINT or SIGTERM.
"""

from __future__ import annotations

import argparse
import queue
import signal
import threading

from swarm.transport.session import add_zenoh_arguments

DESCRIPTION = __doc__.split("\n\n")[1]


def _port(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--port must be an integer in 1..65535, got {text!r}") from None
    if not 1 <= v <= 65535:
        raise argparse.ArgumentTypeError(f"--port must be an integer in 1..65535, got {text!r}")
    return v


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "foxglove", help="serve a running swarm to Foxglove (WebSocket)", description=DESCRIPTION
    )
    p.add_argument("--port", type=_port, default=8765, help="WebSocket port (default 8765)")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1)")
    p.add_argument("--namespace", default="tpods", help="key namespace of the swarm (default tpods)")
    add_zenoh_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import foxglove

    from swarm.transport.foxglove_views import SwarmViews
    from swarm.transport.keys import Keys
    from swarm.transport.recording import swarm_time_ns
    from swarm.transport.session import open_session, zenoh_args_from

    keys = Keys(args.namespace)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    ctx = foxglove.Context()
    server = foxglove.start_server(name=f"tpods-swarm {args.namespace}", host=args.host, port=args.port,
                                   context=ctx)  # fmt: skip
    views = SwarmViews(ctx, keys)
    samples: queue.SimpleQueue = queue.SimpleQueue()
    try:
        with open_session(zenoh_args_from(args)) as session:
            sub = session.declare_subscriber(
                keys.everything(), lambda s: samples.put((str(s.key_expr), s.payload.to_bytes()))
            )
            print(f"foxglove bridge on ws://{args.host}:{server.port} ({keys.everything()})", flush=True)
            last_ns = 0
            while not stop.is_set():
                try:
                    key, payload = samples.get(timeout=0.1)
                except queue.Empty:
                    continue
                last_ns = swarm_time_ns(payload, last_ns)
                views.handle(key, payload, last_ns)
            sub.undeclare()
    finally:
        server.stop()
    return 0
