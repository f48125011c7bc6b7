"""Sensor profiles (``sensors.toml``): the numbers of a UWB range error model and of an IMU noise model.

A profile is what ``swarm fit`` measures on a real log (``docs/logs.md``, "Fitting a sensor profile"), what
``swarm replay --sensors FILE`` takes as the filter's prior, and what ``swarm synth-log --profile`` and the
scenarios draw their sensors from. The range model is

    range = |p_tag - a| + offset_common + offset_anchor + gm + white (+ nlos excess) (+ outlier)

with ``offset_anchor`` drawn around zero with ``offset_spread_m``, a step ``takeoff_step_m`` once airborne,
``gm`` a first-order Gauss-Markov process (stationary sigma ``gm_sigma_m``, correlation time ``gm_tau_s``;
Gelb 1974, table 3.1-1), ``white`` Gaussian (``ground_sigma_m`` on the ground, ``sigma_m`` in flight), NLOS
episodes that start at ``nlos_rate_hz`` per anchor and last ``nlos_duration_s`` on average with a mean
excess ``nlos_excess_m`` (always long: a blocked direct path makes the first detected path later), and
isolated outliers. The IMU model is the IEEE Std 952-1997 one: white noise density (angular / velocity
random walk), bias instability (the Allan deviation's flat floor), and an extra white spread in flight
(rotor vibration).

Bundled profiles live in ``swarm/sensors/profiles/<name>.toml`` (package data): ``default`` reproduces the
synthetic log of ``swarm/logs/synthetic.py``; ``real-crazyflie`` was fitted on a public Crazyflie flight.
"""

from __future__ import annotations

import ast
import inspect
import itertools
import json
import math
import os
import textwrap
from dataclasses import dataclass, field, fields, is_dataclass
from functools import cache
from pathlib import Path

from swarm.config import load_toml
from swarm.errors import ConfigError

PROFILE_DIR = Path(__file__).resolve().parent / "profiles"
"""The bundled profiles, ``<name>.toml``."""


def _finite(section: str, name: str, v: float) -> None:
    if not (isinstance(v, int | float) and math.isfinite(v)):
        raise ConfigError(f"{section}.{name} must be a finite number, got {v!r}")


def _positive(section: str, name: str, v: float) -> None:
    if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
        raise ConfigError(f"{section}.{name} must be a finite number > 0, got {v!r}")


def _non_negative(section: str, name: str, v: float) -> None:
    if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
        raise ConfigError(f"{section}.{name} must be a finite number >= 0, got {v!r}")


def _share(section: str, name: str, v: float) -> None:
    if not (isinstance(v, int | float) and math.isfinite(v) and 0 <= v <= 1):
        raise ConfigError(f"{section}.{name} must be a share in [0, 1], got {v!r}")


@dataclass(frozen=True)
class AnchorProfile:
    """``[uwb.anchors.<id>]``: what ``swarm fit`` measured on one anchor (every key optional: None = not
    measured, e.g. an anchor without ranges on the ground)."""

    ground_bias_m: float | None = None
    """Median range residual on the ground (static segments) [m]."""
    flight_bias_m: float | None = None
    """Median range residual in flight, clear ranges [m]."""
    ground_sigma_m: float | None = None
    """Robust sigma (1.4826 MAD) of the residual on the ground [m]."""
    sigma_m: float | None = None
    """White noise sigma of the clear in-flight residual [m] (the Gauss-Markov part apart)."""
    gm_sigma_m: float | None = None
    """Stationary sigma of the time-correlated (Gauss-Markov) part of the in-flight residual [m]."""
    gm_tau_s: float | None = None
    """Its correlation time [s]."""
    nlos_share: float | None = None
    """Share of the in-flight ranges inside NLOS episodes."""
    nlos_rate_hz: float | None = None
    """Onset rate of NLOS episodes in flight [1/s]."""
    nlos_duration_s: float | None = None
    """Mean NLOS episode length [s]."""
    nlos_excess_m: float | None = None
    """Mean excess of the ranges in NLOS episodes over the clear flight median [m]."""

    def __post_init__(self) -> None:
        for name in ("ground_bias_m", "flight_bias_m"):
            if getattr(self, name) is not None:
                _finite("anchor", name, getattr(self, name))
        for name in ("ground_sigma_m", "sigma_m", "gm_sigma_m", "nlos_rate_hz", "nlos_excess_m"):
            if getattr(self, name) is not None:
                _non_negative("anchor", name, getattr(self, name))
        for name in ("gm_tau_s", "nlos_duration_s"):
            if getattr(self, name) is not None:
                _positive("anchor", name, getattr(self, name))
        if self.nlos_share is not None:
            _share("anchor", "nlos_share", self.nlos_share)


