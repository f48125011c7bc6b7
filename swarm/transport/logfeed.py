"""Publish a recorded log on the swarm's keys as sensor drivers would (``swarm replay DIR --zenoh``).

One vehicle's sensors, in time order, paced at ``speed`` times real time: every ``imu.csv`` row as an
:class:`~swarm.transport.messages.Imu` (``tick`` = the row's index, ``t_s`` from the log's first IMU sample,
``dt_s`` the interval since the previous sample, ``acc_body`` the specific force) on
``<ns>/agent/<vehicle>/imu``; every ``uwb.csv`` row as a :class:`~swarm.transport.messages.Uwb` (``tick``
= the latest IMU sample's, the anchor's id from the file) on ``<ns>/agent/<vehicle>/uwb``; every
``vision.csv`` row as a ``Vision`` of kind ``features`` (target ``markers``, face ``+z``: one marker's
position in the camera frame, ``marker_ids`` = its id; the row's sigmas are not sent) on
``<ns>/agent/<vehicle>/vision``; every ``height.csv`` row as a ``Rangefinder`` (its sigma ``[height]
sigma_m``) on ``<ns>/agent/<vehicle>/rangefinder``; and the
anchors on ``<ns>/mothership/anchors``, published at the start and once a second, and answered to queries,
as the mothership does. Rows the reader skipped (a NaN sample) are not sent; a UWB row before the first
IMU sample is sent with tick 0.
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np

from swarm.logs.reader import Log
from swarm.transport.keys import Keys
from swarm.transport.messages import Anchors, Imu, Rangefinder, Uwb, Vision, encode
from swarm.transport.process import declare_reliable

_LOG = logging.getLogger("swarm.replay")


def feed(log: Log, session, keys: Keys, vehicle: str, speed: float, stop: threading.Event,
         wait_s: float = 5.0) -> dict:  # fmt: skip
    """Publish ``log`` (module docstring); returns the counts sent and the wall time. Waits up to ``wait_s``
    for a subscriber of the IMU key before the first sample (then starts anyway)."""
    anchors = Anchors(tuple(int(i) for i in log.anchor_ids), log.anchors_nav)
    anchors_payload = encode(anchors)
    pub_imu = declare_reliable(session, keys.imu(vehicle))
    pub_uwb = declare_reliable(session, keys.uwb(vehicle))
    pub_vis = declare_reliable(session, keys.vision(vehicle))
    pub_rf = declare_reliable(session, keys.rangefinder(vehicle))
    pub_anchors = declare_reliable(session, keys.anchors(), express=False)

    def on_query(query) -> None:
        try:
            query.reply(keys.anchors(), anchors_payload)
        except Exception as exc:  # a query must never kill the queryable's thread
            _LOG.warning("anchors query not answered: %s", exc)

    queryable = session.declare_queryable(keys.anchors(), on_query)
    try:
        deadline = time.monotonic() + wait_s
        while not pub_imu.matching_status.matching and time.monotonic() < deadline and not stop.is_set():
            time.sleep(0.01)
        if not pub_imu.matching_status.matching:
            _LOG.warning("nobody subscribes to %s after %.1f s: publishing anyway", keys.imu(vehicle), wait_s)
        pub_anchors.put(anchors_payload)
        t0 = float(log.imu_t[0])
        dt0 = float(np.median(np.diff(log.imu_t))) if len(log.imu_t) > 1 else 0.001
        start = time.monotonic()
        last_anchors = start
        i = j = v = h = 0
        n_imu, n_uwb = len(log.imu_t), len(log.uwb_t)
        vis_t = log.vision_t if log.vision_t is not None else np.zeros(0)
        n_vis = len(vis_t)
        h_t = log.height_t if getattr(log, "height_t", None) is not None else np.zeros(0)
        n_h = len(h_t)
        sigma_h = log.config.height.sigma_m
        inf = float("inf")
        while (i < n_imu or j < n_uwb or v < n_vis or h < n_h) and not stop.is_set():
            # the next sample; at one time an IMU sample, a range, a height, then a detection (the replay's
            # order)
            ti = log.imu_t[i] if i < n_imu else inf
            tj = log.uwb_t[j] if j < n_uwb else inf
            th = h_t[h] if h < n_h else inf
            tv = vis_t[v] if v < n_vis else inf
            times = (ti, tj, tv, th)
            kind = min((0, 1, 3, 2), key=lambda k: times[k])  # ties: the first of IMU, range, height, vision
            t = float(times[kind])
            due = start + max(t - t0, 0.0) / speed
            now = time.monotonic()
            if due > now:
                time.sleep(min(due - now, 0.1))
                continue
            if kind == 0:
                dt = float(log.imu_t[i] - log.imu_t[i - 1]) if i > 0 else dt0
                pub_imu.put(encode(Imu(i, t - t0, dt, log.gyro[i], None, log.acc[i])))
                i += 1
            elif kind == 1:
                tick = max(i - 1, 0)
                aid = int(log.anchor_ids[log.uwb_anchor[j]])
                pub_uwb.put(encode(Uwb(tick, max(t - t0, 0.0), aid, float(log.uwb_range[j]))))
                j += 1
            elif kind == 3:
                pub_rf.put(
                    encode(Rangefinder(max(i - 1, 0), max(t - t0, 0.0), float(log.height_range[h]), sigma_h))
                )
                h += 1
            else:
                mid = (int(log.marker_ids[log.vision_marker[v]]),)
                vis = Vision(
                    max(i - 1, 0), max(t - t0, 0.0), "markers", "+z", "features", log.vision_xyz[v][None], mid
                )
                pub_vis.put(encode(vis))
                v += 1
            if now - last_anchors >= 1.0:
                pub_anchors.put(anchors_payload)
                last_anchors = now
        wall = time.monotonic() - start
        time.sleep(0.2)  # let the last samples leave before the session closes
    finally:
        queryable.undeclare()
    return {"imu": i, "uwb": j, "vision": v, "height": h, "wall_s": wall, "log_s": float(log.imu_t[-1] - t0)}
