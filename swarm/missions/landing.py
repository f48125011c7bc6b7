"""Landing (paper sec. VI-B): a quadrotor lands on a pad with an ArUco board; ``mission = "landing"``
(:class:`swarm.landing_scenario.LandingScenario`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from swarm.errors import ConfigError
from swarm.missions.base import Mission


class LandingMission(Mission):
    """The landing stack's runners: ``swarm/sim/landing.py``, the processes of
    ``swarm/cli/launch_landing.py``, the campaign of ``swarm/montecarlo/landing.py``."""

    name = "landing"
    success_key = "landed"
    summary_metrics = ("landing_error_m", "landing_time_s", "energy_j", "deviation_distance_m")
    fault_menu = ("camera_loss", "uwb_dropout")  # what swarm/world/landing.py applies
    sim_entry = "swarm.cli.sim:run_landing"
    launch_entry = "swarm.cli.launch_landing:run_landing_launch"
    montecarlo_entry = "swarm.cli.montecarlo:run_landing"

    def scenario_keys(self) -> frozenset[str]:
        """The fields of LandingScenario."""
        from dataclasses import fields

        from swarm.landing_scenario import LandingScenario

        return frozenset(f.name for f in fields(LandingScenario))

    def load(self, scenario: str | Path, overrides: dict | None = None):
        from swarm.landing_scenario import load_landing

        return load_landing(scenario, overrides)

    def campaign_metrics(self) -> tuple[str, ...]:
        """The landing campaign's metrics (:data:`swarm.montecarlo.landing.METRICS`)."""
        from swarm.montecarlo.landing import METRICS

        return tuple(METRICS)

    def with_agents(self, scenario, agents: int | None):
        """The scenario as it is: its UAVs are the file's (``[[fleet]]``), so ``--agents`` other than 1
        is refused."""
        if agents not in (None, 1):
            raise ConfigError("--agents: a landing scenario lists its UAVs ([[fleet]] in the file)")
        return scenario

    def run_launch(self, args: argparse.Namespace) -> int:
        """The landing launcher, a process per UAV unless ``--vehicles-per-process`` says (a landing swarm
        has no automatic plan, :mod:`swarm.cli.launch_plan`)."""
        if args.vehicles_per_process is None:
            args.vehicles_per_process = 1
        return super().run_launch(args)
