"""``swarm launch`` of a landing scenario (``swarm launch landing-swarm --headless``): the landing world
process (:mod:`swarm.world.landing`) and one landing agent process per UAV (:mod:`agents.landing`), Zenoh
peers linked directly to one another that met at the launcher's router (a mesh) or clients of it (a star;
``--topology``, :func:`swarm.cli.children.topology`), in lockstep. The launcher waits for the world's
``run_end`` and each agent's ``summary``, prints every UAV's outcome as ``swarm sim`` does (``--json FILE``
writes the same summary as ``swarm sim landing-swarm --json``, but ``decisions`` is the number of Algorithm
1 records, the records themselves stay in the agent), stops every process and exits 0 if every UAV landed on
its pad or aborted safely. With ``--record FILE.mcap`` the launcher's router session records the run
(:class:`swarm.cli.children.LauncherRecorder`).

Unless ``--headless``, the dashboard (``python -m dashboard SCENARIO``: pads, quadrotors, camera frustums,
energy; :mod:`dashboard.landing`) is started first, on ``--dashboard-port``, and the run starts once it
serves (it prints ``dashboard on <url>``), so that it shows the whole run; after the run the processes stay
up for it until Ctrl-C or ``--timeout`` (``--until-docked``: exit when the run ends, as headless). A
dashboard that exits is reported and the run goes on without it.

``--clock lockstep --pace realtime`` (or ``scaled:N``) paces the lockstep to the wall clock (to watch the
landing): the world still waits for every command, so the run still equals ``swarm sim``. ``--clock
realtime`` or ``scaled:N`` alone is free-running, as a docking swarm's: the world steps at the wall clock,
each UAV flies the newest command that has come (:mod:`swarm.world.landing`), and the summary gives each
UAV's late ticks.

``--vehicles-per-process N`` runs N UAVs' agents in one process (an agent host, as for a docking swarm).

``--secure`` gives every process its own certificate and the router an access control list of what each
may publish and subscribe (:mod:`swarm.transport.security`, mission ``landing``), as for a docking swarm.

A hung process keeps its liveliness token; the world's clock says it: when it stands at one tick for
``--stall-s`` in a running run, the launcher writes every process's Python stacks (docs/usage.md, "A hung
process"), as for a docking swarm, and ``--timeout`` does so before it stops an unfinished run.

Run-time faults come from ``swarm fault`` (``camera_loss``, ``uwb_dropout``: :mod:`swarm.world.landing`).

A process that exits before the run ends (killed, crashed) is restarted, with exponential backoff, at most
``--max-restarts`` times each, as in a docking swarm: the world with ``--resume`` from the checkpoint it
writes every tick into a private directory of the launcher (:mod:`swarm.world.landing`), an agent (or an
agent host) in lockstep warm from its own (:mod:`agents.landing`). A lockstep run with the world or agents
killed and restarted is the uninterrupted run, bit for bit; the summary says how often each process was
restarted (``restarts`` in ``--json``). Free-running, a lost agent ends the run (the world would fly its UAV
without a controller), so agents are not restarted there; the world is. ``--max-restarts 0`` restarts
nothing and writes no checkpoint.

The dashboard (and any ``control/run`` publisher) pauses and resumes a landing world. Its Reset and New
seed end the run (``run_end``'s ``reason``, with the ``next_seed`` asked for): the launcher then stops the
world and the agents (not the dashboard) and starts the next run, with the same seed or the one asked for
(else the seed after), each run's checkpoints in a directory of their own. ``--repeat`` does the same after
every run (the seed after), as for a docking swarm; ``--json`` holds the last run's summary.

Every stop (Ctrl-C, SIGTERM, the end, the next run) is the docking launcher's, in the same order
(:mod:`swarm.transport.stopping`: ``stopping`` on ``world/event``, the world, then the rest), and logs no
error and no loss. Exit status, as a docking launch's: 0 every UAV landed or aborted safely, 1 not (or the
run failed), 2 bad input, 130 stopped before the run in progress ended; stopped after a run ended (held for
the dashboard, or in the pause between two ``--repeat`` runs, which then starts no next run), that run's.
"""

