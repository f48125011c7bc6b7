"""The range errors of real UWB flights, for the simulated radios (docs/logs.md; the same model as the
synthetic log's, :mod:`swarm.logs.phenomena`, and as a sensor profile's, :mod:`swarm.sensors.profile`):

    range = |tag - anchor| + white + offset_anchor + [airborne] (step + gm + nlos) + [outlier] excess

* ``offset_anchor``: a common offset plus a per-anchor one (an antenna delay: real Loco Positioning ranges
  read short by 0.17-0.36 m), drawn once per run, uniform around ``offset_m`` with standard deviation
  ``offset_spread_m``;
* ``step``: the ground-to-air bias step, per vehicle and anchor, drawn once, around
  ``takeoff_bias_step_m`` (spread ``takeoff_bias_step_spread_m``), while the vehicle is airborne;
* ``gm``: time-correlated multipath in flight, a first-order Gauss-Markov process per vehicle and anchor
  (stationary sigma ``multipath_sigma_m``, correlation time ``multipath_tau_s``), advanced at each exchange
  of that anchor by its exact discretisation over the time since the last one (Maybeck 1979, vol. 1,
  ch. 4), and drawn from its stationary law at the first exchange in flight;
* ``nlos``: sustained NLOS episodes in flight, a two-state (clear / blocked) Markov process per vehicle and
  anchor with onset rate ``lambda = nlos_episode_rate_hz`` and end rate ``mu = 1 / nlos_episode_s``,
  sampled exactly at each exchange: over ``dt`` a clear anchor becomes blocked with probability
  ``lambda / (lambda + mu) (1 - exp(-(lambda + mu) dt))`` and a blocked one clear with
  ``mu / (lambda + mu) (1 - exp(-(lambda + mu) dt))`` (Ross, *Introduction to Probability Models*, sec.
  6.8, the two-state chain), so onsets are a Poisson process of the clear time and episodes last an
  exponential time of mean ``nlos_episode_s``; each episode's excess is drawn at its onset, uniform in
  ``[0.5, 1.5] nlos_episode_excess_m`` (always long);
* an isolated outlier with probability ``outlier_probability``, long by an exponential excess of mean
  ``outlier_excess_m`` (the landing radio's; the docking radio has its own NLOS outliers).

Each exchange takes :data:`ERR_DRAWS` standard normals from the radio's own ``uwb_errors`` stream, so that
switching the model on changes no other draw; every parameter at zero is the radio of before, bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarm.errors import ConfigError

RE_ON, RE_GM_SIGMA, RE_GM_TAU, RE_RATE, RE_EPISODE_S, RE_EXCESS, RE_P_OUT, RE_OUT_EXCESS = range(8)
RE_N = 8
"""The parameter vector :func:`range_error_vector` gives and :func:`range_error_step` reads."""

RS_GM, RS_T, RS_EXCESS = range(3)
RS_N = 3
"""One vehicle-anchor link's state: the Gauss-Markov value [m], the time of its last exchange in flight
[s] (NaN: none yet), the current episode's excess [m] (0: clear)."""

ERR_DRAWS = 5
"""Standard normals one exchange takes: the Gauss-Markov step, the episode's transition and excess, the
outlier's uniform and size."""

FIELDS = (
    "offset_m",
    "offset_spread_m",
    "takeoff_bias_step_m",
    "takeoff_bias_step_spread_m",
    "multipath_sigma_m",
    "multipath_tau_s",
    "nlos_episode_rate_hz",
    "nlos_episode_s",
    "nlos_episode_excess_m",
)
"""The range-error keys a radio's ``[uwb]`` table has (:class:`swarm.core.sensors.UwbParams`,
:class:`swarm.landing_scenario.LandingUwb`)."""

_INV_SQRT2 = 1.0 / math.sqrt(2.0)
_SQRT12 = math.sqrt(12.0)


def check_range_errors(p, section: str = "uwb") -> None:
    """ConfigError naming ``<section>.<key>`` and its value unless ``p``'s range-error fields are valid:
    finite offsets and steps, non-negative spreads, sigma, rate and excess, positive times."""
    for name in ("offset_m", "takeoff_bias_step_m"):
        v = getattr(p, name)
        if not (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)):
            raise ConfigError(f"{section}.{name} must be a finite number, got {v!r}")
    for name in ("offset_spread_m", "takeoff_bias_step_spread_m", "multipath_sigma_m", "nlos_episode_rate_hz",
                 "nlos_episode_excess_m"):  # fmt: skip
        v = getattr(p, name)
        if not (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v >= 0):
            raise ConfigError(f"{section}.{name} must be a finite number >= 0, got {v!r}")
    for name in ("multipath_tau_s", "nlos_episode_s"):
        v = getattr(p, name)
        if not (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v > 0):
            raise ConfigError(f"{section}.{name} must be a finite number > 0, got {v!r}")


