"""``swarm bench swarm``: how many vehicles the swarm runs on this machine (issue 13).

For each case (number of vehicles, clock, topology), ``swarm launch docking --agents V/2`` runs for a fixed
simulated span, laid out as the launcher lays it out without flags (its plan, ``swarm.cli.launch_plan``:
the agent hosts, the staggered controller clocks and the agents' wake chosen from the vehicles and this
machine's cores; the case records what it ran, ``per_process``, ``staggered``, ``agent_wake`` and which
parts the plan chose, ``planned``) unless the bench's flags give a part, while a probe, which joins the
swarm as its processes do (a peer of a mesh, a client of the launcher's router in a star; ``--topology
auto``, the launcher's default, resolved as the launcher resolves it), takes the first pair's
``estimate(k)`` (it decodes only the tick number) with the time it was published and the time its
``imu(k)`` was, which the agent attaches to it: every process of the case stamps what it publishes (Zenoh's
timestamps, :data:`TIMESTAMPING`):

- **CPU per vehicle per tick**: the agents' own CPU time (each agent process reports it at the end of the
  run, ``cpu_s`` in the launch summary) over vehicles x ticks; the world's per tick beside it;
- **late ticks** (free-running clocks): the share of vehicle-ticks that the world stepped with an
  out-of-date command: the command of the vehicle's last control tick had not come by then (an agent
  commands on its control ticks and the world holds it in between; a command later than its tick's period,
  ``dt / factor`` of wall time, leaves the one before in force): ``late_commands`` of the world's
  ``run_end``, counted by the world for every vehicle whose agent has commanded (a swarm in which none did
  in the whole span: 100 %, shown as ``no command``); in lockstep no tick is late by construction;
- **late commands** (free-running): the share of the control ticks' commands that were not in by their
  tick (``late_control_commands``), the stricter figure: a command one tick late makes one late tick of
  ten, but one late command of one;
- **real-time factor**: simulated over wall time of the run (``run_end``);
- **staggered** (``--stagger``; without it, the launcher's plan): the vehicles' controller clocks spread
  over the control period (``swarm.stagger_control``: vehicle ``m`` controls on ticks ``m % period``),
  instead of every vehicle controlling on the same tick;
- **agent wake** (``--agent-wake imu,control``; without it, the launcher's plan): a free-running agent alone
  in its process wakes at each gyro sample (``imu``) or once per control period (``control``:
  ``agent.wake_at_control``, its inputs taken from Zenoh's queues then), each case in each, alternately
  (``agent_wake`` in the JSON; ``ctl`` after the clock in the table);
- **TDMA** (``--tdma``): the tags share one UWB channel (``uwb.tdma``, issue 13's Loco Positioning
  TWR-TDMA model): each ranges once per frame (~238/N ranges a second for N tags, against 50 each
  without), and the mothership sends a tag nothing on the slot ticks without its exchange;
- **wake** (``--cpu-latency off,0``): the CPU wake-up latency request (:mod:`swarm.cpu_latency`, what
  ``swarm launch --cpu-latency`` holds) held by the bench while the case runs, each case in each value,
  alternately; ``cpu_latency_held`` in the JSON says whether the machine granted it (``!`` in the table:
  it did not, and the case ran with the kernel's idle states);
- **sensor-to-estimate latency** p50/p99: ``estimate(k)``'s publication by the agent minus ``imu(k)``'s
  by the world, for the first pair's two vehicles: the hop from the world to the agent (in a star, the
  router's two), the agent's receive, filter and publish time. Both stamps are their publishers' (one
  machine, one clock), so the probe's own delays are not in it, and the probe takes no imu
  (:class:`LatencyProbe`). Beside it,
  **delivered** (``latency_delivered_*``): to the estimate's arrival at the probe, what a consumer of the
  estimates on this machine sees. Since 4df9a3d the target sends only the estimates its chaser reads (a
  fifth), so its ticks are a sixth of the samples, not a half. Split beside it (``latency_camera_*`` and
  ``latency_other_*``): the chaser's camera ticks (``k`` a multiple of the camera's period: the frame is
  fused before the estimate goes out) and all the other samples, the target's included.

``--repeat N`` runs every case N times, round by round (so that a drift of the shared machine's speed falls
on every case alike), and reports each figure's median over the runs with the spread of the late ticks,
late commands, real-time factor and latency p99 (``<figure>_range`` in the JSON, the runs under ``runs``):
one run of a free-running swarm says little here.

The probe is kept to one pair on purpose. Until 2026-11-26 it took every vehicle's ``imu``, ``estimate``
and ``command``, and judged late ticks by the commands' arrival: at 32 vehicles that was 9600 Python
callbacks a second, 25 % of a core for the probe and as much again for the router forwarding to it, out of
the two cores the swarm it measured had.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import msgpack
import numpy as np

from swarm import cpu_latency
from swarm.cli.launch_plan import available_cores
from swarm.errors import ConfigError
from swarm.transport.session import attached_imu_ns, free_loopback_endpoint, open_session, published_ns

QUICK = {"vehicles": (2, 8), "clocks": ("lockstep", "realtime"), "span_s": 5.0, "per_process": (None,)}
FULL = {"vehicles": (2, 8, 32), "clocks": ("lockstep", "realtime"), "span_s": 20.0, "per_process": (None,)}
"""The presets; a ``per_process`` of None (and no ``stagger``, no ``agent_wakes``): the launcher's plan."""
DT_S = 0.01  # the docking scenario's tick
LAUNCH = [sys.executable, "-m", "swarm.cli.main", "launch"]
"""The launcher each case runs (its arguments follow)."""
LAUNCH_START_S = 300.0
"""The wall time a launch may take to start (128 vehicles in processes of one: ~1-2 min on 2 cores)..."""
LAUNCH_SLOWEST = 10.0
"""... plus this many times its simulated span (a free-running swarm runs at ~1x, lockstep faster): past
both, ``--timeout`` ends a hung case, with the stacks of every process (``swarm/stacks.py``)."""
STACKS_LINES = 400
"""Of a failed launch's log, the lines kept from its stack dump on (a stall or ``--timeout`` wrote it)."""


