"""ROS bags (``swarm import rosbag``): a ROS 1 ``.bag``, a ROS 2 bag folder (sqlite3 ``.db3`` or MCAP) or a
bare ``.mcap`` into a log folder (``docs/logs.md``), read with the ``rosbags`` library (the ``import`` extra).

ROS frames are already ours: REP 103 puts a body in FLU (x forward, y left, z up) and a world frame in ENU,
z up, and REP 145 makes ``sensor_msgs/Imu.linear_acceleration`` the specific force (``+9.81`` up at rest).
So nothing is rotated; the importer picks the topics:

- ``--imu-topic`` (``sensor_msgs/Imu``): ``angular_velocity`` and ``linear_acceleration`` -> ``imu.csv``;
  a message whose covariance says the field is absent (``[0] == -1``, REP 145) is dropped.
- ``--range-topic`` (``sensor_msgs/Range``, a downward range finder) -> ``height.csv``; ``range`` outside
  ``[min_range, max_range]`` or not finite (REP 117: ``+-inf`` = no detection) is no return, written empty.
- ``--height-topic`` (barometric height) -> ``baro.csv``: ``sensor_msgs/FluidPressure`` converted with the
  ISA (:func:`isa_altitude_m`), ``geometry_msgs/PointStamped`` (``point.z``), ``std_msgs/Float32|64``.
- ``--pose-topic`` (``geometry_msgs/PoseStamped``, ``PoseWithCovarianceStamped`` or ``nav_msgs/Odometry``)
  -> ``truth.csv``.
- ``--uwb-topic`` -> ``uwb.csv``: ROS has no standard UWB message, so the anchor id and the range are
  fields named by ``--uwb-id-field`` (default ``header.frame_id``, its trailing integer: ``anchor3`` -> 3)
  and ``--uwb-range-field`` (default ``range``): a ``sensor_msgs/Range`` per anchor works as it is.

Times: the message's ``header.stamp`` (the bag's receive time for a message without a header or with a
zero stamp), in seconds from the whole second before the earliest one (log.toml says which).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from swarm.errors import LogError
from swarm.logs.importing import Imported, LogFolder, read_anchor_file, time_order

ISA_P0_PA = 101325.0
"""Sea-level standard pressure [Pa] (ISA, ICAO Doc 7488)."""
ISA_T0_K = 288.15
ISA_LAPSE_K_M = 0.0065
ISA_EXPONENT = 0.190263
"""``R L / (g M)`` of the troposphere's barometric formula (ISA: R = 8.31432, g = 9.80665, M = 0.0289644)."""

_TRAILING_INT = re.compile(r"(\d+)\s*$")


def isa_altitude_m(pressure_pa: np.ndarray) -> np.ndarray:
    """Pressure altitude [m] of the International Standard Atmosphere's troposphere: ``h = (T0 / L) (1 -
    (P / P0)^(R L / (g M)))`` (ICAO Doc 7488; the barometric formula of any avionics text)."""
    return ISA_T0_K / ISA_LAPSE_K_M * (1.0 - (np.asarray(pressure_pa, float) / ISA_P0_PA) ** ISA_EXPONENT)


def _get(msg, path: str):
    for part in path.split("."):
        msg = getattr(msg, part)
    return msg


def _stamp_ns(msg, bag_ns: int) -> int:
    h = getattr(msg, "header", None)
    if h is None:
        return bag_ns
    ns = int(h.stamp.sec) * 1_000_000_000 + int(h.stamp.nanosec)
    return ns if ns > 0 else bag_ns


def _open(path: Path):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    return AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))


