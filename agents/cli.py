"""Command line of the agent process: ``python -m agents`` and ``swarm agent``."""

from __future__ import annotations

import argparse
import threading

DESCRIPTION = (
    "One vehicle's on-board software: subscribes its sensors (and its target's estimate), runs estimator, "
    "switcher, guidance and control, publishes estimate, guidance, command and events. Prints "
    "'agent <id> ready' once subscribed."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    from swarm.transport.process import add_process_arguments

    p.add_argument("--id", required=True, help="the vehicle this agent flies (a vehicle id of the scenario)")
    p.add_argument(
        "--rejoin",
        action="store_true",
        help="join a run in progress: re-initialise from the sensors (a restarted agent)",
    )
    add_process_arguments(p)


def run(args: argparse.Namespace, stop: threading.Event | None = None) -> int:
    from agents.process import AgentProcess
    from swarm.transport.keys import check_id
    from swarm.transport.process import keys_from, scenario_from, zenoh_args
    from swarm.transport.session import open_session

    check_id(args.id, "--id")
    sc = scenario_from(args)
    policy = args.policy or sc.policy
    stop = stop if stop is not None else threading.Event()
    with open_session(zenoh_args(args)) as session:
        proc = AgentProcess(
            sc, args.id, args.seed, policy, session, keys_from(args), args.clock, stop, rejoin=args.rejoin
        )
        proc.run()
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("agent", help="run one vehicle's agent process", description=DESCRIPTION)
    add_arguments(p)
    p.set_defaults(func=run)


def main(argv: list[str] | None = None) -> int:
    from swarm.transport.process import process_main

    return process_main("swarm agent", DESCRIPTION, add_arguments, run, argv)
