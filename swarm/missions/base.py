"""The mission plug-in interface (docs/architecture.md, "Missions").

A mission is what a run is for: docking a chaser with its target, landing a quadrotor on a pad. A scenario
file names its mission with its ``[mission]`` table, ``name = "landing"``; a file without the table is a
docking scenario. :class:`Mission` is what a command asks of that mission: how to load the file, and the
function each command runs (``swarm sim``, ``swarm launch``, ``swarm montecarlo``) given its parsed
arguments, and its campaign part (:meth:`Mission.campaign`), which the one campaign runner takes. The
dashboard asks it for the scenario to draw, live or from a recording.

An entry point is named by its dotted path (``"swarm.cli.sim:run_docking"``), as a packaging entry point
is, and imported when called: so this registry sits under the transport and the processes (the dashboard
consults it), while the commands it names sit above. A mission that has no runner of its own gives
:meth:`Mission.run_one` and gets ``swarm sim`` from the generic entry (:data:`GENERIC_SIM`) and a paired
campaign of its summaries (:mod:`swarm.montecarlo.summary_campaign`); ``swarm launch`` needs processes, so
it has none.
"""

from __future__ import annotations

import argparse
import importlib
import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, ClassVar

from swarm.errors import ConfigError

_LOG = logging.getLogger(__name__)

GENERIC_SIM = "swarm.cli.sim:run_mission"
"""``swarm sim`` of a mission that gives :meth:`Mission.run_one`: one run, its summary printed."""


def resolve(entry: str) -> Callable[..., Any]:
    """The function ``"package.module:function"`` names, its module imported now."""
    module, sep, attr = entry.partition(":")
    if not sep or not module or not attr:
        raise ValueError(f"an entry point is 'package.module:function', got {entry!r}")
    return getattr(importlib.import_module(module), attr)


def overrides_of(args: argparse.Namespace) -> dict:
    """The parsed ``--set KEY=VALUE`` overrides of ``args`` (none if the command has no ``--set``)."""
    from swarm.config import parse_override

    return dict(parse_override(text) for text in getattr(args, "overrides", None) or ())


class Mission:
    """One mission: a subclass sets the class attributes and implements :meth:`load`; an instance is
    registered in :data:`swarm.missions.MISSIONS` (:func:`swarm.missions.register`)."""

    name: ClassVar[str] = ""
    """What a scenario file's ``[mission] name = "..."`` says."""
    success_key: ClassVar[str] = ""
    """The run summary's flag that says the run reached its goal (``docked``, ``landed``)."""
    summary_metrics: ClassVar[tuple[str, ...]] = ()
    """Fields of one run's summary that say how it went, beside :attr:`success_key`."""
    fault_menu: ClassVar[tuple[str, ...]] = ()
    """The ``swarm fault`` kinds a live run of this mission applies (the others are refused)."""
    sim_entry: ClassVar[str] = GENERIC_SIM
    """``swarm sim``'s function, ``(args) -> exit code``."""
    launch_entry: ClassVar[str | None] = None
    """``swarm launch``'s function, ``(args) -> exit code``; None: the mission has no processes."""
    compile_entry: ClassVar[str | None] = None
    """``swarm compile``'s chain of this mission, ``"module:function"``: ``() -> None`` runs its kernels once
    on scratch objects, so numba's cache holds them (:mod:`swarm.cli.compile`); None: nothing to compile."""
    dashboard_drawer: ClassVar[str | None] = None
    """Its dashboard drawer, ``"module:Class"`` of a :class:`dashboard.drawer.MissionDrawer` (its scene,
    panels and fault menu); None: the dashboard refuses the mission."""
    campaign_entry: ClassVar[str | None] = None
    """Its campaign part, ``"module:NAME"`` of a :class:`~swarm.montecarlo.campaign.CampaignMission`; None:
    the campaign of :meth:`run_one`'s summaries (:meth:`campaign`)."""

    def load(self, scenario: str | Path, overrides: dict | None = None) -> Any:
        """The mission's scenario from a file or a bundled name, ``overrides`` (dotted keys) applied.
        ConfigError naming the file and the field for anything invalid."""
        raise NotImplementedError(f"mission {self.name!r} gives no load()")

    def scenario_keys(self) -> frozenset[str]:
        """The top-level keys a file of this mission may have, by which a file that forgot its ``[mission]``
        table is recognised (:func:`swarm.missions.mission_of`); none by default."""
        return frozenset()

    def run_one(self, scenario: Any, policy: str | None, seed: int) -> dict:
        """One run of ``scenario`` with ``policy`` (None: the scenario's) from root seed ``seed``: its
        summary, with :attr:`success_key` and :attr:`summary_metrics`. Used by the generic entries."""
        raise NotImplementedError(f"mission {self.name!r} gives no run_one()")

    def with_agents(self, scenario: Any, agents: int | None) -> Any:
        """``scenario`` for ``--agents N``; a mission whose files list every vehicle refuses N other than
        1 (None: not asked)."""
        if agents not in (None, 1):
            raise ConfigError(
                f"--agents: a {self.name} scenario lists its vehicles in the file, got --agents {agents}"
            )
        return scenario

    def run_sim(self, args: argparse.Namespace) -> int:
        """``swarm sim SCENARIO``: one in-process run; the exit code."""
        return int(resolve(self.sim_entry)(args) or 0)

    def run_launch(self, args: argparse.Namespace) -> int:
        """``swarm launch SCENARIO``: the run as processes over Zenoh; the exit code."""
        if self.launch_entry is None:
            raise ConfigError(
                f"{args.scenario}: mission {self.name!r} has no processes to launch (its Mission names no "
                "launch_entry); run it with `swarm sim`"
            )
        return int(resolve(self.launch_entry)(args) or 0)

    def rights(self, keys: Any, vehicle: str | None, platforms: tuple[str, ...]) -> dict | None:
        """What the mission's world (``vehicle`` None) or the agent of ``vehicle`` may send in a secured swarm
        (:func:`swarm.transport.security.rights`: ACL message kind -> key expressions under ``keys``, a
        :class:`swarm.transport.keys.Keys`; liveliness watching is added there). ``platforms``: the moving
        pads' robots, whose shared estimates the world puts and the agents read. None: no such process."""
        return None

    def campaign(self) -> Any:
        """What the campaign runner asks of this mission (:class:`swarm.montecarlo.campaign.CampaignMission`,
        ``swarm montecarlo``): :attr:`campaign_entry`'s, else the campaign of :meth:`run_one`'s summaries
        (:func:`swarm.montecarlo.summary_campaign.summary_campaign`)."""
        if self.campaign_entry is not None:
            return resolve(self.campaign_entry)
        from swarm.montecarlo.summary_campaign import summary_campaign

        return summary_campaign(self)

    def dashboard_scenario(self, args: argparse.Namespace) -> Any:
        """The scenario ``swarm dashboard SCENARIO`` draws a live swarm with (``--set``, ``--agents``)."""
        return self.with_agents(self.load(args.scenario, overrides_of(args)), args.agents)

    def playback_scenario(
        self, scenario: str | Path, overrides: dict | None, vehicle_ids: Sequence[str] | None
    ) -> Any:
        """The scenario to draw a recording of the vehicles ``vehicle_ids`` (None: not recorded) with."""
        return self.load(scenario, overrides)

    def __repr__(self) -> str:
        return f"<mission {self.name}>"