def _read(path: Path, topics: dict[str, str]) -> dict[str, list]:
    """``(stamp_ns, msg)`` per role of ``topics`` (role -> topic name), in bag order."""
    try:
        from rosbags.highlevel import AnyReaderError
    except ImportError:
        raise LogError(
            "swarm import rosbag needs the rosbags library: pip install 'tpods-swarm[import]' (or rosbags)"
        ) from None
    out: dict[str, list] = {role: [] for role in topics}
    try:
        with _open(path) as reader:
            have = {c.topic: c for c in reader.connections}
            for role, topic in topics.items():
                if topic not in have:
                    raise LogError(
                        f"{path.name}: no topic {topic!r} for --{role}-topic (the bag has "
                        f"{', '.join(f'{t} ({c.msgtype})' for t, c in sorted(have.items())) or 'none'})"
                    )
            role_of: dict[str, list[str]] = {}
            for role, topic in topics.items():
                role_of.setdefault(topic, []).append(role)
            cons = [c for c in reader.connections if c.topic in role_of]
            for k, (con, bag_ns, raw) in enumerate(reader.messages(connections=cons)):
                try:
                    msg = reader.deserialize(raw, con.msgtype)
                except (ValueError, IndexError, KeyError) as exc:  # a damaged message
                    raise LogError(
                        f"{path.name}: message {k} on {con.topic} cannot be decoded: {exc}"
                    ) from None
                for role in role_of[con.topic]:
                    out[role].append((_stamp_ns(msg, bag_ns), con.msgtype, msg))
    except AnyReaderError as exc:
        raise LogError(f"{path.name}: not a readable ROS bag: {exc}") from None
    except OSError as exc:
        raise LogError(f"{path}: cannot read: {exc.strerror or exc}") from None
    return out


def _types(name: str, rows: list, allowed: tuple[str, ...], flag: str) -> None:
    bad = {t for _, t, _ in rows if t not in allowed}
    if bad:
        raise LogError(
            f"{name}: --{flag}-topic carries {', '.join(sorted(bad))}; expected {' or '.join(allowed)}"
        )


