"""PX4's ULog (``swarm import ulog``): a flight log into a log folder (``docs/logs.md``), read with pyulog.

Topics: ``sensor_combined`` (``gyro_rad``, ``accelerometer_m_s2``; the accelerometer's time is ``timestamp
+ accelerometer_timestamp_relative``, interpolated to the gyroscope's as for every importer) becomes
``imu.csv``; ``distance_sensor`` facing down (``orientation`` 25, ROTATION_DOWNWARD_FACING) ``height.csv``
(``current_distance`` outside ``[min_distance, max_distance]`` or ``signal_quality`` 0: no return, written
empty); ``vehicle_air_data`` (``baro_alt_meter``) ``baro.csv``; the topic of ``--truth-topic`` ``truth.csv``;
the topic of ``--uwb-topic`` ``uwb.csv``. Times: ``timestamp_sample`` where the topic has it, else
``timestamp`` (microseconds since boot) -> seconds.

Frames. PX4 is NED (north, east, down) and its body FRD (forward, right, down); our logs are z-up: the
navigation frame ENU (east, north, up) and the body FLU (forward, left, up), as ROS REP 103 and mavros's
``frame_tf`` convert them. Body vectors (rates, specific force): ``v_flu = diag(1, -1, -1) v_frd`` (a half
turn about forward). Positions: ``p_enu = T p_ned``, ``T = [[0, 1, 0], [1, 0, 0], [0, 0, -1]]`` (a half turn
about the north-east bisector, det +1). Attitude body -> nav: ``R_enu_flu = T R_ned_frd diag(1, -1, -1)``.
The accelerometer's specific force is about ``-9.81`` on FRD z at rest, so ``+9.81`` on FLU z, as
``imu.csv`` wants.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from swarm.errors import LogError
from swarm.logs.importing import Imported, LogFolder, pair_imu, read_anchor_file, time_order

FRD_TO_FLU = np.diag([1.0, -1.0, -1.0])
"""Body vectors FRD -> FLU (a half turn about the forward axis)."""
NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
"""Navigation vectors NED -> ENU (x east = NED y, y north = NED x, z up = -NED z)."""
DOWNWARD = 25
"""``distance_sensor.orientation`` of a downward range finder (PX4's ROTATION_DOWNWARD_FACING)."""
RELATIVE_INVALID = 2**31 - 1
"""``accelerometer_timestamp_relative`` of a ``sensor_combined`` without an accelerometer sample."""
TRUTH_TOPICS = (
    "vehicle_local_position",
    "vehicle_odometry",
    "vehicle_visual_odometry",
    "vehicle_mocap_odometry",
)


def ned_frd_to_enu_flu(p_ned: np.ndarray, q_ned_frd_wxyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (n, 3) and attitude (n, 4, PX4's ``w, x, y, z``, body FRD -> NED) as ENU position and the
    scalar-last quaternion body FLU -> ENU (module docstring)."""
    p = np.asarray(p_ned, float) @ NED_TO_ENU.T
    q = np.asarray(q_ned_frd_wxyz, float)
    r = (
        Rotation.from_matrix(NED_TO_ENU)
        * Rotation.from_quat(q[:, [1, 2, 3, 0]])
        * Rotation.from_matrix(FRD_TO_FLU)
    )
    return p, r.as_quat()


def _topics(ulog, name: str) -> list:
    return sorted((d for d in ulog.data_list if d.name == name), key=lambda d: d.multi_id)


def _vec(data: dict, base: str, n: int = 3) -> np.ndarray:
    return np.stack([np.asarray(data[f"{base}[{i}]"], float) for i in range(n)], axis=1)


def _time(data: dict) -> np.ndarray:
    t = data["timestamp_sample"] if "timestamp_sample" in data else data["timestamp"]
    return np.asarray(t, np.float64) * 1e-6


def _field(topic, name: str, fname: str) -> np.ndarray:
    if name not in topic.data:
        raise LogError(f"{fname}: topic {topic.name} has no field {name!r} (it has {', '.join(topic.data)})")
    return np.asarray(topic.data[name], float)


def _truth(ulog, topic: str, fname: str, rep: Imported):
    """Times, ENU positions and FLU -> ENU quaternions of the truth topic."""
    found = _topics(ulog, topic)
    if not found:
        raise LogError(f"{fname}: no topic {topic!r} for --truth-topic (the log has {_names(ulog)})")
    d = found[0].data
    t = _time(d)
    if "position[0]" in d:
        p = _vec(d, "position")
    else:
        p = np.stack([_field(found[0], k, fname) for k in "xyz"], axis=1)
    if "q[0]" in d:
        q = _vec(d, "q", 4)
    else:  # vehicle_local_position has no attitude: vehicle_attitude's nearest sample
        att = _topics(ulog, "vehicle_attitude")
        if not att:
            raise LogError(f"{fname}: {topic} has no attitude and the log has no vehicle_attitude topic")
        ta, qa = _time(att[0].data), _vec(att[0].data, "q", 4)
        k = np.clip(np.searchsorted(ta, t), 1, len(ta) - 1)
        k -= (t - ta[k - 1]) < (ta[k] - t)
        q = qa[k]
        rep.notes.append(f"truth.csv: {topic}'s position with vehicle_attitude's nearest attitude")
    ok = np.isfinite(p).all(axis=1) & np.isfinite(q).all(axis=1)
    for flag in ("xy_valid", "z_valid"):
        if flag in d:
            ok &= np.asarray(d[flag]) != 0
    p_enu, q_enu = ned_frd_to_enu_flu(p[ok], q[ok])
    o, dup = time_order(t[ok], strict=True)
    rep.notes.append(
        f"truth.csv: {topic} NED/FRD -> ENU/FLU; {int((~ok).sum())} invalid samples and {dup} repeated "
        "times dropped"
    )
    return t[ok][o], p_enu[o], q_enu[o]


def _names(ulog) -> str:
    return ", ".join(sorted({d.name for d in ulog.data_list})) or "none"


def import_ulog(
    path: str | Path,
    out: str | Path,
    *,
    truth_topic: str | None = None,
    uwb_topic: str | None = None,
    uwb_id_field: str = "mac_dest",
    uwb_range_field: str = "distance",
    anchors: str | Path | None = None,
    force: bool = False,
) -> Imported:
    """Import the ULog ``path`` into the log folder ``out`` (module docstring). ``uwb_topic``: the topic of
    two-way ranges, its anchor id in ``uwb_id_field`` and range [m] in ``uwb_range_field`` (PX4's
    ``sensor_uwb``: ``mac_dest``, the responder, and ``distance``); without it ``uwb.csv`` has no rows and
    ``anchors`` is optional (``anchors.csv`` then has none either)."""
    from pyulog import ULog
    from pyulog.core import ULogException

    src = Path(path)
    if not src.is_file():
        raise LogError(f"{src}: no such file")
    try:
        ulog = ULog(str(src))
    except ULogException as exc:
        raise LogError(f"{src.name}: not a ULog: {exc}") from None
    except (OSError, ValueError, IndexError) as exc:
        raise LogError(f"{src.name}: cannot read the ULog: {exc}") from None
    rep = Imported(Path(out), f"source: {src.name} (PX4 ULog)")
    rep.notes.append(
        "topics: " + ", ".join(f"{d.name}[{d.multi_id}] {len(d.data['timestamp'])}" for d in ulog.data_list)
    )
    if ulog.file_corruption:
        rep.warn(
            f"{src.name}: pyulog found corrupt data and skipped it (the messages it could read are kept)"
        )
    sc = _topics(ulog, "sensor_combined")
    if not sc:
        raise LogError(f"{src.name}: no sensor_combined topic: imu.csv needs it (the log has {_names(ulog)})")
    d = sc[0].data
    tg = np.asarray(d["timestamp"], np.float64) * 1e-6
    rel = np.asarray(d.get("accelerometer_timestamp_relative", np.zeros(len(tg))), np.int64)
    has_acc = rel != RELATIVE_INVALID
    ta = tg[has_acc] + rel[has_acc] * 1e-6
    gyro = _vec(d, "gyro_rad") @ FRD_TO_FLU.T
    acc = _vec(d, "accelerometer_m_s2")[has_acc] @ FRD_TO_FLU.T
    if uwb_topic is not None and anchors is None:
        raise LogError(f"{src.name}: --uwb-topic {uwb_topic} gives ranges: give the anchors file (--anchors)")
    folder = LogFolder(out, force, rep)
    t, g, a, dropped = pair_imu(tg, gyro, ta, acc)
    folder.write_imu(t, g, a)
    rep.notes.append(
        f"imu.csv: sensor_combined FRD -> FLU; rows at the gyroscope's times, accelerometer interpolated; "
        f"{dropped} dropped"
    )
    ids, xyz = (np.empty(0, np.int64), np.empty((0, 3))) if anchors is None else read_anchor_file(anchors)
    folder.write_anchors(ids, xyz)
    if uwb_topic is not None:
        u = _topics(ulog, uwb_topic)
        if not u:
            raise LogError(f"{src.name}: no topic {uwb_topic!r} for --uwb-topic (the log has {_names(ulog)})")
        tu = _time(u[0].data)
        aid, rng = _field(u[0], uwb_id_field, src.name), _field(u[0], uwb_range_field, src.name)
        unknown = np.flatnonzero(~np.isin(aid, ids))
        if len(unknown):
            k = int(unknown[0])
            raise LogError(
                f"{src.name}: {uwb_topic} message {k} names anchor {aid[k]:g}, not in {Path(anchors).name} "
                f"(it has {', '.join(str(int(i)) for i in ids)})"
            )
        o, _ = time_order(tu, strict=False)
        folder.write_uwb(tu[o], aid[o], np.where(rng[o] >= 0, rng[o], np.nan))
    else:
        folder.write_uwb(np.empty(0), np.empty(0), np.empty(0))
        rep.notes.append("uwb.csv: no --uwb-topic, no ranges")
    down = []
    for ds in _topics(ulog, "distance_sensor"):
        m = np.asarray(ds.data.get("orientation", np.full(len(ds.data["timestamp"]), DOWNWARD))) == DOWNWARD
        if m.any():
            down.append((ds, m))
    if down:
        ds, m = down[0]
        th = _time(ds.data)[m]
        r = _field(ds, "current_distance", src.name)[m]
        lo = ds.data.get("min_distance")
        hi = ds.data.get("max_distance")
        none = ~np.isfinite(r) | (r < 0)
        if lo is not None and hi is not None:
            none |= (r < np.asarray(lo, float)[m]) | (r > np.asarray(hi, float)[m])
        if "signal_quality" in ds.data:
            none |= np.asarray(ds.data["signal_quality"])[m] == 0
        o, dup = time_order(th, strict=True)
        folder.write_height(th[o], np.where(none, np.nan, r)[o])
        rep.notes.append(
            f"height.csv: distance_sensor[{ds.multi_id}] facing down; {int(none.sum())} without a return "
            f"written empty; {dup} repeated times dropped"
            + (f"; {len(down) - 1} other downward sensors ignored" if len(down) > 1 else "")
        )
    air = _topics(ulog, "vehicle_air_data")
    if air:
        tb, hb = _time(air[0].data), _field(air[0], "baro_alt_meter", src.name)
        o, dup = time_order(tb, strict=True)
        folder.write_baro(tb[o], hb[o])
        rep.notes.append(f"baro.csv: vehicle_air_data.baro_alt_meter; {dup} repeated times dropped")
    if truth_topic is not None:
        folder.write_truth(*_truth(ulog, truth_topic, src.name, rep))
    return folder.finish(src.stem)
