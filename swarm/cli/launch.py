"""``swarm launch SCENARIO``: the whole swarm as separate processes over Zenoh.

The launcher opens a Zenoh **router** (``--listen``, default a free loopback port; the line ``swarm
listening on <endpoint>`` says where an outside client connects) and starts, each in its own process
group, the mothership, one agent per vehicle, the world and (unless ``--headless``) the dashboard. The
dashboard is a client of the router; the others are Zenoh peers that meet at the router and link directly
to one another (``--topology mesh``; ``auto``, the default, for a few processes), or clients of it
(``star``: ``auto`` for many, and the only topology with ``--secure``; ``swarm.cli.children.topology``),
docs/protocol.md "Processes and topology" (why a chaser's subscription to its target's estimate is in
place before the world announces the run, in either).

How the vehicles' agents share processes (a process each, or agent hosts of several), whether their
controller clocks are staggered and how a free-running agent wakes, the launcher chooses from the vehicle
count and the cores it may run on, and logs its plan (``swarm.cli.launch_plan``: 32 vehicles on 2 cores run
in four hosts of 8, staggered); ``--vehicles-per-process`` and ``--set swarm.stagger_control=...`` or
``--set agent.wake_at_control=...`` override their part of it.

It waits for every liveliness token (not for a time), supervises the children (an agent or the mothership
whose token goes or that exits is reported lost and restarted with ``--rejoin``, the world with
``--resume`` from the checkpoint it writes every tick into a private directory of the launcher; each with
exponential backoff, at most ``--max-restarts`` times), and collects the run from ``world/event``,
``agent/*/event`` and ``agent/*/guidance``. The summary has ``swarm sim``'s fields per chaser
(swarm/step/outcome.py) and the restarts of each process. After the run: ``--until-docked`` exits;
``--repeat`` starts
the next run with a new seed; otherwise the swarm stays up (for the dashboard) until Ctrl-C or
``--timeout``. Ctrl-C, SIGTERM or the end stop every child in an order that no process mistakes for a
failure (:mod:`swarm.transport.stopping`): a ``stopping`` event on ``world/event``, then the world, then
the rest, each by SIGTERM, then SIGKILL of its process group after a grace period; a stop logs no error
and no loss. ``--cpu-latency 0`` holds a PM QoS request that no CPU take longer than 0 us to wake while the
swarm runs (``swarm.cpu_latency``: processes woken every tick start on a warm CPU; needs root).

Exit status: 0 every chaser docked, 1 not (or the run failed), 2 bad input, 130 interrupted (Ctrl-C or
SIGTERM) before the run in progress ended, a ``--repeat``'s later run included; a stop after a run ended
(the swarm held for the dashboard, or the pause between two ``--repeat`` runs) exits with that run's
status.
"""

from __future__ import annotations

import argparse
import collections
import itertools
import json
import logging
import queue
import shutil
import signal
import threading
import time
from pathlib import Path

from swarm import cpu_latency
from swarm.cli.children import (
    MESH_MAX_PEERS,
    TOPOLOGIES,
    TOPOLOGY_TEXT,
    check_record,
    checkpoint_root,
    child_args,
    client_endpoint,
    config_args,
    launch_listen,
    router_args,
    secure_router,
    start_recorder,
    stop_swarm,
    swarm_processes,
    topology,
)
from swarm.cli.launch_plan import HOSTS_PER_CORE, PROCESS_EACH_PER_CORE, resolve_plan
from swarm.errors import ConfigError, SwarmError
from swarm.step.outcome import chaser_summary, run_summary
from swarm.transport.checkpoint import EXIT_BAD_CHECKPOINT
from swarm.transport.stopping import process_name

_LOG = logging.getLogger("swarm.launch")
HUNG_TICKS = 3
"""``--hung-ticks``'s default: an agent whose due command the lockstep world went without this many times in
a row (``--step-timeout`` each, 5 s) is hung, not slow: its stacks, then it is killed and restarted."""
STALL_S = 30.0
"""``--stall-s``'s default [s]: far beyond a tick's wait for a missing command (``--step-timeout``, 5 s) or
an agent's restart (a few seconds), so that only a hung process (or a stopped one) reaches it."""

