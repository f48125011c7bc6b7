"""A paced world's clock goes out halfway between two ticks, not with the samples (``WorldProcess._pace_to``):
every subscriber wakes for it, and with the samples that wake fell on the vehicles' busiest tick. A
free-running world of agents a process each sends a tick's truths (the mothership's) there too.

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


class _Pub:
    """A publisher that keeps what it was given, when, and under which name."""

    def __init__(self, name: str, sent: list) -> None:
        self.name, self.sent = name, sent

    def put(self, payload: bytes) -> None:
        self.sent.append((time.monotonic(), self.name, payload))


def _recording(wp: WorldProcess, ids) -> list:
    sent: list = []
    wp._pubs = {kind: {v: _Pub(f"{kind}/{v}", sent) for v in [*ids, ""]}
                for kind in ("truth", "truth_batch", "vision", "imu")}  # fmt: skip
    return sent


_TICK = [("truth_batch", "", b"T"), ("truth", "chaser", b"t"), ("vision", "chaser", b"v"),
         ("imu", "chaser", b"i"), ("imu", "target", b"j")]  # fmt: skip
"""A UWB slot tick's samples in world_sensors' order: the truths lead."""


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


def test_a_free_running_world_of_agents_alone_sends_a_ticks_truths_halfway_to_the_next(tmp_path):
    """The agents' samples at once, in order; the truths (batch, then a viewer's) only once the world paces
    on, no earlier than halfway to the next tick, and before it; a world behind its schedule sends them at
    once. Nothing is held past ``_pace_to``."""
    sc = load_scenario("docking")
    stop = threading.Event()
    wp = WorldProcess(sc, 0, None, Keys("pace"), ClockSpec("realtime"), stop, checkpoint_dir=tmp_path)
    wp.pub_clock = _Clock()
    sent = _recording(wp, sc.vehicles)
    period = sc.dt_s

    t0 = time.monotonic()
    wp._publish_tick(11, _TICK)
    assert [p for _, _, p in sent] == [b"v", b"i", b"j"] and all(t >= t0 for t, _, _ in sent)
    due = time.monotonic() + 3 * period
    wp._pace_to(11, due)
    assert time.monotonic() >= due and not wp._between and not wp.pub_clock.sent
    assert [(n, p) for _, n, p in sent[3:]] == [("truth_batch/", b"T"), ("truth/chaser", b"t")]
    assert all(due - 0.5 * period <= t < due for t, _, _ in sent[3:])

    del sent[:]
    wp._publish_tick(12, _TICK)
    t0 = time.monotonic()
    wp._pace_to(12, t0 - 0.1)  # behind its schedule
    assert [p for _, _, p in sent] == [b"v", b"i", b"j", b"T", b"t"]
    assert time.monotonic() - t0 < 0.5  # (no sleep: a generous bound for a loaded machine)


@pytest.mark.parametrize("clock, batch", [("lockstep", False), ("realtime", True)])
def test_lockstep_and_agent_hosts_keep_the_truths_ahead_of_the_samples(tmp_path, clock, batch):
    """A lockstep agent waits for its range, so its world sends the truths first, with the samples; agent
    hosts keep them there too (not measured otherwise)."""
    sc = load_scenario("docking")
    wp = WorldProcess(sc, 0, None, Keys("pace"), ClockSpec(clock), threading.Event(), checkpoint_dir=tmp_path,
                      batch=batch, bundles=False)  # fmt: skip
    sent = _recording(wp, sc.vehicles)
    wp._publish_tick(11, _TICK)
    assert [p for _, _, p in sent] == [b"T", b"t", b"v", b"i", b"j"] and not wp._between
