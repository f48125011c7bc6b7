"""Read a recorded sensor log: a folder of CSV files and a ``log.toml`` (``docs/logs.md`` is the format).

Every error names the file, and where it is in the file the line and the column (``uwb.csv, line 12,
column 2 (anchor_id): unknown anchor 9; anchors.csv has 0, 1, 2, 3``), as a :class:`~swarm.errors.LogError`.
A NaN or empty value in a sample (an IMU or range reading, not a time) is what a logger writes for a lost
reading: that row is skipped and counted in :attr:`Log.skipped`, never fed to a filter.

``uwb.csv`` and ``anchors.csv`` may have a header and no rows (a log without two-way ranges: a TDoA flight,
or an import from a source that logged none); the optional ``height.csv``, ``baro.csv`` and ``tdoa.csv`` are
read into their own fields (``docs/logs.md``).
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarm.config import load_toml
from swarm.core.imu_filter import ImuFilterParams, PhaseParams, RobustParams
from swarm.errors import ConfigError, LogError

IMU_COLUMNS = (
    "t_s",
    "gyro_x_rad_s",
    "gyro_y_rad_s",
    "gyro_z_rad_s",
    "acc_x_m_s2",
    "acc_y_m_s2",
    "acc_z_m_s2",
)
UWB_COLUMNS = ("t_s", "anchor_id", "range_m")
ANCHOR_COLUMNS = ("anchor_id", "x_m", "y_m", "z_m")
TRUTH_COLUMNS = ("t_s", "x_m", "y_m", "z_m", "qx", "qy", "qz", "qw")
VISION_COLUMNS = ("t_s", "marker_id", "x_m", "y_m", "z_m")
VISION_SIGMA_COLUMNS = ("sigma_x_m", "sigma_y_m", "sigma_z_m")
MARKER_COLUMNS = ("marker_id", "x_m", "y_m", "z_m")
HEIGHT_COLUMNS = ("t_s", "range_m")
BARO_COLUMNS = ("t_s", "height_m")
TDOA_COLUMNS = ("t_s", "anchor_a", "anchor_b", "ddist_m")
QUAT_NORM_TOL = 1e-3
TDOA_BASELINE_TOL_M = 0.1
"""How much longer than the two anchors' baseline a TDoA distance difference may be [m]. By the triangle
inequality ``||p - a_b| - |p - a_a|| <= |a_b - a_a|``, so a longer one is a measurement error (the Crazyflie
firmware drops it before its filter: ``isDistanceDiffSmallerThanDistanceBetweenAnchors`` in
``outlierFilterTdoa.c``); the tolerance covers the anchor survey's error and float32 rounding of the logged
values, not the ranging noise (an importer drops those rows, counted, as the firmware does)."""


@dataclass(frozen=True)
class UwbLog:
    """``[uwb]`` of log.toml."""

    sigma_m: float | None = None
    """Range noise standard deviation [m], every anchor; leave out to calibrate it per anchor from the
    static segment (``[calibration] until_s``)."""
    sigma_floor_m: float = 0.02
    """Smallest per-anchor sigma the calibration may give [m] (a static segment is short and quiet)."""

    def __post_init__(self) -> None:
        if self.sigma_m is not None and not (math.isfinite(self.sigma_m) and self.sigma_m > 0):
            raise ConfigError(f"uwb.sigma_m must be a finite number > 0, got {self.sigma_m!r}")
        if not (math.isfinite(self.sigma_floor_m) and self.sigma_floor_m > 0):
            raise ConfigError(f"uwb.sigma_floor_m must be a finite number > 0, got {self.sigma_floor_m!r}")


@dataclass(frozen=True)
class VisionLog:
    """``[vision]`` of log.toml: the camera that measured ``vision.csv``."""

    enabled: bool = True
    """Use ``vision.csv`` when the log has one (false: replay on IMU and UWB alone, to compare)."""
    camera_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The camera's optical centre from the IMU, body frame [m]."""
    camera_quaternion: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    """Camera to body rotation, scalar-last (the default turns the optical axis, camera +z, to body -z: a
    downward camera on a vehicle whose body z is up)."""
    sigma_m: tuple[float, float, float] = (0.01, 0.01, 0.03)
    """Standard deviation of each camera-frame axis [m] for rows without ``sigma_*`` columns."""
    gate_probability: float = 0.9995
    """Hard gate: chi-square(3) quantile of the squared Mahalanobis distance of a detection."""

    def __post_init__(self) -> None:
        q = self.camera_quaternion
        if (
            len(q) != 4
            or not all(math.isfinite(v) for v in q)
            or abs(math.sqrt(sum(v * v for v in q)) - 1) > 1e-6
        ):
            raise ConfigError(
                f"vision.camera_quaternion must be 4 finite numbers of unit norm (x, y, z, w), got {q!r}"
            )
        if len(self.camera_position_m) != 3 or not all(math.isfinite(v) for v in self.camera_position_m):
            raise ConfigError(
                f"vision.camera_position_m must be 3 finite numbers, got {self.camera_position_m!r}"
            )
        if len(self.sigma_m) != 3 or not all(math.isfinite(v) and v > 0 for v in self.sigma_m):
            raise ConfigError(f"vision.sigma_m must be 3 finite numbers > 0, got {self.sigma_m!r}")
        if not 0.0 < self.gate_probability < 1.0:
            raise ConfigError(f"vision.gate_probability must be in (0, 1), got {self.gate_probability!r}")


