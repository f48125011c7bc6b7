"""Command line of the world process: ``python -m swarm.world`` and ``swarm world``."""

from __future__ import annotations

import argparse
import threading

from swarm.errors import ConfigError

DESCRIPTION = (
    "The simulated world: truth dynamics and on-board sensors (gyro, AHRS, camera) of every vehicle, "
    "published over Zenoh; applies each agent's command. Prints 'world <id> ready' once subscribed."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    from swarm.cli.args import add_world_timeouts
    from swarm.transport.process import add_process_arguments

    add_process_arguments(p)
    add_world_timeouts(p)
    p.add_argument(
        "--clock-every", type=int, default=10, metavar="TICKS",
        help="publish world/clock every this many ticks (default 10)",
    )  # fmt: skip


def run(args: argparse.Namespace, stop: threading.Event | None = None) -> int:
    from swarm.transport.process import keys_from, scenario_from, zenoh_args
    from swarm.transport.session import open_session
    from swarm.world.process import WorldProcess

    if args.clock_every < 1:
        raise ConfigError(f"--clock-every must be an integer >= 1, got {args.clock_every!r}")
    sc = scenario_from(args)
    stop = stop if stop is not None else threading.Event()
    with open_session(zenoh_args(args)) as session:
        proc = WorldProcess(
            sc, args.seed, session, keys_from(args), args.clock, stop, step_timeout_s=args.step_timeout,
            start_timeout_s=args.start_timeout, clock_every=args.clock_every,
        )  # fmt: skip
        end = proc.run()
    return 0 if end["reason"] != "not_started" else 1


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("world", help="run the simulated world process", description=DESCRIPTION)
    add_arguments(p)
    p.set_defaults(func=run)


def main(argv: list[str] | None = None) -> int:
    from swarm.transport.process import process_main

    return process_main("swarm world", DESCRIPTION, add_arguments, run, argv)
