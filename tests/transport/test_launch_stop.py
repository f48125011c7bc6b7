"""A clean stop of a launched swarm (issue 46): Ctrl-C ends a docking or a landing swarm, mid-run or after
its run ended, with no line at WARNING or ERROR and no traceback in any process's output (every child logs
to the launcher's stderr), the documented exit status (docs/usage.md, "Exit status": 130 for a run stopped
before its end, else the run's own) and no process left behind.

A terminal's Ctrl-C reaches the launcher alone (each child runs in a session of its own); a mid-run stop
here also sends SIGINT to every child's process group at the same instant, as a wrapper that forwards the
signal to every process would: each child must then leave the stop to the launcher, which stops the world
first, then the rest (``swarm/transport/stopping.py``). Launches are the suite's costly tests: two per
mission, each serving several claims (the dashboard and the ``--record`` recorder ride along in the docking
one). Real losses (SIGKILL, a hang) keep their warnings and restarts: ``test_launch.py``,
``test_landing_launch.py``."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
import uuid

from swarm.transport.keys import Keys
from swarm.transport.messages import Clock, Event, decode
from swarm.transport.recording import read_recording
from swarm.transport.session import ZenohArgs, open_session
from swarm.transport.stopping import STOPPING
from tests.transport.procs import Procs, free_port, loopback, wait_until

UP_S = 300.0  # the swarm up: its processes' kernels loaded (or compiled, on a machine without the cache)
STOP_S = 60.0  # a stop, from the SIGINT to the launcher's exit (measured 2.5-4 s here; a loaded machine)
BAD = re.compile(r" (WARNING|ERROR) |Traceback|Exception in thread")
"""What a clean stop never prints: a log line at WARNING or ERROR (every process logs ``<time> <LEVEL>
<name>: ...``), a traceback, an exception in a thread."""


def _ns() -> str:
    return f"stop-{uuid.uuid4().hex[:8]}"


def _processes(ns: str) -> list[tuple[int, str]]:
    """``(pid, command line)`` of every live process of namespace ``ns`` (its arguments name it)."""
    out = subprocess.run(["ps", "-ww", "-eo", "pid,stat,args"], capture_output=True, text=True).stdout
    rows = [line.split(None, 2) for line in out.splitlines()[1:]]
    return [(int(pid), args) for pid, stat, args in rows
            if f"--namespace {ns}" in args and not stat.startswith("Z") and "ps -ww" not in args]  # fmt: skip


def _launch(procs: Procs, scenario: str, ns: str, *extra: str):
    endpoint = loopback(free_port())
    args = [sys.executable, "-m", "swarm.cli.main", "launch", scenario, "--namespace", ns,
            "--listen", endpoint, *extra]  # fmt: skip
    proc = procs.start(args)
    proc.wait_for_line(r"^swarm listening on ", 60.0)
    return proc, endpoint


def _sigint_everyone(proc, ns: str) -> list[int]:
    """SIGINT to the launcher's process group and to every child's, at once (each child leads a group of
    its own); the children's pids."""
    children = [pid for pid, _ in _processes(ns) if pid != proc.pid]
    for group in [proc.pgid, *children]:
        try:
            os.killpg(group, signal.SIGINT)
        except ProcessLookupError:
            pass
    return children


def _assert_clean_stop(proc, ns: str, rc: int, want_rc: int) -> str:
    """The launcher exited ``want_rc``, nothing it or a child printed is bad (:data:`BAD`), and no process
    of the swarm is left; its output."""
    text = proc.output()
    bad = [line for line in text.splitlines() if BAD.search(line)]
    assert not bad, "\n".join(bad) + "\n" + text
    assert rc == want_rc, text
    wait_until(lambda: not _processes(ns), 10.0, f"every process of {ns} to be gone: {_processes(ns)}")
    return text