from __future__ import annotations

import argparse
import itertools
import json
import logging
import shutil
import signal
import threading
import time

from swarm.errors import ConfigError
from swarm.transport.process import check_pace

_LOG = logging.getLogger("swarm.launch")


def _refuse(args: argparse.Namespace) -> None:
    if getattr(args, "secure", False) and args.vehicles_per_process > 1:
        raise ConfigError("--vehicles-per-process > 1 and --secure: an agent host would need every hosted "
                          "UAV's identity; run secure swarms with one process per UAV")  # fmt: skip
    if args.agents != 1:
        raise ConfigError("--agents: a landing scenario lists its UAVs ([[fleet]] in the file)")
    check_pace(args.clock, args.pace)


def _start_dashboard(args, endpoint: str, sup, Child, stop: threading.Event) -> None:
    """The dashboard child (module docstring), once it serves: it prints its URL as ``dashboard on <url>``.
    ConfigError if it exits or does not serve within ``--start-timeout``."""
    ready = threading.Event()

    def on_line(line: str) -> None:
        if line.startswith("dashboard listening on "):
            print(f"dashboard on {line.split()[-1]}", flush=True)
            ready.set()

    dash = [str(args.scenario), "--namespace", args.namespace, "--port", str(args.dashboard_port),
            "--mode", "client", "--connect", endpoint]  # fmt: skip
    for o in args.overrides:
        dash += ["--set", o]
    from swarm.cli.children import config_args

    dash += config_args(args, "dashboard")
    sup.start(Child("dashboard", ["dashboard", *dash], on_line=on_line))
    deadline = time.monotonic() + args.start_timeout
    while not ready.wait(0.1):
        if stop.is_set():
            return
        if sup.exited() or time.monotonic() > deadline:
            raise ConfigError(f"the dashboard did not serve within {args.start_timeout:g} s (its log says)")


def _hold(args: argparse.Namespace, stop: threading.Event, wall0: float) -> None:
    """After the run, keep the processes (the dashboard) up until Ctrl-C or ``--timeout``."""
    print("run over; the dashboard stays up until Ctrl-C (or --timeout)", flush=True)
    while not stop.wait(0.1):
        if args.timeout is not None and time.monotonic() - wall0 > args.timeout:
            return


