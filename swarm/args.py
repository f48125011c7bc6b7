"""Argument types and scenario flags that the ``swarm`` commands and the processes share.

Each type names the flag and the value it refuses. This module sits in the scenario layer
(``docs/architecture.md``), below the runners, the transport and the command line, so that any of them may
use it without an import cycle."""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable
from pathlib import Path


def _checked(flag: str, convert: Callable[[str], float], ok: Callable[[float], bool], what: str):
    """An argparse type: ``convert(text)`` if it parses and ``ok`` holds, else an error naming ``flag``,
    ``what`` it must be and the text given."""

    def parse(text: str):
        try:
            v = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} must be {what}, got {text!r}") from None
        if not ok(v):
            raise argparse.ArgumentTypeError(f"{flag} must be {what}, got {text!r}")
        return v

    return parse


def positive_float(flag: str) -> Callable[[str], float]:
    """An argparse type: a finite number > 0 (``--timeout 2.5``)."""
    return _checked(flag, float, lambda v: math.isfinite(v) and v > 0, "a finite number > 0")


def positive_int(flag: str) -> Callable[[str], int]:
    """An argparse type: an integer > 0 (``--jobs 2``, ``--runs 50``)."""
    return _checked(flag, int, lambda v: v > 0, "an integer > 0")


def count(flag: str) -> Callable[[str], int]:
    """An argparse type: an integer >= 0 (``--max-restarts 3``)."""
    return _checked(flag, int, lambda v: v >= 0, "an integer >= 0")


def output_file(flag: str, dash: bool = False) -> Callable[[str], Path]:
    """An argparse type: a file to write at the end of a run (``--json FILE``), checked before the run, so
    that a run of minutes is not lost to a typo: its folder must exist and be writable, and it must not be a
    folder itself (``dash``: ``-`` passes, for a flag whose ``-`` means none). The writer still reports an
    error of its own (a full disk)."""

    def parse(text: str) -> Path:
        p = Path(text)
        if dash and text == "-":
            return p
        folder = p.parent  # (a bare name's is ".")
        if p.is_dir():  # ("" is "." too)
            raise argparse.ArgumentTypeError(f"{flag} must name a file to write, got {text!r} (a folder)")
        if not folder.is_dir():
            raise argparse.ArgumentTypeError(f"{flag}: no such folder {str(folder)!r} for {text!r}")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise argparse.ArgumentTypeError(f"{flag}: folder {str(folder)!r} is not writable, for {text!r}")
        return p

    return parse


def add_output_file(
    p, flag: str, help: str, *, metavar: str = "FILE", default=None, dash: bool = False
) -> None:
    """Add ``flag``, a file written at the end of the run, checked when the command line is read
    (:func:`output_file`)."""
    p.add_argument(flag, type=output_file(flag, dash), default=default, metavar=metavar, help=help)


SEED_LIMIT = 2**63
"""Seeds are integers in ``0 .. 2**63 - 1``: numpy's ``SeedSequence`` takes any non-negative integer, but a
launched run's seed travels in the world's ``Clock`` as a msgpack int64 (docs/protocol.md), and a seed a
command accepts must be one every command accepts (``swarm sim --seed S`` re-runs a launched or campaign
run)."""


def seed(text: str) -> int:
    """An argparse type for ``--seed``: an integer in ``0 .. 2**63 - 1`` (:data:`SEED_LIMIT`)."""
    return _SEED(text)


_SEED = _checked("--seed", int, lambda v: 0 <= v < SEED_LIMIT, "an integer in 0..2**63-1")


def add_world_timeouts(p) -> None:
    """``--step-timeout`` and ``--start-timeout``: the world's, also taken by ``swarm launch`` for it."""
    p.add_argument(
        "--step-timeout", type=positive_float("--step-timeout"), default=5.0, metavar="S",
        help="lockstep: step without a silent agent's command after this long, logged (default 5 s)",
    )  # fmt: skip
    p.add_argument(
        "--start-timeout", type=positive_float("--start-timeout"), default=180.0, metavar="S",
        help="give up if the processes are not all up after this long (default 180 s: a first run compiles)",
    )  # fmt: skip


def agents(text: str) -> int:
    """An argparse type for ``--agents``: copies of the scenario's pairs, an integer in ``1..64``."""
    return _AGENTS(text)


_AGENTS = _checked("--agents", int, lambda v: 1 <= v <= 64, "an integer in 1..64")


def add_scenario_args(p: argparse.ArgumentParser) -> None:
    """Arguments every command that loads a scenario shares."""
    p.add_argument("scenario", help="bundled scenario name (docking, ground-docking, ...) or a TOML file")
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override one scenario field, e.g. --set estimator.sigma_range_m=0.03 (repeatable)",
    )


def load_from_args(args: argparse.Namespace):
    """The scenario that ``args.scenario`` and ``args.overrides`` (``--set``) name."""
    from swarm.config import parse_override
    from swarm.scenario import load_scenario

    overrides = dict(parse_override(text) for text in args.overrides)
    return load_scenario(args.scenario, overrides)