GUIDANCE_KEPT = 256
"""Guidance messages the launcher keeps per chaser (25 s at 10 Hz): only the last one before its contact is
read, and none after a known contact is kept, so this need only span the contact event's way to the
launcher."""

VISION_COUNTS = ("features_accepted", "pose_accepted")


def add_parser(sub: argparse._SubParsersAction) -> None:
    from swarm.args import add_output_file, add_world_timeouts, count, positive_float
    from swarm.transport.process import add_process_arguments, clock_arg

    p = sub.add_parser(
        "launch",
        help="run the swarm as separate processes over Zenoh (world, mothership, agents, dashboard)",
        description=" ".join(__doc__.split("\n\n")[1:3]).replace("``", "").replace("**", ""),
    )
    add_process_arguments(p)
    g = p.add_argument_group("launcher")
    g.add_argument("--headless", action="store_true", help="do not start the dashboard")
    g.add_argument(
        "--secure", action="store_true",
        help="mutual TLS and Zenoh access control, certificates made at run time (docs/usage.md: Security)",
    )  # fmt: skip
    g.add_argument(
        "--topology", choices=TOPOLOGIES, default="auto",
        help="mesh: the world, mothership and agents are Zenoh peers linked directly to one another (one "
        "hop a message; the router stays their rendezvous and every client's gateway); star: each a client "
        f"of the launcher's router (every message crosses it); auto (default): a mesh of at most "
        f"{MESH_MAX_PEERS} processes, else a star, and a star with --secure",
    )  # fmt: skip
    g.add_argument("--dashboard-port", type=int, default=8080, metavar="PORT", help="dashboard port (8080)")
    g.add_argument(
        "--until-docked", action="store_true", help="exit when the run ends (every chaser in contact)"
    )
    g.add_argument("--repeat", action="store_true", help="after each run, start another with a new seed")
    g.add_argument(
        "--timeout", type=positive_float("--timeout"), default=None, metavar="S", help="wall-time limit [s]"
    )
    add_output_file(g, "--json", "write the summary (swarm/step/outcome.py)")
    g.add_argument(
        "--record",
        type=Path,
        default=None,
        metavar="FILE.mcap",
        help="record every message to an MCAP file (on the launcher's router session, before the run starts)",
    )
    g.add_argument(
        "--max-restarts", type=count("--max-restarts"), default=3, metavar="N",
        help="restarts of one process (an agent, the mothership or the world) before giving up on it "
        "(default 3); a world restarts from its checkpoint of the last tick and the run goes on",
    )  # fmt: skip
    g.add_argument(
        "--vehicles-per-process", type=count("--vehicles-per-process"), default=None, metavar="N",
        help="agent hosts: N vehicles' agents in one process (one Zenoh session), as ROS 2 component "
        "containers host nodes; keys and liveliness stay per vehicle, a lost host restarts its vehicles "
        f"(default: chosen from the vehicles and the cores, a process per vehicle up to "
        f"{PROCESS_EACH_PER_CORE} vehicles per core, else {HOSTS_PER_CORE} hosts per core, as are the "
        "staggered controller clocks and the agents' wake: swarm.cli.launch_plan; logged at the start)",
    )  # fmt: skip
    g.add_argument(
        "--pace", type=clock_arg, default=None, metavar="realtime|scaled:N",
        help="a lockstep run (every command waited for, so it still equals swarm sim) never ahead of this "
        "wall clock, to watch it or to leave the cores to others; --clock realtime or scaled:N alone is "
        "free-running",
    )  # fmt: skip
    g.add_argument(
        "--no-bundles", dest="bundles", action="store_false",
        help="a lockstep world sends each sample on its own key at its tick, not the ticks up to the next "
        "awaited command in one Bundle per receiver (docs/protocol.md, \"Bundles\"; the run is the same)",
    )  # fmt: skip
    g.add_argument(
        "--stall-s", type=positive_float("--stall-s"), default=STALL_S, metavar="S",
        help=f"when the world's clock stands still this long in a running run (docking or landing), say "
        f"so with every process's stacks (default {STALL_S:g}; kill -USR1 <launcher pid> asks for them at "
        "any time)",
    )  # fmt: skip
    g.add_argument(
        "--hung-ticks", type=count("--hung-ticks"), default=HUNG_TICKS, metavar="N",
        help=f"a lockstep agent whose due command the world went without N times in a row (--step-timeout "
        f"each) is hung: its stacks, then it is killed and restarted like a lost one (default {HUNG_TICKS}; "
        "0: never)",
    )  # fmt: skip
    add_world_timeouts(g)
    cpu_latency.add_argument(g)
    p.set_defaults(func=run)


