"""Navigation as a registry (docs/architecture.md, "Navigation"): one interface over the filters.

:data:`NAVIGATORS` maps a name to its :class:`~swarm.navigation.base.Navigator` class: ``"mekf"`` (the
paper's multiplicative EKF) and ``"eskf"`` (the IMU-driven error-state filter). A vehicle's navigator
follows from what its kind's IMU measures (:func:`navigator_name`): an IMU with an accelerometer gets
``"eskf"``, a gyro alone ``"mekf"``; a scenario may name one per vehicle (``navigation = "..."``).
"""

from __future__ import annotations

from collections.abc import Set

from swarm.errors import ConfigError
from swarm.navigation.base import Fused, Navigator, NavState, check_docking_navigator
from swarm.navigation.eskf import Eskf
from swarm.navigation.mekf import Mekf

NAVIGATORS: dict[str, type[Navigator]] = {n.name: n for n in (Mekf, Eskf)}
"""Every registered navigator by name."""


def navigator_name(imu_measures: Set[str], override: str | None = None, where: str = "vehicle") -> str:
    """The navigator of a vehicle whose IMU measures ``imu_measures`` (``{"gyro"}``, ``{"gyro",
    "accelerometer"}``): ``override`` when given (a scenario's ``<where>.navigation``), else ``"eskf"`` with
    an accelerometer and ``"mekf"`` without. ConfigError naming ``<where>.navigation`` and its value when the
    name is not registered (the registered names listed) or the IMU lacks what that filter needs."""
    if override is None:
        return Eskf.name if "accelerometer" in imu_measures else Mekf.name
    nav = NAVIGATORS.get(override)
    if nav is None:
        raise ConfigError(f"{where}.navigation must be one of {sorted(NAVIGATORS)}, got {override!r}")
    missing = sorted(nav.needs - set(imu_measures))
    if missing:
        raise ConfigError(
            f"{where}.navigation = {override!r} needs an IMU that measures {', '.join(missing)} "
            f"({nav.summary}); this vehicle's IMU measures {', '.join(sorted(imu_measures))}"
        )
    return override


__all__ = [
    "NAVIGATORS",
    "Eskf",
    "Fused",
    "Mekf",
    "NavState",
    "Navigator",
    "check_docking_navigator",
    "navigator_name",
]
