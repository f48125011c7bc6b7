"""The simulated radios learn real flights (swarm.core.range_errors, docs/logs.md): the docking radio
network (swarm.step.radio.UwbNetwork) and the landing world (swarm.step.landing.LandingWorld) range with
per-anchor offsets, a take-off step, Gauss-Markov multipath and NLOS episodes, and the landing IMU vibrates
in flight; each measured from the generated ranges against the truth. Off (the default), nothing changes;
on, the errors come from their own streams and change no other draw."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm.core import range_errors as rerr
from swarm.core._rot_nb import qrotate
from swarm.errors import ConfigError
from swarm.landing_scenario import load_landing
from swarm.scenario import load_scenario
from swarm.step import landing_nb as lnb
from swarm.step.landing import LandingWorld
from swarm.step.radio import UwbNetwork


def _residuals(seconds: float, seed: int = 1, scenario: str = "docking", **uwb):
    """Every exchange of a network of ``scenario``'s vehicles standing still at their start, 1 mm white
    noise and ``uwb`` on: ``(vehicle index, t, anchor, range - true range, outlier)`` arrays."""
    sc = load_scenario(scenario, {"uwb.sigma_m": 0.001, **{f"uwb.{k}": v for k, v in uwb.items()}})
    net = UwbNetwork(sc, seed)
    X = np.zeros((len(net.ids), 13))
    for i, vid in enumerate(net.ids):
        X[i, 0:3] = sc.vehicles[vid].position_m
        X[i, 9] = 1.0
    true = np.linalg.norm(X[:, None, 0:3] + net.lever[:, None, :] - net.anchors[None], axis=2)
    rows = []
    for k in range(net.every, int(seconds / sc.dt_s), net.every):
        for vid, s in net.step(k, k * sc.dt_s, X).items():
            i = net.ids.index(vid)
            rows.append((i, s.t_s, s.anchor_id, s.range_m - true[i, s.anchor_id], s.is_outlier))
    v, t, a, e, o = (np.array(c) for c in zip(*rows, strict=True))
    return net, v.astype(int), t, a.astype(int), e, o.astype(bool)


def test_the_radio_multipath_has_its_sigma_and_correlation_time():
    net, v, _, a, e, _ = _residuals(400.0, multipath_sigma_m=0.05, multipath_tau_s=1.0)
    num, den, pooled = {1: 0.0, 12: 0.0}, 0.0, []
    for i in range(len(net.ids)):
        for anchor in range(len(net.anchors)):
            x = e[(v == i) & (a == anchor)]
            x = x - x.mean()
            pooled.append(x)
            den += float(x @ x)
            for lag in num:  # each link's ranges every 0.08 s (50 Hz over 4 anchors): lag 12 = 0.96 s
                num[lag] += float(x[:-lag] @ x[lag:])
    # 8 links x 400 s: ~1600 independent stretches of 2 tau, so the sigma to ~2 % and the autocorrelation
    # to ~0.025 (biased low by 2 tau / T = 0.005): bounds of ~3-4 of those
    assert np.concatenate(pooled).std() == pytest.approx(0.05, rel=0.08)
    assert num[12] / den == pytest.approx(math.exp(-0.96), abs=0.08)
    assert num[1] / den == pytest.approx(math.exp(-0.08), abs=0.03)


def test_each_anchor_has_its_offset_and_each_flying_link_its_take_off_step():
    uwb = dict(
        offset_m=-0.25, offset_spread_m=0.05, takeoff_bias_step_m=0.08, takeoff_bias_step_spread_m=0.03
    )
    net, v, _, a, e, _ = _residuals(40.0, **uwb)
    assert net.airborne.all()  # cubes float: their links carry the step
    for i in range(len(net.ids)):
        for anchor in range(len(net.anchors)):
            want = net.err_offset[anchor] + net.err_step[i, anchor]
            # ~500 ranges of 1 mm noise: the median to ~0.1 mm
            assert np.median(e[(v == i) & (a == anchor)]) == pytest.approx(want, abs=5e-4)
    # uniform draws: within mean +- sd sqrt(3), and not all alike
    assert np.all(np.abs(net.err_offset + 0.25) <= 0.05 * math.sqrt(3) + 1e-12)
    assert np.all(np.abs(net.err_step - 0.08) <= 0.03 * math.sqrt(3) + 1e-12)
    assert np.ptp(net.err_offset) > 0.01 and np.ptp(net.err_step) > 0.01
    # ground modules never take off: their ranges have the anchors' offsets and no step
    net, v, _, a, e, _ = _residuals(40.0, scenario="ground-docking", **uwb)
    assert not net.airborne.any()
    for anchor in range(len(net.anchors)):
        assert np.median(e[a == anchor]) == pytest.approx(net.err_offset[anchor], abs=5e-4)


def test_nlos_episodes_have_their_share_length_and_excess():
    net, v, t, a, e, o = _residuals(600.0, nlos_episode_rate_hz=0.05, nlos_episode_s=4.0,
                                    nlos_episode_excess_m=0.3)  # fmt: skip
    blocked = e > 0.1  # 100 sigma of the white noise; the smallest excess is 0.15 m
    np.testing.assert_array_equal(blocked, o)  # an episode's ranges are marked outliers
    # two-state chain: blocked a share lambda D / (1 + lambda D) = 1/6 of the time; ~200 episodes in all,
    # so the share to ~10 % and the mean length to ~7 %; bounds of ~3 of those
    assert blocked.mean() == pytest.approx(1 / 6, abs=0.05)
    assert e[blocked].mean() == pytest.approx(0.3, abs=0.03)  # uniform in [0.15, 0.45]
    assert e[blocked].min() >= 0.15 - 0.005 and e[blocked].max() <= 0.45 + 0.005
    lengths = []
    for i in range(len(net.ids)):
        for anchor in range(len(net.anchors)):
            link = (v == i) & (a == anchor)
            b, tt = blocked[link].astype(int), t[link]
            starts, ends = np.flatnonzero(np.diff(b) == 1) + 1, np.flatnonzero(np.diff(b) == -1) + 1
            if b[0]:
                starts = np.r_[0, starts]
            for s0, s1 in zip(starts, ends, strict=False):
                lengths.append(tt[s1] - tt[s0])
    assert len(lengths) > 100
    assert np.mean(lengths) == pytest.approx(4.0, rel=0.25)


def test_off_is_the_radio_of_before_and_on_changes_no_other_draw():
    net0, _, _, a0, e0, o0 = _residuals(20.0)
    assert not net0.err_on and net0.err_noise.size == 0  # nothing drawn for them
    _, _, _, a1, e1, o1 = _residuals(20.0, offset_m=0.1)
    np.testing.assert_array_equal(a0, a1)
    np.testing.assert_allclose(e1 - e0, 0.1, atol=1e-12)  # the same white noise, 0.1 m longer
    assert not o0.any() and not o1.any()


def test_a_bad_range_error_option_is_refused_naming_the_key():
    with pytest.raises(ConfigError, match=r"uwb.multipath_tau_s must be a finite number > 0, got 0"):
        load_scenario("docking", {"uwb.multipath_tau_s": 0.0})
    with pytest.raises(ConfigError, match=r"uwb.nlos_episode_rate_hz must be a finite number >= 0, got -1"):
        load_landing("landing", {"uwb.nlos_episode_rate_hz": -1.0})
    with pytest.raises(ConfigError, match=r"imu.vibration_gyro_rad_s must be a finite number >= 0"):
        load_landing("landing", {"imu.vibration_gyro_rad_s": -0.1})


LANDING_ERRORS = {
    "uwb.offset_m": -0.25, "uwb.offset_spread_m": 0.05, "uwb.takeoff_bias_step_m": 0.05,
    "uwb.takeoff_bias_step_spread_m": 0.05, "uwb.multipath_sigma_m": 0.05, "uwb.nlos_episode_rate_hz": 0.05,
    "uwb.outlier_probability": 0.01, "imu.vibration_accel_m_s2": 0.1, "imu.vibration_gyro_rad_s": 0.04,
}  # fmt: skip
NOMINAL = {"dispersions.enabled": False, "uwb.max_range_m": 100.0}  # every anchor in reach, from the start


def _landing_samples(overrides: dict, ticks: int, seed: int = 2):
    """A landing world's UAV hovering on its held command for ``ticks`` ticks: its IMU samples (n, 6) and
    its ranges ``(t, anchor, range, true range)``."""
    world = LandingWorld(load_landing("landing", {**NOMINAL, **overrides}), seed)
    u = world.uavs["uav"]
    lever = world.sc.uwb.lever_arm_m
    imu, ranges = [], []
    for k in range(1, ticks):
        inp = world.step(k)["uav"]
        imu.append(np.r_[inp.acc, inp.gyro])
        if inp.uwb is not None:
            a, r = inp.uwb
            tag = u.x[0:3] + qrotate(u.x[6:10], np.asarray(lever, float))
            ranges.append((inp.t, a, r, float(np.linalg.norm(tag - world.anchors[a]))))
    return world, np.array(imu), np.array(ranges)


def test_the_landing_world_s_errors_and_vibration_change_no_other_sample():
    w0, imu0, r0 = _landing_samples({}, 1500)
    w1, imu1, r1 = _landing_samples(LANDING_ERRORS, 1500)
    np.testing.assert_array_equal(r0[:, :2], r1[:, :2])  # the same exchanges, at the same times
    # the vibration, drawn in flight from the UAV's own stream: its spread (1500 ticks x 3 axes: ~2 %)
    vib = imu1 - imu0
    assert vib[:, 0:3].std() == pytest.approx(0.1, rel=0.06)
    assert vib[:, 3:6].std() == pytest.approx(0.04, rel=0.06)
    u = w1.uavs["uav"]
    extra = (r1[:, 2] - r1[:, 3]) - (r0[:, 2] - r0[:, 3])
    a = r1[:, 1].astype(int)
    # the UAV flies the whole time: each anchor's median extra is its offset and step (multipath 5 cm over
    # ~370 ranges an anchor, tau 1 s: the median to ~1 cm; outliers and episodes are long, a few %)
    for anchor in range(len(w1.anchors)):
        want = u.ERR_OFF[anchor] + u.ERR_STEP[anchor]
        assert np.median(extra[a == anchor]) == pytest.approx(want, abs=0.04)
    assert w0.errors_on is False and u.errs.Z.size == 4096


def test_a_landing_world_snapshot_carries_the_errors_state_and_stream():
    sc = load_landing("landing", {**NOMINAL, **LANDING_ERRORS})
    a = LandingWorld(sc, 5)
    for k in range(1, 300):
        a.step(k)
    snap = a.snapshot()
    b = LandingWorld(sc, 5)
    b.restore(snap)
    for k in range(300, 700):
        ia, ib = a.step(k)["uav"], b.step(k)["uav"]
        assert np.array_equal(ia.acc, ib.acc) and np.array_equal(ia.gyro, ib.gyro) and ia.uwb == ib.uwb, k
    assert not np.isnan(a.uavs["uav"].ERR_RS[:, rerr.RS_T]).all()  # the links' states did run


def test_the_compiled_landing_with_real_errors_is_the_tick_by_tick_landing_to_the_bit():
    """As tests/test_landing.py's test of the same name, with every range error and the vibration on: the
    compiled loop refills the errors' draws where the objects draw them tick by tick."""
    import json

    from swarm.sim.landing import run_landing_fleet

    sc = load_landing("landing", LANDING_ERRORS)
    fast = run_landing_fleet(sc, "mdp", 3, record_series=True)
    slow = run_landing_fleet(sc, "mdp", 3, record_series=True, compiled=False)
    for r in (fast, slow):
        r.pop("wall_s")
        for s in r["uavs"].values():
            s.pop("wall_s"), s.pop("realtime_factor")
    assert json.dumps(fast) == json.dumps(slow)
    assert lnb.ERR_DRAWS_PER_TICK == 6 + rerr.ERR_DRAWS