def run_landing_launch(args: argparse.Namespace) -> int:
    import zenoh

    from swarm.cli.children import (
        TOPOLOGY_TEXT,
        check_record,
        checkpoint_root,
        client_endpoint,
        launch_listen,
        router_args,
        secure_router,
        start_recorder,
        stop_swarm,
        swarm_processes,
        topology,
    )
    from swarm.cli.supervisor import Child, StallWatch, Supervisor, forward_stacks_signal
    from swarm.config import parse_override
    from swarm.landing_scenario import load_landing
    from swarm.transport.checkpoint import EXIT_BAD_CHECKPOINT
    from swarm.transport.keys import Keys
    from swarm.transport.messages import (
        NEW_RUN_COMMANDS,
        Clock,
        DropCounter,
        Event,
        next_run_seed,
        safe_decode,
    )
    from swarm.transport.session import open_session, subscribe_decoded

    _refuse(args)
    check_record(args)
    sc = load_landing(args.scenario, dict(parse_override(o) for o in args.overrides))
    ids = [u.id for u in sc.uavs()]
    # the world and the agent processes (resolved before anything starts: mesh with --secure is refused)
    n_proc = swarm_processes(len(ids), args.vehicles_per_process, mothership=False)
    args.links = links = topology(args, n_proc)
    policy = args.policy or sc.policy
    keys = Keys(args.namespace)
    listen = launch_listen(args)  # (--secure: mutual TLS + Zenoh ACL, mission "landing", as a docking swarm)
    zargs = router_args(args, listen)
    endpoint = client_endpoint(listen[0])
    stop = threading.Event()
    why = ["the launcher's end"]  # what the stop announcement says (swarm.transport.stopping)

    def on_signal(signum: int, _frame: object) -> None:
        why[0] = signal.Signals(signum).name
        _LOG.info("%s: stopping the swarm", why[0])
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    cond = threading.Condition()
    got: dict = {"run_end": None, "summaries": {}}
    sup = Supervisor(max_restarts=args.max_restarts)
    restore_stacks = forward_stacks_signal(sup)  # kill -USR1 <launcher>: every process's stacks
    wall0 = time.monotonic()
    result = None
    args.secure_material = None
    ckpt_root = checkpoint_root()  # the world's and the agents' checkpoints (removed at exit)
    restarts = args.max_restarts > 0  # (--max-restarts 0: no restart, so no checkpoint written either)
    restart_agents = restarts and args.clock.lockstep  # (free-running, a lost agent ends the run: docstring)
    try:
        platforms = (sc.platform.id,) if sc.platform.enabled and sc.platform.share_estimate else ()
        zargs = secure_router(args, keys, ids, listen, zargs, "landing", platforms)
        with open_session(zargs, lean=True) as session:  # its own swarm's paced ticks
            print(
                f"swarm listening on {' '.join(listen)} (clients: --mode client --connect {endpoint})",
                flush=True,
            )
            _LOG.info("the swarm's processes: %s", TOPOLOGY_TEXT[links])
            drops = DropCounter()

            def on_world_event(_key: str, msg: Event) -> None:
                if msg.kind == "run_end":
                    with cond:
                        got["run_end"] = msg.data
                        cond.notify_all()

            def on_agent_event(key: str, msg: Event) -> None:
                parsed = keys.parse(key)
                if parsed is not None and msg.kind == "summary":
                    with cond:
                        got["summaries"][parsed[1]] = msg.data
                        cond.notify_all()

            subscribe_decoded(session, keys.world_event(), Event, on_world_event, drops)
            subscribe_decoded(session, keys.agent_all("event"), Event, on_agent_event, drops)
            # a hung process keeps its token: the world's clock says it. The newest is kept in Zenoh
            # (RingChannel(1), as the dashboard takes it) and looked at from the loop below, not decoded in a
            # callback for each
            stall = StallWatch(args.stall_s)
            clock = session.declare_subscriber(keys.world_clock(), zenoh.handlers.RingChannel(1))

            def watch_clock() -> None:
                now, sample = time.monotonic(), clock.try_recv()
                msg = (
                    None if sample is None else safe_decode(sample.payload, Clock, keys.world_clock(), drops)
                )
                if msg is not None:
                    stall.on_clock(msg.tick, msg.state, now)
                stall.tell(sup, now)

            recorder = start_recorder(args, session, keys)  # --record: on this router session
            try:
                if not args.headless:
                    _start_dashboard(args, endpoint, sup, Child, stop)
                seed = args.seed
                for run_i in itertools.count():  # one iteration per run (reset, new seed, --repeat)
                    with cond:
                        got["run_end"], got["summaries"] = None, {}
                    result = None  # (a run stopped before its end has none: exit 130, not a past run's)
                    run_dir = ckpt_root / f"run-{run_i}"  # this run's checkpoints: none of another run's
                    run_dir.mkdir()
                    _start_run(args, ids, endpoint, seed, run_dir, sup, restarts, restart_agents)
                    deadline = None if args.timeout is None else wall0 + args.timeout
                    with cond:
                        while got["run_end"] is None:
                            if stop.is_set():
                                break
                            if deadline is not None and time.monotonic() > deadline:
                                _LOG.error("--timeout: %.0f s passed before the run ended", args.timeout)
                                sup.dump_all(f"--timeout {args.timeout:g} s reached before the run ended")
                                break
                            watch_clock()
                            dead = sup.exited()
                            for c in [c for c in dead if c.name == "dashboard"]:  # the run does not need it
                                _LOG.warning(
                                    "the dashboard exited with status %s; the run goes on without it",
                                    c.popen.returncode,
                                )
                                c.popen = None
                            dead = [c for c in dead if c.name != "dashboard"]
                            if got["run_end"] is None and _lost(sup, dead, EXIT_BAD_CHECKPOINT):
                                break
                            for c in sup.due_restarts():
                                how = (
                                    "resuming from its checkpoint"
                                    if c.name == "world"
                                    else "warm, from its checkpoint"
                                )
                                _LOG.warning("%s restarted (pid %d), %s", c.name, c.popen.pid, how)
                            cond.wait(0.1)
                        end = time.monotonic() + 10.0
                        while got["run_end"] is not None and not set(ids) <= set(got["summaries"]):
                            if time.monotonic() > end:
                                missing = sorted(set(ids) - set(got["summaries"]))
                                _LOG.error("no summary from %s", ", ".join(missing))
                                break
                            cond.wait(0.1)
                    if got["run_end"] is not None and set(ids) <= set(got["summaries"]):
                        result = _result(
                            args, sc, policy, seed, ids, got["run_end"], got["summaries"], sup, wall0
                        )
                    end_data = got["run_end"] or {}
                    asked = end_data.get("reason") in NEW_RUN_COMMANDS  # the dashboard's Reset, New seed
                    if (args.repeat or asked) and got["run_end"] is not None and not stop.is_set():
                        seed = next_run_seed(end_data, seed)
                        if not asked:
                            stop.wait(3.0)  # a moment to look at the landed UAVs
                        if stop.is_set():  # Ctrl-C meanwhile: no next run
                            break
                        stop_swarm(sup, session, keys, "next run", keep=("dashboard",))
                        continue
                    if not args.headless and not args.until_docked and got["run_end"] is not None:
                        _hold(args, stop, wall0)
                    break
            finally:
                # every process's last samples are in before the file is finished; announced while the
                # session is open (a failure's way out too)
                stop_swarm(sup, session, keys, why[0])
                if recorder is not None:
                    recorder.close()
    finally:
        sup.stop_all()
        shutil.rmtree(ckpt_root, ignore_errors=True)
        if args.secure_material is not None:
            args.secure_material.close()
        for s, h in previous.items():
            signal.signal(s, h)  # type: ignore[arg-type]
        restore_stacks()
    if result is None:
        return 130 if stop.is_set() else 1
    ok = result["run_end_reason"] == "done" and all(
        r["landed"] or r["aborted"] for r in result["uavs"].values()
    )
    return 0 if ok else 1


