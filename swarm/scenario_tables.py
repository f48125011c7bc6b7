"""The tables every mission's scenario file shares: ``[mission]``, which names the file's mission, and the
sensor and estimate tables that mean the same in every mission (``[initial]``; ``[tdoa]`` is
:class:`swarm.core.tdoa_radio.TdoaParams`, ``[sensors]`` :class:`swarm.sensors.options.SensorsSpec`).

A table read by two missions is one dataclass here, its fields the union of what the missions read: a
mission that does not read a field leaves it at its default. Each mission's scenario picks its own
defaults with a default instance (:mod:`swarm.config`: a key missing from a table keeps the value of the
enclosing field's default instance)."""

from __future__ import annotations

from dataclasses import dataclass

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
