"""The range-error options of a UWB radio's ``[uwb]`` table, one dataclass for every mission's radio (the
docking radio, :class:`swarm.core.sensors.UwbParams`, and the landing one,
:class:`swarm.landing_scenario.LandingUwb`, add their own keys to it). The model they drive is
:mod:`swarm.core.range_errors` (docs/logs.md); all are off by default."""

from __future__ import annotations

from dataclasses import dataclass

from swarm.core.range_errors import check_range_errors


@dataclass(frozen=True)
class RangeErrorParams:
    """The range errors of real flights (:mod:`swarm.core.range_errors`): offsets, the take-off step,
    multipath and NLOS episodes in flight."""

    offset_m: float = 0.0
    """Common range offset [m] (an antenna delay: real Loco Positioning ranges read short, -0.17..-0.36)."""
    offset_spread_m: float = 0.0
    """Standard deviation of the per-anchor offsets around ``offset_m`` (uniform, drawn per run) [m]."""
    takeoff_bias_step_m: float = 0.0
    """Mean ground-to-air bias step [m], added while a vehicle is airborne (a docking vehicle of a planar
    kind is on the ground, the others fly)."""
    takeoff_bias_step_spread_m: float = 0.0
    """Standard deviation of that step over vehicle-anchor links (uniform, drawn per run) [m]."""
    multipath_sigma_m: float = 0.0
    """Stationary sigma of the time-correlated multipath error in flight, a first-order Gauss-Markov
    process per vehicle and anchor [m] (0: none)."""
    multipath_tau_s: float = 1.0
    """Its correlation time [s]."""
    nlos_episode_rate_hz: float = 0.0
    """Onset rate of sustained NLOS episodes per vehicle-anchor link in flight [1/s] (0: none)."""
    nlos_episode_s: float = 4.0
    """Mean length of an episode (exponential) [s]."""
    nlos_episode_excess_m: float = 0.3
    """Mean excess of an episode's ranges [m] (uniform in [0.5, 1.5] times this, drawn per episode)."""

    def __post_init__(self) -> None:
        check_range_errors(self)
