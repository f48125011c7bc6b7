"""Sensor profiles: the numbers of a range error model and an IMU noise model (``swarm.sensors.profile``)."""

from __future__ import annotations

from swarm.sensors.profile import (
    AnchorProfile,
    ImuProfile,
    SensorProfile,
    UwbProfile,
    bundled_profiles,
    load_profile,
    profile_toml,
    save_profile,
)

__all__ = [
    "AnchorProfile",
    "ImuProfile",
    "SensorProfile",
    "UwbProfile",
    "bundled_profiles",
    "load_profile",
    "profile_toml",
    "save_profile",
]
