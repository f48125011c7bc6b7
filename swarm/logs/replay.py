"""Run the IMU-driven filter over a recorded log as fast as it can (``swarm replay DIR``).

The whole log goes through one compiled loop (:func:`swarm.core._imu_nb.replay`), which returns to Python
only for a divergence (re-initialisation from ranges, an ``estimator_reset`` event) or a forced fault.
With a ``truth.csv`` the result has the 3-D and per-axis RMSE, the position NEES against its chi-square
band, the NIS of the ranges against theirs, and the rejections per anchor (``docs/logs.md``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from swarm.core import _imu_nb as nb
from swarm.core import rotations as rot
from swarm.core.imu_filter import ImuFilter, divergence_limits, robust_vector, vibration_level
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
    robust: np.ndarray | None = None
    """(anchors, ``N_RS``): the range model's per-anchor state at the end (:mod:`swarm.core._imu_nb`)."""
    sigma_prior: np.ndarray | None = None
    """Per anchor: the white-noise sigma the filter started from (ground calibration or ``uwb.sigma_m``)."""
    range_error_m: np.ndarray | None = None
    """Per anchor: the modelled range error at the end (common + offset + Gauss-Markov) [m]."""
    common_offset_m: float | None = None
    offset_total_m: np.ndarray | None = None
    """Per anchor: the common offset plus the anchor's own at the end [m] (the range bias of the model)."""
    aux_kind: np.ndarray | None = None
    """Per height sample (``height.csv`` then ``baro.csv`` rows, in time order): its kind."""
    aux_outcome: np.ndarray | None = None
    """Its outcome: accepted, rejected, refused."""
    tdoa: object | None = None
    """With ``tdoa.csv``: the distance differences' outcomes (``_Tdoa``)."""

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
        if self.robust is not None:
            out["range_model"] = self._range_model_summary(ids)
        if self.tdoa is not None:
            out["tdoa"] = self.tdoa.summary(ids)
        if self.aux_kind is not None and len(self.aux_kind):
            out["height"] = {
                name: {
                    "samples": int(np.sum(self.aux_kind == kind)),
                    "accepted": int(np.sum((self.aux_kind == kind) & (self.aux_outcome == nb.ACCEPTED))),
                    "rejected": int(np.sum((self.aux_kind == kind) & (self.aux_outcome == nb.REJECTED))),
                    "refused": int(np.sum((self.aux_kind == kind) & (self.aux_outcome == nb.REFUSED))),
                }
                for kind, name in ((nb.AUX_HEIGHT, "rangefinder"), (nb.AUX_BARO, "barometer"))
                if np.any(self.aux_kind == kind)
            }
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

    def _range_model_summary(self, ids: list[str]) -> dict:
        """Per anchor: the prior (ground) sigma against the adapted one in flight, the NLOS episodes, the
        modelled range error at the end; the common offset."""
        RS = self.robust
        air_n = RS[:, nb.RS_AIR_N]
        flight = np.where(air_n > 0, np.sqrt(RS[:, nb.RS_AIR_VAR_SUM] / np.maximum(air_n, 1)), np.nan)
        return {
            "common_offset_m": self.common_offset_m,
            "by_anchor": {
                a: {
                    "sigma_ground_m": _num(float(self.sigma_prior[k])),
                    "sigma_flight_m": _num(float(flight[k])),
                    "sigma_end_m": _num(float(np.sqrt(RS[k, nb.RS_VAR]))),
                    "nlos_episodes": int(RS[k, nb.RS_EPISODES]),
                    "nlos_ranges": int(RS[k, nb.RS_NLOS_RANGES]),
                    "offset_changes": int(RS[k, nb.RS_STEPS]),
                    "range_error_m": _num(float(self.range_error_m[k])),
                }
                for k, a in enumerate(ids)
            },
        }

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
    if is_tdoa(log):
        prm = tdoa_estimator(cfg)
        ini = dataclasses.replace(ini, sigma_range_bias_m=cfg.tdoa.offset_sigma_m)
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
    elif len(log.uwb_t) == 0:  # no two-way ranges (a TDoA flight): the sigma is never used
        sigma = np.full(m, cfg.uwb.sigma_floor_m)
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
    common = 0.0
    if cal is not None and cfg.calibration.range_bias:
        rb = np.nan_to_num(cal.range_bias, nan=0.0)
        if prm.range_common_offset and np.isfinite(cal.range_bias).any():
            common = float(np.median(cal.range_bias[np.isfinite(cal.range_bias)]))
            rb = np.where(np.isfinite(cal.range_bias), rb - common, 0.0)
        if prm.range_bias:
            rb0 = rb
        else:
            correction = rb  # constant biases, corrected before the filter
    surveyed = cal is not None and cal.position_surveyed and ini.position_m is None
    calibrated = surveyed and cfg.calibration.range_bias and bool(np.any(cal.range_count > 0))
    sigmas = (
        cfg.calibration.position_sigma_m if surveyed else ini.sigma_position_m,
        ini.sigma_velocity_m_s,
        math.radians(ini.sigma_attitude_deg),
        ini.sigma_accel_bias_m_s2,
        ini.sigma_gyro_bias_rad_s,
        cfg.calibration.range_bias_sigma_m if calibrated else ini.sigma_range_bias_m,
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
        common_offset=common,
        sigma_common_m=cfg.calibration.range_bias_sigma_m if calibrated else ini.sigma_common_offset_m,
        baro=_has(log, "baro_t") and cfg.baro.enabled,
    )
    if calibrated:  # an anchor without ranges in the static segment keeps the uncalibrated prior
        for a in np.flatnonzero(cal.range_count == 0):
            if f.layout.offset[a] >= 0:
                f.P[0, f.layout.offset[a], f.layout.offset[a]] = ini.sigma_range_bias_m**2
    return f, cal, correction


