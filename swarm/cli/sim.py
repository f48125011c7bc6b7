"""``swarm sim SCENARIO``: one in-process closed-loop run (world, mothership radio and agents)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from swarm.args import add_output_file, add_scenario_args, agents, load_from_args, seed
from swarm.errors import ConfigError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sim", help="run one docking or landing in-process and print its outcome")
    add_scenario_args(p)
    p.add_argument(
        "--policy", choices=("fixed", "mdp"), default=None, help="switching policy (default: scenario's)"
    )
    p.add_argument("--seed", type=seed, default=0, help="root seed of every random stream (default 0)")
    p.add_argument(
        "--agents", type=agents, default=1, metavar="N", help="copies of the scenario's pairs (default: 1)"
    )
    add_output_file(p, "--json", "write the summary and time series")
    add_output_file(p, "--plot", "draw trajectory and errors", metavar="FILE.png")
    p.add_argument("--no-series", action="store_true", help="do not record time series (faster)")
    p.add_argument(
        "--mcap", type=Path, default=None, metavar="FILE.mcap",
        help="write the run as its processes would have published it in lockstep, an MCAP recording",
    )  # fmt: skip
    p.add_argument(
        "--namespace", default="tpods", help="key namespace of the --mcap recording (default tpods)"
    )
    p.set_defaults(func=run)


def _fmt(v, unit: str = "", scale: float = 1.0, digits: int = 3) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v * scale:.{digits}f}{unit}"


def print_summary(res: dict) -> None:
    print(f"scenario {res['scenario']}  policy {res['policy']}  seed {res['seed']}")
    for cid, c in res["chasers"].items():
        status = (
            "DOCKED" if c["docked"] else ("COLLISION" if c["collided"] else f"not docked ({c['final_mode']})")
        )
        print(f"  {cid}: {status}")
        print(f"    docking time      {_fmt(c['docking_time_s'], ' s', digits=2)}")
        effort = (
            c.get("effort_key", "total_impulse_ns").removesuffix("_ns").removesuffix("_rad").replace("_", " ")
        )
        unit = c.get("effort_unit", "N s")
        print(f"    {effort:<18}{_fmt(c.get('effort', c.get('total_impulse_ns')), ' ' + unit, digits=4)}")
        print(f"    position error    {_fmt(c['position_error_m'], ' cm', 100.0, 3)}")
        print(f"    attitude error    {_fmt(c['attitude_error_rad'], ' rad', digits=4)}")
        print(f"    radii chosen      r2 = {c['r2_m']:.3f} m, r1 = {c['r1_m']:.3f} m")
        print(f"    keep-out violated {c['keepout_violated']}")
        if c.get("closest_approach_m") is not None:
            closest = _fmt(c["closest_approach_m"], " mm", 1000.0, 1)
            print(f"    closest approach  {closest} (centres, outside DOCK)")
        print("    modes:")
        for m in c["modes"]:
            print(f"      t = {m['t_s']:7.2f} s  r = {m['range_m']:.3f} m  -> {m['mode']:<9} {m['reason']}")
    print(
        f"  wall {res['wall_s']:.2f} s for {res['sim_time_s']:.1f} s simulated: "
        f"{res['realtime_factor']:.0f}x real time"
    )


def print_landing(res: dict) -> None:
    print(
        f"scenario {res['scenario']}  policy {res['policy']}  seed {res['seed']}  camera {res['camera_mode']}"
    )
    status = (
        "LANDED"
        if res["landed"]
        else (
            "ABORTED (safe)"
            if res["aborted"]
            else ("LANDED OFF THE PAD" if res["landed_off_pad"] else res["final_mode"])
        )
    )
    print(f"  {status}")
    print(f"    landing error     {_fmt(res['landing_error_m'], ' cm', 100.0, 1)}")
    if "touchdown_rel_speed_m_s" in res:  # a moving pad (landing-moving): judged at the touchdown
        rel = _fmt(res["touchdown_rel_speed_m_s"], " m/s", digits=2)
        print(f"    touchdown         {rel} relative to the pad (robot at {res['platform_speed_m_s']:g} m/s)")
    print(f"    landing time      {_fmt(res['landing_time_s'], ' s', digits=2)}")
    print(
        f"    energy            {_fmt(res['energy_j'], ' J', digits=0)} "
        f"({_fmt(res['hover_equivalent_s'], ' s', digits=1)} of hover)"
    )
    print(
        f"    deviation at      {_fmt(res['deviation_distance_m'], ' m', digits=2)} from the pad (horizontal)"
    )
    print(
        f"    pad seen          {res['pad_detections']} of {res['pad_frames']} frames; "
        f"retries {res['retries']}"
    )
    print("    modes:")
    for m in res["modes"]:
        print(f"      t = {m['t_s']:7.2f} s  -> {m['mode']:<8} {m['reason']}")
    print(
        f"  wall {res['wall_s']:.2f} s for {res['sim_time_s']:.1f} s simulated: "
        f"{res['realtime_factor']:.0f}x real time"
    )


def _write_json(path: Path | None, res: dict) -> None:
    """``--json FILE``: the run's summary (and series), or a clear error naming the file."""
    if path is None:
        return
    try:
        path.write_text(json.dumps(res, indent=1))
    except OSError as exc:
        raise ConfigError(f"--json: cannot write {str(path)!r}: {exc}") from None
    print(f"  summary written to {path}")


