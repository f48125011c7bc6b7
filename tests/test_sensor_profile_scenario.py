"""A scenario may name a sensor profile (``[sensors] profile``, swarm.sensors.options): its numbers fill
the ``[uwb]`` and IMU options the scenario leaves out; keys the scenario sets win, ``--set`` over both."""

from __future__ import annotations

import math

import pytest

from swarm.errors import ConfigError
from swarm.landing_scenario import load_landing
from swarm.scenario import load_scenario
from swarm.sensors.profile import ImuProfile, SensorProfile, UwbProfile, load_profile, save_profile

PROFILE = SensorProfile(
    name="bench",
    uwb=UwbProfile(sigma_m=0.061, ground_sigma_m=0.017, offset_m=-0.27, offset_spread_m=0.043,
                   takeoff_step_m=0.052, takeoff_step_spread_m=0.031, gm_sigma_m=0.047, gm_tau_s=1.3,
                   nlos_rate_hz=0.021, nlos_duration_s=3.7, nlos_excess_m=0.29, outlier_share=0.011,
                   outlier_excess_m=0.8),
    imu=ImuProfile(gyro_noise_rad_s_rthz=0.0021, accel_noise_m_s2_rthz=0.023,
                   gyro_bias_instability_rad_s=1e-4, gyro_vibration_rad_s=0.041, accel_vibration_m_s2=0.11),
)  # fmt: skip


@pytest.fixture
def folder(tmp_path):
    save_profile(PROFILE, tmp_path / "bench.toml")
    return tmp_path


def _landing_file(folder, body: str):
    path = folder / "landing-bench.toml"
    path.write_text('[mission]\nname = "landing"\n' + body)
    return path


def test_a_landing_scenario_takes_the_profile_s_numbers(folder):
    sc = load_landing(_landing_file(folder, '[sensors]\nprofile = "bench.toml"\n'))
    u, i = sc.uwb, sc.imu
    assert (u.sigma_m, u.offset_m, u.offset_spread_m) == (0.061, -0.27, 0.043)
    assert (u.takeoff_bias_step_m, u.takeoff_bias_step_spread_m) == (0.052, 0.031)
    assert (u.multipath_sigma_m, u.multipath_tau_s) == (0.047, 1.3)
    assert (u.nlos_episode_rate_hz, u.nlos_episode_s, u.nlos_episode_excess_m) == (0.021, 3.7, 0.29)
    assert (u.outlier_probability, u.outlier_excess_m) == (0.011, 0.8)
    noise = (i.accel_noise_m_s2_rthz, i.gyro_noise_rad_s_rthz)
    assert (*noise, i.vibration_accel_m_s2, i.vibration_gyro_rad_s) == (
        0.023, 0.0021, 0.11, 0.041,
    )  # fmt: skip
    assert sc.sensors.profile == "bench.toml"


def test_the_scenario_s_own_keys_win_and_set_wins_over_both(folder):
    path = _landing_file(
        folder,
        '[sensors]\nprofile = "bench.toml"\n[uwb]\nsigma_m = 0.2\n[imu]\naccel_noise_m_s2_rthz = 0.5\n',
    )
    sc = load_landing(path, {"uwb.multipath_sigma_m": 0.0})
    assert sc.uwb.sigma_m == 0.2 and sc.imu.accel_noise_m_s2_rthz == 0.5  # the file's
    assert sc.uwb.multipath_sigma_m == 0.0  # the override's
    assert sc.uwb.offset_m == -0.27 and sc.imu.gyro_noise_rad_s_rthz == 0.0021  # the profile's


def test_set_may_name_the_profile_and_a_bundled_one_by_name(folder):
    sc = load_landing("landing", {"sensors.profile": str(folder / "bench.toml")})
    assert sc.uwb.offset_m == -0.27
    assert sc.uwb.sigma_m == 0.10  # landing.toml sets its own
    real = load_profile("real-crazyflie")
    sc = load_landing("landing", {"sensors.profile": "real-crazyflie"})
    assert sc.uwb.multipath_sigma_m == real.uwb.gm_sigma_m and sc.uwb.offset_m == real.uwb.offset_m
    assert sc.imu.vibration_accel_m_s2 == real.imu.accel_vibration_m_s2


def test_a_docking_scenario_maps_the_outliers_and_the_gyro(folder):
    sc = load_scenario("docking", {"sensors.profile": str(folder / "bench.toml")})
    u, g = sc.uwb, sc.gyro
    # docking.toml sets sigma_m, the NLOS outliers and the gyro itself: those stay
    assert (u.sigma_m, u.nlos_probability, g.gyro_noise_rad_s_rthz) == (0.02, 0.0, math.radians(0.0035))
    assert (u.offset_m, u.multipath_sigma_m, u.nlos_episode_s) == (-0.27, 0.047, 3.7)
    path = folder / "dock.toml"
    path.write_text('[sensors]\nprofile = "bench.toml"\n')  # every other key the paper's default
    sc = load_scenario(path)
    u, g = sc.uwb, sc.gyro
    # outliers: the docking radio's uniform [min, max] excess with the profile's exponential mean
    assert (u.nlos_probability, u.nlos_min_m, u.nlos_max_m) == (0.011, 0.0, 1.6)
    assert g.gyro_noise_rad_s_rthz == 0.0021
    assert g.bias_instability_deg_h == pytest.approx(math.degrees(1e-4) * 3600)


def test_no_profile_changes_nothing_and_a_missing_one_is_named(folder):
    assert load_landing("landing") == load_landing("landing", {"sensors.profile": ""})
    with pytest.raises(
        ConfigError, match=r"landing-bench.toml: sensors.profile 'nope': sensor profile 'nope'"
    ):
        load_landing(_landing_file(folder, '[sensors]\nprofile = "nope"\n'))
    with pytest.raises(ConfigError, match=r"sensors.profile must be a name or a path, got 3"):
        load_landing(_landing_file(folder, "[sensors]\nprofile = 3\n"))