def is_tdoa(log: Log) -> bool:
    """A TDoA log: ``tdoa.csv`` fused and no two-way ranges. Its range-error model is ``[tdoa]``'s
    (:func:`tdoa_estimator`)."""
    return _has(log, "tdoa_t") and log.config.tdoa.enabled and len(log.uwb_t) == 0


def tdoa_estimator(cfg):
    """The estimator of a TDoA log: the per-anchor Gauss-Markov term of ``[tdoa] gm_sigma_m`` and
    ``gm_tau_s``, no common offset (every distance difference cancels it: a state nothing observes), and
    per-anchor offsets only with ``[tdoa] offsets`` (a height error hides in them: ``TdoaLog.offsets``)."""
    return dataclasses.replace(
        cfg.estimator,
        range_gm_sigma_m=cfg.tdoa.gm_sigma_m,
        range_gm_tau_s=cfg.tdoa.gm_tau_s,
        range_common_offset=False,
        range_bias=cfg.estimator.range_bias and cfg.tdoa.offsets,
    )


def _has(log: Log, name: str) -> bool:
    v = getattr(log, name, None)
    return v is not None and len(v) > 0


def ground_height(log: Log, cal: StaticCalibration | None) -> float:
    """The ground's height for ``height.csv`` (``[height] ground_z_m``): given, else the calibration
    position's height minus the static segment's median reading, else 0."""
    h = log.config.height
    if h.ground_z_m is not None:
        return float(h.ground_z_m)
    if cal is not None and _has(log, "height_t"):
        seg = log.height_range[log.height_t < cal.until_s]
        seg = seg[np.isfinite(seg)]
        if len(seg):
            return float(cal.position_nav[2] - np.median(seg))
    return 0.0


