"""A sensor profile (``sensors.toml``, :mod:`swarm.sensors.profile`) as the prior of a log's filter.

``swarm replay LOG --sensors FILE|NAME`` and ``swarm navigate ... --sensors`` read a profile that
``swarm fit`` measured on another flight of the same kind of vehicle and radio, and fill the log.toml keys it
speaks for; a key that log.toml or ``--set`` gives wins (the log knows its own flight better). What maps to
what (``docs/logs.md``, "A sensor profile as the prior"):

- ``uwb.gm_sigma_m``, ``gm_tau_s`` -> ``estimator.range_gm`` (off when the sigma is 0),
  ``range_gm_sigma_m``, ``range_gm_tau_s``;
- ``uwb.sigma_m`` -> ``uwb.sigma_m``, only for a log without a static segment (else it calibrates it);
- ``uwb.takeoff_step_m``, ``takeoff_step_spread_m`` -> ``phases.reopen_sigma_m``, their root mean square;
- ``uwb.offset_spread_m`` -> ``initial.sigma_range_bias_m`` (without a calibration);
- ``uwb.nlos_duration_s`` -> ``robust.nlos_max_s``: three mean episodes, at least 10 s;
- ``imu.*_noise_*`` and ``*_vibration_*`` -> ``estimator.accel_noise``, ``gyro_noise``:
  ``sqrt(N^2 + v^2 / f_s)``, the in-flight density.

The vibration is a white spread at the sample rate ``f_s``; a white sequence of standard deviation ``v`` at
``f_s`` is a density of ``v / sqrt(f_s)`` (``Q = sigma^2 dt`` per step, as the filter integrates it).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

from swarm.errors import ConfigError
from swarm.sensors.profile import SensorProfile


def profile_keys(profile: SensorProfile, calibrating: bool) -> dict[str, object]:
    """The log.toml keys (dotted) a profile fills (module docstring); ``calibrating``: the log has a static
    segment that calibrates the white sigma and the offsets."""
    u, imu = profile.uwb, profile.imu
    keys: dict[str, object] = {"estimator.range_gm": u.gm_sigma_m > 0.0}
    if u.gm_sigma_m > 0.0:
        keys["estimator.range_gm_sigma_m"] = u.gm_sigma_m
        keys["estimator.range_gm_tau_s"] = u.gm_tau_s
    step = math.hypot(u.takeoff_step_m, u.takeoff_step_spread_m)
    keys["phases.reopen_sigma_m"] = step
    keys["robust.nlos_max_s"] = max(10.0, 3.0 * u.nlos_duration_s)
    if not calibrating:
        keys["uwb.sigma_m"] = u.sigma_m
        keys["initial.sigma_range_bias_m"] = max(u.offset_spread_m, 0.01)
    if imu.rate_hz > 0:
        keys["estimator.accel_noise"] = math.sqrt(
            imu.accel_noise_m_s2_rthz**2 + imu.accel_vibration_m_s2**2 / imu.rate_hz
        )
        keys["estimator.gyro_noise"] = math.sqrt(
            imu.gyro_noise_rad_s_rthz**2 + imu.gyro_vibration_rad_s**2 / imu.rate_hz
        )
    return keys


def given_keys(toml: Path) -> set[str]:
    """The dotted keys a log.toml gives (none without one)."""
    if not toml.is_file():
        return set()
    try:
        data = tomllib.loads(toml.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:  # read_log reports it with its line
        raise ConfigError(f"{toml}: {exc}") from exc
    out: set[str] = set()

    def walk(d: dict, prefix: str) -> None:
        for k, v in d.items():
            if isinstance(v, dict):
                walk(v, f"{prefix}{k}.")
            else:
                out.add(f"{prefix}{k}")

    walk(data, "")
    return out


def with_profile(log_dir: Path, profile: SensorProfile, overrides: dict[str, object]) -> dict[str, object]:
    """``overrides`` (``--set``) completed with the profile's keys that neither log.toml nor they give."""
    toml = Path(log_dir) / "log.toml"
    given = given_keys(toml) | set(overrides)
    calibrating = "calibration.until_s" in given or any(k.startswith("calibration.") for k in given)
    if calibrating:  # a static segment only if its length is not 0
        try:
            until = overrides.get("calibration.until_s")
            if until is None:
                until = tomllib.loads(toml.read_text()).get("calibration", {}).get("until_s", 0.0)
            calibrating = float(until) > 0.0
        except (OSError, ValueError, TypeError, tomllib.TOMLDecodeError):
            calibrating = False
    keys = profile_keys(profile, calibrating)
    return {**{k: v for k, v in keys.items() if k not in given}, **overrides}