def import_rosbag(
    bag: str | Path,
    out: str | Path,
    *,
    imu_topic: str,
    range_topic: str | None = None,
    height_topic: str | None = None,
    pose_topic: str | None = None,
    uwb_topic: str | None = None,
    uwb_id_field: str = "header.frame_id",
    uwb_range_field: str = "range",
    anchors: str | Path | None = None,
    force: bool = False,
) -> Imported:
    """Import the bag ``bag`` into the log folder ``out`` (module docstring); ``anchors`` is required with
    ``uwb_topic``."""
    path = Path(bag)
    if not path.exists():
        raise LogError(f"{path}: no such bag")
    if uwb_topic is not None and anchors is None:
        raise LogError(
            f"{path.name}: --uwb-topic {uwb_topic} gives ranges: give the anchors file (--anchors)"
        )
    topics = {
        "imu": imu_topic,
        "range": range_topic,
        "height": height_topic,
        "pose": pose_topic,
        "uwb": uwb_topic,
    }
    topics = {k: v for k, v in topics.items() if v is not None}
    got = _read(path, topics)
    rep = Imported(Path(out), f"source: {path.name} (ROS bag)")
    rep.notes.append("topics: " + ", ".join(f"{topics[r]} {len(v)}" for r, v in got.items()))
    if not got["imu"]:
        raise LogError(f"{path.name}: no messages on {imu_topic}: imu.csv needs them")
    origin = min(rows[0][0] for rows in got.values() if rows) // 1_000_000_000 * 1_000_000_000
    rep.notes.append(f"t_s = stamp - {origin // 1_000_000_000} s (header stamps; the bag's time without one)")

    def seconds(rows):
        return np.array([(ns - origin) * 1e-9 for ns, _, _ in rows], dtype=np.float64)

    folder = LogFolder(out, force, rep, time_decimals=9)
    _types(path.name, got["imu"], ("sensor_msgs/msg/Imu",), "imu")
    imu = got["imu"]
    ok = np.array(
        [
            m.angular_velocity_covariance[0] != -1 and m.linear_acceleration_covariance[0] != -1
            for _, _, m in imu
        ]
    )
    w = np.array(
        [[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for _, _, m in imu], float
    )
    f = np.array(
        [[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z] for _, _, m in imu],
        float,
    )
    t = seconds(imu)
    ok &= np.isfinite(w).all(axis=1) & np.isfinite(f).all(axis=1)
    o, dup = time_order(t[ok], strict=True)
    folder.write_imu(t[ok][o], w[ok][o], f[ok][o])
    rep.notes.append(f"imu.csv: {imu_topic} as it is (REP 103 FLU); {int((~ok).sum()) + dup} dropped")
    ids, xyz = (np.empty(0, np.int64), np.empty((0, 3))) if anchors is None else read_anchor_file(anchors)
    folder.write_anchors(ids, xyz)
    if "uwb" in got:
        rows = got["uwb"]
        aid = np.empty(len(rows))
        rng = np.empty(len(rows))
        for k, (_, _, m) in enumerate(rows):
            try:
                v, r = _get(m, uwb_id_field), _get(m, uwb_range_field)
            except AttributeError as exc:
                raise LogError(f"{path.name}: {uwb_topic} message {k}: {exc}") from None
            if isinstance(v, str):
                mt = _TRAILING_INT.search(v)
                if mt is None:
                    raise LogError(
                        f"{path.name}: {uwb_topic} message {k}: {uwb_id_field} {v!r} ends in no anchor id"
                    )
                v = int(mt.group(1))
            aid[k], rng[k] = float(v), float(r)
        unknown = np.flatnonzero(~np.isin(aid, ids))
        if len(unknown):
            k = int(unknown[0])
            raise LogError(
                f"{path.name}: {uwb_topic} message {k} names anchor {aid[k]:g}, not in {Path(anchors).name} "
                f"(it has {', '.join(str(int(i)) for i in ids)})"
            )
        tu = seconds(rows)
        rng = np.where(np.isfinite(rng) & (rng >= 0), rng, np.nan)
        o, _ = time_order(tu, strict=False)
        folder.write_uwb(tu[o], aid[o], rng[o])
    else:
        folder.write_uwb(np.empty(0), np.empty(0), np.empty(0))
    if got.get("range"):
        rows = got["range"]
        _types(path.name, rows, ("sensor_msgs/msg/Range",), "range")
        r = np.array([m.range for _, _, m in rows], float)
        lo = np.array([m.min_range for _, _, m in rows], float)
        hi = np.array([m.max_range for _, _, m in rows], float)
        none = ~np.isfinite(r) | (r < lo) | (r > hi)
        th = seconds(rows)
        o, dup = time_order(th, strict=True)
        folder.write_height(th[o], np.where(none, np.nan, r)[o])
        rep.notes.append(
            f"height.csv: {range_topic}; {int(none.sum())} without a return written empty; {dup} repeated"
        )
    if got.get("height"):
        rows = got["height"]
        kinds = (
            "sensor_msgs/msg/FluidPressure",
            "geometry_msgs/msg/PointStamped",
            "std_msgs/msg/Float32",
            "std_msgs/msg/Float64",
        )
        _types(path.name, rows, kinds, "height")
        h = np.array([_baro_value(mt, m) for _, mt, m in rows], float)
        tb = seconds(rows)
        o, dup = time_order(tb, strict=True)
        folder.write_baro(tb[o], h[o])
        how = "pressure -> ISA altitude" if rows[0][1] == kinds[0] else "as it is"
        rep.notes.append(f"baro.csv: {height_topic} {how}; {dup} repeated times dropped")
    if got.get("pose"):
        rows = got["pose"]
        kinds = (
            "geometry_msgs/msg/PoseStamped",
            "geometry_msgs/msg/PoseWithCovarianceStamped",
            "nav_msgs/msg/Odometry",
        )
        _types(path.name, rows, kinds, "pose")
        poses = [m.pose.pose if hasattr(m.pose, "pose") else m.pose for _, _, m in rows]
        p = np.array([[q.position.x, q.position.y, q.position.z] for q in poses], float)
        q = np.array(
            [[q.orientation.x, q.orientation.y, q.orientation.z, q.orientation.w] for q in poses], float
        )
        tp = seconds(rows)
        o, dup = time_order(tp, strict=True)
        folder.write_truth(tp[o], p[o], q[o])
        rep.notes.append(f"truth.csv: {pose_topic} as it is (ENU, FLU body); {dup} repeated times dropped")
    return folder.finish(path.stem)


def _baro_value(msgtype: str, m) -> float:
    if msgtype.endswith("FluidPressure"):
        return float(isa_altitude_m(m.fluid_pressure))
    if msgtype.endswith("PointStamped"):
        return float(m.point.z)
    v = float(m.data)
    return v if math.isfinite(v) else math.nan
