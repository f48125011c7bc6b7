"""Per-run dispersions of a Monte Carlo campaign, declared in the scenario's ``[dispersions]`` table.

What varies from run to run, and where it is declared:

* initial estimate errors: ``[initial]`` (Gaussian, standard deviations ``sigma_*``), each vehicle's
  ``init`` stream (:func:`swarm.sim.docking.initial_estimate`), always on;
* sensor noise realisations: every sensor table (gyro, AHRS, UWB, camera), one stream per vehicle and
  sensor (:func:`swarm.core.world.stream`), always on;
* everything in :class:`DispersionParams` below, off (all zero) by default: the chasers' initial true
  pose and velocity, and the truth's mass, inertia and nozzle directions (the vehicles' own models keep
  the nominal values, so these are model errors the closed loop has to absorb).

All of them derive from the run's seed alone, and :class:`swarm.sim.docking.DockingSim` applies them
itself, so a run is a function of (scenario, policy, seed): ``swarm sim SCENARIO --seed S`` re-runs it.
Each quantity has its own stream (:func:`dispersion_rng`), so switching one dispersion on does not
change the draws of another, and a quantity draws the same numbers whatever the policy (paired runs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from swarm.core import rotations as rot
from swarm.core.thrusters import N_NOZZLES
from swarm.errors import ConfigError

DISPERSION_KEY = 1000
"""First word of the dispersion streams' spawn keys ``(1000, quantity, vehicle)``: three words, so they
never coincide with the two-word ``(vehicle, sensor)`` keys of :func:`swarm.core.world.stream`."""

QUANTITIES = ("position", "velocity", "attitude", "mass", "inertia", "thrusters")
"""The quantities in stream order (the second word of the spawn key)."""

MAX_FRACTION_SIGMA = 0.1
"""Largest relative standard deviation of mass and inertia: keeps ``1 + e`` positive and the principal
moments a valid inertia (triangle inequality) short of a 10-sigma draw."""


SIGMAS = (
    "position_sigma_m",
    "velocity_sigma_m_s",
    "attitude_sigma_deg",
    "mass_sigma_frac",
    "inertia_sigma_frac",
    "thruster_misalignment_deg",
)
"""The dispersion sizes of :class:`DispersionParams` (each >= 0; zero switches it off)."""


@dataclass(frozen=True)
class DispersionParams:
    """Run-to-run dispersions drawn from the run's seed (module docstring). Zero switches one off."""

    distribution: Literal["normal", "uniform"] = "normal"
    """Distribution of every draw below, zero mean with the given standard deviation: ``"normal"``
    (Gaussian) or ``"uniform"`` on ``[-sqrt(3) sigma, +sqrt(3) sigma]`` (the same standard deviation)."""
    position_sigma_m: float = 0.0
    """Initial true position of every chaser, per mothership axis [m]. The initial estimate follows the
    truth (plus the ``[initial]`` error), the mission attitude and the target do not move."""
    velocity_sigma_m_s: float = 0.0
    """Initial true velocity of every chaser, per mothership axis [m/s] (nominally at rest)."""
    attitude_sigma_deg: float = 0.0
    """Initial true attitude of every chaser: ``q0 (x) exp(e)``, ``e`` per body axis [deg]."""
    mass_sigma_frac: float = 0.0
    """Truth mass of every vehicle times ``1 + e`` (one draw per run: the world has one mass model);
    the agents keep the nominal mass. At most ``MAX_FRACTION_SIGMA``."""
    inertia_sigma_frac: float = 0.0
    """Truth principal moments times ``1 + e_i``, one ``e_i`` per axis (per run, every vehicle); the
    agents keep the nominal inertia. At most ``MAX_FRACTION_SIGMA``."""
    thruster_misalignment_deg: float = 0.0
    """Each nozzle's true thrust direction turned by a rotation vector with this standard deviation per
    axis [deg] (per run, every vehicle); allocation uses the nominal directions."""

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
        """Whether any dispersion of this table is on."""
        return any(getattr(self, n) > 0 for n in SIGMAS)


def dispersion_rng(seed: int, quantity: str, vehicle_index: int = 0) -> np.random.Generator:
    """The stream of one dispersed ``quantity`` (one of :data:`QUANTITIES`) of one vehicle for root
    ``seed``; per-run quantities (mass, inertia, thrusters) use ``vehicle_index = 0``."""
    key = (DISPERSION_KEY, QUANTITIES.index(quantity), int(vehicle_index))
    return np.random.default_rng(np.random.SeedSequence(entropy=int(seed), spawn_key=key))


def _draw(rng: np.random.Generator, sigma: float, size: int, distribution: str) -> np.ndarray:
    if distribution == "uniform":
        half = math.sqrt(3.0) * sigma
        return rng.uniform(-half, half, size=size)
    return rng.normal(0.0, sigma, size=size)


