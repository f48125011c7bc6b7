"""A scenario's sensor profile (``[sensors] profile = "real-crazyflie"``, or a path): the profile's numbers
(:class:`swarm.sensors.profile.SensorProfile`) become the scenario's ``[uwb]`` and IMU options, keys the
scenario sets itself winning (and ``--set`` overrides over both).

The mapping (:func:`profile_options`), profile key -> scenario key, lands on the tables and keys the
scenario's schema has (:func:`apply_sensor_profile` leaves out the others): a docking scenario
(:class:`swarm.scenario.Scenario`) has ``[gyro]`` and the uniform NLOS keys, a landing one
(:class:`swarm.landing_scenario.LandingScenario`) ``[imu]`` and the outlier keys. So the options name no
mission:

* ``uwb.sigma_m`` -> ``uwb.sigma_m`` (the in-flight white noise);
* ``uwb.offset_m``, ``offset_spread_m`` -> ``uwb.offset_m``, ``uwb.offset_spread_m``;
* ``uwb.takeoff_step_m``, ``takeoff_step_spread_m`` -> ``uwb.takeoff_bias_step_m``,
  ``uwb.takeoff_bias_step_spread_m``;
* ``uwb.gm_sigma_m``, ``gm_tau_s`` -> ``uwb.multipath_sigma_m``, ``uwb.multipath_tau_s``;
* ``uwb.nlos_rate_hz``, ``nlos_duration_s``, ``nlos_excess_m`` -> ``uwb.nlos_episode_rate_hz``,
  ``uwb.nlos_episode_s``, ``uwb.nlos_episode_excess_m``;
* ``uwb.outlier_share``, ``outlier_excess_m`` -> landing: ``uwb.outlier_probability``,
  ``uwb.outlier_excess_m``; docking: ``uwb.nlos_probability``, with ``uwb.nlos_min_m = 0`` and
  ``uwb.nlos_max_m = 2 outlier_excess_m`` (a uniform excess of the same mean);
* ``imu.gyro_noise_rad_s_rthz`` -> landing: ``imu.gyro_noise_rad_s_rthz``; docking:
  ``gyro.gyro_noise_rad_s_rthz``;
* ``imu.accel_noise_m_s2_rthz`` -> landing: ``imu.accel_noise_m_s2_rthz`` (a docking kind has no
  accelerometer);
* ``imu.gyro_bias_instability_rad_s`` -> docking, when > 0: ``gyro.bias_instability_deg_h``;
* ``imu.accel_vibration_m_s2``, ``gyro_vibration_rad_s`` -> landing: ``imu.vibration_accel_m_s2``,
  ``imu.vibration_gyro_rad_s``.

Not mapped: the profile's ground white noise (the simulated radios have one sigma), its per-anchor
measurements (a scenario's anchors are not the fitted room's), the accelerometer's bias instability.
"""

from __future__ import annotations

import dataclasses
import math
import os
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from swarm.errors import ConfigError
from swarm.sensors.profile import SensorProfile, load_profile


@dataclass(frozen=True)
class SensorsSpec:
    """``[sensors]`` of a scenario."""

    profile: str = ""
    """A sensor profile (a bundled name such as ``"real-crazyflie"``, or a ``sensors.toml`` path, relative to
    the scenario file's folder or the working directory) whose numbers fill the ``[uwb]`` and IMU options
    the scenario leaves out (module docstring); empty: none."""


def profile_options(profile: SensorProfile) -> dict[str, dict[str, Any]]:
    """The scenario options (``{table: {key: value}}``) that ``profile`` gives, for every table and key a
    scenario may have (module docstring)."""
    u, i = profile.uwb, profile.imu
    uwb: dict[str, Any] = {
        "sigma_m": u.sigma_m,
        "offset_m": u.offset_m,
        "offset_spread_m": u.offset_spread_m,
        "takeoff_bias_step_m": u.takeoff_step_m,
        "takeoff_bias_step_spread_m": u.takeoff_step_spread_m,
        "multipath_sigma_m": u.gm_sigma_m,
        "multipath_tau_s": u.gm_tau_s,
        "nlos_episode_rate_hz": u.nlos_rate_hz,
        "nlos_episode_s": u.nlos_duration_s,
        "nlos_episode_excess_m": u.nlos_excess_m,
    }
    uwb |= {"outlier_probability": u.outlier_share, "outlier_excess_m": u.outlier_excess_m}
    imu = {
        "accel_noise_m_s2_rthz": i.accel_noise_m_s2_rthz,
        "gyro_noise_rad_s_rthz": i.gyro_noise_rad_s_rthz,
        "vibration_accel_m_s2": i.accel_vibration_m_s2,
        "vibration_gyro_rad_s": i.gyro_vibration_rad_s,
    }
    uwb |= {"nlos_probability": u.outlier_share, "nlos_min_m": 0.0, "nlos_max_m": 2.0 * u.outlier_excess_m}
    gyro: dict[str, Any] = {"gyro_noise_rad_s_rthz": i.gyro_noise_rad_s_rthz}
    if i.gyro_bias_instability_rad_s > 0:
        gyro["bias_instability_deg_h"] = math.degrees(i.gyro_bias_instability_rad_s) * 3600.0
    return {"uwb": uwb, "imu": imu, "gyro": gyro}


def _resolve(profile: str, scenario_file: str) -> str | os.PathLike[str]:
    """A profile path relative to the scenario file's folder if it is there, else as given."""
    near = Path(scenario_file).parent / profile
    return near if Path(profile).suffix and not Path(profile).is_absolute() and near.is_file() else profile


def apply_sensor_profile(
    data: dict[str, Any], scenario_file: str, schema: type, overrides: dict | None = None
) -> dict[str, Any]:
    """The parsed scenario ``data`` with its ``[sensors] profile`` (or the ``sensors.profile`` of
    ``overrides``) filled in: each option of :func:`profile_options` that the scenario's ``schema`` (its
    dataclass) has and the scenario does not set. A profile that cannot be read is a ConfigError naming
    the scenario file and the profile."""
    name = (overrides or {}).get("sensors.profile", (data.get("sensors") or {}).get("profile", ""))
    if not name:
        return data
    if not isinstance(name, str):
        raise ConfigError(f"{scenario_file}: sensors.profile must be a name or a path, got {name!r}")
    try:
        profile = load_profile(_resolve(name, scenario_file))
    except ConfigError as exc:
        raise ConfigError(f"{scenario_file}: sensors.profile {name!r}: {exc}") from exc
    out, tables = dict(data), typing.get_type_hints(schema)
    for table, values in profile_options(profile).items():
        if not dataclasses.is_dataclass(tables.get(table)):
            continue  # a table this scenario does not have
        have, keys = dict(out.get(table) or {}), {f.name for f in dataclasses.fields(tables[table])}
        for key, value in values.items():
            if key in keys:
                have.setdefault(key, value)
        out[table] = have
    return out