def range_errors_on(p, outlier_probability: float = 0.0) -> bool:
    """Whether any range error of ``p`` (a radio's ``[uwb]`` params) is switched on."""
    return bool(
        p.offset_m or p.offset_spread_m or p.takeoff_bias_step_m or p.takeoff_bias_step_spread_m
        or p.multipath_sigma_m or p.nlos_episode_rate_hz or outlier_probability
    )  # fmt: skip


def range_error_vector(p, outlier_probability: float = 0.0, outlier_excess_m: float = 1.0) -> np.ndarray:
    """The parameters (``RE_*``) of :func:`range_error_step` from a radio's ``[uwb]`` params ``p``."""
    v = np.zeros(RE_N)
    v[RE_ON] = float(range_errors_on(p, outlier_probability))
    v[RE_GM_SIGMA], v[RE_GM_TAU] = p.multipath_sigma_m, p.multipath_tau_s
    v[RE_RATE], v[RE_EPISODE_S] = p.nlos_episode_rate_hz, p.nlos_episode_s
    v[RE_EXCESS] = p.nlos_episode_excess_m
    v[RE_P_OUT], v[RE_OUT_EXCESS] = outlier_probability, outlier_excess_m
    return v


def draw_offsets(p, rng: np.random.Generator, anchors: int) -> np.ndarray:
    """The per-anchor offsets (anchors,) [m]: uniform, mean ``offset_m``, standard deviation
    ``offset_spread_m`` (:func:`swarm.logs.phenomena.spread_draw`). Draws ``anchors`` doubles."""
    return p.offset_m + p.offset_spread_m * _SQRT12 * (rng.random(anchors) - 0.5)


def draw_steps(p, rng: np.random.Generator, anchors: int) -> np.ndarray:
    """One vehicle's take-off steps per anchor (anchors,) [m], as :func:`draw_offsets` around
    ``takeoff_bias_step_m``."""
    return p.takeoff_bias_step_m + p.takeoff_bias_step_spread_m * _SQRT12 * (rng.random(anchors) - 0.5)


@njit(cache=True)
def _uniform(z):
    """The standard normal ``z`` as a uniform in (0, 1) (its CDF: the probability integral transform)."""
    return 0.5 * math.erfc(-z * _INV_SQRT2)


@njit(cache=True)
def range_error_step(t_s, airborne, st, z, prm, offset, step):
    """The error of one exchange at ``t_s`` [s] on one vehicle-anchor link (module docstring):
    ``(extra range [m], in an NLOS episode)``. ``st`` (:data:`RS_N`,) the link's state, updated; ``z``
    (:data:`ERR_DRAWS`,) standard normals; ``prm`` the ``RE_*`` vector; ``offset`` the anchor's offset and
    ``step`` the link's take-off step [m]. On the ground the multipath and the episode are reset (a
    standing vehicle's geometry does not change)."""
    extra = offset
    if _uniform(z[3]) < prm[RE_P_OUT]:
        extra += -prm[RE_OUT_EXCESS] * math.log(max(_uniform(z[4]), 1e-300))
    if not airborne:
        st[RS_GM], st[RS_T], st[RS_EXCESS] = 0.0, np.nan, 0.0
        return extra, False
    sigma = prm[RE_GM_SIGMA]
    last = st[RS_T]
    dt = 0.0
    if math.isnan(last):
        st[RS_GM] = sigma * z[0]
    else:
        dt = t_s - last
        phi = math.exp(-dt / prm[RE_GM_TAU])
        st[RS_GM] = phi * st[RS_GM] + sigma * math.sqrt(max(1.0 - phi * phi, 0.0)) * z[0]
    st[RS_T] = t_s
    lam = prm[RE_RATE]
    if lam > 0.0 and dt > 0.0:
        mu = 1.0 / prm[RE_EPISODE_S]
        s = lam + mu
        e = 1.0 - math.exp(-s * dt)
        u = _uniform(z[1])
        if st[RS_EXCESS] == 0.0:
            if u < lam / s * e:
                st[RS_EXCESS] = prm[RE_EXCESS] * (0.5 + _uniform(z[2]))
        elif u < mu / s * e:
            st[RS_EXCESS] = 0.0
    return extra + step + st[RS_GM] + st[RS_EXCESS], st[RS_EXCESS] > 0.0
