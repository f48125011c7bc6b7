"""Landing (paper sec. VI-B): a quadrotor lands on a pad with an ArUco board; ``[mission] name = "landing"``
(:class:`swarm.landing_scenario.LandingScenario`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from swarm.errors import ConfigError
from swarm.missions.base import Mission


class LandingMission(Mission):
    """The landing stack's runners: ``swarm/sim/landing.py``, the processes of
    ``swarm/cli/launch.py``, the campaign of ``swarm/montecarlo/landing.py``."""

    name = "landing"
    success_key = "landed"
    summary_metrics = ("landing_error_m", "landing_time_s", "energy_j", "deviation_distance_m")
    fault_menu = ("camera_loss", "uwb_dropout")  # what swarm/world/landing.py applies
    sim_entry = "swarm.cli.sim:run_landing"
    launch_entry = "swarm.cli.launch:run_landing"
    compile_entry = "swarm.cli.compile:landing_kernels"
    dashboard_drawer = "dashboard.landing:LandingDrawer"
    campaign_entry = "swarm.montecarlo.landing:CAMPAIGN"

    def scenario_keys(self) -> frozenset[str]:
        """The fields of LandingScenario."""
        from dataclasses import fields

        from swarm.landing_scenario import LandingScenario

        return frozenset(f.name for f in fields(LandingScenario))

    def load(self, scenario: str | Path, overrides: dict | None = None):
        from swarm.landing_scenario import load_landing

        return load_landing(scenario, overrides)

    def run_one(self, scenario, policy: str | None, seed: int) -> dict:
        """One in-process landing of the scenario's first UAV without series (``swarm sim``'s runner)."""
        from swarm.sim.landing import run_landing

        return run_landing(scenario, policy, seed, record_series=False)

    def with_agents(self, scenario, agents: int | None):
        """The scenario as it is: its UAVs are the file's (``[[fleet]]``), so ``--agents`` other than 1
        is refused."""
        if agents not in (None, 1):
            raise ConfigError("--agents: a landing scenario lists its UAVs ([[fleet]] in the file)")
        return scenario

    def rights(self, keys, vehicle: str | None, platforms: tuple[str, ...]) -> dict:
        """The landing world (``swarm/world/landing.py``) puts every UAV's sensors, its clock and each
        robot's shared estimate; a landing agent (``agents/landing.py``) reads its own sensors and the
        robots' estimates, and puts its commands one UAV at a time."""
        ns = keys.namespace
        if vehicle is None:
            return {
                "put": tuple(f"{ns}/{k}" for k in ("agent/*/imu agent/*/uwb agent/*/tdoa agent/*/gnss "
                    "agent/*/rangefinder agent/*/barometer agent/*/vision agent/*/truth world/clock "
                    "world/event").split())
                + tuple(keys.estimate(p) for p in platforms),
                "declare_subscriber": (keys.agent_all("command"), keys.run_control(), keys.fault()),
                "liveliness_token": (f"{ns}/alive/world/*",),
            }  # fmt: skip
        v = vehicle
        return {
            "put": (keys.estimate(v), keys.guidance(v), keys.command(v), keys.event(v)),
            "declare_subscriber": (keys.imu(v), keys.uwb(v), keys.tdoa(v), keys.gnss(v), keys.rangefinder(v),
                                   keys.barometer(v), keys.vision(v), keys.world_event(),
                                   *(keys.estimate(p) for p in platforms)),
            "liveliness_token": (keys.alive("agent", v),),
        }  # fmt: skip

    def run_launch(self, args: argparse.Namespace) -> int:
        """The landing launcher, a process per UAV unless ``--vehicles-per-process`` says (a landing swarm
        has no automatic plan, :mod:`swarm.cli.launch_plan`)."""
        if args.vehicles_per_process is None:
            args.vehicles_per_process = 1
        return super().run_launch(args)
