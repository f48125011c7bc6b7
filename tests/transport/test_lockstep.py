"""Tests for swarm.transport.lockstep: tick assembly on the agent's side, the command barrier on the world's.

Oracle: the lockstep contract of ``docs/protocol.md`` ("Clocks and lockstep") and the tick order of
``DockingSim.run`` (tick ``k`` needs ``imu(k)``, ``uwb(k)`` on UWB slots, a chaser its target's
``estimate(k - 1)``, ``vision(k)`` on camera slots), written out by hand per case. Threaded
tests feed messages in shuffled orders from several producers (seeded) and check that the result does
not depend on the order. Negative waits use 50 ms timeouts; positive ones 5 s, which they never reach.
"""

from __future__ import annotations

import random
import threading
import time

import numpy as np
import pytest

from swarm.errors import ConfigError
from swarm.transport.lockstep import AgentTickAssembler, CommandBarrier
from swarm.transport.messages import Command, Estimate, Imu, Uwb, Vision

DT = 0.01
SHORT = 0.05  # s: a wait that must time out
LONG = 5.0  # s: a wait that must succeed (returns as soon as it does)


def imu(k: int, w: float = 0.0) -> Imu:
    return Imu(tick=k, t_s=k * DT, dt_s=DT, gyro_body=np.array([w, 0.0, 0.0]))


def uwb(k: int, range_m: float | None = 1.0) -> Uwb:
    return Uwb(tick=k, t_s=k * DT, anchor_id=0, range_m=range_m)


def vision(k: int) -> Vision:
    return Vision(
        tick=k, t_s=k * DT, target_id="target", face="+x", kind="features",
        data=np.array([[0.0, 0.0, 1.0]]), marker_ids=(0,),
    )  # fmt: skip


def estimate(k: int, x: float = 0.0) -> Estimate:
    return Estimate(
        tick=k, t_s=k * DT, p_nav=np.array([x, 0.0, 0.0]), v_nav=np.zeros(3),
        q_nav_body=np.array([0.0, 0.0, 0.0, 1.0]), cov=np.eye(9), sigma_pos_max_m=1.0,
        mahalanobis_d=0.0, rejection_fraction=0.0, counts={},
    )  # fmt: skip


def command(k: int) -> Command:
    return Command(
        tick=k, t_s=k * DT, actuators=np.zeros(4), force_body_n=np.zeros(3),
        torque_body_nm=np.zeros(3), mode="HOLD",
    )  # fmt: skip


def chaser(uwb_every: int = 2, **kw) -> AgentTickAssembler:
    kw.setdefault("start", 1)
    return AgentTickAssembler("chaser", True, "target", uwb_every, **kw)


def plain(uwb_every: int = 2, **kw) -> AgentTickAssembler:
    kw.setdefault("start", 1)
    return AgentTickAssembler("target", False, None, uwb_every, **kw)


def camera(uwb_every: int = 3, vision_every: int = 2, **kw) -> AgentTickAssembler:
    return plain(uwb_every, vision_every=vision_every, **kw)


ALL_ZERO = dict.fromkeys(("stale", "duplicates", "future", "unexpected", "incomplete", "late"), 0)


# ------------------------------------------------------------------------------ completion rules


def test_tick_zero_needs_no_sensor_and_a_chaser_waits_for_the_targets_initial_estimate():
    assert plain(start=0).next_tick(0).tick == 0
    asm = chaser(start=0)
    assert asm.next_tick(SHORT) is None and asm.waiting_for() == ["estimate"]
    asm.add(estimate(0, x=3.0), "target")
    got = asm.next_tick(0)
    assert got.tick == 0 and got.imu is None and got.target_estimate.p_nav[0] == 3.0
    asm.add(imu(1))
    got = asm.next_tick(0)  # tick 1 also uses estimate(0), as DockingSim does
    assert got.tick == 1 and got.target_estimate.tick == 0


def test_a_chaser_waits_for_its_targets_estimate_only_on_the_ticks_that_read_it():
    """With ``target_reads`` (camera every 5 ticks, control every 10), ticks 1-4 complete on their sensors
    and carry the estimate held since tick 0; tick 5 waits for estimate(4), and tick 10 for estimate(9)."""
    asm = chaser(uwb_every=100, start=0, target_reads=(5, 10))
    asm.add(estimate(0, x=1.0), "target")
    assert asm.next_tick(0).target_estimate.tick == 0
    for k in range(1, 5):
        asm.add(imu(k))
        got = asm.next_tick(0)
        assert got.tick == k and got.target_estimate.tick == 0
    asm.add(imu(5))
    assert asm.next_tick(SHORT) is None and asm.waiting_for() == ["estimate"]
    asm.add(estimate(4, x=2.0), "target")
    got = asm.next_tick(0)
    assert got.tick == 5 and got.target_estimate.p_nav[0] == 2.0
    for k in range(6, 10):
        asm.add(imu(k))
        assert asm.next_tick(0).target_estimate.tick == 4
    asm.add(imu(10))
    assert asm.next_tick(SHORT) is None
    asm.add(estimate(9), "target")
    assert asm.next_tick(0).target_estimate.tick == 9
    assert asm.counts() == ALL_ZERO
    with pytest.raises(ConfigError, match="target_reads"):
        chaser(target_reads=(5, 0))


