"""IMU-driven error-state Kalman filter: position, velocity, attitude, IMU biases and UWB range biases.

The process model of a vehicle that carries a 6-axis IMU (a quadrotor, a rover with a VN-100, a Crazyflie):
specific force and angular rate drive the nominal state, gravity is known, accelerometer and gyro biases
are random-walk states, and optionally so is each anchor's range bias (real two-way ranging is biased by
tens of centimetres per anchor, and the bias moves once airborne). Equations and their sources are in
:mod:`swarm.core._imu_nb` (Sola 2017, sec. 5-7).

Robustness to NLOS ranges, beyond the hard Mahalanobis gate: a range whose normalised innovation exceeds
``huber_k`` is underweighted (its variance inflated by ``|e| / huber_k``, Huber's M-estimator), so a
biased range that passes the gate pulls with a bounded influence; every outcome is counted per anchor.

Divergence (:func:`divergence_limits`): over the last ``window`` ranges, the filter is declared
inconsistent if the share rejected by the gate exceeds ``reject_share_max``, or the mean NIS of the
accepted ones exceeds its chi-square quantile at ``1 - divergence_alpha`` (under a consistent filter each
accepted range's NIS is chi-square with one degree of freedom, so the sum of ``n`` is chi-square with
``n``; the gate truncates the tail, which only lowers the false-alarm probability below
``divergence_alpha`` per window). The caller then re-initialises the position from the latest range to each
anchor (:func:`swarm.core.ranging.position_from_ranges`) and reports an ``estimator_reset`` event.

Timestamps: each sample carries its own time; the filter predicts to it, holding the latest IMU sample over
the interval (zero-order hold), so sensors run at any rate, with jitter and dropouts. A sample older than
the filter's time is dropped and counted.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from swarm.core import _imu_nb as nb
from swarm.errors import ConfigError

N_CORE = 15
"""Error states without range biases: position, velocity, attitude, accelerometer bias, gyro bias."""


@dataclass(frozen=True)
class ImuFilterParams:
    """Noise model and robustness settings of the IMU-driven filter (SI units, densities per sqrt(Hz))."""

    accel_noise: float = 0.02
    """Accelerometer white noise density [m/s^2/sqrt(Hz)] (VN-100: 0.14 mg/sqrt(Hz) ~ 0.0014; MEMS in a
    vibrating airframe: 0.02-0.1)."""
    gyro_noise: float = 0.002
    """Gyro white noise density [rad/s/sqrt(Hz)]."""
    accel_bias_rw: float = 1e-3
    """Accelerometer bias random walk [m/s^3/sqrt(Hz)]."""
    gyro_bias_rw: float = 1e-5
    """Gyro bias random walk [rad/s^2/sqrt(Hz)]."""
    range_bias: bool = True
    """Estimate one range offset per anchor (a random walk around its calibrated value: antenna delay and
    the anchor's own multipath)."""
    range_bias_rw: float = 0.002
    """The per-anchor offset's random walk [m/sqrt(s)] (slow: the step at take-off is a phase change's
    re-opened covariance, not a walk)."""
    range_common_offset: bool = True
    """Estimate one offset common to every anchor (the tag's antenna delay), a random walk."""
    range_common_offset_rw: float = 0.001
    """Its random walk [m/sqrt(s)]."""
    range_gm: bool = True
    """A first-order Gauss-Markov range error per anchor (time-correlated multipath; real ranges correlate
    0.3-0.84 at 0.1 s and 0.06-0.44 at 1 s, docs/logs.md)."""
    range_gm_sigma_m: float = 0.02
    """Its stationary standard deviation [m]: the least correlated part; the white part adapts in flight
    (``[robust] adapt``). 0.02 m held on the development hover (NEES 2.2) and on a synthetic flight of the
    ``real-crazyflie`` profile (NEES 4.6); 0.05 m made both conservative (NEES ~1), 0.01 m overconfident."""
    range_gm_tau_s: float = 1.0
    """Its correlation time [s] (0.5-2 s held on real flights)."""
    accel_vibration_k: float = 0.8
    """Accelerometer noise the rotors' vibration adds: per body axis a white density of this times that
    axis' vibration power (the lag-1 autocovariance of the specific force around its 10 ms mean, a slow
    mean: zero for a white sensor noise) [s^2.5/m] (0: none; :func:`swarm.core._imu_nb.vibration_noise`).
    The error a vibrating accelerometer rectifies grows with the vibration's power (a second-order
    nonlinearity: IEEE Std 1293-1998 annex). 0.8: the development TDoA flights (power 0.05-0.27 (m/s^2)^2,
    0.9-2.0 on the faulty accelerometer of 0425 traj1-16: 0.04-0.2 and 0.7-1.6 m/s^2/sqrt(Hz), where their
    accelerometers' errors against the truth's acceleration measured 0.1-0.2 and 0.7-0.8) and the
    development hover (0.02-0.04: 0.01-0.03, beside its measured 0.02-0.04)."""
    baro_offset_rw: float = 0.01
    """The barometer offset's random walk [m/sqrt(s)] (a state only when a log has ``baro.csv``)."""
    gravity_nav: tuple[float, float, float] = (0.0, 0.0, -9.81)
    """Gravity in the navigation frame [m/s^2] (the log's gravity axis)."""
    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """UWB tag antenna in the body frame, from the IMU [m]."""
    gate_probability: float = 0.9995
    """Hard gate: a range whose squared Mahalanobis distance exceeds this chi-square(1) quantile is
    rejected."""
    huber_k: float = 2.0
    """Huber threshold on the normalised innovation (0: off)."""
    window: int = 50
    """Ranges in the divergence test's window."""
    reject_share_max: float = 0.5
    """Divergence if more than this share of the window's ranges is rejected."""
    divergence_alpha: float = 1e-6
    """False-alarm probability per window of the windowed NIS test under a consistent filter."""

    def __post_init__(self) -> None:
        for name in ("accel_noise", "gyro_noise", "accel_bias_rw", "gyro_bias_rw", "range_bias_rw",
                     "range_common_offset_rw", "range_gm_sigma_m", "baro_offset_rw",
                     "accel_vibration_k"):  # fmt: skip
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v >= 0.0):
                raise ConfigError(f"estimator.{name} must be a finite number >= 0, got {v!r}")
        if not 0.5 < self.gate_probability < 1.0:
            raise ConfigError(
                f"estimator.gate_probability must be in (0.5, 1), got {self.gate_probability!r}"
            )
        if not (np.isfinite(self.huber_k) and self.huber_k >= 0.0):
            raise ConfigError(f"estimator.huber_k must be >= 0 (0: off), got {self.huber_k!r}")
        if not (isinstance(self.window, int) and 5 <= self.window <= 10000):
            raise ConfigError(f"estimator.window must be an integer in [5, 10000], got {self.window!r}")
        if not 0.0 < self.reject_share_max <= 1.0:
            raise ConfigError(f"estimator.reject_share_max must be in (0, 1], got {self.reject_share_max!r}")
        if not 0.0 < self.divergence_alpha < 0.5:
            raise ConfigError(
                f"estimator.divergence_alpha must be in (0, 0.5), got {self.divergence_alpha!r}"
            )
        if not (isinstance(self.range_gm_tau_s, int | float) and np.isfinite(self.range_gm_tau_s)
                and self.range_gm_tau_s > 0.0):  # fmt: skip
            raise ConfigError(
                f"estimator.range_gm_tau_s must be a finite number > 0, got {self.range_gm_tau_s!r}"
            )
        g = np.asarray(self.gravity_nav, dtype=float)
        if g.shape != (3,) or not np.isfinite(g).all() or not 5.0 < np.linalg.norm(g) < 15.0:
            raise ConfigError(
                f"estimator.gravity_nav must be a finite 3-vector of norm ~9.8, got {self.gravity_nav!r}"
            )

    def vector(self) -> np.ndarray:
        """The kernels' parameter vector (``swarm.core._imu_nb.PRM_*``)."""
        prm = np.zeros(nb.N_PRM)
        prm[nb.PRM_SIG_A], prm[nb.PRM_SIG_G] = self.accel_noise, self.gyro_noise
        prm[nb.PRM_SIG_BA], prm[nb.PRM_SIG_BG] = self.accel_bias_rw, self.gyro_bias_rw
        prm[nb.PRM_SIG_RB] = self.range_bias_rw
        prm[nb.PRM_G : nb.PRM_G + 3] = self.gravity_nav
        prm[nb.PRM_LEVER : nb.PRM_LEVER + 3] = self.lever_arm_m
        prm[nb.PRM_GATE] = chi2_gate(self.gate_probability, 1)
        prm[nb.PRM_HUBER] = self.huber_k
        return prm


