"""Run the IMU-driven filter over a recorded log as fast as it can (``swarm replay DIR``).

The whole log goes through one compiled loop (:func:`swarm.core._imu_nb.replay`), which returns to Python
only for a divergence (re-initialisation from ranges, an ``estimator_reset`` event) or a forced fault.
With a ``truth.csv`` the result has the 3-D and per-axis RMSE, the position NEES against its chi-square
band, the NIS of the ranges against theirs, and the rejections per anchor (``docs/logs.md``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from swarm.core import _imu_nb as nb
from swarm.core import rotations as rot
from swarm.core.imu_filter import ImuFilter, divergence_limits
from swarm.core.ranging import position_from_ranges
from swarm.errors import LogError
from swarm.logs.calibrate import StaticCalibration, calibrate_static, level_attitude
from swarm.logs.reader import Log

BAND = 0.95
"""Two-sided probability of the NEES and NIS bands reported."""


@dataclass
class ReplayResult:
    log: Log
    calibration: StaticCalibration | None
    t: np.ndarray
    X: np.ndarray
    P: np.ndarray
    """(rows, 9, 9): the position, velocity and attitude block of the covariance at each row."""
    counts: np.ndarray
    """(anchors, 3): accepted, rejected, refused ranges."""
    nis_t: np.ndarray
    nis_anchor: np.ndarray
    nis_d2: np.ndarray
    nis_outcome: np.ndarray
    dropped: int
    imu_refused: int
    range_bias: np.ndarray
    accel_bias: np.ndarray
    gyro_bias: np.ndarray
    wall_s: float
    events: list[dict] = field(default_factory=list)
    vision_outcome: np.ndarray | None = None
    """Per ``vision.csv`` row: accepted, rejected, refused (:mod:`swarm.core._imu_nb`), -1 not used (older
    than the filter, after the last sample, or ``vision.enabled = false``)."""
    vision_d2: np.ndarray | None = None
    """Per row: the squared Mahalanobis distance of the detection (NaN if not used)."""

    # ------------------------------------------------------------------------------------- against truth

    def errors(self):
        """Position error (rows, 3) [m] against the truth interpolated at each row's time, and the attitude
        error angle [rad]; rows outside the truth's time span are dropped. ``None`` without a truth."""
        lg = self.log
        if lg.truth_t is None:
            return None
        inside = (self.t >= lg.truth_t[0]) & (self.t <= lg.truth_t[-1])
        t = self.t[inside]
        p_true = np.column_stack([np.interp(t, lg.truth_t, lg.truth_p[:, k]) for k in range(3)])
        e = self.X[inside, nb.XP : nb.XP + 3] - p_true
        nearest = np.clip(np.searchsorted(lg.truth_t, t), 0, len(lg.truth_t) - 1)
        q_true = lg.truth_q[nearest]
        dq = rot.quat_mul(rot.quat_conj(q_true), self.X[inside, nb.XQ : nb.XQ + 4])
        angle = np.linalg.norm(rot.quat_log(dq), axis=1)
        return inside, e, angle

    def summary(self) -> dict:
        """The JSON of ``swarm replay --json`` (``docs/logs.md`` lists the keys)."""
        lg = self.log
        ids = [str(int(i)) for i in lg.anchor_ids]
        c = self.counts
        gated = c[:, 0] + c[:, 1]
        out: dict = {
            "log": str(lg.path),
            "name": lg.config.name,
            "duration_s": float(lg.imu_t[-1] - lg.imu_t[0]),
            "imu_samples": len(lg.imu_t),
            "ranges": len(lg.uwb_t),
            "skipped_rows": dict(lg.skipped),
            "dropped_out_of_order": int(self.dropped),
            "imu_refused": int(self.imu_refused),
            "replay_wall_s": self.wall_s,
            "counts_by_anchor": {
                a: {"accepted": int(c[k, 0]), "rejected": int(c[k, 1]), "refused": int(c[k, 2])}
                for k, a in enumerate(ids)
            },
            "rejected_share_by_anchor": {
                a: (float(c[k, 1] / gated[k]) if gated[k] else None) for k, a in enumerate(ids)
            },
            "range_bias_m": {a: float(self.range_bias[k]) for k, a in enumerate(ids)}
            if len(self.range_bias)
            else {},
            "accel_bias_m_s2": self.accel_bias.tolist(),
            "gyro_bias_rad_s": self.gyro_bias.tolist(),
            "events": self.events,
        }
        if self.vision_outcome is not None:
            out["vision"] = self._vision_summary()
        acc = self.nis_outcome == nb.ACCEPTED
        lo1, hi1 = chi2.ppf([(1 - BAND) / 2, (1 + BAND) / 2], 1)
        d2 = self.nis_d2[acc]
        out["nis_mean"] = float(d2.mean()) if len(d2) else None
        out["nis_band"] = [float(lo1), float(hi1)]
        out["nis_in_band_share"] = float(((d2 >= lo1) & (d2 <= hi1)).mean()) if len(d2) else None
        cal = self.calibration
        if cal is not None:
            out["calibration"] = {
                "until_s": cal.until_s,
                "position_surveyed": cal.position_surveyed,
                "position_m": cal.position_nav.tolist(),
                "accel_bias_m_s2": cal.accel_bias.tolist(),
                "gyro_bias_rad_s": cal.gyro_bias.tolist(),
                "range_bias_m": {a: _num(cal.range_bias[k]) for k, a in enumerate(ids)},
                "range_sigma_m": {a: _num(cal.range_sigma[k]) for k, a in enumerate(ids)},
            }
        err = self.errors()
        if err is not None:
            inside, e, angle = err
            Pp = self.P[inside, 0:3, 0:3]
            nees = np.einsum("ni,ni->n", e, np.linalg.solve(Pp, e[..., None])[..., 0])
            lo3, hi3 = chi2.ppf([(1 - BAND) / 2, (1 + BAND) / 2], 3)
            out.update(
                {
                    "rmse_m": float(np.sqrt(np.mean(np.sum(e * e, axis=1)))),
                    "rmse_axis_m": np.sqrt(np.mean(e * e, axis=0)).tolist(),
                    "max_error_m": float(np.max(np.linalg.norm(e, axis=1))),
                    "attitude_rmse_deg": float(np.degrees(np.sqrt(np.mean(angle * angle)))),
                    "nees_mean": float(nees.mean()),
                    "nees_band": [float(lo3), float(hi3)],
                    "nees_in_band_share": float(((nees >= lo3) & (nees <= hi3)).mean()),
                }
            )
        return out

    def _vision_summary(self) -> dict:
        lg = self.log
        o, d2 = self.vision_outcome, self.vision_d2
        lo3, hi3 = chi2.ppf([(1 - BAND) / 2, (1 + BAND) / 2], 3)
        acc = d2[o == nb.ACCEPTED]
        by_marker = {}
        for k, mid in enumerate(lg.marker_ids):
            mine = lg.vision_marker == k
            by_marker[str(int(mid))] = {
                "accepted": int(np.sum(mine & (o == nb.ACCEPTED))),
                "rejected": int(np.sum(mine & (o == nb.REJECTED))),
            }
        return {
            "detections": len(o),
            "used": bool(lg.config.vision.enabled),
            "accepted": int(np.sum(o == nb.ACCEPTED)),
            "rejected": int(np.sum(o == nb.REJECTED)),
            "refused": int(np.sum(o == nb.REFUSED)),
            "not_used": int(np.sum(o < 0)),
            "nis_mean": float(acc.mean()) if len(acc) else None,
            "nis_band": [float(lo3), float(hi3)],
            "nis_in_band_share": float(((acc >= lo3) & (acc <= hi3)).mean()) if len(acc) else None,
            "by_marker": by_marker,
        }

    def series(self) -> tuple[list[str], np.ndarray]:
        """The estimate series: header and rows (``docs/logs.md``, ``estimate.csv``)."""
        cols = [
            "t_s",
            "x_m",
            "y_m",
            "z_m",
            "vx_m_s",
            "vy_m_s",
            "vz_m_s",
            "qx",
            "qy",
            "qz",
            "qw",
            "sigma_x_m",
            "sigma_y_m",
            "sigma_z_m",
        ]
        sig = np.sqrt(np.diagonal(self.P[:, 0:3, 0:3], axis1=1, axis2=2))
        rows = np.column_stack([self.t, self.X[:, 0:10], sig])
        err = self.errors()
        if err is not None:
            inside, e, _ = err
            full = np.full((len(self.t), 3), np.nan)
            full[inside] = e
            cols += ["err_x_m", "err_y_m", "err_z_m"]
            rows = np.column_stack([rows, full])
        return cols, rows


