"""``swarm dashboard SCENARIO``: the Viser web dashboard of a running swarm, or with ``--open FILE.mcap``
of a recording (the ``dashboard`` package; the same as ``python -m dashboard``)."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    from dashboard.cli import DESCRIPTION, add_arguments

    p = sub.add_parser(
        "dashboard",
        help="serve the web dashboard of a running swarm or of a recording (Viser)",
        description=DESCRIPTION,
    )
    add_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from dashboard.cli import run as run_dashboard

    return run_dashboard(args)
