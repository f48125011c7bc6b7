"""A log's samples fed to the live navigator (:class:`swarm.logs.online.OnlineNavigator`) as a feed would
send them, for the tests that compare it with the replay (``test_online``, ``test_tdoa_flight``)."""

from __future__ import annotations

RANK = {"imu": 0, "uwb": 1, "tdoa": 2, "height": 2, "vision": 2}
"""At one time: the IMU sample, then the range, then the rest (the replay's order)."""


def _imu(log):
    return [(float(t), "imu", (float(t), i, log.gyro[i], log.acc[i])) for i, t in enumerate(log.imu_t)]


def _uwb(log):
    rows = zip(log.uwb_t, log.uwb_anchor, log.uwb_range, strict=True)
    return [(float(t), "uwb", (float(t), int(log.anchor_ids[a]), float(z))) for t, a, z in rows]


def _tdoa(log):
    ids = log.anchor_ids
    rows = zip(log.tdoa_t, log.tdoa_a, log.tdoa_b, log.tdoa_ddist, strict=True)
    return [(float(t), "tdoa", (float(t), int(ids[a]), int(ids[b]), float(z))) for t, a, b, z in rows]


def _height(log):
    return [
        (float(t), "height", (float(t), float(z)))
        for t, z in zip(log.height_t, log.height_range, strict=True)
    ]


def _vision(log):
    rows = zip(log.vision_t, log.vision_marker, log.vision_xyz, strict=True)
    return [(float(t), "vision", (float(t), int(log.marker_ids[m]), xyz)) for t, m, xyz in rows]


STREAMS = {"imu": _imu, "uwb": _uwb, "tdoa": _tdoa, "height": _height, "vision": _vision}


def in_time_order(log, *streams: str) -> list[tuple]:
    """The samples of the named streams as ``(t_s, stream, args)``, in time order (then :data:`RANK`)."""
    out = [s for name in streams for s in STREAMS[name](log)]
    out.sort(key=lambda s: (s[0], RANK[s[1]]))
    return out


def feed(nav, order, drain_every: int = 97):
    """Each sample of ``order`` to the navigator's method of its stream, draining every ``drain_every``
    samples and at the end (an uneven count, so that drains fall at all phases of the streams)."""
    for n, (_, stream, args) in enumerate(order):
        getattr(nav, stream)(*args)
        if n % drain_every == 0:
            nav.drain()
    nav.drain(final=True)
    return nav