def _num(v: float) -> float | None:
    return None if not math.isfinite(v) else float(v)


def _initial_position(log: Log, lever_nav: np.ndarray) -> np.ndarray:
    """A fix from the first range of each anchor within the log's first second."""
    first: dict[int, float] = {}
    for t, a, z in zip(log.uwb_t, log.uwb_anchor, log.uwb_range, strict=True):
        if t > log.uwb_t[0] + 1.0:
            break
        first.setdefault(int(a), float(z))
    if len(first) < 4:
        raise LogError(
            f"uwb.csv: {len(first)} anchors ranged in the first second; an initial fix needs 4 "
            "(or give initial.position_m in log.toml)"
        )
    p, _ = position_from_ranges(log.anchors_nav, first, lever_nav, log.anchors_nav.mean(axis=0))
    return p


def build_filter(log: Log) -> tuple[ImuFilter, StaticCalibration | None, np.ndarray]:
    """The filter a replay starts from (calibration, ``[initial]``), and what it subtracts from each
    anchor's ranges before feeding them (the calibrated biases when the filter does not estimate them,
    else zeros)."""
    cfg = log.config
    prm = cfg.estimator
    ini = cfg.initial
    g = np.asarray(prm.gravity_nav, dtype=float)
    yaw = math.radians(ini.yaw_deg)
    m = len(log.anchors_nav)
    cal = None
    if cfg.calibration.until_s > 0:
        cal = calibrate_static(
            log,
            cfg.calibration.until_s,
            g,
            prm.lever_arm_m,
            yaw,
            cfg.calibration.position_m,
            cfg.uwb.sigma_floor_m,
        )
    if cfg.uwb.sigma_m is not None:
        sigma = np.full(m, cfg.uwb.sigma_m)
    elif cal is not None:
        sigma = cal.range_sigma.copy()
        known = np.isfinite(sigma)
        if not known.any():
            raise LogError(
                "uwb.csv: no anchor has two ranges in the static segment to calibrate its sigma; "
                "give uwb.sigma_m in log.toml"
            )
        sigma[~known] = np.median(sigma[known])
    else:
        raise LogError(
            "log.toml: uwb.sigma_m is required without a calibration segment (calibration.until_s)"
        )
    q0 = cal.q_nav_body if cal is not None else level_attitude(-g, g, yaw)
    lever_nav = rot.quat_rotate(q0, np.asarray(prm.lever_arm_m, dtype=float))
    if ini.position_m is not None:
        p0 = np.asarray(ini.position_m, dtype=float)
    elif cal is not None:
        p0 = cal.position_nav
    else:
        p0 = _initial_position(log, lever_nav)
    correction = np.zeros(m)
    rb0 = None
    if cal is not None and cfg.calibration.range_bias:
        rb = np.nan_to_num(cal.range_bias, nan=0.0)
        if prm.range_bias:
            rb0 = rb
        else:
            correction = rb  # constant biases, corrected before the filter
    sigmas = (
        ini.sigma_position_m,
        ini.sigma_velocity_m_s,
        math.radians(ini.sigma_attitude_deg),
        ini.sigma_accel_bias_m_s2,
        ini.sigma_gyro_bias_rad_s,
        ini.sigma_range_bias_m,
    )
    f = ImuFilter.create(
        prm,
        log.anchors_nav,
        p0,
        np.zeros(3),
        q0,
        float(log.imu_t[0]),
        sigma,
        sigmas,
        accel_bias=None if cal is None else cal.accel_bias,
        gyro_bias=None if cal is None else cal.gyro_bias,
        range_bias=rb0,
    )
    return f, cal, correction


