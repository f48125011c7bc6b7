"""The launcher's supervisor: children stopped even when they ignore SIGTERM, grandchildren included, and
restarts bounded with exponential backoff. Real processes; each test kills what it started."""

from __future__ import annotations

import os
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
