"""``swarm record FILE.mcap``: record every message of a running swarm to an MCAP file (issue 16).

Connects to the swarm (``--connect`` the launcher's or a router's endpoint), subscribes to the namespace's
every key and writes each sample byte for byte, one channel per key (``swarm/transport/recording.py`` says
exactly what goes where). Prints ``recording <file>`` once subscribed; stops on SIGINT or SIGTERM, after
``--duration`` seconds, or with ``--until-end`` once the world's ``run_end`` event is in the file, and then
finishes the file. Read it back with any MCAP reader (Foxglove Studio, the ``mcap`` CLI or Python package);
``swarm replay FILE.mcap`` publishes it again.
"""

from __future__ import annotations

import argparse
import signal
import threading
import time
from pathlib import Path

from swarm.args import positive_float
from swarm.transport.session import add_zenoh_arguments

DESCRIPTION = __doc__.split("\n\n")[1]


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="record a running swarm to an MCAP file", description=DESCRIPTION)
    p.add_argument("file", type=Path, metavar="FILE.mcap", help="the MCAP file to write (replaced)")
    p.add_argument("--namespace", default="tpods", help="key namespace of the swarm (default tpods)")
    p.add_argument("--duration", type=positive_float("--duration"), default=None, metavar="S",
                   help="stop after this many seconds of wall time")  # fmt: skip
    p.add_argument("--until-end", action="store_true", help="stop once the run's run_end event is recorded")
    add_zenoh_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from swarm.transport.keys import Keys
    from swarm.transport.recording import Recorder, check_mcap_path
    from swarm.transport.session import open_session, zenoh_args_from

    check_mcap_path(args.file, "FILE.mcap")
    keys = Keys(args.namespace)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    with open_session(zenoh_args_from(args)) as session:
        rec = Recorder(session, keys, args.file)

        def ready() -> None:
            print(f"recording {args.file} ({keys.everything()})", flush=True)

        def watch() -> None:
            t_end = None if args.duration is None else time.monotonic() + args.duration
            while not stop.is_set():
                if t_end is not None and time.monotonic() >= t_end:
                    break
                if args.until_end and rec.run_end_seen.is_set():
                    time.sleep(0.5)  # the summaries and last events after run_end
                    break
                time.sleep(0.05)
            stop.set()

        threading.Thread(target=watch, daemon=True).start()
        counts = rec.run(stop, ready)
    total = sum(counts.values())
    print(f"recorded {total} messages on {len(counts)} keys to {args.file}", flush=True)
    return 0
