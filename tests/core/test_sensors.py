"""Tests for swarm.core.sensors: rate gyro, UWB ranging with faults, AHRS.

Oracles: closed forms (white-noise standard deviation ARW / sqrt(dt); Allan deviation ARW / sqrt(tau),
IEEE Std 952-1997 Annex C; stationary Gauss-Markov variance and lag correlation exp(-dt / tau)), binomial
and uniform distributions (scipy.stats) for the fault models, swarm.core.rotations for the AHRS error.
Statistical tests are seeded; each threshold is several standard errors of its estimator wide, quoted
next to it, and tight enough that a model off by a units slip or a wrong formula fails.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy.stats import binom, kstest, uniform

from swarm.core import rotations as rot
from swarm.core.sensors import (
    AhrsParams,
    GyroParams,
    UwbParams,
    UwbRadio,
    ahrs_sample,
    gyro_init_bias,
    gyro_sample,
)
from swarm.errors import ConfigError

DEG = math.pi / 180.0
ANCHORS_MS = np.array([(1.0, -0.2, 0.5), (1.0, 0.2, -0.5), (-1.0, 0.2, -0.5), (-1.0, -0.2, 0.5)])  # paper III
TAG_MS = np.array([0.1, 0.2, 0.3])
TRUE_RANGES_M = np.linalg.norm(TAG_MS - ANCHORS_MS, axis=1)
W_TRUE = np.array([0.1, -0.2, 0.3])


def _gyro_run(params: GyroParams, n: int, dt: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` samples of one gyro at constant ``W_TRUE``: (measured rates (n, 3), bias before each (n, 3))."""
    rng = np.random.default_rng(seed)
    b = gyro_init_bias(params, rng)
    out = np.empty((n, 3))
    biases = np.empty((n, 3))
    for k in range(n):
        biases[k] = b
        out[k], b = gyro_sample(W_TRUE, b, dt, params, rng)
    return out, biases


# ---- gyro ------------------------------------------------------------------------------------------------


def test_gyro_white_noise_std_is_arw_times_sqrt_rate():
    params = GyroParams(enabled_bias=False)
    w, _ = _gyro_run(params, 20_000, params.dt_s, seed=1)
    err = w - W_TRUE
    expected = 0.0035 * DEG * math.sqrt(100.0)  # VN-100 ARW at 100 Hz
    # 60 000 samples: the standard error of a sample std is std / sqrt(2 n) = 0.29 %; 2 % is ~7 of them,
    # while a deg/rad slip or 1/dt instead of 1/sqrt(dt) is off by a factor of 10 or more.
    assert np.std(err) == pytest.approx(expected, rel=0.02)
    assert np.all(np.abs(err.mean(axis=0)) < 5 * expected / math.sqrt(len(err)))