@dataclass(frozen=True)
class RobustParams:
    """The robust range model of a replay (``[robust]`` of log.toml; :func:`swarm.core._imu_nb.fuse_range`):
    per-anchor noise adaptation, NLOS episodes, and the window test's effective sample size."""

    adapt: bool = True
    """Estimate each anchor's white-noise sigma in flight (covariance matching); the ground calibration, or
    ``[uwb] sigma_m``, is only its prior."""
    adapt_alpha: float = 0.02
    """Weight of one range in the adaptation's exponentially weighted means (memory ~1 / alpha ranges)."""
    sigma_ceiling_m: float = 0.5
    """Largest adapted sigma [m] (the floor is ``[uwb] sigma_floor_m``)."""
    nlos: bool = True
    """Detect sustained NLOS per anchor (a one-sided CUSUM of the normalised innovation) and hold its ranges
    out while it lasts."""
    cusum_k: float = 1.0
    """The CUSUM's allowance on the normalised innovation (half the 2-sigma shift it is tuned to)."""
    cusum_h: float = 6.0
    """Its decision threshold (released under half of it)."""
    cusum_clip: float = 4.0
    """A single range's largest contribution (an isolated outlier does not declare an episode)."""
    nlos_max_s: float = 10.0
    """An episode held longer is taken as a change of the anchor's offset: released, the offset re-opened."""
    nlos_grace_s: float = 3.0
    """After a recovery no episode is declared for this long [s]: while the filter re-converges, its large
    innovations are its own, not the anchors'."""
    nlos_max_held_share: float = 0.25
    """At most this share of the anchors (at least one) is held out at once."""
    ess: bool = True
    """Count correlated innovations by their effective sample size in the divergence test."""

    def __post_init__(self) -> None:
        for name in ("adapt_alpha", "sigma_ceiling_m", "cusum_k", "cusum_h", "cusum_clip", "nlos_max_s",
                     "nlos_grace_s"):  # fmt: skip
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v > 0.0):
                raise ConfigError(f"robust.{name} must be a finite number > 0, got {v!r}")
        if not 0.0 < self.nlos_max_held_share <= 1.0:
            raise ConfigError(
                f"robust.nlos_max_held_share must be in (0, 1], got {self.nlos_max_held_share!r}"
            )
        if self.adapt_alpha >= 1.0:
            raise ConfigError(f"robust.adapt_alpha must be in (0, 1), got {self.adapt_alpha!r}")


