"""``swarm import cfusd``: Crazyflie uSD event logs written by the test (tests/logs/cfusd_writer.py, a correct
CRC32), their units and frames, and every kind of damage refused with its byte offset; a file cut mid-write
keeps what was decoded before the cut."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from swarm.cli.main import main
from swarm.errors import LogError
from swarm.logs.cfusd import decode, import_cfusd
from swarm.logs.importing import STANDARD_G_M_S2, read_anchor_file
from swarm.logs.reader import read_log
from tests.logs.cfusd_writer import big_log, build, header, imu_events

ANCHORS = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [4.0, 3.0, 2.0], [0.0, 3.0, 2.0]])
UTIL_SURVEY = """uwbDatasetFrame1,-0.0002,-0.0001,-0.0004
anchor0_1, -3.1301,-3.9836,0.2447
{lines}
anchor3_3,4.0040,-4.2697,3.2052
"""


@pytest.fixture
def anchors_file(tmp_path):
    """The anchors in the UTIL survey's format, with its other lines around them."""
    lines = "\n".join(f"anchorAnt{i}, {x},{y},{z}" for i, (x, y, z) in enumerate(ANCHORS))
    p = tmp_path / "anchor_test.txt"
    p.write_text(UTIL_SURVEY.format(lines=lines))
    return p


def _flight(version: int = 2):
    """Events of a short flight: 50 IMU pairs, ranges, TDoA (one with the same anchor twice, one longer
    than its baseline), poses, ToF (a 0 and an out-of-range code), barometer, and an ignored estFlow."""
    unit = 1 if version == 1 else 1000  # per millisecond
    ev = imu_events(50, version)
    t = 1005 * unit  # 1.005 s
    ev += [
        ("estDistance", t, (0, 2.5)),
        ("estDistance", t + 2 * unit, (3, 3.25)),
        ("estTDOA", t + 3 * unit, (0, 1, -1.5)),
        ("estTDOA", t + 4 * unit, (2, 2, 0.1)),  # the same anchor twice: dropped
        ("estTDOA", t + 5 * unit, (0, 1, 4.5)),  # longer than the 4 m baseline: dropped
        ("estPose", t + 6 * unit, (1.0, 2.0, 0.5, 0.0, 0.0, math.sin(0.25), math.cos(0.25))),
        ("estPose", t + 16 * unit, (1.1, 2.0, 0.5, 0.0, 0.0, 0.0, 1.0)),
        ("estTOF", t + 7 * unit, (523,)),
        ("estTOF", t + 8 * unit, (0,)),  # no return
        ("estTOF", t + 9 * unit, (8190,)),  # out-of-range code: no return
        ("estBarometer", t + 10 * unit, (185.25,)),
        ("estFlow", t + 11 * unit, (3, -2)),
    ]
    return ev


def test_the_util_survey_gives_the_antenna_lines_only(anchors_file):
    ids, xyz = read_anchor_file(anchors_file)
    assert ids.tolist() == [0, 1, 2, 3]
    np.testing.assert_allclose(xyz, ANCHORS)