def test_gyro_allan_deviation_follows_arw_over_sqrt_tau():
    """White rate noise has Allan deviation N / sqrt(tau) (IEEE Std 952-1997, Annex C)."""
    params = GyroParams(enabled_bias=False)
    w, _ = _gyro_run(params, 60_000, params.dt_s, seed=2)  # 600 s
    arw = params.gyro_noise_rad_s_rthz
    for tau_s in (0.1, 1.0, 10.0):
        m = round(tau_s * params.rate_hz)
        clusters = (w[: len(w) // m * m] - W_TRUE).reshape(-1, m, 3).mean(axis=1)
        adev = math.sqrt(0.5 * np.mean(np.diff(clusters, axis=0) ** 2))
        k = 3 * (len(clusters) - 1)  # independent differences over the three axes
        # relative standard error of an Allan deviation from k differences: ~1 / sqrt(2 k) (0.5 % at
        # 0.1 s, 1.7 % at 1 s, 5.3 % at 10 s; ~1.2x that with neighbouring differences sharing a cluster).
        # 5 of them still rejects a tau^-1 slope (x3.2 at 10 s) or a rate off by 10 % at 0.1 s.
        tol = 5.0 / math.sqrt(2 * k)
        assert adev == pytest.approx(arw / math.sqrt(tau_s), rel=tol), f"tau = {tau_s} s"


def test_gyro_bias_is_stationary_gauss_markov_with_sigma_from_bias_instability():
    """The exact discretization keeps the variance sigma_b^2 and the lag correlation exp(-dt/tau) at any
    step, even dt = tau / 5 (Brown & Hwang 2012, first-order Gauss-Markov)."""
    params = GyroParams()
    sigma_b = 10.0 * DEG / 3600.0
    dt = 20.0
    chains, steps = 2000, 20
    rng = np.random.default_rng(3)
    b = np.empty((steps + 1, chains, 3))
    for c in range(chains):
        b[0, c] = gyro_init_bias(params, rng)
        for k in range(steps):
            _, b[k + 1, c] = gyro_sample(W_TRUE, b[k, c], dt, params, rng)
    # 6000 values per step: the relative standard error of a std is 1 / sqrt(2 * 6000) = 0.9 %; 5 % ~ 5.5x.
    for k in (0, steps // 2, steps):
        assert np.std(b[k]) == pytest.approx(sigma_b, rel=0.05), f"step {k}"
    rho = np.corrcoef(b[:-1].ravel(), b[1:].ravel())[0, 1]
    # correlation estimate from 120 000 pairs (20 steps x 6000, strongly dependent within a chain):
    # standard error below (1 - rho^2) / sqrt(6000) = 0.004; 0.02 is 5x and rejects exp(-dt / (2 tau)).
    assert rho == pytest.approx(math.exp(-dt / 100.0), abs=0.02)


def test_gyro_measurement_carries_the_current_bias():
    params = GyroParams(bias_instability_deg_h=36_000.0, initial_bias_sigma_deg_s=10.0)  # bias >> noise
    rng = np.random.default_rng(4)
    b = gyro_init_bias(params, rng)
    sigma_w = params.gyro_noise_rad_s_rthz / math.sqrt(params.dt_s)
    for _ in range(100):
        w, b_next = gyro_sample(W_TRUE, b, params.dt_s, params, rng)
        assert np.all(np.abs(w - W_TRUE - b) < 6 * sigma_w)
        b = b_next


def test_gyro_bias_disabled_is_zero_and_constant():
    params = GyroParams(enabled_bias=False)
    rng = np.random.default_rng(5)
    b = gyro_init_bias(params, rng)
    assert np.all(b == 0.0)
    _, b2 = gyro_sample(W_TRUE, b, 0.01, params, rng)
    assert np.all(b2 == 0.0)


def test_gyro_same_seed_same_samples():
    a, _ = _gyro_run(GyroParams(), 50, 0.01, seed=6)
    b, _ = _gyro_run(GyroParams(), 50, 0.01, seed=6)
    assert np.array_equal(a, b)


def test_gyro_rejects_non_positive_dt():
    with pytest.raises(ValueError, match="dt"):
        gyro_sample(W_TRUE, np.zeros(3), 0.0, GyroParams(), np.random.default_rng(0))


# ---- UWB ------------------------------------------------------------------------------------------------


def _uwb_run(params: UwbParams, n: int, seed: int, t0: float = 0.0):
    radio = UwbRadio(ANCHORS_MS, params)
    rng = np.random.default_rng(seed)
    return [radio.sample(t0 + k * params.period_s, TAG_MS, rng) for k in range(n)]


def _errors(samples) -> tuple[np.ndarray, np.ndarray]:
    err = np.array([s.range_m - TRUE_RANGES_M[s.anchor_id] for s in samples])
    return err, np.array([s.is_outlier for s in samples])


def test_uwb_white_noise_std_and_zero_mean():
    err, outl = _errors(_uwb_run(UwbParams(), 20_000, seed=10))
    assert not outl.any()
    # 20 000 samples: std standard error 0.5 %, 2.5 % is 5x; mean standard error 0.14 mm, 5x allowed.
    assert np.std(err) == pytest.approx(0.02, rel=0.025)
    assert abs(err.mean()) < 5 * 0.02 / math.sqrt(len(err))


def test_uwb_round_robin_advances_through_dropouts():
    radio = UwbRadio(ANCHORS_MS, UwbParams(dropout_probability=0.5))
    rng = np.random.default_rng(11)
    seen = 0
    for k in range(400):
        assert radio.next_anchor == k % 4
        s = radio.sample(k * 0.02, TAG_MS, rng)
        if s is not None:
            seen += 1
            assert s.anchor_id == k % 4
    assert 0 < seen < 400


def test_uwb_nlos_outlier_fraction_is_binomial():
    n, p = 20_000, 0.1
    _, outl = _errors(_uwb_run(UwbParams(nlos_probability=p), n, seed=12))
    # a correct model lands outside the central 1 - 1e-6 binomial interval (+-4.9 sigma = +-208) once
    # in a million seeds; a rate 15 % off (300 outliers) fails.
    lo, hi = binom.interval(1 - 1e-6, n, p)
    assert lo <= outl.sum() <= hi


def test_uwb_nlos_outliers_add_uniform_excess_path_length():
    params = UwbParams(sigma_m=1e-9, nlos_probability=0.3, nlos_min_m=0.3, nlos_max_m=1.5)
    err, outl = _errors(_uwb_run(params, 5000, seed=13))
    assert np.all(np.abs(err[~outl]) < 1e-6)
    excess = err[outl]
    assert np.all((excess >= 0.3 - 1e-6) & (excess <= 1.5 + 1e-6))  # always long, never short
    # ~1500 outliers against U(0.3, 1.5): a correct model gives p < 1e-3 once in a thousand seeds; a
    # shift of 5 cm or a normal shape gives p < 1e-6.
    assert kstest(excess, uniform(loc=0.3, scale=1.2).cdf).pvalue > 1e-3


def test_uwb_dropout_windows_yield_none_inside_only():
    params = UwbParams(dropout_windows_s=((1.0, 2.0), (3.0, 3.5)))
    samples = _uwb_run(params, 250, seed=14)  # t = 0 .. 4.98 s
    for k, s in enumerate(samples):
        t = k * params.period_s
        inside = 1.0 <= t < 2.0 or 3.0 <= t < 3.5
        assert (s is None) == inside, f"t = {t:.2f} s"


def test_uwb_random_dropout_fraction_is_binomial():
    n, p = 20_000, 0.2
    lost = sum(s is None for s in _uwb_run(UwbParams(dropout_probability=p), n, seed=15))
    lo, hi = binom.interval(1 - 1e-6, n, p)  # as for the outliers: +-5 sigma, ~+-280
    assert lo <= lost <= hi


def test_uwb_clock_drift_bias_grows_linearly_after_start():
    params = UwbParams(sigma_m=1e-9, clock_drift_m_s=0.01, clock_drift_start_s=2.0)
    samples = _uwb_run(params, 500, seed=16)  # 0 .. 10 s
    for k, s in enumerate(samples):
        t = k * params.period_s
        assert s.range_m - TRUE_RANGES_M[s.anchor_id] == pytest.approx(0.01 * max(0.0, t - 2.0), abs=1e-6)


def test_uwb_clock_drift_per_anchor_link():
    rates = (0.01, -0.02, 0.0, 0.005)
    samples = _uwb_run(UwbParams(sigma_m=1e-9, clock_drift_m_s=rates), 200, seed=17)
    for k, s in enumerate(samples):
        t = k * 0.02
        err = s.range_m - TRUE_RANGES_M[s.anchor_id]
        assert err == pytest.approx(rates[s.anchor_id] * t, abs=1e-6)


def test_uwb_switching_faults_on_keeps_the_other_samples_noise():
    """Every exchange draws the same random numbers, so scenario variants share their white noise."""
    clean = _uwb_run(UwbParams(), 1000, seed=18)
    dirty = _uwb_run(UwbParams(nlos_probability=0.2, dropout_probability=0.1), 1000, seed=18)
    kept = [(c, d) for c, d in zip(clean, dirty, strict=True) if d is not None and not d.is_outlier]
    assert len(kept) > 600
    assert all(c.range_m == d.range_m for c, d in kept)


def test_uwb_range_is_never_negative():
    radio = UwbRadio(ANCHORS_MS, UwbParams(sigma_m=0.5))
    rng = np.random.default_rng(19)
    ranges = [radio.sample(0.0, ANCHORS_MS[k % 4], rng).range_m for k in range(400)]
    assert min(ranges) == 0.0


def test_uwb_drift_tuple_must_match_anchor_count():
    with pytest.raises(ConfigError, match=r"uwb\.clock_drift_m_s"):
        UwbRadio(ANCHORS_MS, UwbParams(clock_drift_m_s=(0.01, 0.02)))


def test_uwb_rejects_bad_anchor_array():
    with pytest.raises(ValueError, match="anchors_nav"):
        UwbRadio(np.zeros((4, 2)), UwbParams())


# ---- AHRS -----------------------------------------------------------------------------------------------


def test_ahrs_error_is_body_frame_rotation_vector_with_sigma():
    params = AhrsParams(sigma_deg=0.5)
    q_true = rot.euler_to_quat([0.3, -1.0, 2.0], "ZYX")
    rng = np.random.default_rng(20)
    q_meas = np.array([ahrs_sample(q_true, params, rng) for _ in range(20_000)])
    err = rot.attitude_error(q_true, q_meas)
    # 60 000 values: std standard error 0.29 %, 2 % is 7x; mean standard error sigma / 245, 5x allowed.
    assert np.std(err) == pytest.approx(0.5 * DEG, rel=0.02)
    assert np.all(np.abs(err.mean(axis=0)) < 5 * 0.5 * DEG / math.sqrt(len(err)))


def test_ahrs_noise_multiplies_on_the_right():
    """``q_meas = q_true (x) exp(dtheta)`` exactly, the convention of PoseEstimator.update_attitude."""
    params = AhrsParams(sigma_deg=5.0)
    q_true = rot.euler_to_quat([0.3, -1.0, 2.0], "ZYX")
    q_meas = ahrs_sample(q_true, params, np.random.default_rng(21))
    dtheta = params.sigma_rad * np.random.default_rng(21).standard_normal(3)
    np.testing.assert_allclose(q_meas, rot.multiplicative_reset(q_true, dtheta), atol=1e-14)
    assert params.cov_body == pytest.approx(params.sigma_rad**2 * np.eye(3))


# ---- validation -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("cls", "kwargs", "field"),
    [
        (GyroParams, {"rate_hz": 0.0}, "gyro.rate_hz"),
        (GyroParams, {"gyro_noise_rad_s_rthz": -1.0}, "gyro.gyro_noise_rad_s_rthz"),
        (GyroParams, {"bias_instability_deg_h": float("nan")}, "gyro.bias_instability_deg_h"),
        (GyroParams, {"bias_corr_time_s": 0.0}, "gyro.bias_corr_time_s"),
        (GyroParams, {"initial_bias_sigma_deg_s": -0.1}, "gyro.initial_bias_sigma_deg_s"),
        (GyroParams, {"enabled_bias": "yes"}, "gyro.enabled_bias"),
        (UwbParams, {"rate_hz": -50.0}, "uwb.rate_hz"),
        (UwbParams, {"sigma_m": 0.0}, "uwb.sigma_m"),
        (UwbParams, {"nlos_probability": 1.5}, "uwb.nlos_probability"),
        (UwbParams, {"nlos_min_m": -0.1}, "uwb.nlos_min_m"),
        (UwbParams, {"nlos_max_m": 0.1}, "uwb.nlos_max_m"),
        (UwbParams, {"clock_drift_m_s": float("inf")}, "uwb.clock_drift_m_s"),
        (UwbParams, {"clock_drift_start_s": float("nan")}, "uwb.clock_drift_start_s"),
        (UwbParams, {"dropout_probability": -0.1}, "uwb.dropout_probability"),
        (UwbParams, {"dropout_windows_s": ((2.0, 1.0),)}, "uwb.dropout_windows_s"),
        (AhrsParams, {"rate_hz": 0.0}, "ahrs.rate_hz"),
        (AhrsParams, {"sigma_deg": -1.0}, "ahrs.sigma_deg"),
        (AhrsParams, {"enabled": 1}, "ahrs.enabled"),
    ],
)
def test_invalid_params_raise_config_error_naming_the_field(cls, kwargs, field):
    with pytest.raises(ConfigError, match=rf"^{re.escape(field)} must") as info:
        cls(**kwargs)
    assert isinstance(info.value, ValueError)
    assert repr(next(iter(kwargs.values()))) in str(info.value)  # the message quotes the bad value
