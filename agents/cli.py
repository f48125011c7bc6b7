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

    p.add_argument(
        "--id",
        required=True,
        help="the vehicle this agent flies (a vehicle id of the scenario); several, comma-separated, make "
        "this process an agent host: their agents on one Zenoh session, stepped by one thread, keys and "
        "liveliness per vehicle",
    )
    p.add_argument(
        "--rejoin",
        action="store_true",
        help="join a run in progress: re-initialise from the sensors (a restarted agent)",
    )
    add_process_arguments(p)


def run(args: argparse.Namespace, stop: threading.Event | None = None) -> int:
    import logging

    from agents.host import AgentHost
    from agents.process import AgentProcess
    from swarm.transport.process import keys_from, scenario_from, zenoh_args
    from swarm.transport.session import open_session

    ids = hosted_ids(args.id, "vehicle")
    sc = scenario_from(args)
    policy = args.policy or sc.policy
    stop = stop if stop is not None else threading.Event()
    with open_session(zenoh_args(args)) as session:
        keys, hosted = keys_from(args), len(ids)
        # the vehicles' tick assemblers share a condition and a set of those with news: one thread steps all
        cond, ready = threading.Condition(), set()
        procs = [AgentProcess(sc, vid, args.seed, policy, session, keys, args.clock, stop, rejoin=args.rejoin,
                              hosted=hosted, cond=cond, ready=ready) for vid in ids]  # fmt: skip
        try:
            AgentHost(procs, session, keys, stop).run()
        except Exception as exc:  # logged with the vehicle; its supervisor restarts every hosted vehicle
            logging.getLogger("agents").error("agent host of %s failed: %s", ",".join(ids), exc)
            stop.set()
            return 1
        return 0


def hosted_ids(text: str, noun: str) -> list[str]:
    """``--id a,b,...``: the ids of the vehicles this process flies (several: an agent host), each a valid
    id, none twice; ConfigError naming ``--id`` otherwise."""
    from swarm.errors import ConfigError
    from swarm.transport.keys import check_id

    ids = text.split(",")
    for vid in ids:
        check_id(vid, "--id")
    if len(set(ids)) != len(ids):
        raise ConfigError(f"--id names a {noun} twice: {text!r}")
    return ids


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("agent", help="run one vehicle's agent process", description=DESCRIPTION)
    add_arguments(p)
    p.set_defaults(func=run)


def main(argv: list[str] | None = None) -> int:
    from swarm.transport.process import process_main

    return process_main("swarm agent", DESCRIPTION, add_arguments, run, argv)
