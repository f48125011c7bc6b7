"""The live navigator (swarm.logs.online) gives the log replay's estimates bit for bit when it is fed the same
samples, in whatever order two streams deliver them within its horizon."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.errors import ConfigError
from swarm.logs.online import OnlineNavigator
from swarm.logs.reader import read_log
from swarm.logs.replay import replay_log
from swarm.logs.synthetic import SyntheticSpec, make_log
from tests.logs.feed import feed, in_time_order


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    d = tmp_path_factory.mktemp("online")
    make_log(d, seed=4, spec=SyntheticSpec(duration_s=20.0))
    return d


def _samples(log):
    return in_time_order(log, "imu", "uwb")


def _run(log, order, delay_s=0.05, drain_every=97):
    return feed(OnlineNavigator(log.config, log.anchor_ids, log.anchors_nav, delay_s), order, drain_every)


def _same(nav, r):
    t = np.array([e.t_s for e in nav.estimates])
    X = np.array([e.X for e in nav.estimates])
    P = np.array([e.P9 for e in nav.estimates])
    assert len(t) == len(r.t)
    assert np.array_equal(t, r.t) and np.array_equal(X, r.X) and np.array_equal(P, r.P)
    assert np.array_equal(nav.f.counts, r.counts)


def test_fed_in_time_order_it_gives_the_replay_bit_for_bit(flight):
    log = read_log(flight)
    nav = _run(log, _samples(log))
    r = replay_log(log)
    _same(nav, r)
    # the flight's take-off (a phase change, not a reset) is seen alike by both, at the same sample
    assert nav.dropped == 0 and nav.events == r.events
    assert [e["kind"] for e in nav.events] == ["takeoff"]
    e = nav.estimates[-1]
    assert e.counts["range_accepted"] == int(nav.f.counts[:, 0].sum()) and 0.0 <= e.reject_share <= 1.0


def test_two_streams_out_of_order_within_the_horizon_change_nothing(flight):
    log = read_log(flight)
    order = _samples(log)
    rng = np.random.default_rng(0)
    # each UWB sample arrives up to 40 ms (of sensor time) late against the IMU stream: inside a 50 ms
    # horizon every sample is still processed in time order
    late = [(s[0] + (rng.uniform(0, 0.04) if s[1] == "uwb" else 0.0), s) for s in order]
    late.sort(key=lambda x: x[0])
    nav = _run(log, [s for _, s in late], delay_s=0.05)
    _same(nav, replay_log(log))
    # with no horizon the late ranges are older than the filter: dropped and counted, never applied
    nav0 = _run(log, [s for _, s in late], delay_s=0.0, drain_every=1)
    assert nav0.dropped > 0 and nav0.f.counts.sum() + nav0.dropped == len(log.uwb_t)


def test_a_forced_divergence_is_detected_and_recovered_as_in_the_replay(flight):
    log = read_log(flight, {"faults.jump_at_s": 12.0})
    r = replay_log(log)
    nav = _run(log, _samples(log))
    _same(nav, r)
    kinds = [e["kind"] for e in r.events if e["kind"] not in ("takeoff", "landing")]
    assert kinds == ["fault", "estimator_reset"]
    assert nav.events == r.events


def test_without_calibration_it_starts_from_the_first_second_of_ranges(flight):
    log = read_log(flight, {"calibration.until_s": 0.0, "uwb.sigma_m": 0.08})
    _same(_run(log, _samples(log)), replay_log(log))


def test_an_unknown_anchor_is_counted_not_fed_and_a_config_that_cannot_start_is_refused(flight):
    log = read_log(flight)
    nav = OnlineNavigator(log.config, log.anchor_ids, log.anchors_nav)
    nav.uwb(0.1, 99, 3.0)
    assert nav.unknown_anchor == 1 and nav.drain(final=True) == ([], [])
    bad = read_log(flight, {"calibration.until_s": 0.0})
    with pytest.raises(ConfigError, match=r"uwb\.sigma_m is required"):
        OnlineNavigator(bad.config, bad.anchor_ids, bad.anchors_nav)
    with pytest.raises(ValueError, match="delay_s"):
        OnlineNavigator(log.config, log.anchor_ids, log.anchors_nav, delay_s=float("nan"))


@pytest.fixture(scope="module")
def seen(tmp_path_factory):
    """A flight with a camera over markers, its vision.csv without sigma columns (a live feed carries none:
    log.toml's vision.sigma_m applies on both sides)."""
    d = tmp_path_factory.mktemp("online-vision")
    make_log(d, seed=6, spec=SyntheticSpec(duration_s=14.0, vision_rate_hz=15.0, vision_sigma_columns=False))
    return d


def _with_vision(log):
    return in_time_order(log, "imu", "uwb", "vision")


def _run_v(log, order):
    nav = OnlineNavigator(log.config, log.anchor_ids, log.anchors_nav, 0.05, log.marker_ids, log.markers_nav)
    return feed(nav, order)


def test_marker_detections_are_fused_as_the_replay_fuses_them(seen):
    log = read_log(seen)
    r = replay_log(log)
    nav = _run_v(log, _with_vision(log))
    _same(nav, r)
    v = r.summary()["vision"]
    assert v["accepted"] > 50  # the camera saw markers: vision took part
    assert list(nav.vision_counts) == [v["accepted"], v["rejected"], v["refused"]]
    # and without vision the estimates differ: the equality above is not vacuous
    blind = _run(log, _samples(log))
    assert not np.array_equal(np.array([e.X for e in blind.estimates]), r.X)


def test_an_unknown_marker_is_counted_and_disabled_vision_feeds_nothing(seen):
    log = read_log(seen)
    nav = OnlineNavigator(log.config, log.anchor_ids, log.anchors_nav, 0.05, log.marker_ids, log.markers_nav)
    nav.vision(1.0, 77, [0.0, 0.0, 1.0])
    assert nav.unknown_marker == 1
    off = read_log(seen, {"vision.enabled": False})
    nav = _run_v(off, _with_vision(off))
    assert nav.vision_counts.sum() == 0
    _same(nav, replay_log(off))


def test_a_tdoa_flight_fed_in_time_order_gives_the_replay_bit_for_bit(tmp_path):
    """A passive tag's distance differences (tdoa.csv, no two-way ranges) through the live navigator
    (OnlineNavigator.tdoa) and through the replay: the same estimates to the bit, the same counts per pair;
    one NLOS anchor's pairs mostly rejected in both."""
    d = tmp_path / "tdoa"
    make_log(d, seed=2, spec=SyntheticSpec(duration_s=15.0, tdoa="tdoa3", tdoa_nlos_anchor=3))
    log = read_log(d)
    r = replay_log(log)
    nav = feed(
        OnlineNavigator(log.config, log.anchor_ids, log.anchors_nav, 0.05), in_time_order(log, "imu", "tdoa")
    )
    _same(nav, r)
    assert np.array_equal(nav.tdoa_counts, r.tdoa.counts)
    s = r.summary()
    # the NLOS anchor's pairs: 60 % of its packets long by ~1 m in flight, mostly past the gate
    nlos = [
        v for k, v in s["tdoa"]["by_pair"].items() if "3" in k.split("-") and v["rejected_share"] is not None
    ]
    clear = [
        v
        for k, v in s["tdoa"]["by_pair"].items()
        if "3" not in k.split("-") and v["rejected_share"] is not None
    ]
    assert np.mean([v["rejected_share"] for v in nlos]) > 3 * np.mean([v["rejected_share"] for v in clear])
    assert s["rmse_m"] < 0.15


@pytest.mark.parametrize("enabled", [True, False])
def test_range_finder_readings_are_fused_as_the_replay_fuses_them_or_not_at_all(tmp_path, enabled):
    """``height.csv`` through the live navigator equals the replay bit for bit with ``height.enabled`` on,
    and off: a disabled range finder's readings are not fed at all (a refused reading would still split the
    IMU interval it falls in, and the estimates would differ from the replay's)."""
    d = tmp_path / "h"
    make_log(d, seed=4, spec=SyntheticSpec(duration_s=12.0, height_rate_hz=25.0))
    log = read_log(d, {"height.enabled": enabled})
    r = replay_log(log)
    nav = feed(
        OnlineNavigator(log.config, log.anchor_ids, log.anchors_nav, 0.05),
        in_time_order(log, "imu", "uwb", "height"),
    )
    _same(nav, r)
    assert (nav.aux_counts[0].sum() > 0) == enabled
