"""Many UWB tags on one channel: the Loco Positioning TWR-TDMA model of :mod:`swarm.step.radio`.

Oracle: the slot arithmetic, written here independently of the kernel: tag ``v``'s exchanges start
at ``(m * F + slot_v) * slot_s`` (``m = 0, 1, ...``), a UWB tick at ``t`` reports the tag when one of them
lies in ``(t - period, t]`` (one range per tick at most), tags with the same slot collide. So the per-tag
rate is ``min(1 / period, 1 / (F * slot_s))``: ~238/N Hz for N tags once below the 50 Hz of the UWB tick.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm.core.sensors import UwbParams, UwbRadio
from swarm.errors import ConfigError
from swarm.scenario import load_scenario
from swarm.sim.docking import run_docking
from swarm.step.radio import UwbNetwork, tdma_slots, uwb_tick

ANCHORS = np.array([[1.0, -0.2, 0.5], [1.0, 0.2, -0.5], [-1.0, 0.2, -0.5], [-1.0, -0.2, 0.5]])
SLOT_S = 0.0042
PERIOD_S = 0.02  # the docking scenario's UWB tick: 50 Hz
DURATION_S = 20.0


def _run(slots: np.ndarray, frame: int, duration_s: float = DURATION_S):
    """The kernel over ``duration_s`` of UWB ticks for tags of the given ``slots``: (reported ranges per
    tag, collisions per tag, anchors ranged per tag)."""
    n = len(slots)
    X = np.zeros((n, 13))
    X[:, 9] = 1.0
    X[:, 0:3] = [0.1, 0.2, 0.3]
    prm = UwbRadio(ANCHORS, UwbParams()).vector
    ticks = round(duration_s / PERIOD_S)
    noise = np.zeros((n, ticks + 2, 4))
    arrays = dict(
        next_anchor=np.zeros(n, dtype=np.int64), ui=np.zeros(1, dtype=np.int64),
        env_lost=np.zeros(n, dtype=np.bool_), env_p=np.zeros(n), lost=np.zeros(n, dtype=np.bool_),
        anchor_id=np.zeros(n, dtype=np.int64), range_m=np.zeros(n), outlier=np.zeros(n, dtype=np.bool_),
        idle=np.zeros(n, dtype=np.bool_), collided=np.zeros(n, dtype=np.bool_),
        collisions=np.zeros(n, dtype=np.int64),
    )  # fmt: skip
    a = arrays
    tdma_prm = np.array([SLOT_S, float(frame), PERIOD_S])
    got = np.zeros(n, dtype=int)
    anchors_seen = [[] for _ in range(n)]
    slots = np.asarray(slots, dtype=np.int64)
    for j in range(ticks + 1):
        uwb_tick(j * PERIOD_S, X, np.zeros((n, 3)), ANCHORS, np.zeros(4), prm, a["next_anchor"], noise,
                 a["ui"], a["env_lost"], a["env_p"], a["lost"], a["anchor_id"], a["range_m"], a["outlier"],
                 slots, tdma_prm, a["idle"], a["collided"], a["collisions"])  # fmt: skip
        for v in range(n):
            if not a["lost"][v]:
                got[v] += 1
                anchors_seen[v].append(int(a["anchor_id"][v]))
    return got, a["collisions"].copy(), anchors_seen


def _expected(slot: int, frame: int, duration_s: float = DURATION_S) -> int:
    """Ticks ``j * period`` (j = 0 .. J) with a slot start of the tag in ``(t - period, t]``."""
    ticks = round(duration_s / PERIOD_S)
    periods = set()
    m = 0
    while (start := (m * frame + slot) * SLOT_S) <= ticks * PERIOD_S + 1e-12:
        periods.add(math.ceil(start / PERIOD_S - 1e-9))  # the period (t - P, t] that holds it
        m += 1
    return len(periods)


@pytest.mark.parametrize("tags", [1, 2, 4, 8, 16])
def test_each_tag_ranges_at_the_rate_the_slot_arithmetic_gives(tags):
    frame = 1 << max(0, (tags - 1).bit_length())
    got, collisions, anchors_seen = _run(np.arange(tags), frame)
    want = [_expected(s, frame) for s in range(tags)]
    assert got.tolist() == want
    assert collisions.tolist() == [0] * tags  # one slot each
    rate = got / DURATION_S
    nominal = min(1.0 / PERIOD_S, 1.0 / (frame * SLOT_S))  # 50, 50, 50, 29.8, 14.9 Hz
    assert np.all(np.abs(rate - nominal) <= 1.0 / DURATION_S + 1e-9), (rate, nominal)
    if tags >= 8:  # below the tick rate: ~238/N ranges per second, as the Loco Positioning TDMA gives
        assert np.allclose(rate, 1.0 / (tags * SLOT_S), atol=0.1)
    for seen in anchors_seen:  # each exchange with the next anchor, round robin over the four
        assert seen[:8] == [0, 1, 2, 3, 0, 1, 2, 3][: len(seen[:8])]


def test_tags_sharing_a_slot_collide_and_are_counted():
    # addresses 0, 4 and 1 in a frame of 4: the first two share slot 0, the third has slot 1 alone
    got, collisions, _ = _run(np.array([0, 0, 1]), 4)
    assert got[0] == 0 and got[1] == 0  # every exchange of theirs collided
    assert got[2] == _expected(1, 4)
    assert collisions[0] == collisions[1] == _expected(0, 4) > 0
    assert collisions[2] == 0


def test_the_scenario_gives_each_tag_its_slot_and_off_is_todays_radio():
    sc = load_scenario("docking", {"uwb.tdma": True}).with_pairs(4)  # 8 tags
    slots, frame = tdma_slots(sc)
    assert frame == 8 and sorted(slots.tolist()) == list(range(8))
    off, _ = tdma_slots(load_scenario("docking").with_pairs(4))
    assert off.tolist() == [-1] * 8
    sc2 = load_scenario("docking", {"uwb.tdma": True, "uwb.tdma_frame_slots": 2,
                                    "vehicles.chaser.uwb_address": 5})  # fmt: skip
    slots2, frame2 = tdma_slots(sc2)
    assert frame2 == 2 and slots2.tolist() == [1, 1]  # 5 % 2 and the target's index 1: they collide
    net = UwbNetwork(sc2, 0)
    X = np.zeros((2, 13))
    X[:, 9] = 1.0
    out = [net.step(k, k * sc2.dt_s, X) for k in range(0, 400, net.every)]
    assert not any(out) and net.collisions.tolist() == [net.collisions[0]] * 2 and net.collisions[0] > 50


@pytest.mark.parametrize(
    ("overrides", "field"),
    [({"uwb.tdma_frame_slots": 3}, "uwb.tdma_frame_slots must be 0 or a power of two"),
     ({"uwb.tdma_slot_s": 0.0}, "tdma_slot_s"),
     ({"vehicles.chaser.uwb_address": -1}, "uwb_address must be an integer in 0..65535, got -1")],
)  # fmt: skip
def test_bad_tdma_settings_are_refused_naming_the_field(overrides, field):
    with pytest.raises(ConfigError, match=field):
        load_scenario("docking", overrides)


def test_four_pairs_on_one_channel_dock_with_fewer_ranges_each():
    """``swarm sim`` of four pairs (8 tags, a frame of 8 slots: 29.8 ranges/s per tag instead of 50):
    every chaser docks, each fuses about 29.8/50 of the ranges of the same run without TDMA (the filter's
    gate rejects a few either way: +-10 % covers it)."""
    base = load_scenario("docking").with_pairs(4)
    shared = load_scenario("docking", {"uwb.tdma": True}).with_pairs(4)
    a = run_docking(base, "fixed", 3, record_series=False)["chasers"]
    b = run_docking(shared, "fixed", 3, record_series=False)["chasers"]
    for cid in a:
        assert b[cid]["docked"] and not b[cid]["keepout_violated"], (cid, b[cid]["final_mode"])
        ratio = b[cid]["estimator"]["accepted_ranges"] / a[cid]["estimator"]["accepted_ranges"]
        assert abs(ratio - (1 / (8 * SLOT_S)) / 50.0) < 0.1 * 0.595, (cid, ratio)
        print(f"{cid}: {ratio:.3f} of the ranges without TDMA (slot arithmetic: {1 / (8 * SLOT_S) / 50:.3f})")