@dataclass(frozen=True)
class Calibration:
    """``[calibration]`` of log.toml: a static segment at the start of the log."""

    until_s: float = 0.0
    """The vehicle stands still for ``t < until_s`` [s] (log time); 0: no calibration."""
    position_m: tuple[float, float, float] | None = None
    """Where the IMU stands during the segment, nav [m] (a surveyed pad), so that per-anchor range biases are
    absolute; leave out to take the least-squares fix of the segment's median ranges (then the biases are
    the fit's residuals: their common part is absorbed)."""
    range_bias: bool = True
    """Calibrate a bias per anchor (else only sigma)."""
    position_sigma_m: float = 0.01
    """Standard deviation of the surveyed ``position_m`` [m]: the filter's first position sigma when given
    (``[initial] sigma_position_m`` otherwise)."""
    range_bias_sigma_m: float = 0.02
    """Standard deviation of a calibrated range offset [m] (the common one and each anchor's): the filter's
    prior on them after a calibration at a surveyed position (``[initial]`` sigmas otherwise)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.until_s) and self.until_s >= 0):
            raise ConfigError(f"calibration.until_s must be a finite number >= 0, got {self.until_s!r}")
        for name in ("position_sigma_m", "range_bias_sigma_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"calibration.{name} must be a finite number > 0, got {v!r}")


@dataclass(frozen=True)
class Initial:
    """``[initial]`` of log.toml: the filter's first state and standard deviations."""

    position_m: tuple[float, float, float] | None = None
    """First position, nav [m]; leave out to take the calibration position or a fix from the first ranges."""
    yaw_deg: float = 0.0
    """First heading [deg] about the gravity axis (a static accelerometer gives roll and pitch, not yaw)."""
    sigma_position_m: float = 0.3
    sigma_velocity_m_s: float = 0.1
    sigma_attitude_deg: float = 5.0
    sigma_accel_bias_m_s2: float = 0.2
    sigma_gyro_bias_rad_s: float = 0.01
    sigma_range_bias_m: float = 0.3
    """Prior on each range bias [m] (after calibration it is the calibration's uncertainty)."""
    sigma_common_offset_m: float = 0.3
    """Prior on the offset common to every anchor [m] (the calibration's median bias, or zero)."""

    def __post_init__(self) -> None:
        for name in (
            "sigma_position_m",
            "sigma_velocity_m_s",
            "sigma_attitude_deg",
            "sigma_accel_bias_m_s2",
            "sigma_gyro_bias_rad_s",
            "sigma_range_bias_m",
            "sigma_common_offset_m",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"initial.{name} must be a finite number > 0, got {v!r}")


@dataclass(frozen=True)
class Recovery:
    """``[recovery]`` of log.toml: what the replay does after a divergence."""

    enabled: bool = True
    """Recover when the divergence test fires (else only report it)."""
    mode: str = "inflate"
    """``inflate``: add the window's median squared range innovation to the position covariance and
    ``sigma_velocity_m_s`` squared to the velocity's, the estimate kept (it cannot make the estimate worse;
    the ranges then pull it); ``refix``: re-initialise the position from the latest range to each anchor
    and zero the velocity (the first model's)."""
    max_position_sigma_m: float = 10.0
    """Largest position standard deviation one ``inflate`` recovery adds [m]."""
    max_range_age_s: float = 1.0
    """Ranges older than this [s] are not used for the fix."""
    sigma_velocity_m_s: float = 1.0
    """Velocity standard deviation added (``inflate``) or set with a zero velocity (``refix``) [m/s]."""

    def __post_init__(self) -> None:
        if self.mode not in ("inflate", "refix"):
            raise ConfigError(f"recovery.mode must be 'inflate' or 'refix', got {self.mode!r}")
        if not (math.isfinite(self.max_position_sigma_m) and self.max_position_sigma_m > 0.0):
            raise ConfigError(
                "recovery.max_position_sigma_m must be a finite number > 0, "
                f"got {self.max_position_sigma_m!r}"
            )