def test_a_flight_imports_in_si_units_and_reads_back(tmp_path, anchors_file):
    raw = tmp_path / "log00"
    raw.write_bytes(build(_flight()).data)
    rep = import_cfusd(raw, tmp_path / "out", anchors_file)
    lg = read_log(tmp_path / "out")
    # IMU: rows at the gyroscope's times (exact, microseconds), deg/s -> rad/s; the last gyroscope sample
    # has no accelerometer sample after it (they come 17 us before theirs): dropped, 49 rows
    assert len(lg.imu_t) == 49 and "1 gyroscope samples without one around them dropped" in rep.notes[2]
    np.testing.assert_allclose(lg.imu_t, 1.0 + np.arange(49) * 1e-3, atol=1e-9)
    np.testing.assert_allclose(lg.gyro[:, 0], np.radians(10.0 + lg.imu_t), rtol=1e-6)
    np.testing.assert_allclose(lg.gyro[:, 1:], np.radians([[-20.0, 30.0]] * 49), rtol=1e-6)
    # g -> m/s^2 with 9.81, the accelerometer (17 us earlier) interpolated to the gyroscope's time: linear
    # in time, so exact up to float32
    np.testing.assert_allclose(lg.acc[:, 2], STANDARD_G_M_S2 * (1.0 + 0.1 * lg.imu_t), rtol=1e-6)
    np.testing.assert_allclose(lg.acc[:, 0], STANDARD_G_M_S2 * 0.01 * lg.imu_t, rtol=1e-5)
    # ranges and TDoA, the bad TDoA rows dropped
    assert lg.anchor_ids[lg.uwb_anchor].tolist() == [0, 3]
    np.testing.assert_allclose(lg.uwb_range, [2.5, 3.25])
    assert len(lg.tdoa_t) == 1 and lg.anchor_ids[lg.tdoa_a[0]] == 0 and lg.anchor_ids[lg.tdoa_b[0]] == 1
    assert lg.tdoa_ddist[0] == pytest.approx(-1.5)
    # truth as logged (scalar-last), ToF mm -> m with the two non-returns skipped, barometer
    np.testing.assert_allclose(lg.truth_p[0], [1.0, 2.0, 0.5], rtol=1e-6)
    np.testing.assert_allclose(lg.truth_q[0], [0, 0, math.sin(0.25), math.cos(0.25)], atol=1e-7)
    assert lg.height_range.tolist() == pytest.approx([0.523]) and lg.skipped["height.csv"] == 2
    assert lg.baro_height.tolist() == pytest.approx([185.25])
    toml = (tmp_path / "out" / "log.toml").read_text()
    assert 'name = "log00"' in toml and "estFlow 1" in toml and "ignored: estFlow 1" in toml
    assert "estGyroscope 50" in toml and "times 9.81" in toml and not rep.warnings
    # TWR: the firmware's range noise suggested, not set (a static segment calibrates it per anchor)
    assert "# sigma_m = 0.25" in toml and lg.config.uwb.sigma_m is None


def test_version_1_stamps_are_milliseconds(tmp_path, anchors_file):
    raw = tmp_path / "v1"
    raw.write_bytes(build(_flight(1), version=1).data)
    import_cfusd(raw, tmp_path / "out", anchors_file)
    lg = read_log(tmp_path / "out")
    # ms stamps: the gyroscope's times are whole milliseconds (each accelerometer sample, 17 us earlier,
    # floors to the millisecond before; the last gyroscope sample has none after it)
    np.testing.assert_allclose(lg.imu_t, 1.0 + np.arange(49) * 1e-3, atol=1e-9)
    assert lg.uwb_t.tolist() == pytest.approx([1.005, 1.007])


def _refused(tmp_path, data: bytes, pattern: str):
    raw = tmp_path / "bad"
    raw.write_bytes(data)
    with pytest.raises(LogError, match=pattern):
        decode(raw)


def test_a_bad_magic_is_refused_at_byte_0(tmp_path):
    data = bytearray(build(_flight()).data)
    data[0] = 0xBD
    _refused(tmp_path, bytes(data), r"^bad, byte 0: magic 0xBD, expected 0xBC")


def test_an_unknown_version_is_refused_at_byte_1(tmp_path):
    _refused(tmp_path, build(_flight(), version=3).data, r"^bad, byte 1: unknown version 3")


def test_a_truncated_header_is_refused_where_it_ends(tmp_path):
    head, at = header()
    cut = at[3] + 5  # inside estDistance's name
    _refused(tmp_path, head[:cut], rf"^bad, byte {at[3] + 2}: truncated header: the name of event 3 has no")


def test_a_bad_field_type_is_refused_at_its_byte(tmp_path):
    defs = {1: ("estGyroscope", (("gyro.x", "f"), ("gyro.y", "X")))}
    head, at = header(defs=defs)
    field_at = at[1] + 2 + len("estGyroscope") + 1 + 2 + len("gyro.x(f)") + 1
    _refused(
        tmp_path,
        head + bytes(4),
        rf"^bad, byte {field_at}: field 'gyro.y\(X\)' of estGyroscope: unknown type",
    )


def test_an_undefined_event_id_is_refused_at_its_offset(tmp_path):
    b = build(_flight())
    data = bytearray(b.data)
    k = b.offsets[7]
    data[k : k + 2] = (99).to_bytes(2, "little")  # and the CRC is now wrong too: the id is found first
    _refused(tmp_path, bytes(data), rf"^bad, byte {k}: event id 99 is not defined in the header")


