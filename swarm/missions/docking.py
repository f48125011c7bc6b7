"""Docking (paper Fig. 5, Table II, Fig. 8): a chaser docks with its target. The default mission: a
scenario file without a ``mission`` key is a docking one (:class:`swarm.scenario.Scenario`)."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

from swarm.missions.base import Mission

_LOG = logging.getLogger(__name__)


class DockingMission(Mission):
    """The docking stack's runners: ``swarm/sim/docking.py``, the processes of ``swarm/cli/launch.py``,
    the campaign of ``swarm/montecarlo/campaign.py``."""

    name = "docking"
    # the summary's fields are each chaser's (summary["chasers"][id], swarm/step/outcome.py)
    success_key = "docked"
    summary_metrics = ("docking_time_s", "position_error_m", "attitude_error_rad", "effort")
    fault_menu = ("uwb_dropout", "nlos_burst", "camera_loss", "gyro_bias_step", "sensor_delay")
    sim_entry = "swarm.cli.sim:run_docking"
    launch_entry = "swarm.cli.launch:run_docking"
    compile_entry = "swarm.cli.compile:docking_kernels"
    dashboard_drawer = "dashboard.docking:DockingDrawer"
    campaign_entry = "swarm.montecarlo.campaign:DOCKING"

    def scenario_keys(self) -> frozenset[str]:
        """The top-level keys of a docking file: the fields of Scenario and the keys of the format before
        vehicle kinds (:data:`swarm.scenario.LEGACY_KEYS`), which it still reads."""
        from dataclasses import fields

        from swarm.scenario import LEGACY_KEYS, Scenario

        return frozenset(f.name for f in fields(Scenario)) | {old[0] for old in LEGACY_KEYS}

    def load(self, scenario: str | Path, overrides: dict | None = None):
        from swarm.scenario import load_scenario

        return load_scenario(scenario, overrides)

    def run_one(self, scenario, policy: str | None, seed: int) -> dict:
        """One in-process docking without series (``swarm sim``'s runner): its summary, each chaser's
        fields under ``chasers``."""
        from swarm.sim.docking import run_docking

        return run_docking(scenario, policy, seed, record_series=False)

    def with_agents(self, scenario, agents: int | None):
        """The scenario's vehicles copied ``agents`` times (:meth:`swarm.scenario.Scenario.with_pairs`)."""
        return scenario if agents is None else scenario.with_pairs(agents)

    def rights(self, keys, vehicle: str | None, platforms: tuple[str, ...]) -> dict:
        """The docking world (``swarm/world/process.py``) puts every vehicle's sensors and bundles; an agent
        (``agents/process.py``) reads its own and the shared ones, and every vehicle's estimate."""
        ns = keys.namespace
        if vehicle is None:
            return {
                "put": tuple(f"{ns}/{k}" for k in ("agent/*/imu agent/*/vision agent/*/truth agent/*/event "
                    "agent/*/bundle world/imu world/vision world/truth world/bundle world/clock "
                    "world/event").split()),
                "declare_subscriber": (keys.agent_all("command"), keys.agent_all("commands"),
                                       keys.run_control(), keys.fault()),
                "liveliness_token": (f"{ns}/alive/world/*",),
            }  # fmt: skip
        v = vehicle
        return {
            "put": (keys.estimate(v), keys.guidance(v), keys.command(v), keys.commands(v), keys.event(v)),
            "declare_subscriber": (keys.imu(v), keys.uwb(v), keys.tdoa(v), keys.vision(v), keys.bundle(v),
                                   keys.agent_all("estimate"), keys.world_imu(), keys.world_vision(),
                                   keys.mothership_uwb(), keys.mothership_tdoa(),
                                   keys.world_clock(), keys.world_event()),  # world_resumed
            "liveliness_token": (keys.alive("agent", v),),
        }  # fmt: skip

    def playback_scenario(
        self, scenario: str | Path, overrides: dict | None, vehicle_ids: Sequence[str] | None
    ):
        """The scenario, copied into as many pairs as the recorded vehicles are (``swarm launch --agents
        N``); as it is, with a warning, when they do not match a copy of it."""
        sc = self.load(scenario, overrides)
        if vehicle_ids is None or set(vehicle_ids) == set(sc.vehicles):
            return sc
        per_pair = len(sc.vehicles)
        n = len(vehicle_ids) // per_pair if per_pair else 0
        if per_pair and len(vehicle_ids) % per_pair == 0 and 1 < n <= 64:
            copies = sc.with_pairs(n)
            if set(copies.vehicles) == set(vehicle_ids):
                return copies
        ids, own = list(vehicle_ids), list(sc.vehicles)
        _LOG.warning("the recording's vehicles %s are not the scenario's %s", ids, own)
        return sc