def world_args(args: argparse.Namespace) -> list[str]:
    """The world process's own flags (the common ones and its Zenoh config aside)."""
    world = ["swarm.world", "--clock", str(args.clock), "--step-timeout", str(args.step_timeout),
             "--start-timeout", str(args.start_timeout),
             "--checkpoint-dir", str(args.checkpoint_dir)]  # fmt: skip
    if args.pace is not None:
        world += ["--pace", str(args.pace)]
    if _hosted(args):  # one message for many vehicles' imu, one for their truths
        world += ["--batch"]
    if not args.bundles:
        world += ["--no-bundles"]
    return world


def mothership_args(args: argparse.Namespace) -> list[str]:
    """The mothership process's own flags (the common ones and its Zenoh config aside)."""
    return ["mothership", *(["--batch"] if _hosted(args) else [])]  # one message for many vehicles' ranges


def _hosted(args: argparse.Namespace) -> bool:
    """Whether the agents run in hosts of several vehicles, which take the world's and the mothership's
    batches (docs/protocol.md, "Rates")."""
    return getattr(args, "vehicles_per_process", 1) > 1


def _hosts(args: argparse.Namespace, sc) -> dict[str, list[str]]:
    """The agent processes to start, ``{child name: [vehicle ids]}``: ``agent/<id>`` with one vehicle each
    (the default), or ``agents/<i>`` hosting ``--vehicles-per-process`` vehicles in scenario order."""
    n = getattr(args, "vehicles_per_process", 1)
    if n < 1 or n > 64:
        raise ConfigError(f"--vehicles-per-process must be an integer in 1..64, got {n}")
    ids = list(sc.vehicles)
    if n == 1:
        return {f"agent/{v}": [v] for v in ids}
    if getattr(args, "secure", False):
        raise ConfigError("--vehicles-per-process > 1 and --secure: an agent host would need every hosted "
                          "vehicle's identity; run secure swarms with one process per vehicle")  # fmt: skip
    return {f"agents/{i // n}": ids[i : i + n] for i in range(0, len(ids), n)}


def _child_of(args: argparse.Namespace, sc) -> dict[str, str]:
    """Vehicle id -> the name of the child process that hosts its agent."""
    return {v: name for name, vids in _hosts(args, sc).items() for v in vids}


