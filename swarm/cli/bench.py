"""``swarm bench [BENCH] [--quick] [--json FILE]``: the performance measurements of BENCHMARKS.md.

Each bench lives in :mod:`swarm.bench` and returns a JSON-ready dict (section 8 names) and a printable
report; this module only parses flags, prints, and writes the JSON. Without ``BENCH`` every bench runs
and ``--json`` gets one object keyed by bench name.
"""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import math
from collections.abc import Callable
from pathlib import Path

from swarm import cpu_latency
from swarm.args import add_output_file
from swarm.errors import ConfigError

log = logging.getLogger(__name__)


def _bench(module: str, presets: bool) -> Callable[..., tuple[dict, str]]:
    """The runner of ``swarm.bench.<module>``, imported only when it runs (a bench's imports are heavy):
    ``run(QUICK or FULL)`` for a bench with presets (``preset`` entries given to the runner override the
    preset's: a bench's own flags), ``run(quick)`` for the others; then its report."""

    def runner(quick: bool, **preset) -> tuple[dict, str]:
        bench = importlib.import_module(f"swarm.bench.{module}")
        if not presets:
            record = bench.run(quick)
        else:  # (a preset may be a dict or a bench's own config object: overridden only when asked)
            chosen = bench.QUICK if quick else bench.FULL
            record = bench.run({**chosen, **preset} if preset else chosen)
        return record, bench.format_report(record)

    return runner


