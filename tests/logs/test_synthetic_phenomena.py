"""The synthetic log with a sensor profile (swarm.logs.synthetic, swarm.logs.phenomena): each phenomenon of
real Crazyflie flights (docs/logs.md) switched on alone is in the written files with its parameters,
measured from the CSV files against the truth; the others stay off, and switching one on changes no other
sample."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from swarm.cli.main import main
from swarm.core import rotations as rot
from swarm.logs import phenomena as ph
from swarm.logs.synthetic import ANCHORS, SyntheticSpec, make_log, truth_at
from swarm.sensors.profile import ImuProfile, SensorProfile, UwbProfile

# a short log with a 100 Hz IMU (the phenomena are in the ranges and the IMU's white part: the rate does not
# matter, and it keeps each log at a few hundredths of a second), no scene NLOS anchor, no bias walk
SPEC = SyntheticSpec(duration_s=40.0, imu_rate_hz=100.0, imu_gap_at_s=20.0, nlos_probability=0.0,
                     range_bias_rw=0.0, range_loss=0.0)  # fmt: skip
QUIET_UWB = UwbProfile(sigma_m=0.005, ground_sigma_m=0.005, offset_m=0.0, offset_spread_m=0.0)
QUIET = SensorProfile(name="quiet", uwb=QUIET_UWB, imu=ImuProfile())


def only(**uwb) -> SensorProfile:
    """The quiet profile (5 mm white ranges, nothing else) with the given range-model keys."""
    return replace(QUIET, uwb=replace(QUIET_UWB, **uwb))


def residuals(d, spec=SPEC):
    """``(t, anchor, range - true range)`` of uwb.csv, the truth from the trajectory at each row's time."""
    rows = np.loadtxt(d / "uwb.csv", delimiter=",", skiprows=1, ndmin=2)
    t, a, r = rows[:, 0], rows[:, 1].astype(int), rows[:, 2]
    p, _, q, _, _ = truth_at(spec, t)
    tag = p + rot.quat_rotate(q, np.broadcast_to(np.array(spec.lever_arm_m), p.shape))
    return t, a, r - np.linalg.norm(tag - ANCHORS[a], axis=1)


def test_the_gauss_markov_multipath_has_its_sigma_and_correlation_time(tmp_path):
    info = make_log(tmp_path, 3, replace(SPEC, duration_s=60.0), only(gm_sigma_m=0.05, gm_tau_s=1.0))
    t, a, e = residuals(tmp_path, replace(SPEC, duration_s=60.0))
    fly = t >= info["takeoff_s"]
    num = {1: 0.0, 10: 0.0}
    den, sq = 0.0, []
    for anchor in range(len(ANCHORS)):
        x = e[fly & (a == anchor)]
        x = x - x.mean()
        sq.append(x)
        den += float(x @ x)
        for lag in num:  # each anchor's ranges come every 0.1 s (8 anchors at 80 Hz): lag 10 = 1.0 s
            num[lag] += float(x[:-lag] @ x[lag:])
    sigma = float(np.concatenate(sq).std())
    # ~440 samples per anchor over 55 s: N_eff ~ 55 s / (2 tau) ~ 27 independent stretches per anchor, 220
    # in all, so the pooled sigma's relative error is ~1/sqrt(2 * 220) ~ 5 % and the lag-1 s
    # autocorrelation's ~0.07, biased low by ~2 tau / T from the removed mean; bounds of ~2-3 of those
    # (seeds 0-9: 0.048-0.053 m, 0.28-0.38 at 1 s, 0.884-0.902 at 0.1 s)
    assert abs(sigma - 0.05) < 0.008
    assert abs(num[10] / den - math.exp(-1.0)) < 0.12
    # at 0.1 s the process has barely moved: exp(-0.1) = 0.905 (the 5 mm white part lowers it by 1 %)
    assert abs(num[1] / den - math.exp(-0.1)) < 0.03
    # and on the ground the error is white: no multipath while the vehicle stands still
    assert np.abs(e[~fly]).max() < 5 * 0.005


