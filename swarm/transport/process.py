"""What every swarm process shares: its command-line flags, the clock mode, signals, the ready line and
reliable publishers.

Each process (``python -m swarm.world``, ``python -m mothership``, ``python -m agents``) takes the same
scenario flags as ``swarm sim`` (a scenario name or file, ``--set key=value``, ``--agents N``, ``--seed``),
so every process of a swarm builds the very same :class:`~swarm.scenario.Scenario` from the same words,
plus ``--namespace``, ``--clock`` and the Zenoh session flags of :mod:`swarm.transport.session`.

Once its subscriptions and liveliness token are declared, a process prints one line on stdout,
``<role> <id> ready`` (flushed), for a launcher or a test to wait on; it logs to stderr. SIGINT and SIGTERM
set a stop flag: the process finishes its current step, publishes what it owes (a world its ``run_end``),
closes its Zenoh session (a callback subscriber left open hangs the interpreter at exit:
tests/transport/test_session.py) and exits 0; a child of a launcher leaves a SIGINT to the launcher,
which stops the swarm in order (:mod:`swarm.transport.stopping`).
"""

from __future__ import annotations

import argparse
import logging
import math
import signal
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass

import zenoh

from swarm import cpu_latency
from swarm.args import add_scenario_args, agents, load_from_args, positive_int, seed
from swarm.errors import ConfigError, SwarmError
from swarm.stacks import enable_stack_dumps
from swarm.transport.keys import Keys
from swarm.transport.messages import CLOCK_EVERY
from swarm.transport.session import add_zenoh_arguments, zenoh_args_from
from swarm.transport.stopping import StopFlag

__all__ = [
    "PROCESS_NOISE_BLOCK",
    "ClockSpec",
    "add_process_arguments",
    "declare_reliable",
    "install_stop_signals",
    "keys_from",
    "print_ready",
    "process_main",
    "scenario_from",
    "zenoh_args",
]

_LOG = logging.getLogger(__name__)

PROCESS_NOISE_BLOCK = 64
"""Rows per vehicle of a refill of a world or mothership process's pre-drawn noise (``World.noise_block``,
``UwbNetwork.noise_block``): the in-process run draws 1024 at a time, the same samples, but in a
process of 128 vehicles that is a ~16 ms stall once every 1024 ticks, which made every vehicle's next
commands late; 64 rows take ~0.6 ms once every 64 ticks. The first block is drawn before the process says
it is ready."""


@dataclass(frozen=True)
class ClockSpec:
    """How the world's clock advances (``--clock``, docs/protocol.md).

    ``lockstep``: tick ``k + 1`` only once every live agent's command of tick ``k`` arrived (or a timeout
    passed): deterministic, as fast as the slowest agent. ``realtime``: one tick per ``dt`` of wall time.
    ``scaled:N``: ``N`` times real time (``N`` > 0; ``scaled:1`` is ``realtime``)."""

    mode: str = "lockstep"
    factor: float = 1.0
    """Simulated seconds per wall second (``realtime`` and ``scaled`` only)."""

    @classmethod
    def parse(cls, text: str) -> ClockSpec:
        """``"lockstep"``, ``"realtime"`` or ``"scaled:N"``; ConfigError naming ``--clock`` otherwise."""
        bad = ConfigError(f"--clock must be lockstep, realtime or scaled:N with N > 0, got {text!r}")
        if text in ("lockstep", "realtime"):
            return cls(text, 1.0)
        if not isinstance(text, str) or not text.startswith("scaled:"):
            raise bad
        try:
            factor = float(text.split(":", 1)[1])
        except ValueError:
            raise bad from None
        if not (math.isfinite(factor) and factor > 0):
            raise bad
        return cls("scaled", factor)

    @property
    def lockstep(self) -> bool:
        return self.mode == "lockstep"

    def __str__(self) -> str:
        return self.mode if self.mode != "scaled" else f"scaled:{self.factor:g}"


def check_pace(clock: ClockSpec, pace: ClockSpec | None) -> None:
    """``--pace`` (a landing swarm) paces a lockstep run to realtime or scaled:N; ConfigError naming it
    otherwise."""
    if pace is None:
        return
    if pace.lockstep:
        raise ConfigError("--pace must be realtime or scaled:N (the wall clock a lockstep run keeps to), "
                          "got lockstep")  # fmt: skip
    if not clock.lockstep:
        raise ConfigError(f"--pace {pace} paces a lockstep run; --clock {clock} is free-running already")


