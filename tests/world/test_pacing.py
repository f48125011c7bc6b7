"""A paced world's clock goes out halfway between two ticks, not with the samples (``WorldProcess._pace_to``):
every subscriber wakes for it, and with the samples that wake fell on the vehicles' busiest tick.

Oracle: the wall clock. At ``realtime`` a tick is ``dt`` = 10 ms; tick ``k``'s samples are out, the next
tick is due at ``due``: the clock of a tick that publishes one leaves no earlier than ``due - dt / 2`` and
the world waits until ``due``; at ``scaled:2`` half of that. Only lower bounds are asserted (a loaded
machine sleeps longer, never shorter); a world behind its schedule publishes at once.
"""

from __future__ import annotations

import threading
import time

import pytest

from swarm.scenario import load_scenario
from swarm.transport.keys import Keys
from swarm.transport.messages import Clock, decode
from swarm.transport.process import ClockSpec
from swarm.world.process import WorldProcess


class _Clock:
    def __init__(self) -> None:
        self.sent: list[tuple[float, Clock]] = []

    def put(self, payload: bytes) -> None:
        self.sent.append((time.monotonic(), decode(payload, Clock)))


@pytest.mark.parametrize("factor", [1.0, 2.0])
def test_the_clock_leaves_halfway_to_the_next_tick_and_the_world_waits_for_it(tmp_path, factor):
    sc = load_scenario("docking")
    assert sc.dt_s == 0.01
    clock = ClockSpec("realtime" if factor == 1.0 else "scaled", factor)
    wp = WorldProcess(sc, 0, None, Keys("pace"), clock, threading.Event(), checkpoint_dir=tmp_path)
    assert wp.clock_every == 10 and wp.pace is clock
    wp.pub_clock = pub = _Clock()
    period = sc.dt_s / factor

    due = time.monotonic() + 3 * period
    wp._pace_to(10, due)  # a tick that publishes the clock
    assert time.monotonic() >= due
    assert [m.tick for _, m in pub.sent] == [10] and pub.sent[0][1].state == wp.state
    assert pub.sent[0][0] >= due - 0.5 * period

    due = time.monotonic() + 2 * period
    wp._pace_to(11, due)  # one that does not
    assert time.monotonic() >= due and len(pub.sent) == 1

    t0 = time.monotonic()
    wp._pace_to(20, t0 - 0.1)  # behind its schedule: the clock at once, no wait
    assert [m.tick for _, m in pub.sent] == [10, 20]
    assert time.monotonic() - t0 < 0.5  # (no sleep: a generous bound for a loaded machine)


def test_a_stop_ends_the_wait(tmp_path):
    sc = load_scenario("docking")
    stop = threading.Event()
    wp = WorldProcess(sc, 0, None, Keys("pace"), ClockSpec("realtime"), stop, checkpoint_dir=tmp_path)
    wp.pub_clock = _Clock()
    stop.set()
    t0 = time.monotonic()
    wp._pace_to(10, t0 + 30.0)
    assert time.monotonic() - t0 < 5.0