def test_the_take_off_steps_each_anchors_bias_from_its_ground_offset(tmp_path):
    prof = only(offset_m=-0.25, offset_spread_m=0.05, takeoff_step_m=0.08, takeoff_step_spread_m=0.03)
    info = make_log(tmp_path, 4, SPEC, prof)
    t, a, e = residuals(tmp_path)
    fly = t >= info["takeoff_s"]
    for anchor in range(len(ANCHORS)):
        ground = np.median(e[~fly & (a == anchor)])
        flight = np.median(e[fly & (a == anchor)])
        # ~60 ground and ~400 flight ranges of 5 mm noise: each median to ~1 mm
        assert ground == pytest.approx(info["range_bias_static"][anchor], abs=0.003)
        assert flight - ground == pytest.approx(info["range_bias_step"][anchor], abs=0.003)
        # and the step is at the take-off: every ground range near the ground offset, every flight one
        # near the flight offset (5 sigma of the white noise)
        assert np.abs(e[~fly & (a == anchor)] - ground).max() < 0.025
        assert np.abs(e[fly & (a == anchor)] - flight).max() < 0.025
    # per-anchor offsets and steps inside their uniform's support: mean +- sd sqrt(3)
    assert np.all(np.abs(info["range_bias_static"] + 0.25) <= 0.05 * math.sqrt(3) + 1e-12)
    assert np.all(np.abs(info["range_bias_step"] - 0.08) <= 0.03 * math.sqrt(3) + 1e-12)
    assert np.ptp(info["range_bias_static"]) > 0.02  # the anchors do differ (8 draws over 0.17 m)


def test_the_white_noise_is_quieter_on_the_ground_than_in_flight(tmp_path):
    info = make_log(tmp_path, 5, SPEC, only(ground_sigma_m=0.015, sigma_m=0.06))
    t, _, e = residuals(tmp_path)
    fly = t >= info["takeoff_s"]

    def robust_sigma(mask):
        x = e[mask]
        return 1.4826 * np.median(np.abs(x - np.median(x)))

    # ~480 ground and ~2700 flight ranges: the robust sigma to ~5 % and ~2 %
    assert robust_sigma(~fly) == pytest.approx(0.015, rel=0.15)
    assert robust_sigma(fly) == pytest.approx(0.06, rel=0.08)


def test_a_forced_nlos_episode_has_its_excess_and_duration(tmp_path):
    spec = replace(SPEC, nlos_episode=(2, 12.0, 4.0, 0.3))
    make_log(tmp_path, 6, spec, only(sigma_m=0.01, ground_sigma_m=0.01))
    t, a, e = residuals(tmp_path, spec)
    long = e > 0.15  # 15 sigma of the white noise, half the excess
    assert set(a[long]) == {2}
    t_long = t[long]
    # the anchor is ranged every 0.1 s (+ 2 ms jitter): the episode's ends are seen to within that
    assert t_long.min() == pytest.approx(12.0, abs=0.11)
    assert t_long.max() == pytest.approx(16.0, abs=0.11)
    assert t_long.max() - t_long.min() == pytest.approx(4.0, abs=0.2)
    # ~40 ranges of 1 cm noise: the mean excess to ~2 mm
    assert e[long].mean() == pytest.approx(0.3, abs=0.006)
    assert np.all((t_long >= 12.0) & (t_long < 16.0))