class RunLog:
    """What the launcher hears of a run (thread-safe): the world's events, each agent's mode events,
    guidance and summary, and whether the world's clock stands still (:class:`StallWatch`)."""

    def __init__(self, stall_s: float = STALL_S, hung_ticks: int = HUNG_TICKS) -> None:
        from swarm.cli.supervisor import StallWatch

        self.stall = StallWatch(stall_s)
        self.hung_ticks = hung_ticks
        self.hung: queue.SimpleQueue = queue.SimpleQueue()  # agents found hung, for the supervising loop
        self.lock = threading.Lock()
        self.run_end: dict | None = None
        self.run_start: dict | None = None
        self.events: dict[str, list] = {}
        # per chaser, bounded (a long run of many chasers sent millions): the latest GUIDANCE_KEPT guidance
        # messages, none past its contact once that is known, and each Algorithm 1 record once (summarize)
        self.guidance: dict[str, collections.deque] = {}
        self.decisions: dict[str, dict[float, tuple[float, dict]]] = {}  # record's t_s -> (its message's, it)
        self._contact_t: dict[str, float] = {}  # a chaser's contact (or collision) time [s]
        self.summaries: dict[str, dict] = {}
        self.ended = threading.Event()
        self.t_s = 0.0  # the world's latest clock time [s]
        self.resumed: list[dict] = []  # the data of each world_resumed

    def on_clock(self, _key: str, msg) -> None:
        self.t_s = msg.t_s
        self.stall.on_clock(msg.tick, msg.state, time.monotonic())

    def on_world_event(self, _key: str, msg) -> None:
        with self.lock:
            if msg.kind == "run_start":
                self.run_start = msg.data
            elif msg.kind == "run_end":
                self.run_end = msg.data
                self.ended.set()
            elif msg.kind == "world_resumed":
                self.resumed.append(msg.data)
            elif msg.kind == "agent_missing":
                self._on_missing(msg.data)
        if msg.kind == "world_resumed":
            _LOG.warning("world resumed from its checkpoint at tick %s (t = %.2f s)", msg.data.get("tick"),
                         msg.t_s)  # fmt: skip

    def _on_missing(self, data: dict) -> None:
        """A lockstep tick the world stepped without some agents' commands (``agent_missing``, whose
        ``in_a_row`` counts each one's due commands missing since its last): an agent missing
        :attr:`hung_ticks` in a row is queued on :attr:`hung`, once per such run."""
        in_a_row = data.get("in_a_row")
        if self.hung_ticks <= 0 or not isinstance(in_a_row, dict):
            return
        for vid, n in in_a_row.items():
            if n == self.hung_ticks:
                self.hung.put((vid, n))

    def on_event(self, key: str, msg, keys) -> None:
        vid = (keys.parse(key) or (None, None))[1]
        with self.lock:
            if msg.kind == "summary":
                self.summaries[vid] = msg.data
            else:
                self.events.setdefault(vid, []).append(msg)
                if msg.kind in ("contact", "collision") and vid not in self._contact_t:
                    self._contact_t[vid] = msg.data["t_s"]

    def on_guidance(self, key: str, msg, keys) -> None:
        """Keep what :func:`summarize` reads of a chaser's guidance: its latest messages up to its contact
        (the last one gives the final mode and radii) and each Algorithm 1 record with the time of the
        first message that carried it (the records up to the contact)."""
        vid = (keys.parse(key) or (None, None))[1]
        with self.lock:
            if msg.t_s > self._contact_t.get(vid, float("inf")):
                return  # after its contact: never read (and a docked chaser flies on while others do not)
            self.guidance.setdefault(vid, collections.deque(maxlen=GUIDANCE_KEPT)).append(msg)
            dec = msg.decision
            if dec is not None:
                self.decisions.setdefault(vid, {}).setdefault(dec["t_s"], (msg.t_s, dec))


def summarize(sc, policy: str, seed: int, log: RunLog, wall_s: float) -> dict:
    """The run summary with ``swarm sim``'s fields per chaser, from what the launcher heard."""
    end = log.run_end or {}
    chasers = {}
    with log.lock:
        for cid in sc.chasers:
            events = log.events.get(cid, [])
            contact = next((e for e in events if e.kind in ("contact", "collision")), None)
            t_end = contact.data["t_s"] if contact is not None else float("inf")
            picked = [e.data for e in events if e.kind == "mode" and e.data.get("t_s", 0.0) <= t_end]
            picked.sort(key=lambda d: d["t_s"])
            if contact is not None:
                picked.append(contact.data)
            modes = [
                {"mode": d["to"], "t_s": d["t_s"], "range_m": d["range_m"], "reason": d["reason"]}
                for d in picked
            ]
            guid = [g for g in log.guidance.get(cid, ()) if g.t_s <= t_end]
            last = guid[-1] if guid else None
            decisions = [dec for t_s, dec in log.decisions.get(cid, {}).values() if t_s <= t_end]
            summary = log.summaries.get(cid, {})
            counts = summary.get("counts", {})
            c = chaser_summary(
                sc, cid,
                docked=bool(contact is not None and contact.data["docked"]),
                collided=bool(contact is not None and not contact.data["docked"]),
                docking_time_s=None if contact is None else contact.data["docking_time_s"],
                effort=end.get("effort", {}).get(cid),
                position_error_m=None if contact is None else contact.data["position_error_m"],
                attitude_error_rad=None if contact is None else contact.data["attitude_error_rad"],
                final_mode=last.mode if last is not None else summary.get("final_mode"),
                modes=modes,
                r1_m=last.r1_m if last is not None else summary.get("r1_m"),
                r2_m=last.r2_m if last is not None else summary.get("r2_m"),
                keepout_violated=any(e.kind == "keepout_violation" for e in events),
                closest_approach_m=end.get("closest_approach_m", {}).get(cid),
                contact=None if contact is None else contact.data["contact"],
                estimator={  # absent counters are zero; no summary at all: unknown
                    "rejected_ranges": counts.get("range_rejected", 0) if summary else None,
                    "accepted_ranges": counts.get("range_accepted", 0) if summary else None,
                    "accepted_vision": sum(counts.get(k, 0) for k in VISION_COUNTS) if summary else None,
                },
                wall_s=end.get("wall_s"),
                realtime_factor=end.get("realtime_factor"),
                restarted=any(e.kind == "restarted" for e in events),
                tick_assembly=summary.get("assembler"),  # the agent's drop counters of late/odd messages
            )  # fmt: skip
            if policy == "mdp":
                c["decisions"] = decisions
            chasers[cid] = c
    cpu = {"world": end.get("cpu_s"), **{v: s.get("cpu_s") for v, s in log.summaries.items()}}
    out = run_summary(sc, policy, seed, end.get("t_s"), end.get("wall_s", wall_s), end.get("effort", {}),
                      chasers, end_reason=end.get("reason", "no run_end received"), cpu_s=cpu)  # fmt: skip
    if end.get("realtime_factor") is not None:
        out["realtime_factor"] = end["realtime_factor"]
    for key in ("late_commands", "late_control_commands"):  # free-running: [late, of] (world/process.py)
        if end.get(key) is not None:
            out[key] = end[key]
    return out


