"""The Loco Positioning TDoA radio (:mod:`swarm.core.tdoa_radio`): simulated counts against the closed forms,
the tag engine's rules (context limit, matching, wrap), TDoA2's slots, the errors of a difference.

Oracles: the closed forms of the module (exact for the rates and collisions of the model; the measurement
rate is an approximation, checked within the margin its docstring states), the firmware's constants, and the
TWR-TDMA slot arithmetic of :mod:`swarm.step.radio`. Every simulation is seeded and a few seconds long.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm.core import tdoa_radio as tr
from swarm.errors import ConfigError
from swarm.step.radio import tdma_has_slot

ROOM = np.array(
    [[x, y, z] for z in (0.2, 2.8) for x, y in ((-4.0, -3.0), (4.0, -3.0), (4.0, 3.0), (-4.0, 3.0))]
)
"""Eight anchors in the corners of an 8 x 6 x 3 m room."""
TAG = np.array([0.5, -0.3, 1.2])


def _room(n: int) -> np.ndarray:
    """``n`` anchors on a 10 x 10 m grid at two heights (all in range of each other)."""
    rng = np.random.default_rng(5)
    return np.column_stack([rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), rng.choice([0.2, 2.8], n)])


def test_airtime_is_the_dw1000_frame_time_of_a_full_tdoa3_packet():
    # 108 bytes = 864 bits + 3 Reed-Solomon blocks of 48 = 1008 data bits at 128.21 ns; SHR 136 symbols at
    # 1017.63 ns; PHR 21 bits at 1025.64 ns: 138.398 + 21.538 + 129.236 us
    assert tr.TDOA3_FRAME_BYTES == 108
    assert tr.AIRTIME_S == pytest.approx(289.17e-6, abs=0.02e-6)
    # 850 kbps: the same header, 1008 bits at 1025.64 ns
    assert tr.AIRTIME_LONG_RANGE_S == pytest.approx(138.398e-6 + 21.538e-6 + 1008 * 1025.64e-9, rel=1e-6)
    assert tr.WRAP_S == pytest.approx(0.067216, abs=1e-6)  # 2^32 ticks of 63.8976 GHz
    assert tr.TDOA2_SLOT_S == pytest.approx(2.1005e-3, abs=1e-7)  # 2^27 ticks


@pytest.mark.parametrize(
    ("n", "long_range", "rate"),
    [
        (4, False, 50.0),
        (8, False, 50.0),
        (16, False, 25.0),
        (32, False, 20.0),
        (8, True, 25.0),
        (4, True, 50.0),
    ],
)
def test_anchor_rate_is_the_system_rate_shared_within_20_to_50_hz(n, long_range, rate):
    f = tr.anchor_rates_hz(tr.TdoaParams(long_range=long_range), n)
    assert f == pytest.approx(np.full(n, rate))


def test_closed_form_collisions_tend_to_pure_aloha_for_many_slow_anchors():
    # 200 anchors at 20 Hz (the clamp): sum_j 2 T f_j small each, so prod(1 - x) -> exp(-sum x) = exp(-2 G)
    e = tr.expected_rates(tr.TdoaParams(system_rate_hz=4000.0, anchor_min_rate_hz=1.0), 200)
    assert e.collision_share == pytest.approx(e.aloha_collision, rel=0.01)
    e8 = tr.expected_rates(tr.TdoaParams(), 8)
    assert e8.offered_load == pytest.approx(400 * tr.AIRTIME_S)
    assert e8.collision_share == pytest.approx(1.0 - (1.0 - 2 * tr.AIRTIME_S * 50.0) ** 7)


@pytest.mark.parametrize("n_tags", [1, 8, 64])
def test_simulated_counts_equal_the_closed_form_for_any_number_of_tags(n_tags):
    p = tr.TdoaParams(tag_loss=0.05)
    D = 30.0
    radio = tr.TdoaRadio(p, ROOM, n_tags, D, seed=11)
    radio.step(D, np.tile(TAG, (n_tags, 1)))
    e = tr.expected_rates(p, 8)
    sent, lost = radio.channel.counts(0.0, D, 8)
    # per anchor: a renewal count; its variance is ~ f D CV^2, CV = (w / sqrt 12) f = 0.144 -> sd ~ 5.6
    sd_anchor = math.sqrt(50.0 * D * (p.jitter_s / math.sqrt(12) * 50.0) ** 2 + 1.0)
    assert np.all(np.abs(sent - e.per_anchor_hz * D) <= 5 * sd_anchor)
    # collisions: Bernoulli(1 - s) per packet, in pairs, so twice the binomial variance; 4 sd
    K = sent.sum()
    sd_col = math.sqrt(2 * K * e.collision_share * (1 - e.collision_share))
    assert abs(lost.sum() - K * e.collision_share) <= 4 * sd_col
    # each tag: binomial(survivors, 1 - loss) around the closed form (the survivors' own spread added)
    rx = radio.counts["received"]
    sd_rx = math.sqrt(K * e.received_per_tag_hz / e.total_hz * (1 + p.tag_loss)) + sd_col
    assert np.all(np.abs(rx - e.received_per_tag_hz * D) <= 4 * sd_rx)
    # the anchors' packets do not depend on the number of tags (tags never transmit)
    ref = tr.TdoaRadio(p, ROOM, 1, D, seed=11).channel
    assert np.array_equal(ref.t_s, radio.channel.t_s) and np.array_equal(ref.ok, radio.channel.ok)


@pytest.mark.parametrize("loss", [0.0, 0.1])
def test_measurement_rate_is_the_approximate_closed_form(loss):
    p = tr.TdoaParams(tag_loss=loss, anchor_loss=loss)
    radio = tr.TdoaRadio(p, ROOM, 4, 30.0, seed=3)
    radio.step(30.0, np.tile(TAG, (4, 1)))
    e = tr.expected_rates(p, 8)
    c = radio.counts
    # rows per received packet against clock_good * match * fresh: over 30 seeds the ratio was unbiased
    # (-0.1 %) with a 0.2 % sd, so 1 % is 5 sd and would catch a factor modelled wrong (each is 0.6-3 %)
    share = e.parts["clock_good"] * e.parts["match"] * e.parts["fresh"]
    assert c["rows"].sum() / c["received"].sum() == pytest.approx(share, rel=0.01)
    # the rate itself also carries the channel's collision count (0.7 % sd over seeds): 3 % is 4 sd
    assert c["rows"].mean() / 30.0 == pytest.approx(e.measurements_per_tag_hz, rel=0.03)
    assert e.measurements_per_tag_hz < e.received_per_tag_hz


def test_context_keeps_at_most_16_anchors_and_evicts_the_oldest():
    many = _room(24)  # 24 anchors at 20 Hz each (480 packets/s), all audible
    radio = tr.TdoaRadio(tr.TdoaParams(), many, 2, 10.0, seed=4)
    rows = radio.step(10.0, np.tile(TAG, (2, 1)))
    c = radio.counts
    assert np.all(c["max_context"] == 16)
    assert np.all(c["evictions"] > 0)
    wide = tr.TdoaRadio(tr.TdoaParams(context_anchors=24), many, 2, 10.0, seed=4)
    wide.step(10.0, np.tile(TAG, (2, 1)))
    assert np.all(wide.counts["evictions"] == 0) and np.all(wide.counts["max_context"] == 24)
    # thrashing costs differences: the 16-slot tag loses clock references and partners
    assert np.all(c["rows"] < 0.9 * wide.counts["rows"])
    assert rows[0].shape[0] == c["rows"][0]
    # eight anchors fit: no eviction
    small = tr.TdoaRadio(tr.TdoaParams(), ROOM, 1, 5.0, seed=4)
    small.step(5.0, TAG[None])
    assert small.counts["evictions"][0] == 0 and small.counts["max_context"][0] == 8


def test_tdoa2_slots_frame_and_ring_pairs():
    p = tr.TdoaParams(mode="tdoa2")
    radio = tr.TdoaRadio(p, ROOM, 1, 5.0, seed=2)
    rows = radio.step(5.0, TAG[None])[0]
    ch = radio.channel
    assert np.allclose(np.diff(ch.t_s), tr.TDOA2_SLOT_S)  # one packet per slot, no gap, no overlap
    assert np.array_equal(np.diff(ch.anchor) % 8, np.ones(len(ch.anchor) - 1))  # anchors 0..7 in turn
    assert ch.ok.all()
    e = tr.expected_rates(p, 8)
    assert e.per_anchor_hz == pytest.approx(np.full(8, 1.0 / (8 * 2.0**27 / (499.2e6 * 128))))  # 59.5 Hz
    assert e.collision_share == 0.0
    sent, _ = ch.counts(0.0, 5.0, 8)
    assert np.all(np.abs(sent - 5.0 * e.per_anchor_hz) <= 1)
    # youngest matching with no loss: every difference pairs the previous slot's anchor
    assert np.array_equal((rows[:, tr.ROW_B] - rows[:, tr.ROW_A]) % 8, np.ones(len(rows)))
    assert len(rows) == pytest.approx(5.0 * e.total_hz, abs=2)
    # nine anchors: TDoA2 has 8 slots, the ninth never transmits
    assert tr.anchor_rates_hz(p, 9)[8] == 0.0


def test_random_matching_pairs_every_named_anchor():
    radio = tr.TdoaRadio(tr.TdoaParams(), ROOM, 1, 10.0, seed=6)
    rows = radio.step(10.0, TAG[None])[0]
    pairs = np.bincount((rows[:, tr.ROW_A] * 8 + rows[:, tr.ROW_B]).astype(int), minlength=64).reshape(8, 8)
    off = pairs[~np.eye(8, dtype=bool)]
    # 56 ordered pairs, ~3200 rows: each ~58 expected; none empty and none more than twice its share
    assert off.min() > 0 and off.max() < 2 * off.mean()
    assert np.all(np.diag(pairs) == 0)


def test_a_difference_is_the_geometry_plus_white_noise_and_a_millimetre_clock_residual():
    p = tr.TdoaParams(sigma_m=0.05)
    radio = tr.TdoaRadio(p, ROOM, 1, 20.0, seed=8)
    rows = radio.step(20.0, TAG[None])[0]
    true = np.linalg.norm(TAG - ROOM[rows[:, 2].astype(int)], axis=1) - np.linalg.norm(
        TAG - ROOM[rows[:, 1].astype(int)], axis=1
    )
    assert np.allclose(rows[:, tr.ROW_TRUE], true)
    res = rows[:, tr.ROW_DDIST] - true
    # ~6000 rows: the sample sd of N(0, 0.05) is within 3 % with margin
    assert np.std(res) == pytest.approx(0.05, rel=0.03) and abs(np.mean(res)) < 0.003
    clock = rows[:, tr.ROW_CLOCK]
    assert np.sqrt(np.mean(clock**2)) < 0.003  # corrected: millimetres ...
    # ... where an uncorrected 10 ppm over the rows' intervals would be metres: c (t_B - t_A) eps
    assert tr.C_M_S * 0.005 * 10e-6 > 10.0


def test_range_errors_enter_as_differences_and_an_nlos_anchor_reaches_all_its_pairs():
    off = np.linspace(-0.3, 0.1, 8)
    errors = tr.LinkErrors(np.zeros(8) + _offset_only_prm(), off, np.zeros((1, 8)))
    radio = tr.TdoaRadio(tr.TdoaParams(sigma_m=0.01), ROOM, 1, 20.0, seed=9, errors=errors, nlos_anchor=5,
                         nlos_probability=0.5, nlos_excess_m=0.4)  # fmt: skip
    rows = radio.step(20.0, TAG[None], airborne=True)[0]
    a, b = rows[:, 1].astype(int), rows[:, 2].astype(int)
    clear = (a != 5) & (b != 5)
    np.testing.assert_allclose(rows[clear, tr.ROW_ERR], off[b[clear]] - off[a[clear]], atol=1e-12)
    # anchor 5 long by an exponential of mean 0.4 on half its packets: +0.2 on average as B, -0.2 as A
    as_b = rows[b == 5, tr.ROW_ERR] - (off[5] - off[a[b == 5]])
    as_a = rows[a == 5, tr.ROW_ERR] - (off[b[a == 5]] - off[5])
    assert np.mean(as_b) == pytest.approx(0.2, abs=0.05) and np.all(as_b >= -1e-12)
    assert np.mean(as_a) == pytest.approx(-0.2, abs=0.05) and np.all(as_a <= 1e-12)
    # on the ground the episode is off
    grounded = tr.TdoaRadio(tr.TdoaParams(sigma_m=0.01), ROOM, 1, 5.0, seed=9, errors=errors, nlos_anchor=5,
                            nlos_probability=0.5, nlos_excess_m=0.4)  # fmt: skip
    g = grounded.step(5.0, TAG[None], airborne=False)[0]
    ga, gb = g[:, 1].astype(int), g[:, 2].astype(int)
    np.testing.assert_allclose(g[:, tr.ROW_ERR], off[gb] - off[ga], atol=1e-12)


def _offset_only_prm() -> np.ndarray:
    from swarm.core import range_errors as re_

    prm = np.zeros(re_.RE_N)
    prm[re_.RE_ON], prm[re_.RE_GM_TAU], prm[re_.RE_EPISODE_S] = 1.0, 1.0, 1.0
    return prm


def test_ticks_give_the_rows_of_one_run_and_a_seed_its_draws():
    one = tr.TdoaRadio(tr.TdoaParams(), ROOM, 2, 3.0, seed=1)
    whole = one.step(3.0, np.tile(TAG, (2, 1)))
    ticked = tr.TdoaRadio(tr.TdoaParams(), ROOM, 2, 3.0, seed=1)
    parts = [ticked.step(t, np.tile(TAG, (2, 1))) for t in np.arange(-1.0, 3.0001, 0.02)]
    for i in range(2):
        np.testing.assert_array_equal(np.vstack([p[i] for p in parts]), whole[i])
    other = tr.TdoaRadio(tr.TdoaParams(), ROOM, 2, 3.0, seed=2).step(3.0, np.tile(TAG, (2, 1)))
    assert not np.array_equal(other[0][:50, 0], whole[0][:50, 0])


def test_twr_tdma_rate_falls_as_one_over_n_and_tdoa_holds():
    for n in (2, 8, 32, 128):
        frame = 1 << (n - 1).bit_length()
        # the radio step's own slot test, counted over 10 s of 50 Hz ticks for the tag of slot 0
        prm = np.array([0.0042, float(frame), 0.02])
        ticks = sum(tdma_has_slot(k * 0.02, 0, prm) for k in range(1, 501))
        assert tr.twr_tdma_rate_hz(n) == pytest.approx(min(50.0, ticks / 10.0), abs=0.11)
    assert tr.twr_tdma_rate_hz(32) == pytest.approx(238.1 / 32, rel=1e-3)
    rows = tr.per_tag_rates([2, 8, 32, 128])
    assert len({r["tdoa_hz"] for r in rows}) == 1 and rows[0]["tdoa_hz"] > 300
    assert [r["twr_hz"] for r in rows] == sorted((r["twr_hz"] for r in rows), reverse=True)


def test_bad_parameters_are_refused_naming_the_field():
    with pytest.raises(ConfigError, match=r"tdoa\.mode"):
        tr.TdoaParams(mode="twr")
    with pytest.raises(ConfigError, match=r"tdoa\.tag_loss"):
        tr.TdoaParams(tag_loss=1.0)
    with pytest.raises(ConfigError, match="two air times"):
        tr.TdoaParams(anchor_max_rate_hz=1000.0, jitter_s=0.0, airtime_s=0.001)
    with pytest.raises(ConfigError, match="at least 2 anchors"):
        tr.TdoaRadio(tr.TdoaParams(), ROOM[:1], 1, 1.0)