def test_poisson_nlos_episodes_are_in_the_log(tmp_path):
    spec = replace(SPEC, duration_s=60.0)
    info = make_log(tmp_path, 7, spec, only(sigma_m=0.01, ground_sigma_m=0.01, nlos_rate_hz=0.05,
                                          nlos_duration_s=2.0, nlos_excess_m=0.3))  # fmt: skip
    eps = info["nlos_episodes"]
    # 8 anchors x 55 s x 0.05 /s, minus the time spent in episodes: ~20 expected; Poisson, so 8-35 is
    # ~3 sigma either side
    assert 8 <= len(eps) <= 35
    t, a, e = residuals(tmp_path, spec)
    inside = ph.episode_excess(t, a, eps)
    # every range inside an episode is long by its excess, every other one is clear (1 cm noise)
    assert np.abs(e[inside > 0] - inside[inside > 0]).max() < 0.05
    assert np.abs(e[inside == 0]).max() < 0.05
    assert all(ep.start_s >= info["takeoff_s"] for ep in eps)
    assert all(0.15 <= ep.excess_m <= 0.45 for ep in eps)


def test_the_episode_process_has_its_rate_duration_and_excess():
    # the generator alone, over a long time: 8 anchors x 20000 s x 0.02 /s ~ 2900 episodes; their mean
    # length (exponential, 4 s) to ~2 %, the mean excess (uniform 0.15-0.45) to ~0.3 %, and the onsets a
    # Poisson process of the clear time (rate 0.02 /s to ~2 %): bounds of ~4 of those
    rng = np.random.default_rng(0)
    eps = ph.poisson_episodes(rng, 8, 0.0, 20000.0, 0.02, 4.0, 0.3)
    length = np.array([ep.end_s - ep.start_s for ep in eps])
    assert length.mean() == pytest.approx(4.0, rel=0.08)
    assert np.mean([ep.excess_m for ep in eps]) == pytest.approx(0.3, rel=0.015)
    clear = 8 * 20000.0 - length.sum()
    assert len(eps) / clear == pytest.approx(0.02, rel=0.08)


def test_isolated_outliers_have_their_share_and_size(tmp_path):
    info = make_log(tmp_path, 8, SPEC, only(outlier_share=0.03, outlier_excess_m=1.0))
    t, _, e = residuals(tmp_path)
    long = e > 0.03  # 6 sigma of the white noise: what is longer is an outlier (or a tiny one missed)
    # 3200 ranges: 96 outliers expected (sd ~10), of which exp(-0.03) = 97 % above the threshold
    assert long.mean() == pytest.approx(0.03, abs=0.01)
    assert e[long].mean() == pytest.approx(1.0, abs=0.3)  # exponential, ~90 of them: sd 0.1
    assert set(np.round(t[long], 6)) <= set(np.round(info["range_outliers_t"], 6))


def test_the_imu_vibrates_in_flight_only(tmp_path):
    imu = ImuProfile(accel_noise_m_s2_rthz=3e-4, gyro_noise_rad_s_rthz=2e-4, accel_vibration_m_s2=0.1,
                     gyro_vibration_rad_s=0.04)  # fmt: skip
    info = make_log(tmp_path, 9, SPEC, replace(QUIET, imu=imu))
    rows = np.loadtxt(tmp_path / "imu.csv", delimiter=",", skiprows=1)
    t = rows[:, 0]
    _, _, _, w, f = truth_at(SPEC, t)
    fly = t >= info["takeoff_s"]

    def spread(x, mask):  # first differences remove the slowly moving bias: white std = std(diff) / sqrt(2)
        return float(np.diff(x[mask], axis=0).std() / math.sqrt(2))

    acc_e, gyro_e = rows[:, 4:7] - f, rows[:, 1:4] - w
    # 500 ground and 3500 flight samples x 3 axes: each spread to ~2-3 %; the ground one is the density
    # times sqrt(100 Hz), the flight one that and the vibration added in power
    assert spread(acc_e, ~fly) == pytest.approx(3e-3, rel=0.1)
    assert spread(acc_e, fly) == pytest.approx(math.hypot(3e-3, 0.1), rel=0.05)
    assert spread(gyro_e, ~fly) == pytest.approx(2e-3, rel=0.1)
    assert spread(gyro_e, fly) == pytest.approx(math.hypot(2e-3, 0.04), rel=0.05)