def _kill_leftovers(ns: str) -> None:
    """Whatever a failed test left of the swarm (the launcher's group dies with Procs; a child whose
    launcher died is SIGKILLed by its parent-death signal, this is the belt to those braces)."""
    for pid, _ in _processes(ns):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def test_a_docking_swarm_stopped_mid_run_by_sigint_to_every_process_stops_quietly_in_order(tmp_path):
    """One launch, with the dashboard and ``--record``, ``--repeat``:

    - the first run docks; the launcher stops its world, mothership and agents for the next run (the
      dashboard stays) without a warning: the agents say the world and the mothership *stopped*;
    - 1 s into the second run (a lockstep docking takes ~3.5 s here) SIGINT reaches every process at once:
      the children leave the stop to the launcher, which announces it, stops the world (its run ends
      ``stopped``), then the mothership, the agents and the dashboard; exit 130 (a run stopped before its
      end), no warning, no error, no traceback, nothing left;
    - the recording is complete (readable to its end) and holds the launcher's ``stopping`` events."""
    ns, rec = _ns(), tmp_path / "run.mcap"
    try:
        with Procs() as procs:
            proc, _ = _launch(procs, "docking", ns, "--seed", "1", "--repeat", "--record", str(rec),
                              "--dashboard-port", str(free_port()))  # fmt: skip
            proc.wait_for_line(r"^dashboard on http://", UP_S)
            proc.wait_for_line(r"^  wall [\d.]+ s for [\d.]+ s simulated", UP_S)  # the first run's summary
            wait_until(lambda: len(re.findall(r"^swarm up:", proc.output(), re.M)) == 2, UP_S,
                       "the second run", poll_s=0.05)  # fmt: skip
            time.sleep(1.0)
            children = _sigint_everyone(proc, ns)
            rc = proc.wait(STOP_S)
        text = _assert_clean_stop(proc, ns, rc, 130)
    finally:
        _kill_leftovers(ns)
    assert len(children) == 5, children  # world, mothership, two agents, dashboard
    # the children got the SIGINT and left the stop to the launcher
    assert len(re.findall(r"SIGINT: the launcher stops the swarm, this process in its turn", text)) == 5, text
    second = text[text.rindex("SIGINT: stopping the swarm") :]
    assert "swarm world: run ended (stopped)" in second, second  # mid-run
    # in order: the world first, then the others (each process logs its SIGTERM)
    terms = [m.group(1) for m in re.finditer(r"INFO (swarm world|swarm mothership|swarm agent|dashboard): "
                                             r"SIGTERM: stopping", second)]  # fmt: skip
    assert terms[0] == "swarm world" and sorted(terms[1:]) == sorted(
        ["swarm mothership", "swarm agent", "swarm agent", "dashboard"]
    ), terms
    for who in ("chaser", "target"):  # the peers' going, said as a stop (and the world named once)
        assert f"swarm agent: {who}: world stopped (the swarm is stopping)" in text, who
    assert "world world" not in text.replace("world world ready", "")  # (the ready line is the protocol's)
    msgs, _ = read_recording(rec)
    keys = Keys(ns)
    stops = [decode(m.payload, Event) for m in msgs if m.key == keys.world_event()]
    whys = [e.data["why"] for e in stops if e.kind == STOPPING]
    assert sorted(whys) == ["SIGINT", "next run"], whys  # (in swarm time order: each run's time)
    assert re.search(rf"^recorded \d+ messages on \d+ keys to {re.escape(str(rec))}$", text, re.M), text