def run(args: argparse.Namespace) -> int:
    """The launch, docking or landing, with ``--cpu-latency``'s request held from before the first process
    starts until the last has stopped."""
    with cpu_latency.hold(args.cpu_latency):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    import zenoh

    zenoh.try_init_log_from_env()  # RUST_LOG=...: Zenoh's own log (its ACL decisions: access_control=trace)

    from swarm.missions import mission_of

    return mission_of(args.scenario).run_launch(args)


def run_docking(args: argparse.Namespace) -> int:
    """``swarm launch`` of a docking scenario (:class:`swarm.missions.docking.DockingMission`)."""
    import zenoh

    from swarm.transport.process import check_pace

    check_pace(args.clock, args.pace)

    from swarm.cli.sim import print_summary
    from swarm.cli.supervisor import Child, Supervisor, forward_stacks_signal
    from swarm.transport.keys import Keys
    from swarm.transport.messages import (
        NEW_RUN_COMMANDS,
        Clock,
        DropCounter,
        Event,
        Guidance,
        encode,
        next_run_seed,
    )
    from swarm.transport.process import scenario_from
    from swarm.transport.session import (
        open_session,
        subscribe_decoded,
        watch_liveliness,
    )

    sc = scenario_from(args)
    plan = _plan(args, sc)
    if plan is not None:
        sc = scenario_from(args)  # with the plan's overrides
    _hosts(args, sc)  # the agent processes' layout (swarm_processes counts it), checked before any start
    check_record(args)
    # the world, the mothership and the agent processes (mesh with --secure refused before anything starts)
    args.links = links = topology(args, swarm_processes(len(sc.vehicles), args.vehicles_per_process))
    keys = Keys(args.namespace)
    policy = args.policy or sc.policy
    listen = launch_listen(args)  # (--secure: mutual TLS + Zenoh ACL, each process its own certificate)
    args.secure_material = None
    zargs = router_args(args, listen)
    endpoint = client_endpoint(listen[0])
    stop = threading.Event()
    interrupted = threading.Event()
    why = ["the launcher's end"]  # what the stop announcement says (swarm.transport.stopping)

    def on_signal(signum: int, _frame: object) -> None:
        why[0] = signal.Signals(signum).name
        _LOG.info("%s: stopping the swarm", why[0])
        interrupted.set()
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    sup = Supervisor(max_restarts=args.max_restarts)
    restore_stacks = forward_stacks_signal(sup)  # kill -USR1 <launcher>: every process's stacks
    alive_changes: queue.Queue = queue.Queue()
    seed = args.seed
    result: dict | None = None
    wall0 = time.monotonic()
    args.checkpoint_root = checkpoint_root()
    runs = itertools.count()
    try:
        zargs = secure_router(args, keys, sc.vehicles, listen, zargs, "docking")
        with open_session(zargs, lean=True) as session:  # its own swarm's paced ticks
            print(
                f"swarm listening on {' '.join(listen)} (clients: --mode client --connect {endpoint})",
                flush=True,
            )
            _LOG.info("the swarm's processes: %s", TOPOLOGY_TEXT[links])
            drops = DropCounter()
            # the current run's log: the callbacks always feed the current one
            box = [RunLog(args.stall_s, args.hung_ticks)]
            subscribe_decoded(
                session, keys.world_event(), Event, lambda k, m: box[0].on_world_event(k, m), drops
            )
            subscribe_decoded(session, keys.world_clock(), Clock, lambda k, m: box[0].on_clock(k, m), drops)
            subscribe_decoded(
                session, keys.agent_all("event"), Event, lambda k, m: box[0].on_event(k, m, keys), drops
            )
            for cid in sc.chasers:  # its chasers' only: a target's guidance is then sent to a viewer alone
                subscribe_decoded(
                    session, keys.guidance(cid), Guidance, lambda k, m: box[0].on_guidance(k, m, keys), drops
                )
            watch_liveliness(session, keys, lambda r, p, a: alive_changes.put((r, p, a, time.monotonic())))
            _token = session.liveliness().declare_token(keys.alive("launcher", "launcher"))

            def announce(vid: str | None, kind: str, data: dict) -> None:
                """An event for all: on the agent's key, or (``vid`` None: the world) on ``world/event``."""
                key = keys.event(vid) if vid is not None else keys.world_event()
                session.put(key, encode(Event(box[0].t_s, kind, data)))

            recorder = start_recorder(args, session, keys)  # --record: on this router session
            try:
                while True:  # one iteration per run
                    log = box[0]
                    result = None  # (a run stopped before its end has none: exit 130, not a past run's)
                    args.checkpoint_dir = args.checkpoint_root / f"run-{next(runs)}"
                    args.checkpoint_dir.mkdir()
                    _start_run(args, sc, seed, endpoint, sup, Child)
                    ok = _wait_alive(sc, sup, alive_changes, args.start_timeout, stop)
                    if not ok:
                        result = None
                        break
                    n_proc = len(sup.children)
                    paced = "" if args.pace is None else f" paced at {args.pace}"
                    print(f"swarm up: {n_proc} processes, seed {seed}, clock {args.clock}{paced}", flush=True)
                    outcome = _supervise(args, sc, sup, alive_changes, log, stop, wall0, announce)
                    if outcome == "ended":
                        _wait_summaries(sc, log, sup, child_of=_child_of(args, sc))
                        result = summarize(sc, policy, seed, log, time.monotonic() - wall0)
                        result["restarts"] = {c.name: c.restarts for c in sup.children.values()}
                        result["world_resumed_at"] = [d.get("tick") for d in log.resumed]
                        result["launch_plan"] = args.launch_plan
                        print_summary(result)
                        restarted = {n: r for n, r in result["restarts"].items() if r}
                        if restarted:
                            print("  restarts: " + ", ".join(f"{n} {r}" for n, r in restarted.items()))
                        if args.json is not None:
                            args.json.write_text(json.dumps(result, indent=1))
                        end = log.run_end or {}
                        # the dashboard asked for a new run
                        asked = end.get("reason") in NEW_RUN_COMMANDS
                        if (args.repeat or asked) and not stop.is_set():
                            seed = next_run_seed(end, seed)
                            if not asked:
                                stop.wait(3.0)  # a moment to look at the docked pair
                            if stop.is_set():  # Ctrl-C meanwhile: no next run
                                break
                            stop_swarm(sup, session, keys, "next run", log.t_s, keep=("dashboard",))
                            box[0] = RunLog(args.stall_s, args.hung_ticks)
                            continue
                        if not args.until_docked:
                            _hold(args, stop, wall0)
                    break
                _ = (_token, zenoh)
            finally:
                # every process's last samples are in before the file is finished; announced while the
                # session is open (a failure's way out too)
                stop_swarm(sup, session, keys, why[0], box[0].t_s)
                if recorder is not None:
                    recorder.close()
    finally:
        sup.stop_all()
        shutil.rmtree(args.checkpoint_root, ignore_errors=True)
        if args.secure_material is not None:
            args.secure_material.close()
        for s, h in previous.items():
            signal.signal(s, h)  # type: ignore[arg-type]
        restore_stacks()
    if interrupted.is_set() and result is None:
        return 130
    if result is None:
        return 1
    return 0 if result["chasers"] and all(c["docked"] for c in result["chasers"].values()) else 1


