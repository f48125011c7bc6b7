"""Publish a recorded log on the swarm's keys as sensor drivers would (``swarm replay DIR --zenoh``).

One vehicle's sensors, in time order, paced at ``speed`` times real time: every ``imu.csv`` row as an
:class:`~swarm.transport.messages.Imu` (``tick`` = the row's index, ``t_s`` from the log's first IMU sample,
``dt_s`` the interval since the previous sample, ``acc_body`` the specific force) on
``<ns>/agent/<vehicle>/imu``; every ``uwb.csv`` row as a :class:`~swarm.transport.messages.Uwb` (``tick``
= the latest IMU sample's, the anchor's id from the file) on ``<ns>/agent/<vehicle>/uwb``; every
``vision.csv`` row as a ``Vision`` of kind ``features`` (target ``markers``, face ``+z``: one marker's
position in the camera frame, ``marker_ids`` = its id; the row's sigmas are not sent) on
``<ns>/agent/<vehicle>/vision``; every ``height.csv`` row as a ``Rangefinder`` (its sigma ``[height]
sigma_m``) on ``<ns>/agent/<vehicle>/rangefinder``; every ``baro.csv`` row as a ``Barometer`` (its sigma
``[baro] sigma_m``, sent whether or not ``[baro] enabled``: the receiver decides) on
``<ns>/agent/<vehicle>/barometer``; and the
anchors on ``<ns>/mothership/anchors``, published at the start and once a second, and answered to queries,
as the mothership does. Rows the reader skipped (a NaN sample) are not sent; a UWB row before the first
IMU sample is sent with tick 0. It starts once the IMU key has a subscriber (or after ``wait_s``), and then
gives the other streams' subscribers :data:`OTHERS_GRACE_S` to match, so that no first reading is lost.
:func:`messages` is the sequence, :func:`feed` paces and publishes it.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator

import numpy as np

from swarm.logs.reader import Log
from swarm.transport.keys import Keys
from swarm.transport.messages import Anchors, Barometer, Imu, Message, Rangefinder, Uwb, Vision, encode
from swarm.transport.process import declare_reliable

_LOG = logging.getLogger("swarm.replay")


_KINDS = ("imu", "uwb", "rangefinder", "barometer", "vision")
"""The streams of :func:`messages`, in the order samples of one time are sent (the replay's order: an IMU
sample, a range, a height, a barometric height, then a detection)."""


def messages(log: Log) -> Iterator[tuple[float, str, Message]]:
    """Every sample of ``log`` as the feed sends it, in time order (ties: :data:`_KINDS`' order):
    ``(t_s, kind, message)`` with ``t_s`` the log's own time [s] and ``kind`` one of :data:`_KINDS` (the
    key the message goes on)."""
    none = np.zeros(0)
    imu_t = log.imu_t
    t0 = float(imu_t[0])
    dt0 = float(np.median(np.diff(imu_t))) if len(imu_t) > 1 else 0.001
    streams = (
        imu_t,
        log.uwb_t,
        log.height_t if log.height_t is not None else none,
        log.baro_t if log.baro_t is not None else none,
        log.vision_t if log.vision_t is not None else none,
    )
    sigma_h, sigma_b = log.config.height.sigma_m, log.config.baro.sigma_m
    cursor = [0] * len(streams)
    inf = float("inf")
    while True:
        times = [ts[c] if c < len(ts) else inf for ts, c in zip(streams, cursor, strict=True)]
        kind = min(range(len(streams)), key=times.__getitem__)  # the first of the tied kinds
        t = float(times[kind])
        if t == inf:
            return
        row, tick, rel = cursor[kind], max(cursor[0] - 1, 0), max(t - t0, 0.0)
        cursor[kind] += 1
        if kind == 0:
            dt = float(imu_t[row] - imu_t[row - 1]) if row > 0 else dt0
            msg: Message = Imu(row, t - t0, dt, log.gyro[row], None, log.acc[row])
        elif kind == 1:
            msg = Uwb(tick, rel, int(log.anchor_ids[log.uwb_anchor[row]]), float(log.uwb_range[row]))
        elif kind == 2:
            msg = Rangefinder(tick, rel, float(log.height_range[row]), sigma_h)
        elif kind == 3:
            msg = Barometer(tick, rel, float(log.baro_height[row]), sigma_b)
        else:
            mid = (int(log.marker_ids[log.vision_marker[row]]),)
            msg = Vision(tick, rel, "markers", "+z", "features", log.vision_xyz[row][None], mid)
        yield t, _KINDS[kind], msg


OTHERS_GRACE_S = 1.0
"""Once the IMU key has a subscriber, how long [s of wall time] the feed waits for subscribers of the other
streams the log has before its first sample (a navigator declares them all at once; a consumer that reads
only some of them costs this once)."""


def _streams_with_rows(log: Log) -> tuple[str, ...]:
    rows = {"uwb": log.uwb_t, "rangefinder": log.height_t, "barometer": log.baro_t, "vision": log.vision_t}
    return tuple(k for k, t in rows.items() if t is not None and len(t))


def _wait_others(pubs: dict, kinds: tuple[str, ...], stop: threading.Event, grace_s: float) -> None:
    deadline = time.monotonic() + grace_s
    while time.monotonic() < deadline and not stop.is_set():
        if all(pubs[k].matching_status.matching for k in kinds):
            return
        time.sleep(0.01)
    missing = [k for k in kinds if not pubs[k].matching_status.matching]
    if missing:
        _LOG.info("no subscriber of %s after %.1f s more: publishing anyway", ", ".join(missing), grace_s)


def feed(log: Log, session, keys: Keys, vehicle: str, speed: float, stop: threading.Event,
         wait_s: float = 5.0) -> dict:  # fmt: skip
    """Publish ``log`` (module docstring); returns the counts sent per stream (``imu``, ``uwb``,
    ``vision``, ``height``, ``baro``) and the wall time. Waits up to ``wait_s`` for a subscriber of the IMU
    key before the first sample (then starts anyway)."""
    anchors = Anchors(tuple(int(i) for i in log.anchor_ids), log.anchors_nav)
    anchors_payload = encode(anchors)
    pubs = {kind: declare_reliable(session, getattr(keys, kind)(vehicle)) for kind in _KINDS}
    pub_imu = pubs["imu"]
    pub_anchors = declare_reliable(session, keys.anchors(), express=False)

    def on_query(query) -> None:
        try:
            query.reply(keys.anchors(), anchors_payload)
        except Exception as exc:  # a query must never kill the queryable's thread
            _LOG.warning("anchors query not answered: %s", exc)

    queryable = session.declare_queryable(keys.anchors(), on_query)
    sent = dict.fromkeys(_KINDS, 0)
    try:
        deadline = time.monotonic() + wait_s
        while not pub_imu.matching_status.matching and time.monotonic() < deadline and not stop.is_set():
            time.sleep(0.01)
        if not pub_imu.matching_status.matching:
            _LOG.warning("nobody subscribes to %s after %.1f s: publishing anyway", keys.imu(vehicle), wait_s)
        else:  # the IMU's subscriber may have declared its others a moment later: a short grace for them
            _wait_others(pubs, _streams_with_rows(log), stop, OTHERS_GRACE_S)
        pub_anchors.put(anchors_payload)
        t0 = float(log.imu_t[0])
        start = time.monotonic()
        last_anchors = start
        for t, kind, msg in messages(log):
            due = start + max(t - t0, 0.0) / speed
            while (now := time.monotonic()) < due and not stop.is_set():
                time.sleep(min(due - now, 0.1))
            if stop.is_set():
                break
            pubs[kind].put(encode(msg))
            sent[kind] += 1
            if now - last_anchors >= 1.0:
                pub_anchors.put(anchors_payload)
                last_anchors = now
        wall = time.monotonic() - start
        time.sleep(0.2)  # let the last samples leave before the session closes
    finally:
        queryable.undeclare()
    return {
        "imu": sent["imu"], "uwb": sent["uwb"], "vision": sent["vision"], "height": sent["rangefinder"],
        "baro": sent["barometer"], "wall_s": wall, "log_s": float(log.imu_t[-1] - t0),
    }  # fmt: skip