def test_a_crc_mismatch_is_refused_at_the_trailer(tmp_path):
    b = build(_flight())
    data = bytearray(b.data)
    data[b.offsets[10] + 12] ^= 0x01  # a bit of a float: every event still parses
    n = len(data)
    _refused(tmp_path, bytes(data), rf"^bad, byte {n - 4}: CRC mismatch: the trailer says 0x")


def test_a_file_cut_mid_event_keeps_what_decoded_before(tmp_path, anchors_file):
    b = build(_flight(), crc=False)
    last = b.offsets[-1]
    raw = tmp_path / "cut"
    raw.write_bytes(b.data[: last + 7])  # the trailer lost, 7 bytes of the last event (estFlow) written
    usd = decode(raw)
    assert (usd.cut_at, usd.dropped_bytes) == (last, 7)
    assert "estFlow" not in usd.counts and usd.counts["estBarometer"] == 1
    rep = import_cfusd(raw, tmp_path / "out", anchors_file)
    assert rep.warnings == [
        f"cut was cut mid-write: 7 bytes of a partial event dropped at byte offset {last}; the events before "
        "it are kept"
    ]
    assert (
        f"WARNING: cut was cut mid-write: 7 bytes of a partial event dropped at byte offset {last}"
        in (tmp_path / "out" / "log.toml").read_text()
    )
    lg = read_log(tmp_path / "out")
    assert len(lg.imu_t) == 49 and len(lg.baro_t) == 1


def test_a_file_cut_between_events_keeps_them_all(tmp_path):
    b = build(_flight(), crc=False)
    raw = tmp_path / "cut"
    raw.write_bytes(b.data)
    usd = decode(raw)
    assert (usd.cut_at, usd.dropped_bytes) == (len(b.data), 0) and usd.counts["estFlow"] == 1


def test_a_range_from_an_anchor_not_surveyed_is_refused_at_its_event(tmp_path, anchors_file):
    ev = [*imu_events(5), ("estDistance", 1_002_000, (7, 2.0))]
    b = build(ev)
    raw = tmp_path / "log"
    raw.write_bytes(b.data)
    with pytest.raises(
        LogError, match=rf"^log, byte {b.offsets[-1]}: estDistance id 7 is not in anchor_test\.txt"
    ):
        import_cfusd(raw, tmp_path / "out", anchors_file)
    with pytest.raises(LogError, match=r"^log: has UWB events .* give the anchors file \(--anchors\)"):
        import_cfusd(raw, tmp_path / "out2")


def test_the_command_line_imports_and_refuses_with_one_line(tmp_path, anchors_file, capsys):
    raw = tmp_path / "log00"
    raw.write_bytes(build(_flight()).data)
    out = tmp_path / "out"
    assert main(["import", "cfusd", str(raw), str(out), "--anchors", str(anchors_file)]) == 0
    text = capsys.readouterr().out
    assert "rows: imu.csv 49, anchors.csv 4, uwb.csv 2, tdoa.csv 1" in text and f"written to {out}" in text
    assert main(["import", "cfusd", str(raw), str(out), "--anchors", str(anchors_file)]) == 2  # no --force
    assert "already holds a log" in capsys.readouterr().err
    bad = tmp_path / "bad"
    bad.write_bytes(b"\xbb" + raw.read_bytes()[1:])
    assert main(["import", "cfusd", str(bad), str(tmp_path / "o2")]) == 2
    assert (
        capsys.readouterr().err.strip()
        == "swarm: error: bad, byte 0: magic 0xBB, expected 0xBC (a Crazyflie uSD event log)"
    )


def test_a_4_mb_log_imports_in_well_under_two_seconds(tmp_path):
    raw = tmp_path / "big"
    raw.write_bytes(big_log(120_000))  # 240 000 events of 22 bytes: 5.3 MB
    assert raw.stat().st_size > 4_000_000
    t0 = time.perf_counter()
    import_cfusd(raw, tmp_path / "out")
    wall = time.perf_counter() - t0
    # the brief: a couple of seconds at most for 4 MB; measured ~0.6 s here (walk + numpy views + CSV
    # text); 2 s leaves room for a loaded 2-core machine
    assert wall < 2.0, wall
    # a header and a row per gyroscope sample but the last (no accelerometer sample after it)
    assert (tmp_path / "out" / "imu.csv").read_text().count("\n") == 120_000
