"""Sensor profiles: save -> load round trip, the bundled profiles, and refusals that name the file and key."""

from __future__ import annotations

import pytest

from swarm.errors import ConfigError
from swarm.sensors import (
    AnchorProfile,
    ImuProfile,
    SensorProfile,
    UwbProfile,
    bundled_profiles,
    load_profile,
    save_profile,
)


def _odd_profile() -> SensorProfile:
    """Every field away from its default (so a key the writer forgot would load back as the default)."""
    return SensorProfile(
        name='fitted "x"',
        source="a\nb",
        uwb=UwbProfile(
            sigma_m=0.061,
            ground_sigma_m=0.0137,
            offset_m=-0.25,
            offset_spread_m=0.051,
            takeoff_step_m=0.043,
            takeoff_step_spread_m=0.052,
            gm_sigma_m=0.047,
            gm_tau_s=0.93,
            nlos_rate_hz=0.021,
            nlos_duration_s=3.7,
            nlos_excess_m=0.31,
            outlier_share=0.011,
            outlier_excess_m=1.2,
            anchors={
                "3": AnchorProfile(ground_bias_m=-0.21, sigma_m=0.05, nlos_share=0.4, gm_tau_s=0.9),
                "12": AnchorProfile(flight_bias_m=-0.18),
            },
        ),
        imu=ImuProfile(
            rate_hz=500.0,
            gyro_noise_rad_s_rthz=1.7e-3,
            gyro_bias_instability_rad_s=1.1e-4,
            accel_noise_m_s2_rthz=0.021,
            accel_bias_instability_m_s2=1.3e-3,
            gyro_vibration_rad_s=0.041,
            accel_vibration_m_s2=0.11,
        ),
    )


def test_save_then_load_gives_the_same_profile(tmp_path):
    p = _odd_profile()
    path = tmp_path / "sensors.toml"
    save_profile(p, path, comments=["made by a test", "second line"])
    text = path.read_text()
    assert text.startswith("# made by a test\n# second line\n")
    assert "[uwb.anchors.3]" in text and "[uwb.anchors.12]" in text
    assert "# Gyro white noise density" in text  # the field docstrings become comments
    assert load_profile(path) == p


def test_bundled_default_is_the_dataclass_defaults_and_loads_by_name():
    assert "default" in bundled_profiles()
    p = load_profile("default")
    assert p.uwb == UwbProfile() and p.imu == ImuProfile()


def test_every_bundled_profile_loads():
    for name in bundled_profiles():
        assert load_profile(name).name == name


def test_an_unknown_key_is_refused_naming_file_and_key(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("[uwb]\nsigma_m = 0.05\nsigma_mm = 0.1\n")
    with pytest.raises(ConfigError) as e:
        load_profile(path)
    assert str(path) in str(e.value) and "uwb.sigma_mm: unknown key" in str(e.value)
    assert "did you mean 'sigma_m'" in str(e.value)


def test_a_bad_value_is_refused_naming_file_key_line_and_value(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('name = "x"\n\n[imu]\nrate_hz = 100.0\ngyro_noise_rad_s_rthz = -1\n')
    with pytest.raises(ConfigError) as e:
        load_profile(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: imu.gyro_noise_rad_s_rthz must be a finite number > 0, got -1")
    assert "line 5" in msg


def test_a_bad_anchor_value_names_the_anchor(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("[uwb.anchors.7]\nnlos_share = 1.5\n")
    want = r"uwb\.anchors\.7\.nlos_share must be a share in \[0, 1\], got 1\.5"
    with pytest.raises(ConfigError, match=want):
        load_profile(path)


def test_an_anchor_key_that_is_not_an_id_is_refused(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("[uwb.anchors.north]\nsigma_m = 0.1\n")
    with pytest.raises(ConfigError, match=r"uwb.anchors: key 'north' is not an anchor id"):
        load_profile(path)


def test_an_unknown_name_lists_the_bundled_profiles():
    with pytest.raises(ConfigError, match=r"'no-such-profile'.*bundled: .*default"):
        load_profile("no-such-profile")


def test_a_type_error_names_the_key(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('[uwb]\ngm_tau_s = "long"\n')
    with pytest.raises(ConfigError, match=r"uwb\.gm_tau_s: expected a number, got 'long'"):
        load_profile(path)


def test_the_dataclass_refuses_a_bad_value_in_code():
    with pytest.raises(ConfigError, match=r"uwb\.outlier_share must be a share in \[0, 1\], got 2"):
        UwbProfile(outlier_share=2)
