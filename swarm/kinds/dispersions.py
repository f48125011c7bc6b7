"""Per-run dispersions of a Monte Carlo campaign, declared in the scenario's ``[dispersions]`` table and in
each kind's ``[kinds.<kind>.dispersions]``.

What varies from run to run, and where it is declared:

* initial estimate errors: ``[initial]`` (Gaussian, standard deviations ``sigma_*``), each vehicle's
  ``init`` stream (:func:`swarm.step.initial.initial_estimate`), always on;
* sensor noise realisations: every sensor table (gyro, AHRS, UWB, camera), one stream per vehicle and
  sensor (:func:`swarm.step.streams.stream`), always on;
* everything in :class:`DispersionParams` below, off (all zero) by default: the chasers' initial true
  pose and velocity, and every vehicle's own true mass and inertia (the vehicles' own models keep the
  nominal values, so these are model errors the closed loop has to absorb);
* each kind's own, off by default: a cube's nozzle misalignment
  (``kinds.cubesat.dispersions.thruster_misalignment_deg``), a wheeled module's wheel slip
  (``kinds.ground.dispersions.wheel_slip_sigma_frac``).

All of them derive from the run's seed alone, and the world applies them itself when it is built
(:class:`swarm.step.world.World`), so no runner can leave them out and a run is a function of (scenario,
policy, seed): ``swarm sim SCENARIO --seed S`` re-runs it. Each quantity of each vehicle has its own
stream (:func:`dispersion_rng`), so switching one dispersion on does not change the draws of another, and
a quantity draws the same numbers whatever the policy (paired runs). A planar kind (a ground module) draws
the same numbers and keeps their in-plane part: no height, roll or pitch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from swarm.errors import ConfigError
from swarm.kinds.base import VehicleDispersion

DISPERSION_KEY = 1000
"""First word of the dispersion streams' spawn keys ``(1000, quantity, vehicle)``: three words, so they
never coincide with the two-word ``(vehicle, sensor)`` keys of :func:`swarm.step.streams.stream`."""

QUANTITIES = ("position", "velocity", "attitude", "mass", "inertia", "thrusters", "wheel_slip")
"""The quantities in stream order (the second word of the spawn key); a kind's own quantities too."""

MAX_FRACTION_SIGMA = 0.1
"""Largest relative standard deviation of mass and inertia: keeps ``1 + e`` positive and the principal
moments a valid inertia (triangle inequality) short of a 10-sigma draw."""


SIGMAS = (
    "position_sigma_m",
    "velocity_sigma_m_s",
    "attitude_sigma_deg",
    "mass_sigma_frac",
    "inertia_sigma_frac",
)
"""The dispersion sizes of :class:`DispersionParams` (each >= 0; zero switches it off)."""


@dataclass(frozen=True)
class DispersionParams:
    """Run-to-run dispersions shared by every kind, drawn from the run's seed (module docstring). Zero
    switches one off."""

    distribution: Literal["normal", "uniform"] = "normal"
    """Distribution of every draw (the kinds' own too), zero mean with the given standard deviation:
    ``"normal"`` (Gaussian) or ``"uniform"`` on ``[-sqrt(3) sigma, +sqrt(3) sigma]`` (the same standard
    deviation)."""
    position_sigma_m: float = 0.0
    """Initial true position of every chaser, per nav axis [m]. The initial estimate follows the truth
    (plus the ``[initial]`` error); the mission attitude and the target do not move."""
    velocity_sigma_m_s: float = 0.0
    """Initial true velocity of every chaser, per nav axis [m/s] (nominally at rest)."""
    attitude_sigma_deg: float = 0.0
    """Initial true attitude of every chaser: ``q0 (x) exp(e)``, ``e`` per body axis [deg]."""
    mass_sigma_frac: float = 0.0
    """Truth mass of each vehicle times its own ``1 + e``; the agents keep the nominal mass. At most
    ``MAX_FRACTION_SIGMA``."""
    inertia_sigma_frac: float = 0.0
    """Truth principal moments of each vehicle times ``1 + e_i``, one ``e_i`` per axis; the agents keep the
    nominal inertia. At most ``MAX_FRACTION_SIGMA``."""

    def __post_init__(self) -> None:
        if self.distribution not in ("normal", "uniform"):
            raise ConfigError(
                f"dispersions.distribution must be 'normal' or 'uniform', got {self.distribution!r}"
            )
        for name in SIGMAS:
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"dispersions.{name} must be a non-negative finite number, got {v!r}")
        for name in ("mass_sigma_frac", "inertia_sigma_frac"):
            v = getattr(self, name)
            if v > MAX_FRACTION_SIGMA:
                raise ConfigError(f"dispersions.{name} must be at most {MAX_FRACTION_SIGMA}, got {v!r}")

    @property
    def enabled(self) -> bool:
        """Whether any dispersion of this table is on (the kinds' own: :func:`enabled`)."""
        return any(getattr(self, n) > 0 for n in SIGMAS)


