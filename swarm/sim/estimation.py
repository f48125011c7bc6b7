"""Estimator-only Monte Carlo: a simple simulated motion, the paper's sensors, many filters at once.

Truth is generated with the filter's own process model so that consistency (NEES, NIS) can be tested
against chi-square bounds (Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4): the centre of mass follows
white-noise-acceleration kinematics around a known, commanded acceleration (a damped pull towards the
workspace centre plus a slow excitation); the body turns with smooth known rates; the gyro adds VN-100
angle random walk; UWB ranges to the four anchors in round robin carry 2 cm white noise and, on
request, NLOS outliers (always long, paper sec. IV-D). All runs are one batched
:class:`~swarm.core.estimator.PoseEstimator`; every random stream comes from one ``SeedSequence``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarm.core import rotations as rot
from swarm.core.estimator import EstimatorParams, MeasKind, PoseEstimator, UpdateStatus

PAPER_ANCHORS_MS = np.array([[1.0, -0.2, 0.5], [1.0, 0.2, -0.5], [-1.0, 0.2, -0.5], [-1.0, -0.2, 0.5]])


@dataclass(frozen=True)
class EstimationScenario:
    """Settings of :func:`run_estimation`; defaults are the paper's sensors (sec. III, VI-A)."""

    runs: int = 50
    duration_s: float = 30.0
    imu_rate_hz: float = 100.0
    uwb_every: int = 2
    """A range every ``uwb_every`` IMU steps (100 Hz / 2 = the hardware's ~50 Hz)."""
    anchors_nav: np.ndarray = field(default_factory=lambda: PAPER_ANCHORS_MS.copy())
    centre_nav: tuple[float, float, float] = (0.0, 0.5, 0.0)
    pull_rate_rad_s: float = 0.5
    """Natural frequency of the commanded pull towards ``centre_nav`` [rad/s]."""
    pull_damping: float = 0.7
    """Damping ratio of that pull."""
    excitation_m_s2: float = 0.02
    """Amplitude of the commanded sinusoidal excitation [m/s^2] ..."""
    excitation_rad_s: float = 0.3
    """... and its angular frequency [rad/s]."""
    body_rate_rad_s: float = 0.1
    """Amplitude of the true body rates [rad/s] ..."""
    body_rate_freqs_rad_s: tuple[float, float, float] = (0.5, 0.4, 0.3)
    """... and their angular frequencies per body axis [rad/s]."""
    start_box_m: float = 0.3
    """True start positions are uniform within +- this of ``centre_nav`` per axis [m] ..."""
    start_attitude_rad: float = 0.5
    """... and true start attitudes have this standard deviation per rotation-vector axis [rad]."""
    ahrs_every: int = 0
    """An AHRS attitude every ``ahrs_every`` IMU steps (0: none). The hardware's VN-100 gives one."""
    ahrs_sigma_rad: float = 0.01
    """AHRS attitude noise per axis (body-frame rotation vector) [rad]."""
    init_sigma_pos_m: float = 0.05
    init_sigma_vel_m_s: float = 0.02
    init_sigma_att_rad: float = 0.05
    outlier_probability: float = 0.0
    outlier_range_m: tuple[float, float] = (0.3, 1.5)
    seed: int = 0


@dataclass
class EstimationResult:
    """Per-run, per-sample histories (runs first) and per-run counters."""

    t_s: np.ndarray
    nees: np.ndarray  # (runs, K) normalised estimation error squared, 9 dof
    err: np.ndarray  # (runs, K, 9) error state (d_p, d_v, d_theta): truth = estimate (+) error
    cov: np.ndarray  # (runs, K, 9, 9) the filter's covariance at the same samples
    pos_err_m: np.ndarray  # (runs, K) |p_est - p_true|
    att_err_rad: np.ndarray  # (runs, K)
    nis_range: np.ndarray  # (runs, R) squared Mahalanobis distance of each clean range
    outlier_total: int
    outlier_rejected: int
    clean_total: int
    clean_rejected: int
    estimator: PoseEstimator


def _truth_accel(t: float, p: np.ndarray, v: np.ndarray, sc: EstimationScenario, phase: np.ndarray):
    w0 = sc.pull_rate_rad_s
    c = np.asarray(sc.centre_nav)
    excitation = sc.excitation_m_s2 * np.sin(sc.excitation_rad_s * t + phase)
    return -(w0**2) * (p - c) - 2.0 * sc.pull_damping * w0 * v + excitation


