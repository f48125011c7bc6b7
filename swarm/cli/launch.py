"""``swarm launch SCENARIO``: the whole swarm as separate processes over Zenoh, for every mission.

The launcher opens a Zenoh **router** (``--listen``, default a free loopback port; the line ``swarm
listening on <endpoint>`` says where an outside client connects) and starts, each in its own process
group, the dashboard (unless ``--headless``: it prints ``dashboard on <url>``, and the run starts once it
serves), then the world and the agents (a docking swarm also has a mothership). The dashboard is a client of
the router; the others are Zenoh peers that meet at the router and link directly to one another
(``--topology mesh``; ``auto``, the default, for a few processes), or clients of it (``star``: ``auto`` for
many, and the only topology with ``--secure``; ``swarm.cli.children.topology``), docs/protocol.md
"Processes and topology". How the vehicles' agents share processes, whether their controller clocks are
staggered and how a free-running agent wakes, the launcher chooses from the vehicle count and the cores
(``swarm.cli.launch_plan``; a landing swarm runs a process per UAV); ``--vehicles-per-process`` and
``--set swarm.stagger_control=...`` or ``--set agent.wake_at_control=...`` override their part of it.

It waits for every liveliness token (not for a time), supervises the children (a process whose token goes
or that exits is reported lost and restarted, an agent or the mothership to rejoin the run, the world with
``--resume`` from the checkpoint it writes every tick into a private directory of the launcher; each with
exponential backoff, at most ``--max-restarts`` times), tells a world clock that stands still
(``--stall-s``) with every process's stacks, and collects the run's events. The summary has ``swarm
sim``'s fields per vehicle and the restarts of each process. After the run: ``--until-docked`` exits;
``--repeat`` (or the dashboard's Reset and New seed) starts the next run; otherwise the swarm stays up until
Ctrl-C or ``--timeout``. Ctrl-C, SIGTERM or the end stop every child in an order that no process mistakes for
a failure (:mod:`swarm.transport.stopping`). ``--cpu-latency 0`` holds a PM QoS request that no CPU take
longer than 0 us to wake while the swarm runs (``swarm.cpu_latency``; needs root).

What differs per mission (its processes and their flags, which losses end the run, how the run is judged
and printed) is a small plan in :mod:`swarm.cli.launch_missions`. Exit status: 0 the mission's goal reached
(every chaser docked; every UAV landed on its pad or aborted safely), 1 not (or the run failed), 2 bad
input, 130 interrupted (Ctrl-C or SIGTERM) before the run in progress ended, a ``--repeat``'s later run
included; a stop after a run ended exits with that run's status.
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
from swarm.cli.launch_missions import LAUNCHES, clock_name, mothership_args, world_args  # noqa: F401
from swarm.cli.launch_plan import HOSTS_PER_CORE, PROCESS_EACH_PER_CORE
from swarm.errors import ConfigError, SwarmError
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
SUMMARY_WAIT_S = 10.0
"""How long [s] the launcher waits, after ``run_end``, for each live agent's ``summary`` event."""


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
        "--until-docked",
        action="store_true",
        help="exit when the run ends (every chaser in contact, every UAV landed or aborted)",
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


def _hosts(args: argparse.Namespace, ids) -> dict[str, list[str]]:
    """The agent processes to start, ``{child name: [vehicle ids]}``: ``agent/<id>`` with one vehicle each
    (the default), or ``agents/<i>`` hosting ``--vehicles-per-process`` vehicles in scenario order."""
    n, ids = getattr(args, "vehicles_per_process", 1), list(ids)
    if n < 1 or n > 64:
        raise ConfigError(f"--vehicles-per-process must be an integer in 1..64, got {n}")
    if n == 1:
        return {f"agent/{v}": [v] for v in ids}
    if getattr(args, "secure", False):
        raise ConfigError("--vehicles-per-process > 1 and --secure: an agent host would need every hosted "
                          "vehicle's identity; run secure swarms with one process per vehicle")  # fmt: skip
    return {f"agents/{i // n}": ids[i : i + n] for i in range(0, len(ids), n)}


class RunLog:
    """What the launcher hears of a run (thread-safe): the world's events, each agent's events and summary,
    the guidance of the vehicles asked for (a docking summary reads it), and whether the world's clock
    stands still (:class:`StallWatch`)."""

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


