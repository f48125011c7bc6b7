"""``swarm navigate LOG.toml --id ID``: the IMU-driven filter of the log replay as a swarm process, on live
or replayed sensors (``swarm replay DIR --zenoh``, a vehicle's drivers).

It asks for the anchors (``<ns>/mothership/anchors``, a query, as an agent would ask the mothership), then
subscribes ``<ns>/agent/<ID>/imu`` (an :class:`~swarm.transport.messages.Imu` with ``acc_body``: the
specific force drives the filter), ``<ns>/agent/<ID>/uwb``, ``<ns>/agent/<ID>/rangefinder`` and
``<ns>/agent/<ID>/barometer`` (fused as ``height.csv`` and ``baro.csv`` are, with ``[height]`` and
``[baro]`` of log.toml: the barometer only with ``baro.enabled = true``) and ``<ns>/agent/<ID>/vision``
(``features``: a surveyed marker's position in the camera frame, fused with ``[vision]`` of log.toml and
the ``markers.csv`` beside it), runs :class:`swarm.logs.online.OnlineNavigator`
(the replay's filter, calibration, divergence test and recovery, behind a reorder horizon of ``--delay``
seconds of sensor time) and publishes an :class:`~swarm.transport.messages.Estimate` on
``<ns>/agent/<ID>/estimate`` for every ``output_every``-th IMU sample and an ``estimator_reset`` (or forced
``fault``) :class:`~swarm.transport.messages.Event` on ``<ns>/agent/<ID>/event``. A message that does not
decode is dropped and counted; an IMU message without ``acc_body`` cannot drive this filter and is counted
too. It prints ``navigator <ID> ready`` once subscribed, and stops on SIGINT or SIGTERM, or ``--until-idle``
seconds after the last sample; then it processes what its horizon still holds, writes ``--series``, and
prints one summary line.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from pathlib import Path

import numpy as np

from swarm.args import positive_float

_LOG = logging.getLogger("swarm.navigate")
SERIES_COLUMNS = (
    "t_s, tick, x_m, y_m, z_m, vx_m_s, vy_m_s, vz_m_s, qx, qy, qz, qw, sigma_x_m, sigma_y_m, sigma_z_m"
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    from swarm.transport.session import add_zenoh_arguments

    p = sub.add_parser(
        "navigate",
        help="the log replay's IMU-driven filter as a process on live or replayed sensors",
        description=__doc__.split("\n\n")[0],
    )
    p.add_argument("config", type=Path, metavar="LOG.toml", help="the filter's settings (docs/logs.md)")
    p.add_argument("--id", required=True, help="the vehicle whose sensors it fuses")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a log.toml key (repeatable)")  # fmt: skip
    p.add_argument("--namespace", default="tpods", help="key namespace of the swarm (default tpods)")
    p.add_argument("--delay", type=_delay, default=0.05, metavar="S",
                   help="reorder horizon [s of sensor time]: samples are fused this far behind the newest "
                   "(default 0.05)")  # fmt: skip
    p.add_argument("--wait", type=positive_float("--wait"), default=10.0, metavar="S",
                   help="how long to ask for the anchors before giving up (default 10)")  # fmt: skip
    p.add_argument("--until-idle", type=positive_float("--until-idle"), default=None, metavar="S",
                   help="stop this many seconds of wall time after the last sample")  # fmt: skip
    p.add_argument("--series", type=Path, default=None, metavar="FILE.csv",
                   help="write the estimate series at the end (full precision)")  # fmt: skip
    add_zenoh_arguments(p)
    p.set_defaults(func=run)


def _delay(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--delay: not a number: {text!r}") from None
    if not (np.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"--delay: must be a finite number >= 0, got {text!r}")
    return v


def _anchors(session, keys, wait_s: float, stop: threading.Event):
    from swarm.errors import ConfigError
    from swarm.transport.messages import Anchors, MessageError, decode

    deadline = time.monotonic() + wait_s
    while not stop.is_set():
        for reply in session.get(keys.anchors(), timeout=1.0):
            if reply.ok is None:
                continue
            try:
                return decode(reply.ok.payload.to_bytes(), Anchors)
            except MessageError as exc:
                _LOG.warning("bad anchors reply dropped: %s", exc)
        if time.monotonic() >= deadline:
            break
        time.sleep(0.1)
    raise ConfigError(f"no answer to the anchors query on {keys.anchors()} within {wait_s:g} s")


def run(args: argparse.Namespace, stop: threading.Event | None = None) -> int:
    import signal

    from swarm.config import load_toml, parse_override
    from swarm.logs.online import OnlineNavigator
    from swarm.logs.reader import LogConfig
    from swarm.transport.keys import Keys, check_id
    from swarm.transport.messages import Barometer, DropCounter, Event, Imu, Rangefinder, Uwb, Vision, encode
    from swarm.transport.process import declare_reliable
    from swarm.transport.session import open_session, subscribe_decoded, zenoh_args_from

    check_id(args.id, "--id")
    overrides = dict(parse_override(o) for o in args.overrides)
    config = load_toml(LogConfig, args.config, overrides)
    keys = Keys(args.namespace)
    if stop is None:
        stop = threading.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    drops = DropCounter()
    with open_session(zenoh_args_from(args)) as session:
        anchors = _anchors(session, keys, args.wait, stop)
        marker_ids, markers_nav = (), None
        markers = args.config.parent / "markers.csv"
        if markers.is_file():  # the surveyed markers of vision.csv, beside the log's log.toml
            from swarm.logs.reader import read_markers

            marker_ids, markers_nav = read_markers(markers)
        nav = OnlineNavigator(
            config, anchors.anchor_ids, anchors.positions_nav, args.delay, marker_ids, markers_nav
        )
        last = [time.monotonic(), 0]  # wall time of the last sample, samples seen
        no_acc = [0]

        def on_imu(_key: str, m: Imu) -> None:
            last[0], last[1] = time.monotonic(), last[1] + 1
            if m.acc_body is None:
                no_acc[0] += 1
                return
            nav.imu(m.t_s, m.tick, m.gyro_body, m.acc_body)

        def on_uwb(_key: str, m: Uwb) -> None:
            last[0], last[1] = time.monotonic(), last[1] + 1
            if m.range_m is not None:
                nav.uwb(m.t_s, m.anchor_id, m.range_m)

        def on_rangefinder(_key: str, m: Rangefinder) -> None:
            last[0], last[1] = time.monotonic(), last[1] + 1
            if m.range_m is not None:
                nav.height(m.t_s, m.range_m)

        def on_barometer(_key: str, m: Barometer) -> None:
            last[0], last[1] = time.monotonic(), last[1] + 1
            if m.height_m is not None:
                nav.baro(m.t_s, m.height_m)

        def on_vision(key: str, m: Vision) -> None:
            last[0], last[1] = time.monotonic(), last[1] + 1
            if m.kind != "features":
                drops.drop(
                    key,
                    f"kind: a marker detection is 'features' (a position in the camera frame), got {m.kind}",
                )
                return
            for mid, xyz in zip(m.marker_ids, m.data, strict=True):
                nav.vision(m.t_s, mid, xyz)

        pub_est = declare_reliable(session, keys.estimate(args.id))
        pub_ev = declare_reliable(session, keys.event(args.id), express=False)
        subscribe_decoded(session, keys.uwb(args.id), Uwb, on_uwb, drops)
        subscribe_decoded(session, keys.vision(args.id), Vision, on_vision, drops)
        subscribe_decoded(session, keys.rangefinder(args.id), Rangefinder, on_rangefinder, drops)
        subscribe_decoded(session, keys.barometer(args.id), Barometer, on_barometer, drops)
        # the IMU last: a feed that starts once its IMU subscriber matches (swarm replay --zenoh) then finds
        # the others declared too (declarations travel in order on a link), and its first range finder and
        # barometer readings, at the first IMU sample's time, are not lost
        subscribe_decoded(session, keys.imu(args.id), Imu, on_imu, drops)
        print(f"navigator {args.id} ready", flush=True)

        def publish(final: bool = False) -> None:
            estimates, events = nav.drain(final)
            for e in estimates:
                pub_est.put(encode(_estimate(e)))
            for ev in events:
                data = {k: v for k, v in ev.items() if k not in ("t_s", "kind")}
                pub_ev.put(encode(Event(ev["t_s"], ev["kind"], data)))
                level = logging.INFO if ev["kind"] in ("takeoff", "landing") else logging.WARNING
                why = ev.get("reason", ev.get("fault", ""))
                _LOG.log(level, "%s at %.2f s: %s", ev["kind"], ev["t_s"], why)

        while not stop.wait(0.01):
            publish()
            if args.until_idle is not None and last[1] and time.monotonic() - last[0] > args.until_idle:
                break
        publish(final=True)
        time.sleep(0.1)  # let the last estimates leave before the session closes
    if args.series is not None:
        _write_series(args.series, nav.estimates)
    c = nav.f.counts if nav.f is not None else np.zeros((0, 3), dtype=np.int64)
    aux = nav.aux_counts if nav.f is not None else np.zeros((2, 3), dtype=np.int64)  # [sensor, outcome]
    print(
        f"navigator {args.id}: {len(nav.estimates)} estimates, ranges accepted {int(c[:, 0].sum())} "
        f"rejected {int(c[:, 1].sum())}, dropped (older than the filter) {nav.dropped}, unknown anchor "
        f"{nav.unknown_anchor}, vision accepted {int(nav.vision_counts[0])} rejected "
        f"{int(nav.vision_counts[1])}, unknown marker {nav.unknown_marker}, rangefinder accepted "
        f"{int(aux[0, 0])} rejected {int(aux[0, 1])}, barometer accepted {int(aux[1, 0])} rejected "
        f"{int(aux[1, 1])}, "
        f"IMU without acc_body {no_acc[0]}, undecodable {drops.total}, events "
        f"{len(nav.events)}",
        flush=True,
    )
    return 0


def _estimate(e):
    from swarm.core import _imu_nb as nb
    from swarm.transport.messages import Estimate

    X, P = e.X, e.P9
    P = 0.5 * (P + P.T)
    return Estimate(
        e.tick,
        e.t_s,
        X[nb.XP : nb.XP + 3],
        X[nb.XV : nb.XV + 3],
        X[nb.XQ : nb.XQ + 4],
        P,
        float(np.sqrt(np.max(np.diag(P)[0:3]))),
        float(np.sqrt(e.d2)) if np.isfinite(e.d2) else 0.0,
        e.reject_share,
        e.counts,
    )


def _write_series(path: Path, estimates) -> None:
    rows = np.array([[e.t_s, e.tick, *e.X[0:10], *np.sqrt(np.diag(e.P9)[0:3])] for e in estimates]).reshape(
        -1, 15
    )
    np.savetxt(path, rows, delimiter=",", header=SERIES_COLUMNS.replace(" ", ""), comments="", fmt="%.17g")