def test_a_target_sends_the_estimates_its_chasers_read():
    """wire.target_reads / estimate_reads / estimate_read against the scenario's rates: the target
    of the docking scenario sends estimate(0) and those of the ticks before a camera or control tick; a
    chaser (no one's target) every one; without the latch every one (its published covariance reads it)."""
    from swarm.scenario import load_scenario
    from swarm.transport.wire import estimate_read, estimate_reads, target_reads

    sc = load_scenario("docking")
    cam, ctl = sc.every(sc.camera.rate_hz), sc.control_every("chaser")
    assert target_reads(sc, "chaser") == tuple(sorted({cam, ctl})) == (5, 10)
    reads = estimate_reads(sc, "target")
    assert reads == (5, 10) and estimate_reads(sc, "chaser") is None
    sent = [k for k in range(31) if estimate_read(reads, k)]
    assert sent == [0, 4, 9, 14, 19, 24, 29]
    assert all(estimate_read(None, k) for k in range(31))
    off = load_scenario("docking", {"agent.latch_target_with_vision": False})
    assert target_reads(off, "chaser") is None and estimate_reads(off, "target") is None
    # a chaser whose controller clock is staggered (control_phase 3) reads on its camera ticks and on
    # ticks 3, 13, 23, ...: the target sends the estimates of the ticks before those
    late = load_scenario("docking", {"vehicles.chaser.control_phase": 3})
    assert target_reads(late, "chaser") == (5, (10, 3)) == estimate_reads(late, "target")
    sent = [k for k in range(31) if estimate_read(estimate_reads(late, "target"), k)]
    assert sent == [0, 2, 4, 9, 12, 14, 19, 22, 24, 29]
    asm = chaser(uwb_every=100, start=0, target_reads=target_reads(late, "chaser"))
    assert [k for k in range(1, 25) if asm._needed_estimate(k) is not None] == [3, 5, 10, 13, 15, 20, 23]
    with pytest.raises(ConfigError, match="phase must be below"):
        chaser(target_reads=(5, (10, 10)))


def test_non_uwb_tick_completes_on_imu_alone():
    asm = plain(uwb_every=2)
    asm.add(imu(1))
    got = asm.next_tick(0)
    assert got is not None and got.tick == 1 and got.uwb is None and got.vision is None
    assert got.target_estimate is None


def test_uwb_tick_waits_for_uwb():
    asm = plain(uwb_every=2)
    asm.add(imu(1))
    asm.next_tick(0)
    asm.add(imu(2))
    assert asm.next_tick(SHORT) is None
    assert asm.waiting_for() == ["uwb"]
    asm.add(uwb(2))
    got = asm.next_tick(0)
    assert got is not None and got.tick == 2 and got.uwb.range_m == 1.0


def test_lost_uwb_reply_completes_the_tick_with_range_none():
    asm = plain(uwb_every=1)
    asm.add(uwb(1, range_m=None))
    asm.add(imu(1))
    got = asm.next_tick(0)
    assert got is not None and got.uwb is not None and got.uwb.range_m is None


def test_uwb_off_slot_is_dropped_as_unexpected():
    asm = plain(uwb_every=2)
    assert not asm.add(uwb(1))
    assert asm.counts()["unexpected"] == 1


def test_on_a_tdma_channel_only_the_tags_exchange_ticks_wait_for_a_range():
    """A tag idle on a TDMA channel has no exchange on that slot tick and the mothership sends it nothing:
    the tick completes on its imu, and a range of such a tick is not its own (unexpected)."""
    slots = {4, 10}  # the exchange ticks of this tag among the slot ticks 2, 4, 6, 8, 10
    asm = plain(uwb_every=2, uwb_slots=lambda k: k in slots)
    got = []
    for k in range(1, 11):
        asm.add(imu(k))
        if k in slots:
            assert asm.next_tick(SHORT) is None and asm.waiting_for() == ["uwb"], k
            asm.add(uwb(k))
        got.append(asm.next_tick(0))
    assert [g.tick for g in got] == list(range(1, 11))
    assert [g.tick for g in got if g.uwb is not None] == sorted(slots)
    # a slot tick, but not one of its exchanges
    assert not asm.add(uwb(12)) and asm.counts()["unexpected"] == 1


def test_chaser_waits_for_target_estimate_of_previous_tick():
    asm = chaser(uwb_every=5)
    asm.add(imu(1))
    asm.add(estimate(1))  # estimate(k) is for tick k + 1, not k
    assert asm.next_tick(SHORT) is None
    assert asm.waiting_for() == ["estimate"]
    asm.add(estimate(0, x=7.0), "target")
    got = asm.next_tick(0)
    assert got is not None and got.tick == 1 and got.target_estimate.tick == 0
    assert got.target_estimate.p_nav[0] == 7.0
    asm.add(imu(2))
    got = asm.next_tick(0)
    assert got is not None and got.target_estimate.tick == 1


