"""The log replay's filter on live sensors (``swarm navigate``): samples arrive one by one, from two streams
whose relative order the transport does not keep, and the estimates must be those ``swarm replay`` gives
for the same samples.

Samples go into a reorder buffer and are processed in time order once they are ``delay_s`` older than the
newest sample seen (the *delayed fusion horizon* of PX4's EKF2, which fuses every sensor at a time behind
the newest IMU sample so that late sensors still arrive in order). A sample that comes later than that,
older than the filter, is dropped and counted, as the replay drops one.

Until the filter can start, samples are kept: with a calibration segment (``[calibration] until_s``) the
filter is built from the samples before ``until_s`` exactly as the replay builds it
(:func:`swarm.logs.replay.build_filter`); without one and without ``[initial] position_m``, from the first
second of ranges. Then every kept sample is processed from the first IMU sample on, and every later one as
it comes. Each sample takes the steps of the compiled replay loop (:func:`swarm.core._imu_nb.replay`):
the same kernels in the same order, the same divergence window (:func:`~swarm.core._imu_nb.window_push`),
the same recovery and forced fault, so a log fed in time order gives the replay's estimates bit for bit
(tests/logs/test_online.py). Times are those of the samples (``swarm replay --zenoh`` sends them from the
log's first IMU sample), and log.toml's times (``until_s``, ``jump_at_s``) are read on that clock.
"""

from __future__ import annotations

import heapq
import math
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from swarm.core import _imu_nb as nb
from swarm.core import rotations as rot
from swarm.core.imu_filter import ImuFilter, divergence_limits
from swarm.errors import ConfigError
from swarm.logs.reader import Log, LogConfig
from swarm.logs.replay import (
    _Window,
    aux_streams,
    build_filter,
    jump,
    phase_event,
    recover,
    robust_state,
    tdoa_noise,
)

_IMU, _UWB, _TDOA, _HEIGHT, _BARO, _VISION = 0, 1, 2, 3, 4, 5  # samples of one time in the replay's order


@dataclass
class OnlineEstimate:
    """One output row: after the IMU sample ``tick`` (every ``output_every``-th, as the replay writes)."""

    t_s: float
    tick: int
    X: np.ndarray
    P9: np.ndarray
    """The position, velocity and attitude block of the covariance (9, 9)."""
    d2: float
    """Squared Mahalanobis distance of the latest gated range."""
    reject_share: float
    """Share of the divergence window's ranges rejected (over the ranges seen so far while it fills)."""
    counts: dict[str, int] = field(default_factory=dict)