def replay_log(log: Log) -> ReplayResult:
    """Run the filter over ``log`` (module docstring)."""
    cfg = log.config
    prm = cfg.estimator
    f, cal, correction = build_filter(log)
    ranges = log.uwb_range - correction[log.uwb_anchor]
    m = len(log.anchors_nav)
    n_imu, n_rng = len(log.imu_t), len(log.uwb_t)
    every = cfg.output_every
    rows = n_imu // every + 1
    out_t, out_X, out_P = np.zeros(rows), np.zeros((rows, f.X.shape[1])), np.zeros((rows, 9, 9))
    nis_t, nis_anchor = np.full(n_rng, np.nan), np.full(n_rng, -1, dtype=np.int64)
    nis_d2, nis_outcome = np.full(n_rng, np.nan), np.full(n_rng, -1, dtype=np.int64)
    ST = np.zeros(nb.N_ST, dtype=np.int64)
    ST[nb.ST_HELD] = -1
    tf = np.array([f.t])
    W = prm.window
    win_rej, win_d2 = np.zeros(W), np.zeros(W)
    limits = divergence_limits(W, prm.divergence_alpha)
    last_range, last_range_t = np.full(m, np.nan), np.full(m, -np.inf)
    imu_t, gyro, acc = (np.ascontiguousarray(a) for a in (log.imu_t, log.gyro, log.acc))
    uwb_t, uwb_a = np.ascontiguousarray(log.uwb_t), np.ascontiguousarray(log.uwb_anchor)
    faults = cfg.faults
    t_stop = faults.jump_at_s if faults.jump_at_s is not None else math.inf
    events: list[dict] = []
    X, P = f.X[0], f.P[0]
    vision = _Vision(log) if log.vision_t is not None else None
    t0 = time.perf_counter()
    while True:
        t_vis = vision.next_t() if vision is not None and cfg.vision.enabled else math.inf
        ev = nb.replay(
            X,
            P,
            f.prm,
            tf,
            min(t_stop, t_vis),
            imu_t,
            gyro,
            acc,
            uwb_t,
            uwb_a,
            ranges,
            f.anchors,
            f.bias_of,
            f.sigma,
            ST,
            f.counts,
            win_rej,
            win_d2,
            limits,
            prm.reject_share_max,
            last_range,
            last_range_t,
            every,
            out_t,
            out_X,
            out_P,
            nis_t,
            nis_anchor,
            nis_d2,
            nis_outcome,
        )
        if ev == nb.EV_DONE:
            break
        if ev == nb.EV_PAUSE and t_vis <= t_stop:  # a detection of vision.csv is next
            vision.update(X, P, f.prm, tf, ST, gyro, acc)
            continue
        if ev == nb.EV_PAUSE:  # the forced divergence of [faults]
            X[nb.XP : nb.XP + 3] += faults.jump_m
            P[0:3, :] = 0.0
            P[:, 0:3] = 0.0
            P[0:3, 0:3] = np.eye(3) * faults.jump_sigma_m**2
            events.append(
                {
                    "t_s": float(tf[0]),
                    "kind": "fault",
                    "fault": "position_jump",
                    "jump_m": list(faults.jump_m),
                }
            )
            t_stop = math.inf
            continue
        events.append(_recover(f, log, cfg, float(tf[0]), win_rej, win_d2, last_range, last_range_t))
        ST[nb.ST_WIN_FILL] = ST[nb.ST_WIN_POS] = 0
        win_rej[:] = 0.0
        win_d2[:] = 0.0
    wall = time.perf_counter() - t0
    k = int(ST[nb.ST_I_OUT])
    return ReplayResult(
        log,
        cal,
        out_t[:k],
        out_X[:k],
        out_P[:k],
        f.counts,
        nis_t,
        nis_anchor,
        nis_d2,
        nis_outcome,
        int(ST[nb.ST_DROPPED]),
        int(ST[nb.ST_IMU_REFUSED]),
        f.range_bias[0].copy(),
        f.accel_bias[0].copy(),
        f.gyro_bias[0].copy(),
        wall,
        events,
        None if vision is None else vision.outcome,
        None if vision is None else vision.d2,
    )