def test_estimate_of_another_vehicle_is_unexpected():
    asm = chaser()
    assert not asm.add(estimate(0), "other")
    assert asm.counts()["unexpected"] == 1
    assert not plain().add(estimate(0))  # a non-chaser uses no estimate


def test_sensor_message_of_another_vehicle_is_unexpected():
    asm = plain()
    assert not asm.add(imu(1), "someone-else")
    assert asm.counts()["unexpected"] == 1 and asm.next_tick(0) is None


def test_camera_tick_waits_for_its_frame_in_either_arrival_order():
    for order in ((imu, vision), (vision, imu)):
        asm = camera(vision_every=1)
        asm.add(order[0](1))
        assert asm.next_tick(SHORT) is None
        asm.add(order[1](1))
        got = asm.next_tick(0)
        assert got.vision is not None and got.vision.tick == 1 and got.imu.tick == 1


def test_a_frame_without_markers_completes_the_camera_tick():
    asm = camera(vision_every=1)
    asm.add(imu(1))
    asm.add(Vision(1, 0.01, "target", "+x", "features", np.zeros((0, 3)), ()))
    got = asm.next_tick(0)
    assert got is not None and not got.vision.seen


def test_vision_off_its_camera_slots_or_without_a_camera_is_unexpected():
    asm = camera(vision_every=2)
    assert not asm.add(vision(3))
    assert not plain().add(vision(2))  # no camera
    assert asm.counts()["unexpected"] == 1


# ------------------------------------------------------------------------------ ordering and counters


def test_ticks_come_out_in_order_whatever_the_arrival_order():
    asm = plain(uwb_every=2)
    for k in (3, 1, 4, 2):
        asm.add(imu(k))
    for k in (4, 2):
        asm.add(uwb(k))
    assert [asm.next_tick(0).tick for _ in range(4)] == [1, 2, 3, 4]
    assert asm.next_tick(0) is None


def test_a_later_complete_tick_does_not_overtake_an_incomplete_one():
    asm = plain(uwb_every=2)
    asm.add(imu(2))
    asm.add(uwb(2))
    assert asm.next_tick(SHORT) is None  # tick 1 lacks imu
    asm.add(imu(1))
    assert asm.next_tick(0).tick == 1


def test_stale_messages_are_dropped_and_counted():
    asm = chaser(uwb_every=1)
    asm.add(estimate(0))
    asm.add(imu(1))
    asm.add(uwb(1))
    asm.next_tick(0)
    assert not asm.add(imu(1))
    assert not asm.add(uwb(1))
    assert not asm.add(estimate(0))  # used by tick 1, already processed
    assert asm.counts()["stale"] == 3


def test_duplicates_keep_the_first_message():
    asm = plain(uwb_every=1)
    assert asm.add(imu(1, w=1.0))
    assert not asm.add(imu(1, w=2.0))
    assert asm.add(uwb(1, range_m=3.0))
    assert not asm.add(uwb(1, range_m=4.0))
    assert asm.counts()["duplicates"] == 2
    got = asm.next_tick(0)
    assert got.imu.gyro_body[0] == 1.0 and got.uwb.range_m == 3.0


def test_duplicate_estimate_is_counted():
    asm = chaser()
    assert asm.add(estimate(0, x=1.0))
    assert not asm.add(estimate(0, x=2.0))
    assert asm.counts()["duplicates"] == 1


def test_samples_published_again_by_a_resumed_world_change_no_tick():
    """A world resumed at tick k publishes tick k's samples again (docs/protocol.md, "Restart and loss").
    An agent that already processed tick k drops them as stale; one that had part of tick k keeps the
    first of each and completes the tick with the part it lacked. Either way each tick comes out once,
    with the first samples, as without the restart."""
    done = camera(uwb_every=2, vision_every=2, start=2)  # processed tick 2 before the world was killed
    for msg in (imu(2, w=1.0), uwb(2), vision(2)):
        done.add(msg)
    assert done.next_tick(0).tick == 2
    for msg in (imu(2, w=9.0), uwb(2), vision(2)):  # the resumed world's copies
        assert not done.add(msg)
    assert done.counts() == {**ALL_ZERO, "stale": 3}
    assert done.next_tick(SHORT) is None  # nothing new to process: it waits for tick 3

    partial = camera(uwb_every=2, vision_every=2, start=2)  # had imu(2) only when the world was killed
    partial.add(imu(2, w=1.0))
    assert partial.next_tick(SHORT) is None
    for msg in (imu(2, w=9.0), uwb(2), vision(2)):
        partial.add(msg)
    got = partial.next_tick(0)
    assert (got.tick, got.imu.gyro_body[0]) == (2, 1.0)  # the first imu of the tick
    assert got.uwb is not None and got.vision is not None
    assert partial.counts() == {**ALL_ZERO, "duplicates": 1}


def test_far_future_messages_are_dropped_and_counted():
    asm = chaser(uwb_every=1, max_ahead=10)
    assert asm.add(imu(11))  # next is 1: 10 ahead is still buffered
    assert not asm.add(imu(12))
    assert not asm.add(uwb(12))
    assert not asm.add(estimate(11))  # used by tick 12
    assert asm.counts()["future"] == 3