def run(args: argparse.Namespace) -> int:
    """The launch of the scenario's mission, with ``--cpu-latency``'s request held from before the first
    process starts until the last has stopped."""
    with cpu_latency.hold(args.cpu_latency):
        import zenoh

        zenoh.try_init_log_from_env()  # RUST_LOG=...: Zenoh's own log (its ACL: access_control=trace)

        from swarm.missions import mission_of

        return mission_of(args.scenario).run_launch(args)


def run_docking(args: argparse.Namespace) -> int:
    """``swarm launch`` of a docking scenario (:class:`swarm.missions.docking.DockingMission`)."""
    return launch(args, LAUNCHES["docking"])


def run_landing(args: argparse.Namespace) -> int:
    """``swarm launch`` of a landing scenario (:class:`swarm.missions.landing.LandingMission`)."""
    return launch(args, LAUNCHES["landing"])


def launch(args: argparse.Namespace, m) -> int:
    """The swarm of mission plan ``m`` (:mod:`swarm.cli.launch_missions`) as processes (module
    docstring); the exit status."""
    from swarm.cli.supervisor import Supervisor, forward_stacks_signal
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
    from swarm.transport.process import check_pace
    from swarm.transport.session import open_session, subscribe_decoded, watch_liveliness

    check_pace(args.clock, args.pace)
    sc = m.load(args)  # (refusals and the launch plan: before anything starts)
    ids = m.vehicles(sc)
    hosts = _hosts(args, ids)
    child_of = {v: name for name, vids in hosts.items() for v in vids}
    check_record(args)
    # mesh with --secure refused before anything starts
    n_proc = swarm_processes(len(ids), args.vehicles_per_process, mothership=m.mothership)
    args.links = links = topology(args, n_proc)
    keys = Keys(args.namespace)
    policy = args.policy or sc.policy
    listen = launch_listen(args)  # (--secure: mutual TLS + Zenoh ACL, each process its own certificate)
    args.secure_material = None
    zargs = router_args(args, listen)
    endpoint = client_endpoint(listen[0])
    stop = threading.Event()
    why = ["the launcher's end"]  # what the stop announcement says (swarm.transport.stopping)

    def on_signal(signum: int, _frame: object) -> None:
        why[0] = signal.Signals(signum).name
        _LOG.info("%s: stopping the swarm", why[0])
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    sup = Supervisor(max_restarts=args.max_restarts)
    restore_stacks = forward_stacks_signal(sup)  # kill -USR1 <launcher>: every process's stacks
    alive_changes: queue.Queue = queue.Queue()
    seed = args.seed
    result: dict | None = None
    wall0 = time.monotonic()
    ckpt_root = checkpoint_root()  # every run's checkpoints (removed at exit)
    try:
        zargs = secure_router(args, keys, ids, listen, zargs, m.name, m.platforms(sc))
        with open_session(zargs, lean=True) as session:  # its own swarm's paced ticks
            print(
                f"swarm listening on {' '.join(listen)} (clients: --mode client --connect {endpoint})",
                flush=True,
            )
            _LOG.info("the swarm's processes: %s", TOPOLOGY_TEXT[links])
            drops = DropCounter()
            box = [RunLog(args.stall_s, args.hung_ticks)]  # the current run's: the callbacks feed it
            for key, kind, on in ((keys.world_event(), Event, lambda k, e: box[0].on_world_event(k, e)),
                                  (keys.world_clock(), Clock, lambda k, c: box[0].on_clock(k, c)),
                                  (keys.agent_all("event"), Event, lambda k, e: box[0].on_event(k, e, keys)),
                                  *((keys.guidance(v), Guidance, lambda k, g: box[0].on_guidance(k, g, keys))
                                    for v in m.guided(sc))):  # fmt: skip
                subscribe_decoded(session, key, kind, on, drops)
            watch_liveliness(session, keys, lambda r, p, a: alive_changes.put((r, p, a, time.monotonic())))
            _token = session.liveliness().declare_token(keys.alive("launcher", "launcher"))

            def announce(vid: str | None, kind: str, data: dict) -> None:
                """An event for all: on the agent's key, or (``vid`` None: the world) on ``world/event``."""
                key = keys.event(vid) if vid is not None else keys.world_event()
                session.put(key, encode(Event(box[0].t_s, kind, data)))

            recorder = start_recorder(args, session, keys)  # --record: on this router session
            try:
                if not args.headless:
                    _start_dashboard(args, endpoint, sup, stop)
                for run_i in itertools.count():  # one iteration per run (--repeat, Reset, New seed)
                    log = box[0]
                    result = None  # (a run stopped before its end has none: exit 130, not a past run's)
                    run_dir = ckpt_root / f"run-{run_i}"  # this run's checkpoints: none of another run's
                    run_dir.mkdir()
                    for child in m.children(args, sc, hosts, child_args(args, endpoint, seed), run_dir):
                        sup.start(child)
                    if not _wait_alive(m, ids, sup, alive_changes, args.start_timeout, stop):
                        break
                    print(f"swarm up: world{', mothership' if m.mothership else ''} and {len(ids)} {m.name} "
                          f"agents in {len(hosts)} processes, seed {seed}, clock "
                          f"{clock_name(args.clock, args.pace)}", flush=True)  # fmt: skip
                    outcome = _supervise(args, m, child_of, sup, alive_changes, log, stop, wall0, announce)
                    if outcome != "ended":
                        break
                    _wait_summaries(ids, log, sup, child_of)
                    result = m.summary(args, sc, policy, seed, log, time.monotonic() - wall0)
                    if result is not None:
                        _report(args, result, sup, log)
                    end = log.run_end or {}
                    asked = end.get("reason") in NEW_RUN_COMMANDS  # the dashboard's Reset, New seed
                    if (args.repeat or asked) and not stop.is_set():
                        seed = next_run_seed(end, seed)
                        if not asked:
                            stop.wait(3.0)  # a moment to look at the docked pair, the landed UAVs
                        if stop.is_set():  # Ctrl-C meanwhile: no next run
                            break
                        stop_swarm(sup, session, keys, "next run", log.t_s, keep=("dashboard",))
                        box[0] = RunLog(args.stall_s, args.hung_ticks)
                        continue
                    if not args.until_docked and (m.hold_headless or not args.headless):
                        _hold(args, stop, wall0)
                    break
                _ = (_token, session)
            finally:
                # every process's last samples are in before the file is finished; announced while the
                # session is open (a failure's way out too)
                stop_swarm(sup, session, keys, why[0], box[0].t_s)
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
    return 0 if m.ok(result) else 1