class _Vision:
    """The detections of ``vision.csv``, fed between the compiled loop's pauses: the loop stops before the
    first sample after the next detection; the filter predicts to the detection's time with the held IMU
    sample and takes the marker's position in the camera frame (:func:`swarm.core._imu_nb.update_pad_one`,
    ``t = R_bc^T (R(q)^T (m - p) - c)``)."""

    def __init__(self, log: Log) -> None:
        v = log.config.vision
        self.log = log
        self.k = 0
        self.cam = np.asarray(v.camera_position_m, dtype=float)
        self.R_bc = np.ascontiguousarray(rot.quat_to_matrix(np.asarray(v.camera_quaternion, dtype=float)))
        self.gate = float(chi2.ppf(v.gate_probability, 3))
        n = len(log.vision_t)
        self.outcome = np.full(n, -1, dtype=np.int64)
        self.d2 = np.full(n, np.nan)
        self.res = np.empty(2)

    def next_t(self) -> float:
        return float(self.log.vision_t[self.k]) if self.k < len(self.log.vision_t) else math.inf

    def update(self, X, P, prm, tf, ST, gyro, acc) -> None:
        lg, k = self.log, self.k
        self.k += 1
        t = float(lg.vision_t[k])
        if t < tf[0]:  # older than the filter (before the first IMU sample): dropped, counted
            ST[nb.ST_DROPPED] += 1
            return
        h = int(ST[nb.ST_HELD])
        if h >= 0 and t > tf[0] and not nb.predict_one(X, P, gyro[h], acc[h], t - tf[0], prm):
            ST[nb.ST_IMU_REFUSED] += 1
        tf[0] = t
        cov = np.diag(lg.vision_sigma[k] ** 2)
        m = lg.markers_nav[lg.vision_marker[k]]
        self.outcome[k] = nb.update_pad_one(
            X, P, m, self.cam, self.R_bc, lg.vision_xyz[k], cov, self.gate, self.res
        )
        self.d2[k] = self.res[1]


