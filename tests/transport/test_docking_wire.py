"""The world's samples of a tick as the processes publish them (swarm.transport.docking_wire.world_sensors):
for agent hosts, every vehicle's imu in one ImuBatch on world/imu.

Oracle: the same tick encoded one message per vehicle (a process each, decoded by the Imu codec):
each vehicle's row of the batch must be that message, field for field."""

from __future__ import annotations

import pytest

from swarm.scenario import load_scenario
from swarm.step.world import World
from swarm.transport.docking_wire import batch_sample, world_sensors
from swarm.transport.messages import MAX_BATCH, Imu, ImuBatch, decode


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
    # the truths and frames are the same, in the same order; the imu leave the per-vehicle keys for one batch
    assert [s for s in batched if s[0] != "imu_batch"] == [s for s in alone if s[0] != "imu"]
    ((_kind, vid, payload),) = [s for s in batched if s[0] == "imu_batch"]
    assert batched[-1][0] == "imu_batch" and vid == ""  # after every frame of the tick
    batch = decode(payload, ImuBatch)
    assert batch.ids == tuple(ids) and batch.tick == k
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


@pytest.mark.parametrize("per_process", [1, 2, 16])
def test_the_launcher_asks_the_world_for_batches_only_for_agent_hosts(per_process):
    """A host takes one world/imu for all its vehicles; a process of one vehicle would take every vehicle's
    row to use one (measured: 10-15 % more agent CPU at 4 pairs, BENCHMARKS.md), so it keeps its own key."""
    import argparse

    from swarm.cli.launch import world_args

    args = argparse.Namespace(clock="lockstep", step_timeout=5.0, start_timeout=180.0, checkpoint_dir="/x",
                              pace=None, vehicles_per_process=per_process)  # fmt: skip
    assert ("--batch-imu" in world_args(args)) == (per_process > 1)
