"""Command line of the world process: ``python -m swarm.world`` and ``swarm world``."""

from __future__ import annotations

import argparse
import sys
import threading

from swarm.errors import ConfigError

DESCRIPTION = (
    "The simulated world: truth dynamics and on-board sensors (gyro, AHRS, camera) of every vehicle, "
    "published over Zenoh; applies each agent's command. Prints 'world <id> ready' once subscribed."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    from swarm.args import add_world_timeouts
    from swarm.transport.process import (
        add_checkpoint_arguments,
        add_clock_every,
        add_process_arguments,
        clock_arg,
    )

    add_process_arguments(p)
    add_world_timeouts(p)
    p.add_argument(
        "--pace", type=clock_arg, default=None, metavar="realtime|scaled:N",
        help="a lockstep world paced to this clock: every command waited for (the run is the unpaced one), "
        "never ahead of the wall clock, to watch it or to leave a machine's cores to others",
    )  # fmt: skip
    p.add_argument(
        "--batch", action="store_true",
        help="for agent hosts (swarm launch passes it with --vehicles-per-process > 1): every vehicle's imu "
        "of a tick as one ImuBatch on world/imu and the chasers' camera frames as one VisionBatch on "
        "world/vision, which the hosts split, and its truth as one TruthBatch on world/truth for the "
        "mothership (the per-vehicle truths only while a viewer subscribes)",
    )  # fmt: skip
    p.add_argument(
        "--no-bundles", dest="bundles", action="store_false",
        help="lockstep: publish each sample on its own key at its tick, not the ticks up to the next command "
        "awaited in one Bundle per receiver (agent/<id>/bundle, world/bundle; docs/protocol.md \"Bundles\": "
        "a free-running, paced or --batch world never bundles)",
    )  # fmt: skip
    add_clock_every(p)
    add_checkpoint_arguments(
        p,
        "the world's complete state to DIR/world.ckpt at every tick, so that a restart with --resume "
        "continues the run",
        "continue the run from the checkpoint in --checkpoint-dir (announced as "
        "world_resumed); a missing checkpoint is an error too",
    )


def run(args: argparse.Namespace, stop: threading.Event | None = None) -> int:
    from swarm.transport import checkpoint
    from swarm.transport.process import check_pace, keys_from, scenario_from, zenoh_args
    from swarm.transport.session import open_session
    from swarm.world.process import WorldProcess

    if args.resume and args.checkpoint_dir is None:
        raise ConfigError("--resume needs --checkpoint-dir (the directory of the checkpoint to resume)")
    check_pace(args.clock, args.pace)
    sc = scenario_from(args)
    stop = stop if stop is not None else threading.Event()
    resume = None
    try:
        if args.resume:  # read before joining the swarm: a bad checkpoint never shows up as a world
            resume = checkpoint.load(checkpoint.checkpoint_path(args.checkpoint_dir))
        with open_session(zenoh_args(args)) as session:
            proc = WorldProcess(
                sc, args.seed, session, keys_from(args), args.clock, stop, step_timeout_s=args.step_timeout,
                start_timeout_s=args.start_timeout, clock_every=args.clock_every,
                checkpoint_dir=args.checkpoint_dir, resume=resume, pace=args.pace, batch=args.batch,
                bundles=args.bundles,
            )  # fmt: skip
            end = proc.run()
    except checkpoint.CheckpointError as exc:
        print(f"swarm world: error: {exc}; not resuming", file=sys.stderr, flush=True)
        return checkpoint.EXIT_BAD_CHECKPOINT
    return 0 if end["reason"] != "not_started" or stop.is_set() else 1  # (a stop is no failure)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("world", help="run the simulated world process", description=DESCRIPTION)
    add_arguments(p)
    p.set_defaults(func=run)


def main(argv: list[str] | None = None) -> int:
    from swarm.transport.process import process_main

    return process_main("swarm world", DESCRIPTION, add_arguments, run, argv)
