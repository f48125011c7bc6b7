"""Inertial and radio sensor models: rate gyro, UWB two-way ranging with faults, optional AHRS attitude.

Each model is a frozen params dataclass plus a sampling function or a tiny state-holding class; state
(gyro bias, round-robin index) and the ``numpy.random.Generator`` are passed in explicitly, so a seed
means the same measurements in the in-process simulation and in the distributed one. Every sample draws
the same number of random numbers whatever the faults, so switching a fault on does not reshuffle the
white noise of the other samples (common random numbers between scenario variants).

Paper sec. III adopts the gyro and UWB models of Mueller, Hamer & D'Andrea 2015 (its ref. [19]): white
gyro noise matching a VectorNav VN-100 and 2 cm white range noise. The faults (NLOS/multipath outliers,
clock-drift bias, dropouts) are those the paper's sec. IV-D names as the reason for outlier rejection.
These run at 50-100 Hz per vehicle in a simulation that must run hundreds of times faster than real
time, so each call makes one random draw and little else: the gyro's arithmetic is a small compiled
kernel, the UWB range plain Python floats (numpy's per-operation overhead dominated both).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike

from swarm.core._rot_nb import qexp, qmul, qnormalize
from swarm.core.range_error_params import RangeErrorParams
from swarm.core.range_errors import check_range_errors
from swarm.errors import ConfigError

__all__ = [
    "AhrsParams",
    "GyroParams",
    "UwbParams",
    "UwbRadio",
    "UwbSample",
    "ahrs_sample",
    "gyro_init_bias",
    "gyro_sample",
]

_DEG = math.pi / 180.0
_INV_SQRT2 = 1.0 / math.sqrt(2.0)


def _check_positive(section: str, name: str, value: float) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ConfigError(f"{section}.{name} must be a positive finite number, got {value!r}")


def _check_nonneg(section: str, name: str, value: float) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
        raise ConfigError(f"{section}.{name} must be a non-negative finite number, got {value!r}")


def _check_probability(section: str, name: str, value: float) -> None:
    if not (isinstance(value, int | float) and 0.0 <= value <= 1.0):
        raise ConfigError(f"{section}.{name} must be a probability in [0, 1], got {value!r}")


# ---- rate gyro -----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GyroParams:
    """A three-axis MEMS rate gyro of the VectorNav VN-100 class (paper sec. III, Fig. 7)."""

    rate_hz: float = 100.0
    """Output rate [Hz]; the hardware's IMU is read at 100 Hz (paper sec. VI-A)."""
    RENAMED: ClassVar[dict[str, tuple[str, float]]] = {"arw_deg_s_rthz": ("gyro_noise_rad_s_rthz", _DEG)}
    """Keys of older files and the names that replaced them (:mod:`swarm.config`)."""

    gyro_noise_rad_s_rthz: float = 0.0035 * _DEG
    """Angle random walk, the white rate-noise density [rad/s/sqrt(Hz)] (VN-100 datasheet: 0.0035
    deg/s/sqrt(Hz)); the name of the landing's and the sensor profiles' IMU key."""
    bias_instability_deg_h: float = 10.0
    """In-run bias instability [deg/h] (VN-100 class: ~10 deg/h), used as the stationary standard
    deviation of the Gauss-Markov bias."""
    bias_corr_time_s: float = 100.0
    """Correlation time tau of the first-order Gauss-Markov bias [s]."""
    initial_bias_sigma_deg_s: float = 10.0 / 3600.0
    """Standard deviation of the bias at switch-on [deg/s]; the default equals the Gauss-Markov sigma, so
    the bias process is stationary from the first sample."""
    enabled_bias: bool = True
    """Add the bias; ``False`` gives the paper's unbiased white-noise gyro (paper eq. 3)."""

    def __post_init__(self) -> None:
        for name in ("rate_hz", "gyro_noise_rad_s_rthz", "bias_corr_time_s"):
            _check_positive("gyro", name, getattr(self, name))
        for name in ("bias_instability_deg_h", "initial_bias_sigma_deg_s"):
            _check_nonneg("gyro", name, getattr(self, name))
        if not isinstance(self.enabled_bias, bool):
            raise ConfigError(f"gyro.enabled_bias must be a bool, got {self.enabled_bias!r}")

    @property
    def dt_s(self) -> float:
        """Sample interval [s]."""
        return 1.0 / self.rate_hz

    @property
    def bias_sigma_rad_s(self) -> float:
        """Stationary standard deviation of the Gauss-Markov bias [rad/s]."""
        return self.bias_instability_deg_h * _DEG / 3600.0

    @property
    def initial_bias_sigma_rad_s(self) -> float:
        """Switch-on bias standard deviation [rad/s]."""
        return self.initial_bias_sigma_deg_s * _DEG


