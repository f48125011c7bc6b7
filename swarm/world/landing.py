"""The landing world process (``python -m swarm.world.landing SCENARIO``; started by ``swarm launch`` for a
landing scenario): the world step of :mod:`swarm.step.landing` for every UAV, over Zenoh, in lockstep.

Per tick ``k``, for every UAV not done: the truth steps, then the tick's samples go out on the UAV's keys
(``docs/protocol.md``): an ``Imu`` with ``acc_body`` (stamped ``t - dt``), on a UWB tick a ``Uwb`` (the
anchor's index; ``range_m`` nil when the anchor is out of reach; with ``uwb.mode`` tdoa2/tdoa3 a ``Tdoa`` on
``agent/<id>/tdoa`` instead: the differences heard since the last, possibly none), on a GNSS tick a
``Gnss``, on a camera tick a ``Vision`` of kind ``pixels`` (target ``pad-<uav>``, face ``+z``, every corner
of every detected marker: row ``4 m + c`` is corner ``c`` of marker ``m``; none when the pad is not in
view), and a ``Truth``; then, every ``--clock-every`` ticks (10), ``world/clock`` (also at the run's start
and on a resume). The world waits for each such UAV's ``Command`` of tick ``k`` (its mode one of the
landing modes; :class:`~swarm.transport.lockstep.CommandBarrier`, as the docking world), holds it, and
steps on. When
every UAV is done (landed for a second, or hovering at the abort height) it publishes ``run_end`` on
``world/event`` with each UAV's outcome and a ``stopped`` clock, and exits 0. It waits for every UAV's agent
(liveliness ``alive/agent/<id>``) before the first tick. It takes run-time faults on ``control/fault``
(``swarm fault``): ``camera_loss`` (the pad hidden from a UAV's camera) and ``uwb_dropout`` (its UWB replies
lost), for one UAV or all; other kinds are refused with a ``fault_refused`` event. It takes ``pause`` and
``resume`` on ``control/run`` (the dashboard's Run folder) between two ticks: paused, it steps nothing, its
clock says ``paused``, and a paced or free-running run's wall clock stops with it (no tick is late for the
pause; the run's ``wall_s`` leaves it out). ``reset`` and ``new_seed`` end the run before the next tick,
paused or not (``run_end``'s ``reason``, with the ``next_seed`` asked for, if any): ``swarm launch`` then
starts the next run, the same seed or a new one, with new processes. A restarted world resumes running.

``--clock lockstep`` (the default) steps as fast as the agents answer: the run is ``swarm sim``'s. With
``--pace`` a lockstep world also never runs ahead of the wall clock (at ``realtime`` or ``scaled:N``, to watch
the landing on the dashboard), still waiting for every command. ``--clock realtime`` or ``scaled:N`` alone is
a free-running world, as the docking world is: tick ``k`` is stepped at its wall time whatever the agents
did; each UAV flies the newest command it has (a command of tick ``k`` that comes after tick ``k``'s wall
time is late: the rotors keep the previous one, as a flight controller's mixer keeps its last setpoint), and
``run_end`` counts each UAV's late ticks. A slow agent then costs its UAV accuracy, not the swarm its pace.

Restarts (``swarm launch`` does them, as for a docking swarm). With ``--checkpoint-dir`` the world writes
its complete state at every tick ``k`` (:mod:`swarm.transport.checkpoint`: the truths, the sensors' random
streams, the faults, and the encoded samples of ticks ``k`` and ``k - 1``) right *after* it publishes tick
``k``'s samples, while the agents work on them, so that the write is off the tick's critical path. A world
killed before the write is done resumes from tick ``k - 1``, whose agents may have answered tick ``k``
already: each agent keeps its last two commands and sends again those of the resumed tick or later.
``--resume`` continues from the checkpoint: ``world_resumed`` on ``world/event`` (tick ``j``), tick ``j``'s
samples again (an agent drops what it already has), the commands the agents send again (one of a later
tick waits for its tick), then on as before, stepping and publishing again the same ticks (dropped by the
agents that had them). A lockstep run with its world killed and resumed is the uninterrupted run, bit for
bit. An agent whose liveliness token comes back in a running lockstep run (a restarted agent, warm from its
own checkpoint: :mod:`agents.landing`) is sent its UAV's samples of the tick before and of the current tick
again. A lost agent stops a lockstep world until it is back or ``--step-timeout`` passes; a free-running
world ends the run (its UAV would fly on without a controller).

SIGINT or SIGTERM ends the run before the next tick (``run_end`` ``stopped``) and the process exits 0; an
agent that goes once the world stops is logged as a stop, not a loss (:mod:`swarm.transport.stopping`).
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
import time

from swarm.transport.process import check_pace, exit_process, print_ready, process_main

_LOG = logging.getLogger("swarm.world.landing")
DESCRIPTION = "The landing world: quadrotor truth and sensors of every UAV, lockstep over Zenoh."


def add_arguments(p: argparse.ArgumentParser) -> None:
    from swarm.args import positive_float
    from swarm.transport.process import (
        add_checkpoint_arguments,
        add_clock_every,
        add_process_arguments,
        clock_arg,
    )

    add_process_arguments(p)
    p.add_argument("--step-timeout", type=positive_float("--step-timeout"), default=30.0, metavar="S",
                   help="give up when an agent's command of a tick has not come after this long")  # fmt: skip
    p.add_argument("--start-timeout", type=positive_float("--start-timeout"), default=60.0, metavar="S",
                   help="give up when the agents are not all up after this long")  # fmt: skip
    p.add_argument("--pace", type=clock_arg, default=None, metavar="CLOCK",
                   help="a lockstep world paced to this clock (realtime or scaled:N): every command waited "
                        "for, never ahead of the wall clock")  # fmt: skip
    add_clock_every(p)
    add_checkpoint_arguments(
        p,
        "the world's complete state to DIR/world.ckpt at every tick, so that a restart with --resume "
        "continues the run",
        "continue the run from the checkpoint in --checkpoint-dir (announced as "
        "world_resumed); a missing checkpoint is an error too",
    )


def run(args: argparse.Namespace, stop: threading.Event) -> int:
    from swarm.transport.checkpoint import EXIT_BAD_CHECKPOINT, CheckpointError

    try:
        return _run(args, stop)
    except CheckpointError as exc:
        print(f"swarm.world.landing: error: {exc}; not resuming", file=sys.stderr, flush=True)
        return EXIT_BAD_CHECKPOINT


def _run_id(sc, seed: int, policy: str, ids: list[str], clock: str) -> dict:
    """What a checkpoint must share with this world to be resumed by it."""
    from swarm.transport.checkpoint import fingerprint

    return {"scenario": sc.name, "fingerprint": fingerprint(sc), "seed": seed, "policy": policy, "uavs": ids,
            "clock": clock}  # fmt: skip


def _load_resume(args, world, run_id: dict) -> dict:
    """The checkpoint to resume from, its world state restored into ``world``; CheckpointError naming the
    file if it is missing, torn, or of another run."""
    from swarm.step.landing import SnapshotError
    from swarm.transport import checkpoint
    from swarm.transport.checkpoint import CheckpointError

    path = checkpoint.checkpoint_path(args.checkpoint_dir)
    st = checkpoint.load(path)
    checkpoint.check_run(f"checkpoint {path}", st.get("run"), run_id)
    try:
        world.restore(st["world"])
    except (SnapshotError, KeyError, TypeError, ValueError) as exc:
        raise CheckpointError(f"checkpoint {path}: unreadable world state: {exc}") from None
    return st


def _run(args: argparse.Namespace, stop: threading.Event) -> int:
    from swarm.config import parse_override
    from swarm.core.landing import LandingMode
    from swarm.errors import ConfigError
    from swarm.landing_scenario import load_landing
    from swarm.step.landing import LandingCommand, LandingWorld
    from swarm.transport import checkpoint, wire
    from swarm.transport.keys import Keys
    from swarm.transport.lockstep import CommandBarrier
    from swarm.transport.messages import (
        LANDING_MODES,
        NEW_RUN_COMMANDS,
        Command,
        DropCounter,
        Fault,
        RunControl,
    )
    from swarm.transport.process import declare_reliable
    from swarm.transport.session import (
        declare_liveliness,
        open_session,
        subscribe_decoded,
        watch_liveliness,
        zenoh_args_from,
    )
    from swarm.transport.stopping import Stopping

    check_pace(args.clock, args.pace)
    if args.resume and args.checkpoint_dir is None:
        raise ConfigError("--resume needs --checkpoint-dir (the directory of the checkpoint to resume)")
    sc = load_landing(args.scenario, dict(parse_override(o) for o in args.overrides))
    policy = args.policy or sc.policy
    keys = Keys(args.namespace)
    world = LandingWorld(sc, args.seed)
    ids = list(world.uavs)
    run_id = _run_id(sc, args.seed, policy, ids, str(args.clock))
    # read before joining the swarm: a bad checkpoint never shows up as a world
    resume = _load_resume(args, world, run_id) if args.resume else None
    ckpt = None
    if args.checkpoint_dir is not None:
        after = None if resume is None else resume["checkpoint"]
        ckpt = checkpoint.CheckpointFile(checkpoint.checkpoint_path(args.checkpoint_dir), after)
    dt = sc.dt_s
    drops = DropCounter()
    stopping = Stopping(stop)  # an agent that goes then is no loss (swarm.transport.stopping)
    cond = threading.Condition()
    commands: dict[tuple[str, int], Command] = {}  # free-running: each UAV's newest is flown at its tick
    barrier = CommandBarrier(ids)  # lockstep: every command of the tick is waited for
    alive: set[str] = set()
    back: set[str] = set()  # agents whose token came back in a running run: sent the current tick again
    # the tick whose commands are awaited, whether the run is on, and whether it is paused
    now = {"k": 0, "running": False, "paused": False}
    faults: list[Fault] = []  # run-time faults come, applied before the next tick's samples

    def on_fault(_key: str, msg: Fault) -> None:
        with cond:
            faults.append(msg)

    controls: list[RunControl] = []  # run controls come, taken between two ticks
    asked: dict = {}  # a reset or new_seed: the run ends, {"reason", "next_seed"}

    def on_control(_key: str, msg: RunControl) -> None:
        with cond:
            controls.append(msg)
            cond.notify_all()

    def paused_at(k: int) -> bool:
        """Take the pending run controls before tick ``k``; True when the run is paused. ``reset`` and
        ``new_seed`` end the run (``asked``), paused or not: the launcher starts the next one."""
        with cond:
            pending = list(controls)
            controls.clear()
        for msg in pending:
            if msg.command in NEW_RUN_COMMANDS:
                if not asked:
                    asked.update(reason=msg.command, next_seed=msg.seed)
                    _LOG.info("run control %s: the run ends at tick %d", msg.command, k - 1)
            elif now["paused"] != (msg.command == "pause"):
                now["paused"] = msg.command == "pause"
                state = "paused" if now["paused"] else "running"
                put([wire.clock(keys, k - 1, dt, args.seed, state)])
                _LOG.info("run control %s: clock %s at tick %d", msg.command, state, k - 1)
        return now["paused"] and not asked

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
        if args.clock.lockstep:  # a command of a tick stepped already (a restarted agent's) is stale
            barrier.add(uid, msg)
            return
        with cond:  # free-running: a late one still counts (the newest of each UAV is flown)
            commands[(uid, msg.tick)] = msg
            cond.notify_all()

    def on_alive(role: str, pid: str, up: bool) -> None:
        if role == "agent":
            with cond:
                (alive.add if up else alive.discard)(pid)
                if up and now["running"] and pid in world.uavs:
                    back.add(pid)
                elif not up and now["running"]:
                    stopping.gone(_LOG, f"agent {pid}", "agent %s lost at tick %d", pid, now["k"])
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
        subscribe_decoded(session, keys.run_control(), RunControl, on_control, drops)
        watch_liveliness(session, keys, on_alive)
        _token = declare_liveliness(session, keys, "world", "world")
        print_ready("world", "landing")
        deadline = time.monotonic() + args.start_timeout
        with cond:
            while not set(ids) <= alive:
                if stop.is_set():
                    return 0  # stopped before the run (a stop is no failure)
                if time.monotonic() > deadline:
                    raise ConfigError(
                        f"agents not up after {args.start_timeout:g} s: {sorted(set(ids) - alive)}"
                    )
                cond.wait(0.1)
        n_ticks = round(sc.max_duration_s / dt)
        k0, tick_wire, prev_wire, uids = 1, [], [], []
        reason = "done"
        free = not args.clock.lockstep
        pace = args.clock if free else args.pace
        held: dict[str, LandingCommand] = {}  # free-running: the command each UAV's rotors have
        late = dict.fromkeys(ids, 0)
        wall_before = 0.0  # a resumed run's wall time before the restart
        if resume is not None:
            k0, tick_wire, prev_wire, uids = (
                resume["tick"],
                resume["wire"],
                resume["prev_wire"],
                resume["uids"],
            )
            held, late, wall_before = resume["held"], resume["late"], resume["wall_s"]
            put([wire.world_event(keys, "world_resumed", (k0 - 1) * dt, {"tick": k0}),
                 wire.clock(keys, k0 - 1, dt, args.seed)])  # fmt: skip
            _LOG.warning("resumed from the checkpoint of tick %d (t = %.2f s)", k0, k0 * dt)
        else:
            put([wire.landing_run_start(keys, sc, args.seed, policy, ids, str(args.clock)),
                 wire.clock(keys, 0, dt, args.seed)])  # fmt: skip
        k = k0 - 1
        # the wall clock of tick k is t_wall + k dt / factor (a resumed run starts its clock again at k0 - 1)
        t_wall = time.monotonic() - (k0 - 1) * dt / (pace.factor if pace is not None else 1.0)
        t_start = time.monotonic()
        with cond:
            now["running"] = True
        for k in range(k0, n_ticks + 1):
            if paused_at(k):  # between two ticks: tick k - 1 flown, tick k not stepped; the wall clock stops
                paused_since = time.monotonic()
                while not stop.is_set():
                    with cond:
                        cond.wait_for(lambda: controls or stop.is_set(), 0.1)
                    if not paused_at(k):
                        break
                if stop.is_set():
                    reason = "stopped"
                    break
                # a paced or free-running run's ticks keep their spacing after it; the run's wall time leaves
                # it out
                t_wall += time.monotonic() - paused_since
                t_start += time.monotonic() - paused_since
            if asked:  # the dashboard's Reset or New seed: the run ends before tick k
                k -= 1
                reason = asked["reason"]
                break
            stepped = resume is None or k > k0  # (a resumed world's first tick is the checkpoint's, stepped)
            if stepped:
                apply_faults(k)
                inputs = world.step(k)
                if not inputs:
                    k -= 1
                    break
                uids = list(inputs)
                prev_wire, tick_wire = tick_wire, wire.landing_world_tick(keys, world, k, inputs, args.seed,
                                                                  args.clock_every)  # fmt: skip
            with cond:
                now["k"] = k
                back.clear()
            put(tick_wire)
            if ckpt is not None and stepped:
                # after the samples went out, while the agents work on them (off the tick's critical path):
                # a world killed before this write resumes at k - 1, whose commands and tick k's the agents
                # send again (module docstring)
                ckpt.write({"run": run_id, "tick": k, "world": world.snapshot(), "wire": tick_wire,
                            "prev_wire": prev_wire, "uids": uids, "held": held, "late": late,
                            "wall_s": wall_before + time.monotonic() - t_start})  # fmt: skip
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
                    gone = sorted(uid for uid in uids if uid not in alive)
                if gone and stopping:  # the swarm is stopping: its agents go, no fault
                    reason = "stopped"
                    break
                if gone:  # nobody flies these UAVs any more: the run ends (a lockstep world would time out)
                    reason = "agent_missing"
                    _LOG.error("tick %d: agent_missing (%s lost)", k, ", ".join(gone))
                    break
                for uid in uids:
                    cmd = newest.get(uid)
                    if cmd is None or cmd.tick < k:
                        late[uid] += 1
                    if cmd is not None and (uid not in held or cmd.tick > held[uid].k):
                        held[uid] = LandingCommand(cmd.tick, cmd.actuators, LandingMode(cmd.mode))
                    if uid in held:  # (before its first command a UAV keeps its hover trim)
                        h = held[uid]
                        world.hold(uid, LandingCommand(k, h.u, h.mode))
                continue
            barrier.set_live(uids)  # every UAV still flying commands every tick
            step_deadline = time.monotonic() + args.step_timeout
            while True:  # the stop looked at before each wait: agents that answer within a poll never
                # leave it a timed-out one (a paced run stopped mid-run otherwise flew on to its end)
                if stop.is_set():
                    reason = "stopped"
                    break
                if barrier.poll(k, 0.05):
                    break
                if time.monotonic() > step_deadline:
                    reason = "agent_missing"
                    break
                with cond:  # a restarted agent: its UAV's samples of the tick before (which its checkpoint
                    # may lack: it writes it after its command) and of this tick again
                    again = [(key, d) for key, d in (*prev_wire, *tick_wire) if _owner(keys, key) in back]
                    if back:
                        _LOG.warning("agent %s back at tick %d: its samples sent again",
                                     ", ".join(sorted(back)), k)  # fmt: skip
                    back.clear()
                put(again)
            got, missing = barrier.wait(k, 0)
            if reason != "done":
                if reason == "agent_missing":  # (stopped: no fault)
                    _LOG.error("tick %d: %s (no command from %s)", k, reason, ", ".join(missing) or "-")
                break
            for uid in uids:
                world.hold(uid, LandingCommand(k, got[uid].actuators, LandingMode(got[uid].mode)))
            if pace is not None:  # paced lockstep: never ahead of the wall clock (and still every command)
                left = t_wall + k * dt / pace.factor - time.monotonic()
                if left > 0:
                    stop.wait(left)
        with cond:
            now["running"] = False
        for uid in ids:
            if not world.uavs[uid].done:
                world.uavs[uid].end_k = k
        wall = wall_before + time.monotonic() - t_start
        if ckpt is not None:
            ckpt.close()
        late_ticks = late if free else None
        put(wire.landing_run_end(keys, world, k, reason, wall, late_ticks, asked.get("next_seed")))
        _LOG.info("run ended (%s) at tick %d, %.1f s simulated in %.1f s", reason, k, k * dt, wall)
        time.sleep(0.2)  # let the last messages leave before the session closes
        _ = _token
    # an end asked for (a new run, a stop) is no failure
    return 0 if reason in ("done", "stopped") or reason in NEW_RUN_COMMANDS else 1


def _owner(keys, key: str) -> str | None:
    """The UAV whose key ``key`` is (None: a swarm-wide key)."""
    parsed = keys.parse(key)
    return None if parsed is None else parsed[1]


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
    exit_process(main())
