"""The ``swarm`` command line: one entry point, one module per sub-command."""

from __future__ import annotations

import argparse
import logging
import sys

from swarm.errors import SwarmError
from swarm.stacks import enable_stack_dumps


def build_parser() -> argparse.ArgumentParser:
    from agents import cli as agent_cli
    from agents import navigator
    from mothership import cli as mothership_cli
    from swarm.cli import (
        analyze,
        bench,
        compile,
        dashboard,
        demo,
        fault,
        fit,
        foxglove_bridge,
        importer,
        launch,
        montecarlo,
        record,
        replay,
        router,
        sim,
    )
    from swarm.world import cli as world_cli

    parser = argparse.ArgumentParser(
        prog="swarm",
        description="TPODS swarm: robust proximity operations with Markov-model guidance switching.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in (
        demo,
        sim,
        montecarlo,
        analyze,
        replay,
        importer,
        fit,
        navigator,
        record,
        foxglove_bridge,
        bench,
        compile,
        launch,
        router,
        fault,
        dashboard,
        world_cli,
        mothership_cli,
        agent_cli,
    ):
        module.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    enable_stack_dumps()  # kill -USR1: every thread's stack on stderr (swarm/stacks.py)
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.func(args) or 0)
    except SwarmError as exc:  # user-facing errors: one clear line, no traceback
        print(f"swarm: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