@dataclass(frozen=True)
class PhaseParams:
    """Take-off and landing detection (``[phases]`` of log.toml; :func:`swarm.core._imu_nb.phase_step`)."""

    enabled: bool = True
    """Detect the phases and re-open the per-anchor offsets at each change."""
    vibration_tau_s: float = 0.1
    """Time constant of the vibration level (RMS change of the specific force between samples) [s]."""
    vibration_ratio: float = 3.0
    """Airborne above this many times the vibration level standing still (the static segment's, else the
    log's first second), and landed below its level in flight over this ratio (the rotors stopped): a small
    quadrotor's rotors raise it ~10x (0.01 -> 0.1 m/s^2, docs/logs.md); relative, so that an IMU's own
    noise and sample rate do not matter."""
    takeoff_height_m: float = 0.3
    """Airborne, too, when the estimate is this high over the ground reference [m] (0: not used)."""
    dwell_s: float = 0.3
    """A change must hold this long [s] (0.5 s with a 0.25 s level declared take-off 0.7 s late, after the
    offsets had stepped: one reset in 20 synthetic profile flights; 0.3 s and 0.1 s: none)."""
    reopen_sigma_m: float = 0.1
    """Standard deviation added to each anchor's offset at a change [m] (steps of -0.02 to +0.36 m were
    measured at take-off on real anchors, docs/logs.md)."""
    reopen_baro_sigma_m: float = 1.0
    """Standard deviation added to the barometer's offset at a change [m] (rotor downwash)."""
    land_height_m: float = 0.15
    """Touchdown: a descent stopped under this height over the ground reference [m], less two sigmas of the
    estimate's height, is a landing (0: no touchdown rule): the landing gear's play and the pad's survey;
    the sigmas, because without a range finder the radio's height is off by 0.2-0.5 m at the ground (the
    UTIL TDoA logs' last half metre). A hover this low is not a touchdown unless it follows a descent."""
    land_speed_m_s: float = 0.3
    """Touchdown: the estimate's vertical speed under this [m/s] (the contact stops the vehicle; the IMU
    sees it)."""
    descent_speed_m_s: float = 0.35
    """Touchdown: after the estimate descended faster than this [m/s] (a Crazyflie lands at 0.4-0.8 m/s; a
    hover's estimate wanders at up to 0.2 m/s without a range finder) ..."""
    descent_s: float = 1.0
    """... at most this long before [s]; and no take-off by the climb this long after a change (the
    contact's jolt)."""
    climb_accel_m_s2: float = 0.3
    """Take-off from the ground: the vertical specific force over gravity by this [m/s^2] (low-passed as the
    vibration, held for the dwell; 0: not used). A lift-off accelerates at 0.2-0.9 m/s^2 (UTIL flights); on
    the ground, rotors spinning, it spreads ~0.1 m/s^2. Without it, a vehicle pinned on its pad whose rotors
    spin from the log's first sample and which has no range finder takes off only by the estimate's
    height, which the pin holds down: set ``pin_velocity_sigma_m_s = 0`` too."""
    pin_velocity_sigma_m_s: float = 0.02
    """While standing where it is known to stand (the pad before take-off, or after a touchdown): a zero
    velocity of this sigma per axis every ``pin_period_s`` (0: no pin)."""
    pin_height_sigma_m: float = 0.02
    """After a touchdown, the height of the ground reference with this sigma [m] (0: velocity only): the
    vehicle stands on that ground (a touchdown is declared only near it), and a height left where the radio
    put it at the contact (0.3-0.5 m off without a range finder) would declare a take-off. Not on the pad
    before the take-off, where the estimate starts at the surveyed height (pinning it there took the
    development hover's NEES band share from 89 % to 84 %)."""
    pin_period_s: float = 0.01
    """The pin's pseudo-measurements at most this often [s]."""

    def __post_init__(self) -> None:
        for name in ("vibration_tau_s", "vibration_ratio", "dwell_s", "descent_s", "pin_period_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v > 0.0):
                raise ConfigError(f"phases.{name} must be a finite number > 0, got {v!r}")
        for name in ("takeoff_height_m", "reopen_sigma_m", "reopen_baro_sigma_m", "land_height_m",
                     "land_speed_m_s", "descent_speed_m_s", "climb_accel_m_s2", "pin_velocity_sigma_m_s",
                     "pin_height_sigma_m"):  # fmt: skip
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v >= 0.0):
                raise ConfigError(f"phases.{name} must be a finite number >= 0, got {v!r}")