def run_estimation(params: EstimatorParams, sc: EstimationScenario) -> EstimationResult:
    """Run ``sc.runs`` independent trials of one filter structure; see the module docstring."""
    n, dt = sc.runs, 1.0 / sc.imu_rate_hz
    steps = round(sc.duration_s * sc.imu_rate_hz)
    ss = np.random.SeedSequence(sc.seed)
    rng_init, rng_proc, rng_gyro, rng_uwb, rng_out, rng_ahrs = (np.random.default_rng(s) for s in ss.spawn(6))

    p = np.tile(np.asarray(sc.centre_nav), (n, 1)) + rng_init.uniform(-sc.start_box_m, sc.start_box_m, (n, 3))
    v = np.zeros((n, 3))
    q = rot.rotvec_exp(rng_init.normal(0.0, sc.start_attitude_rad, (n, 3)))
    phase = rng_init.uniform(0, 2 * np.pi, (n, 3))
    sig0 = np.array([sc.init_sigma_pos_m] * 3 + [sc.init_sigma_vel_m_s] * 3 + [sc.init_sigma_att_rad] * 3)
    e0 = rng_init.normal(size=(n, 9)) * sig0
    est = PoseEstimator.create(
        params, p + e0[:, :3], v + e0[:, 3:6], rot.multiplicative_reset(q, -e0[:, 6:]), sig0**2, n=n
    )

    qa = params.accel_psd_m2_s3
    Qd = np.block(
        [
            [qa * dt**3 / 3 * np.eye(3), qa * dt**2 / 2 * np.eye(3)],
            [qa * dt**2 / 2 * np.eye(3), qa * dt * np.eye(3)],
        ]
    )
    Lq = np.linalg.cholesky(Qd)
    sig_g = params.gyro_arw_rad_rts / np.sqrt(dt)
    lever = np.asarray(params.lever_arm_body_m)
    n_anchor = len(sc.anchors_nav)
    f0, f1, f2 = sc.body_rate_freqs_rad_s

    ks, errs, covs, perr, aerr, nis = [], [], [], [], [], []
    out_tot = out_rej = clean_tot = clean_rej = 0
    for k in range(steps):
        t = k * dt
        a_cmd = _truth_accel(t, p, v, sc, phase)
        w_true = sc.body_rate_rad_s * np.stack(
            [np.sin(f0 * t + phase[:, 0]), np.cos(f1 * t + phase[:, 1]), np.sin(f2 * t + phase[:, 2])],
            axis=-1,
        )
        # truth: exact discretisation of the filter's own process model
        w = rng_proc.normal(size=(n, 6)) @ Lq.T
        p, v = p + v * dt + 0.5 * a_cmd * dt**2 + w[:, :3], v + a_cmd * dt + w[:, 3:]
        q = rot.quat_normalize(rot.quat_mul(q, rot.rotvec_exp(w_true * dt)))
        gyro = w_true + rng_gyro.normal(0.0, sig_g, (n, 3))
        est.predict(gyro, a_cmd, dt)

        if k % sc.uwb_every == 0:
            anchor = sc.anchors_nav[(k // sc.uwb_every) % n_anchor]
            true_range = np.linalg.norm(p + rot.quat_rotate(q, lever) - anchor, axis=-1)
            z = true_range + rng_uwb.normal(0.0, params.sigma_range_m, n)
            is_out = rng_out.random(n) < sc.outlier_probability
            z = np.where(is_out, z + rng_out.uniform(*sc.outlier_range_m, n), z)
            status = est.update_range(anchor, z)
            rejected = status == UpdateStatus.REJECTED_OUTLIER
            out_tot += int(is_out.sum())
            out_rej += int((rejected & is_out).sum())
            clean_tot += int((~is_out).sum())
            clean_rej += int((rejected & ~is_out).sum())
            nis.append(np.where(is_out, np.nan, est.last_d2[:, MeasKind.RANGE]))

        if sc.ahrs_every and k % sc.ahrs_every == 0:
            q_meas = rot.multiplicative_reset(q, rng_ahrs.normal(0.0, sc.ahrs_sigma_rad, (n, 3)))
            est.update_attitude(q_meas, sc.ahrs_sigma_rad**2 * np.eye(3))

        if (k + 1) % 10 == 0:
            # error-state convention: truth = estimate (+) error, q = q_est (x) exp(d_theta)
            e = np.concatenate([p - est.p_nav, v - est.v_nav, rot.attitude_error(est.q_nav_body, q)], axis=-1)
            errs.append(e)
            covs.append(est.P.copy())
            perr.append(np.linalg.norm(e[:, :3], axis=-1))
            aerr.append(np.linalg.norm(e[:, 6:], axis=-1))
            ks.append((k + 1) * dt)
    err, cov = np.stack(errs, axis=1), np.stack(covs, axis=1)
    return EstimationResult(
        t_s=np.asarray(ks),
        nees=np.einsum("nki,nki->nk", err, np.linalg.solve(cov, err[..., None])[..., 0]),
        err=err,
        cov=cov,
        pos_err_m=np.stack(perr, axis=1),
        att_err_rad=np.stack(aerr, axis=1),
        nis_range=np.stack(nis, axis=1),
        outlier_total=out_tot,
        outlier_rejected=out_rej,
        clean_total=clean_tot,
        clean_rejected=clean_rej,
        estimator=est,
    )