def test_timeout_consumes_nothing_and_the_tick_completes_later():
    asm = plain(uwb_every=2)
    asm.add(imu(1))
    asm.next_tick(0)
    asm.add(imu(2))
    t0 = time.monotonic()
    assert asm.next_tick(SHORT) is None
    assert time.monotonic() - t0 >= SHORT * 0.9
    assert asm.next_expected == 2
    asm.add(uwb(2))
    assert asm.next_tick(0).tick == 2


def test_next_tick_wakes_when_another_thread_completes_the_tick():
    asm = chaser(uwb_every=1)
    timer = threading.Timer(0.02, lambda: [asm.add(m) for m in (uwb(1), estimate(0), imu(1))])
    timer.start()
    got = asm.next_tick(LONG)
    timer.join()
    assert got is not None and got.tick == 1


def test_close_wakes_a_waiting_consumer():
    asm = plain()
    threading.Timer(0.02, asm.close).start()
    assert asm.next_tick(LONG) is None


def test_chaser_without_target_is_a_config_error():
    with pytest.raises(ConfigError, match="target id"):
        AgentTickAssembler("chaser", True, None, 2)
    with pytest.raises(ConfigError, match="uwb_every"):
        AgentTickAssembler("chaser", False, None, 0)
    with pytest.raises(ConfigError, match="vision_every"):
        AgentTickAssembler("chaser", False, None, 2, vision_every=0)


# ------------------------------------------------------------------------------ joining, lost target


def test_a_joining_agent_starts_after_the_first_imu_it_sees():
    asm = plain(uwb_every=2, start=None)
    assert asm.next_expected is None and asm.waiting_for() == ["imu"]
    assert asm.add(uwb(500))  # before any imu: kept until the start is known
    assert not asm.add(imu(500))  # fixes the start at 501; tick 500 may have lost inputs
    assert asm.next_expected == 501 and asm.counts()["stale"] == 2
    asm.add(imu(501))
    assert asm.next_tick(0).tick == 501
    assert not asm.add(imu(499))
    assert asm.counts()["stale"] == 3


def test_a_joining_chaser_waits_for_estimates_only_once_they_flow():
    asm = chaser(uwb_every=5, start=None)
    asm.add(imu(100))
    asm.add(imu(101))
    got = asm.next_tick(0)  # no estimate arrived yet: the tick does not wait, and has none
    assert got.tick == 101 and got.target_estimate is None
    asm.add(estimate(101, x=1.0))
    asm.add(imu(102))
    asm.add(imu(103))
    assert asm.next_tick(0).target_estimate.tick == 101
    assert asm.next_tick(SHORT) is None and asm.waiting_for() == ["estimate"]  # now it waits: estimate(102)


def test_a_lost_target_stops_the_wait_and_its_last_estimate_is_held():
    asm = chaser(uwb_every=5)
    asm.add(estimate(0, x=4.0))
    for k in (1, 2, 3):
        asm.add(imu(k))
    assert asm.next_tick(0).tick == 1
    assert asm.next_tick(SHORT) is None  # waits for estimate(1)
    asm.set_target_live(False)
    got = asm.next_tick(0)
    assert got.tick == 2 and got.target_estimate.tick == 0 and got.target_estimate.p_nav[0] == 4.0
    asm.set_target_live(True)  # back (restarted): waits again from its first new estimate
    assert asm.next_tick(0).tick == 3  # nothing from it yet
    asm.add(estimate(3, x=5.0))
    asm.add(imu(4))
    asm.add(imu(5))
    got = asm.next_tick(0)
    assert got.tick == 4 and got.target_estimate.tick == 3
    assert asm.next_tick(SHORT) is None and asm.waiting_for() == ["uwb", "estimate"]


def test_a_free_running_agent_takes_a_late_tick_partially_and_never_waits_for_the_target():
    asm = chaser(uwb_every=2, wait_for_target=False)
    asm.add(imu(1))
    got = asm.next_tick(0)
    assert got.tick == 1 and got.target_estimate is None  # no estimate yet: not waited for
    asm.add(imu(2))  # uwb(2) is late
    assert asm.next_tick(SHORT) is None
    got = asm.poll(0.0)[0]  # its grace over: taken without its range
    assert got.tick == 2 and got.uwb is None and asm.counts()["incomplete"] == 1
    assert not asm.add(uwb(2))  # came too late: stale
    asm.add(estimate(2, x=9.0))
    asm.add(imu(4))  # imu(3) never came: tick 3 is skipped, and tick 4 taken without its range
    got = asm.poll(0.0)[0]
    assert got.tick == 4 and got.target_estimate.tick == 2 and asm.counts()["incomplete"] == 3
    assert asm.poll(0.0) == (None, None)  # nothing further arrived