def parse_vehicles(text: str) -> tuple[int, ...]:
    """``--vehicles 2,8,32``: even counts (a chaser and its target per pair), 2..128."""
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--vehicles must be even integers separated by commas, got {text!r}") from None
    bad = [v for v in values if v < 2 or v > 128 or v % 2]
    if not values or bad:
        raise ConfigError(f"--vehicles must be even integers in 2..128 (pairs), got {text!r}")
    return values


def parse_per_process(text: str) -> tuple[int | None, ...]:
    """``--vehicles-per-process 1,8,auto``: agent hosts of that many vehicles (1: one process per vehicle;
    ``auto``, None: the launcher's plan)."""
    try:
        values = tuple(None if v == "auto" else int(v) for v in text.split(","))
    except ValueError:
        values = ()
    if not values or any(v is not None and (v < 1 or v > 64) for v in values):
        raise ConfigError(
            f"--vehicles-per-process must be integers in 1..64 or auto, comma-separated, got {text!r}"
        )
    return values


def parse_topologies(text: str) -> tuple[str, ...]:
    """``--topology mesh,star`` (``swarm launch --topology``: auto, mesh, star)."""
    from swarm.cli.children import TOPOLOGIES

    values = tuple(text.split(","))
    if not values or any(t not in TOPOLOGIES for t in values) or len(set(values)) < len(values):
        raise ConfigError(
            f"--topology must be auto, mesh or star, or several (comma-separated), got {text!r}"
        )
    return values


def parse_clocks(text: str) -> tuple[str, ...]:
    """``--clock realtime,lockstep``."""
    values = tuple(text.split(","))
    bad = [c for c in values if c not in ("realtime", "lockstep")]
    if bad:
        raise ConfigError(f"--clock must be realtime, lockstep or both (comma-separated), got {text!r}")
    return values


TIMESTAMPING = "{ timestamping: { enabled: { router: true, peer: true, client: true } } }"
"""The Zenoh configuration (``--zenoh-config``) of every process of a case: each session stamps what it
publishes with its hybrid logical clock (``Sample.timestamp``, Zenoh's HLC: the machine's real-time clock at
the ``put``, to a few nanoseconds), which the probe reads. The stamp is Zenoh's metadata, not the payload:
docs/protocol.md's messages are unchanged."""


def timestamping_args(directory: str | os.PathLike) -> list[str]:
    """``swarm launch`` flags that have every process of a launch stamp what it publishes: the
    :data:`TIMESTAMPING` configuration, written into ``directory``."""
    path = Path(directory) / "zenoh.json5"
    path.write_text(TIMESTAMPING)
    return ["--zenoh-config", str(path)]