def _recover(f: ImuFilter, log: Log, cfg, t: float, win_rej, win_d2, last_range, last_range_t) -> dict:
    """After the divergence test fired at ``t``: the event, and the re-initialisation from ranges."""
    W = len(win_rej)
    rej = float(win_rej.sum())
    n_acc = W - int(rej)
    event = {
        "t_s": t,
        "kind": "estimator_reset",
        "window": W,
        "reject_share": rej / W,
        "mean_nis": (float(win_d2.sum()) / n_acc) if n_acc else None,
    }
    rec = cfg.recovery
    fresh = {
        a: float(last_range[a] - (f.range_bias[0, a] if f.range_bias.shape[1] else 0.0))
        for a in range(len(last_range))
        if t - last_range_t[a] <= rec.max_range_age_s
    }
    limit = divergence_limits(W, cfg.estimator.divergence_alpha)[n_acc] if n_acc else None
    event["reason"] = (
        f"{rej / W:.0%} of the last {W} ranges rejected (limit {cfg.estimator.reject_share_max:.0%})"
        if rej / W > cfg.estimator.reject_share_max
        else f"mean NIS {event['mean_nis']:.2f} of {n_acc} accepted ranges above {limit:.2f}, its "
        f"chi-square quantile at 1 - {cfg.estimator.divergence_alpha:g}"
    )
    if not rec.enabled:
        event["action"] = "reported only (recovery.enabled = false)"
        return event
    if len(fresh) < 4:
        event["action"] = (
            f"not re-initialised: {len(fresh)} anchors ranged in the last {rec.max_range_age_s:g} s"
        )
        return event
    q = f.q_nav_body[0]
    lever_nav = rot.quat_rotate(q, np.asarray(cfg.estimator.lever_arm_m, dtype=float))
    p, jtj_inv = position_from_ranges(f.anchors, fresh, lever_nav, f.anchors.mean(axis=0))
    var = float(np.max(f.sigma) ** 2) + (float(np.max(np.diag(f.P[0])[15:])) if f.P.shape[1] > 15 else 0.0)
    before = f.p_nav[0].copy()
    f.reset_position(0, p, jtj_inv * var + np.eye(3) * 1e-4, rec.sigma_velocity_m_s)
    event.update(
        {
            "action": "position re-initialised from ranges",
            "anchors": len(fresh),
            "position_before_m": before.tolist(),
            "position_after_m": p.tolist(),
        }
    )
    return event