@dataclass(frozen=True)
class HeightLog:
    """``[height]`` of log.toml: the downward range finder of ``height.csv``."""

    enabled: bool = True
    """Fuse ``height.csv`` when the log has one."""
    sigma_m: float = 0.02
    """Its white noise [m]."""
    max_range_m: float = 3.0
    """Readings beyond are refused (the sensor's reach; past it a ToF sensor reports junk)."""
    min_cos_tilt: float = 0.866
    """Readings at an estimated tilt whose cosine is below this are refused (the beam leaves the flat
    ground of the model; 0.866: 30 deg)."""
    ground_z_m: float | None = None
    """The ground's height in nav [m]; leave out to take the calibration position's height minus the static
    segment's median reading (the sensor's own offset included), else 0."""
    gate_probability: float = 0.9995
    """Hard gate: chi-square(1) quantile of the squared Mahalanobis distance."""
    reset_after: int = 5
    """After this many readings rejected in a row the height re-opens to the next one (0: never;
    :func:`swarm.core._imu_nb.fuse_aux`): ~0.2 s at a Crazyflie's 20-25 Hz, longer than an isolated spike.
    The development TDoA flights: 4 of 23 with a range finder lost it for 1.5 s at the take-off (the estimate
    0.3-0.6 m low); median 3-D RMSE of the 23 0.180 -> 0.169 m, the other 19 unchanged."""

    def __post_init__(self) -> None:
        for name in ("sigma_m", "max_range_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"height.{name} must be a finite number > 0, got {v!r}")
        if not (isinstance(self.reset_after, int) and not isinstance(self.reset_after, bool)
                and self.reset_after >= 0):  # fmt: skip
            raise ConfigError(f"height.reset_after must be an integer >= 0, got {self.reset_after!r}")
        if not 0.0 < self.min_cos_tilt <= 1.0:
            raise ConfigError(f"height.min_cos_tilt must be in (0, 1], got {self.min_cos_tilt!r}")
        if not 0.5 < self.gate_probability < 1.0:
            raise ConfigError(f"height.gate_probability must be in (0.5, 1), got {self.gate_probability!r}")


@dataclass(frozen=True)
class BaroLog:
    """``[baro]`` of log.toml: the barometric height of ``baro.csv`` (its offset is a filter state)."""

    enabled: bool = False
    """Fuse ``baro.csv`` when the log has one. Off by default: on the UTIL Crazyflie TDoA flights the
    barometer steps by ~2 m at take-off and then drifts ~0.17 m/s as it warms (docs/logs.md), which a
    random-walk offset cannot follow; the range finder is the height sensor to trust."""
    sigma_m: float = 0.5
    """Its white noise [m] (a small quadrotor's barometer in its own prop wash)."""
    gate_probability: float = 0.9995

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma_m) and self.sigma_m > 0):
            raise ConfigError(f"baro.sigma_m must be a finite number > 0, got {self.sigma_m!r}")
        if not 0.5 < self.gate_probability < 1.0:
            raise ConfigError(f"baro.gate_probability must be in (0.5, 1), got {self.gate_probability!r}")


