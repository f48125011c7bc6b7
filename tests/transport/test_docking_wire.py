"""The world's samples of a tick as the processes publish them (swarm.transport.docking_wire.world_sensors):
for agent hosts, every vehicle's imu in one ImuBatch on world/imu.

Oracle: the same tick encoded one message per vehicle (a process each, decoded by the Imu codec):
each vehicle's row of the batch must be that message, field for field."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.scenario import load_scenario
from swarm.step.radio import UwbNetwork
from swarm.step.world import World
from swarm.transport.docking_wire import batch_sample, uwb_slot, uwb_slot_batch, world_sensors
from swarm.transport.messages import MAX_BATCH, Imu, ImuBatch, Truth, TruthBatch, Uwb, UwbBatch, decode


def _tick(pairs: int, k_ahrs: bool):
    sc = load_scenario("docking").with_pairs(pairs)
    w = World(sc, 3)
    frames = w.step()
    if k_ahrs:  # step on to a tick with an AHRS output (10 Hz of the 100 Hz), so the batch carries attitudes
        while all(f.q_ahrs_nav_body is None for f in frames.values()):
            frames = w.step()
    return sc, w, frames


@pytest.mark.parametrize("k_ahrs", [False, True], ids=["gyro only", "with AHRS"])
def test_each_vehicles_row_of_the_batch_is_the_imu_it_would_have_had_alone(k_ahrs):
    sc, w, frames = _tick(3, k_ahrs)
    ids, chasers = list(sc.vehicles), list(sc.chasers)
    k = w.k
    alone = world_sensors(w, ids, chasers, k, frames, 1)
    batched = world_sensors(w, ids, chasers, k, frames, 1, batch=True)
    # the per-vehicle truths and frames are the same, in the same order; the imu leave their keys for a batch
    assert [s for s in batched if s[0] not in ("imu_batch", "truth_batch")] == [
        s for s in alone if s[0] != "imu"
    ]
    ((_kind, vid, payload),) = [s for s in batched if s[0] == "imu_batch"]
    assert batched[-1][0] == "imu_batch" and vid == ""  # after every frame of the tick
    batch = decode(payload, ImuBatch)
    assert batch.ids == tuple(ids) and batch.tick == k
    # every tick here is a truth tick (truth_every 1): the truths lead, in a batch for the mothership, and
    # each vehicle's own only for a viewer (viewed); every row of the batch is that vehicle's own truth
    (truths,) = [decode(p, TruthBatch) for kd, _, p in batched if kd == "truth_batch"]
    assert batched[0][0] == "truth_batch" and truths.ids == tuple(ids)
    for vid in ids:
        own = decode(next(p for kd, v, p in alone if kd == "truth" and v == vid), Truth)
        assert truths.sample(vid) == own
    seen = world_sensors(w, ids, chasers, k, frames, 1, batch=True, viewed={"target1"})
    assert [v for kd, v, _ in seen if kd == "truth"] == ["target1"]
    assert [s for s in seen if s[0] != "truth"] == [s for s in batched if s[0] != "truth"]
    assert (len(batch.ahrs_ids) > 0) == k_ahrs
    for vid, row in batch.index().items():
        own = decode(next(p for kd, v, p in alone if kd == "imu" and v == vid), Imu)
        assert batch.sample(vid, row) == own == batch.sample(vid)
        assert decode(batch_sample(batched, vid), Imu) == own  # what a rejoined agent is sent
    assert batch.sample("ghost") is None and batch_sample(batched, "ghost") is None


def test_a_vehicle_held_back_by_a_delay_keeps_its_own_imu_and_a_big_swarm_several_batches(monkeypatch):
    sc, w, frames = _tick(2, False)
    ids, chasers = list(sc.vehicles), list(sc.chasers)
    out = world_sensors(w, ids, chasers, w.k, frames, 1, batch=True, solo={"target1"})
    assert [v for kd, v, _ in out if kd == "imu"] == ["target1"]
    assert decode(out[-1][2], ImuBatch).ids == ("chaser0", "target0", "chaser1")
    monkeypatch.setattr("swarm.transport.docking_wire.MAX_BATCH", 3)  # 4 vehicles: batches of 3 and 1
    out = world_sensors(w, ids, chasers, w.k, frames, 1, batch=True)
    assert [decode(p, ImuBatch).ids for kd, _, p in out if kd == "imu_batch"] == [tuple(ids[:3]), (ids[3],)]
    assert MAX_BATCH >= 128  # the real cap: the 128-vehicle swarm's imu are one message


def test_each_vehicles_entry_of_a_slots_batch_is_the_range_it_would_have_had_alone():
    """The mothership's slot for agent hosts (``--batch``): one UwbBatch, whose entry for each vehicle
    is the Uwb of its own key, lost replies (nil ranges) included."""
    sc = load_scenario("docking").with_pairs(3)
    ids = list(sc.vehicles)
    net = UwbNetwork(sc, 5)
    X = np.zeros((len(ids), 13))
    X[:, 0:3] = np.random.default_rng(1).uniform(-1.0, 1.0, (len(ids), 3))
    X[:, 9] = 1.0
    lost = np.zeros(len(ids), dtype=np.bool_)
    lost[1] = True  # the radio environment loses vehicle 1's reply
    net.step(net.every, net.every * sc.dt_s, X, lost)
    k, t = net.every, net.every * sc.dt_s
    batch = decode(uwb_slot_batch(net, ids, k, t), UwbBatch)
    alone = {vid: decode(p, Uwb) for vid, p in uwb_slot(net, ids, k, t)}
    assert batch.ids == tuple(ids) and batch.range_m[1] is None
    assert {vid: batch.sample(vid) for vid in ids} == alone
    assert batch.sample("ghost") is None


@pytest.mark.parametrize("per_process", [1, 2, 16])
def test_the_launcher_asks_world_and_mothership_for_batches_only_for_agent_hosts(per_process):
    """A host takes one world/imu and one mothership/uwb for all its vehicles (and the mothership one
    world/truth for all of them); a process of one vehicle
    would take every vehicle's entry to use one (measured: 10-15 % more agent CPU at 4 pairs with the imu
    batch, BENCHMARKS.md), so it keeps its own keys."""
    import argparse

    from swarm.cli.launch import mothership_args, world_args

    args = argparse.Namespace(clock="lockstep", step_timeout=5.0, start_timeout=180.0, checkpoint_dir="/x",
                              pace=None, vehicles_per_process=per_process)  # fmt: skip
    assert ("--batch" in world_args(args)) == (per_process > 1)
    assert mothership_args(args) == ["mothership", *(["--batch"] if per_process > 1 else [])]
