"""Multiplicative (error-state) EKF for the pose of one TPODS module, or of many at once.

Paper section IV-A: the state is ``zeta = (rho, rho_dot, delta_theta)`` (eq. 4): the centre-of-mass
position and velocity in the navigation frame ``nav`` (the paper's ``c``, a mothership) and a 3-parameter
attitude error about a reference quaternion propagated with the gyro as an input (eq. 3). Quaternions are
scalar-last (x, y, z, w) with the Hamilton product, like ``scipy.spatial.transform.Rotation``;
``q_nav_body`` maps body vectors into ``nav``; the attitude error is body-frame,
``q = q_ref (x) exp(delta_theta)`` (Markley 2003).

Two structures share all measurement models and the Joseph update (:mod:`swarm.core._ekf_nb`):

* ``"tandem"`` (the paper's choice): a 6-state translation filter and a 3-state attitude filter.
  The UWB range depends on attitude through the tag lever arm ``P1``; the translation filter does not
  estimate that error but *considers* it, adding ``H_theta P_theta H_theta^T`` to the range noise, and
  the range does not update the attitude filter (its 5 cm lever arm observes attitude only weakly).
  No cross-covariance is kept between the two filters.
* ``"compounded"``: one 9-state filter that keeps the cross-covariance and lets ranges correct attitude.

Robustness (paper section IV-D): every innovation is gated on its squared Mahalanobis distance at the
``gate_probability`` quantile of the chi-square distribution of its dimension (``scipy.stats.chi2``);
measurements right after a long prediction are underweighted (Zanetti, DeMars & Bishop 2010). Every
acceptance, rejection and refusal (non-finite or invalid input) is counted per measurement type.

Every array carries a leading batch axis of ``n`` filters (``n = 1`` for one vehicle). The compiled
kernels loop over that axis running the same per-filter code, so one filter gives bit-identical numbers
alone or inside a Monte Carlo batch.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from swarm.core import _ekf_nb as nb
from swarm.core.rotations import quat_to_matrix
from swarm.errors import ConfigError


class Structure(enum.StrEnum):
    TANDEM = "tandem"
    COMPOUNDED = "compounded"


class MeasKind(enum.IntEnum):
    """Columns of the counters in :attr:`PoseEstimator.counts`."""

    RANGE = nb.TYPE_RANGE
    FEATURES = nb.TYPE_FEATURES
    POSE = nb.TYPE_POSE
    ATTITUDE = nb.TYPE_ATTITUDE
    PREDICT = nb.TYPE_PREDICT


class UpdateStatus(enum.IntEnum):
    """Outcome of one predict or update, per filter."""

    ACCEPTED = nb.ST_ACCEPTED
    REJECTED_OUTLIER = nb.ST_REJECTED  # outside the Mahalanobis gate
    REFUSED_NONFINITE = nb.ST_REFUSED_NONFINITE  # NaN or Inf in the input: never reaches the filter
    REFUSED_INVALID = nb.ST_REFUSED_INVALID  # e.g. negative range, zero noise, degenerate geometry
    SKIPPED = nb.ST_SKIPPED  # masked out in a batch call


@dataclass(frozen=True)
class EstimatorParams:
    """Tuning of the pose estimator. Defaults follow the paper's hardware (VN-100 gyro, 2 cm UWB)."""

    structure: Structure = Structure.TANDEM
    """``tandem`` (6 + 3 states) or ``compounded`` (9 states)."""
    sigma_range_m: float = 0.02
    """UWB range white-noise standard deviation [m] (paper sec. III)."""
    sigma_tdoa_m: float = 0.05
    """White-noise standard deviation of a TDoA distance difference [m] (``uwb.mode`` tdoa2/tdoa3)."""
    sigma_feature_m: float = 0.001
    """Feature-vector noise per axis in the camera frame [m] (paper sec. III, 1 mm)."""
    accel_psd_m2_s3: float = 1e-4
    """Power spectral density of the unmodelled acceleration (white-noise acceleration model) [m^2/s^3]."""
    gyro_arw_rad_rts: float = 0.0035 * np.pi / 180.0
    """Gyro angle random walk [rad/sqrt(s)]; VN-100: 0.0035 deg/s/sqrt(Hz)."""
    attitude_rw_extra_rad_rts: float = 0.0
    """Extra attitude random walk absorbing unmodelled gyro bias [rad/sqrt(s)]."""
    lever_arm_body_m: tuple[float, float, float] = (0.05, 0.05, 0.0)
    """UWB tag position ``P1`` in the body frame [m] (paper sec. III)."""
    gate_probability: float = 0.9999
    """Chi-square probability of the Mahalanobis gate (paper sec. IV-D: 99.99 %)."""
    underweight_beta: float = 0.2
    """Underweighting factor beta in ``S = (1 + beta) H P H^T + R``; 0 disables (Zanetti et al. 2010)."""
    underweight_gap_s: float = 1.0
    """A prediction span without accepted updates at least this long arms underweighting [s]."""
    underweight_count: int = 5
    """How many accepted updates are underweighted after such a span."""
    underweight_ratio: float = 4.0
    """Underweight only while ``tr(H P H^T) > ratio * tr(R)`` (the prior dominates the noise)."""
    camera_pos_body_m: tuple[float, float, float] = (0.0, 0.0, -0.05)
    """Camera optical centre in the body frame [m] (chaser's bottom, -z, face)."""
    q_body_cam: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    """Camera-to-body rotation, scalar-last; the default turns the camera's +z (optical axis) to body -z."""
    range_common_offset: bool = False
    """Estimate one range offset common to every anchor (a tag's antenna delay; ``_ekf_nb`` module doc)."""
    range_common_offset_rw: float = 0.001
    """Its random walk density [m/sqrt(s)]."""
    range_bias: bool = False
    """Estimate one range offset per anchor (an anchor's antenna delay, a fixed multipath)."""
    range_bias_rw: float = 0.002
    """Each anchor offset's random walk density [m/sqrt(s)]."""
    range_gm: bool = False
    """Estimate one first-order Gauss-Markov term per anchor (slow, time-correlated multipath)."""
    range_gm_sigma_m: float = 0.02
    """The Gauss-Markov term's stationary standard deviation [m]."""
    range_gm_tau_s: float = 1.0
    """Its correlation time [s]."""
    sigma_common_offset_m: float = 0.5
    """Prior standard deviation of the common offset [m] (a Loco Positioning tag reads 0.2-0.4 m short)."""
    sigma_range_offset_m: float = 0.1
    """Prior standard deviation of each anchor's offset [m]."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "structure", Structure(self.structure))
        positive = ("sigma_range_m", "sigma_tdoa_m", "sigma_feature_m")
        nonneg = (
            "accel_psd_m2_s3",
            "gyro_arw_rad_rts",
            "attitude_rw_extra_rad_rts",
            "underweight_beta",
            "underweight_gap_s",
            "underweight_ratio",
        )
        positive = (*positive, "range_gm_tau_s", "sigma_common_offset_m", "sigma_range_offset_m")
        nonneg = (*nonneg, "range_common_offset_rw", "range_bias_rw", "range_gm_sigma_m")
        for name in ("range_common_offset", "range_bias", "range_gm"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"estimator.{name} must be true or false, got {getattr(self, name)!r}")
        for name in positive:
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"estimator.{name} must be a positive finite number, got {v!r}")
        for name in nonneg:
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError(f"estimator.{name} must be a non-negative finite number, got {v!r}")
        if not (0.5 < self.gate_probability < 1.0):
            raise ConfigError(
                f"estimator.gate_probability must be in (0.5, 1), got {self.gate_probability!r}"
            )
        if int(self.underweight_count) != self.underweight_count or self.underweight_count < 0:
            raise ConfigError(
                f"estimator.underweight_count must be a non-negative integer, got {self.underweight_count!r}"
            )
        for name, n in (("lever_arm_body_m", 3), ("camera_pos_body_m", 3), ("q_body_cam", 4)):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.shape != (n,) or not np.all(np.isfinite(v)):
                raise ConfigError(f"estimator.{name} must be {n} finite numbers, got {getattr(self, name)!r}")
        if abs(np.linalg.norm(self.q_body_cam) - 1.0) > 1e-6:
            raise ConfigError(f"estimator.q_body_cam must be a unit quaternion, got {self.q_body_cam!r}")

    @property
    def range_model(self) -> bool:
        """True when any part of the range-error model is on."""
        return self.range_common_offset or self.range_bias or self.range_gm

    def n_extra(self, n_anchors: int) -> int:
        """How many range-error states the filter carries with ``n_anchors`` anchors."""
        if n_anchors <= 0:
            return 0
        return int(self.range_common_offset) + n_anchors * (int(self.range_bias) + int(self.range_gm))

    def extra_sigmas(self, n_anchors: int) -> np.ndarray:
        """Prior standard deviations of the range-error states, in their order (``_ekf_nb`` module doc):
        the common offset's, each anchor offset's, each Gauss-Markov term's stationary sigma."""
        if n_anchors <= 0:
            return np.zeros(0)
        out = [self.sigma_common_offset_m] if self.range_common_offset else []
        out += [self.sigma_range_offset_m] * (n_anchors if self.range_bias else 0)
        out += [self.range_gm_sigma_m] * (n_anchors if self.range_gm else 0)
        return np.array(out, dtype=float)

    def param_vector(self, n_anchors: int = 0) -> np.ndarray:
        """The flat parameter vector the compiled kernels read (``_ekf_nb.PRM_*``), with the range-error
        model's extension when it is on and there are anchors."""
        prm = np.zeros(nb.N_PRM_RE if self.n_extra(n_anchors) else nb.N_PRM)
        prm[nb.PRM_TANDEM] = 1.0 if self.structure is Structure.TANDEM else 0.0
        prm[nb.PRM_ACCEL_PSD] = self.accel_psd_m2_s3
        prm[nb.PRM_ATT_PSD] = self.gyro_arw_rad_rts**2 + self.attitude_rw_extra_rad_rts**2
        prm[nb.PRM_UW_BETA] = self.underweight_beta
        prm[nb.PRM_UW_GAP_S] = self.underweight_gap_s
        prm[nb.PRM_UW_COUNT] = self.underweight_count
        prm[nb.PRM_UW_RATIO] = self.underweight_ratio
        prm[nb.PRM_LEVER : nb.PRM_LEVER + 3] = self.lever_arm_body_m
        if prm.shape[0] == nb.N_PRM_RE:
            prm[nb.PRM_RE_ANCHORS] = n_anchors
            prm[nb.PRM_RE_COMMON] = float(self.range_common_offset)
            prm[nb.PRM_RE_OFFSET] = float(self.range_bias)
            prm[nb.PRM_RE_GM] = float(self.range_gm)
            prm[nb.PRM_RE_COMMON_RW] = self.range_common_offset_rw
            prm[nb.PRM_RE_OFFSET_RW] = self.range_bias_rw
            prm[nb.PRM_RE_GM_SIGMA] = self.range_gm_sigma_m
            prm[nb.PRM_RE_GM_TAU] = self.range_gm_tau_s
        return prm


