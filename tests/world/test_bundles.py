"""A lockstep world's bundles (docs/protocol.md, "Bundles"): the samples of the ticks up to the next one an
agent commands on leave as one message per receiver, once that tick is stepped, and nothing before it.

Oracle: the same world's samples published one by one (``world_sensors``, what a world without bundles
puts on each key at each tick): every bundle's entries are those bytes, in tick and publishing order, for
its receiver alone; and the checkpoint is written before each bundle leaves, not at every tick.
"""

from __future__ import annotations

import threading
import time

import pytest

from swarm.scenario import load_scenario
from swarm.transport.keys import Keys
from swarm.transport.messages import Bundle, DropCounter, TruthBatch, bundle_messages, decode
from swarm.transport.process import ClockSpec, clock_arg
from swarm.world.process import WorldProcess


class _Pub:
    def __init__(self, log: list, name: str) -> None:
        self.log, self.name = log, name

    def put(self, payload: bytes) -> None:
        self.log.append((self.name, payload))


def _world(sc, tmp_path, bundles: bool, clock: ClockSpec | None = None) -> tuple[WorldProcess, list]:
    wp = WorldProcess(sc, 2, None, Keys("bun"), clock or ClockSpec(), threading.Event(),
                      checkpoint_dir=tmp_path, bundles=bundles)  # fmt: skip
    log: list = []
    wp.pub_bundle = {v: _Pub(log, f"bundle/{v}") for v in [*wp.ids, ""]}
    kinds = ("truth", "vision", "imu", "imu_batch", "vision_batch", "truth_batch")
    wp._pubs = {kind: {v: _Pub(log, f"{kind}/{v}") for v in [*wp.ids, ""]} for kind in kinds}
    return wp, log


def _run(wp: WorldProcess, ticks: int) -> list[list[tuple[str, str, bytes]]]:
    """``ticks`` ticks as the run loop steps them (no commands: the nozzles stay closed); each tick's
    samples, as ``world_sensors`` encoded them."""
    out = []
    for _ in range(ticks):
        frames = wp.world.step()
        wp._new_tick(wp.world.k, frames)
        if not wp.bundles:
            wp._checkpoint()
        wp._publish_tick(wp.world.k, wp._sensors)
        if wp.pace is not None:  # due now: what _pace_to sends halfway (free-running: the truths) at once
            wp._pace_to(wp.world.k, time.monotonic())
        out.append(list(wp._sensors))
    return out


@pytest.fixture(scope="module")
def sc():
    return load_scenario("docking")


def test_a_control_periods_samples_leave_as_one_bundle_per_receiver_at_its_control_tick(sc, tmp_path):
    wp, log = _world(sc, tmp_path, bundles=True)
    assert wp.bundles
    every = sc.control_every("chaser")
    samples = _run(wp, every - 1)
    assert log == [] and wp.ckpt_n == 0  # no agent is due before tick 10: nothing left, nothing written
    samples += _run(wp, 1)
    assert wp.ckpt_n == 1  # written once, before the bundles
    names = [name for name, _ in log]
    assert sorted(names) == sorted(["bundle/chaser", "bundle/target", "bundle/"])
    by = {name: decode(p, Bundle) for name, p in log}
    drops = DropCounter()
    for vid in ("chaser", "target"):
        want = [p for tick in samples for kind, v, p in tick if v == vid and kind in ("imu", "vision")]
        b = by[f"bundle/{vid}"]
        assert list(b.entries) == want and b.tick == every
        got = bundle_messages(b, "k", drops)
        assert [m.tick for m in got if type(m).__name__ == "Imu"] == list(range(1, every + 1))
    truths = [p for tick in samples for kind, _, p in tick if kind == "truth_batch"]
    assert list(by["bundle/"].entries) == truths and set(by["bundle/"].types) == {"TruthBatch"}
    assert [decode(p, TruthBatch).tick for p in truths] == list(range(2, every + 1, 2))
    assert drops.total == 0
    log.clear()
    _run(wp, every)  # the next period: its own bundles, its ticks only
    assert sorted(decode(p, Bundle).tick for _, p in log) == [2 * every] * 3
    assert wp.ckpt_n == 2


def test_the_pending_ticks_leave_before_a_pause_a_wait_for_a_lost_agent_and_the_end(sc, tmp_path):
    wp, log = _world(sc, tmp_path, bundles=True)
    _run(wp, 3)
    assert log == []
    wp._flush_bundles(checkpoint_first=False)  # as the end of the run does
    assert len(log) == 3 and wp.ckpt_n == 0
    ticks = {name: decode(p, Bundle).tick for name, p in log}
    assert ticks == {"bundle/chaser": 3, "bundle/target": 3, "bundle/": 2}  # (the truths: UWB slots only)
    log.clear()
    wp._flush_bundles()  # nothing pending: nothing sent
    assert log == []
    with wp._lock:
        wp._awaited.add("chaser")
    _run(wp, 2)
    wp.stop.set()  # (the wait for the lost agent returns at once)
    wp._await_lost()
    assert len(log) == 3 and wp.ckpt_n == 1  # sent, after the checkpoint of the current tick


@pytest.mark.parametrize("how", ["no bundles", "free-running", "paced"])
def test_without_bundles_each_sample_leaves_at_its_tick(sc, tmp_path, how):
    clock = clock_arg("realtime") if how == "free-running" else None
    wp, log = _world(sc, tmp_path, bundles=how != "no bundles", clock=clock)
    if how == "paced":
        wp, log = _world(sc, tmp_path, bundles=True)
        wp.pace, wp.bundles = clock_arg("realtime"), False  # as WorldProcess(pace=...) decides
    assert not wp.bundles
    samples = _run(wp, 4)
    # free-running (agents a process each) the truths leave after the tick's other samples, halfway to the
    # next tick (tests/world/test_pacing.py); lockstep, paced or not, they lead it
    last = how == "free-running"
    order = [sorted(tick, key=lambda s: last and s[0].startswith("truth")) for tick in samples]
    assert [p for _, p in log] == [p for tick in order for _, _, p in tick]
    assert not any(name.startswith("bundle/") for name, _ in log)