def test_a_docking_swarm_held_after_its_run_stops_quietly_at_the_terminals_ctrl_c():
    """Headless, no ``--until-docked``: the run docks and the swarm stays up; Ctrl-C as a terminal sends it
    (SIGINT to the launcher's process group, which holds the launcher alone) stops every process in order,
    quietly, and the exit status is the run's: 0, docked. The same launch (launches are the suite's costly
    tests; this one was ``test_launch.py``'s SIGINT test) also shows, while the swarm is held up:

    - the default topology is a mesh: each of the swarm's processes (world, mothership, agents) has a
      direct link to every other, besides its link to the launcher's router;
    - ``--cpu-latency 0`` holds the kernel's CPU latency bound at 0 while the swarm runs, and no longer."""
    from tests.transport.test_launch import DEVICE, _direct_links, _machine_cpu_latency, _tcp_sockets

    ns = _ns()
    before = _machine_cpu_latency()
    # root: granted; else the launcher warns (tests/test_cpu_latency.py), which a clean stop may not print
    latency = ["--cpu-latency", "0"] if os.access(DEVICE, os.W_OK) else []
    try:
        with Procs() as procs:
            proc, endpoint = _launch(procs, "docking", ns, "--seed", "1", "--headless", *latency)
            proc.wait_for_line(r"^run over; the swarm stays up until Ctrl-C", UP_S)
            if latency:
                assert _machine_cpu_latency() == 0
            names = {"swarm.world": "world", "-m mothership": "mothership", "--id chaser": "chaser",
                     "--id target": "target"}  # fmt: skip
            pids = {name: pid for pid, line in _processes(ns) for k, name in names.items() if k in line}
            assert sorted(pids) == sorted(names.values()), _processes(ns)
            router_port = int(endpoint.rpartition(":")[2])
            for name, pid in pids.items():  # each still has its link to the router, its rendezvous
                assert any(remote == router_port for _, remote in _tcp_sockets(pid)["links"]), name
            want = {frozenset((a, b)) for a in pids for b in pids if a < b}
            # the links come up from the router's gossip within milliseconds of each process's start
            wait_until(lambda: _direct_links(pids) >= want, 10.0, "a direct link between every two processes")
            os.killpg(proc.pgid, signal.SIGINT)
            rc = proc.wait(STOP_S)
        text = _assert_clean_stop(proc, ns, rc, 0)
    finally:
        _kill_leftovers(ns)
    assert _machine_cpu_latency() == before  # the request went with the launcher
    assert "the launcher stops the swarm, this process in its turn" not in text  # no child got the SIGINT
    assert "swarm world: SIGTERM: stopping" in text
    assert "swarm agent: chaser: world stopped (the swarm is stopping)" in text, text


def _wait_for_running_clock(endpoint: str, ns: str, timeout_s: float) -> None:
    """Until the world's clock says ``running`` past tick 0 (the landing run has started)."""
    running = threading.Event()

    def on_clock(sample) -> None:
        msg = decode(bytes(sample.payload), Clock)
        if msg.state == "running" and msg.tick > 0:
            running.set()

    with open_session(ZenohArgs(mode="client", connect=(endpoint,))) as session:
        _sub = session.declare_subscriber(Keys(ns).world_clock(), on_clock)
        assert running.wait(timeout_s), "the landing run did not start"


def test_a_landing_swarm_stopped_mid_run_by_sigint_to_every_process_stops_quietly():
    """Headless, lockstep paced at scaled:4 (a landing then takes ~4.5 s of wall time): once its clock
    runs, SIGINT to every process at once; the landing world ends the run ``stopped`` (no error), every
    process stops, exit 130, nothing bad printed, nothing left."""
    ns = _ns()
    try:
        with Procs() as procs:
            proc, endpoint = _launch(procs, "landing-swarm", ns, "--seed", "0", "--headless",
                                     "--pace", "scaled:4")  # fmt: skip
            proc.wait_for_line(r"^swarm up:", UP_S)
            _wait_for_running_clock(endpoint, ns, UP_S)
            children = _sigint_everyone(proc, ns)
            rc = proc.wait(STOP_S)
        text = _assert_clean_stop(proc, ns, rc, 130)
    finally:
        _kill_leftovers(ns)
    assert len(children) == 5, children  # the world and four agents
    assert len(re.findall(r"SIGINT: the launcher stops the swarm, this process in its turn", text)) == 5, text
    assert re.search(r"swarm\.world\.landing: run ended \(stopped\) at tick \d+", text), text
    assert "UAVs landed on their pads" not in text  # stopped before its end: no result


def test_a_landing_swarm_stopped_between_two_repeat_runs_starts_no_next_run_and_exits_with_the_first():
    """Headless ``--repeat``: the first run lands (its result printed); Ctrl-C (the launcher's group) in
    the pause before the next run starts none, stops every process quietly and exits 0 (the run's
    status)."""
    ns = _ns()
    try:
        with Procs() as procs:
            proc, _ = _launch(procs, "landing-swarm", ns, "--seed", "0", "--headless", "--repeat")
            proc.wait_for_line(r"^4 of 4 UAVs landed on their pads", UP_S)
            os.killpg(proc.pgid, signal.SIGINT)  # within the launcher's 3 s pause
            rc = proc.wait(STOP_S)
        text = _assert_clean_stop(proc, ns, rc, 0)
    finally:
        _kill_leftovers(ns)
    assert len(re.findall(r"^swarm up:", text, re.M)) == 1, text  # no next run
    assert len(re.findall(r"agents\.landing: SIGTERM: stopping", text)) == 4, text
