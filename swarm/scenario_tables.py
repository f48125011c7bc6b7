"""The tables every mission's scenario file shares: ``[mission]``, which names the file's mission, and the
sensor and estimate tables that mean the same in every mission (``[initial]``; ``[tdoa]`` is
:class:`swarm.core.tdoa_radio.TdoaParams`, ``[sensors]`` :class:`swarm.sensors.options.SensorsSpec`).

A table read by two missions is one dataclass here, its fields the union of what the missions read: a
mission that does not read a field leaves it at its default. Each mission's scenario picks its own
defaults with a default instance (:mod:`swarm.config`: a key missing from a table keeps the value of the
enclosing field's default instance)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from swarm.config import _locate
from swarm.errors import ConfigError


@dataclass(frozen=True)
class MissionTable:
    """``[mission]``: what the scenario is for (:data:`swarm.missions.MISSIONS`), read before the mission's
    schema is (:func:`swarm.missions.mission_of`). A file without the table is a docking one."""

    name: str = "docking"
    """The registered mission's name: ``"docking"``, ``"landing"``, ..."""


def refuse_mission_key(data: dict, file: str) -> None:
    """ConfigError naming ``file``, the line and the value if the parsed scenario ``data`` names its mission
    with the top-level key of the format before ``[mission]`` (``mission = "landing"``): the table to write
    instead, as :mod:`swarm.config` refuses a renamed key."""
    value = data.get("mission")
    if value is None or isinstance(value, dict):
        return
    shown = f'"{value}"' if isinstance(value, str) else repr(value)
    at = _locate(file, "mission: ")
    where = "" if at is None else f" (line {at[0]})"
    raise ConfigError(
        f"{file}{where}: mission = {shown}: the mission is a table now; write [mission] name = {shown} "
        "instead (after the top-level keys)"
    )


def check_mission(mission: MissionTable, name: str) -> None:
    """ConfigError unless ``mission`` (a scenario's ``[mission]``) names ``name``, its schema's mission."""
    if mission.name != name:
        raise ConfigError(f"mission.name must be {name!r} for a {name} scenario, got {mission.name!r}")


@dataclass(frozen=True)
class InitialEstimateParams:
    """``[initial]``: a vehicle's first estimate is its truth plus a Gaussian error with these standard
    deviations, which are also the filter's initial covariance. The bias and offset sigmas are the
    IMU-driven filter's states (landing); the MEKF (docking) has none of them and leaves them unread."""

    RENAMED: ClassVar[dict[str, tuple[str, float]]] = {
        "sigma_pos_m": ("sigma_position_m", 1.0),
        "sigma_vel_m_s": ("sigma_velocity_m_s", 1.0),
        "sigma_att_deg": ("sigma_attitude_deg", 1.0),
    }
    """Keys of older files and the names that replaced them (:mod:`swarm.config`)."""

    sigma_position_m: float = 0.05
    sigma_velocity_m_s: float = 0.005
    sigma_attitude_deg: float = 2.0
    sigma_accel_bias_m_s2: float = 0.02
    sigma_gyro_bias_rad_s: float = 0.002
    sigma_range_offset_m: float = 0.1
    """Prior of each anchor's range offset (``[estimator] range_bias``) [m]."""
    sigma_common_offset_m: float = 0.5
    """Prior of the offset common to every anchor (``[estimator] range_common_offset``) [m]: a Loco
    Positioning tag's antenna delay reads ranges 0.2-0.4 m short."""

    def __post_init__(self) -> None:
        for name in ("sigma_position_m", "sigma_velocity_m_s", "sigma_attitude_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"initial.{name} must be a positive number, got {v!r}")

    @property
    def sigmas(self) -> np.ndarray:
        """(9,) standard deviations in the MEKF's error-state order (d_p, d_v, d_theta)."""
        return np.array(
            [self.sigma_position_m] * 3
            + [self.sigma_velocity_m_s] * 3
            + [np.radians(self.sigma_attitude_deg)] * 3
        )