def enabled(scenario) -> bool:
    """Whether any dispersion of the scenario is on: its ``[dispersions]`` or a used kind's own."""
    return scenario.dispersions.enabled or any(
        scenario.kind(vid).dispersion_enabled() for vid in scenario.vehicles
    )


def dispersion_rng(seed: int, quantity: str, vehicle_index: int = 0) -> np.random.Generator:
    """The stream of one dispersed ``quantity`` (one of :data:`QUANTITIES`) of one vehicle for root
    ``seed``."""
    key = (DISPERSION_KEY, QUANTITIES.index(quantity), int(vehicle_index))
    return np.random.default_rng(np.random.SeedSequence(entropy=int(seed), spawn_key=key))


def draw(rng: np.random.Generator, sigma: float, size: int, distribution: str) -> np.ndarray:
    """``size`` zero-mean draws with standard deviation ``sigma`` (``"normal"`` or ``"uniform"``)."""
    if distribution == "uniform":
        half = math.sqrt(3.0) * sigma
        return rng.uniform(-half, half, size=size)
    return rng.normal(0.0, sigma, size=size)


@dataclass(frozen=True)
class Dispersion:
    """The dispersions of one run, as drawn (zeros / ones where a quantity is off)."""

    vehicles: dict[str, VehicleDispersion]
    """Vehicle id -> its draws."""

    # the chasers' views the campaign tables and the tests read
    @property
    def position_m(self) -> dict[str, np.ndarray]:
        return {v: d.position_m for v, d in self.vehicles.items()}

    @property
    def velocity_m_s(self) -> dict[str, np.ndarray]:
        return {v: d.velocity_m_s for v, d in self.vehicles.items()}

    @property
    def attitude_rad(self) -> dict[str, np.ndarray]:
        return {v: d.attitude_rad for v, d in self.vehicles.items()}


def draw_dispersion(scenario, seed: int) -> Dispersion:
    """Draw one run's dispersions from its ``seed`` (:func:`dispersion_rng`, one stream per quantity and
    vehicle). A quantity whose standard deviation is zero draws nothing and is exactly nominal."""
    p: DispersionParams = scenario.dispersions
    dist = p.distribution
    chasers = set(scenario.chasers)
    out = {}
    for i, vid in enumerate(scenario.vehicles):
        kind = scenario.kind(vid)
        d = VehicleDispersion()
        if vid in chasers:
            if p.position_sigma_m > 0:
                d.position_m = draw(dispersion_rng(seed, "position", i), p.position_sigma_m, 3, dist)
            if p.velocity_sigma_m_s > 0:
                d.velocity_m_s = draw(dispersion_rng(seed, "velocity", i), p.velocity_sigma_m_s, 3, dist)
            if p.attitude_sigma_deg > 0:
                sigma = math.radians(p.attitude_sigma_deg)
                d.attitude_rad = draw(dispersion_rng(seed, "attitude", i), sigma, 3, dist)
            if kind.planar:  # the same draws, in the table's plane: no height, roll or pitch
                d.position_m[2] = d.velocity_m_s[2] = 0.0
                d.attitude_rad[0:2] = 0.0
        if p.mass_sigma_frac > 0:
            d.mass_factor = 1.0 + float(draw(dispersion_rng(seed, "mass", i), p.mass_sigma_frac, 1, dist)[0])
        if p.inertia_sigma_frac > 0:
            d.inertia_factor = 1.0 + draw(dispersion_rng(seed, "inertia", i), p.inertia_sigma_frac, 3, dist)
        d.kind = kind.draw_dispersion(seed, i, dist)
        out[vid] = d
    return Dispersion(out)


def dispersion_columns(scenario, disp: Dispersion, chaser: str) -> dict[str, float]:
    """The drawn values of one chaser's run as flat CSV columns (``disp_*``)."""
    d = disp.vehicles[chaser]
    out = {}
    for name, vec in (("pos", d.position_m), ("vel", d.velocity_m_s), ("att", d.attitude_rad)):
        for axis, v in zip("xyz", vec, strict=True):
            out[f"disp_{name}_{axis}"] = float(v)
    out["disp_mass_factor"] = float(d.mass_factor)
    for axis, v in zip("xyz", d.inertia_factor, strict=True):
        out[f"disp_inertia_factor_{axis}"] = float(v)
    out.update(scenario.kind(chaser).dispersion_columns(d.kind))
    return out