def _start_run(args, ids: list[str], endpoint: str, seed: int, run_dir, sup, restarts: bool,
               restart_agents: bool) -> None:  # fmt: skip
    """Start one run's processes, the agents (``--vehicles-per-process`` UAVs each) and the world, their
    checkpoints in ``run_dir`` where they may be restarted, and say so (``swarm up: ...``)."""
    from swarm.cli.children import child_args, config_args
    from swarm.cli.supervisor import Child
    from swarm.transport.security import agent_name

    common = child_args(args, endpoint, seed)
    n = args.vehicles_per_process  # agent hosts: N UAVs' agents in one process (default 1)
    for i in range(0, len(ids), n):
        host = ids[i : i + n]
        name = f"agent/{host[0]}" if n == 1 else f"agents/{'+'.join(host)}"
        identity = agent_name(host[0])  # (an agent host is refused with --secure: _refuse)
        agent = ["agents.landing", "--id", ",".join(host), *common, *config_args(args, identity)]
        if restart_agents:
            agent += ["--checkpoint-dir", str(run_dir)]
        sup.start(Child(name, agent, restartable=restart_agents, rejoin_args=["--resume"]))
    world_ckpt = ["--checkpoint-dir", str(run_dir)] if restarts else []
    world = ["swarm.world.landing", "--clock", str(args.clock),
             *(["--pace", str(args.pace)] if args.pace is not None else []),
             "--step-timeout", str(args.step_timeout),
             "--start-timeout", str(args.start_timeout), *common,
             *world_ckpt, *config_args(args, "world")]  # fmt: skip
    sup.start(Child("world", world, restartable=restarts, rejoin_args=["--resume"]))
    print(
        f"swarm up: world and {len(ids)} landing agents in {-(-len(ids) // n)} processes, "
        f"seed {seed}, clock {_clock_name(args.clock, args.pace)}",
        flush=True,
    )