def _start_dashboard(args, endpoint: str, sup, stop: threading.Event) -> None:
    """The dashboard child, once it serves (it prints its URL as ``dashboard on <url>``): kept across runs
    (the browser stays connected) and restarted like the others when it dies (the page reconnects to the
    same port and rebuilds its state from the next messages). ConfigError if it exits or does not serve
    within ``--start-timeout``."""
    from swarm.cli.supervisor import Child

    ready = threading.Event()

    def on_line(line: str) -> None:
        if line.startswith("dashboard listening on "):
            print(f"dashboard on {line.split()[-1]}", flush=True)
            ready.set()

    dash = [str(args.scenario), "--agents", str(args.agents), "--namespace", args.namespace,
            "--port", str(args.dashboard_port), "--mode", "client", "--connect", endpoint]  # fmt: skip
    for o in args.overrides:
        dash += ["--set", o]
    dash += config_args(args, "dashboard")
    sup.start(Child("dashboard", ["dashboard", *dash], restartable=True, on_line=on_line))
    deadline = time.monotonic() + args.start_timeout
    while not ready.wait(0.1):
        if stop.is_set():
            return
        if sup.exited() or time.monotonic() > deadline:
            raise ConfigError(f"the dashboard did not serve within {args.start_timeout:g} s (its log says)")


def _name(role: str, pid: str) -> str:
    """The liveliness name of a process (``agent/<id>`` per vehicle, even in an agent host)."""
    return f"agent/{pid}" if role == "agent" else role