class OnlineNavigator:
    """The IMU-driven filter of a log's ``log.toml`` on samples pushed as they arrive (module docstring).
    ``imu`` and ``uwb`` may be called from any thread; ``drain`` from one."""

    def __init__(self, config: LogConfig, anchor_ids, anchors_nav, delay_s: float = 0.05,
                 marker_ids=(), markers_nav=None) -> None:  # fmt: skip
        if not (math.isfinite(delay_s) and delay_s >= 0):
            raise ValueError(f"delay_s must be a finite number >= 0, got {delay_s!r}")
        if config.uwb.sigma_m is None and config.calibration.until_s <= 0:
            raise ConfigError(
                "log.toml: uwb.sigma_m is required without a calibration segment (calibration.until_s)"
            )
        self.config = config
        self.anchor_ids = np.asarray(anchor_ids, dtype=np.int64)
        self.anchors_nav = np.ascontiguousarray(anchors_nav, dtype=float)
        self._index = {int(a): k for k, a in enumerate(self.anchor_ids)}
        self.delay_s = float(delay_s)
        self._lock = threading.Lock()
        self._heap: list = []
        self._seq = 0
        self._newest = -math.inf
        self._kept: list = []  # samples before the filter starts, in time order
        self.f: ImuFilter | None = None
        self.unknown_anchor = 0
        self.marker_ids = np.asarray(marker_ids, dtype=np.int64)
        self.markers_nav = np.zeros((0, 3)) if markers_nav is None else np.asarray(markers_nav, dtype=float)
        self._marker_index = {int(m): k for k, m in enumerate(self.marker_ids)}
        v = config.vision
        self._cam = np.asarray(v.camera_position_m, dtype=float)
        self._R_bc = np.ascontiguousarray(rot.quat_to_matrix(np.asarray(v.camera_quaternion, dtype=float)))
        self._vision_cov = np.diag(np.asarray(v.sigma_m, dtype=float) ** 2)
        self._vision_gate = float(chi2.ppf(v.gate_probability, 3))
        self.unknown_marker = 0
        self.tdoa_refused = 0
        self.vision_counts = np.zeros(3, dtype=np.int64)
        """Detections accepted, rejected, refused."""
        self.dropped = 0
        self.imu_refused = 0
        self.events: list[dict] = []
        self.estimates: list[OnlineEstimate] = []

    # ------------------------------------------------------------------------------------------ input

    def imu(self, t_s: float, tick: int, gyro_body, acc_body) -> None:
        g = np.array(gyro_body, dtype=float)
        a = np.array(acc_body, dtype=float)
        self._push(float(t_s), _IMU, (int(tick), g, a))

    def uwb(self, t_s: float, anchor_id: int, range_m: float) -> None:
        k = self._index.get(int(anchor_id))
        if k is None:
            with self._lock:
                self.unknown_anchor += 1
            return
        self._push(float(t_s), _UWB, (k, float(range_m)))

    def tdoa(self, t_s: float, anchor_a: int, anchor_b: int, ddist_m: float) -> None:
        """A distance difference ``|p - a_b| - |p - a_a|`` [m] (``tdoa.csv``); an unknown anchor, the same
        anchor twice or a non-finite value is counted in ``unknown_anchor`` / ``tdoa_refused``, not fed."""
        a, b = self._index.get(int(anchor_a)), self._index.get(int(anchor_b))
        if a is None or b is None:
            with self._lock:
                self.unknown_anchor += 1
            return
        if a == b or not math.isfinite(ddist_m) or not self.config.tdoa.enabled:
            with self._lock:
                self.tdoa_refused += 1
            return
        self._push(float(t_s), _TDOA, (a, b, float(ddist_m)))

    def height(self, t_s: float, range_m: float) -> None:
        """A downward rangefinder's distance [m] (``height.csv``; NaN or None: no reading, not fed). With
        ``height.enabled = false`` nothing is fed, as the replay leaves ``height.csv`` out (:meth:`baro`)."""
        if range_m is not None and math.isfinite(range_m) and self.config.height.enabled:
            self._push(float(t_s), _HEIGHT, float(range_m))

    def baro(self, t_s: float, height_m: float) -> None:
        """A barometric height [m] (``baro.csv``), any offset. The barometer's offset is a state of the
        filter only if a reading arrived before the filter started (as in a replay of a log with
        ``baro.csv``); without it, readings are refused (counted in ``aux_counts``). With
        ``baro.enabled = false`` (the default) nothing is fed, as the replay leaves ``baro.csv`` out of its
        stream: a refused reading would still split the IMU interval it falls in (a prediction to its time),
        and the estimates would no longer be the replay's bit for bit."""
        if height_m is not None and math.isfinite(height_m) and self.config.baro.enabled:
            self._push(float(t_s), _BARO, float(height_m))

    def vision(self, t_s: float, marker_id: int, xyz_cam) -> None:
        """A detection of marker ``marker_id`` at ``xyz_cam`` (3,) [m] in the camera frame (``vision.csv``);
        its sigma is ``[vision] sigma_m`` of log.toml. An unknown marker is counted, not fed; with
        ``vision.enabled = false`` nothing is fed."""
        k = self._marker_index.get(int(marker_id))
        if k is None:
            with self._lock:
                self.unknown_marker += 1
            return
        if self.config.vision.enabled:
            self._push(float(t_s), _VISION, (k, np.array(xyz_cam, dtype=float)))

    def _push(self, t: float, kind: int, data) -> None:
        with self._lock:
            heapq.heappush(self._heap, (t, kind, self._seq, data))
            self._seq += 1
            self._newest = max(self._newest, t)

    # ------------------------------------------------------------------------------------------ output

    def drain(self, final: bool = False) -> tuple[list[OnlineEstimate], list[dict]]:
        """Process every sample older than the horizon (all of them if ``final``: the stream has ended);
        returns the estimates and the events that came of it."""
        n_est, n_ev = len(self.estimates), len(self.events)
        while True:
            with self._lock:
                if not self._heap or not (final or self._heap[0][0] <= self._newest - self.delay_s):
                    break
                sample = heapq.heappop(self._heap)
            if self.f is None:
                self._kept.append(sample)
                if self._ready(sample[0]):
                    self._start()
            else:
                self._process(sample)
        if final and self.f is None and self._kept:
            self._start()
        return self.estimates[n_est:], self.events[n_ev:]

    # -------------------------------------------------------------------------------------- the filter

    def _ready(self, t: float) -> bool:
        cfg = self.config
        if cfg.calibration.until_s > 0 and t < cfg.calibration.until_s:
            return False
        if cfg.calibration.until_s <= 0 and cfg.initial.position_m is None:
            first = next((s[0] for s in self._kept if s[1] == _UWB), None)
            return first is not None and t > first + 1.0  # the first second of ranges (replay's fix)
        # an IMU sample, and a radio sample: whether it is a range or a distance difference sets the range-
        # error model (swarm.logs.replay.is_tdoa), as the replay sets it from the log's files
        return any(s[1] == _IMU for s in self._kept) and any(s[1] in (_UWB, _TDOA) for s in self._kept)

    def _start(self) -> None:
        """Build the filter from the kept samples as the replay builds it from a log, then process them."""
        kept = [s for s in self._kept if s[1] == _IMU]  # vision is not used to build the filter
        rng = [s for s in self._kept if s[1] == _UWB]
        hgt = [s for s in self._kept if s[1] == _HEIGHT]
        bar = [s for s in self._kept if s[1] == _BARO]
        if not kept:
            return  # no IMU sample yet: keep waiting
        log = Log(
            Path("<live>"),
            self.config,
            np.array([s[0] for s in kept]),
            np.array([s[3][1] for s in kept]).reshape(-1, 3),
            np.array([s[3][2] for s in kept]).reshape(-1, 3),
            np.array([s[0] for s in rng]),
            np.array([s[3][0] for s in rng], dtype=np.int64),
            np.array([s[3][1] for s in rng]),
            self.anchor_ids,
            self.anchors_nav,
        )
        log.height_t, log.height_range = np.array([s[0] for s in hgt]), np.array([s[3] for s in hgt])
        log.baro_t, log.baro_height = np.array([s[0] for s in bar]), np.array([s[3] for s in bar])
        # a TDoA log's range-error model (replay.is_tdoa) when distance differences came before the start
        log.tdoa_t = np.array([s[0] for s in self._kept if s[1] == _TDOA])
        f, cal, self._correction = build_filter(log)
        self.f = f
        prm = self.config.estimator
        self.X, self.P = f.X[0], f.P[0]
        self.t = f.t
        self._held = False
        self._held_t = math.nan
        self._gyro, self._acc = np.zeros(3), np.zeros(3)
        self._ST = np.zeros(nb.N_ST, dtype=np.int64)
        self._win = _Window(prm.window)
        self._RS, self._RP, self._PH = robust_state(log, f, cal)
        self._AX = aux_streams(log, f, cal)[3]
        self.aux_counts = np.zeros((2, 3), dtype=np.int64)
        self.tdoa_counts = np.zeros((len(self.anchors_nav), len(self.anchors_nav), 3), dtype=np.int64)
        self._TV = tdoa_noise(len(self.anchors_nav), self.config.tdoa.sigma_m)
        """Height samples (rangefinder, barometer) accepted, rejected, refused."""
        self._limits = divergence_limits(prm.window, prm.divergence_alpha)
        m = len(self.anchors_nav)
        self._last_range, self._last_range_t = np.full(m, np.nan), np.full(m, -np.inf)
        self._work, self._res = np.empty((3, self.P.shape[0])), np.empty(4)
        self._d2 = math.nan
        faults = self.config.faults
        self._t_stop = faults.jump_at_s if faults.jump_at_s is not None else math.inf
        kept_all, self._kept = self._kept, []
        for s in kept_all:
            self._process(s)

    def _process(self, sample) -> None:
        """One sample: the body of :func:`swarm.core._imu_nb.replay`'s loop, kernel for kernel."""
        t, kind, _, data = sample
        if t > self._t_stop:  # the forced divergence of [faults], applied as the replay's pause applies it
            self._jump()
        if t < self.t:  # older than the filter: dropped, counted
            self.dropped += 1
            return
        X, P, prm = self.X, self.P, self.f.prm
        if kind == _VISION:  # swarm.logs.replay._Vision.update: predict only over a positive interval
            RP, PH, dt = self._RP, self._PH, t - self.t
            if self._held and dt > 0.0 and not nb.predict_step(X, P, self._gyro, self._acc, dt, prm, RP, PH):
                self.imu_refused += 1
            self.t = t
            m, xyz = data
            res = np.empty(2)
            marker, gate = self.markers_nav[m], self._vision_gate
            outcome = nb.update_pad_one(X, P, marker, self._cam, self._R_bc, xyz, self._vision_cov, gate, res)
            self.vision_counts[outcome] += 1
            return
        RP, PH = self._RP, self._PH
        if self._held and not nb.predict_step(X, P, self._gyro, self._acc, t - self.t, prm, RP, PH):
            self.imu_refused += 1
        self.t = t
        f = self.f
        if kind == _IMU:
            tick, g, a = data
            dt = t - self._held_t if self._held else 0.0
            self._gyro, self._acc, self._held, self._held_t = g, a, True, t
            ch = nb.phase_step(X, P, self._RP, self._PH, f.ridx, a, dt, t)
            if ch != 0:
                touch = ch < 0 and self._PH[nb.PH_TOUCH] > 0.0
                self.events.append(phase_event(float(t), 1 if ch > 0 else (-1 if touch else 0)))
            nb.pin_step(X, P, self._RP, self._PH, t, self._work)
            if tick % self.config.output_every == 0:
                self._estimate(t, tick)
            return
        if kind == _TDOA:
            a, b, z = data
            PH = self._PH
            pinned = PH[nb.PH_PINNED] > 0.0 and PH[nb.PH_TOUCH] > 0.0
            outcome = nb.fuse_tdoa(
                X, P, prm, self._RP, f.anchors, f.ridx, a, b, z, t, self._TV, self._RS, self._work, self._res,
                pinned,
            )  # fmt: skip
            self.tdoa_counts[a, b, outcome] += 1
            self._window(t)
            return
        if kind in (_HEIGHT, _BARO):
            aux = nb.AUX_HEIGHT if kind == _HEIGHT else nb.AUX_BARO
            outcome = nb.fuse_aux(X, P, self._AX, aux, data, self._res)
            self.aux_counts[aux, outcome] += 1
            return
        k, z = data
        z = z - self._correction[k]
        RS = self._RS
        outcome = nb.fuse_range(X, P, prm, self._RP, f.anchors[k], f.ridx, k, z, t, RS, self._work, self._res)
        f.counts[k, outcome] += 1
        if outcome == nb.REFUSED:
            return
        if self._PH[nb.PH_AIR] > 0.0:
            RS[k, nb.RS_AIR_VAR_SUM] += RS[k, nb.RS_VAR]
            RS[k, nb.RS_AIR_N] += 1.0
        self._d2 = float(self._res[1])
        self._last_range[k], self._last_range_t[k] = z, t
        self._window(t)

    def _window(self, t: float) -> None:
        """The last range or difference (in ``_res``) into the divergence window; a recovery when it
        declares the filter inconsistent (:func:`swarm.core._imu_nb.window_gated`, as the replay)."""
        w = self._win
        limit = self.config.estimator.reject_share_max
        if nb.window_gated(self._PH, self._res, w.rej, w.d2, w.w, w.all, self._ST, self._limits, limit):
            self.events.append(
                recover(self.f, self.config, t, w, self._last_range, self._last_range_t, self._RS)
            )
            w.clear(self._ST)

    def _jump(self) -> None:
        self.events.append(jump(self.X, self.P, self.config.faults, float(self.t)))
        self._t_stop = math.inf

    def _estimate(self, t: float, tick: int) -> None:
        c = self.f.counts
        fill = int(self._ST[nb.ST_WIN_FILL])
        self.estimates.append(
            OnlineEstimate(
                t,
                tick,
                self.X.copy(),
                self.P[0:9, 0:9].copy(),
                self._d2,
                float(self._win.rej.sum() / fill) if fill else 0.0,
                {
                    "range_accepted": int(c[:, nb.ACCEPTED].sum()),
                    "range_rejected": int(c[:, nb.REJECTED].sum()),
                    "range_refused": int(c[:, nb.REFUSED].sum()),
                },
            )
        )
