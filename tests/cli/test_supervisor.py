"""The launcher's supervisor: children stopped even when they ignore SIGTERM, grandchildren included, and
restarts bounded with exponential backoff. Real processes; each test kills what it started."""

from __future__ import annotations

import os
import signal
import time

import pytest

from swarm.cli.supervisor import Child, Supervisor
from tests.transport.procs import wait_until


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
        with open(f"/proc/{pid}/stat") as f:  # a zombie is dead (reparented ones wait for init to reap them)
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (ProcessLookupError, FileNotFoundError):
        return False


@pytest.fixture
def sup():
    s = Supervisor(max_restarts=2, backoff_s=0.2, grace_s=0.5)
    yield s
    s.stop_all()


def test_a_child_that_ignores_sigterm_and_its_own_child_are_killed_after_the_grace(sup):
    lines: list[str] = []
    child = Child("hang", ["tests.cli._hang"], on_line=lines.append)
    sup.start(child)
    deadline = time.monotonic() + 20
    while "up" not in lines and time.monotonic() < deadline:
        time.sleep(0.02)
    assert "up" in lines
    pgid = child.popen.pid
    members = [int(p) for p in os.listdir("/proc") if p.isdigit() and _pgid(int(p)) == pgid]
    assert len(members) >= 2  # the child and its grandchild
    t0 = time.monotonic()
    sup.stop_all()
    assert time.monotonic() - t0 < 5.0
    # SIGKILL is delivered asynchronously: give the kernel a moment to finish them
    wait_until(lambda: not any(_alive(p) for p in members), 5.0, f"processes {members} to die")


def _pgid(pid: int) -> int | None:
    try:
        return os.getpgid(pid)
    except ProcessLookupError:
        return None


def test_restarts_back_off_exponentially_and_stop_at_the_limit(sup):
    child = Child("agent/x", ["tests.cli._hang"], restartable=True, rejoin_args=["--rejoin"])
    sup.start(child)
    msgs = [sup.lost("agent/x", "test")]
    assert "restart 1/2 in 0.2 s" in msgs[0]
    assert not child.running
    assert sup.lost("agent/x", "test") == ""  # already scheduled: not counted twice
    time.sleep(0.25)
    assert [c.name for c in sup.due_restarts()] == ["agent/x"] and child.running
    assert "restart 2/2 in 0.4 s" in sup.lost("agent/x", "test")
    time.sleep(0.45)
    sup.due_restarts()
    assert "giving up" in sup.lost("agent/x", "test")
    assert sup.due_restarts() == [] and not child.running


def _wait_spoken(*children: Child) -> None:
    wait_until(lambda: all(c.spoke for c in children), 30.0, "the children's first line")


def test_stacks_come_from_each_child_that_has_spoken_and_none_is_harmed(sup, capfd):
    """:meth:`Supervisor.dump_children` signals each running child that has printed its first line, one after
    the other: each writes its threads' stacks to the launcher's stderr (the function it waits in is named)
    and goes on running. A child still starting (it has said nothing: the signal would end it before it
    enables the dump) is not signalled and lives on; neither is one that has exited."""
    ready = [Child(f"agent/{i}", ["tests.cli._waiter"]) for i in range(2)]
    starting = Child("world", ["tests.cli._waiter", "--quiet-s", "60"])
    ended = Child("mothership", ["tests.cli._hang"])  # (ignores SIGTERM: killed below, before the dump)
    for c in (*ready, starting, ended):
        sup.start(c)
    _wait_spoken(*ready, ended)
    os.killpg(ended.popen.pid, signal.SIGKILL)
    ended.popen.wait(5.0)
    capfd.readouterr()
    asked = sup.dump_children(gap_s=0.2)
    assert asked == [f"agent/{i} (pid {c.popen.pid})" for i, c in enumerate(ready)]
    err = ""
    deadline = time.monotonic() + 10.0
    while err.count("in waiting_in_the_waiter") < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
        err += capfd.readouterr().err
    assert err.count("in waiting_in_the_waiter") == 2, err
    assert err.count("(most recent call first)") >= 2
    assert all(c.running for c in (*ready, starting)), "a stacks signal ended a child"