@dataclass(frozen=True)
class TdoaLog:
    """``[tdoa]`` of log.toml: the distance differences of ``tdoa.csv``."""

    enabled: bool = True
    """Fuse ``tdoa.csv`` when the log has one."""
    sigma_m: float = 0.1
    """Their white noise [m], each pair's prior (adapted upward in flight). The development TDoA flights'
    residuals against the truth spread 0.2-0.5 m per pair (1.4826 MAD), but almost all of it is each
    anchor's slow error (``gm_sigma_m``): two rows of one pair within 60 ms differ by 0.07 m RMS / sqrt(2)
    (the white part; the Crazyflie firmware's 0.3 m takes all of it as white)."""
    gm_sigma_m: float = 0.15
    """A TDoA log's per-anchor Gauss-Markov range error (``[estimator] range_gm`` with this stationary
    sigma [m], in place of ``range_gm_sigma_m``): each anchor's error as its differences carry it, 0.1-0.3 m
    per anchor on the development flights (0.2 s bins of their residuals solved for one error per anchor)."""
    gm_tau_s: float = 0.5
    """Its correlation time [s] (those anchor errors correlate 0.5-0.8 at 0.2 s, 0.3-0.5 at 0.4 s, 0.1-0.3
    at 1 s), in place of ``range_gm_tau_s``."""
    cusum_k: float = 2.0
    """A TDoA log's NLOS CUSUM allowance on the normalised innovation (in place of ``[robust] cusum_k``):
    each anchor's modelled slow error moves the innovations of its differences by 1-2 of their sigmas for
    half a second at a time, 200-400 of them a second; with 1.0 clean anchors were held out 20-30 % of the
    time on the development flights, with 2.0 an anchor whose packets come 0.8 m late is held in ~0.1 s."""
    offsets: bool = False
    """Estimate each anchor's offset (``[estimator] range_bias``) in a TDoA log. Off: in a room whose anchors
    stand in two layers (floor and ceiling, the Loco Positioning and UTIL layouts) a height error ``dz``
    moves every difference as offsets ``-u_z dz`` would (``u_z`` the unit vector's height to each anchor:
    about +0.25 to the upper layer, -0.25 to the lower from mid-height), so offsets of 0.1 m let a 0.4 m
    height error stand; only the change of ``u_z`` across the room tells them apart, which a flight at one
    height hardly gives, and a random-walk offset holds what it took for tens of seconds. The
    Gauss-Markov term (``gm_sigma_m``) takes each anchor's slow error instead and lets it go within
    ``gm_tau_s``. Measured on the 39 development TDoA flights (BENCHMARKS.md): median 3-D RMSE 0.196 m with
    offsets, 0.188 m without; 0.251 -> 0.226 m on the 16 flights without a range finder (height RMS
    0.14-0.45 -> 0.14-0.25 m)."""
    offset_sigma_m: float = 0.1
    """A TDoA log's prior sigma of each anchor's offset [m] with ``offsets`` (in place of ``[initial]
    sigma_range_bias_m``): only their differences enter, so only their spread matters (0.076 m over the
    development hover's anchors; 0.05-0.15 m on the TDoA flights); the common offset cancels and is not a
    state."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma_m) and self.sigma_m > 0):
            raise ConfigError(f"tdoa.sigma_m must be a finite number > 0, got {self.sigma_m!r}")
        for name in ("gm_sigma_m", "gm_tau_s", "offset_sigma_m", "cusum_k"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"tdoa.{name} must be a finite number > 0, got {v!r}")


@dataclass(frozen=True)
class Faults:
    """``[faults]`` of log.toml: a forced divergence, to see the recovery (testing, demonstrations)."""

    jump_at_s: float | None = None
    """At this log time [s] the position estimate jumps by ``jump_m`` while its covariance shrinks to
    ``jump_sigma_m``: an overconfident, wrong filter."""
    jump_m: tuple[float, float, float] = (5.0, 0.0, 0.0)
    jump_sigma_m: float = 0.01


@dataclass(frozen=True)
class LogConfig:
    """``log.toml``: what the CSV files cannot say (``docs/logs.md``)."""

    name: str = ""
    estimator: ImuFilterParams = field(default_factory=ImuFilterParams)
    uwb: UwbLog = UwbLog()
    vision: VisionLog = VisionLog()
    calibration: Calibration = Calibration()
    initial: Initial = Initial()
    recovery: Recovery = Recovery()
    robust: RobustParams = field(default_factory=RobustParams)
    phases: PhaseParams = field(default_factory=PhaseParams)
    height: HeightLog = HeightLog()
    baro: BaroLog = BaroLog()
    tdoa: TdoaLog = TdoaLog()
    faults: Faults = Faults()
    output_every: int = 10
    """Write one estimate row every this many IMU samples (10: 100 Hz for a 1 kHz IMU)."""

    def __post_init__(self) -> None:
        if not (isinstance(self.output_every, int) and self.output_every >= 1):
            raise ConfigError(f"output_every must be an integer >= 1, got {self.output_every!r}")


@dataclass
class Log:
    """A log in memory: arrays sorted by time, anchors by index (``anchor_ids[index]`` is the file's id)."""

    path: Path
    config: LogConfig
    imu_t: np.ndarray
    gyro: np.ndarray
    acc: np.ndarray
    uwb_t: np.ndarray
    uwb_anchor: np.ndarray
    """Index into :attr:`anchors_nav` of each range."""
    uwb_range: np.ndarray
    anchor_ids: np.ndarray
    anchors_nav: np.ndarray
    truth_t: np.ndarray | None = None
    truth_p: np.ndarray | None = None
    truth_q: np.ndarray | None = None
    vision_t: np.ndarray | None = None
    """Detection times (sorted); with :attr:`vision_marker`, :attr:`vision_xyz`, :attr:`vision_sigma`."""
    vision_marker: np.ndarray | None = None
    """Index into :attr:`markers_nav` of each detection."""
    vision_xyz: np.ndarray | None = None
    """The marker's position in the camera frame (n, 3) [m] (a PnP translation)."""
    vision_sigma: np.ndarray | None = None
    """Its standard deviation per camera axis (n, 3) [m]."""
    marker_ids: np.ndarray | None = None
    markers_nav: np.ndarray | None = None
    height_t: np.ndarray | None = None
    """``height.csv``: times of the downward range finder's samples (strictly increasing) [s]."""
    height_range: np.ndarray | None = None
    """Its range along body -z from the body origin [m] (>= 0; rows without a return are skipped)."""
    baro_t: np.ndarray | None = None
    """``baro.csv``: times of the barometric altitudes (strictly increasing) [s]."""
    baro_height: np.ndarray | None = None
    """Barometric altitude, up, with any constant offset [m]."""
    tdoa_t: np.ndarray | None = None
    """``tdoa.csv``: times of the TDoA measurements (non-decreasing) [s]."""
    tdoa_a: np.ndarray | None = None
    """Index into :attr:`anchors_nav` of each measurement's anchor A."""
    tdoa_b: np.ndarray | None = None
    """Index into :attr:`anchors_nav` of its anchor B (never A)."""
    tdoa_ddist: np.ndarray | None = None
    """Distance difference ``|p - a_b| - |p - a_a|`` [m] (the Crazyflie's distanceDiff of idB minus idA)."""
    skipped: dict[str, int] = field(default_factory=dict)
    """Rows skipped per file (a NaN or empty sample value)."""


def _at(name: str, line: int, col: int, column: str) -> str:
    """Where in a file: ``"uwb.csv, line 12, column 2 (anchor_id)"`` (``col`` counted from 0)."""
    return f"{name}, line {line}, column {col + 1} ({column})"


def _rows(
    path: Path,
    columns: tuple[str, ...],
    optional: bool = False,
    maybe: tuple[str, ...] = (),
    allow_empty: bool = False,
):
    """The header's positions of ``columns`` (and of those of ``maybe`` it has) and the data rows ``(line
    number, fields)`` of a CSV file (``allow_empty``: a header without rows is no rows, not an error)."""
    name = path.name
    if not path.is_file():
        if optional:
            return None
        raise LogError(f"{path}: missing (a log folder needs imu.csv, uwb.csv and anchors.csv; docs/logs.md)")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise LogError(f"{name}: not UTF-8 text ({exc})") from None
    except OSError as exc:
        raise LogError(f"{name}: cannot read: {exc.strerror or exc}") from None
    lines = [
        (i + 1, ln)
        for i, ln in enumerate(text.splitlines())
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if not lines:
        raise LogError(f"{name}: empty (expected a header line: {', '.join(columns)})")
    head_no, head = lines[0]
    header = [h.strip() for h in next(csv.reader([head]))]
    where = {}
    for c in columns:
        if c not in header:
            raise LogError(
                f"{name}, line {head_no}: missing column {c!r} (the header has {', '.join(header)})"
            )
        where[c] = header.index(c)
    for c in maybe:
        if c in header:
            where[c] = header.index(c)
    rows = []
    for no, ln in lines[1:]:
        fields = next(csv.reader([ln]))
        if len(fields) != len(header):
            raise LogError(f"{name}, line {no}: {len(fields)} fields, the header has {len(header)}")
        rows.append((no, fields))
    if not rows and not allow_empty:
        raise LogError(f"{name}: no data rows after the header")
    return where, rows


def _table(
    path: Path,
    columns: tuple[str, ...],
    nan_ok: tuple[str, ...],
    skipped: dict[str, int],
    optional: bool = False,
    maybe: tuple[str, ...] = (),
    allow_empty: bool = False,
):
    """The columns as a float array (rows, len(columns)); a NaN or empty value in a ``nan_ok`` column skips
    the row (counted), anywhere else it is an error naming line and column. The columns of ``maybe`` that
    the header has follow ``columns``. A well-formed file is parsed by numpy in C (:func:`_fast_table`,
    ~10x faster); anything it does not take goes through the row-by-row parser, which names the error."""
    fast = _fast_table(path, columns, nan_ok, maybe)
    if fast is not None:
        out, lines, cols, n_skipped = fast
        if n_skipped:
            skipped[path.name] = skipped.get(path.name, 0) + n_skipped
        return out, lines, cols
    got = _rows(path, columns, optional, maybe, allow_empty)
    if got is None:
        return None, None, None
    where, rows = got
    columns = tuple(columns) + tuple(c for c in maybe if c in where)
    cols = [where[c] for c in columns]
    out = np.empty((len(rows), len(columns)))
    lines = np.empty(len(rows), dtype=np.int64)
    keep = 0
    for no, fields in rows:
        row = out[keep]
        bad = False
        for k, (c, col) in enumerate(zip(columns, cols, strict=True)):
            text = fields[col].strip()
            try:
                v = float(text) if text else math.nan
            except ValueError:
                raise LogError(f"{_at(path.name, no, col, c)}: not a number: {text!r}") from None
            if not math.isfinite(v):
                if c in nan_ok and not math.isinf(v):
                    bad = True
                else:
                    raise LogError(f"{_at(path.name, no, col, c)}: {text or 'empty'} is not a finite number")
            row[k] = v
        if bad:
            skipped[path.name] = skipped.get(path.name, 0) + 1
            continue
        lines[keep] = no
        keep += 1
    return out[:keep], lines[:keep], cols


def _fast_table(path: Path, columns: tuple[str, ...], nan_ok: tuple[str, ...], maybe: tuple[str, ...]):
    """:func:`_table` for a file without comments, blank lines, empty fields or anything but numbers past
    its header, in one ``numpy.loadtxt`` call; ``None`` whenever the file is not that (then the careful
    parser reads it and says what is wrong). A NaN in a ``nan_ok`` column skips the row, as there."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    head, sep, body = text.partition("\n")
    if not sep or not body.strip() or "#" in text or ",," in body or "\n\n" in body.rstrip("\n"):
        return None
    header = [h.strip() for h in head.split(",")]
    if any(c not in header for c in columns):
        return None
    columns = tuple(columns) + tuple(c for c in maybe if c in header)
    cols = [header.index(c) for c in columns]
    try:
        data = np.loadtxt(io.StringIO(body), delimiter=",", ndmin=2)
    except ValueError:
        return None
    if data.shape[1] != len(header) or np.isinf(data[:, cols]).any():
        return None  # a row of another width, or an infinity: the careful parser names it
    out = np.ascontiguousarray(data[:, cols])
    nan = np.isnan(out)
    if nan.any():
        ok = np.array([c in nan_ok for c in columns])
        if nan[:, ~ok].any():
            return None  # a NaN where none may be: the careful parser names it
    keep = ~nan.any(axis=1)
    lines = np.arange(2, len(out) + 2, dtype=np.int64)
    return out[keep], lines[keep], cols, int((~keep).sum())


def _ids(name: str, what: str, ids: np.ndarray, lines: np.ndarray, col: int):
    """Integer ids >= 0, each once: the ids and their index."""
    for k, v in enumerate(ids):
        if v != int(v) or v < 0:
            raise LogError(f"{_at(name, lines[k], col, what + '_id')}: not an integer id >= 0: {float(v)!r}")
    ids = ids.astype(np.int64)
    if len(set(ids.tolist())) != len(ids):
        dup = next(int(v) for v in ids if (ids == v).sum() > 1)
        raise LogError(f"{name}: {what} {dup} is listed twice")
    return ids, {int(v): k for k, v in enumerate(ids)}


def _lookup(
    name: str,
    column: str,
    values: np.ndarray,
    lines,
    col: int,
    index: dict,
    ids,
    listing: str,
    what: str | None = None,
):
    """The index of each id in ``values``; an unknown or non-integer id names its line and column (``what``:
    the word for an id, by default the column's name less ``_id``)."""
    out = np.empty(len(values), dtype=np.int64)
    for k, v in enumerate(values):
        if v != int(v) or int(v) not in index:
            raise LogError(
                f"{_at(name, lines[k], col, column)}: unknown {what or column[:-3]} {v:g}; "
                f"{listing} has {', '.join(str(i) for i in ids) or 'none'}"
            )
        out[k] = index[int(v)]
    return out


def _monotonic(name: str, t: np.ndarray, lines: np.ndarray, col: int, strict: bool) -> None:
    d = np.diff(t)
    bad = np.flatnonzero(d <= 0.0 if strict else d < 0.0)
    if len(bad):
        i = int(bad[0]) + 1
        word = "after" if strict else "at or after"
        raise LogError(
            f"{_at(name, lines[i], col, 't_s')}: time {float(t[i])!r} is not {word} the previous "
            f"sample's {float(t[i - 1])!r} (line {lines[i - 1]}): samples must be in time order"
        )


def read_log(directory: str | os.PathLike[str], overrides: dict[str, object] | None = None) -> Log:
    """The log in ``directory`` (``docs/logs.md``), its ``log.toml`` with ``overrides`` (dotted keys, as
    ``--set``) applied. Raises LogError (a bad CSV file) or ConfigError (a bad log.toml)."""
    d = Path(directory)
    if not d.is_dir():
        raise LogError(f"{d}: not a folder (a log is a folder of CSV files, docs/logs.md)")
    toml = d / "log.toml"
    if toml.is_file():
        config = load_toml(LogConfig, toml, overrides)
    else:
        from swarm.config import apply_overrides, from_mapping

        config = from_mapping(LogConfig, apply_overrides({}, overrides or {}))
    skipped: dict[str, int] = {}
    a, a_lines, a_cols = _table(d / "anchors.csv", ANCHOR_COLUMNS, (), skipped, allow_empty=True)
    ids, index = _ids("anchors.csv", "anchor", a[:, 0], a_lines, a_cols[0])

    imu, i_lines, i_cols = _table(d / "imu.csv", IMU_COLUMNS, IMU_COLUMNS[1:], skipped)
    _monotonic("imu.csv", imu[:, 0], i_lines, i_cols[0], strict=True)
    uwb, u_lines, u_cols = _table(d / "uwb.csv", UWB_COLUMNS, ("range_m",), skipped, allow_empty=True)
    _monotonic("uwb.csv", uwb[:, 0], u_lines, u_cols[0], strict=False)
    anchor_index = _lookup("uwb.csv", "anchor_id", uwb[:, 1], u_lines, u_cols[1], index, ids, "anchors.csv")
    neg = np.flatnonzero(uwb[:, 2] < 0.0)
    if len(neg):
        k = int(neg[0])
        raise LogError(
            f"{_at('uwb.csv', u_lines[k], u_cols[2], 'range_m')}: negative range {float(uwb[k, 2])!r}"
        )

    log = Log(
        d,
        config,
        imu[:, 0].copy(),
        imu[:, 1:4].copy(),
        imu[:, 4:7].copy(),
        uwb[:, 0].copy(),
        anchor_index,
        uwb[:, 2].copy(),
        ids,
        a[:, 1:4].copy(),
        skipped=skipped,
    )
    truth, t_lines, t_cols = _table(d / "truth.csv", TRUTH_COLUMNS, (), skipped, optional=True)
    if truth is not None:
        _monotonic("truth.csv", truth[:, 0], t_lines, t_cols[0], strict=True)
        norms = np.linalg.norm(truth[:, 4:8], axis=1)
        bad = np.flatnonzero(np.abs(norms - 1.0) > QUAT_NORM_TOL)
        if len(bad):
            k = int(bad[0])
            raise LogError(
                f"{_at('truth.csv', t_lines[k], t_cols[4], 'qx')}: quaternion norm {norms[k]:.6g} is not "
                f"within {QUAT_NORM_TOL:g} of 1 (qx, qy, qz, qw, scalar-last)"
            )
        log.truth_t, log.truth_p, log.truth_q = (
            truth[:, 0].copy(),
            truth[:, 1:4].copy(),
            truth[:, 4:8] / norms[:, None],
        )
    _read_vision(d, log, skipped)
    _read_height_baro(d, log, skipped)
    _read_tdoa(d, log, index, skipped)
    return log


def _read_height_baro(d: Path, log: Log, skipped: dict[str, int]) -> None:
    """The optional ``height.csv`` (a downward range finder) and ``baro.csv`` (barometric altitude)."""
    h, h_lines, h_cols = _table(d / "height.csv", HEIGHT_COLUMNS, ("range_m",), skipped, optional=True)
    if h is not None:
        _monotonic("height.csv", h[:, 0], h_lines, h_cols[0], strict=True)
        neg = np.flatnonzero(h[:, 1] < 0.0)
        if len(neg):
            k = int(neg[0])
            raise LogError(
                f"{_at('height.csv', h_lines[k], h_cols[1], 'range_m')}: negative range {float(h[k, 1])!r}"
            )
        log.height_t, log.height_range = h[:, 0].copy(), h[:, 1].copy()
    b, b_lines, b_cols = _table(d / "baro.csv", BARO_COLUMNS, ("height_m",), skipped, optional=True)
    if b is not None:
        _monotonic("baro.csv", b[:, 0], b_lines, b_cols[0], strict=True)
        log.baro_t, log.baro_height = b[:, 0].copy(), b[:, 1].copy()


def _read_tdoa(d: Path, log: Log, index: dict[int, int], skipped: dict[str, int]) -> None:
    """The optional ``tdoa.csv``: anchors of ``anchors.csv``, two different ones per row, and a distance
    difference no longer than their baseline (plus :data:`TDOA_BASELINE_TOL_M`)."""
    td, lines, cols = _table(d / "tdoa.csv", TDOA_COLUMNS, ("ddist_m",), skipped, optional=True)
    if td is None:
        return
    _monotonic("tdoa.csv", td[:, 0], lines, cols[0], strict=False)
    ids = log.anchor_ids
    a = _lookup("tdoa.csv", "anchor_a", td[:, 1], lines, cols[1], index, ids, "anchors.csv", "anchor")
    b = _lookup("tdoa.csv", "anchor_b", td[:, 2], lines, cols[2], index, ids, "anchors.csv", "anchor")
    same = np.flatnonzero(a == b)
    if len(same):
        k = int(same[0])
        raise LogError(
            f"{_at('tdoa.csv', lines[k], cols[2], 'anchor_b')}: anchor {int(td[k, 2])} is also anchor_a: a "
            "distance difference needs two different anchors"
        )
    baseline = np.linalg.norm(log.anchors_nav[b] - log.anchors_nav[a], axis=1)
    bad = np.flatnonzero(np.abs(td[:, 3]) > baseline + TDOA_BASELINE_TOL_M)
    if len(bad):
        k = int(bad[0])
        raise LogError(
            f"{_at('tdoa.csv', lines[k], cols[3], 'ddist_m')}: |{float(td[k, 3])!r}| is longer than the "
            f"{baseline[k]:.3f} m between anchors {int(td[k, 1])} and {int(td[k, 2])} "
            f"(+ {TDOA_BASELINE_TOL_M:g} m): no position has that distance difference"
        )
    log.tdoa_t, log.tdoa_a, log.tdoa_b, log.tdoa_ddist = td[:, 0].copy(), a, b, td[:, 3].copy()


def _read_vision(d: Path, log: Log, skipped: dict[str, int]) -> None:
    """``vision.csv`` and its ``markers.csv`` into ``log`` (nothing without a ``vision.csv``)."""
    vis, v_lines, v_cols = _table(
        d / "vision.csv",
        VISION_COLUMNS,
        ("x_m", "y_m", "z_m", *VISION_SIGMA_COLUMNS),
        skipped,
        optional=True,
        maybe=VISION_SIGMA_COLUMNS,
    )
    if vis is None:
        return
    if len(v_cols) not in (len(VISION_COLUMNS), len(VISION_COLUMNS) + 3):
        raise LogError(
            f"vision.csv: give all three of {', '.join(VISION_SIGMA_COLUMNS)} or none (then log.toml's "
            "vision.sigma_m applies)"
        )
    if not (d / "markers.csv").is_file():
        raise LogError("vision.csv: needs markers.csv (marker_id, x_m, y_m, z_m: the surveyed markers)")
    mids, markers_nav = read_markers(d / "markers.csv", skipped)
    mindex = {int(v): k for k, v in enumerate(mids)}
    _monotonic("vision.csv", vis[:, 0], v_lines, v_cols[0], strict=False)
    marker = _lookup("vision.csv", "marker_id", vis[:, 1], v_lines, v_cols[1], mindex, mids, "markers.csv")
    if vis.shape[1] == len(VISION_COLUMNS) + 3:
        sig = vis[:, 5:8]
        bad = np.argwhere(sig <= 0.0)
        if len(bad):
            k, c = int(bad[0, 0]), int(bad[0, 1])
            raise LogError(
                f"{_at('vision.csv', v_lines[k], v_cols[5 + c], VISION_SIGMA_COLUMNS[c])}: a standard "
                f"deviation must be > 0, got {float(sig[k, c])!r}"
            )
    else:
        sig = np.broadcast_to(np.asarray(log.config.vision.sigma_m, dtype=float), (len(vis), 3))
    log.vision_t = vis[:, 0].copy()
    log.vision_marker = marker
    log.vision_xyz = vis[:, 2:5].copy()
    log.vision_sigma = np.array(sig, dtype=float)
    log.marker_ids, log.markers_nav = mids, markers_nav


def read_markers(path: Path, skipped: dict[str, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``markers.csv``: the marker ids (integers >= 0, each once) and their surveyed positions (n, 3), nav
    [m]; LogError naming the line and column of a bad row."""
    mk, m_lines, m_cols = _table(Path(path), MARKER_COLUMNS, (), {} if skipped is None else skipped)
    mids, _ = _ids(Path(path).name, "marker", mk[:, 0], m_lines, m_cols[0])
    return mids, mk[:, 1:4].copy()


def read_anchors(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """An ``anchors.csv`` file: the anchor ids (integers >= 0, each once) and their positions (n, 3), nav
    [m]; LogError naming the line and column of a bad row."""
    a, a_lines, a_cols = _table(Path(path), ANCHOR_COLUMNS, (), {})
    ids, _ = _ids(Path(path).name, "anchor", a[:, 0], a_lines, a_cols[0])
    return ids, a[:, 1:4].copy()