def robust_vector(
    robust: RobustParams,
    phases: PhaseParams,
    sigma_floor_m: float,
    ground_z_m: float,
    baro_index: int = -1,
    n_anchors: int = 8,
    ground_vibration_m_s2: float = np.inf,
    accel_vibration_k: float = 0.0,
    g_norm_m_s2: float = 9.81,
):
    """The kernels' ``RP`` vector (:mod:`swarm.core._imu_nb`, ``RP_*``); ``ground_vibration_m_s2`` is the
    vibration level standing still (:func:`vibration_level`; infinite: not used); ``accel_vibration_k``
    the estimator's (:attr:`ImuFilterParams.accel_vibration_k`), ``g_norm_m_s2`` gravity's magnitude."""
    rp = np.zeros(nb.N_RP)
    rp[nb.RP_LAND_HEIGHT] = phases.land_height_m
    rp[nb.RP_LAND_SPEED] = phases.land_speed_m_s
    rp[nb.RP_DESCENT_SPEED] = phases.descent_speed_m_s
    rp[nb.RP_DESCENT_S] = phases.descent_s
    rp[nb.RP_CLIMB_ACCEL] = phases.climb_accel_m_s2
    rp[nb.RP_G_NORM] = g_norm_m_s2
    rp[nb.RP_PIN_VEL_VAR] = phases.pin_velocity_sigma_m_s**2
    rp[nb.RP_PIN_Z_VAR] = phases.pin_height_sigma_m**2
    rp[nb.RP_PIN_PERIOD] = phases.pin_period_s
    rp[nb.RP_VIB_ACCEL_K] = accel_vibration_k
    rp[nb.RP_NLOS_MAX_HELD] = max(1, int(robust.nlos_max_held_share * n_anchors))
    rp[nb.RP_REOPEN_BARO_VAR] = phases.reopen_baro_sigma_m**2
    rp[nb.RP_BARO_INDEX] = baro_index
    rp[nb.RP_ADAPT] = float(robust.adapt)
    rp[nb.RP_ADAPT_ALPHA] = robust.adapt_alpha
    rp[nb.RP_VAR_FLOOR] = sigma_floor_m**2
    rp[nb.RP_VAR_CEIL] = robust.sigma_ceiling_m**2
    rp[nb.RP_NLOS] = float(robust.nlos)
    rp[nb.RP_CUSUM_K], rp[nb.RP_CUSUM_H], rp[nb.RP_CUSUM_CLIP] = (
        robust.cusum_k,
        robust.cusum_h,
        robust.cusum_clip,
    )
    rp[nb.RP_NLOS_MAX_S] = robust.nlos_max_s
    rp[nb.RP_VIB_TAU] = phases.vibration_tau_s
    rp[nb.RP_VIB_THRESHOLD] = phases.vibration_ratio * ground_vibration_m_s2
    rp[nb.RP_VIB_RATIO] = phases.vibration_ratio
    rp[nb.RP_TAKEOFF_HEIGHT] = phases.takeoff_height_m
    rp[nb.RP_DWELL] = phases.dwell_s
    rp[nb.RP_REOPEN_VAR] = phases.reopen_sigma_m**2
    rp[nb.RP_GROUND_Z] = ground_z_m
    rp[nb.RP_ESS] = float(robust.ess)
    rp[nb.RP_PHASES] = float(phases.enabled)
    return rp


