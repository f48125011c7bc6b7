"""A ``swarm`` command run in the test's own process: what a started ``python -m swarm.cli.main`` would
do, without the ~1.6 s of CPU a Python start costs."""

from __future__ import annotations


def swarm_exit_status(argv: list[str]) -> int:
    """The exit status of ``swarm ARGV`` (:func:`swarm.cli.main.main`), argparse's own refusals
    (``SystemExit``) included."""
    from swarm.cli.main import main

    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code