def _plan(args: argparse.Namespace, sc):
    """The swarm's layout (:func:`swarm.cli.launch_plan.resolve_plan`): ``args.vehicles_per_process`` set,
    the ``--set`` overrides of the parts the plan chose added to ``args.overrides`` (the children load the
    scenario with them), the plan logged and kept for the summary (``args.launch_plan``). Returns the plan
    when it added overrides (the launcher's scenario must be loaded again), else None."""
    plan, extra = resolve_plan(len(sc.vehicles), args.clock.lockstep, args.vehicles_per_process,
                               args.overrides, secure=bool(getattr(args, "secure", False)))  # fmt: skip
    args.vehicles_per_process = plan.vehicles_per_process
    args.overrides = [*args.overrides, *extra]
    args.launch_plan = plan.as_dict()
    _LOG.info("launch plan: %s", plan.describe())
    return plan if extra else None


def _start_run(args, sc, seed, endpoint, sup, Child):
    common = child_args(args, endpoint, seed)
    from swarm.transport.security import agent_name

    mothership = [*mothership_args(args), *common, *config_args(args, "mothership")]
    sup.start(Child("mothership", mothership, restartable=True, rejoin_args=["--rejoin"]))
    for name, vids in _hosts(args, sc).items():
        agent = ["agents", "--id", ",".join(vids), "--clock", str(args.clock), *common,
                 *config_args(args, agent_name(vids[0]))]  # fmt: skip
        sup.start(Child(name, agent, restartable=True, rejoin_args=["--rejoin"]))
    world = [*world_args(args), *common, *config_args(args, "world")]
    sup.start(Child("world", world, restartable=True, rejoin_args=["--resume"]))
    if not args.headless and not (sup.children.get("dashboard") and sup.children["dashboard"].running):
        dash = [str(args.scenario), "--agents", str(args.agents), "--namespace", args.namespace,
                "--port", str(args.dashboard_port), "--mode", "client", "--connect", endpoint]  # fmt: skip
        for o in args.overrides:
            dash += ["--set", o]
        dash += config_args(args, "dashboard")

        def on_line(line: str) -> None:
            if line.startswith("dashboard listening on "):
                print(f"dashboard on {line.split()[-1]}", flush=True)

        # kept across runs: the browser stays connected; restarted like the others when it dies (the page
        # reconnects to the same port and rebuilds its state from the next messages)
        sup.start(Child("dashboard", ["dashboard", *dash], restartable=True, on_line=on_line))