BENCHES: dict[str, tuple[Callable[[bool], tuple[dict, str]], str]] = {
    "estimator": (
        _bench("estimator", presets=True),
        "estimator step: tandem vs compounded vs FilterPy (paper Table I)",
    ),
    "codec": (
        _bench("codec", presets=True),
        "one message of every tick: build, encode, decode (msgspec fast path vs reference checks)",
    ),
    "replay": (
        _bench("replay", presets=True),
        "a 60 s UWB + IMU log through the IMU-driven filter; its step against the tandem's",
    ),
    "record": (
        _bench("record", presets=True),
        "what --record costs a 4-pair realtime swarm (CPU with and without the MCAP recorder)",
    ),
    "sim": (_bench("sim", presets=False), "one in-process docking: real-time factor and profile"),
    "transport": (
        _bench("transport", presets=True),
        "the swarm over Zenoh: RTT, lockstep tick period (1/4/16 pairs), latency",
    ),
    "montecarlo": (
        _bench("montecarlo", presets=False),
        "Monte Carlo campaign wall time: 1 vs 2 workers, number of runs",
    ),
    "faults": (
        _bench("faults", presets=False),
        "200 runs under the issue-7 faults: docked / safely aborted / failed, NEES",
    ),
    "checkpoint": (
        _bench("checkpoint", presets=True),
        "the checkpoints per tick: the world's (1/4/16 pairs), in memory and on disk; a landing swarm's",
    ),
    "swarm": (
        _bench("swarm", presets=True),
        "the swarm at scale: CPU per vehicle per tick, late ticks, real-time factor, latency (--vehicles)",
    ),
    "tdoa": (
        _bench("tdoa", presets=True),
        "TWR-TDMA vs TDoA3 for 2-128 vehicles: per-tag measurement rate, swarm replay's RMSE at that rate",
    ),
}
"""Bench name -> (runner taking ``quick``, one-line help)."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench",
        help="performance benchmarks (all of them without a BENCH)",
        description="Performance benchmarks; ratios are measured in one run, absolute times are noisy.",
    )
    # SUPPRESS on both levels: a flag given before BENCH is not reset by the sub-parser's default.
    _add_flags(p, argparse.SUPPRESS)
    p.set_defaults(func=run, bench=None, quick=False, json=None)
    benches = p.add_subparsers(dest="bench", metavar="BENCH")
    for name, (_, help_text) in BENCHES.items():
        bp = benches.add_parser(name, help=help_text, description=help_text)
        _add_flags(bp, argparse.SUPPRESS)
        if name == "transport":
            bp.add_argument("--cpu-latency", dest="cpu_latency", type=cpu_latency.parse, default=None,
                            metavar="US|off",
                            help="hold a CPU wake-up latency request (swarm launch --cpu-latency) "
                                 "for the whole bench: off (default) or microseconds (0: idle CPUs "
                                 "poll)")  # fmt: skip
        if name == "swarm":
            bp.add_argument("--vehicles", default=None, metavar="N,N,...",
                            help="vehicle counts, even; default 2,8,32 (2,8 with --quick)")  # fmt: skip
            bp.add_argument("--clock", default=None, metavar="CLOCK[,CLOCK]",
                            help="realtime, lockstep or both (default both)")  # fmt: skip
            bp.add_argument("--topology", default=None, metavar="auto|mesh|star[,..]",
                            help="swarm launch --topology of the cases: auto (default, as swarm launch), "
                                 "mesh, star or several, each case run in each, alternately")  # fmt: skip
            bp.add_argument("--cpu-latency", dest="cpu_latency", default=None, metavar="US|off[,..]",
                            help="hold a CPU wake-up latency request (swarm launch --cpu-latency) while "
                                 "each case runs: off (default), microseconds (0: idle CPUs poll) or "
                                 "several, each case run in each, alternately")  # fmt: skip
            bp.add_argument("--vehicles-per-process", dest="per_process", default=None, metavar="N|auto[,..]",
                            help="agent hosts of N vehicles (1: a process per vehicle; default auto: "
                                 "swarm launch's own plan for the vehicles and cores)")  # fmt: skip
            bp.add_argument("--span", type=float, default=None, metavar="S",
                            help="simulated seconds per case (default 20, 5 with --quick)")  # fmt: skip
            bp.add_argument("--repeat", type=int, default=None, metavar="N",
                            help="run each case N times, round by round, and report the medians and the "
                                 "spread (default 1)")  # fmt: skip
            bp.add_argument("--stagger", action="store_true", default=None,
                            help="stagger the vehicles' controller clocks (swarm.stagger_control): vehicle "
                                 "m controls on ticks m %% period, not all on one tick (default: swarm "
                                 "launch's plan)")  # fmt: skip
            bp.add_argument("--agent-wake", dest="agent_wake", default=None, metavar="imu|control[,..]",
                            help="a free-running agent alone in its process wakes at each gyro sample (imu) "
                                 "or once per control period (control: agent.wake_at_control); both: each "
                                 "case in each, alternately (default: swarm launch's plan)")  # fmt: skip
            bp.add_argument("--tdma", action="store_true", default=None,
                            help="the tags share one UWB channel (uwb.tdma): each ranges once per TDMA "
                                 "frame, ~238/N times a second for N tags, not 50")  # fmt: skip
    _add_peer(benches)
    _add_real_flights(benches)


def _add_flags(p: argparse.ArgumentParser, default) -> None:
    p.add_argument("--quick", action="store_true", default=default, help="short run (a few seconds)")
    add_output_file(p, "--json", "write the results as JSON", default=default)


def run(args: argparse.Namespace) -> int:
    names = [args.bench] if args.bench else list(BENCHES)
    records = {}
    for name in names:
        log.info("bench %s%s", name, " (quick)" if args.quick else "")
        if name == "swarm" and args.bench == "swarm":  # its own flags override the preset
            record, report = _swarm(args)
        elif name == "transport" and args.bench == "transport":  # --cpu-latency (None: none)
            record, report = BENCHES[name][0](args.quick, cpu_latency=args.cpu_latency)
        else:
            record, report = BENCHES[name][0](args.quick)
        print(report)
        records[name] = record
    if args.json is not None:
        out = records[names[0]] if args.bench else records
        try:
            args.json.write_text(json.dumps(_finite_or_null(out), indent=2) + "\n")
        except OSError as exc:
            raise ConfigError(f"--json: cannot write {str(args.json)!r}: {exc.strerror}") from exc
        log.info("wrote %s", args.json)
    return 0


def _add_real_flights(benches: argparse._SubParsersAction) -> None:
    """``swarm bench real-flights LOG...``: the filter on recorded flights with a truth (swarm/bench/
    real_flights.py); not one of :data:`BENCHES` (it needs logs)."""
    text = (
        "the IMU-driven filter on recorded flights with a truth: the pad, heading and static segment read "
        "off the truth, everything else the defaults (BENCHMARKS.md, Real flights)"
    )
    bp = benches.add_parser("real-flights", help=text, description=text)
    bp.add_argument("logs", nargs="+", type=Path, metavar="LOG", help="log folders (swarm import output)")
    bp.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="override a log.toml key for every flight (repeatable)")  # fmt: skip
    add_output_file(bp, "--json", "write the rows as JSON")
    bp.set_defaults(func=_real_flights)


def _real_flights(args: argparse.Namespace) -> int:
    from swarm.bench import real_flights
    from swarm.config import parse_override

    record, report = real_flights.run(args.logs, dict(parse_override(o) for o in args.overrides))
    print(report)
    if args.json is not None:
        args.json.write_text(json.dumps(record, indent=1))
    return 0


def _add_peer(benches: argparse._SubParsersAction) -> None:
    """``swarm bench peer LOG --util-eskf DIR``: not one of :data:`BENCHES` (it needs a log and the
    user's checkout of a peer's code, so a bare ``swarm bench`` does not run it)."""
    text = "the UTIL dataset authors' ESKF (your checkout) on a TDoA log, scored as swarm replay scores"
    bp = benches.add_parser("peer", help=text, description=text)
    bp.add_argument("log", metavar="LOG", help="a log folder with tdoa.csv and truth.csv (docs/logs.md)")
    bp.add_argument(
        "--util-eskf",
        dest="util_eskf",
        required=True,
        metavar="DIR",
        help="a checkout of utiasDSL/util-uwb-dataset, or its scripts/estimation folder",
    )
    bp.add_argument(
        "--mode",
        default="auto",
        choices=("auto", "tdoa2", "tdoa3"),
        help="TDoA2 keeps only the 8 ring pairs, as their main.py (auto: from the pairs)",
    )
    bp.add_argument(
        "--span",
        default="full",
        choices=("full", "airborne"),
        help="the whole log (default), or only where the truth is 0.2 m above its start",
    )
    bp.add_argument(
        "--initial",
        default="truth",
        choices=("truth", "authors"),
        help="initial position: the truth's (default) or main.py's (1.25, 0, 0.07)",
    )
    bp.add_argument(
        "--downsample",
        type=int,
        default=8,
        metavar="N",
        help="every N-th IMU sample and TDoA row of a pair (main.py: 8)",
    )
    add_output_file(bp, "--json", "write the results as JSON", default=argparse.SUPPRESS)
    bp.set_defaults(func=_peer)


def _peer(args: argparse.Namespace) -> int:
    from swarm.bench import peer_util

    cfg = peer_util.PeerConfig(
        mode=args.mode, downsample=args.downsample, initial=args.initial, span=args.span
    )
    record = peer_util.run_peer(args.log, args.util_eskf, cfg)
    print(peer_util.format_report(record))
    if args.json is not None:
        try:
            args.json.write_text(json.dumps(_finite_or_null(record), indent=2) + "\n")
        except OSError as exc:
            raise ConfigError(f"--json: cannot write {str(args.json)!r}: {exc.strerror}") from exc
    return 0


def _swarm(args: argparse.Namespace) -> tuple[dict, str]:
    from swarm.bench import swarm as bench

    preset = dict(bench.QUICK if args.quick else bench.FULL)
    if getattr(args, "vehicles", None) is not None:
        preset["vehicles"] = bench.parse_vehicles(args.vehicles)
    if getattr(args, "clock", None) is not None:
        preset["clocks"] = bench.parse_clocks(args.clock)
    if getattr(args, "topology", None) is not None:
        preset["topologies"] = bench.parse_topologies(args.topology)
    if getattr(args, "cpu_latency", None) is not None:
        preset["cpu_latencies"] = bench.parse_cpu_latencies(args.cpu_latency)
    if getattr(args, "per_process", None) is not None:
        preset["per_process"] = bench.parse_per_process(args.per_process)
    if getattr(args, "agent_wake", None) is not None:
        preset["agent_wakes"] = bench.parse_agent_wakes(args.agent_wake)
    if getattr(args, "span", None) is not None:
        if not (math.isfinite(args.span) and 1.0 <= args.span <= 3600.0):
            raise ConfigError(f"--span must be a number of seconds in 1..3600, got {args.span}")
        preset["span_s"] = args.span
    if getattr(args, "stagger", None):
        preset["stagger"] = True
    if getattr(args, "tdma", None):
        preset["tdma"] = True
    if getattr(args, "repeat", None) is not None:
        preset["repeat"] = bench.parse_repeat(args.repeat)
    record = bench.run(preset)
    return record, bench.format_report(record)


def _finite_or_null(x):
    """``x`` with NaN and infinities as ``None``, so the file is strict JSON."""
    if isinstance(x, dict):
        return {k: _finite_or_null(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_finite_or_null(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x