def test_the_compiled_docking_with_real_errors_is_the_per_tick_docking_to_the_bit():
    """tests/test_fastloop.py's check with the range errors on: run_ticks calls uwb_errors_tick where the
    per-tick path's UwbNetwork.step does (60 s of a docking: the approach, where the ranges matter)."""
    from swarm.sim.docking import DockingSim

    sc = load_scenario("docking", {
        "uwb.offset_m": -0.25, "uwb.offset_spread_m": 0.05, "uwb.takeoff_bias_step_m": 0.05,
        "uwb.takeoff_bias_step_spread_m": 0.05, "uwb.multipath_sigma_m": 0.05,
        "uwb.nlos_episode_rate_hz": 0.05, "sim.max_duration_s": 60.0,
    })  # fmt: skip
    fast = DockingSim(sc, "mdp", 3, record_series=False, fast=True).run()["chasers"]["chaser"]
    slow = DockingSim(sc, "mdp", 3, record_series=False, fast=False).run()["chasers"]["chaser"]
    assert fast["estimator"] == slow["estimator"]
    assert fast["modes"] == slow["modes"] and fast["total_impulse_ns"] == slow["total_impulse_ns"]
    assert fast["estimator"]["accepted_ranges"] > 500  # (972 here: the ranges are fused)