def _name(role: str, pid: str) -> str:
    """The liveliness name of a process (``agent/<id>`` per vehicle, even in an agent host)."""
    return f"agent/{pid}" if role == "agent" else role


def _wait_alive(sc, sup, changes: queue.Queue, timeout_s: float, stop: threading.Event) -> bool:
    want = {"world", "mothership", *(f"agent/{v}" for v in sc.vehicles)}
    seen: set[str] = set()
    deadline = time.monotonic() + timeout_s
    while not want <= seen:
        if stop.is_set():
            return False
        for c in sup.exited():
            _LOG.error("%s exited with status %s before it was up", c.name, c.popen.returncode)
            return False
        try:
            role, pid, alive, _ = changes.get(timeout=0.05)
        except queue.Empty:
            if time.monotonic() > deadline:
                _LOG.error("not up after %.0f s: %s", timeout_s, ", ".join(sorted(want - seen)))
                return False
            continue
        (seen.add if alive else seen.discard)(_name(role, pid))
    return True


def _supervise(
    args, sc, sup, changes: queue.Queue, log: RunLog, stop: threading.Event, wall0: float, announce=None
) -> str:
    """Until the run ends (``"ended"``), a stop (``"stopped"``), the timeout or a fatal loss
    (``"failed"``)."""
    child_of = _child_of(args, sc)
    while not stop.is_set():
        if log.ended.is_set():
            return "ended"
        if args.timeout is not None and time.monotonic() - wall0 > args.timeout:
            _LOG.error("--timeout %.0f s reached", args.timeout)
            sup.dump_all(f"--timeout {args.timeout:g} s reached before the run ended")
            return "failed"
        _restart_hung(args, sup, log, child_of, announce)
        log.stall.tell(sup, time.monotonic())
        try:
            role, pid, alive, t_seen = changes.get(timeout=0.05)
        except queue.Empty:
            role = None
        if role is not None and not alive and role in ("agent", "world", "mothership"):
            name = child_of.get(pid, _name(role, pid)) if role == "agent" else _name(role, pid)
            if name in sup.children:
                if role == "world" and log.ended.is_set():
                    continue  # the run is over: nothing to resume
                what = sup.lost(name, "liveliness token gone")
                if what:
                    _LOG.warning("%s (seen %.0f ms after the loss)", what, 1000 * (time.monotonic() - t_seen))
                if role in ("agent", "world") and announce is not None and what:
                    data = {"why": "liveliness token gone", "action": what}
                    announce(pid if role == "agent" else None, "lost", {**data, "role": role, "id": pid})
                if role == "world" and what and sup.children[name].next_start_s is None:
                    _LOG.error("the world is gone for good: the run cannot go on")
                    return "failed"
        elif role is not None and alive and role in ("agent", "world"):
            _LOG.info("%s is alive", process_name(role, pid))
        for c in sup.exited():
            code = c.popen.returncode
            if c.name == "world" and log.ended.is_set():
                continue
            if c.name == "world" and code == EXIT_BAD_CHECKPOINT:
                _LOG.error("world exited with status %d: it could not resume from its checkpoint (its log "
                           "says why); giving up rather than resuming from a bad state", code)  # fmt: skip
                c.popen = None
                return "failed"
            if c.name == "dashboard":  # the run does not need it: restarted while the budget lasts
                what = sup.lost(c.name, f"exited with status {code}")
                _LOG.warning("%s", what or f"dashboard exited with status {code}")
                c.popen = None
                continue
            what = sup.lost(c.name, f"exited with status {code}")
            if what:
                _LOG.warning("%s", what)
            if c.name == "world" and c.next_start_s is None:
                _LOG.error("the world is gone for good: the run cannot go on")
                return "failed"
        for c in sup.due_restarts():
            how = {"world": "resuming from its checkpoint", "dashboard": "serving the page again"}.get(
                c.name, "rejoining the run"
            )
            _LOG.warning("%s restarted (pid %d), %s", c.name, c.popen.pid, how)
    return "stopped"