def clock_arg(text: str) -> ClockSpec:
    try:
        return ClockSpec.parse(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_process_arguments(p: argparse.ArgumentParser, *, clock: bool = True) -> None:
    """The scenario, seed, namespace, clock and Zenoh flags every swarm process takes."""
    add_scenario_args(p)
    p.add_argument(
        "--agents",
        type=agents,
        default=1,
        metavar="N",
        help="copies of the scenario's pairs (default 1)",
    )
    p.add_argument("--seed", type=seed, default=0, help="root seed of every random stream (default 0)")
    p.add_argument(
        "--policy", choices=("fixed", "mdp"), default=None, help="switching policy (default: scenario's)"
    )
    p.add_argument("--namespace", default="tpods", help="key namespace of this swarm (default tpods)")
    if clock:
        p.add_argument(
            "--clock",
            type=clock_arg,
            default=ClockSpec(),
            metavar="lockstep|realtime|scaled:N",
            help="how the world's clock advances (default lockstep)",
        )
    p.add_argument(
        "--lease-ms",
        type=int,
        default=None,
        metavar="MS",
        help="Zenoh link lease: a hung peer is seen lost after about this long (default Zenoh's 10000)",
    )
    add_zenoh_arguments(p)


def add_clock_every(p: argparse.ArgumentParser) -> None:
    """A world's ``--clock-every TICKS`` (the docking world's and the landing world's)."""
    p.add_argument("--clock-every", type=positive_int("--clock-every"), default=CLOCK_EVERY, metavar="TICKS",
                   help=f"publish world/clock every this many ticks (default {CLOCK_EVERY})")  # fmt: skip


def add_checkpoint_arguments(p: argparse.ArgumentParser, writes: str, resumes: str) -> None:
    """``--checkpoint-dir DIR`` and ``--resume`` of a process that a restart resumes
    (:mod:`swarm.transport.checkpoint`): ``writes`` says what it writes there and when, ``resumes`` what
    ``--resume`` does; a torn or foreign checkpoint is an error naming the file, exit status 3."""
    p.add_argument("--checkpoint-dir", default=None, metavar="DIR",
                   help=f"write {writes} (a private directory: the file is a pickle)")  # fmt: skip
    p.add_argument("--resume", action="store_true",
                   help=f"{resumes}; a torn or foreign checkpoint is an error naming the file (exit status "
                        "3)")  # fmt: skip


def scenario_from(args: argparse.Namespace):
    """The scenario the flags name, with ``--set`` overrides and ``--agents`` copies."""
    return load_from_args(args).with_pairs(args.agents)


def keys_from(args: argparse.Namespace) -> Keys:
    return Keys(args.namespace)


def zenoh_args(args: argparse.Namespace):
    """The :class:`~swarm.transport.session.ZenohArgs` of the flags (``--lease-ms`` included)."""
    from dataclasses import replace

    return replace(zenoh_args_from(args), lease_ms=args.lease_ms)


def declare_reliable(session: zenoh.Session, key: str, express: bool = True) -> zenoh.Publisher:
    """A reliable publisher that blocks rather than drops when congested (lockstep loses nothing);
    ``express`` sends each sample at once instead of batching (lower latency, BENCHMARKS.md)."""
    return session.declare_publisher(
        key,
        reliability=zenoh.Reliability.RELIABLE,
        congestion_control=zenoh.CongestionControl.BLOCK,
        express=express,
    )


_READY_LOCK = threading.Lock()


def print_ready(role: str, process_id: str) -> None:
    """The ready line ``<role> <id> ready`` on stdout, flushed: one write under a lock, so that the agents of
    an agent host, each on its thread, never interleave their lines (``print`` writes the text and the
    newline apart: two threads made ``agent uav3 readyagent uav4 ready``)."""
    with _READY_LOCK:
        sys.stdout.write(f"{role} {process_id} ready\n")
        sys.stdout.flush()


def install_stop_signals(stop: threading.Event) -> dict[int, object]:
    """SIGINT and SIGTERM set ``stop`` (main thread only; a launched child leaves a SIGINT to its launcher:
    :func:`swarm.transport.stopping.install_stop_signals`); returns the previous handlers."""
    from swarm.transport.stopping import install_stop_signals as install

    return install(stop, _LOG)


def exit_process(code: int) -> None:
    """End a swarm process (``python -m ...``) with ``code`` once its session is closed and its output
    flushed, without the interpreter's finalization: there a Zenoh object's finalizer collected with a
    closed session's callbacks still tied to it can block in the garbage collector (seen: a hosted landing
    agent stuck "Garbage-collecting" for its launcher's whole 3 s grace, then SIGKILLed). Files it owes are
    closed by then (checkpoints at the run's end, recordings by their writers)."""
    import os

    sys.stdout.flush()
    sys.stderr.flush()
    logging.shutdown()
    os._exit(code)


def process_main(
    prog: str,
    description: str,
    add_arguments: Callable[[argparse.ArgumentParser], None],
    run: Callable[[argparse.Namespace, threading.Event], int],
    argv: list[str] | None = None,
) -> int:
    """``python -m <process>``: parse, configure logging (stderr), run until done or a stop signal.
    Bad input (a flag, the scenario) prints one ``<prog>: error: ...`` line and returns 2."""
    enable_stack_dumps()  # before its ready line: the launcher signals only a child that has printed one
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    add_arguments(parser)
    cpu_latency.add_argument(parser)  # a process started by hand (another machine); a launch holds its own
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format=f"%(asctime)s %(levelname)s {prog}: %(message)s",
        stream=sys.stderr,
    )
    stop = StopFlag()  # (its ``told``: the swarm is stopping, swarm.transport.stopping)
    previous = install_stop_signals(stop)
    try:
        with cpu_latency.hold(args.cpu_latency):
            return int(run(args, stop) or 0)
    except SwarmError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr, flush=True)
        return 2
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)  # type: ignore[arg-type]