def gyro_init_bias(params: GyroParams, rng: np.random.Generator) -> np.ndarray:
    """Switch-on bias ``b_0 ~ N(0, initial_bias_sigma^2 I)`` (3,) [rad/s], body frame; zeros when the
    bias is disabled (three normals are drawn either way)."""
    z = rng.standard_normal(3)
    if not params.enabled_bias:
        return np.zeros(3)
    return params.initial_bias_sigma_rad_s * z


def gyro_sample(
    w_true_body: ArrayLike, bias: np.ndarray, dt: float, params: GyroParams, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """One gyro sample: ``(w_meas (3,) [rad/s], new_bias (3,) [rad/s])``, body frame (two views of one new
    (6,) array: no allocation beyond the random draw).

    ``w_meas = w_true + b_k + n_k`` with white ``n_k ~ N(0, (ARW / sqrt(dt))^2 I)``: a rate sample that
    averages white noise of density ``ARW`` over ``dt`` (IEEE Std 952-1997, Annex C: its Allan deviation
    is ``ARW / sqrt(tau)``; Crassidis & Junkins 2011, sec. 7.2.1, gyro simulation ``sigma_v / sqrt(dt)``).

    The bias is a first-order Gauss-Markov process with correlation time ``tau`` and stationary standard
    deviation ``sigma_b``, advanced with its exact discretization
    ``b_{k+1} = exp(-dt/tau) b_k + sigma_b sqrt(1 - exp(-2 dt/tau)) w_k``, ``w_k ~ N(0, I)``
    (Maybeck 1979, Vol. 1, ch. 4; Brown & Hwang 2012, ch. 2-3): its variance stays ``sigma_b^2`` at any
    ``dt`` once stationary. With the bias disabled ``new_bias`` is ``bias`` unchanged.

    ``w_true_body`` (3,) true body rate [rad/s]; ``bias`` (3,) current bias [rad/s]; ``dt`` > 0 the time
    to the next sample [s] (normally ``params.dt_s``).
    """
    if not dt > 0.0:
        raise ValueError(f"dt must be positive, got {dt!r}")
    z = rng.standard_normal(6)
    if params.enabled_bias:
        phi = math.exp(-dt / params.bias_corr_time_s)
        s_b = params.bias_sigma_rad_s * math.sqrt(1.0 - phi * phi)
    else:
        phi, s_b = 1.0, 0.0
    w = np.asarray(w_true_body, dtype=np.float64)
    sigma_w = params.gyro_noise_rad_s_rthz / math.sqrt(dt)
    _gyro_kernel(w, np.asarray(bias, dtype=np.float64), z, sigma_w, phi, s_b)
    return z[:3], z[3:]


@numba.njit(cache=True)
def _gyro_kernel(w, bias, z, s_w, phi, s_b):
    """In place: ``z[:3] <- w + bias + s_w z[:3]``, ``z[3:] <- phi bias + s_b z[3:]``. Compiled because the
    gyro runs at 100 Hz per vehicle: numpy's per-operation overhead made the call 3x slower."""
    for i in range(3):
        n_w = z[i]
        n_b = z[3 + i]
        z[i] = w[i] + bias[i] + s_w * n_w
        z[3 + i] = phi * bias[i] + s_b * n_b


# ---- UWB two-way ranging ------------------------------------------------------------------------------


@dataclass(frozen=True)
class UwbParams(RangeErrorParams):
    """UWB two-way ranging of one tag against fixed anchors, one anchor per exchange in round robin
    (paper sec. III, sec. VI-A: ~50 Hz, 2 cm), with switchable faults (paper sec. IV-D) and the range errors
    of real flights (:class:`~swarm.core.range_error_params.RangeErrorParams`)."""

    mode: str = "twr"
    """``"twr"``: two-way ranging, one anchor per exchange (this class); ``"tdoa2"`` / ``"tdoa3"``: the
    Loco Positioning TDoA radio (:class:`swarm.core.tdoa_radio.TdoaRadio`, the scenario's ``[tdoa]``
    table): anchors transmit, tags only listen, and each UWB tick delivers every distance difference heard
    since the last (the range-error options below apply per link; ``rate_hz`` is then only how often they
    are handed over)."""
    rate_hz: float = 50.0
    """Exchanges per second [Hz]; each exchange ranges one anchor, so each anchor gets rate_hz / N."""
    sigma_m: float = 0.02
    """White range-noise standard deviation [m] (paper sec. III: 2 cm)."""
    nlos_probability: float = 0.0
    """Probability that an exchange is an NLOS/multipath outlier."""
    nlos_min_m: float = 0.3
    """Smallest extra path length of an outlier [m]; outliers are always long (a reflected path)."""
    nlos_max_m: float = 1.5
    """Largest extra path length of an outlier [m]; the extra length is uniform in [min, max]."""
    clock_drift_m_s: tuple[float, ...] = (0.0,)
    """Growth rate of the clock-drift range bias [m/s]: one value for every anchor link, or one per
    anchor (a plain number is accepted in code). The bias is ``rate * (t - clock_drift_start_s)`` after
    the start, zero before."""
    clock_drift_start_s: float = 0.0
    """Time at which the clock-drift bias starts growing [s]."""
    dropout_probability: float = 0.0
    """Probability that an exchange's reply is lost (no measurement)."""
    dropout_windows_s: tuple[tuple[float, float], ...] = ()
    """Intervals ``(start, end)`` [s], start inclusive, end exclusive, in which every reply is lost."""
    tdma: bool = False
    """Many tags on one channel, as the Loco Positioning TWR-TDMA shares it: time is cut into slots of
    ``tdma_slot_s``, a frame is ``tdma_frame_slots`` slots, each tag ranges once per frame (with its next
    anchor) in the slot ``address % frame`` (``[vehicles.X] uwb_address``, default its index), and tags
    with the same slot collide (both exchanges lost, counted). Each tag reports at most one range per UWB
    tick (``rate_hz``), so its rate is ``min(rate_hz, 1 / (frame * slot))``: ~238/N Hz for N tags once
    that is below ``rate_hz``. Off: every tag ranges at ``rate_hz`` (a single pair, today's default)."""
    tdma_slot_s: float = 0.0042
    """Length of one TDMA slot [s] (Loco Positioning TWR-TDMA: ~4.2 ms per exchange)."""
    tdma_frame_slots: int = 0
    """Slots per TDMA frame, a power of two; 0: the smallest power of two >= the number of tags."""

    def __post_init__(self) -> None:
        _check_positive("uwb", "rate_hz", self.rate_hz)
        if self.mode not in ("twr", "tdoa2", "tdoa3"):
            raise ConfigError(f"uwb.mode must be 'twr', 'tdoa2' or 'tdoa3', got {self.mode!r}")
        check_range_errors(self)
        if not isinstance(self.tdma, bool):
            raise ConfigError(f"uwb.tdma must be true or false, got {self.tdma!r}")
        _check_positive("uwb", "tdma_slot_s", self.tdma_slot_s)
        f = self.tdma_frame_slots
        if isinstance(f, bool) or not isinstance(f, int) or f < 0 or (f and f & (f - 1)):
            raise ConfigError(f"uwb.tdma_frame_slots must be 0 or a power of two (1, 2, 4, ...), got {f!r}")
        _check_positive("uwb", "sigma_m", self.sigma_m)
        for name in ("nlos_min_m", "nlos_max_m"):
            _check_nonneg("uwb", name, getattr(self, name))
        if self.nlos_max_m < self.nlos_min_m:
            raise ConfigError(
                f"uwb.nlos_max_m must be >= uwb.nlos_min_m ({self.nlos_min_m!r}), got {self.nlos_max_m!r}"
            )
        for name in ("nlos_probability", "dropout_probability"):
            _check_probability("uwb", name, getattr(self, name))
        drift = self.clock_drift_m_s
        if isinstance(drift, list | np.ndarray):
            drift = tuple(float(d) for d in drift)
        elif isinstance(drift, int | float) and not isinstance(drift, bool):
            drift = (drift,)
        object.__setattr__(self, "clock_drift_m_s", drift)
        values = drift if isinstance(drift, tuple) else (drift,)
        if len(values) == 0 or not all(isinstance(d, int | float) and math.isfinite(d) for d in values):
            raise ConfigError(
                f"uwb.clock_drift_m_s must be a finite number or a non-empty tuple of them, got {drift!r}"
            )
        if not (
            isinstance(self.clock_drift_start_s, int | float) and math.isfinite(self.clock_drift_start_s)
        ):
            raise ConfigError(
                f"uwb.clock_drift_start_s must be a finite number, got {self.clock_drift_start_s!r}"
            )
        windows = tuple(tuple(w) for w in self.dropout_windows_s)
        for w in windows:
            if not (
                len(w) == 2
                and all(isinstance(x, int | float) and math.isfinite(x) for x in w)
                and w[0] < w[1]
            ):
                raise ConfigError(
                    "uwb.dropout_windows_s must be (start, end) pairs with start < end, "
                    f"got {self.dropout_windows_s!r}"
                )
        object.__setattr__(self, "dropout_windows_s", windows)

    @property
    def period_s(self) -> float:
        """Time between exchanges [s]."""
        return 1.0 / self.rate_hz


class UwbSample(NamedTuple):
    """One two-way range (a NamedTuple: cheap to create at 50 Hz per vehicle)."""

    t_s: float
    """Time of the exchange [s]."""
    anchor_id: int
    """Index of the ranged anchor in the radio's anchor array."""
    range_m: float
    """Measured range [m], never negative."""
    is_outlier: bool
    """True when an NLOS/multipath excess was added (ground truth for tests and metrics only)."""


class UwbRadio:
    """The UWB tag of one vehicle ranging the anchors ``anchors_nav`` (N, 3) [m], frame ``nav``, in round
    robin: call :meth:`sample` once per exchange, every ``params.period_s``."""

    def __init__(self, anchors_nav: ArrayLike, params: UwbParams) -> None:
        a = np.array(anchors_nav, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] == 0 or not np.all(np.isfinite(a)):
            raise ValueError(f"anchors_nav must be a finite (N, 3) array with N >= 1, got shape {a.shape}")
        drift = params.clock_drift_m_s
        if len(drift) == 1:
            drift = drift[0]
        if isinstance(drift, tuple):
            if len(drift) != a.shape[0]:
                raise ConfigError(
                    f"uwb.clock_drift_m_s must have one value per anchor ({a.shape[0]}), got {drift!r}"
                )
            self._drift_m_s = tuple(float(d) for d in drift)
        else:
            self._drift_m_s = (float(drift),) * a.shape[0]
        self.params = params
        self.anchors_nav = a
        self.anchors_nav.setflags(write=False)
        self._anchor_rows = [tuple(row) for row in a.tolist()]
        self._next = 0
        self._vector = self.vector

    @property
    def next_anchor(self) -> int:
        """Index of the anchor the next exchange ranges."""
        return self._next

    def drift_bias_m(self, t_s: float, anchor_id: int) -> float:
        """Clock-drift range bias [m] of the link to ``anchor_id`` at time ``t_s`` [s]."""
        elapsed = t_s - self.params.clock_drift_start_s
        return self._drift_m_s[anchor_id] * elapsed if elapsed > 0.0 else 0.0

    def sample(self, t_s: float, tag_nav: ArrayLike, rng: np.random.Generator) -> UwbSample | None:
        """One exchange at time ``t_s`` [s] with the tag at ``tag_nav`` (3,) [m], frame ``nav`` (the tag, not
        the centre of mass: ``p_nav + R(q_nav_body) P1``). Returns None when the reply is lost.

        ``range = |tag - anchor| + n + b_drift(t) + [outlier] U(nlos_min, nlos_max)``, ``n ~ N(0, sigma^2)``,
        clipped at zero. NLOS and multipath replies travel a longer path, so outliers only add length
        (paper sec. IV-D and its ref. [29]). A relative clock-frequency offset biases
        two-way ranging in proportion to the reply delay (Neirynck, Luk & McLaughlin 2016, sec. II); its
        slow wander over a run is modelled as a bias growing linearly in time. The round robin advances
        even on a dropout: the exchange took place, only its reply was lost.
        """
        i = self._next
        self._next = (i + 1) % len(self._anchor_rows)
        # One draw of four normals per exchange whatever happens (see uwb_exchange).
        z = rng.standard_normal(4)
        tag = np.asarray(tag_nav, dtype=np.float64)
        quiet = any(a <= t_s < b for a, b in self.params.dropout_windows_s)
        lost, r, outlier = uwb_exchange(
            t_s, tag, self.anchors_nav[i], z, self._drift_m_s[i], self._vector, quiet, 0.0
        )
        return None if lost else UwbSample(t_s, i, r, outlier)

    def drift_rate(self, anchor_id: int) -> float:
        """Clock-drift bias growth rate of the link to ``anchor_id`` [m/s]."""
        return self._drift_m_s[anchor_id]

    @property
    def vector(self) -> np.ndarray:
        """The parameters as the flat vector :func:`uwb_exchange` reads (``UWB_*`` indices). The dropout
        windows are not in it: they are the radio environment (``env_lost``), which the world decides."""
        p = self.params
        v = np.empty(UWB_N)
        v[UWB_SIGMA], v[UWB_P_DROP], v[UWB_P_NLOS] = p.sigma_m, p.dropout_probability, p.nlos_probability
        v[UWB_NLOS_MIN], v[UWB_NLOS_MAX], v[UWB_DRIFT_START] = (
            p.nlos_min_m,
            p.nlos_max_m,
            p.clock_drift_start_s,
        )
        return v


UWB_SIGMA, UWB_P_DROP, UWB_P_NLOS, UWB_NLOS_MIN, UWB_NLOS_MAX, UWB_DRIFT_START = range(6)
UWB_N = 6


@numba.njit(cache=True)
def uwb_exchange(t_s, tag_nav, anchor_nav, z, drift_m_s, prm, env_lost, env_nlos_p):
    """One two-way-ranging exchange: ``(lost, range_m, is_outlier)``; the arithmetic of
    :meth:`UwbRadio.sample` (its docstring has the model), compiled so the simulation's inner loop can
    call it. ``prm`` is :attr:`UwbRadio.vector`. The radio environment of the exchange
    (:func:`swarm.step.radio.radio_env`): ``env_lost`` loses the reply (a dropout window); inside an NLOS
    burst window the outlier probability is ``env_nlos_p`` when larger than the radio's own. ``z`` (4,)
    standard normals: ``z0`` is the range noise; ``z1..z3`` become the dropout, outlier and outlier-size
    uniforms through the normal CDF (probability integral transform), so an exchange always consumes four
    draws whatever happens."""
    if 0.5 * math.erfc(-z[1] * _INV_SQRT2) < prm[UWB_P_DROP]:
        return True, 0.0, False
    if env_lost:
        return True, 0.0, False
    dx = tag_nav[0] - anchor_nav[0]
    dy = tag_nav[1] - anchor_nav[1]
    dz = tag_nav[2] - anchor_nav[2]
    r = math.sqrt(dx * dx + dy * dy + dz * dz) + prm[UWB_SIGMA] * z[0]
    elapsed = t_s - prm[UWB_DRIFT_START]
    if elapsed > 0.0:
        r += drift_m_s * elapsed
    u_nlos = 0.5 * math.erfc(-z[2] * _INV_SQRT2)
    outlier = u_nlos < prm[UWB_P_NLOS]
    if not outlier and env_nlos_p > 0.0:  # an NLOS burst (swarm.core.faults): the same uniform
        outlier = u_nlos < env_nlos_p
    if outlier:
        r += prm[UWB_NLOS_MIN] + (prm[UWB_NLOS_MAX] - prm[UWB_NLOS_MIN]) * 0.5 * math.erfc(-z[3] * _INV_SQRT2)
    return False, (r if r > 0.0 else 0.0), outlier


# ---- AHRS attitude (optional) --------------------------------------------------------------------------


@dataclass(frozen=True)
class AhrsParams:
    """An attitude output such as the VN-100's on-board AHRS (paper sec. VI-A reads it at 100 Hz)."""

    enabled: bool = False
    """Publish AHRS attitudes at all (the paper's simulation, sec. III, uses none)."""
    rate_hz: float = 10.0
    """Output rate [Hz]."""
    sigma_deg: float = 0.5
    """Per-axis standard deviation of the body-frame rotation-vector error [deg]."""

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ConfigError(f"ahrs.enabled must be a bool, got {self.enabled!r}")
        _check_positive("ahrs", "rate_hz", self.rate_hz)
        _check_positive("ahrs", "sigma_deg", self.sigma_deg)

    @property
    def sigma_rad(self) -> float:
        """Per-axis error standard deviation [rad]."""
        return self.sigma_deg * _DEG

    @property
    def cov_body(self) -> np.ndarray:
        """Error covariance (3, 3) [rad^2] for ``PoseEstimator.update_attitude``."""
        return self.sigma_rad**2 * np.eye(3)


def ahrs_sample(q_true_nav_body: ArrayLike, params: AhrsParams, rng: np.random.Generator) -> np.ndarray:
    """Measured attitude ``q_meas = q_true (x) exp(dtheta)`` (4,), scalar-last, with body-frame
    ``dtheta ~ N(0, sigma^2 I)``: the multiplicative error that ``PoseEstimator.update_attitude`` assumes
    (Markley 2003, written with the Hamilton product). ``q_true_nav_body`` (4,) unit quaternion."""
    q = np.asarray(q_true_nav_body, dtype=np.float64)
    return qnormalize(qmul(q, qexp(params.sigma_rad * rng.standard_normal(3))))