def aux_streams(log: Log, f: ImuFilter, cal: StaticCalibration | None):
    """``height.csv`` and ``baro.csv`` as one time-ordered stream for the compiled loop: times, kinds
    (``AUX_HEIGHT``, ``AUX_BARO``), values, and the ``AX`` parameter vector. The barometer's offset state
    starts at the first reading minus the filter's first height (then it is estimated)."""
    cfg = log.config
    parts_t, parts_k, parts_z = [np.zeros(0)], [np.zeros(0, np.int64)], [np.zeros(0)]
    ax = np.zeros(nb.N_AX)
    ax[nb.AX_B_INDEX] = -1.0
    if _has(log, "height_t") and cfg.height.enabled:
        hc = cfg.height
        ax[nb.AX_H_ON] = 1.0
        ax[nb.AX_H_SIGMA], ax[nb.AX_H_MAX] = hc.sigma_m, hc.max_range_m
        ax[nb.AX_H_COS] = hc.min_cos_tilt
        ax[nb.AX_H_GROUND] = ground_height(log, cal)
        ax[nb.AX_H_GATE] = chi2.ppf(hc.gate_probability, 1)
        ax[nb.AX_H_RESET_N] = hc.reset_after
        parts_t.append(log.height_t)
        parts_k.append(np.full(len(log.height_t), nb.AUX_HEIGHT, np.int64))
        parts_z.append(log.height_range)
    if f.layout.baro >= 0:
        bc = cfg.baro
        ax[nb.AX_B_ON] = 1.0
        ax[nb.AX_B_SIGMA], ax[nb.AX_B_INDEX] = bc.sigma_m, f.layout.baro
        ax[nb.AX_B_GATE] = chi2.ppf(bc.gate_probability, 1)
        f.X[:, f.layout.baro + 1] = float(log.baro_height[0]) - f.X[0, nb.XP + 2]
        parts_t.append(log.baro_t)
        parts_k.append(np.full(len(log.baro_t), nb.AUX_BARO, np.int64))
        parts_z.append(log.baro_height)
    t = np.concatenate(parts_t)
    order = np.argsort(t, kind="stable")
    return (
        np.ascontiguousarray(t[order]),
        np.ascontiguousarray(np.concatenate(parts_k)[order]),
        np.ascontiguousarray(np.concatenate(parts_z)[order]),
        ax,
    )


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
    win = _Window(W)
    limits = divergence_limits(W, prm.divergence_alpha)
    last_range, last_range_t = np.full(m, np.nan), np.full(m, -np.inf)
    imu_t, gyro, acc = (np.ascontiguousarray(a) for a in (log.imu_t, log.gyro, log.acc))
    uwb_t, uwb_a = np.ascontiguousarray(log.uwb_t), np.ascontiguousarray(log.uwb_anchor)
    aux_t, aux_kind, aux_z, AX = aux_streams(log, f, cal)
    aux_outcome = np.full(len(aux_t), -1, dtype=np.int64)
    td = _Tdoa(log, m)
    RS, RP, PH = robust_state(log, f, cal)
    phase_t, phase_air = np.zeros(64), np.zeros(64, dtype=np.int64)
    faults = cfg.faults
    t_stop = faults.jump_at_s if faults.jump_at_s is not None else math.inf
    events: list[dict] = []
    X, P = f.X[0], f.P[0]
    vision = _Vision(log) if log.vision_t is not None else None
    t0 = time.perf_counter()
    while True:
        t_vis = vision.next_t() if vision is not None and cfg.vision.enabled else math.inf
        ev = nb.replay(
            X, P, f.prm, tf, min(t_stop, t_vis), imu_t, gyro, acc, uwb_t, uwb_a, ranges, f.anchors, f.ridx,
            RS, RP, aux_t, aux_kind, aux_z, AX, aux_outcome, PH, phase_t, phase_air,
            td.t, td.a, td.b, td.z, td.TV, td.counts, td.d2, td.outcome, ST, f.counts,
            win.rej, win.d2, win.w, win.all, limits, prm.reject_share_max, last_range, last_range_t,
            every, out_t, out_X, out_P, nis_t, nis_anchor, nis_d2, nis_outcome,
        )  # fmt: skip
        if ev == nb.EV_DONE:
            break
        if ev == nb.EV_PAUSE and t_vis <= t_stop:  # a detection of vision.csv is next
            vision.update(X, P, f.prm, tf, ST, gyro, acc, RP, PH)
            continue
        if ev == nb.EV_PAUSE:  # the forced divergence of [faults]
            events.append(jump(X, P, faults, float(tf[0])))
            t_stop = math.inf
            continue
        events.append(recover(f, cfg, float(tf[0]), win, last_range, last_range_t, RS))
        win.clear(ST)
    wall = time.perf_counter() - t0
    k = int(ST[nb.ST_I_OUT])
    for j in range(int(ST[nb.ST_N_PHASE])):
        events.append(phase_event(float(phase_t[j]), int(phase_air[j])))
    events.sort(key=lambda e: e["t_s"])
    res = ReplayResult(
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
    res.robust = RS
    res.range_error_m = f.range_error_total[0].copy()
    res.offset_total_m = f.range_bias[0] + (res_common := _common(f))
    res.common_offset_m = res_common if f.layout.common >= 0 else None
    res.sigma_prior = f.sigma.copy()
    res.aux_kind, res.aux_outcome = aux_kind, aux_outcome
    res.tdoa = td if len(td.t) else None
    return res


def robust_state(log: Log, f: ImuFilter, cal: StaticCalibration | None):
    """The range model's per-anchor state ``RS`` (from the filter's prior sigmas), its settings ``RP`` and
    the phase detector's state ``PH`` (:mod:`swarm.core._imu_nb`), as a replay and the live navigator start
    them. The take-off height is measured from the calibration position's height, else the filter's first;
    the vibration level standing still from the static segment, else the log's first second."""
    cfg = log.config
    RS = np.zeros((len(f.anchors), nb.N_RS))
    nb.robust_init(RS, f.sigma)
    ground = float(cal.position_nav[2]) if cal is not None else float(f.X[0, nb.XP + 2])
    still = log.imu_t < (cal.until_s if cal is not None else log.imu_t[0] + 1.0)
    RP = robust_vector(
        cfg.robust, cfg.phases, cfg.uwb.sigma_floor_m, ground, f.layout.baro, len(f.anchors),
        vibration_level(log.acc[still]), cfg.estimator.accel_vibration_k,
        float(np.linalg.norm(cfg.estimator.gravity_nav)),
    )  # fmt: skip
    if is_tdoa(log):
        RP[nb.RP_CUSUM_K] = cfg.tdoa.cusum_k
    PH = np.zeros(nb.N_PH)
    PH[nb.PH_SINCE] = -1.0
    PH[nb.PH_DESC_T] = PH[nb.PH_PIN_T] = PH[nb.PH_CHANGE_T] = -np.inf
    PH[nb.PH_ARMED] = 1.0
    # the vehicle starts on a known pad: a surveyed calibration position, or [initial] position_m
    pinned = (cal is not None and cal.position_surveyed) or cfg.initial.position_m is not None
    PH[nb.PH_PINNED] = PH[nb.PH_TOUCH] = float(pinned and cfg.phases.enabled)
    return RS, RP, PH


def phase_event(t: float, change: int) -> dict:
    """A flight-phase change as a report event: ``change`` 1 a take-off, 0 a landing, -1 a touchdown (a
    landing after which the vehicle is pinned, :func:`swarm.core._imu_nb.pin_step`)."""
    if change > 0:
        return {"t_s": t, "kind": "takeoff"}
    return {"t_s": t, "kind": "landing", "touchdown": change < 0}


def tdoa_noise(m: int, sigma_m: float) -> np.ndarray:
    """Each anchor pair's noise state for :func:`swarm.core._imu_nb.fuse_tdoa`: the prior variance, no
    running means yet."""
    TV = np.full((m, m, nb.N_TV), np.nan)
    TV[:, :, nb.TV_VAR] = TV[:, :, nb.TV_PRIOR] = sigma_m**2
    return TV


class _Tdoa:
    """``tdoa.csv`` for the compiled loop (empty arrays without one, or with ``[tdoa] enabled = false``), and
    what the loop writes back: per row the squared distance and the outcome, per anchor pair the counts."""

    def __init__(self, log: Log, m: int) -> None:
        use = getattr(log, "tdoa_t", None) is not None and len(log.tdoa_t) and log.config.tdoa.enabled
        self.t = np.ascontiguousarray(log.tdoa_t) if use else np.zeros(0)
        self.a = np.ascontiguousarray(log.tdoa_a, dtype=np.int64) if use else np.zeros(0, np.int64)
        self.b = np.ascontiguousarray(log.tdoa_b, dtype=np.int64) if use else np.zeros(0, np.int64)
        self.z = np.ascontiguousarray(log.tdoa_ddist) if use else np.zeros(0)
        self.counts = np.zeros((m, m, 3), dtype=np.int64)
        self.TV = tdoa_noise(m, log.config.tdoa.sigma_m)
        self.d2 = np.full(len(self.t), np.nan)
        self.outcome = np.full(len(self.t), -1, dtype=np.int64)

    def summary(self, ids: list[str]) -> dict:
        acc = self.outcome == nb.ACCEPTED
        gated = (self.outcome == nb.ACCEPTED) | (self.outcome == nb.REJECTED)
        lo1, hi1 = chi2.ppf([(1 - BAND) / 2, (1 + BAND) / 2], 1)
        d2 = self.d2[acc]
        c = self.counts
        pairs = {}
        for a, b in zip(*np.nonzero(c.sum(axis=2)), strict=True):
            n_acc, n_rej, n_ref = (int(x) for x in c[a, b])
            pairs[f"{ids[a]}-{ids[b]}"] = {
                "accepted": n_acc,
                "rejected": n_rej,
                "refused": n_ref,
                "rejected_share": n_rej / (n_acc + n_rej) if n_acc + n_rej else None,
            }
        return {
            "measurements": len(self.t),
            "accepted": int(acc.sum()),
            "rejected": int(np.sum(self.outcome == nb.REJECTED)),
            "rejected_share": float(np.sum(self.outcome == nb.REJECTED) / gated.sum())
            if gated.any()
            else None,
            "nis_mean": float(d2.mean()) if len(d2) else None,
            "nis_in_band_share": float(((d2 >= lo1) & (d2 <= hi1)).mean()) if len(d2) else None,
            "by_pair": pairs,
            "sigma_by_pair_m": {
                f"{ids[a]}-{ids[b]}": float(np.sqrt(self.TV[a, b, 0]))
                for a, b in zip(*np.nonzero(c.sum(axis=2)), strict=True)
            },
        }


def _common(f: ImuFilter) -> float:
    return float(f.X[0, f.layout.common + 1]) if f.layout.common >= 0 else 0.0


class _Window:
    """The divergence test's window (:func:`swarm.core._imu_nb.window_push`): rejected flags, the accepted
    ranges' NIS and effective-sample weights, and every range's NIS."""

    def __init__(self, W: int) -> None:
        self.rej, self.d2, self.w, self.all = np.zeros(W), np.zeros(W), np.zeros(W), np.zeros(W)

    def clear(self, ST) -> None:
        ST[nb.ST_WIN_FILL] = ST[nb.ST_WIN_POS] = 0
        for a in (self.rej, self.d2, self.w, self.all):
            a[:] = 0.0


def jump(X, P, faults, t: float) -> dict:
    """The forced divergence of ``[faults]``: the estimate jumps, its covariance shrinks."""
    X[nb.XP : nb.XP + 3] += faults.jump_m
    P[0:3, :] = 0.0
    P[:, 0:3] = 0.0
    P[0:3, 0:3] = np.eye(3) * faults.jump_sigma_m**2
    return {"t_s": t, "kind": "fault", "fault": "position_jump", "jump_m": list(faults.jump_m)}


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

    def update(self, X, P, prm, tf, ST, gyro, acc, RP, PH) -> None:
        lg, k = self.log, self.k
        self.k += 1
        t = float(lg.vision_t[k])
        if t < tf[0]:  # older than the filter (before the first IMU sample): dropped, counted
            ST[nb.ST_DROPPED] += 1
            return
        h = int(ST[nb.ST_HELD])
        if h >= 0 and t > tf[0] and not nb.predict_step(X, P, gyro[h], acc[h], t - tf[0], prm, RP, PH):
            ST[nb.ST_IMU_REFUSED] += 1
        tf[0] = t
        cov = np.diag(lg.vision_sigma[k] ** 2)
        m = lg.markers_nav[lg.vision_marker[k]]
        self.outcome[k] = nb.update_pad_one(
            X, P, m, self.cam, self.R_bc, lg.vision_xyz[k], cov, self.gate, self.res
        )
        self.d2[k] = self.res[1]


def recover(f: ImuFilter, cfg, t: float, win: _Window, last_range, last_range_t, RS) -> dict:
    """After the divergence test fired at ``t``: the ``estimator_reset`` event, and the recovery of
    ``[recovery] mode``.

    ``inflate`` adds the 90th percentile of the squared innovations of the window's rejected ranges (of all
    its ranges when none was rejected; at most ``max_position_sigma_m`` squared: a range's innovation is
    the position error projected on the anchor's direction, so the largest ones measure the error, and a
    covariance too large costs only a few ranges' weight) to each axis of the position covariance, and
    ``sigma_velocity_m_s`` squared to the velocity's. The estimate is kept, so a false alarm costs nothing
    but a few ranges' weight. Then the least-squares fix of the latest range to each anchor (soft-L1
    against NLOS; its covariance from the largest adapted range variance) is fused as one position
    measurement, so that a large error is not left to the linearised scalar updates (the fix is not a
    reset: a consistent estimate barely moves).

    ``refix`` re-initialises the position from the latest range to each anchor (least squares) and zeroes
    the velocity. Both clear the NLOS holds."""
    W = len(win.rej)
    rej = float(win.rej.sum())
    n_acc = W - int(rej)
    event = {
        "t_s": t,
        "kind": "estimator_reset",
        "window": W,
        "reject_share": rej / W,
        "mean_nis": (float(win.d2.sum()) / n_acc) if n_acc else None,
        "n_eff": float(win.w.sum()),
    }
    rec = cfg.recovery
    limit = (
        divergence_limits(W, cfg.estimator.divergence_alpha)[max(1, int(win.w.sum() + 1e-9))]
        if n_acc
        else None
    )
    event["reason"] = (
        f"{rej / W:.0%} of the last {W} ranges rejected (limit {cfg.estimator.reject_share_max:.0%})"
        if rej / W > cfg.estimator.reject_share_max
        else f"mean NIS {event['mean_nis']:.2f} of {n_acc} accepted ranges (worth {event['n_eff']:.1f} "
        f"independent ones) above {limit:.2f}, its chi-square quantile at 1 - "
        f"{cfg.estimator.divergence_alpha:g}"
    )
    if not rec.enabled:
        event["action"] = "reported only (recovery.enabled = false)"
        return event
    RS[:, nb.RS_NLOS] = 0.0
    RS[:, nb.RS_CUSUM] = 0.0
    RS[:, nb.RS_GRACE_UNTIL] = t + cfg.robust.nlos_grace_s
    fresh = {
        a: float(last_range[a] - f.range_error_total[0, a])
        for a in range(len(last_range))
        if t - last_range_t[a] <= rec.max_range_age_s
    }
    if rec.mode == "inflate":
        rejected = win.rej > 0.5
        seen = win.all[rejected] if rejected.any() else win.all  # the ranges that disagree say how far
        var = float(min(np.quantile(seen, 0.9), rec.max_position_sigma_m**2))
        f.inflate(0, var, rec.sigma_velocity_m_s**2)
        event.update({"action": "position and velocity covariance inflated", "sigma_added_m": math.sqrt(var)})
        if len(fresh) >= 4:  # the latest ranges' least-squares fix as one measurement of the position
            q = f.q_nav_body[0]
            lever_nav = rot.quat_rotate(q, np.asarray(cfg.estimator.lever_arm_m, dtype=float))
            p, jtj_inv = position_from_ranges(f.anchors, fresh, lever_nav, f.p_nav[0])
            cov = jtj_inv * float(np.max(RS[:, nb.RS_VAR])) + np.eye(3) * 1e-4
            out = f.update_position(t, p, cov)
            event["fix"] = {"anchors": len(fresh), "position_m": p.tolist(), "outcome": int(out[0])}
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
