"""Missions as plug-ins (docs/architecture.md, "Missions").

:data:`MISSIONS` maps a scenario file's ``[mission] name = "..."`` to its :class:`Mission`;
:func:`mission_of` is the one place a command, the dashboard or a playback asks which mission a scenario
is. A file without the table is a docking one (:data:`DEFAULT_MISSION`). :func:`register` adds a mission.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from swarm.config import _locate
from swarm.errors import ConfigError
from swarm.missions.base import GENERIC_SIM, Mission, overrides_of, resolve
from swarm.missions.docking import DockingMission
from swarm.missions.landing import LandingMission
from swarm.scenario_tables import refuse_mission_key

SCENARIO_DIR = Path(__file__).resolve().parent.parent / "scenarios"
"""Where the bundled scenarios are (``swarm/scenarios/<name>.toml``)."""

DEFAULT_MISSION = "docking"
"""The mission of a scenario file without a ``[mission]`` table."""

MISSIONS: dict[str, Mission] = {m.name: m for m in (DockingMission(), LandingMission())}
"""Every registered mission by name."""


def register(mission: Mission) -> Mission:
    """Add ``mission`` to :data:`MISSIONS` (and return it); ConfigError if its name is empty or taken."""
    if not isinstance(mission, Mission) or not isinstance(mission.name, str) or not mission.name:
        raise ConfigError(f"a mission is a Mission with a name, got {mission!r}")
    if mission.name in MISSIONS:
        raise ConfigError(
            f"mission {mission.name!r} is registered already ({MISSIONS[mission.name]!r}); "
            f"registered: {', '.join(sorted(MISSIONS))}"
        )
    MISSIONS[mission.name] = mission
    return mission


def scenario_path(scenario: str | Path) -> Path:
    """A scenario file, or a bundled one by name (``"landing"`` -> ``swarm/scenarios/landing.toml``), as
    the scenarios' loaders find them."""
    path = Path(scenario)
    return SCENARIO_DIR / f"{scenario}.toml" if not path.suffix and not path.exists() else path


def mission_of(scenario: str | Path) -> Mission:
    """The mission of ``scenario`` (a file or a bundled name), from its ``[mission]`` table's ``name``.

    ConfigError naming the file, the line and the value for a name that is not a registered mission, for
    the top-level ``mission = "..."`` of the format before the table (the table to write instead), and for
    a file without the table that has another mission's tables (``[pad]`` without ``[mission] name =
    "landing"``). A file that cannot be read or parsed is left to the default mission's loader, which names
    the problem."""
    path = scenario_path(scenario)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return MISSIONS[DEFAULT_MISSION]
    refuse_mission_key(data, str(path))
    if "mission" in data:
        value = data["mission"].get("name", DEFAULT_MISSION)
        if isinstance(value, str) and value in MISSIONS:
            return MISSIONS[value]
        raise ConfigError(
            f"{path}{_at(path, 'mission.name')}: mission.name = {_toml(value)} is not a registered mission; "
            f"registered: {', '.join(sorted(MISSIONS))}"
        )
    default = MISSIONS[DEFAULT_MISSION]
    unknown = set(data) - default.scenario_keys()
    if unknown:
        claims = {}
        for m in MISSIONS.values():
            if m.name != DEFAULT_MISSION:
                claims[m.name] = sorted(unknown & (m.scenario_keys() - default.scenario_keys()))
        name, keys = max(sorted(claims.items()), key=lambda kv: len(kv[1]), default=("", []))
        if keys:
            where = ", ".join(f"{k}{_at(path, k)}" for k in keys[:4]) + (
                f" and {len(keys) - 4} more" if len(keys) > 4 else ""
            )
            raise ConfigError(
                f"{path}: {where} {'is a key' if len(keys) == 1 else 'are keys'} of a {name} scenario, and "
                f"the file has no [mission] table ({DEFAULT_MISSION} is assumed then): write [mission] "
                f'name = "{name}" after its top-level keys'
            )
    return default


def _toml(value: object) -> str:
    """``value`` as TOML writes it (a string in double quotes)."""
    return f'"{value}"' if isinstance(value, str) else repr(value)


def _at(path: Path, key: str) -> str:
    """`` (line N)``: the line of ``path`` that sets the dotted ``key`` or opens its table (``""``: none)."""
    at = _locate(path, f"{key}: ")
    return "" if at is None else f" (line {at[0]})"


__all__ = [
    "DEFAULT_MISSION",
    "GENERIC_SIM",
    "MISSIONS",
    "Mission",
    "mission_of",
    "overrides_of",
    "register",
    "resolve",
    "scenario_path",
]
