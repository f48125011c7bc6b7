"""``swarm import cfusd|ulog|rosbag``: a recorded flight from a vehicle's own format into a log folder that
``swarm replay`` reads (``docs/logs.md``, Importing logs). The module is ``importer``: ``import`` is a Python
keyword."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from swarm.args import positive_float

IMPORT = """Convert a recorded flight into a log folder (imu.csv, uwb.csv, anchors.csv, and what the source
has of tdoa.csv, truth.csv, height.csv, baro.csv; a log.toml whose comment block says what was imported;
docs/logs.md). Units and frames are converted to the folder's (SI, body FLU, navigation z up). A damaged
source is refused naming the byte offset or message; a file cut mid-write keeps what was decoded before the
cut and says so."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from swarm.logs.cfusd import TOF_MAX_MM
    from swarm.logs.importing import STANDARD_G_M_S2

    p = sub.add_parser(
        "import", help="convert a recorded flight into a log folder (docs/logs.md)", description=IMPORT
    )
    kinds = p.add_subparsers(dest="kind", required=True, metavar="KIND")

    c = kinds.add_parser(
        "cfusd",
        help="a Crazyflie uSD-card event log",
        description="A Crazyflie uSD-card event log (usddeck): estGyroscope, estAcceleration, estDistance "
        "(TWR), estTDOA, estPose (motion capture), estTOF, estBarometer.",
    )
    c.add_argument("raw", type=Path, metavar="RAW", help="the log file from the card")
    c.add_argument("out", type=Path, metavar="OUT", help="the log folder to write")
    c.add_argument(
        "--anchors",
        type=Path,
        metavar="FILE",
        help="anchor positions: an anchors.csv or the UTIL survey (anchorAnt<id>,x,y,z); needed with ranges",
    )
    c.add_argument(
        "--g",
        type=positive_float("--g"),
        default=STANDARD_G_M_S2,
        metavar="M_S2",
        help=f"one g for estAcceleration [m/s^2] (default {STANDARD_G_M_S2}, the firmware's)",
    )
    c.add_argument(
        "--tof-max-mm",
        type=positive_float("--tof-max-mm"),
        default=TOF_MAX_MM,
        metavar="MM",
        help=f"estTOF readings at or beyond are no return (default {TOF_MAX_MM}, the Flow deck v2's limit)",
    )
    c.set_defaults(func=run_cfusd)

    u = kinds.add_parser("ulog", help="a PX4 ULog", description="A PX4 ULog (.ulg), read with pyulog.")
    u.add_argument("file", type=Path, metavar="FILE")
    u.add_argument("out", type=Path, metavar="OUT")
    u.add_argument(
        "--truth-topic",
        metavar="TOPIC",
        help="the topic for truth.csv: vehicle_local_position (with vehicle_attitude), vehicle_odometry, "
        "vehicle_visual_odometry, vehicle_mocap_odometry (NED/FRD, converted to ENU/FLU)",
    )
    u.add_argument(
        "--uwb-topic", metavar="TOPIC", help="a topic of two-way ranges (none: uwb.csv has no rows)"
    )
    u.add_argument(
        "--uwb-id-field", default="mac_dest", metavar="FIELD", help="its anchor id (default mac_dest)"
    )
    u.add_argument(
        "--uwb-range-field", default="distance", metavar="FIELD", help="its range [m] (default distance)"
    )
    u.add_argument("--anchors", type=Path, metavar="FILE", help="anchor positions; required with --uwb-topic")
    u.set_defaults(func=run_ulog)

    r = kinds.add_parser(
        "rosbag",
        help="a ROS 1 bag, a ROS 2 bag (db3 or MCAP)",
        description="A ROS 1 .bag, a ROS 2 bag folder (sqlite3 or MCAP) or a .mcap, read with rosbags.",
    )
    r.add_argument("bag", type=Path, metavar="BAG")
    r.add_argument("out", type=Path, metavar="OUT")
    r.add_argument("--imu-topic", required=True, metavar="T", help="sensor_msgs/Imu -> imu.csv")
    r.add_argument(
        "--range-topic", metavar="T", help="sensor_msgs/Range of a downward range finder -> height.csv"
    )
    r.add_argument(
        "--height-topic",
        metavar="T",
        help="barometric height -> baro.csv: sensor_msgs/FluidPressure (ISA), PointStamped (z), Float32/64",
    )
    r.add_argument(
        "--pose-topic", metavar="T", help="PoseStamped, PoseWithCovarianceStamped, Odometry -> truth.csv"
    )
    r.add_argument("--uwb-topic", metavar="T", help="two-way ranges -> uwb.csv (needs --anchors)")
    r.add_argument(
        "--uwb-id-field",
        default="header.frame_id",
        metavar="FIELD",
        help="the anchor id, a dotted field (a text's trailing integer; default header.frame_id)",
    )
    r.add_argument(
        "--uwb-range-field", default="range", metavar="FIELD", help="the range [m] (default range)"
    )
    r.add_argument("--anchors", type=Path, metavar="FILE", help="anchor positions; required with --uwb-topic")
    r.set_defaults(func=run_rosbag)
    for q in (c, u, r):
        q.add_argument("--force", action="store_true", help="overwrite a log already in OUT")


def _done(report, wall_s: float) -> int:
    for line in report.lines():
        print(line)
    print(f"written to {report.out} in {wall_s:.2f} s")
    return 0


def run_cfusd(args: argparse.Namespace) -> int:
    from swarm.logs.cfusd import import_cfusd

    t0 = time.perf_counter()
    rep = import_cfusd(
        args.raw, args.out, args.anchors, g_m_s2=args.g, tof_max_mm=args.tof_max_mm, force=args.force
    )
    return _done(rep, time.perf_counter() - t0)


def run_ulog(args: argparse.Namespace) -> int:
    from swarm.logs.ulog import import_ulog

    t0 = time.perf_counter()
    rep = import_ulog(
        args.file,
        args.out,
        truth_topic=args.truth_topic,
        uwb_topic=args.uwb_topic,
        uwb_id_field=args.uwb_id_field,
        uwb_range_field=args.uwb_range_field,
        anchors=args.anchors,
        force=args.force,
    )
    return _done(rep, time.perf_counter() - t0)


def run_rosbag(args: argparse.Namespace) -> int:
    from swarm.logs.rosbag import import_rosbag

    t0 = time.perf_counter()
    rep = import_rosbag(
        args.bag,
        args.out,
        imu_topic=args.imu_topic,
        range_topic=args.range_topic,
        height_topic=args.height_topic,
        pose_topic=args.pose_topic,
        uwb_topic=args.uwb_topic,
        uwb_id_field=args.uwb_id_field,
        uwb_range_field=args.uwb_range_field,
        anchors=args.anchors,
        force=args.force,
    )
    return _done(rep, time.perf_counter() - t0)
