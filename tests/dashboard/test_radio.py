"""The radio's rates as the dashboard measures them (dashboard.radio, issue 45 item 5): the sliding windows
against hand-computed values, the anchors' and tags' rates of a TDoA swarm and a TWR one, the panel's text,
the store (a new run starts the windows again) and the link (every Tdoa counts, however it travels: its own
key, a mothership/tdoa batch, a lockstep bundle; two real sessions on loopback)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from dashboard.radio import CounterWindow, RadioRates, SlotWindow, radio_markdown
from dashboard.state import SwarmState
from swarm.transport.messages import Clock, Estimate, Tdoa

APPROX = 1e-12  # the rates are ratios of small integers and decimal times: equal to rounding


def _tdoa(t_s: float, senders: list[int], tick: int | None = None) -> Tdoa:
    """A slot whose rows came from ``senders`` (each row's partner: the anchor after it, mod 4)."""
    a = tuple((b + 1) % 4 for b in senders)
    k = round(100 * t_s) if tick is None else tick
    return Tdoa(k, t_s, a, tuple(senders), np.zeros(len(senders)))


def _estimate(t_s: float, accepted: int, rejected: int, refused: int = 0) -> Estimate:
    counts = {"range_accepted": accepted, "range_rejected": rejected, "range_refused": refused}
    counts = {k: v for k, v in counts.items() if v}  # the agents send only the non-zero counters
    return Estimate(
        tick=round(100 * t_s), t_s=t_s, p_nav=np.zeros(3), v_nav=np.zeros(3), q_nav_body=[0, 0, 0, 1],
        cov=np.eye(9) * 1e-4, sigma_pos_max_m=0.01, mahalanobis_d=0.5, rejection_fraction=0.0, counts=counts,
    )  # fmt: skip


# ------------------------------------------------------------------------------------------ windows


def test_slot_window_counts_the_rows_after_its_base_over_the_time_they_cover() -> None:
    w = SlotWindow(window_s=1.0)
    w.add(0.0, [1, 2])
    assert w.rates_hz() is None  # one slot: its rows were heard since a slot the window never saw
    w.add(0.5, [1])
    # base 0.0; after it: one row of anchor 1 in (0, 0.5]
    assert w.rates_hz() == pytest.approx({1: 2.0}, abs=APPROX)
    w.add(1.0, [1, 1, 2])
    # the window starts at 0.0 (1.0 - 1.0): base 0.0; rows after it: anchor 1 three, anchor 2 one, in 1 s
    assert w.rates_hz() == pytest.approx({1: 3.0, 2: 1.0}, abs=APPROX)
    w.add(1.5, [2])
    # starts at 0.5: base 0.5 (the 0.0 slot forgotten); after it: [1, 1, 2] and [2] over 1 s
    assert w.rates_hz() == pytest.approx({1: 2.0, 2: 2.0}, abs=APPROX)
    assert w.total_hz() == pytest.approx(4.0, abs=APPROX)
    w.add(1.7, [3])
    # starts at 0.7: the base is the newest slot at or before it, 0.5; after it 5 rows over 1.2 s
    assert w.span_s() == pytest.approx(1.2, abs=APPROX)
    assert w.rates_hz() == pytest.approx({1: 2 / 1.2, 2: 2 / 1.2, 3: 1 / 1.2}, abs=APPROX)
    # over another window: the rows of the slots in (t_a, t_b] (kept: the last 2 s, 2 x the window)
    assert w.rows_in(0.0, 1.0) == 4 and w.rows_in(0.2, 1.5) == 5 and w.rows_in(0.5, 1.7) == 5
    assert w.rows_in(0.0, 1.8) is None  # the slot of 1.8 has not come: its rows would be missing
    w.add(2.6, [])
    assert w.rows_in(0.4, 2.6) is None  # no slot kept at or before 0.4 (0.5 is the oldest)


def test_slot_window_at_a_steady_rate_reads_that_rate_and_restarts_when_time_goes_back() -> None:
    # a tag hearing anchor 0 twice and anchor 1 once every 20 ms slot: 100 and 50 rows a second
    w = SlotWindow(window_s=2.0)
    for k in range(500):
        w.add(0.02 * k, [0, 0, 1])
    assert w.span_s() == pytest.approx(2.0, abs=1e-9)
    assert w.rates_hz() == pytest.approx({0: 100.0, 1: 50.0}, abs=1e-6)
    w.add(0.5, [0])  # a new run (the time went back): nothing before it counts
    assert w.rates_hz() is None
    w.add(0.52, [])
    assert w.rates_hz() == {}  # a slot with no rows: zero for every anchor


def test_counter_window_divides_the_counters_increase_by_the_span() -> None:
    w = CounterWindow(window_s=1.0)
    w.add(0.0, (0, 0, 0))
    assert w.deltas() is None
    w.add(0.4, (10, 2, 0))
    w.add(1.0, (30, 5, 1))
    w.add(1.3, (40, 5, 1))
    # starts at 0.3: base 0.0 (the newest sample at or before it)
    assert w.deltas() == (0.0, 1.3, (40, 5, 1))
    w.add(2.0, (60, 10, 1))
    # starts at 1.0: base 1.0
    assert w.deltas() == (1.0, 2.0, (30, 5, 0))
    w.add(2.0, (61, 10, 1))  # the same time again: replaces the newest
    assert w.deltas() == (1.0, 2.0, (31, 5, 0))
    w.add(2.5, (3, 0, 0))  # a counter went down (the agent restarted): a new window
    assert w.deltas() is None


# ------------------------------------------------------------------------------------------ the rates


def test_tdoa_rates_per_anchor_are_the_best_tags_and_per_tag_the_filters_accepted_share() -> None:
    """Two tags over 1 s (slots every 0.1 s, window 1 s): tag a hears anchor 0 five times and anchor 1 once
    a slot, tag b anchor 0 three times; anchors 2 and 3 are silent. Tag a's filter accepted 300 and
    rejected 60 of them in that second, b's 30 and none."""
    r = RadioRates("tdoa3", window_s=1.0)
    for k in range(11):
        t = 0.1 * k
        r.on_tdoa("a", _tdoa(t, [0, 0, 0, 0, 0, 1]))
        r.on_tdoa("b", _tdoa(t, [0, 0, 0]))
    r.on_counts("a", 0.0, {"range_accepted": 1000, "range_rejected": 40})
    r.on_counts("a", 1.0, {"range_accepted": 1300, "range_rejected": 100})
    r.on_counts("b", 0.0, {})
    r.on_counts("b", 1.0, {"range_accepted": 30})
    snap = r.snapshot((0, 1, 2, 3))
    best = {a.anchor: (round(a.best_hz, 9), round(a.mean_hz, 9), a.tags) for a in snap.anchors}
    assert best == {0: (50.0, 40.0, 2), 1: (10.0, 5.0, 1), 2: (0.0, 0.0, 0), 3: (0.0, 0.0, 0)}
    tags = {t.tag: tuple(round(x, 9) for x in (t.heard_hz, t.accepted_hz, t.rejected_share))
            for t in snap.tags}  # fmt: skip
    assert tags == {"a": (60.0, 300.0, round(60 / 360, 9)), "b": (30.0, 30.0, 0.0)}
    text = radio_markdown(snap)
    assert "| 0 | 50.0 | 40.0 | 2 |" in text and "| 3 | 0.0 | 0.0 | 0 |" in text
    assert "| a | 60.0 | 300.0 | 17 % |" in text and "differences/s" in text


def test_a_tags_differences_are_counted_over_its_accepted_rates_window_when_the_slots_reach_it() -> None:
    """Slots every 0.1 s up to 2 s, ten rows each up to 1.0 s and five after; the estimates (sampled once a
    frame) at 0.5 and 1.5 s: the differences a second are those of (0.5, 1.5], 5 x 10 + 5 x 5 = 75 in 1 s,
    as the 75 accepted, not the slot window's (1.0, 2.0] (50/s). An estimate later than the newest slot (its
    rows not all here): the slot window's rate."""
    r = RadioRates("tdoa3", window_s=1.0)
    for k in range(21):
        r.on_tdoa("a", _tdoa(0.1 * k, [0] * (10 if k <= 10 else 5)))
    r.on_counts("a", 0.5, {"range_accepted": 100})
    r.on_counts("a", 1.5, {"range_accepted": 175})
    (tag,) = r.snapshot((0, 1, 2, 3)).tags
    assert (tag.heard_hz, tag.accepted_hz, tag.span_s) == pytest.approx((75.0, 75.0, 1.0), abs=1e-9)
    r.on_counts("a", 2.5, {"range_accepted": 225})  # window (1.5, 2.5]: 50 accepted a second
    (tag,) = r.snapshot((0, 1, 2, 3)).tags
    assert (tag.heard_hz, tag.accepted_hz, tag.span_s) == pytest.approx((50.0, 50.0, 1.0), abs=1e-9)


def test_twr_rates_are_each_tags_ranges_from_its_filters_counters() -> None:
    r = RadioRates("twr", window_s=2.0)
    r.on_counts("chaser", 1.0, {"range_accepted": 100, "range_rejected": 10, "range_refused": 2})
    r.on_counts("chaser", 3.0, {"range_accepted": 180, "range_rejected": 20, "range_refused": 2})
    r.on_counts("target", 1.0, {})
    snap = r.snapshot((0, 1, 2, 3))
    assert snap.anchors == ()
    (chaser, target) = snap.tags
    # 2 s: 80 accepted, 10 rejected, none refused -> 45 ranges/s, 40 accepted/s, 10/90 rejected
    assert (chaser.heard_hz, chaser.accepted_hz) == pytest.approx((45.0, 40.0), abs=1e-12)
    assert chaser.rejected_share == pytest.approx(1 / 9, abs=1e-12)
    assert (target.heard_hz, target.accepted_hz, target.rejected_share) == (None, None, None)
    text = radio_markdown(snap)
    assert "ranges/s" in text and "| chaser | 45.0 | 40.0 | 11 % |" in text and "packets/s" not in text


def test_a_tag_silent_for_longer_than_the_window_reads_as_not_measured() -> None:
    """A tag whose slots and estimates stopped at 1 s (its agent, or the radio, gone): at the world's 2.5 s
    its rates would read as current; they read as not measured once the clock is a window (1 s) past them."""
    r = RadioRates("tdoa3", window_s=1.0)
    for k in range(11):
        r.on_tdoa("a", _tdoa(0.1 * k, [0]))
    r.on_counts("a", 0.0, {})
    r.on_counts("a", 1.0, {"range_accepted": 10})
    (tag,) = r.snapshot((0, 1), now_s=2.0).tags  # 1 s behind the clock: still the window's
    assert (tag.heard_hz, tag.accepted_hz) == pytest.approx((10.0, 10.0))
    snap = r.snapshot((0, 1), now_s=2.5)
    assert snap.anchors == () and (snap.tags[0].heard_hz, snap.tags[0].accepted_hz) == (None, None)


def test_a_tdoa_panel_before_any_slot_says_so_instead_of_zero_rates() -> None:
    snap = RadioRates("tdoa2").snapshot((0, 1))
    assert snap.anchors == () and "no distance differences yet" in radio_markdown(snap)
    assert radio_markdown(None) == "no radio rates yet"


# ------------------------------------------------------------------------------------------ the store


def test_the_store_takes_every_tdoa_and_a_new_run_starts_the_windows_again() -> None:
    vehicles = {"chaser": ("chaser", "target"), "target": ("target", None)}
    state = SwarmState(vehicles, np.zeros((4, 3)), uwb_mode="tdoa3", rate_window_s=1.0)
    state.on_clock(Clock(tick=0, t_s=0.0, state="running", seed=1))
    for k in range(11):
        state.on_message("tdoa", "chaser", _tdoa(0.1 * k, [2, 2]))
    state.on_message("estimate", "chaser", _estimate(0.0, 0, 0))
    state.on_message("estimate", "chaser", _estimate(1.0, 15, 5))
    assert state.snapshot().radio is None  # only a panel frame asks for the rates
    snap = state.snapshot(radio=True).radio
    assert snap is not None and snap.anchor_hz() == pytest.approx({0: 0.0, 1: 0.0, 2: 20.0, 3: 0.0})
    chaser = next(t for t in snap.tags if t.tag == "chaser")
    assert (chaser.heard_hz, chaser.accepted_hz, chaser.rejected_share) == pytest.approx((20.0, 15.0, 0.25))
    assert state.on_clock(Clock(tick=0, t_s=0.0, state="running", seed=2))  # a new seed: a new run
    snap = state.snapshot(radio=True).radio
    assert snap.anchors == () and all(t.heard_hz is None and t.accepted_hz is None for t in snap.tags)


# ------------------------------------------------------------------------------------------ the link


def test_every_tdoa_reaches_the_store_from_its_key_a_batch_and_a_bundle() -> None:
    """The three ways a tag's slot travels (docs/protocol.md): ``agent/<id>/tdoa`` (a free-running
    mothership), ``mothership/tdoa`` (agent hosts), a lockstep bundle's ``Tdoa`` entries (beside the world's
    imu). Five slots of 0.1 s, each sent once, reach the store as five: anchor 1 heard at 10/s per tag over
    0.4 s (a slot lost, or counted twice, changes the rate)."""
    from dashboard.link import SwarmLink
    from swarm.transport.keys import Keys
    from swarm.transport.messages import Bundle, DropCounter, Imu, TdoaBatch, encode
    from swarm.transport.session import ZenohArgs, open_session
    from tests.transport.procs import free_port, loopback

    keys = Keys(f"radio{free_port()}")
    ids = ("c1", "c2", "c3")
    state = SwarmState({v: ("chaser", None) for v in ids}, np.zeros((4, 3)), uwb_mode="tdoa3")
    drops = DropCounter()
    endpoint = loopback(free_port())
    with open_session(ZenohArgs(mode="peer", listen=(endpoint,))) as session:
        link = SwarmLink(session, keys, state, drops, anchors_retry_s=0.05, tdoa=True)
        try:
            with open_session(ZenohArgs(mode="peer", connect=(endpoint,))) as other:
                pubs = {
                    "tdoa": other.declare_publisher(keys.tdoa("c1")),
                    "batch": other.declare_publisher(keys.mothership_tdoa()),
                    "bundle": other.declare_publisher(keys.bundle("c3")),
                }
                deadline = time.monotonic() + 10.0
                while not all(p.matching_status.matching for p in pubs.values()):
                    assert time.monotonic() < deadline, "the link's subscribers never matched"
                    time.sleep(0.01)
                for k in range(5):
                    t, slot = 0.1 * k, _tdoa(0.1 * k, [1], tick=10 * k)
                    pubs["tdoa"].put(encode(slot))
                    pubs["batch"].put(encode(TdoaBatch(10 * k, t, ("c2",), (encode(slot),))))
                    imu = Imu(10 * k, t, 0.01, np.zeros(3))
                    pubs["bundle"].put(encode(Bundle(10 * k, ("Imu",), (encode(imu),))))  # the world's
                    pubs["bundle"].put(encode(Bundle(10 * k, ("Tdoa",), (encode(slot),))))  # the mothership's

                def rates() -> dict:
                    snap = state.snapshot(radio=True).radio
                    return {t.tag: (t.heard_hz, t.span_s) for t in snap.tags}

                while {k: v[1] for k, v in rates().items()} != pytest.approx(dict.fromkeys(ids, 0.4)):
                    assert time.monotonic() < deadline, f"slots missing: {rates()}"
                    time.sleep(0.01)
                assert {k: v[0] for k, v in rates().items()} == pytest.approx(dict.fromkeys(ids, 10.0))
        finally:
            link.close()
    assert drops.total == 0
