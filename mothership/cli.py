"""Command line of the mothership process: ``python -m mothership`` and ``swarm mothership``."""

from __future__ import annotations

import argparse
import threading

DESCRIPTION = (
    "The mothership: its UWB anchors (published on mothership/anchors, answered to queries) and the "
    "simulated UWB radio network that ranges every vehicle's tag from the world's truth. Prints "
    "'mothership mothership ready' once subscribed."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    from swarm.transport.process import add_process_arguments

    add_process_arguments(p, clock=False)
    p.add_argument(
        "--rejoin",
        action="store_true",
        help="join a run in progress (a restarted mothership)",
    )
    p.add_argument(
        "--batch", action="store_true",
        help="for agent hosts (swarm launch passes it with --vehicles-per-process > 1): take the world's "
        "truth as TruthBatch messages on world/truth (a world run with --batch), and send every vehicle's "
        "range of a UWB slot as one UwbBatch on mothership/uwb, which the hosts split",
    )  # fmt: skip


def run(args: argparse.Namespace, stop: threading.Event | None = None) -> int:
    from mothership.process import MothershipProcess
    from swarm.transport.process import keys_from, scenario_from, zenoh_args
    from swarm.transport.session import open_session

    sc = scenario_from(args)
    stop = stop if stop is not None else threading.Event()
    with open_session(zenoh_args(args)) as session:
        MothershipProcess(
            sc, args.seed, session, keys_from(args), stop, rejoin=args.rejoin, batch=args.batch
        ).run()
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "mothership", help="run the mothership process (anchors, UWB)", description=DESCRIPTION
    )
    add_arguments(p)
    p.set_defaults(func=run)


def main(argv: list[str] | None = None) -> int:
    from swarm.transport.process import process_main

    return process_main("swarm mothership", DESCRIPTION, add_arguments, run, argv)