def run_landing(args: argparse.Namespace) -> int:
    """``swarm sim`` of a landing scenario (:class:`swarm.missions.landing.LandingMission`)."""
    from swarm.config import parse_override
    from swarm.sim import landing
    from swarm.sim.landing import load_landing, run_landing_fleet

    if args.agents != 1:
        raise ConfigError(
            "--agents: a landing scenario lists its UAVs ([[fleet]] in the file, e.g. landing-swarm)"
        )
    if args.plot is not None:
        raise ConfigError("--plot: not drawn for a landing yet (the series is in --json)")
    sc = load_landing(args.scenario, dict(parse_override(text) for text in args.overrides))
    record = not args.no_series or args.json is not None
    tap = None
    if args.mcap is not None:
        from swarm.transport.wire import LandingTap

        tap = LandingTap(args.mcap, args.seed, args.namespace)
    if not sc.fleet and tap is None:
        res = landing.run_landing(sc, args.policy, args.seed, record_series=record)
        print_landing(res)
        _write_json(args.json, res)
        return 0 if res["landed"] or res["aborted"] else 1
    res = run_landing_fleet(sc, args.policy, args.seed, record_series=record, tap=tap)
    if tap is not None:
        print(f"  wrote {args.mcap}: {sum(tap.sink.counts.values())} messages on {len(tap.sink.counts)} keys")
    if not sc.fleet:
        res = res["uavs"][sc.uavs()[0].id]
        print_landing(res)
        _write_json(args.json, res)
        return 0 if res["landed"] or res["aborted"] else 1
    for uid, r in res["uavs"].items():
        print(f"[{uid}]", end=" ")
        print_landing(r)
    n = len(res["uavs"])
    print(f"{res['landed']} of {n} UAVs landed on their pads in {res['sim_time_s']:.1f} s simulated")
    _write_json(args.json, res)
    return 0 if all(r["landed"] or r["aborted"] for r in res["uavs"].values()) else 1


def run(args: argparse.Namespace) -> int:
    """``swarm sim SCENARIO``: the scenario's mission runs it (:func:`swarm.missions.mission_of`)."""
    from swarm.missions import mission_of

    return mission_of(args.scenario).run_sim(args)


def run_mission(args: argparse.Namespace) -> int:
    """``swarm sim`` of a mission that gives only ``run_one`` (:data:`swarm.missions.GENERIC_SIM`): one
    run, its summary printed (and written by ``--json``); exit 0 if it reached its goal."""
    from swarm.missions import mission_of, overrides_of

    mission = mission_of(args.scenario)
    for flag, value in (("--plot", args.plot), ("--mcap", args.mcap)):
        if value is not None:
            raise ConfigError(f"{flag}: mission {mission.name!r} gives a summary, no trajectory or recording")
    sc = mission.with_agents(mission.load(args.scenario, overrides_of(args)), args.agents)
    res = mission.run_one(sc, args.policy, args.seed)
    policy = res.get("policy", args.policy)
    print(f"scenario {args.scenario}  mission {mission.name}  policy {policy}  seed {args.seed}")
    print(f"  {mission.success_key:<18}{res[mission.success_key]}")
    for key in mission.summary_metrics:
        v = res.get(key)
        print(f"  {key:<18}{_fmt(v) if isinstance(v, float) or v is None else v}")
    _write_json(args.json, res)
    return 0 if res[mission.success_key] else 1


def run_docking(args: argparse.Namespace) -> int:
    """``swarm sim`` of a docking scenario (:class:`swarm.missions.docking.DockingMission`)."""
    from swarm.sim import docking

    sc = load_from_args(args).with_pairs(args.agents)
    tap = None
    if args.mcap is not None:
        from swarm.transport.wire import DockingTap

        tap = DockingTap(args.mcap, args.seed, args.namespace)
    record = not args.no_series or args.plot is not None or args.json is not None
    res = docking.run_docking(sc, args.policy, args.seed, record_series=record, tap=tap)
    if tap is not None:
        print(f"  wrote {args.mcap}: {sum(tap.sink.counts.values())} messages on {len(tap.sink.counts)} keys")
    print_summary(res)
    _write_json(args.json, res)
    if args.plot is not None:
        from swarm.sim.plot import plot_run

        plot_run(res, sc, args.plot)
        print(f"  plot written to {args.plot}")
    return 0 if all(c["docked"] for c in res["chasers"].values()) else 1