def test_a_lost_mothership_stops_the_wait_for_ranges_until_they_flow_again():
    asm = plain(uwb_every=1)
    asm.add(imu(1))
    assert asm.next_tick(SHORT) is None and asm.waiting_for() == ["uwb"]
    asm.set_uwb_live(False)
    got = asm.next_tick(0)
    assert got.tick == 1 and got.uwb is None
    asm.set_uwb_live(True)  # restarted: no range arrived yet, so none is waited for
    asm.add(imu(2))
    assert asm.next_tick(0).tick == 2
    asm.add(uwb(4))  # its first range
    asm.add(imu(3))
    assert asm.next_tick(0).tick == 3  # before its first range: not waited for
    asm.add(imu(4))
    asm.add(imu(5))
    assert asm.next_tick(0).uwb.tick == 4
    assert asm.next_tick(SHORT) is None and asm.waiting_for() == ["uwb"]  # from then on, waited for


def test_ranges_that_always_come_after_their_ticks_are_waited_for_from_the_first_stale_one():
    """A lockstep world sends a control period's ticks in one bundle and the mothership their ranges in
    another, after it: a joining agent (or one whose mothership came back) that waits for ranges only from
    the first that arrives in time would take every tick of every bundle before its range, for good (a
    restarted chaser never re-initialised and drifted into its target). The first range that comes late
    proves the mothership serves: from the next tick on, each waits for its range."""
    asm = plain(uwb_every=2)
    asm.set_uwb_live(False)
    asm.set_uwb_live(True)  # back: no range arrived yet
    for k in range(1, 11):  # the world's bundle of ticks 1-10
        asm.add(imu(k))
    assert [asm.next_tick(0).tick for _ in range(10)] == list(range(1, 11))  # none waited for ...
    for k in range(2, 11, 2):  # ... then the mothership's bundle: every range stale
        assert not asm.add(uwb(k))
    for k in range(11, 21):  # the next bundle
        asm.add(imu(k))
    assert asm.next_tick(0).tick == 11
    assert asm.next_tick(SHORT) is None and asm.waiting_for() == ["uwb"]  # tick 12 waits for its range
    for k in range(12, 21, 2):
        asm.add(uwb(k))
    got = [asm.next_tick(0) for _ in range(9)]
    assert [g.tick for g in got] == list(range(12, 21))
    assert [g.uwb.tick for g in got if g.uwb is not None] == list(range(12, 21, 2))


@pytest.mark.parametrize("seed", range(5))
def test_concurrent_producers_in_shuffled_order_give_the_in_process_tick_sequence(seed):
    n, uwb_every, vision_every = 60, 2, 5
    rnd = random.Random(seed)
    asm = chaser(uwb_every=uwb_every, vision_every=vision_every, start=0)
    # separate subscribers: imu and vision on different threads, each in its publisher's order
    imus = [imu(k, w=float(k)) for k in range(1, n + 1)]
    frames = [vision(k) for k in range(vision_every, n + 1, vision_every)]
    mothership = [uwb(k, range_m=float(k)) for k in range(uwb_every, n + 1, uwb_every)]
    target = [estimate(k, x=float(k)) for k in range(n)]
    rnd.shuffle(mothership)  # any order at all: the assembler must not care
    rnd.shuffle(target)

    def feed(msgs, source):
        for m in msgs:
            asm.add(m, source)
            if rnd.random() < 0.1:
                time.sleep(0.0005)

    threads = [
        threading.Thread(target=feed, args=(imus, "chaser")),
        threading.Thread(target=feed, args=(frames, "chaser")),
        threading.Thread(target=feed, args=(mothership, None)),
        threading.Thread(target=feed, args=(target, "target")),
    ]
    for t in threads:
        t.start()
    got = [asm.next_tick(LONG) for _ in range(n + 1)]
    for t in threads:
        t.join()
    assert all(g is not None for g in got)
    assert [g.tick for g in got] == list(range(n + 1))
    assert all(g.imu.gyro_body[0] == g.tick for g in got[1:])
    assert [g.tick for g in got if g.uwb is not None] == list(range(uwb_every, n + 1, uwb_every))
    assert all(g.uwb is None or g.uwb.range_m == g.tick for g in got)
    assert [g.tick for g in got if g.vision is not None] == list(range(vision_every, n + 1, vision_every))
    assert all(g.target_estimate.p_nav[0] == max(g.tick - 1, 0) for g in got)
    assert asm.counts() == ALL_ZERO


# ------------------------------------------------------------------------------ command barrier


def test_barrier_returns_when_all_commands_arrived():
    bar = CommandBarrier(["a", "b"])
    bar.add("b", command(0))
    bar.add("a", command(0))
    cmds, missing = bar.wait(0, 0)
    assert set(cmds) == {"a", "b"} and missing == []


def test_barrier_timeout_lists_missing_agents_in_order():
    bar = CommandBarrier(["a", "b", "c"])
    bar.add("b", command(1))
    t0 = time.monotonic()
    cmds, missing = bar.wait(1, SHORT)
    assert time.monotonic() - t0 >= SHORT * 0.9
    assert set(cmds) == {"b"} and missing == ["a", "c"]