@dataclass(frozen=True)
class Dispersion:
    """The dispersions of one run, as drawn (zeros / ones where a quantity is off)."""

    position_m: dict[str, np.ndarray]
    """Chaser id -> (3,) offset of the initial true position, frame nav [m]."""
    velocity_m_s: dict[str, np.ndarray]
    """Chaser id -> (3,) initial true velocity, frame nav [m/s]."""
    attitude_rad: dict[str, np.ndarray]
    """Chaser id -> (3,) body-frame rotation vector applied to the initial true attitude [rad]."""
    mass_factor: float
    """Truth mass / nominal mass."""
    inertia_factor: np.ndarray
    """(3,) truth principal moments / nominal."""
    thruster_rotvec_rad: np.ndarray
    """(10, 3) body-frame rotation vector turning each nozzle's thrust direction [rad]."""


def draw_dispersion(scenario, seed: int) -> Dispersion:
    """Draw one run's dispersions from its ``seed`` (:func:`dispersion_rng`, one stream per quantity).

    A quantity whose standard deviation is zero draws nothing and is exactly nominal.
    """
    p: DispersionParams = scenario.dispersions
    dist = p.distribution
    ids = list(scenario.vehicles)
    pos, vel, att = {}, {}, {}
    for cid in scenario.chasers:
        i = ids.index(cid)
        pos[cid] = (
            _draw(dispersion_rng(seed, "position", i), p.position_sigma_m, 3, dist)
            if p.position_sigma_m > 0
            else np.zeros(3)
        )
        vel[cid] = (
            _draw(dispersion_rng(seed, "velocity", i), p.velocity_sigma_m_s, 3, dist)
            if p.velocity_sigma_m_s > 0
            else np.zeros(3)
        )
        att[cid] = (
            _draw(dispersion_rng(seed, "attitude", i), math.radians(p.attitude_sigma_deg), 3, dist)
            if p.attitude_sigma_deg > 0
            else np.zeros(3)
        )
    mass = 1.0
    if p.mass_sigma_frac > 0:
        mass += float(_draw(dispersion_rng(seed, "mass"), p.mass_sigma_frac, 1, dist)[0])
    inertia = (
        1.0 + _draw(dispersion_rng(seed, "inertia"), p.inertia_sigma_frac, 3, dist)
        if p.inertia_sigma_frac > 0
        else np.ones(3)
    )
    sigma_thr = math.radians(p.thruster_misalignment_deg)
    thr = (
        _draw(dispersion_rng(seed, "thrusters"), sigma_thr, 3 * N_NOZZLES, dist)
        if sigma_thr > 0
        else np.zeros(3 * N_NOZZLES)
    ).reshape(N_NOZZLES, 3)
    return Dispersion(pos, vel, att, mass, inertia, thr)


def apply_dispersion(world, scenario, disp: Dispersion) -> None:
    """Apply a run's dispersions to the truth of ``world`` (:class:`swarm.core.world.World`) before the
    first tick: the chasers' initial state, and the world's mass, inertia and nozzle directions. A
    quantity that is off leaves the world untouched (bit for bit)."""
    from swarm.core.thrusters import nozzle_geometry
    from swarm.core.world import W_IXX, W_IZZ, W_MASS

    p: DispersionParams = scenario.dispersions
    for cid in scenario.chasers:
        x = world.x[cid]
        if p.position_sigma_m > 0:
            x[0:3] += disp.position_m[cid]
        if p.velocity_sigma_m_s > 0:
            x[3:6] += disp.velocity_m_s[cid]
        if p.attitude_sigma_deg > 0:
            x[6:10] = rot.multiplicative_reset(x[6:10], disp.attitude_rad[cid])
    if p.mass_sigma_frac > 0:
        world.prm[W_MASS] *= disp.mass_factor
    if p.inertia_sigma_frac > 0:
        world.prm[W_IXX : W_IZZ + 1] *= disp.inertia_factor
    if p.thruster_misalignment_deg > 0:
        r, d = nozzle_geometry(scenario.thrusters)
        d_true = rot.quat_rotate(rot.rotvec_exp(disp.thruster_rotvec_rad), d)
        world.B = np.vstack([d_true.T, np.cross(r, d_true).T])


def dispersion_columns(scenario, disp: Dispersion, chaser: str) -> dict[str, float]:
    """The drawn values of one chaser's run as flat CSV columns (``disp_*``)."""
    out = {}
    for name, vec in (
        ("pos", disp.position_m[chaser]),
        ("vel", disp.velocity_m_s[chaser]),
        ("att", disp.attitude_rad[chaser]),
    ):
        for axis, v in zip("xyz", vec, strict=True):
            out[f"disp_{name}_{axis}"] = float(v)
    out["disp_mass_factor"] = float(disp.mass_factor)
    for axis, v in zip("xyz", disp.inertia_factor, strict=True):
        out[f"disp_inertia_factor_{axis}"] = float(v)
    out["disp_thruster_rms_rad"] = float(np.sqrt(np.mean(np.sum(disp.thruster_rotvec_rad**2, axis=1))))
    return out
