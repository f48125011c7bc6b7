"""``swarm fit``: a sensor profile (``swarm.sensors.profile``) measured on a log with a truth.

Range residuals ``range - |p_tag(t) - a|``, the tag at ``p(t) + R(q(t)) l`` with the truth interpolated at
the range's time (position linearly, attitude by slerp; ``l`` is ``estimator.lever_arm_m`` of the log's
log.toml), are split by flight phase, from the truth's height: airborne while the height above the starting
height exceeds ``airborne_height_m`` (a change of state must last ``airborne_dwell_s``); ground = before the
first take-off and after the last landing, a margin ``transition_s`` away from them. Per anchor
(``swarm/logs/uwb_stats.py`` for the estimators and their sources):

* ground bias and sigma: median and ``1.4826 MAD`` of the ground residuals;
* flight: the NLOS split (clear / episodes / isolated outliers), then the median and robust sigma of the
  clear residuals, the NLOS share, episode onset rate and mean duration, mean excess;
* the white + Gauss-Markov split of the clear in-flight residual, from its autocorrelation (per anchor, and
  pooled over anchors for the profile's ``gm_tau_s`` and ``gm_sigma_m``: a minute of one anchor knows tau to
  only ~50 %, eight pooled to ~10 %).

The profile's numbers: ``offset_m`` the median over anchors of the ground bias and ``offset_spread_m`` their
standard deviation; ``takeoff_step_m`` the mean over anchors of flight minus ground bias, with its standard
deviation; ``sigma_m`` and ``ground_sigma_m`` medians over anchors; the NLOS rate as episodes per
anchor-second of flight. The IMU's (``swarm/logs/allan.py``): Allan deviation of the static segment (the
ground before take-off, ``static_margin_s`` before it, or ``static_until_s``), and the vibration: the spread
above ``highpass_hz`` in flight minus (in quadrature) on the static ground, read as white noise over the
whole band (divided by ``sqrt(1 - 2 highpass_hz / rate_hz)``, the share of a white spectrum above the cut).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from swarm.errors import ConfigError, LogError
from swarm.logs import allan, uwb_stats
from swarm.logs.reader import Log
from swarm.sensors.profile import AnchorProfile, ImuProfile, SensorProfile, UwbProfile


@dataclass(frozen=True)
class FitParams:
    """What ``swarm fit`` assumes (``--set key=value``)."""

    airborne_height_m: float = 0.03
    """Airborne while the truth's height above its starting height exceeds this [m]."""
    airborne_dwell_s: float = 0.5
    """A change between ground and air must last this long to count [s]."""
    start_height_s: float = 1.0
    """The starting height is the truth's median height over its first this many seconds [s]."""
    transition_s: float = 1.0
    """Samples this close to a take-off or a landing are in neither phase [s] (spin-up, climb, touch-down)."""
    static_until_s: float | None = None
    """End of the IMU's static segment, log time [s]; None: ``static_margin_s`` before the first take-off."""
    static_margin_s: float = 2.0
    """Without ``static_until_s``, the static segment ends this long before take-off [s] (motors start)."""
    truth_max_gap_s: float = 0.1
    """A range between two truth samples further apart than this is not used [s]."""
    nlos_k: float = 3.0
    """An NLOS range's smoothed residual lies this many clear sigmas above the clear median."""
    nlos_window: int = 5
    """Ranges in the running median that flags NLOS."""
    nlos_min_duration_s: float = 0.3
    """A flagged run must last this long to be an episode [s] (else its ranges are outliers)."""
    nlos_min_ranges: int = 3
    """... and hold this many ranges."""
    acf_max_lag_s: float = 3.0
    """Longest lag of the autocorrelation fitted [s]."""
    highpass_hz: float = 20.0
    """The vibration is the IMU's spread above this frequency [Hz]."""
    tau_white_min_s: float = 0.02
    """The shortest Allan tau used for the white-noise density [s] (above the sensor's low-pass filter)."""

    def __post_init__(self) -> None:
        for name in ("airborne_height_m", "nlos_k", "acf_max_lag_s", "highpass_hz", "tau_white_min_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"fit.{name} must be a finite number > 0, got {v!r}")
        for name in ("airborne_dwell_s", "start_height_s", "transition_s", "static_margin_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"fit.{name} must be a finite number >= 0, got {v!r}")
        if not (self.nlos_window >= 1 and self.nlos_window % 2 == 1):
            raise ConfigError(f"fit.nlos_window must be an odd integer >= 1, got {self.nlos_window!r}")


@dataclass
class AnchorFit:
    """One anchor's numbers, and the series the plots draw."""

    anchor_id: int
    ground_n: int
    flight_n: int
    ground_bias_m: float
    ground_sigma_m: float
    flight_bias_m: float
    flight_sigma_m: float
    """Robust sigma of the clear in-flight residual (white and GM together) [m]."""
    nlos_share: float
    nlos_episodes: int
    nlos_rate_hz: float
    nlos_duration_s: float
    nlos_excess_m: float
    outlier_share: float
    outlier_excess_m: float
    gm: uwb_stats.GmFit
    ground_residual: np.ndarray = field(repr=False)
    flight_residual: np.ndarray = field(repr=False)
    flight_label: np.ndarray = field(repr=False)


@dataclass
class FitResult:
    """What :func:`fit_log` measured."""

    profile: SensorProfile
    anchors: list[AnchorFit]
    gm_pooled: uwb_stats.GmFit
    gyro: allan.AllanFit | None
    accel: allan.AllanFit | None
    spread: dict[str, list[float]]
    """High-passed spread per axis: ``gyro_ground``, ``gyro_flight``, ``accel_ground``, ``accel_flight``."""
    takeoff_s: float
    landing_s: float | None
    static_s: tuple[float, float]
    flight_s: float
    ranges: int
    ranges_unused: int
    """Ranges outside the truth or in a truth gap."""
    notes: list[str]

    def summary(self) -> dict:
        """The numbers, JSON-ready (no series)."""

        def num(v):
            return None if v is None or not math.isfinite(v) else round(float(v), 6)

        def allan_json(a: allan.AllanFit | None):
            if a is None:
                return None
            return {
                "noise_density": [num(v) for v in a.noise_density],
                "bias_instability": [num(v) for v in a.bias_instability],
                "tau_min_s": [num(v) for v in a.tau_min_s],
                "floor_reached": a.floor_reached,
                "white_slope": num(a.white_slope),
                "white_taus_s": list(a.white_taus_s),
            }

        return {
            "takeoff_s": num(self.takeoff_s),
            "landing_s": num(self.landing_s),
            "static_s": list(self.static_s),
            "flight_s": num(self.flight_s),
            "ranges": self.ranges,
            "ranges_unused": self.ranges_unused,
            "gm_pooled": {
                "gm_sigma_m": num(self.gm_pooled.gm_sigma_m),
                "gm_tau_s": num(self.gm_pooled.gm_tau_s),
                "white_sigma_m": num(self.gm_pooled.white_sigma_m),
            },
            "anchors": {
                str(a.anchor_id): {
                    k: (num(v) if isinstance(v, float) else v)
                    for k, v in vars(a).items()
                    if isinstance(v, int | float) and k != "anchor_id"
                }
                | {
                    "gm_sigma_m": num(a.gm.gm_sigma_m),
                    "gm_tau_s": num(a.gm.gm_tau_s),
                    "white_sigma_m": num(a.gm.white_sigma_m),
                }
                for a in self.anchors
            },
            "gyro": allan_json(self.gyro),
            "accel": allan_json(self.accel),
            "spread": {k: [num(x) for x in v] for k, v in self.spread.items()},
            "notes": self.notes,
        }


def _airborne_intervals(t: np.ndarray, h: np.ndarray, prm: FitParams) -> list[tuple[float, float]]:
    """``[(take-off, landing)]`` from the height above the start ``h`` at truth times ``t``: runs above the
    threshold, runs of either state shorter than the dwell absorbed into their neighbours."""
    raw = h > prm.airborne_height_m
    for state in (True, False):  # drop short hops, then fill short dips
        for a, b in uwb_stats.runs(raw == state):
            inner = a > 0 and b < len(t) if not state else True
            if inner and t[b - 1] - t[a] < prm.airborne_dwell_s:
                raw[a:b] = not state
    return [(float(t[a]), float(t[b - 1])) for a, b in uwb_stats.runs(raw)]


def _phase(t: np.ndarray, intervals, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Masks ``(ground, flight)`` of times ``t``: flight inside an interval, ``margin`` from its ends;
    ground before the first or after the last interval, ``margin`` away."""
    flight = np.zeros(len(t), dtype=bool)
    for a, b in intervals:
        flight |= (t >= a + margin) & (t <= b - margin)
    first, last = intervals[0][0], intervals[-1][1]
    ground = (t <= first - margin) | (t >= last + margin)
    return ground, flight


def tag_residuals(log: Log, max_gap_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Each range minus the true distance from the tag (truth interpolated, lever arm from log.toml) and the
    mask of ranges it could be computed for (inside the truth, not in a gap longer than ``max_gap_s``)."""
    tt, tr = log.truth_t, log.uwb_t
    i = np.searchsorted(tt, tr)
    ok = (i > 0) & (i < len(tt)) | (tr == tt[0])
    ii = np.clip(i, 1, len(tt) - 1)
    ok &= (tt[ii] - tt[ii - 1]) <= max_gap_s
    res = np.full(len(tr), np.nan)
    t = tr[ok]
    p = np.column_stack([np.interp(t, tt, log.truth_p[:, k]) for k in range(3)])
    rot = Slerp(tt, Rotation.from_quat(log.truth_q))(t)
    lever = np.asarray(log.config.estimator.lever_arm_m, dtype=float)
    tag = p + rot.apply(lever)
    res[ok] = log.uwb_range[ok] - np.linalg.norm(tag - log.anchors_nav[log.uwb_anchor[ok]], axis=1)
    return res, ok


def _anchor_fit(aid, t, r, ground, flight, seg, dt, flight_s, prm) -> tuple[AnchorFit, uwb_stats.Autocov]:
    """One anchor's fit from its ranges' times ``t``, residuals ``r``, phase masks and segment indices."""
    g = r[ground]
    gb, gs = uwb_stats.robust(g)
    tf, rf, sf = t[flight], r[flight], seg[flight]
    sp = uwb_stats.split_nlos(
        tf, rf, prm.nlos_k, prm.nlos_window, prm.nlos_min_duration_s, prm.nlos_min_ranges, dt
    )
    clear = sp.label == -1
    ac = uwb_stats.residual_autocov(tf[clear], rf[clear], sf[clear], dt, prm.acf_max_lag_s)
    gm = uwb_stats.fit_gm(ac)
    n = max(len(rf), 1)
    epi = sp.label >= 0
    out = sp.label == -2
    return AnchorFit(
        aid,
        len(g),
        len(rf),
        gb,
        gs,
        sp.location_m,
        sp.sigma_m,
        float(epi.sum() / n),
        len(sp.episodes),
        len(sp.episodes) / flight_s if flight_s > 0 else math.nan,
        float(np.mean([b - a for a, b, _ in sp.episodes])) if sp.episodes else math.nan,
        float(np.mean(rf[epi]) - sp.location_m) if epi.any() else math.nan,
        float(out.sum() / n),
        float(np.mean(rf[out]) - sp.location_m) if out.any() else math.nan,
        gm,
        g,
        rf,
        sp.label,
    ), ac


def fit_log(log: Log, prm: FitParams | None = None, source: str = "", name: str = "fitted") -> FitResult:
    """Measure the sensor profile of ``log`` (module docstring). LogError without a truth, a flight, or
    ranges in flight."""
    prm = prm or FitParams()
    if log.truth_t is None:
        raise LogError(f"{log.path}: swarm fit needs truth.csv (the motion-capture truth), which is missing")
    notes: list[str] = []
    g = np.asarray(log.config.estimator.gravity_nav, dtype=float)
    up = -g / np.linalg.norm(g)
    height = log.truth_p @ up
    start = log.truth_t < log.truth_t[0] + prm.start_height_s
    h = height - np.median(height[start])
    intervals = _airborne_intervals(log.truth_t, h, prm)
    if not intervals:
        raise LogError(
            f"truth.csv: the vehicle never rises {prm.airborne_height_m:g} m above its starting height for "
            f"{prm.airborne_dwell_s:g} s: no flight to fit (set airborne_height_m lower?)"
        )
    takeoff = intervals[0][0]
    landing = intervals[-1][1] if intervals[-1][1] < log.truth_t[-1] else None
    flight_s = float(sum(max(b - a - 2 * prm.transition_s, 0.0) for a, b in intervals))

    res, ok = tag_residuals(log, prm.truth_max_gap_s)
    if (~ok).sum():
        notes.append(f"{int((~ok).sum())} ranges outside the truth or in a truth gap were not used")
    ground, flight = _phase(log.uwb_t, intervals, prm.transition_s)
    ground &= ok
    flight &= ok
    seg = np.searchsorted([a for a, _ in intervals], log.uwb_t)
    if not flight.any():
        raise LogError(f"uwb.csv: no range in flight ({len(intervals)} airborne intervals from truth.csv)")
    m = len(log.anchor_ids)
    intervals_by = [np.diff(log.uwb_t[flight & (log.uwb_anchor == a)]) for a in range(m)]
    per_anchor = [float(np.median(d)) for d in intervals_by if len(d) > 10]
    if not per_anchor:
        raise LogError(f"uwb.csv: no anchor has more than 11 ranges in flight ({int(flight.sum())} in all)")
    dt = float(np.median(per_anchor))
    anchors, acs = [], []
    for a in range(m):
        sel = log.uwb_anchor == a
        if not (flight & sel).any():
            what = "no range in flight" if sel.any() else "no range in the log"
            notes.append(f"anchor {int(log.anchor_ids[a])}: {what}, left out")
            continue
        if not (ground & sel).any():
            notes.append(f"anchor {int(log.anchor_ids[a])}: no range on the ground (no ground bias)")
        fit, ac = _anchor_fit(
            int(log.anchor_ids[a]), log.uwb_t[sel], res[sel], ground[sel], flight[sel], seg[sel], dt,
            flight_s, prm,
        )  # fmt: skip
        anchors.append(fit)
        if fit.gm.ok:
            acs.append(ac)
    pooled = (
        uwb_stats.fit_gm(uwb_stats.Autocov.pooled(acs))
        if acs
        else uwb_stats.fit_gm(uwb_stats.Autocov(np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64), 0.0))
    )
    if not pooled.ok:
        notes.append("too few clear in-flight ranges for the Gauss-Markov fit: gm_sigma_m = 0")

    imu, gyro, accel, spread, static = _imu(log, intervals, prm, notes)
    uwb = _uwb_profile(anchors, pooled, notes)
    duration = float(log.uwb_t[-1] - log.uwb_t[0])
    src = source or f"fitted by swarm fit from {log.path} ({len(log.uwb_t)} ranges, {duration:.0f} s)"
    profile = SensorProfile(name=name, source=src, uwb=uwb, imu=imu)
    return FitResult(
        profile, anchors, pooled, gyro, accel, spread, takeoff, landing, static, flight_s, len(log.uwb_t),
        int((~ok).sum()), notes,
    )  # fmt: skip


def _med(values) -> float:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return float(np.median(v)) if v else math.nan


def _std(values) -> float:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return float(np.std(v, ddof=1)) if len(v) > 1 else 0.0


def _sig(v: float, digits: int = 4) -> float:
    """``v`` to ``digits`` significant digits (a profile is read by people; the fit is not that exact)."""
    return float(f"{v:.{digits}g}")


def _opt(v: float) -> float | None:
    return _sig(v) if v is not None and math.isfinite(v) else None


def _uwb_profile(anchors: list[AnchorFit], pooled: uwb_stats.GmFit, notes: list[str]) -> UwbProfile:
    d = UwbProfile()
    ground_bias = [a.ground_bias_m for a in anchors]
    steps = [a.flight_bias_m - a.ground_bias_m for a in anchors]
    flight_total = sum(a.flight_n for a in anchors)
    n_epi = sum(a.nlos_episodes for a in anchors)
    epi_s = sum(a.nlos_duration_s * a.nlos_episodes for a in anchors if a.nlos_episodes)
    nlos_n = sum(a.nlos_share * a.flight_n for a in anchors)
    nlos_x = sum(a.nlos_excess_m * a.nlos_share * a.flight_n for a in anchors if a.nlos_share > 0)
    out_n = sum(a.outlier_share * a.flight_n for a in anchors)
    out_x = sum(a.outlier_excess_m * a.outlier_share * a.flight_n for a in anchors if a.outlier_share > 0)
    white = [a.gm.white_sigma_m if a.gm.ok else a.flight_sigma_m for a in anchors]
    gm_sigma = pooled.gm_sigma_m if pooled.ok else 0.0
    ground_sigma = _med([a.ground_sigma_m for a in anchors])
    if not math.isfinite(ground_sigma):
        notes.append(
            "no range on the ground: ground_sigma_m, offset_m and takeoff_step_m keep their defaults"
        )
    finite_steps = [s for s in steps if math.isfinite(s)]
    values = {
        "sigma_m": max(_med(white), 1e-4),
        "ground_sigma_m": max(ground_sigma, 1e-4) if math.isfinite(ground_sigma) else d.ground_sigma_m,
        "offset_m": _med(ground_bias) if math.isfinite(_med(ground_bias)) else d.offset_m,
        "offset_spread_m": _std(ground_bias),
        "takeoff_step_m": float(np.mean(finite_steps)) if finite_steps else 0.0,
        "takeoff_step_spread_m": _std(steps),
        "gm_sigma_m": gm_sigma,
        "gm_tau_s": pooled.gm_tau_s if pooled.ok else d.gm_tau_s,
        "nlos_rate_hz": float(np.mean([a.nlos_rate_hz for a in anchors])),
        "nlos_duration_s": epi_s / n_epi if n_epi else d.nlos_duration_s,
        "nlos_excess_m": nlos_x / nlos_n if nlos_n > 0 else d.nlos_excess_m,
        "outlier_share": out_n / max(flight_total, 1),
        "outlier_excess_m": out_x / out_n if out_n > 0 else d.outlier_excess_m,
    }
    return UwbProfile(
        **{k: _sig(v) for k, v in values.items()},
        anchors={
            str(a.anchor_id): AnchorProfile(
                ground_bias_m=_opt(a.ground_bias_m),
                flight_bias_m=_opt(a.flight_bias_m),
                ground_sigma_m=_opt(a.ground_sigma_m),
                sigma_m=_opt(a.gm.white_sigma_m if a.gm.ok else a.flight_sigma_m),
                gm_sigma_m=_opt(a.gm.gm_sigma_m) if a.gm.ok else None,
                gm_tau_s=_opt(a.gm.gm_tau_s) if a.gm.ok else None,
                nlos_share=_opt(a.nlos_share),
                nlos_rate_hz=_opt(a.nlos_rate_hz),
                nlos_duration_s=_opt(a.nlos_duration_s),
                nlos_excess_m=_opt(a.nlos_excess_m),
            )
            for a in anchors
        },
    )


def _imu(log: Log, intervals, prm: FitParams, notes: list[str]):
    """The IMU profile, its Allan fits, the high-passed spreads and the static segment."""
    t = log.imu_t
    end = prm.static_until_s if prm.static_until_s is not None else intervals[0][0] - prm.static_margin_s
    static = (t >= t[0]) & (t < end)
    dt = float(np.median(np.diff(t)))
    seg = (float(t[0]), float(end))
    d = ImuProfile()
    if static.sum() < 100:
        notes.append(
            f"static segment {seg[0]:g}-{seg[1]:g} s holds {int(static.sum())} IMU samples: no Allan fit"
        )
        return ImuProfile(rate_hz=_sig(1.0 / dt)), None, None, {}, seg
    T = float(static.sum() * dt)
    gyro = allan.allan_fit(log.gyro[static], dt, prm.tau_white_min_s)
    accel = allan.allan_fit(log.acc[static], dt, prm.tau_white_min_s)
    if T < 10.0:
        notes.append(
            f"static segment of {T:.1f} s: the Allan deviation reaches tau = {gyro.tau_s[-1]:.2f} s only; "
            f"N is read on tau {gyro.white_taus_s[0]:.2g}-{gyro.white_taus_s[1]:.2g} s (gyro), "
            f"{accel.white_taus_s[0]:.2g}-{accel.white_taus_s[1]:.2g} s (accelerometer), extrapolated "
            "along the -1/2 line to 1 s"
        )
    for what, a in (("gyro", gyro), ("accelerometer", accel)):
        if not a.floor_reached:
            notes.append(
                f"{what}: the Allan deviation is still falling at its longest tau ({a.tau_s[-1]:.2g} s): "
                "its bias instability is an upper bound (a longer static segment would show the floor)"
            )
        if abs(a.white_slope + 0.5) > 0.15:
            notes.append(
                f"{what}: the Allan slope where N is read is {a.white_slope:.2f}, not -0.5: white noise does "
                "not dominate there; N is approximate"
            )
    _, flight = _phase(t, intervals, prm.transition_s)
    spread = {
        "gyro_ground": allan.highpass_spread(t, log.gyro, static, prm.highpass_hz),
        "gyro_flight": allan.highpass_spread(t, log.gyro, flight, prm.highpass_hz),
        "accel_ground": allan.highpass_spread(t, log.acc, static, prm.highpass_hz),
        "accel_flight": allan.highpass_spread(t, log.acc, flight, prm.highpass_hz),
    }
    # read as white noise over the whole band (the profile's model): the high-passed variance is the share
    # 1 - 2 fc / fs of a white spectrum's
    band = math.sqrt(max(1.0 - 2.0 * prm.highpass_hz * dt, 1e-6))
    gv = allan.vibration(spread["gyro_flight"], spread["gyro_ground"]) / band
    av = allan.vibration(spread["accel_flight"], spread["accel_ground"]) / band
    if not np.all(np.isfinite(gv)):
        notes.append(f"the IMU rate ({1 / dt:.0f} Hz) or the flight is too short for the vibration spread")

    def rms(v):
        return float(np.sqrt(np.mean(np.square(v))))

    imu = ImuProfile(
        rate_hz=_sig(1.0 / dt),
        gyro_noise_rad_s_rthz=_sig(rms(gyro.noise_density)),
        gyro_bias_instability_rad_s=_sig(rms(gyro.bias_instability)),
        accel_noise_m_s2_rthz=_sig(rms(accel.noise_density)),
        accel_bias_instability_m_s2=_sig(rms(accel.bias_instability)),
        gyro_vibration_rad_s=_sig(rms(gv)) if np.all(np.isfinite(gv)) else d.gyro_vibration_rad_s,
        accel_vibration_m_s2=_sig(rms(av)) if np.all(np.isfinite(av)) else d.accel_vibration_m_s2,
    )
    return imu, gyro, accel, {k: v.tolist() for k, v in spread.items()}, seg