def test_barrier_command_after_its_tick_was_released_is_stale():
    bar = CommandBarrier(["a", "b"])
    bar.add("a", command(1))
    bar.wait(1, SHORT)
    assert not bar.add("b", command(1))
    assert not bar.add("b", command(0))
    assert bar.counts()["stale"] == 2
    with pytest.raises(ConfigError, match="already released"):
        bar.wait(1, 0)


def test_barrier_set_live_shrinking_releases_the_wait():
    bar = CommandBarrier(["a", "b"])
    bar.add("a", command(3))
    threading.Timer(0.02, bar.set_live, args=(["a"],)).start()
    t0 = time.monotonic()
    cmds, missing = bar.wait(3, LONG)
    assert time.monotonic() - t0 < LONG / 2
    assert set(cmds) == {"a"} and missing == []


def test_barrier_set_live_rejects_unknown_ids():
    bar = CommandBarrier(["a"])
    with pytest.raises(ConfigError, match="unknown"):
        bar.set_live(["a", "z"])


def test_barrier_counts_duplicates_future_and_unknown():
    bar = CommandBarrier(["a"], max_ahead=5)
    assert bar.add("a", command(5))
    assert not bar.add("a", command(5))
    assert not bar.add("a", command(6))
    assert not bar.add("z", command(0))
    assert bar.counts() == {"stale": 0, "duplicates": 1, "future": 1, "unknown": 1}


def test_barrier_keeps_commands_of_later_ticks():
    bar = CommandBarrier(["a"])
    bar.add("a", command(2))
    bar.add("a", command(1))
    assert bar.wait(1, 0)[1] == []
    cmds, missing = bar.wait(2, 0)
    assert cmds["a"].tick == 2 and missing == []


def test_barrier_waits_for_each_agent_on_its_control_ticks_only():
    """An agent commands on its control ticks (every 10 ticks for a, 4 for b, every tick for c) and the world
    holds the command in between: tick k waits for the agents with k % every == 0, nobody else. Oracle: the
    rule per tick; a missing due agent is listed after the timeout, a missing agent that is not due is not."""
    bar = CommandBarrier(["a", "b", "c"], every={"a": 10, "b": 4})
    assert bar.every == {"a": 10, "b": 4, "c": 1}
    for k in range(41):
        want = {x for x, e in (("a", 10), ("b", 4), ("c", 1)) if k % e == 0}
        assert bar.due(k) == want, k
    bar.add("c", command(0))
    bar.add("b", command(0))
    assert not bar.poll(0, 0)  # a is due at 0
    bar.add("a", command(0))
    assert bar.poll(0, 0) and bar.wait(0, 0)[1] == []
    for k in range(1, 4):  # only c is due: a and b are held
        bar.add("c", command(k))
        cmds, missing = bar.wait(k, 0)
        assert set(cmds) == {"c"} and missing == []
    bar.add("c", command(4))
    cmds, missing = bar.wait(4, SHORT)  # b's command(4) never came
    assert set(cmds) == {"c"} and missing == ["b"]
    bar.set_live({"a", "b"})  # c lost: ticks 5..7 wait for nobody
    assert bar.due(5) == set() and bar.wait(5, 0) == ({}, [])
    assert bar.due(20) == {"a", "b"}


def test_barrier_waits_for_staggered_agents_on_their_own_phase():
    """Staggered controller clocks (control_phase): a every 10 ticks from tick 3, b every 4 from tick 1,
    c every 10 from 0. Oracle: (k - phase) % every == 0 per tick; before its phase an agent is not due."""
    bar = CommandBarrier(["a", "b", "c"], every={"a": 10, "b": 4, "c": 10}, phase={"a": 3, "b": 1})
    assert bar.phase == {"a": 3, "b": 1, "c": 0}
    for k in range(61):
        want = {x for x, e, p in (("a", 10, 3), ("b", 4, 1), ("c", 10, 0)) if k >= p and (k - p) % e == 0}
        assert bar.due(k) == want, k
    assert bar.due(0) == {"c"} and bar.wait(0, SHORT) == ({}, ["c"])
    bar.add("a", command(3))
    assert bar.wait(3, 0) == ({"a": command(3)}, [])


def test_barrier_refuses_a_period_for_an_unknown_agent_or_below_one():
    with pytest.raises(ConfigError, match="not among"):
        CommandBarrier(["a"], every={"z": 2})
    with pytest.raises(ConfigError, match="every"):
        CommandBarrier(["a"], every={"a": 0})
    with pytest.raises(ConfigError, match="phase must be below"):
        CommandBarrier(["a"], every={"a": 10}, phase={"a": 10})
    with pytest.raises(ConfigError, match="not among"):
        CommandBarrier(["a"], phase={"z": 1})


def test_barrier_concurrent_producers():
    ids = [f"agent{i}" for i in range(8)]
    n = 50
    bar = CommandBarrier(ids)
    rnd = random.Random(1)

    def produce(agent_id, delay_s):
        for k in range(n):
            bar.add(agent_id, command(k))
            if rnd.random() < 0.1:
                time.sleep(delay_s)

    threads = [threading.Thread(target=produce, args=(a, 0.0005 * (i % 3))) for i, a in enumerate(ids)]
    for t in threads:
        t.start()
    results = [bar.wait(k, LONG) for k in range(n)]
    for t in threads:
        t.join()
    assert all(missing == [] for _, missing in results)
    assert all(sorted(cmds) == ids and all(c.tick == k for c in cmds.values()) for k, (cmds, _) in
               enumerate(results))  # fmt: skip
    assert bar.counts() == {"stale": 0, "duplicates": 0, "future": 0, "unknown": 0}