def vibration_level(acc_body) -> float:
    """The vibration level of specific-force samples ``acc_body`` (n, 3) [m/s^2] as the phase detector
    measures it (:func:`swarm.core._imu_nb.phase_step`): the RMS per axis of the change between samples over
    sqrt(2) (a white noise's own standard deviation)."""
    d = np.diff(np.asarray(acc_body, dtype=float), axis=0)
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1)) / 6.0)) if len(d) else float("inf")


@dataclass(frozen=True)
class StateLayout:
    """Where the extra error states of the range-error model sit (after the 15 core ones), in this order: the
    common offset, one offset per anchor, one Gauss-Markov term per anchor, the barometer offset; -1 where a
    part is off."""

    n_err: int
    common: int
    offset: np.ndarray
    """(M,) error index of each anchor's offset."""
    gm: np.ndarray
    """(M,) error index of each anchor's Gauss-Markov term."""
    baro: int
    ridx: np.ndarray
    """(M, 3): the three range-error terms of each anchor's range (common, offset, Gauss-Markov)."""
    ext: np.ndarray
    """The PRM extension: (tau [s] or 0, sigma) per extra state."""


def state_layout(n_anchors: int, params: ImuFilterParams, baro: bool = False) -> StateLayout:
    """The extra error states for ``n_anchors`` anchors (:class:`StateLayout`)."""
    k = N_CORE
    ext: list[tuple[float, float]] = []
    common = -1
    if params.range_common_offset and n_anchors:
        common, k = k, k + 1
        ext.append((0.0, params.range_common_offset_rw))
    offset = np.full(n_anchors, -1, dtype=np.int64)
    if params.range_bias:
        offset[:] = np.arange(k, k + n_anchors)
        k += n_anchors
        ext += [(0.0, params.range_bias_rw)] * n_anchors
    gm = np.full(n_anchors, -1, dtype=np.int64)
    if params.range_gm:
        gm[:] = np.arange(k, k + n_anchors)
        k += n_anchors
        ext += [(params.range_gm_tau_s, params.range_gm_sigma_m)] * n_anchors
    b = -1
    if baro:
        b, k = k, k + 1
        ext.append((0.0, params.baro_offset_rw))
    ridx = np.column_stack([np.full(n_anchors, common, dtype=np.int64), offset, gm]).astype(np.int64)
    return StateLayout(
        k, common, offset, gm, b, np.ascontiguousarray(ridx), np.asarray(ext, float).reshape(-1)
    )


@lru_cache(maxsize=16)
def divergence_limits(window: int, alpha: float) -> np.ndarray:
    """``limits[n]``: the largest mean NIS of ``n`` accepted scalar ranges a consistent filter exceeds with
    probability ``alpha``, ``chi2.ppf(1 - alpha, n) / n`` (``limits[0]`` unused)."""
    from scipy.stats import chi2  # here, not at the top: ~0.26 s of CPU at a process start

    n = np.arange(1, window + 1)
    return np.concatenate([[np.inf], chi2.ppf(1.0 - alpha, n) / n])