@lru_cache(maxsize=256)
def chi2_gate(dim: int, probability: float) -> float:
    """Squared-Mahalanobis gate: the ``probability`` quantile of chi-square with ``dim`` degrees of
    freedom (paper sec. IV-D: 99.99 %)."""
    from scipy.stats import chi2  # here, not at the top: ~0.26 s of CPU at a process start

    return float(chi2.ppf(probability, dim))


def _batch(name: str, value, n: int, tail: tuple[int, ...]) -> np.ndarray:
    """``value`` as a C-contiguous float64 array of shape ``(n, *tail)``, broadcasting a single item."""
    if tail == () and n == 1 and type(value) in (float, np.float64):
        return np.array([value])
    if type(value) is np.ndarray and value.dtype == np.float64 and value.flags.c_contiguous:
        if value.shape == (n, *tail):
            return value
        if n == 1 and value.shape == tail:
            return value.reshape(1, *tail)
    a = np.asarray(value, dtype=np.float64)
    if a.shape == tail:
        a = np.broadcast_to(a, (n, *tail))
    elif a.shape != (n, *tail):
        raise ValueError(f"{name} must have shape {tail} or {(n, *tail)}, got {a.shape}")
    return np.ascontiguousarray(a)


def _mask(mask, n: int, all_true: np.ndarray) -> np.ndarray:
    if mask is None:
        return all_true
    m = np.asarray(mask, dtype=np.bool_)
    if m.shape != (n,):
        raise ValueError(f"mask must have shape ({n},), got {m.shape}")
    return m