# ------------------------------------------------------------------------------ poll (the agent host's loop)


def test_poll_in_lockstep_takes_only_complete_ticks_and_never_blocks():
    asm = plain(uwb_every=2)
    assert asm.poll() == (None, None)  # nothing yet: wait for a message, no deadline
    asm.add(imu(1))
    got, due = asm.poll()
    assert got.tick == 1 and due is None
    asm.add(imu(2))  # uwb(2) missing: lockstep waits for it, however long
    assert asm.poll(None, now=time.monotonic() + 1e6) == (None, None)
    asm.add(uwb(2))
    assert asm.poll()[0].tick == 2 and asm.counts()["incomplete"] == 0


def test_poll_free_running_gives_a_late_tick_a_deadline_from_its_imu_then_takes_it_partially():
    asm = chaser(uwb_every=2, wait_for_target=False)
    asm.add(imu(1))
    assert asm.poll(0.005)[0].tick == 1  # complete: no estimate is waited for when free-running
    t0 = time.monotonic()
    asm.add(imu(2))  # uwb(2) late
    got, due = asm.poll(0.005)
    assert got is None and t0 <= due - 0.005 <= time.monotonic()  # grace counted from the imu's arrival
    assert asm.poll(0.005, now=due - 1e-6) == (None, due)  # not yet
    got, again = asm.poll(0.005, now=due)
    assert got.tick == 2 and got.uwb is None and again is None and asm.counts()["incomplete"] == 1
    assert not asm.add(uwb(2))  # too late now: stale


def test_poll_free_running_skips_a_tick_whose_imu_was_lost_as_soon_as_a_later_one_is_in():
    asm = plain(uwb_every=2, wait_for_target=False)
    asm.add(imu(1))
    asm.poll(0.005)
    asm.add(uwb(2))  # imu(2) lost
    assert asm.poll(0.005) == (None, None)  # no later imu yet: nothing to skip to, no deadline
    asm.add(imu(3))
    got, due = asm.poll(0.005)
    # tick 2 skipped, tick 3 complete
    assert got.tick == 3 and due is None and asm.counts()["incomplete"] == 1


def test_late_fusion_takes_a_tick_at_its_imu_and_hands_its_late_range_and_frame_over_once():
    """Free-running with late fusion: no grace, the tick goes with its imu; its range and frame that come
    after are kept for take_late (counted late, each once), within the window; older ones are stale."""
    cond, ready = threading.Condition(), set()
    asm = camera(uwb_every=2, vision_every=2, wait_for_target=False, late_ticks=2, cond=cond, ready=ready)
    assert asm.add(imu(1)) and asm.poll(0.0)[0].tick == 1
    assert asm.add(imu(2))
    got, due = asm.poll(0.0)  # uwb(2) and vision(2) not in: taken now, nothing counted incomplete
    assert got.tick == 2 and got.uwb is None and got.vision is None and due is None
    assert asm.take_late() == []
    ready.clear()
    assert asm.add(uwb(2, 1.5)) and asm in ready  # the consumer is woken for it
    assert not asm.add(uwb(2, 1.6))  # a second range of tick 2: a duplicate, not fused twice
    assert asm.add(vision(2))
    late = asm.take_late()
    assert [type(m).__name__ for m in late] == ["Uwb", "Vision"] and late[0].range_m == 1.5
    assert asm.take_late() == []  # handed over once
    assert asm.counts() == {**ALL_ZERO, "late": 2, "duplicates": 1}
    for k in (3, 4, 5):
        asm.add(imu(k))
        assert asm.poll(0.0)[0].tick == k
    assert asm.add(uwb(4))  # two ticks before the next one (6): still within late_ticks
    assert not asm.add(vision(2)) and not asm.add(uwb(2))  # four ticks old: beyond the window, stale
    assert asm.counts() == {**ALL_ZERO, "late": 3, "duplicates": 1, "stale": 2}