class LatencyProbe:
    """The probed vehicles' estimates, each with the publication stamp of the imu it was computed from.

    For each estimate it keeps two latencies: from its imu's publication by the world to its own by the
    agent (``latency``: both stamped by their publishers: :func:`~swarm.transport.session.published_ns` of
    the estimate, and the imu's, which the agent attaches to it, :func:`~swarm.transport.session.
    attached_imu_ns`), and to its arrival here (``delivered``: what a consumer on this machine sees, the
    estimate's hop and this probe's own delay taking it included). The probe takes no imu: until
    2026-11-29 it subscribed to every probed imu and matched the two by tick, and so was woken with the
    agents at each tick's instant, on the same two cores, for a message no deployment has a reader of
    (BENCHMARKS.md, "The sensor's stamp on the estimate"). An estimate without its own stamp is counted
    (``unstamped``: a process the bench's Zenoh configuration did not reach), one without its imu's
    (``without_imu``: the initial ``estimate(0)``, made before any imu) too; neither is measured."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.latency: list[tuple[str, int, float]] = []  # (vehicle, tick, estimate's publication - imu's [s])
        self.delivered: list[tuple[str, int, float]] = []  # (vehicle, tick, estimate's arrival - imu's [s])
        self.unstamped = 0
        self.without_imu = 0

    def on_estimate(self, sample) -> None:
        arrival_ns = time.time_ns()
        try:
            vid = str(sample.key_expr).split("/")[-2]
            k = int(msgpack.unpackb(bytes(sample.payload))["tick"])
        except Exception:  # a payload of someone else's making: not ours to measure
            return
        pub_ns, imu_ns = published_ns(sample), attached_imu_ns(sample)
        with self.lock:
            if pub_ns is None or imu_ns is None:
                if pub_ns is None:
                    self.unstamped += 1
                else:
                    self.without_imu += 1
                return
            self.latency.append((vid, k, (pub_ns - imu_ns) * 1e-9))
            self.delivered.append((vid, k, (arrival_ns - imu_ns) * 1e-9))


def _case(vehicles: int, clock: str, span_s: float, per_process: int | None = None,
          stagger: bool | None = None, tdma: bool = False, topology: str = "auto",
          agent_wake: str | None = None) -> dict:  # fmt: skip
    """One launch of the case; ``per_process``, ``stagger`` and ``agent_wake`` None: the launcher's plan's."""
    from swarm.cli.children import resolved, swarm_processes
    from swarm.cli.launch_plan import STAGGER_KEY, WAKE_KEY, resolve_plan

    pairs = vehicles // 2
    sets = [f"{STAGGER_KEY}=true"] if stagger else []
    if agent_wake is not None:
        sets.append(f"{WAKE_KEY}={str(agent_wake == 'control').lower()}")
    # the launcher's plan on this machine, as it will resolve it (the probe joins the topology it makes)
    plan, _ = resolve_plan(vehicles, clock == "lockstep", per_process, sets)
    links = resolved(topology, swarm_processes(vehicles, plan.vehicles_per_process))
    ns = f"benchswarm{os.getpid()}v{vehicles}p{per_process or 'auto'}{clock}{topology}"
    endpoint = free_loopback_endpoint()
    # the launcher's stderr (its children's too) into a file: its last lines say why a launch failed
    with tempfile.TemporaryDirectory() as tmp, open(Path(tmp) / "launch.log", "w+") as log:
        out = Path(tmp) / "run.json"
        cmd = [*LAUNCH, "docking", "--headless", "--until-docked",
               "--agents", str(pairs), "--clock", clock, "--set", f"sim.max_duration_s={span_s}",
               "--json", str(out), "--namespace", ns, "--listen", endpoint, "--topology", topology,
               *timestamping_args(tmp),
               "--timeout", f"{LAUNCH_START_S + LAUNCH_SLOWEST * span_s:g}"]  # fmt: skip
        if per_process is not None:
            cmd += ["--vehicles-per-process", str(per_process)]
        if stagger:
            cmd += ["--set", f"{STAGGER_KEY}=true"]
        if tdma:
            cmd += ["--set", "uwb.tdma=true"]
        if agent_wake is not None:
            cmd += ["--set", sets[-1]]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=log, text=True)
        probe = LatencyProbe()
        up, listening = threading.Event(), threading.Event()

        def drain() -> None:  # the launcher's stdout: wait for "swarm up", then keep the pipe empty
            for line in proc.stdout:
                if line.startswith("swarm listening on"):
                    listening.set()
                    up.set()
            up.set()

        threading.Thread(target=drain, daemon=True).start()
        try:
            up.wait(300)
            if listening.is_set():  # else it ended (or hangs) before its router listened: nothing to probe
                _probe_run(proc, endpoint, ns, pairs, probe, links)
        finally:
            if proc.poll() is None:
                proc.send_signal(2)
                proc.wait(60)
        rc = proc.returncode
        if not out.exists():
            log.seek(0)
            raise RuntimeError(f"swarm launch --agents {pairs} --clock {clock} --topology {links} "
                               f"failed ({rc}):\n{_what_it_said(log.read())}")  # fmt: skip
        res = json.loads(out.read_text())
    ticks = max(1, round(res["sim_time_s"] / DT_S))
    cpu = res.get("cpu_s") or {}
    agents = [v for k, v in cpu.items() if k != "world" and v is not None]
    from swarm.scenario import load_scenario

    sc = load_scenario("docking")
    camera_every, cameras = sc.every(sc.camera.rate_hz), {probed_pair(pairs)[0]}
    lat = latency_split(probe.latency, camera_every, cameras)
    delivered = latency_split(probe.delivered, camera_every, cameras)
    late, stepped = late_share(clock, res.get("late_commands"))
    late_cmd, _ = late_share(clock, res.get("late_control_commands"))
    ran = res.get("launch_plan") or plan.as_dict()  # what the launcher says it ran (the same plan)
    return {
        "vehicles": vehicles,
        "per_process": ran["vehicles_per_process"],
        "clock": clock,
        "topology": links,
        "staggered": ran["stagger_control"],
        "tdma": tdma,
        "agent_wake": "control" if ran["wake_at_control"] else "imu",
        "planned": ran["chosen"],  # the parts the launcher's plan chose (the others the bench's flags gave)
        "cpu_us_per_vehicle_tick": 1e6 * float(np.sum(agents)) / (len(agents) * ticks) if agents else None,
        "world_cpu_us_per_tick": 1e6 * cpu["world"] / ticks if cpu.get("world") is not None else None,
        "late_tick_share": late,
        "late_command_share": late_cmd,  # of the control ticks' commands (None: lockstep)
        "commanded_vehicle_ticks": stepped,  # the late share's denominator (None: lockstep)
        "realtime_factor": res.get("realtime_factor"),
        **lat,
        "latency_delivered_p50_us": delivered["latency_p50_us"],
        "latency_delivered_p99_us": delivered["latency_p99_us"],
        "unstamped": probe.unstamped,
        "without_imu_stamp": probe.without_imu,
        "ticks": ticks,
    }


def probed_pair(pairs: int) -> tuple[str, str]:
    """The chaser and the target whose latency the probe measures: the first pair."""
    return ("chaser", "target") if pairs == 1 else ("chaser0", "target0")


def latency_split(samples: list[tuple[str, int, float]], camera_every: int, cameras: set[str]) -> dict:
    """The probe's ``(vehicle, tick, latency [s])`` samples as p50/p99 [us] of all (``latency_p50_us``,
    ..., ``samples``), of the camera ticks (``latency_camera_*``: a vehicle of ``cameras`` at a tick that is
    a multiple of ``camera_every``, whose frame is fused before the estimate goes out) and of the others
    (``latency_other_*``, the target's ticks among them); ``None`` where none."""
    ticks = np.array([k for _, k, _ in samples], dtype=np.int64)
    us = np.array([s for _, _, s in samples], dtype=float) * 1e6
    has_camera = np.array([v in cameras for v, _, _ in samples], dtype=bool)
    camera = has_camera & (ticks % camera_every == 0)
    out: dict = {}
    for name, sel in (("latency", slice(None)), ("latency_camera", camera), ("latency_other", ~camera)):
        x = us[sel]
        out[f"{name}_p50_us"] = float(np.percentile(x, 50)) if x.size else None
        out[f"{name}_p99_us"] = float(np.percentile(x, 99)) if x.size else None
    out["samples"], out["camera_samples"] = int(us.size), int(camera.sum())
    return out


def _what_it_said(text: str) -> str:
    """A failed launch's log, shortened: its last 20 lines, after the stacks its launcher had every process
    write when the world's clock stood still or ``--timeout`` came (at most :data:`STACKS_LINES` from the
    first such dump), which say where each process was."""
    lines = text.splitlines()
    first = next((i for i, line in enumerate(lines) if ": the stacks of the launcher (pid " in line), None)
    if first is None or first >= len(lines) - 20:
        return "\n".join(lines[-20:])
    stacks, rest = lines[first : first + STACKS_LINES], lines[first + STACKS_LINES :]
    return "\n".join([*stacks, "...", *rest[-20:]] if len(rest) > 20 else [*stacks, *rest])


def _probe_run(
    proc: subprocess.Popen, endpoint: str, ns: str, pairs: int, probe: LatencyProbe, topology: str
) -> None:
    """Take the first pair's ``estimate`` (:class:`LatencyProbe`) until the launcher
    ``proc`` exits, on a session that joins the swarm as its processes do (a client of the launcher's
    router at ``endpoint`` in a star, a peer of the mesh in a mesh: as a consumer of the estimates would)."""
    from swarm.cli.children import member_args

    session = open_session(member_args(endpoint, topology))
    try:
        for vid in probed_pair(pairs):
            session.declare_subscriber(f"{ns}/agent/{vid}/estimate", probe.on_estimate)
        proc.wait(timeout=1800)
    finally:
        session.close()


def late_share(clock: str, late_commands: list[int] | None) -> tuple[float | None, int | None]:
    """The share of late vehicle-ticks and its denominator from the world's ``late_commands`` ``[late,
    commanded]`` (``None`` for lockstep, or a world that did not report it). A free-running swarm in which
    no vehicle ever commanded (an overloaded one) had every tick without a command: 1.0, not undefined."""
    if clock == "lockstep" or late_commands is None:
        return None, None
    late_n, stepped = late_commands
    return (late_n / stepped if stepped else 1.0), stepped


def parse_agent_wakes(text: str) -> tuple[str, ...]:
    """``--agent-wake imu,control``: how a free-running agent alone in its process wakes (module
    docstring), each case run in each."""
    values = tuple(v.strip() for v in text.split(","))
    if not values or any(v not in ("imu", "control") for v in values) or len(set(values)) < len(values):
        raise ConfigError(f"--agent-wake must be imu, control or both (comma-separated), got {text!r}")
    return values


def parse_repeat(value: int) -> int:
    """``--repeat N``: runs of each case, 1..20."""
    if not 1 <= value <= 20:
        raise ConfigError(f"--repeat must be an integer in 1..20, got {value}")
    return value


RANGED = (
    "late_tick_share",
    "late_command_share",
    "realtime_factor",
    "latency_p99_us",
    "latency_delivered_p99_us",
)
"""The figures whose spread over a case's runs is reported beside their median (``<name>_range``)."""


def summarise(runs: list[dict]) -> dict:
    """One case from its runs (``--repeat``): every number the median over the runs that have it (``None``
    where none has), and for the :data:`RANGED` figures ``[min, max]`` as ``<name>_range``; the runs
    themselves under ``runs``. A single run is returned as it is. On a shared machine one run of a
    free-running swarm says little: 128 vehicles gave 0.5-3.3 % late ticks in six runs of the same code."""
    if len(runs) == 1:
        return runs[0]
    out = dict(runs[0])
    for key, first in runs[0].items():
        if isinstance(first, bool) or not isinstance(first, int | float | type(None)):
            continue
        values = [r[key] for r in runs if r.get(key) is not None]
        if not values:
            continue
        med = float(np.median(values))
        out[key] = round(med) if all(isinstance(v, int) for v in values) else med
        if key in RANGED:
            out[f"{key}_range"] = [min(values), max(values)]
    out["repeat"] = len(runs)
    out["runs"] = runs
    return out


def parse_cpu_latencies(text: str) -> tuple[int | None, ...]:
    """``--cpu-latency off,0``: ``swarm launch --cpu-latency`` values (``off``: None), each case run in
    each."""
    try:
        values = tuple(cpu_latency.parse(v) for v in text.split(","))
    except argparse.ArgumentTypeError:
        values = ()
    if not values or len(set(values)) < len(values):
        raise ConfigError(
            f"--cpu-latency must be off or microseconds in 0..{cpu_latency.MAX_US}, "
            f"or several (comma-separated), got {text!r}"
        )
    return values


def run(preset: dict) -> dict:
    stagger, tdma = preset.get("stagger") or None, bool(preset.get("tdma", False))  # (None: the plan's)
    specs = [(v, c, n, t, q, w) for c in preset["clocks"] for n in preset["per_process"]
             for v in preset["vehicles"] if n is None or n <= v for t in preset.get("topologies", ("auto",))
             for q in preset.get("cpu_latencies", (None,)) for w in preset.get("agent_wakes", (None,))
             if w in (None, "imu") or (c != "lockstep" and n in (None, 1))]  # fmt: skip
    runs: dict[tuple, list[dict]] = {spec: [] for spec in specs}
    for _ in range(int(preset.get("repeat", 1))):  # round by round: a drift of the machine hits every case
        for v, c, n, t, q, w in specs:
            # the request is the machine's (the launch's and the probe's alike): held here, so that the
            # record says whether it was
            with cpu_latency.hold(q) as held:
                case = _case(v, c, preset["span_s"], n, stagger, tdma, t, w)
            runs[v, c, n, t, q, w].append({**case, **held.as_dict()})
    return {
        "cases": [summarise(runs[spec]) for spec in specs],
        "span_s": preset["span_s"],
        "cores": available_cores(),  # (the launcher's plan's: those this process may run on)
        "load_1min": os.getloadavg()[0],
        "cpu_idle": cpu_latency.idle_config(),  # what a process woken every tick pays: the VM's or laptop's
    }


def _fmt(x, spec: str) -> str:
    return "-" if x is None else format(x, spec)


def format_report(r: dict) -> str:
    lines = [
        f"swarm launch docking, {r['span_s']:.0f} s simulated per case "
        f"({r['cores']} cores, 1-min load {r['load_1min']:.2f} at the end)"
        + ("; controller clocks staggered" if any(c.get("staggered") for c in r["cases"]) else "")
        + ("; one TDMA UWB channel" if any(c.get("tdma") for c in r["cases"]) else ""),
        "vehicles  per proc  clock      links  wake  CPU us/vehicle/tick  world us/tick  "
        "late ticks / commands  real-time  latency p50/p99 us (camera ticks; others)  delivered p50/p99 us",
    ]
    for c in r["cases"]:
        late = "-" if c["late_tick_share"] is None else f"{100 * c['late_tick_share']:.1f} %"
        if c.get("late_command_share") is not None:
            late += f" / {100 * c['late_command_share']:.1f} %"
        if c.get("commanded_vehicle_ticks") == 0:
            late = "no command"
        clock = c["clock"] + (" ctl" if c.get("agent_wake") == "control" else "")
        lines.append(
            f"{c['vehicles']:>8}  {c['per_process']:>8}  {clock:<9}  {c.get('topology', 'star'):<5}  "
            f"{_wake(c):>4}  "
            f"{_fmt(c['cpu_us_per_vehicle_tick'], '19.0f')}  "
            f"{_fmt(c['world_cpu_us_per_tick'], '13.0f')}  {late:>21}  "
            f"{_fmt(c['realtime_factor'], '8.2f')}x  "
            f"{_fmt(c['latency_p50_us'], '.0f')}/{_fmt(c['latency_p99_us'], '.0f')}"
            f" ({_fmt(c.get('latency_camera_p50_us'), '.0f')}/{_fmt(c.get('latency_camera_p99_us'), '.0f')};"
            f" {_fmt(c.get('latency_other_p50_us'), '.0f')}/{_fmt(c.get('latency_other_p99_us'), '.0f')})"
            f"  {_fmt(c.get('latency_delivered_p50_us'), '.0f')}/"
            f"{_fmt(c.get('latency_delivered_p99_us'), '.0f')}" + _spread(c)
        )
    if any("runs" in c for c in r["cases"]):
        lines.append("medians of the runs of each case; [min-max] over them")
    if r.get("cpu_idle"):
        lines.append(cpu_latency.describe_idle(r["cpu_idle"]))
    return "\n".join(lines)


def _wake(c: dict) -> str:
    """The case's ``--cpu-latency``: ``off``, the microseconds held, or ``!`` after them when the request
    could not be held (no root: the case ran with the kernel's idle states)."""
    us = c.get("cpu_latency_us")
    if us is None:
        return "off"
    return f"{us}" + ("" if c.get("cpu_latency_held") else "!")


def _spread(c: dict) -> str:
    """``--repeat``: the runs' count and the spread of their late ticks (free-running) or real-time factor."""
    if "runs" not in c:
        return ""
    late = c.get("late_tick_share_range")
    if late is not None:
        return f"  {c['repeat']} runs, late ticks [{100 * late[0]:.1f}-{100 * late[1]:.1f} %]"
    rtf = c.get("realtime_factor_range")
    return f"  {c['repeat']} runs" + ("" if rtf is None else f", real-time [{rtf[0]:.2f}-{rtf[1]:.2f}x]")