def _result(args, sc, policy: str, seed: int, ids: list[str], end_data: dict, summaries: dict, sup,
            wall0: float) -> dict:  # fmt: skip
    """The run's summary from the world's ``run_end`` and each agent's ``summary`` event (``swarm sim``'s
    fields per UAV), printed, and written to ``--json``."""
    from swarm.cli.sim import print_landing
    from swarm.step.landing import landing_summary

    wall = float(end_data.get("wall_s", time.monotonic() - wall0))
    uavs = {}
    for uid in ids:
        w = end_data["uavs"][uid]
        uavs[uid] = landing_summary(sc, policy, seed, w, summaries[uid], w["end_tick"], wall)
        if "late_ticks" in w:  # free-running: ticks flown on an older command
            uavs[uid]["late_ticks"] = int(w["late_ticks"])
    result = {
        "scenario": sc.name,
        "policy": policy,
        "seed": seed,
        "camera_mode": sc.camera.mode,
        "landed": sum(1 for v in uavs.values() if v["landed"]),
        "uavs": uavs,
        "sim_time_s": round(int(end_data["ticks"]) * sc.dt_s, 4),
        "wall_s": wall,
        "run_end_reason": end_data.get("reason"),
        "restarts": {c.name: c.restarts for c in sup.children.values()},
    }
    for uid, r in uavs.items():
        print(f"[{uid}]", end=" ")
        print_landing(r)
    n_ok, sim_s = result["landed"], result["sim_time_s"]
    how = _clock_name(args.clock, args.pace)
    print(f"{n_ok} of {len(ids)} UAVs landed on their pads in {sim_s:.1f} s simulated "
          f"({wall:.1f} s of wall time, {how} over Zenoh)", flush=True)  # fmt: skip
    restarted = {n: r for n, r in result["restarts"].items() if r}
    if restarted:
        print("restarts: " + ", ".join(f"{n} {r}" for n, r in restarted.items()), flush=True)
    late = {u: r["late_ticks"] for u, r in uavs.items() if "late_ticks" in r}
    if late:
        ticks = max(1, int(end_data["ticks"]))
        print("late ticks (flown on an older command): " + ", ".join(
            f"{u} {n} ({n / ticks:.1%})" for u, n in late.items()), flush=True)  # fmt: skip
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=1))
    return result


def _lost(sup, dead: list, bad_checkpoint: int) -> bool:
    """The processes that exited before the run ended, restarted if they may be (:meth:`~swarm.cli.
    supervisor.Supervisor.lost`); True when one is gone for good (not restartable, out of restarts, or a
    checkpoint it cannot resume from): the run cannot end."""
    for c in dead:
        code = c.popen.returncode
        if code == bad_checkpoint:
            _LOG.error("%s exited with status %d: it could not resume from its checkpoint (its log says "
                       "why); giving up rather than resuming from a bad state", c.name, code)  # fmt: skip
            return True
        what = sup.lost(c.name, f"exited with status {code}")
        if what:
            _LOG.warning("%s", what)
        if c.next_start_s is None:
            _LOG.error("%s exited with status %s before the run ended", c.name, code)
            return True
    return False


def _clock_name(clock, pace=None) -> str:
    if not clock.lockstep:
        return f"free-running at {clock}"
    return "lockstep" if pace is None else f"lockstep paced at {pace}"