class PoseEstimator:
    """A batch of ``n`` multiplicative EKFs (module docstring). Construct with :meth:`create`."""

    def __init__(self, params: EstimatorParams, X: np.ndarray, P: np.ndarray, n_anchors: int = 0) -> None:
        self.params = params
        self.n = X.shape[0]
        self.n_anchors = n_anchors
        self.X = X  # (n, 10 + M): p_nav, v_nav, q_nav_body, then M range-error states
        self.P = P  # (n, 9 + M, 9 + M)
        self.counts = np.zeros((self.n, 3, nb.N_TYPES), dtype=np.int64)  # [accepted, rejected, refused]
        self.book = np.zeros((self.n, nb.N_STF))
        self._prm = params.param_vector(n_anchors)
        self._cam_pos = np.asarray(params.camera_pos_body_m, dtype=np.float64)
        self._q_bc = np.asarray(params.q_body_cam, dtype=np.float64)
        self._R_bc = np.ascontiguousarray(quat_to_matrix(self._q_bc))
        self._status = np.zeros(self.n, dtype=np.int64)
        self._all = np.ones(self.n, dtype=np.bool_)
        self._sigma_range = np.full(self.n, params.sigma_range_m)
        self._gate_range = chi2_gate(1, params.gate_probability)

    @classmethod
    def create(
        cls,
        params: EstimatorParams,
        p_nav,
        v_nav,
        q_nav_body,
        cov0,
        n: int | None = None,
        n_anchors: int = 0,
    ) -> PoseEstimator:
        """Filters initialised at position ``p_nav`` [m], velocity ``v_nav`` [m/s], attitude ``q_nav_body``
        and error covariance ``cov0`` (9x9, or its diagonal (9,), order ``(d_p, d_v, d_theta)``).
        Each argument is one item or a batch; ``n`` defaults to the largest batch given (or 1). With the
        range-error model on (``params``) and ``n_anchors`` anchors, its states start at zero with the
        prior of :meth:`EstimatorParams.extra_sigmas`, uncorrelated with the core."""
        shapes = [np.shape(a) for a in (p_nav, v_nav, q_nav_body)]
        if n is None:
            n = max([s[0] for s in shapes if len(s) == 2] + [1])
        p = _batch("p_nav", p_nav, n, (3,))
        v = _batch("v_nav", v_nav, n, (3,))
        q = _batch("q_nav_body", q_nav_body, n, (4,))
        c = np.asarray(cov0, dtype=np.float64)
        if c.shape in ((9,), (n, 9)):
            c = np.einsum("...i,ij->...ij", c, np.eye(9))
        P = _batch("cov0", c, n, (9, 9)).copy()
        for name, a in (("p_nav", p), ("v_nav", v), ("q_nav_body", q), ("cov0", P)):
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name} must be finite, got {a}")
        if np.any(np.abs(np.linalg.norm(q, axis=-1) - 1.0) > 1e-6):
            raise ValueError(f"q_nav_body must be unit quaternions, got {q}")
        if np.any(np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, -1, -2))) <= 0):
            raise ValueError("cov0 must be symmetric positive definite")
        if params.structure is Structure.TANDEM:
            P[:, :6, 6:] = 0.0
            P[:, 6:, :6] = 0.0
        X = np.ascontiguousarray(np.concatenate([p, v, q], axis=-1))
        extra = params.extra_sigmas(n_anchors)
        if extra.size:
            m = extra.size
            X = np.ascontiguousarray(np.concatenate([X, np.zeros((n, m))], axis=-1))
            Pe = np.zeros((n, 9 + m, 9 + m))
            Pe[:, :9, :9] = P
            Pe[:, 9:, 9:] = np.diag(extra**2)
            P = Pe
        return cls(params, X, np.ascontiguousarray(P), n_anchors)

    # ---- state views -------------------------------------------------------------------------------
    @property
    def p_nav(self) -> np.ndarray:
        """Position estimates (n, 3) [m], frame c (a view)."""
        return self.X[:, 0:3]

    @property
    def v_nav(self) -> np.ndarray:
        """Velocity estimates (n, 3) [m/s], frame c (a view)."""
        return self.X[:, 3:6]

    @property
    def q_nav_body(self) -> np.ndarray:
        """Attitude estimates (n, 4), scalar-last (a view)."""
        return self.X[:, 6:10]

    @property
    def sigma_pos_max_m(self) -> np.ndarray:
        """Largest position standard deviation per filter (n,) [m] (Algorithm 1's max(sigma_pos))."""
        out = np.empty(self.n)
        nb.max_sigma_pos_batch(self.P, out)
        return out

    @property
    def last_d2(self) -> np.ndarray:
        """Squared Mahalanobis distance of the last gated update, per filter and kind (n, N_TYPES)."""
        return self.book[:, nb.STF_D2 : nb.STF_D2 + nb.N_TYPES]

    def count(self, kind: MeasKind, what: str = "rejected") -> np.ndarray:
        """Number of ``accepted``/``rejected``/``refused`` updates of ``kind`` per filter (n,)."""
        row = {"accepted": nb.COUNT_ACCEPTED, "rejected": nb.COUNT_REJECTED, "refused": nb.COUNT_REFUSED}
        return self.counts[:, row[what], int(kind)]

    # ---- steps -------------------------------------------------------------------------------------
    def predict(self, w_body, a_nav, dt_s: float) -> np.ndarray:
        """Propagate over ``dt_s`` [s] with gyro rates ``w_body`` [rad/s] and known acceleration
        ``a_nav`` [m/s^2] (frame c). Returns the status per filter; a non-finite input is refused and the
        filter left unchanged."""
        n = self.n
        W = _batch("w_body", w_body, n, (3,))
        A = _batch("a_nav", a_nav, n, (3,))
        nb.predict_batch(self.X, self.P, self.counts, self.book, W, A, float(dt_s), self._prm, self._status)
        return self._status.copy()

    def update_range(self, anchor_nav, range_m, sigma_m=None, mask=None) -> np.ndarray:
        """One UWB two-way range [m] to the anchor at ``anchor_nav`` (frame c) per filter."""
        n = self.n
        anchors = _batch("anchor_nav", anchor_nav, n, (3,))
        z = _batch("range_m", range_m, n, ())
        s = self._sigma_range if sigma_m is None else _batch("sigma_m", sigma_m, n, ())
        gate = self._gate_range
        nb.update_range_batch(
            self.X,
            self.P,
            self.counts,
            self.book,
            self._prm,
            anchors,
            z,
            s,
            _mask(mask, n, self._all),
            gate,
            self._status,
        )
        return self._status.copy()

    def update_features(self, markers_nav, f_cam_m, target_cov_nav=None, sigma_m=None, mask=None):
        """Feature vectors ``f_cam_m`` (n, M, 3) [m] of markers whose positions in frame c are
        ``markers_nav`` (n, M, 3), e.g. from the target's estimated pose with position covariance
        ``target_cov_nav`` (n, 3, 3) (paper sec. IV-D, 1 mm noise by default)."""
        n = self.n
        mk = np.ascontiguousarray(np.asarray(markers_nav, dtype=np.float64))
        if mk.ndim == 2:
            mk = np.ascontiguousarray(np.broadcast_to(mk, (n, *mk.shape)))
        m = mk.shape[1] if mk.ndim == 3 else -1
        if mk.ndim != 3 or mk.shape[0] != n or mk.shape[2] != 3:
            raise ValueError(f"markers_nav must have shape (M, 3) or ({n}, M, 3), got {mk.shape}")
        f = _batch("f_cam_m", f_cam_m, n, (m, 3))
        tc = _batch(
            "target_cov_nav", np.zeros((3, 3)) if target_cov_nav is None else target_cov_nav, n, (3, 3)
        )
        s = _batch("sigma_m", self.params.sigma_feature_m if sigma_m is None else sigma_m, n, ())
        gate = chi2_gate(3 * m, self.params.gate_probability)
        nb.update_features_batch(
            self.X, self.P, self.counts, self.book, self._prm, mk, f, s, tc, self._cam_pos, self._R_bc,
            _mask(mask, n, self._all), gate, self._status,
        )  # fmt: skip
        return self._status.copy()

    def update_pose(
        self, p_target_nav, q_nav_target, t_cam_m, q_cam_target, cov_cam, target_cov_nav=None, mask=None
    ) -> np.ndarray:
        """Relative pose from PnP: the target's origin ``t_cam_m`` (n, 3) and attitude ``q_cam_target``
        (n, 4) in the camera frame, covariance ``cov_cam`` (n, 6, 6) of ``(dt_cam, dphi_cam)``; the
        target's pose ``(p_target_nav, q_nav_target)`` in frame c with position covariance
        ``target_cov_nav``."""
        n = self.n
        args = (
            _batch("p_target_nav", p_target_nav, n, (3,)),
            _batch("q_nav_target", q_nav_target, n, (4,)),
            _batch("t_cam_m", t_cam_m, n, (3,)),
            _batch("q_cam_target", q_cam_target, n, (4,)),
            _batch("cov_cam", cov_cam, n, (6, 6)),
            _batch(
                "target_cov_nav", np.zeros((3, 3)) if target_cov_nav is None else target_cov_nav, n, (3, 3)
            ),
        )
        gate = chi2_gate(6, self.params.gate_probability)
        nb.update_pose_batch(
            self.X, self.P, self.counts, self.book, self._prm, *args, self._cam_pos, self._R_bc, self._q_bc,
            _mask(mask, n, self._all), gate, self._status,
        )  # fmt: skip
        return self._status.copy()

    def update_attitude(self, q_meas_nav_body, cov_body, mask=None) -> np.ndarray:
        """An AHRS attitude ``q_meas_nav_body`` (n, 4) with body-frame rotation-vector covariance
        ``cov_body`` (n, 3, 3) [rad^2]."""
        n = self.n
        q = _batch("q_meas_nav_body", q_meas_nav_body, n, (4,))
        c = _batch("cov_body", cov_body, n, (3, 3))
        gate = chi2_gate(3, self.params.gate_probability)
        nb.update_attitude_batch(
            self.X,
            self.P,
            self.counts,
            self.book,
            self._prm,
            q,
            c,
            _mask(mask, n, self._all),
            gate,
            self._status,
        )
        return self._status.copy()
