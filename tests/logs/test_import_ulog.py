"""``swarm import ulog`` on ULog files the test writes (tests/logs/ulog_writer.py): PX4's NED/FRD converted
to our ENU/FLU (checked on headings whose answer is known, and against scipy's rotations), the downward
range finder chosen by its orientation, the barometer, UWB by flags, and a file that is not a ULog."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from swarm.errors import LogError
from swarm.logs.reader import read_log
from swarm.logs.ulog import DOWNWARD, import_ulog, ned_frd_to_enu_flu
from tests.logs.ulog_writer import ulog_bytes

SC = [
    ("uint64_t", "timestamp"),
    ("float[3]", "gyro_rad"),
    ("int32_t", "accelerometer_timestamp_relative"),
    ("float[3]", "accelerometer_m_s2"),
]
DIST = [
    ("uint64_t", "timestamp"),
    ("float", "min_distance"),
    ("float", "max_distance"),
    ("float", "current_distance"),
    ("int8_t", "signal_quality"),
    ("uint8_t", "orientation"),
]
AIR = [("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"), ("float", "baro_alt_meter")]
ODOM = [
    ("uint64_t", "timestamp"),
    ("uint64_t", "timestamp_sample"),
    ("float[3]", "position"),
    ("float[4]", "q"),
]
UWB = [("uint64_t", "timestamp"), ("uint16_t", "mac_dest"), ("float", "distance")]
YAW_EAST = (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4))  # w, x, y, z: 90 deg about NED down


def _write(path, with_uwb=False):
    topics = {"sensor_combined": SC, "vehicle_air_data": AIR, "vehicle_odometry": ODOM}
    data = []
    for k in range(20):
        t = 1_000_000 + 4000 * k  # 250 Hz, us
        # FRD: rolling right, pitching up, yawing right; standing still: -g on FRD z
        data.append(("sensor_combined", (t, 0.1, 0.2, 0.3, 0, 0.5, -0.25, -9.81)))
    data.append(("vehicle_air_data", (1_010_000, 1_009_000, 123.5)))
    data.append(("vehicle_odometry", (1_020_000, 1_019_000, 1.0, 2.0, -3.0, 1.0, 0.0, 0.0, 0.0)))
    data.append(("vehicle_odometry", (1_030_000, 1_029_000, 1.0, 2.0, -3.0, *YAW_EAST)))
    # two range finders: instance 0 faces forward (orientation 0) and is ignored, instance 1 faces down
    topics["distance_sensor"] = DIST
    fwd, down = ("distance_sensor", 0), ("distance_sensor", 1)
    data += [
        (fwd, (1_004_000, 0.1, 4.0, 2.0, 100, 0)),
        (down, (1_005_000, 0.1, 4.0, 0.8, 100, DOWNWARD)),
        (down, (1_015_000, 0.1, 4.0, 9.0, 100, DOWNWARD)),  # beyond max_distance
        (fwd, (1_016_000, 0.1, 4.0, 2.5, 100, 0)),
        (down, (1_025_000, 0.1, 4.0, 0.9, 0, DOWNWARD)),  # signal quality 0: invalid
        (down, (1_035_000, 0.1, 4.0, 1.0, -1, DOWNWARD)),  # quality unknown: kept
    ]
    if with_uwb:
        topics["sensor_uwb"] = UWB
        data += [("sensor_uwb", (1_012_000, 2, 3.5)), ("sensor_uwb", (1_013_000, 4, 2.25))]
    path.write_bytes(ulog_bytes(topics, data, {"distance_sensor": (0, 1)}))
    return path


def test_headings_known_in_both_conventions():
    # level, facing north: FLU forward is ENU north (+y), FLU up is ENU up
    p, q = ned_frd_to_enu_flu(np.array([[1.0, 2.0, -3.0]]), np.array([[1.0, 0.0, 0.0, 0.0]]))
    np.testing.assert_allclose(p[0], [2.0, 1.0, 3.0])  # north 1, east 2, 3 m up
    r = Rotation.from_quat(q[0])
    np.testing.assert_allclose(r.apply([1, 0, 0]), [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(r.apply([0, 0, 1]), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(r.apply([0, 1, 0]), [-1, 0, 0], atol=1e-12)  # left of north is west
    # facing east (yaw 90 deg, NED's heading): forward is ENU east (+x)
    _, q = ned_frd_to_enu_flu(np.zeros((1, 3)), np.array([YAW_EAST]))
    np.testing.assert_allclose(Rotation.from_quat(q[0]).apply([1, 0, 0]), [1, 0, 0], atol=1e-12)


def test_any_attitude_maps_body_vectors_consistently():
    # a body vector through either path lands on the same nav vector: FRD -> NED -> ENU and FRD -> FLU -> ENU
    rng = np.random.default_rng(7)
    q_wxyz = rng.normal(size=(50, 4))
    q_wxyz /= np.linalg.norm(q_wxyz, axis=1, keepdims=True)
    v_frd = rng.normal(size=(50, 3))
    _, q = ned_frd_to_enu_flu(np.zeros((50, 3)), q_wxyz)
    t = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1.0]])
    via_ned = (Rotation.from_quat(q_wxyz[:, [1, 2, 3, 0]]).apply(v_frd)) @ t.T
    via_flu = Rotation.from_quat(q).apply(v_frd * [1, -1, -1])
    np.testing.assert_allclose(via_flu, via_ned, atol=1e-12)


def test_a_ulog_imports_with_frames_converted(tmp_path):
    src = _write(tmp_path / "flight.ulg")
    rep = import_ulog(src, tmp_path / "out", truth_topic="vehicle_odometry")
    lg = read_log(tmp_path / "out")
    # the accelerometer shares the gyroscope's time (relative 0): every row kept
    assert len(lg.imu_t) == 20 and lg.imu_t[0] == pytest.approx(1.0) and lg.imu_t[1] == pytest.approx(1.004)
    np.testing.assert_allclose(lg.gyro, [[0.1, -0.2, -0.3]] * 20, rtol=1e-6)  # FRD -> FLU
    np.testing.assert_allclose(lg.acc, [[0.5, 0.25, 9.81]] * 20, rtol=1e-6)  # -g on FRD z is +g on FLU z
    # barometer at its sample time; the range finder: out of range and quality 0 skipped, unknown kept
    assert lg.baro_t.tolist() == pytest.approx([1.009]) and lg.baro_height.tolist() == pytest.approx([123.5])
    assert lg.height_t.tolist() == pytest.approx([1.005, 1.035])  # the downward instance's only
    assert lg.height_range.tolist() == pytest.approx([0.8, 1.0]) and lg.skipped["height.csv"] == 2
    # truth in ENU: north 1, east 2, down -3 -> (2, 1, 3); facing east, forward is +x
    np.testing.assert_allclose(lg.truth_p, [[2.0, 1.0, 3.0]] * 2, rtol=1e-6)
    np.testing.assert_allclose(Rotation.from_quat(lg.truth_q[1]).apply([1, 0, 0]), [1, 0, 0], atol=1e-6)
    assert lg.truth_t.tolist() == pytest.approx([1.019, 1.029])
    # no UWB topic: uwb.csv and anchors.csv have no rows, and the log reads
    assert len(lg.uwb_t) == 0 and len(lg.anchor_ids) == 0
    assert "uwb.csv: no --uwb-topic, no ranges" in rep.notes


def test_uwb_by_flags_needs_anchors_and_names_them(tmp_path):
    src = _write(tmp_path / "flight.ulg", with_uwb=True)
    anchors = tmp_path / "anchors.csv"
    anchors.write_text("anchor_id, x_m, y_m, z_m\n2,0,0,0\n4,3,0,0\n")
    with pytest.raises(LogError, match=r"--uwb-topic sensor_uwb gives ranges: give the anchors file"):
        import_ulog(src, tmp_path / "out", uwb_topic="sensor_uwb")
    import_ulog(src, tmp_path / "out", uwb_topic="sensor_uwb", anchors=anchors)
    lg = read_log(tmp_path / "out")
    assert lg.anchor_ids[lg.uwb_anchor].tolist() == [2, 4] and lg.uwb_range.tolist() == [3.5, 2.25]
    anchors.write_text("anchor_id, x_m, y_m, z_m\n2,0,0,0\n")
    with pytest.raises(
        LogError, match=r"sensor_uwb message 1 names anchor 4, not in anchors\.csv \(it has 2\)"
    ):
        import_ulog(src, tmp_path / "out2", uwb_topic="sensor_uwb", anchors=anchors)


def test_a_missing_topic_and_a_file_that_is_not_a_ulog_are_refused(tmp_path):
    src = _write(tmp_path / "flight.ulg")
    with pytest.raises(LogError, match=r"no topic 'vehicle_mocap_odometry' for --truth-topic \(the log has "):
        import_ulog(src, tmp_path / "out", truth_topic="vehicle_mocap_odometry")
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(b"NotULog" + src.read_bytes()[7:])
    with pytest.raises(LogError, match=r"^bad\.ulg: not a ULog: "):
        import_ulog(bad, tmp_path / "out3")


def test_local_position_takes_the_nearest_attitude_and_drops_invalid_samples(tmp_path):
    lpos = [
        ("uint64_t", "timestamp"),
        ("float", "x"),
        ("float", "y"),
        ("float", "z"),
        ("bool", "xy_valid"),
        ("bool", "z_valid"),
    ]
    att = [("uint64_t", "timestamp"), ("float[4]", "q")]
    topics = {"sensor_combined": SC, "vehicle_local_position": lpos, "vehicle_attitude": att}
    data = [("sensor_combined", (1_000_000 + 4000 * k, 0, 0, 0, 0, 0, 0, -9.81)) for k in range(5)]
    data += [
        ("vehicle_attitude", (1_000_000, 1.0, 0.0, 0.0, 0.0)),  # facing north
        ("vehicle_attitude", (1_010_000, *YAW_EAST)),  # facing east
        ("vehicle_local_position", (1_004_000, 1.0, 0.0, 0.0, True, True)),  # nearest: north (4 ms)
        ("vehicle_local_position", (1_007_000, 2.0, 0.0, 0.0, True, True)),  # nearest: east (3 ms)
        ("vehicle_local_position", (1_008_000, 9.0, 0.0, 0.0, False, True)),  # xy not valid: dropped
    ]
    src = tmp_path / "lpos.ulg"
    src.write_bytes(ulog_bytes(topics, data))
    rep = import_ulog(src, tmp_path / "out", truth_topic="vehicle_local_position")
    lg = read_log(tmp_path / "out")
    np.testing.assert_allclose(lg.truth_p, [[0.0, 1.0, 0.0], [0.0, 2.0, 0.0]], atol=1e-6)
    fwd = Rotation.from_quat(lg.truth_q).apply([1, 0, 0])
    np.testing.assert_allclose(fwd, [[0, 1, 0], [1, 0, 0]], atol=1e-6)
    assert any("1 invalid samples" in n for n in rep.notes)
