"""``swarm import rosbag`` on bags the test writes with rosbags' own writers: a ROS 2 bag (sqlite3 and MCAP)
and a ROS 1 bag, with an IMU, a downward range finder, a barometer (pressure, converted with the ISA), a
motion-capture pose and per-anchor UWB ranges."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.errors import LogError
from swarm.logs.reader import read_log
from swarm.logs.rosbag import import_rosbag, isa_altitude_m

rosbags = pytest.importorskip("rosbags")  # the `import` extra (make installs it)

from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

T0 = 1_700_000_000  # a Unix time, as real bags have


def _messages(ts, ros1: bool):
    """(topic, msgtype, stamp_ns, message) of a 0.1 s flight."""
    t = ts.types
    seq = {"seq": 0} if ros1 else {}

    def header(ns, frame="base_link"):
        return t["std_msgs/msg/Header"](
            **seq, stamp=t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame
        )

    v3, quat = t["geometry_msgs/msg/Vector3"], t["geometry_msgs/msg/Quaternion"]
    out = []
    for k in range(10):
        ns = T0 * 10**9 + 123_456_789 + k * 10_000_000  # 100 Hz
        cov = np.zeros(9)
        imu = t["sensor_msgs/msg/Imu"](
            header=header(ns),
            orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=-np.eye(3).ravel(),  # orientation absent (REP 145): not used
            angular_velocity=v3(x=0.01 * k, y=-0.02, z=0.03),
            angular_velocity_covariance=cov,
            linear_acceleration=v3(x=0.1, y=0.2, z=9.81),
            linear_acceleration_covariance=cov,
        )
        out.append(("/imu", "sensor_msgs/msg/Imu", ns, imu))
    rng = t["sensor_msgs/msg/Range"]
    for k, r in enumerate((0.75, float("inf"), 5.0)):  # inf: no detection (REP 117); 5 > max_range 4
        ns = T0 * 10**9 + 130_000_000 + k * 20_000_000
        out.append(
            (
                "/down",
                "sensor_msgs/msg/Range",
                ns,
                rng(
                    header=header(ns, "tof"),
                    radiation_type=1,
                    field_of_view=0.4,
                    min_range=0.05,
                    max_range=4.0,
                    range=r,
                ),
            )
        )
    for k, (anchor, r) in enumerate((("anchor2", 3.5), ("anchor_11", 4.25))):
        ns = T0 * 10**9 + 140_000_000 + k * 5_000_000
        out.append(
            (
                "/uwb",
                "sensor_msgs/msg/Range",
                ns,
                rng(
                    header=header(ns, anchor),
                    radiation_type=2,
                    field_of_view=0.0,
                    min_range=0.0,
                    max_range=50.0,
                    range=r,
                ),
            )
        )
    ns = T0 * 10**9 + 150_000_000
    fp = t["sensor_msgs/msg/FluidPressure"](header=header(ns), fluid_pressure=89874.6, variance=0.0)
    out.append(("/baro", "sensor_msgs/msg/FluidPressure", ns, fp))
    pose = t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.5),
        orientation=quat(x=0.0, y=0.0, z=0.6, w=0.8),
    )
    out.append(
        (
            "/mocap",
            "geometry_msgs/msg/PoseStamped",
            ns,
            t["geometry_msgs/msg/PoseStamped"](header=header(ns), pose=pose),
        )
    )
    return sorted(out, key=lambda m: m[2])


def _write_ros2(path, storage):
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Writer2(path, version=9, storage_plugin=storage) as w:
        cons = {}
        for topic, mt, ns, msg in _messages(ts, ros1=False):
            if topic not in cons:
                cons[topic] = w.add_connection(topic, mt, typestore=ts)
            w.write(cons[topic], ns, ts.serialize_cdr(msg, mt))
    return path


def _write_ros1(path):
    ts = get_typestore(Stores.ROS1_NOETIC)
    with Writer1(path) as w:
        cons = {}
        for topic, mt, ns, msg in _messages(ts, ros1=True):
            if topic not in cons:
                cons[topic] = w.add_connection(topic, mt, typestore=ts)
            w.write(cons[topic], ns, ts.serialize_ros1(msg, mt))
    return path


@pytest.fixture
def anchors(tmp_path):
    p = tmp_path / "anchors.csv"
    p.write_text("anchor_id, x_m, y_m, z_m\n2,0,0,0\n11,5,0,2\n")
    return p


def test_the_isa_altitude_of_published_pressures():
    # ICAO standard atmosphere table: 101325 Pa at 0 m, 89874.6 Pa at 1000 m, 79495.2 Pa at 2000 m
    np.testing.assert_allclose(isa_altitude_m([101325.0, 89874.6, 79495.2]), [0.0, 1000.0, 2000.0], atol=0.5)


@pytest.mark.parametrize("kind", ["ros2-sqlite3", "ros2-mcap", "ros1"])
def test_a_bag_imports_every_topic(tmp_path, anchors, kind):
    if kind == "ros1":
        bag = _write_ros1(tmp_path / "flight.bag")
    else:
        storage = StoragePlugin.SQLITE3 if kind == "ros2-sqlite3" else StoragePlugin.MCAP
        bag = _write_ros2(tmp_path / "flight", storage)
    out = tmp_path / "out"
    rep = import_rosbag(
        bag,
        out,
        imu_topic="/imu",
        range_topic="/down",
        height_topic="/baro",
        pose_topic="/mocap",
        uwb_topic="/uwb",
        anchors=anchors,
    )
    lg = read_log(out)
    # times from the header stamps, from the whole second before the first (nanoseconds kept)
    assert f"t_s = stamp - {T0} s" in rep.notes[1]
    np.testing.assert_allclose(lg.imu_t, 0.123456789 + 0.01 * np.arange(10), atol=1e-9)
    np.testing.assert_allclose(lg.gyro[:, 0], 0.01 * np.arange(10))
    np.testing.assert_allclose(lg.acc[0], [0.1, 0.2, 9.81])  # REP 145: already the specific force
    assert lg.height_range.tolist() == [0.75] and lg.skipped["height.csv"] == 2  # inf and > max_range
    assert lg.anchor_ids[lg.uwb_anchor].tolist() == [2, 11] and lg.uwb_range.tolist() == [3.5, 4.25]
    assert lg.baro_height[0] == pytest.approx(1000.0, abs=0.5)
    np.testing.assert_allclose(lg.truth_p[0], [1.0, 2.0, 0.5])
    np.testing.assert_allclose(lg.truth_q[0], [0.0, 0.0, 0.6, 0.8])


def test_a_missing_topic_a_wrong_type_and_a_bad_bag_are_refused(tmp_path, anchors):
    bag = _write_ros2(tmp_path / "flight", StoragePlugin.SQLITE3)
    with pytest.raises(
        LogError, match=r"no topic '/gps' for --pose-topic \(the bag has /baro \(sensor_msgs/msg/Flu"
    ):
        import_rosbag(bag, tmp_path / "o1", imu_topic="/imu", pose_topic="/gps")
    with pytest.raises(
        LogError, match=r"--range-topic carries sensor_msgs/msg/Imu; expected sensor_msgs/msg/Range"
    ):
        import_rosbag(bag, tmp_path / "o2", imu_topic="/imu", range_topic="/imu")
    with pytest.raises(LogError, match=r"--uwb-topic /uwb gives ranges: give the anchors file"):
        import_rosbag(bag, tmp_path / "o3", imu_topic="/imu", uwb_topic="/uwb")
    anchors.write_text("anchor_id, x_m, y_m, z_m\n2,0,0,0\n")
    with pytest.raises(LogError, match=r"/uwb message 1 names anchor 11, not in anchors\.csv \(it has 2\)"):
        import_rosbag(bag, tmp_path / "o4", imu_topic="/imu", uwb_topic="/uwb", anchors=anchors)
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"#ROSBAG V1.0\n" + bytes(50))
    with pytest.raises(LogError, match=r"^junk\.bag: not a readable ROS bag"):
        import_rosbag(junk, tmp_path / "o5", imu_topic="/imu")