@dataclass(frozen=True)
class UwbProfile:
    """``[uwb]``: the two-way range error model (module docstring). Defaults: the synthetic log's."""

    sigma_m: float = 0.05
    """In-flight white noise sigma, median over anchors [m]."""
    ground_sigma_m: float = 0.05
    """White noise sigma on the ground (static segment) [m]."""
    offset_m: float = 0.35
    """Common offset: median over anchors of the ground bias [m] (an antenna delay makes it negative)."""
    offset_spread_m: float = 0.0866
    """Standard deviation of the per-anchor offsets around the common one [m]."""
    takeoff_step_m: float = 0.0
    """Airborne minus ground bias, mean over anchors [m]."""
    takeoff_step_spread_m: float = 0.0
    """Standard deviation over anchors of that step [m]."""
    gm_sigma_m: float = 0.0
    """First-order Gauss-Markov (time-correlated multipath) stationary sigma [m] (0: none)."""
    gm_tau_s: float = 1.0
    """Its correlation time [s]."""
    nlos_rate_hz: float = 0.0
    """Onset rate of sustained NLOS episodes per anchor in flight [1/s] (0: none)."""
    nlos_duration_s: float = 4.0
    """Mean NLOS episode length [s]."""
    nlos_excess_m: float = 1.0
    """Mean excess range during an episode [m] (always long)."""
    outlier_share: float = 0.0
    """Isolated outliers, share of all ranges."""
    outlier_excess_m: float = 1.0
    """Their mean excess [m] (exponential, long)."""
    anchors: dict[str, AnchorProfile] = field(default_factory=dict)
    """Per anchor id (``[uwb.anchors.3]``): what the fit measured on each (optional)."""

    def __post_init__(self) -> None:
        for name in ("sigma_m", "ground_sigma_m", "gm_tau_s", "nlos_duration_s"):
            _positive("uwb", name, getattr(self, name))
        _finite("uwb", "offset_m", self.offset_m)
        _finite("uwb", "takeoff_step_m", self.takeoff_step_m)
        for name in (
            "offset_spread_m",
            "takeoff_step_spread_m",
            "gm_sigma_m",
            "nlos_rate_hz",
            "nlos_excess_m",
            "outlier_excess_m",
        ):
            _non_negative("uwb", name, getattr(self, name))
        _share("uwb", "outlier_share", self.outlier_share)
        for key, value in self.anchors.items():
            if not (isinstance(key, str) and key.isdigit() and key.isascii()):
                raise ConfigError(f"uwb.anchors: key {key!r} is not an anchor id (an integer >= 0)")
            if not isinstance(value, AnchorProfile):
                raise ConfigError(f"uwb.anchors.{key} must be an AnchorProfile, got {value!r}")

    def anchor(self, anchor_id: int) -> AnchorProfile | None:
        """The measured profile of anchor ``anchor_id``, or None."""
        for key, value in self.anchors.items():
            if int(key) == int(anchor_id):
                return value
        return None


@dataclass(frozen=True)
class ImuProfile:
    """``[imu]``: white noise densities and bias instabilities (Allan deviation of a static segment, IEEE Std
    952-1997 annex C), and the extra in-flight spread. Defaults: the synthetic log's."""

    rate_hz: float = 1000.0
    """Sample rate [Hz]."""
    gyro_noise_rad_s_rthz: float = 0.002
    """Gyro white noise density, the angular random walk N [rad/s/sqrt(Hz)]."""
    gyro_bias_instability_rad_s: float = 0.0
    """Gyro bias instability B (the Allan deviation's floor / 0.664) [rad/s]."""
    accel_noise_m_s2_rthz: float = 0.02
    """Accelerometer white noise density, the velocity random walk [m/s^2/sqrt(Hz)]."""
    accel_bias_instability_m_s2: float = 0.0
    """Accelerometer bias instability [m/s^2]."""
    gyro_vibration_rad_s: float = 0.0
    """Extra in-flight white spread of the gyro (rotor vibration), a standard deviation, not a density
    [rad/s]."""
    accel_vibration_m_s2: float = 0.0
    """Extra in-flight white spread of the accelerometer [m/s^2]."""

    def __post_init__(self) -> None:
        for name in ("rate_hz", "gyro_noise_rad_s_rthz", "accel_noise_m_s2_rthz"):
            _positive("imu", name, getattr(self, name))
        for name in (
            "gyro_bias_instability_rad_s",
            "accel_bias_instability_m_s2",
            "gyro_vibration_rad_s",
            "accel_vibration_m_s2",
        ):
            _non_negative("imu", name, getattr(self, name))


