"""The world's samples of a tick as the processes publish them (swarm.transport.wire.world_sensors):
for agent hosts, every vehicle's imu in one ImuBatch on world/imu, and every chaser's camera frame in one
VisionBatch on world/vision.

Oracle: the same tick encoded one message per vehicle (a process each, decoded by the Imu and Vision
codecs): each vehicle's row of a batch must be that message, field for field (a frame: byte for byte)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm.scenario import load_scenario
from swarm.step.radio import UwbNetwork
from swarm.step.world import World
from swarm.transport.messages import (
    MAX_BATCH,
    MAX_PAYLOAD_BYTES,
    DropCounter,
    Imu,
    ImuBatch,
    Truth,
    TruthBatch,
    Uwb,
    UwbBatch,
    Vision,
    VisionBatch,
    batch_rows,
    decode,
    encode,
    pack_entries,
)
from swarm.transport.wire import batch_samples, uwb_slot, uwb_slot_batch, world_sensors


def _tick(pairs: int, k_ahrs: bool, camera: bool = False):
    sc = load_scenario("docking").with_pairs(pairs)
    w = World(sc, 3)
    frames = w.step()
    if k_ahrs:  # step on to a tick with an AHRS output (10 Hz of the 100 Hz), so the batch carries attitudes
        while all(f.q_ahrs_nav_body is None for f in frames.values()):
            frames = w.step()
    if camera:  # ... or to a camera tick (20 Hz), so the chasers' frames are in the tick
        while w.k % w.vision_every:
            frames = w.step()
    return sc, w, frames


@pytest.mark.parametrize("k_ahrs", [False, True], ids=["gyro only", "with AHRS"])
def test_each_vehicles_row_of_the_batch_is_the_imu_it_would_have_had_alone(k_ahrs):
    sc, w, frames = _tick(3, k_ahrs)
    ids, chasers = list(sc.vehicles), list(sc.chasers)
    k = w.k
    alone = world_sensors(w, ids, chasers, k, frames, 1)
    batched = world_sensors(w, ids, chasers, k, frames, 1, batch=True)
    # the per-vehicle truths are the same, in the same order; the imu and frames leave their keys for batches
    assert [s for s in batched if s[0] not in ("imu_batch", "vision_batch")] == [
        s for s in alone if s[0] not in ("imu", "vision")
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
        sent = dict(batch_samples(batched, vid))  # what a rejoined agent is sent
        assert decode(sent["imu"], Imu) == own
    assert batch.sample("ghost") is None and batch_samples(batched, "ghost") == []


def test_a_world_of_processes_of_one_sends_its_mothership_the_truth_batch_and_its_viewers_their_own():
    """Agents a process each (no imu batch): the truths of a slot tick still leave as one batch for the
    mothership, a vehicle's own truth only for a viewer, and the imu and frames on each vehicle's keys."""
    sc, w, frames = _tick(3, False)
    ids, chasers = list(sc.vehicles), list(sc.chasers)
    k = w.k
    alone = world_sensors(w, ids, chasers, k, frames, 1)
    out = world_sensors(w, ids, chasers, k, frames, 1, viewed={"chaser1"})
    assert [kd for kd, _, _ in out if kd.endswith("batch")] == ["truth_batch"] and out[0][0] == "truth_batch"
    (truths,) = [decode(p, TruthBatch) for kd, _, p in out if kd == "truth_batch"]
    assert all(truths.sample(vid) == decode(p, Truth) for kd, vid, p in alone if kd == "truth")
    assert [v for kd, v, _ in out if kd == "truth"] == ["chaser1"]
    assert [s for s in out if s[0] in ("imu", "vision")] == [s for s in alone if s[0] in ("imu", "vision")]


def test_each_chasers_entry_of_the_vision_batch_is_the_frame_it_would_have_had_alone(monkeypatch):
    """A camera tick for agent hosts: the chasers' frames leave their keys for one VisionBatch, after the
    truths and before the imu batch (a host's tick is ready on its imu); each entry is the vehicle's own
    frame byte for byte, and a rejoined chaser is sent its frame and its imu on its own keys. A delayed
    chaser keeps its own key; a tick whose frames do not fit one message is split, none lost."""
    sc, w, frames = _tick(3, False, camera=True)
    ids, chasers = list(sc.vehicles), list(sc.chasers)
    k = w.k
    alone = world_sensors(w, ids, chasers, k, frames, 1)
    batched = world_sensors(w, ids, chasers, k, frames, 1, batch=True)
    own = {v: p for kd, v, p in alone if kd == "vision"}
    assert sorted(own) == sorted(chasers) and not [s for s in batched if s[0] in ("vision", "imu")]
    assert [kd for kd, _, _ in batched] == ["truth_batch", *["truth"] * len(ids), "vision_batch", "imu_batch"]
    batch = decode(next(p for kd, _, p in batched if kd == "vision_batch"), VisionBatch)
    assert batch.ids == tuple(chasers) and batch.tick == k and batch.t_s == k * sc.dt_s
    for vid in chasers:
        assert batch.frames[batch.index()[vid]] == own[vid]
        assert batch.sample(vid) == decode(own[vid], Vision)
        assert [kd for kd, _ in batch_samples(batched, vid)] == ["vision", "imu"]
        assert batch_samples(batched, vid)[0][1] == own[vid]
    assert [kd for kd, _ in batch_samples(batched, "target0")] == ["imu"]
    assert batch_rows(batch, "k", DropCounter(), {"chaser1"}) == [("chaser1", decode(own["chaser1"], Vision))]

    held = world_sensors(w, ids, chasers, k, frames, 1, batch=True, solo={"chaser1"})
    assert [(kd, v) for kd, v, _ in held if kd in ("vision", "imu")] == [
        ("vision", "chaser1"),
        ("imu", "chaser1"),
    ]
    solo_batch = decode(next(p for kd, _, p in held if kd == "vision_batch"), VisionBatch)
    assert solo_batch.ids == ("chaser0", "chaser2")

    limit = len(encode(batch)) - 1  # one byte short of the whole batch: two messages
    monkeypatch.setattr("swarm.transport.messages.MAX_PAYLOAD_BYTES", limit)
    seen = [(v, own[v]) for v in chasers]  # what world_sensors packs (its imu batch would not fit the limit)
    split = pack_entries(seen, lambda vids, blobs: VisionBatch(k, k * sc.dt_s, vids, blobs))
    assert len(split) == 2 and all(len(p) <= limit for p in split)
    parts = [decode(p, VisionBatch) for p in split]
    assert sum((b.ids for b in parts), ()) == tuple(chasers)
    assert sum((b.frames for b in parts), ()) == tuple(own[v] for v in chasers)
    assert (
        MAX_PAYLOAD_BYTES // len(own["chaser0"]) >= 128
    )  # the real cap: 128 chasers' frames are one message


def test_a_bad_frame_in_a_vision_batch_is_dropped_alone_and_named():
    """A receiver decodes the entries it takes: one that does not decode, or is of another tick, is dropped
    and counted under the batch's key naming the vehicle and the entry; the other vehicles' frames stay."""
    sc, w, _ = _tick(2, False, camera=True)
    good = encode(Vision(w.k, w.k * sc.dt_s, "target0", "+x", "features", np.zeros((0, 3)), ()))
    stale = encode(Vision(w.k - 1, (w.k - 1) * sc.dt_s, "target0", "+x", "features", np.zeros((0, 3)), ()))
    batch = VisionBatch(w.k, w.k * sc.dt_s, ("a", "b", "c"), (good, b"\x81\xa1v\x02", stale))
    drops = DropCounter()
    assert [v for v, _ in batch_rows(batch, "ns/world/vision", drops)] == ["a"]
    assert drops.count("ns/world/vision") == 2
    with pytest.raises(Exception, match=r"frames\[1\]: type: expected 'Vision'"):
        batch.sample("b")
    with pytest.raises(Exception, match=r"frames\[2\]: tick .* in the batch of tick"):
        batch.sample("c")


def test_a_vehicle_held_back_by_a_delay_keeps_its_own_imu_and_a_big_swarm_several_batches(monkeypatch):
    sc, w, frames = _tick(2, False)
    ids, chasers = list(sc.vehicles), list(sc.chasers)
    out = world_sensors(w, ids, chasers, w.k, frames, 1, batch=True, solo={"target1"})
    assert [v for kd, v, _ in out if kd == "imu"] == ["target1"]
    assert decode(out[-1][2], ImuBatch).ids == ("chaser0", "target0", "chaser1")
    monkeypatch.setattr("swarm.transport.wire.MAX_BATCH", 3)  # 4 vehicles: batches of 3 and 1
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


def test_on_a_tdma_channel_a_slot_sends_ranges_only_of_the_tags_whose_slot_came():
    """8 pairs on one TDMA channel (16 slots of 4.2 ms, a 67 ms frame, 50 Hz slot ticks): at each slot tick
    the mothership's ranges (alone and batched) are exactly the tags with an exchange, which each agent
    predicts from the scenario alone (``exchange_ticks``), and over a second each tag ranges once a frame."""
    from swarm.step.radio import exchange_ticks

    sc = load_scenario("docking", {"uwb.tdma": True}).with_pairs(8)
    ids = list(sc.vehicles)
    net = UwbNetwork(sc, 5)
    due = {vid: exchange_ticks(sc, vid) for vid in ids}
    X = np.zeros((len(ids), 13))
    X[:, 0:3] = np.random.default_rng(1).uniform(-1.0, 1.0, (len(ids), 3))
    X[:, 9] = 1.0
    sent = dict.fromkeys(ids, 0)
    ticks = range(net.every, round(1.0 / sc.dt_s) + 1, net.every)  # one second of slot ticks
    for k in ticks:
        t = k * sc.dt_s
        net.step(k, t, X)
        alone = [vid for vid, _ in uwb_slot(net, ids, k, t)]
        assert alone == [vid for vid in ids if due[vid](k)], k
        payload = uwb_slot_batch(net, ids, k, t)
        assert (payload is None) == (not alone)
        assert payload is None or list(decode(payload, UwbBatch).ids) == alone
        for vid in alone:
            sent[vid] += 1
    frame_s = 16 * sc.uwb.tdma_slot_s
    # each tag's slot comes once a frame (67.2 ms): 14 or 15 times in the second, against 50 slot ticks
    assert all(math.floor(1.0 / frame_s) <= n <= math.ceil(1.0 / frame_s) for n in sent.values()), sent
    assert exchange_ticks(load_scenario("docking").with_pairs(8), ids[0]) is None  # TDMA off: every tick


@pytest.mark.parametrize("per_process", [1, 2, 16])
def test_the_launcher_asks_world_and_mothership_for_batches_only_for_agent_hosts(per_process):
    """A host takes one world/imu and one mothership/uwb for all its vehicles (and the mothership one
    world/truth for all of them); a process of one vehicle
    would take every vehicle's entry to use one (measured: 10-15 % more agent CPU at 4 pairs with the imu
    batch, BENCHMARKS.md), so it keeps its own keys."""
    import argparse

    from swarm.cli.launch import mothership_args, world_args

    args = argparse.Namespace(clock="lockstep", step_timeout=5.0, start_timeout=180.0, checkpoint_dir="/x",
                              pace=None, vehicles_per_process=per_process, bundles=True)  # fmt: skip
    assert ("--batch" in world_args(args)) == (per_process > 1)
    assert "--no-bundles" not in world_args(args)
    assert "--no-bundles" in world_args(argparse.Namespace(**{**vars(args), "bundles": False}))
    assert mothership_args(args) == ["mothership", *(["--batch"] if per_process > 1 else [])]