def _restart_hung(args, sup, log: RunLog, child_of: dict[str, str], announce=None) -> None:
    """Each agent :class:`RunLog` found hung: its process's stacks (``swarm/stacks.py``), then it is killed
    and restarted as a lost one (:meth:`~swarm.cli.supervisor.Supervisor.lost`; a lockstep world waits for
    it to rejoin). A hung process keeps its liveliness token: without this the run would go on at one
    ``--step-timeout`` per tick."""
    while True:
        try:
            vid, ticks = log.hung.get_nowait()
        except queue.Empty:
            return
        name = child_of.get(vid)
        child = sup.children.get(name) if name is not None else None
        if child is None or not child.running:
            continue
        why = f"{ticks} due commands missing in a row ({args.step_timeout:g} s each): hung"
        _LOG.error("%s (%s): its stacks follow, then it is restarted", name, why)
        sup.dump_children(names=(name,))
        what = sup.lost(name, why)
        if what:
            _LOG.warning("%s", what)
            if announce is not None:
                announce(vid, "lost", {"why": why, "action": what, "role": "agent", "id": vid})


def _wait_summaries(sc, log: RunLog, sup, timeout_s: float = 3.0, *, child_of: dict[str, str]) -> None:
    """After ``run_end``, until every live agent's ``summary`` event arrived (or ``timeout_s``)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with log.lock:
            missing = [v for v in sc.vehicles if v not in log.summaries and sup.children[child_of[v]].running]
        if not missing:
            return
        time.sleep(0.01)


def _hold(args, stop: threading.Event, wall0: float) -> None:
    print("run over; the swarm stays up until Ctrl-C (or --timeout)", flush=True)
    while not stop.wait(0.1):
        if args.timeout is not None and time.monotonic() - wall0 > args.timeout:
            return


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="swarm launch")
    sub = parser.add_subparsers(dest="command", required=True)
    add_parser(sub)
    args = parser.parse_args(["launch", *(argv or [])])
    try:
        return args.func(args)
    except (ConfigError, SwarmError) as exc:
        print(f"swarm launch: error: {exc}")
        return 2