@dataclass(frozen=True)
class SensorProfile:
    """``sensors.toml``: a named sensor profile (``docs/logs.md``)."""

    name: str = "default"
    """A short name (the bundled file's stem for a bundled profile)."""
    source: str = ""
    """Where the numbers come from (a fitted log and its size, or a model)."""
    uwb: UwbProfile = UwbProfile()
    """The range error model."""
    imu: ImuProfile = ImuProfile()
    """The IMU noise model."""


def bundled_profiles() -> list[str]:
    """The names of the bundled profiles."""
    return sorted(p.stem for p in PROFILE_DIR.glob("*.toml"))


def load_profile(path_or_name: str | os.PathLike[str]) -> SensorProfile:
    """A profile from a TOML file, or the bundled profile of that name (``"real-crazyflie"``). Raises
    ConfigError naming the file and the key (an unknown key, a bad value, a missing file or name)."""
    path = Path(path_or_name)
    if not path.suffix and not path.exists() and os.sep not in str(path_or_name):
        bundled = PROFILE_DIR / f"{path_or_name}.toml"
        if not bundled.is_file():
            raise ConfigError(
                f"sensor profile {str(path_or_name)!r}: no such file, nor a bundled profile "
                f"(bundled: {', '.join(bundled_profiles()) or 'none'})"
            )
        path = bundled
    return load_toml(SensorProfile, path)


# ------------------------------------------------------------------------------------------- writer


@cache
def _field_docs(cls: type) -> dict[str, str]:
    """The first line of each field's docstring (the string literal after its annotation)."""
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    except (OSError, TypeError, SyntaxError):
        return {}
    body = tree.body[0].body
    docs = {}
    for node, after in itertools.pairwise(body):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            docs[node.target.id] = " ".join(after.value.value.split())
    return docs


def _value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float | int):
        return repr(float(v))  # shortest round-tripping repr; always TOML float syntax when finite
    if isinstance(v, str):
        # a JSON string is a TOML basic string, but for DEL, which TOML wants escaped
        return json.dumps(v, ensure_ascii=False).replace("\x7f", "\\u007F")
    raise ConfigError(f"cannot write {v!r} to a sensor profile")


def _table(obj: object, header: str | None, lines: list[str]) -> None:
    """``[header]`` and one ``key = value  # doc`` line per scalar field of ``obj``, then its sub-tables."""
    docs = _field_docs(type(obj))
    if header is not None:
        lines += ["", f"[{header}]"]
    subs = []
    for f in fields(obj):
        v = getattr(obj, f.name)
        if v is None:
            continue
        if is_dataclass(v) or isinstance(v, dict):
            subs.append((f.name, v))
            continue
        doc = docs.get(f.name, "")
        lines.append(f"{f.name} = {_value(v)}" + (f"  # {doc}" if doc else ""))
    for name, v in subs:
        sub = name if header is None else f"{header}.{name}"
        if isinstance(v, dict):
            for key in sorted(v, key=int):
                _table(v[key], f"{sub}.{key}", lines)
        else:
            _table(v, sub, lines)


def profile_toml(profile: SensorProfile, comments: tuple[str, ...] | list[str] = ()) -> str:
    """``profile`` as commented TOML that :func:`load_profile` reads back to an equal profile; ``comments``
    become ``#`` lines at the top (e.g. the fit's notes)."""
    lines = [f"# {line}" if line else "#" for c in comments for line in str(c).splitlines() or [""]]
    if lines:
        lines.append("")
    _table(profile, None, lines)
    return "\n".join(lines) + "\n"


def save_profile(
    profile: SensorProfile, path: str | os.PathLike[str], comments: tuple[str, ...] | list[str] = ()
) -> None:
    """Write ``profile`` to ``path`` as commented TOML (:func:`profile_toml`)."""
    try:
        Path(path).write_text(profile_toml(profile, comments), encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot write the sensor profile: {exc.strerror or exc}") from exc
