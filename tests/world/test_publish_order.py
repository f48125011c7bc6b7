"""The world publishes a tick's samples of the vehicles that command on it first (``due_first``): with
staggered controller clocks, the few commands of a tick are not queued behind every other vehicle's
filter-only tick. Oracle: the rule written out per case (docstring of ``due_first``)."""

from __future__ import annotations

import threading
from collections import Counter

from swarm.scenario import load_scenario
from swarm.transport.keys import Keys
from swarm.transport.process import ClockSpec
from swarm.world.process import WorldProcess, due_first

TICK = [("truth_batch", "", b"T"), ("vision", "c0", b"v0"), ("imu", "c0", b"i0"), ("imu", "t0", b"j0"),
        ("vision", "c1", b"v1"), ("imu", "c1", b"i1"), ("imu", "t1", b"j1")]  # fmt: skip


def test_the_due_vehicles_go_first_each_in_its_own_order():
    due = frozenset({"t0", "c1"})
    free = due_first(TICK, due, lockstep=False)
    # free-running: the commands must not wait, the truths (ranges fused late) after the due samples
    assert [p for _, _, p in free] == [b"j0", b"v1", b"i1", b"T", b"v0", b"i0", b"j1"]
    # lockstep: an agent's UWB tick waits for its range, made from the truths: those stay first
    lock = due_first(TICK, due, lockstep=True)
    assert [p for _, _, p in lock] == [b"T", b"j0", b"v1", b"i1", b"v0", b"i0", b"j1"]
    assert Counter(free) == Counter(lock) == Counter(TICK)  # the same messages, reordered only


def test_all_or_none_due_leaves_the_order_alone():
    for lockstep in (False, True):
        assert due_first(TICK, frozenset(), lockstep) is TICK
        assert due_first(TICK, frozenset({"c0", "t0", "c1", "t1"}), lockstep) is TICK
        assert due_first(TICK, frozenset({"nobody"}), lockstep) is TICK
        batches = [("truth_batch", "", b"T"), ("imu_batch", "", b"B")]  # agent hosts: nothing on own keys
        assert due_first(batches, frozenset({"c0"}), lockstep) is batches


class _Recorder:
    def __init__(self, out: list, kind: str, vid: str) -> None:
        self.out, self.kind, self.vid = out, kind, vid

    def put(self, payload: bytes) -> None:
        self.out.append((self.kind, self.vid))


def test_a_staggered_free_running_world_publishes_the_due_vehicles_first(tmp_path):
    sc = load_scenario("docking", {"swarm": {"stagger_control": True}}).with_pairs(4)
    wp = WorldProcess(sc, 0, None, Keys("order"), ClockSpec("realtime"), threading.Event(),
                      checkpoint_dir=tmp_path)  # fmt: skip
    sent: list = []
    wp._pub = lambda kind, vid: _Recorder(sent, kind, vid)  # the session's publishers, recorded
    k = 13  # 8 vehicles staggered over a control period of 10: vehicle m commands on ticks m % 10
    due = wp.barrier.due(k)
    assert due == {vid for m, vid in enumerate(wp.ids) if m == k % 10} and len(due) == 1
    # a tick's samples as world_sensors orders them: the truths, then per vehicle its frame and its imu
    tick = [("truth_batch", "", b"T")]
    for vid in wp.ids:
        tick += [("vision", vid, b"v")] if vid in wp.chasers else []
        tick += [("imu", vid, b"i")]
    wp._publish_tick(k, tick)
    (first,) = due
    assert sent[0] == ("imu", first)  # a target's (m = 3: odd), woken before the 7 others and the truths
    assert sorted(sent) == sorted((kind, vid) for kind, vid, _ in tick)
    assert sent[1:] == [(kind, vid) for kind, vid, _ in tick if vid != first]  # the rest in their order
