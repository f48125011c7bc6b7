"""The landing world process (``python -m swarm.world.landing SCENARIO``; started by ``swarm launch`` for a
landing scenario): the world step of :mod:`swarm.step.landing` for every UAV, over Zenoh, in lockstep.

Per tick ``k``, for every UAV not done: the truth steps, then the tick's samples go out on the UAV's keys
(``docs/protocol.md``): an ``Imu`` with ``acc_body`` (stamped ``t - dt``), on a UWB tick a ``Uwb`` (the
anchor's index; ``range_m`` nil when the anchor is out of reach), on a GNSS tick a ``Gnss``, on a camera
tick a ``Vision`` of kind ``pixels`` (target ``pad-<uav>``, face ``+z``, every corner of every detected
marker: row ``4 m + c`` is corner ``c`` of marker ``m``; none when the pad is not in view), and a
``Truth``; then ``world/clock``. The world waits for each such UAV's ``Command`` of tick ``k`` (its mode
one of the landing modes), holds it, and steps on. When every UAV is done (landed for a second, or hovering
at the abort height) it publishes ``run_end`` on ``world/event`` with each UAV's outcome and a ``stopped``
clock, and exits 0. It waits for every UAV's agent (liveliness ``alive/agent/<id>``) before the first tick.
It takes run-time faults on ``control/fault`` (``swarm fault``): ``camera_loss`` (the pad hidden from a
UAV's camera) and ``uwb_dropout`` (its UWB replies lost), for one UAV or all; other kinds are refused with a
``fault_refused`` event.

``--clock lockstep`` (the default) steps as fast as the agents answer: the run is ``swarm sim``'s. With
``--pace`` a lockstep world also never runs ahead of the wall clock (at ``realtime`` or ``scaled:N``, to watch
the landing on the dashboard), still waiting for every command. ``--clock realtime`` or ``scaled:N`` alone is
a free-running world, as the docking world is: tick ``k`` is stepped at its wall time whatever the agents
did; each UAV flies the newest command it has (a command of tick ``k`` that comes after tick ``k``'s wall
time is late: the rotors keep the previous one, as a flight controller's mixer keeps its last setpoint), and
``run_end`` counts each UAV's late ticks. A slow agent then costs its UAV accuracy, not the swarm its pace.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
import time

from swarm.transport.process import check_pace, print_ready, process_main

_LOG = logging.getLogger("swarm.world.landing")
DESCRIPTION = "The landing world: quadrotor truth and sensors of every UAV, lockstep over Zenoh."


def add_arguments(p: argparse.ArgumentParser) -> None:
    from swarm.args import positive_float
    from swarm.transport.process import add_process_arguments, clock_arg

    add_process_arguments(p)
    p.add_argument("--step-timeout", type=positive_float("--step-timeout"), default=30.0, metavar="S",
                   help="give up when an agent's command of a tick has not come after this long")  # fmt: skip
    p.add_argument("--start-timeout", type=positive_float("--start-timeout"), default=60.0, metavar="S",
                   help="give up when the agents are not all up after this long")  # fmt: skip
    p.add_argument("--pace", type=clock_arg, default=None, metavar="CLOCK",
                   help="a lockstep world paced to this clock (realtime or scaled:N): every command waited "
                        "for, never ahead of the wall clock")  # fmt: skip


def run(args: argparse.Namespace, stop: threading.Event) -> int:
    from swarm.config import parse_override
    from swarm.core.landing import LandingMode
    from swarm.errors import ConfigError
    from swarm.landing_scenario import load_landing
    from swarm.step.landing import LandingCommand, LandingWorld
    from swarm.transport import landing_wire as wire
    from swarm.transport.keys import Keys
    from swarm.transport.messages import LANDING_MODES, Command, DropCounter, Fault
    from swarm.transport.process import declare_reliable
    from swarm.transport.session import (
        declare_liveliness,
        open_session,
        subscribe_decoded,
        watch_liveliness,
        zenoh_args_from,
    )

    check_pace(args.clock, args.pace)
    sc = load_landing(args.scenario, dict(parse_override(o) for o in args.overrides))
    policy = args.policy or sc.policy
    keys = Keys(args.namespace)
    world = LandingWorld(sc, args.seed)
    ids = list(world.uavs)
    dt = sc.dt_s
    drops = DropCounter()
    cond = threading.Condition()
    commands: dict[tuple[str, int], Command] = {}
    alive: set[str] = set()
    faults: list[Fault] = []  # run-time faults come, applied before the next tick's samples

    def on_fault(_key: str, msg: Fault) -> None:
        with cond:
            faults.append(msg)

    def apply_faults(k: int) -> None:
        """Run-time faults (``swarm fault``): a window opens no earlier than tick ``k``, whose samples are
        not out yet; ``fault`` on ``world/event`` when applied, ``fault_refused`` with the reason when
        not."""
        with cond:
            pending = list(faults)
            faults.clear()
        for f in pending:
            start = max(f.start_s if f.start_s is not None else k * dt, k * dt)
            who = [f.vehicle] if f.vehicle is not None else list(ids)
            try:
                world.add_fault(f.kind, start, f.duration_s, who)
            except ValueError as exc:
                _LOG.warning("fault refused: %s: %s", f.kind, exc)
                refused = {"kind": f.kind, "vehicle": f.vehicle, "reason": str(exc)}
                put([wire.world_event(keys, "fault_refused", (k - 1) * dt, refused)])
                continue
            applied = {"kind": f.kind, "start_s": start, "duration_s": f.duration_s, "vehicles": who}
            put([wire.world_event(keys, "fault", (k - 1) * dt, applied)])
            _LOG.warning("fault applied: %s on %s from t = %.2f s", f.kind, who, start)

    def on_command(key: str, msg: Command) -> None:
        parsed = keys.parse(key)
        uid = parsed[1] if parsed else None
        if uid not in world.uavs or msg.mode not in LANDING_MODES or len(msg.actuators) != 4:
            drops.drop(key, f"not a landing UAV's rotor command: {uid!r}, mode {msg.mode}")
            return
        with cond:
            commands[(uid, msg.tick)] = msg
            cond.notify_all()

    def on_alive(role: str, pid: str, up: bool) -> None:
        if role == "agent":
            with cond:
                (alive.add if up else alive.discard)(pid)
                cond.notify_all()

    with open_session(zenoh_args_from(args)) as session:
        pubs: dict[str, object] = {}

        def put(wire) -> None:
            for key, payload in wire:
                pub = pubs.get(key)
                if pub is None:
                    pub = pubs[key] = declare_reliable(session, key, express=key != keys.world_event())
                pub.put(payload)

        subscribe_decoded(session, keys.agent_all("command"), Command, on_command, drops)
        subscribe_decoded(session, keys.fault(), Fault, on_fault, drops)
        watch_liveliness(session, keys, on_alive)
        _token = declare_liveliness(session, keys, "world", "world")
        print_ready("world", "landing")
        deadline = time.monotonic() + args.start_timeout
        with cond:
            while not set(ids) <= alive:
                if stop.is_set():
                    return 130
                if time.monotonic() > deadline:
                    raise ConfigError(
                        f"agents not up after {args.start_timeout:g} s: {sorted(set(ids) - alive)}"
                    )
                cond.wait(0.1)
        put([wire.run_start(keys, sc, args.seed, policy, ids, str(args.clock))])
        n_ticks = round(sc.max_duration_s / dt)
        k = 0
        t_wall = time.monotonic()
        reason = "done"
        free = not args.clock.lockstep
        pace = args.clock if free else args.pace
        held: dict[str, LandingCommand] = {}  # free-running: the command each UAV's rotors have
        late = dict.fromkeys(ids, 0)
        for k in range(1, n_ticks + 1):
            apply_faults(k)
            inputs = world.step(k)
            if not inputs:
                k -= 1
                break
            put(wire.world_tick(keys, world, k, inputs, args.seed))
            if free:  # until tick k's wall time: the newest command come by then is flown, the rest is late
                due = t_wall + k * dt / pace.factor
                with cond:
                    while not stop.is_set():
                        left = due - time.monotonic()
                        if left <= 0:
                            break
                        cond.wait(left)
                    newest = _newest(commands, k)
                if stop.is_set():
                    reason = "stopped"
                    break
                with cond:
                    gone = sorted(uid for uid in inputs if uid not in alive)
                if gone:  # nobody flies these UAVs any more: the run ends (a lockstep world would time out)
                    reason = "agent_missing"
                    _LOG.error("tick %d: agent_missing (%s lost)", k, ", ".join(gone))
                    break
                for uid in inputs:
                    cmd = newest.get(uid)
                    if cmd is None or cmd.tick < k:
                        late[uid] += 1
                    if cmd is not None and (uid not in held or cmd.tick > held[uid].k):
                        held[uid] = LandingCommand(cmd.tick, cmd.actuators, LandingMode(cmd.mode))
                    if uid in held:  # (before its first command a UAV keeps its hover trim)
                        h = held[uid]
                        world.hold(uid, LandingCommand(k, h.u, h.mode))
                continue
            step_deadline = time.monotonic() + args.step_timeout
            with cond:
                while not all((uid, k) in commands for uid in inputs):
                    if stop.is_set():
                        reason = "stopped"
                        break
                    if time.monotonic() > step_deadline:
                        reason = "agent_missing"
                        break
                    cond.wait(0.05)
                got = {uid: commands.pop((uid, k), None) for uid in inputs}
            if reason != "done":
                missing = [u for u, c in got.items() if c is None]
                _LOG.error("tick %d: %s (no command from %s)", k, reason, ", ".join(missing) or "-")
                break
            for uid, cmd in got.items():
                world.hold(uid, LandingCommand(k, cmd.actuators, LandingMode(cmd.mode)))
            if pace is not None:  # paced lockstep: never ahead of the wall clock (and still every command)
                left = t_wall + k * dt / pace.factor - time.monotonic()
                if left > 0:
                    stop.wait(left)
        for uid in ids:
            if not world.uavs[uid].done:
                world.uavs[uid].end_k = k
        wall = time.monotonic() - t_wall
        put(wire.run_end(keys, world, k, reason, wall, late if free else None))
        _LOG.info("run ended (%s) at tick %d, %.1f s simulated in %.1f s", reason, k, k * dt, wall)
        time.sleep(0.2)  # let the last messages leave before the session closes
        _ = _token
    return 0 if reason == "done" else 1


def _newest(commands: dict, k: int) -> dict:
    """Take every command of tick ``k`` or earlier out of ``commands`` (``(uid, tick) -> Command``): the
    newest of each UAV."""
    newest: dict = {}
    for key in [key for key in commands if key[1] <= k]:
        cmd = commands.pop(key)
        if key[0] not in newest or cmd.tick > newest[key[0]].tick:
            newest[key[0]] = cmd
    return newest


def main(argv: list[str] | None = None) -> int:
    return process_main("swarm.world.landing", DESCRIPTION, add_arguments, run, argv)


if __name__ == "__main__":
    sys.exit(main())