def _wait_alive(m, ids, sup, changes: queue.Queue, timeout_s: float, stop: threading.Event) -> bool:
    """Until the world's, the mothership's (if any) and every vehicle's liveliness token is up; False at a
    stop, a child's exit or ``timeout_s``."""
    want = {"world", *(["mothership"] if m.mothership else []), *(f"agent/{v}" for v in ids)}
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
    args, m, child_of: dict[str, str], sup, changes: queue.Queue, log: RunLog, stop: threading.Event,
    wall0: float, announce=None,
) -> str:  # fmt: skip
    """Until the run ends (``"ended"``), a stop (``"stopped"``), the timeout or a fatal loss
    (``"failed"``: a process ``m.essential`` names gone for good)."""
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
        if log.ended.is_set():
            return "ended"  # (a process gone meanwhile, as a landing world after its run_end: no loss)
        if role is not None and not alive and role in ("agent", "world", "mothership"):
            name = child_of.get(pid, _name(role, pid)) if role == "agent" else _name(role, pid)
            if name in sup.children:
                what, fatal = _lose(m, sup, name, "liveliness token gone")
                if what:
                    _LOG.warning("%s (seen %.0f ms after the loss)", what, 1000 * (time.monotonic() - t_seen))
                if role in ("agent", "world") and announce is not None and what:
                    data = {"why": "liveliness token gone", "action": what}
                    announce(pid if role == "agent" else None, "lost", {**data, "role": role, "id": pid})
                if fatal:
                    return "failed"
        elif role is not None and alive and role in ("agent", "world"):
            _LOG.info("%s is alive", process_name(role, pid))
        for c in sup.exited():
            code = c.popen.returncode
            if log.ended.is_set():
                return "ended"
            if code == EXIT_BAD_CHECKPOINT and c.name != "dashboard":
                _LOG.error("%s exited with status %d: it could not resume from its checkpoint (its log says "
                           "why); giving up rather than resuming from a bad state", c.name, code)  # fmt: skip
                c.popen = None
                return "failed"
            what, fatal = _lose(m, sup, c.name, f"exited with status {code}")
            _LOG.warning("%s", what)
            if fatal:
                return "failed"
        for c in sup.due_restarts():
            how = {"world": "resuming from its checkpoint", "dashboard": "serving the page again"}
            _LOG.warning("%s restarted (pid %d), %s", c.name, c.popen.pid, how.get(c.name, m.agent_back))
    return "stopped"


def _lose(m, sup, name: str, why: str) -> tuple[str, bool]:
    """:meth:`~swarm.cli.supervisor.Supervisor.lost` of ``name``: what to log, and whether the run cannot
    go on (said): ``m.essential`` names it and it is not coming back. A child not coming back is forgotten
    (its exit is not a loss again)."""
    what = sup.lost(name, why)
    child = sup.children[name]
    if not what or child.next_start_s is not None:
        return what, False
    child.popen = None
    if not m.essential(name):
        return what, False
    _LOG.error("%s is gone for good: the run cannot go on", "the world" if name == "world" else name)
    return what, True


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


def _wait_summaries(
    ids, log: RunLog, sup, child_of: dict[str, str], timeout_s: float = SUMMARY_WAIT_S
) -> None:
    """After ``run_end``, until every live agent's ``summary`` event arrived (or ``timeout_s``)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with log.lock:
            missing = [v for v in ids if v not in log.summaries and sup.children[child_of[v]].running]
        if not missing:
            return
        time.sleep(0.01)


def _report(args, result: dict, sup, log: RunLog) -> None:
    """The summary's launcher fields (each process's restarts, the ticks the world resumed at), the
    restarts printed under the mission's summary, and ``--json``."""
    result["restarts"] = {c.name: c.restarts for c in sup.children.values()}
    result["world_resumed_at"] = [d.get("tick") for d in log.resumed]
    restarted = {n: r for n, r in result["restarts"].items() if r}
    if restarted:
        print("  restarts: " + ", ".join(f"{n} {r}" for n, r in restarted.items()), flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=1))


def _hold(args, stop: threading.Event, wall0: float) -> None:
    """After the run, keep the processes up (for the dashboard, or an outside client) until Ctrl-C or
    ``--timeout``."""
    who = "swarm" if args.headless else "dashboard"
    print(f"run over; the {who} stays up until Ctrl-C (or --timeout)", flush=True)
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