def test_the_launchers_signal_dumps_its_own_stacks_then_every_childs(sup, capfd, caplog):
    """In the launcher, the stacks signal (:func:`forward_stacks_signal`) writes a line naming each process
    in order, the launcher's own stacks, then each child's; once restored, the launcher's plain dump is back
    (and still does not end it)."""
    from swarm.cli.supervisor import forward_stacks_signal
    from swarm.stacks import STACKS_SIGNAL

    child = Child("agent/a", ["tests.cli._waiter"])
    sup.start(child)
    _wait_spoken(child)
    capfd.readouterr()
    restore = forward_stacks_signal(sup)
    try:
        os.kill(os.getpid(), STACKS_SIGNAL)
        err = ""
        deadline = time.monotonic() + 10.0
        while "in waiting_in_the_waiter" not in err and time.monotonic() < deadline:
            time.sleep(0.05)
            err += capfd.readouterr().err
    finally:
        restore()
    me = os.getpid()
    said = f"SIGUSR1: the stacks of the launcher (pid {me}), then of agent/a (pid {child.popen.pid}) follow"
    assert said in caplog.text  # (the launcher's log is on its stderr)
    assert err.index("test_the_launchers_signal_dumps") < err.index("in waiting_in_the_waiter"), err
    os.kill(me, STACKS_SIGNAL)  # the plain dump, restored: this process goes on
    time.sleep(0.2)
    assert "test_the_launchers_signal_dumps" in capfd.readouterr().err


def test_a_stall_is_told_once_while_running_and_again_only_after_the_clock_moved():
    """:class:`StallWatch`: nothing before the first clock, nor while paused or stopped, nor before
    ``stall_s``; once at ``stall_s`` in a running run (the tick and the seconds), not again for the same
    stall; a moved clock re-arms it; a stall counted across a pause starts again from the resume."""
    from swarm.cli.supervisor import StallWatch

    w = StallWatch(2.0)
    assert w.check(100.0) is None  # no clock yet
    w.on_clock(10, "running", 100.0)
    assert w.check(101.9) is None
    assert w.check(102.0) == (10, 2.0)
    assert w.check(105.0) is None  # told once
    w.on_clock(20, "running", 106.0)
    assert w.check(107.0) is None
    assert w.check(108.5) == (20, 2.5)
    w.on_clock(20, "paused", 109.0)
    assert w.check(200.0) is None  # a paused world stands still on purpose
    w.on_clock(20, "running", 201.0)
    assert w.check(202.5) is None  # counted from the resume, not from the pause
    assert w.check(203.0) == (20, 2.0)
    w.on_clock(30, "stopped", 204.0)
    assert w.check(300.0) is None  # the run is over


class _Sup:
    """A supervisor that only records what the launcher's loop asks of it (no child)."""

    def __init__(self) -> None:
        self.children: dict = {}
        self.dumps: list[str] = []

    def dump_all(self, why: str) -> None:
        self.dumps.append(why)

    def exited(self) -> list:
        return []

    def due_restarts(self) -> list:
        return []


def test_the_launchers_loop_dumps_every_stack_at_a_stall_and_at_the_timeout():
    """``swarm launch``'s supervising loop: a world clock standing still in a running run past
    ``--stall-s`` asks every process for its stacks (once), and ``--timeout`` before the run ended asks
    again before the loop gives up ("failed"), so that the children are stopped only after they said where
    they were."""
    import argparse
    import queue
    import threading

    from swarm.cli.launch import RunLog, _supervise
    from swarm.cli.launch_missions import LAUNCHES
    from swarm.transport.messages import Clock

    args = argparse.Namespace(timeout=1.0, vehicles_per_process=1)
    log, sup = RunLog(stall_s=0.2), _Sup()
    log.on_clock("ns/world/clock", Clock(40, 0.4, "running", 1))
    t0 = time.monotonic()
    assert (
        _supervise(args, LAUNCHES["docking"], {}, sup, queue.Queue(), log, threading.Event(), t0) == "failed"
    )
    assert time.monotonic() - t0 >= 1.0
    wait_until(lambda: len(sup.dumps) == 2, 5.0, "the stall's dump, on its thread")
    assert sorted(sup.dumps) == sorted([
        "the world's clock has stood at tick 40 for 0.2 s in a running run",
        "--timeout 1 s reached before the run ended",
    ])  # fmt: skip
