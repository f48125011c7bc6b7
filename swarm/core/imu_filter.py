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
from scipy.stats import chi2

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
    """Estimate one range bias per anchor (random walk)."""
    range_bias_rw: float = 0.01
    """Range bias random walk [m/sqrt(s)]."""
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
        for name in ("accel_noise", "gyro_noise", "accel_bias_rw", "gyro_bias_rw", "range_bias_rw"):
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
        prm[nb.PRM_GATE] = chi2.ppf(self.gate_probability, 1)
        prm[nb.PRM_HUBER] = self.huber_k
        return prm


@lru_cache(maxsize=16)
def divergence_limits(window: int, alpha: float) -> np.ndarray:
    """``limits[n]``: the largest mean NIS of ``n`` accepted scalar ranges a consistent filter exceeds with
    probability ``alpha``, ``chi2.ppf(1 - alpha, n) / n`` (``limits[0]`` unused)."""
    n = np.arange(1, window + 1)
    return np.concatenate([[np.inf], chi2.ppf(1.0 - alpha, n) / n])


@lru_cache(maxsize=64)
def chi2_gate(probability: float, dof: int) -> float:
    """The chi-square(``dof``) gate of a measurement, once per probability (scipy's ppf costs ~80 us a
    call)."""
    return float(chi2.ppf(probability, dof))


def _gate3(probability: float) -> float:
    """The chi-square(3) gate of a vector fix."""
    return chi2_gate(probability, 3)


def state_size(n_anchors: int, params: ImuFilterParams) -> tuple[int, int]:
    """(nominal, error) state sizes for ``n_anchors`` anchors."""
    m = n_anchors if params.range_bias else 0
    return 16 + m, N_CORE + m


class ImuFilter:
    """A batch of ``n`` IMU-driven filters sharing one clock (``n = 1`` for one vehicle).

    ``X`` (n, 16 + M) and ``P`` (n, 15 + M, 15 + M) as :mod:`swarm.core._imu_nb` lays them out; ``counts``
    (n_anchors, 3) holds the accepted, rejected and refused ranges per anchor (summed over the batch);
    ``dropped`` the samples older than the filter's time."""

    def __init__(self, params: ImuFilterParams, anchors_nav, X, P, t_s: float, sigma_range_m) -> None:
        self.params = params
        self.anchors = np.ascontiguousarray(anchors_nav, dtype=float)
        if self.anchors.ndim != 2 or self.anchors.shape[1] != 3:
            raise ValueError(f"anchors_nav: expected shape (M, 3), got {self.anchors.shape}")
        m = len(self.anchors)
        nx, ne = state_size(m, params)
        self.X = np.ascontiguousarray(np.atleast_2d(X), dtype=float).copy()
        self.P = np.ascontiguousarray(P, dtype=float).copy()
        if self.P.ndim == 2:
            self.P = self.P[None]
        if self.X.shape[1:] != (nx,) or self.P.shape[1:] != (ne, ne) or len(self.X) != len(self.P):
            raise ValueError(
                f"X, P: expected (n, {nx}) and (n, {ne}, {ne}), got {self.X.shape}, {self.P.shape}"
            )
        self.sigma = np.broadcast_to(np.asarray(sigma_range_m, dtype=float), (m,)).copy()
        self.bias_of = np.array([N_CORE + a if params.range_bias else -1 for a in range(m)], dtype=np.int64)
        self.prm = params.vector()
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
    ) -> ImuFilter:
        """One filter from a first state and its standard deviations ``sigmas`` = ``(p [m], v [m/s],
        attitude [rad], accelerometer bias [m/s^2], gyro bias [rad/s], range bias [m])``."""
        m = len(np.asarray(anchors_nav))
        nx, ne = state_size(m, params)
        X = np.zeros(nx)
        X[nb.XP : nb.XP + 3], X[nb.XV : nb.XV + 3], X[nb.XQ : nb.XQ + 4] = p, v, q
        if accel_bias is not None:
            X[nb.XBA : nb.XBA + 3] = accel_bias
        if gyro_bias is not None:
            X[nb.XBG : nb.XBG + 3] = gyro_bias
        if params.range_bias and range_bias is not None:
            X[nb.XRB :] = range_bias
        s = (1.0, 0.5, 0.05, 0.1, 0.01, 0.3) if sigmas is None else sigmas
        diag = np.concatenate(
            [
                np.full(3, s[0]),
                np.full(3, s[1]),
                np.full(3, s[2]),
                np.full(3, s[3]),
                np.full(3, s[4]),
                np.full(ne - N_CORE, s[5]),
            ]
        )
        return cls(params, anchors_nav, X, np.diag(diag**2), t_s, sigma_range_m)

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
        return self.X[:, nb.XRB :]

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
            self.bias_of[anchor],
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