@lru_cache(maxsize=64)
def chi2_gate(probability: float, dof: int) -> float:
    """The chi-square(``dof``) gate of a measurement, once per probability (scipy's ppf costs ~80 us a
    call)."""
    from scipy.stats import chi2  # here, not at the top: ~0.26 s of CPU at a process start

    return float(chi2.ppf(probability, dof))


def _gate3(probability: float) -> float:
    """The chi-square(3) gate of a vector fix."""
    return chi2_gate(probability, 3)


def state_size(n_anchors: int, params: ImuFilterParams, baro: bool = False) -> tuple[int, int]:
    """(nominal, error) state sizes for ``n_anchors`` anchors (:func:`state_layout`)."""
    ne = state_layout(n_anchors, params, baro).n_err
    return ne + 1, ne


class ImuFilter:
    """A batch of ``n`` IMU-driven filters sharing one clock (``n = 1`` for one vehicle).

    ``X`` (n, 16 + M) and ``P`` (n, 15 + M, 15 + M) as :mod:`swarm.core._imu_nb` lays them out; ``counts``
    (n_anchors, 3) holds the accepted, rejected and refused ranges per anchor (summed over the batch);
    ``dropped`` the samples older than the filter's time."""

    def __init__(
        self, params: ImuFilterParams, anchors_nav, X, P, t_s: float, sigma_range_m, baro: bool = False
    ) -> None:
        self.params = params
        self.anchors = np.ascontiguousarray(anchors_nav, dtype=float)
        if self.anchors.ndim != 2 or self.anchors.shape[1] != 3:
            raise ValueError(f"anchors_nav: expected shape (M, 3), got {self.anchors.shape}")
        m = len(self.anchors)
        self.layout = state_layout(m, params, baro)
        nx, ne = self.layout.n_err + 1, self.layout.n_err
        self.X = np.ascontiguousarray(np.atleast_2d(X), dtype=float).copy()
        self.P = np.ascontiguousarray(P, dtype=float).copy()
        if self.P.ndim == 2:
            self.P = self.P[None]
        if self.X.shape[1:] != (nx,) or self.P.shape[1:] != (ne, ne) or len(self.X) != len(self.P):
            raise ValueError(
                f"X, P: expected (n, {nx}) and (n, {ne}, {ne}), got {self.X.shape}, {self.P.shape}"
            )
        self.sigma = np.broadcast_to(np.asarray(sigma_range_m, dtype=float), (m,)).copy()
        self.bias_of = self.layout.offset
        """Each anchor's offset state (-1: none), for the kernels that take one range-error term."""
        self.ridx = self.layout.ridx
        self.prm = params.vector()
        if params.range_common_offset or params.range_gm or baro:
            self.prm = np.concatenate([self.prm, self.layout.ext])
        self.t = float(t_s)
        self._gyro: np.ndarray | None = None  # the held IMU sample (n, 3)
        self._acc: np.ndarray | None = None
        self.counts = np.zeros((m, 3), dtype=np.int64)
        self.dropped = 0
        self.imu_refused = 0
        self._work = np.empty((3, ne))
        self._res = np.empty(3)

    @classmethod
    def create(
        cls,
        params: ImuFilterParams,
        anchors_nav,
        p,
        v,
        q,
        t_s: float,
        sigma_range_m,
        sigmas=None,
        accel_bias=None,
        gyro_bias=None,
        range_bias=None,
        common_offset: float = 0.0,
        sigma_common_m: float | None = None,
        baro: bool = False,
        sigma_baro_m: float = 1.0,
    ) -> ImuFilter:
        """One filter from a first state and its standard deviations ``sigmas`` = ``(p [m], v [m/s],
        attitude [rad], accelerometer bias [m/s^2], gyro bias [rad/s], range bias [m])``; the per-anchor
        offsets start at ``range_bias`` (M,), the common offset at ``common_offset`` with
        ``sigma_common_m`` (default: the range bias sigma), the Gauss-Markov terms at zero with their
        stationary sigma, the barometer offset (``baro``) at zero with ``sigma_baro_m`` (the first
        barometer sample sets it, :mod:`swarm.logs.replay`)."""
        m = len(np.asarray(anchors_nav))
        lay = state_layout(m, params, baro)
        nx, ne = lay.n_err + 1, lay.n_err
        X = np.zeros(nx)
        X[nb.XP : nb.XP + 3], X[nb.XV : nb.XV + 3], X[nb.XQ : nb.XQ + 4] = p, v, q
        if accel_bias is not None:
            X[nb.XBA : nb.XBA + 3] = accel_bias
        if gyro_bias is not None:
            X[nb.XBG : nb.XBG + 3] = gyro_bias
        if params.range_bias and range_bias is not None:
            X[lay.offset + 1] = range_bias  # nominal index = error index + 1 past the quaternion
        s = (1.0, 0.5, 0.05, 0.1, 0.01, 0.3) if sigmas is None else sigmas
        diag = np.concatenate(
            [
                np.full(3, s[0]),
                np.full(3, s[1]),
                np.full(3, s[2]),
                np.full(3, s[3]),
                np.full(3, s[4]),
                np.zeros(ne - N_CORE),
            ]
        )
        if lay.common >= 0:
            X[lay.common + 1] = common_offset
            diag[lay.common] = s[5] if sigma_common_m is None else sigma_common_m
        diag[lay.offset[lay.offset >= 0]] = s[5]
        diag[lay.gm[lay.gm >= 0]] = params.range_gm_sigma_m
        if lay.baro >= 0:
            diag[lay.baro] = sigma_baro_m
        return cls(params, anchors_nav, X, np.diag(diag**2), t_s, sigma_range_m, baro)

    @property
    def n(self) -> int:
        return len(self.X)

    @property
    def p_nav(self) -> np.ndarray:
        return self.X[:, nb.XP : nb.XP + 3]

    @property
    def v_nav(self) -> np.ndarray:
        return self.X[:, nb.XV : nb.XV + 3]

    @property
    def q_nav_body(self) -> np.ndarray:
        return self.X[:, nb.XQ : nb.XQ + 4]

    @property
    def accel_bias(self) -> np.ndarray:
        return self.X[:, nb.XBA : nb.XBA + 3]

    @property
    def gyro_bias(self) -> np.ndarray:
        return self.X[:, nb.XBG : nb.XBG + 3]

    @property
    def range_bias(self) -> np.ndarray:
        """(n, M) each anchor's offset (zeros without offset states; the common offset not included)."""
        off = self.layout.offset
        if not len(off) or off[0] < 0:
            return np.zeros((self.n, len(off)))
        return self.X[:, off + 1]

    @property
    def range_error_total(self) -> np.ndarray:
        """(n, M) the whole modelled range error per anchor: common + offset + Gauss-Markov term [m]."""
        tot = np.zeros((self.n, len(self.layout.ridx)))
        for j in range(3):
            idx = self.layout.ridx[:, j]
            tot[:, idx >= 0] += self.X[:, idx[idx >= 0] + 1]
        return tot

    def _predict_to(self, t_s: float) -> None:
        if self._gyro is not None and t_s > self.t:
            refused = np.zeros(1, dtype=np.int64)
            nb.predict_batch(self.X, self.P, self._gyro, self._acc, t_s - self.t, self.prm, refused)
            self.imu_refused += int(refused[0])
        self.t = max(self.t, t_s)

    def imu(self, t_s: float, gyro_body, acc_body) -> bool:
        """An IMU sample at ``t_s`` [s]: predict to it with the held sample, then hold this one. False (and
        counted in ``dropped``) if it is older than the filter's time."""
        if not t_s >= self.t:
            self.dropped += 1
            return False
        self._predict_to(t_s)
        if self._gyro is None:
            self._gyro, self._acc = np.empty((self.n, 3)), np.empty((self.n, 3))
        self._gyro[:] = gyro_body  # the held sample, in place: no allocation per sample
        self._acc[:] = acc_body
        return True

    def update_range(self, t_s: float, anchor: int, range_m) -> np.ndarray:
        """A range ``range_m`` [m] (scalar or (n,)) to anchor index ``anchor`` measured at ``t_s``: predict to
        it, then update. Returns the outcome per filter (``_imu_nb.ACCEPTED/REJECTED/REFUSED``), or an
        empty array if the sample is older than the filter's time (dropped, counted)."""
        if not t_s >= self.t:
            self.dropped += 1
            return np.zeros(0, dtype=np.int64)
        self._predict_to(t_s)
        z = np.broadcast_to(np.asarray(range_m, dtype=float), (self.n,))
        out = np.empty(self.n, dtype=np.int64)
        self.last_d2 = np.empty(self.n)
        nb.update_range_batch(
            self.X,
            self.P,
            self.anchors[anchor],
            self.ridx[anchor],
            np.ascontiguousarray(z),
            self.sigma[anchor],
            self.prm,
            self._work,
            self._res,
            out,
            self.last_d2,
        )
        np.add.at(self.counts[anchor], out, 1)
        return out

    def update_pad(
        self,
        t_s: float,
        p_pad_nav,
        t_cam_m,
        cov_t,
        cam_pos_body,
        R_body_cam,
        gate_probability: float = 0.9995,
    ) -> np.ndarray:
        """The pad's position ``t_cam_m`` (3,) in the camera frame with its covariance ``cov_t`` (3, 3),
        measured
        at ``t_s``, of a pad surveyed at ``p_pad_nav``, from a camera at ``cam_pos_body`` turned by
        ``R_body_cam`` (camera to body): predict to it, then update every filter. Returns the outcomes, or an
        empty array if the sample is older than the filter's time (dropped, counted)."""
        if not t_s >= self.t:
            self.dropped += 1
            return np.zeros(0, dtype=np.int64)
        self._predict_to(t_s)
        gate = _gate3(gate_probability)
        out = np.empty(self.n, dtype=np.int64)
        self.last_pad_d2 = np.empty(self.n)
        res = np.empty(2)
        args = (
            np.asarray(p_pad_nav, float),
            np.asarray(cam_pos_body, float),
            np.ascontiguousarray(R_body_cam, float),
            np.asarray(t_cam_m, float),
            np.ascontiguousarray(cov_t, float),
        )
        for i in range(self.n):
            out[i] = nb.update_pad_one(self.X[i], self.P[i], *args[:4], args[4], gate, res)
            self.last_pad_d2[i] = res[1]
        return out

    def update_position(self, t_s: float, p_nav, cov, gate_probability: float = 0.9995) -> np.ndarray:
        """A position fix ``p_nav`` (3,) with covariance ``cov`` (3, 3) at ``t_s`` (GNSS): predict to it,
        then update every filter. The outcomes, or an empty array if it is older than the filter (dropped)."""
        if not t_s >= self.t:
            self.dropped += 1
            return np.zeros(0, dtype=np.int64)
        self._predict_to(t_s)
        gate = _gate3(gate_probability)
        out = np.empty(self.n, dtype=np.int64)
        res = np.empty(2)
        z, R = np.asarray(p_nav, float), np.ascontiguousarray(cov, float)
        for i in range(self.n):
            out[i] = nb.update_position_one(self.X[i], self.P[i], z, R, gate, res)
        return out

    def inflate(self, i: int, var_p: float, var_v: float) -> None:
        """Add ``var_p`` [m^2] to each axis of filter ``i``'s position covariance and ``var_v`` [m^2/s^2] to
        its velocity's (positive definite whenever ``P`` is): the estimate stays where it is, and the
        ranges that disagree with it can pull it again (additive covariance inflation; the Crazyflie's
        TDoA outlier filter opens its gate likewise when its share of good measurements falls). Their cross
        terms with the other states are cleared (the block-diagonal part of a positive definite matrix is
        positive definite): what went wrong is the position, and a range's pull on it must not move the
        offsets and biases through correlations learnt before."""
        P = self.P[i]
        P[0:6, 6:] = 0.0
        P[6:, 0:6] = 0.0
        for k in range(3):
            P[k, k] += var_p
            P[3 + k, 3 + k] += var_v

    def reset_position(self, i: int, p_nav, cov_p, sigma_v_m_s: float) -> None:
        """Re-initialise filter ``i``'s position (and its covariance ``cov_p`` (3, 3)) and its velocity (zero,
        ``sigma_v_m_s``) after a divergence; attitude and biases are kept, their cross terms with position
        and velocity cleared."""
        self.X[i, nb.XP : nb.XP + 3] = p_nav
        self.X[i, nb.XV : nb.XV + 3] = 0.0
        P = self.P[i]
        P[0:6, :] = 0.0
        P[:, 0:6] = 0.0
        P[0:3, 0:3] = cov_p
        P[3:6, 3:6] = np.eye(3) * sigma_v_m_s**2