def test_without_late_fusion_a_range_after_its_tick_is_stale_and_nothing_is_handed_over():
    asm = plain(uwb_every=2, wait_for_target=False)
    asm.add(imu(1))
    asm.poll(0.0)
    asm.add(imu(2))
    assert asm.poll(0.0)[0].tick == 2 and asm.counts()["incomplete"] == 1  # grace 0: taken at once, counted
    assert not asm.add(uwb(2)) and asm.take_late() == [] and asm.counts()["stale"] == 1


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.parametrize(("grace", "late_ticks"), [(None, None), (0.0, None), (0.0, 3)])
def test_poll_round_takes_what_take_late_and_poll_take_and_says_when_a_further_tick_is_ready(
    seed, grace, late_ticks
):
    """The agent host's ``poll_round`` (one look per round, the condition held by the host) against
    ``take_late`` + ``poll`` on a twin fed the same messages: the same late messages and ticks, and
    whenever it answers ``more=False``, ``poll`` finds no further tick (a round it skips would have
    taken nothing). Messages of a chaser's ticks in a seeded shuffled order (free-running, some lost), the
    consumer looking after each message."""
    rng = random.Random(seed)
    kept = 1.0 if grace is None else 0.9  # lockstep waits for every message: none is lost there
    msgs = []
    for k in range(1, 40):
        if rng.random() < kept:
            msgs.append(imu(k))
        if k % 2 == 0 and rng.random() < kept:
            msgs.append(uwb(k))
        if k % 4 == 0 and rng.random() < kept:
            msgs.append(vision(k))
        msgs.append(estimate(k - 1))
    for i in range(len(msgs) - 1):  # local shuffles: messages a few places from their publishing order
        if rng.random() < 0.3:
            msgs[i], msgs[i + 1] = msgs[i + 1], msgs[i]
    kw = dict(vision_every=4, wait_for_target=grace is None, late_ticks=late_ticks, max_ahead=8)
    twin, mine = chaser(**kw), chaser(**kw)
    taken_twin, taken_mine, late_twin, late_mine = [], [], [], []
    for m in msgs:
        src = "target" if isinstance(m, Estimate) else "chaser"
        assert twin.add(m, src) == mine.add(m, src)
        while True:  # the twin: take_late and poll until no tick comes
            late_twin.extend(twin.take_late())
            got = twin.poll(grace, now=1e9)[0]
            if got is None:
                break
            taken_twin.append(got.tick)
        more = True
        while more:  # mine: poll_round while it says a further tick may be ready
            with mine.cond:
                late, got, more = mine.poll_round(grace)
            late_mine.extend(late)
            if got is not None:
                taken_mine.append(got.tick)
            else:
                assert not more
        with mine.cond:
            assert mine.poll(grace, now=1e9)[0] is None  # more=False: nothing was left behind
    assert taken_mine == taken_twin and len(taken_mine) > 10
    assert [(type(m), m.tick) for m in late_mine] == [(type(m), m.tick) for m in late_twin]
    assert mine.counts() == twin.counts()


def test_poll_round_hands_over_late_messages_in_a_list_of_their_own():
    """A range kept after a round took the late ones must not appear in what that round already has."""
    asm = plain(uwb_every=2, wait_for_target=False, late_ticks=2)
    asm.add(imu(1))
    asm.add(imu(2))
    with asm.cond:
        assert asm.poll_round(0.0)[1].tick == 1
        late, got, more = asm.poll_round(0.0)
    assert got.tick == 2 and not more and list(late) == []
    asm.add(uwb(2))  # late: after its tick was taken
    assert list(late) == []  # the round's own (empty) list is not the assembler's
    with asm.cond:
        late, got, more = asm.poll_round(0.0)
    assert [m.tick for m in late] == [2] and got is None and not more


def test_a_shared_condition_and_ready_set_wake_one_waiter_for_any_vehicle():
    cond, ready = threading.Condition(), set()
    a = plain(uwb_every=2, cond=cond, ready=ready)
    b = AgentTickAssembler("chaser", True, "target", 2, start=1, cond=cond, ready=ready)
    got = []

    def host():  # the agent host's loop, reduced: wait, then poll the assemblers with news
        with cond:
            while not ready:
                cond.wait(LONG)
            got.extend(asm for asm in list(ready))
            ready.clear()

    t = threading.Thread(target=host)
    t.start()
    time.sleep(0.02)
    b.add(uwb(2))  # not news: the next tick (1) lacks its imu and estimate
    b.add(imu(1))  # an imu is news
    t.join(LONG)
    assert got == [b] and b.poll()[0] is None  # tick 1 still lacks the target's estimate(0)
    b.add(estimate(0))  # completes tick 1: news
    a.add(imu(1))  # the other vehicle's news goes to the same set
    assert ready == {a, b} and b.poll()[0].tick == 1 and a.poll()[0].tick == 1


def test_barrier_wakes_the_world_once_per_complete_tick():
    """The world's loop waits on the barrier: 32 commands per tick must not wake it 32 times (each wake takes
    the GIL from the callbacks still decoding commands), only the one that completes the tick."""
    bar = CommandBarrier(["a", "b", "c"])
    wakes = []

    class Counting(type(bar._cond)):
        def notify_all(self):
            wakes.append(1)
            super().notify_all()

    bar._cond = Counting()
    bar.add("a", command(0))
    bar.add("b", command(0))
    bar.add("a", command(1))  # a later tick, incomplete
    assert wakes == []
    bar.add("c", command(0))
    assert len(wakes) == 1
    cmds, missing = bar.wait(0, 0)
    assert set(cmds) == {"a", "b", "c"} and missing == []
    bar.add("b", command(1))
    bar.set_live({"a", "b"})  # c is lost: tick 1 is complete without it, and the change wakes the world
    assert len(wakes) == 2 and bar.poll(1, 0)