def test_a_blackout_has_no_range(tmp_path):
    spec = replace(SPEC, blackout=(10.0, 3.0))
    make_log(tmp_path, 10, spec)
    t = np.loadtxt(tmp_path / "uwb.csv", delimiter=",", skiprows=1)[:, 0]
    assert not np.any((t >= 10.0) & (t < 13.0))
    # the ranges either side are there: 80 Hz up to the blackout and from its end
    assert np.sum((t >= 9.0) & (t < 10.0)) >= 79 and np.sum((t >= 13.0) & (t < 14.0)) >= 79


def test_height_and_baro_files(tmp_path):
    spec = replace(SPEC, height_rate_hz=25.0, baro_rate_hz=20.0, height_max_range_m=1.6)
    info = make_log(tmp_path, 11, spec)
    h = np.loadtxt(tmp_path / "height.csv", delimiter=",", skiprows=1)
    p, _, q, _, _ = truth_at(spec, h[:, 0])
    cos_tilt = 1.0 - 2.0 * (q[:, 0] ** 2 + q[:, 1] ** 2)
    d = p[:, 2] / cos_tilt
    # no return beyond its reach (the figure climbs to ~1.95 m) and one wherever it is within reach
    assert np.all(np.isnan(h[d > 1.6, 1])) and np.any(d > 1.6)
    ok = ~np.isnan(h[:, 1])
    assert np.all(ok[d <= 1.6])
    # ~900 readings: the noise's sigma to ~3 %
    assert (h[ok, 1] - d[ok]).std() == pytest.approx(0.005, rel=0.12)
    assert abs((h[ok, 1] - d[ok]).mean()) < 0.001
    b = np.loadtxt(tmp_path / "baro.csv", delimiter=",", skiprows=1)
    pb, _, _, _, _ = truth_at(spec, b[:, 0])
    e = b[:, 1] - pb[:, 2]
    # the offset plus a drift of 0.01 m/sqrt(s) (~6 cm over 40 s), the noise 0.2 m (800 readings: ~1 cm on
    # the mean); the white part by first differences (the drift's steps are ~2 mm)
    assert e.mean() == pytest.approx(spec.baro_offset_m, abs=0.15)
    assert np.diff(e).std() / math.sqrt(2) == pytest.approx(0.2, rel=0.08)
    assert abs(info["baro_drift_final_m"]) < 0.1
    assert np.all(np.diff(h[:, 0]) > 0) and np.all(np.diff(b[:, 0]) > 0)


def test_a_phenomenon_changes_no_other_sample(tmp_path):
    make_log(tmp_path / "a", 12, SPEC, QUIET)
    make_log(tmp_path / "b", 12, SPEC, only(gm_sigma_m=0.05, nlos_rate_hz=0.1))
    make_log(tmp_path / "c", 12, SPEC)  # no profile
    imu = [(tmp_path / x / "imu.csv").read_bytes() for x in "abc"]
    assert imu[0] == imu[1] == imu[2]  # the quiet profile's IMU densities are the model's
    ua, ub = (np.loadtxt(tmp_path / x / "uwb.csv", delimiter=",", skiprows=1) for x in "ab")
    np.testing.assert_array_equal(ua[:, :2], ub[:, :2])
    ground = ua[:, 0] < SPEC.static_s
    np.testing.assert_array_equal(ua[ground], ub[ground])  # the phenomena are in flight only
    assert np.any(ua[~ground, 2] != ub[~ground, 2])


def test_the_cli_writes_a_profiled_log(tmp_path, capsys):
    d = tmp_path / "log"
    code = main(["synth-log", str(d), "--duration", "10", "--profile", "default", "--height", "20",
                 "--baro", "10"])  # fmt: skip
    assert code == 0
    assert {"height.csv", "baro.csv", "uwb.csv", "imu.csv"} <= {p.name for p in d.iterdir()}
    assert "sensor profile 'default'" in capsys.readouterr().out
    assert "sensor profile 'default'" in (d / "log.toml").read_text()
