"""The optional height.csv, baro.csv and tdoa.csv of a log folder: good rows read into the Log, bad ones
refused naming file, line, column and value, nan samples skipped and counted; a uwb.csv and an anchors.csv
with a header and no rows are a log without ranges."""

from __future__ import annotations

import pytest

from swarm.errors import LogError
from swarm.logs.reader import TDOA_BASELINE_TOL_M, read_log

IMU = """t_s, gyro_x_rad_s, gyro_y_rad_s, gyro_z_rad_s, acc_x_m_s2, acc_y_m_s2, acc_z_m_s2
0.000,0,0,0,0,0,9.81
0.001,0,0,0,0,0,9.81
0.002,0,0,0,0,0,9.81
"""
ANCHORS = """anchor_id, x_m, y_m, z_m
3,0,0,0
5,4,0,0
7,4,3,0
"""
UWB = """t_s, anchor_id, range_m
0.001,3,1.5
"""


@pytest.fixture
def log(tmp_path):
    d = tmp_path / "log"
    d.mkdir()
    (d / "imu.csv").write_text(IMU)
    (d / "anchors.csv").write_text(ANCHORS)
    (d / "uwb.csv").write_text(UWB)
    return d


def test_a_log_without_the_optional_files_has_none_of_their_fields(log):
    lg = read_log(log)
    assert lg.height_t is None and lg.baro_t is None and lg.tdoa_t is None


def test_good_rows_read_and_nan_samples_are_skipped_and_counted(log):
    (log / "height.csv").write_text("t_s, range_m\n0.0,0.52\n0.1,\n0.2,nan\n0.3,0.61\n")
    (log / "baro.csv").write_text("# barometric altitude\nheight_m, t_s\n185.2,0.0\n,0.05\n-3.5,0.1\n")
    (log / "tdoa.csv").write_text(
        "t_s, anchor_a, anchor_b, ddist_m\n0.0,3,5,-1.5\n0.0,5,7,2.9\n0.01,7,3,nan\n0.02,7,3,-4.5\n"
    )
    lg = read_log(log)
    assert lg.height_t.tolist() == [0.0, 0.3] and lg.height_range.tolist() == [0.52, 0.61]
    assert lg.baro_t.tolist() == [0.0, 0.1] and lg.baro_height.tolist() == [185.2, -3.5]  # columns by name
    assert lg.tdoa_t.tolist() == [0.0, 0.0, 0.02]  # equal times allowed (non-decreasing, as uwb.csv)
    assert lg.anchor_ids[lg.tdoa_a].tolist() == [3, 5, 7] and lg.anchor_ids[lg.tdoa_b].tolist() == [5, 7, 3]
    # 3-7 is 5 m apart: 4.5 fits, and 2.9 fits 5-7's 3 m
    assert lg.tdoa_ddist.tolist() == [-1.5, 2.9, -4.5]
    assert lg.skipped == {"height.csv": 2, "baro.csv": 1, "tdoa.csv": 1}


CASES = [
    (
        "height.csv",
        "t_s, range_m\n0.0,0.5\n0.1,-0.2\n",
        r"^height\.csv, line 3, column 2 \(range_m\): negative range -0\.2$",
    ),
    (
        "height.csv",
        "t_s, range_m\n0.1,0.5\n0.1,0.6\n",
        r"^height\.csv, line 3, column 1 \(t_s\): time 0\.1 is not after the previous sample's 0\.1 "
        r"\(line 2\)",
    ),
    (
        "height.csv",
        "t_s, range_m\n0.0,high\n",
        r"^height\.csv, line 2, column 2 \(range_m\): not a number: 'high'$",
    ),
    (
        "baro.csv",
        "t_s, height_m\n0.2,1\n0.1,2\n",
        r"^baro\.csv, line 3, column 1 \(t_s\): time 0\.1 is not after the previous sample's 0\.2",
    ),
    ("baro.csv", "t_s, height_m\nabc,1\n", r"^baro\.csv, line 2, column 1 \(t_s\): not a number: 'abc'$"),
    (
        "tdoa.csv",
        "t_s, anchor_a, anchor_b, ddist_m\n0.0,3,9,1.0\n",
        r"^tdoa\.csv, line 2, column 3 \(anchor_b\): unknown anchor 9; anchors\.csv has 3, 5, 7$",
    ),
    (
        "tdoa.csv",
        "t_s, anchor_a, anchor_b, ddist_m\n0.0,3,5,1.0\n0.1,5,5,0.0\n",
        r"^tdoa\.csv, line 3, column 3 \(anchor_b\): anchor 5 is also anchor_a",
    ),
    (
        "tdoa.csv",
        "t_s, anchor_a, anchor_b, ddist_m\n0.0,3,5,4.2\n",
        r"^tdoa\.csv, line 2, column 4 \(ddist_m\): \|4\.2\| is longer than the 4\.000 m between anchors "
        r"3 and 5",
    ),
    (
        "tdoa.csv",
        "t_s, anchor_a, anchor_b, ddist_m\n0.2,3,5,1.0\n0.1,3,5,1.0\n",
        r"^tdoa\.csv, line 3, column 1 \(t_s\): time 0\.1 is not at or after the previous sample's 0\.2",
    ),
    (
        "tdoa.csv",
        "t_s, anchor_a, anchor_b, ddist_m\n0.0,3.5,5,1.0\n",
        r"^tdoa\.csv, line 2, column 2 \(anchor_a\): unknown anchor 3\.5",
    ),
    ("tdoa.csv", "t_s, anchor_a, ddist_m\n0.0,3,1.0\n", r"^tdoa\.csv, line 1: missing column 'anchor_b'"),
    (
        "tdoa.csv",
        "t_s, anchor_a, anchor_b, ddist_m\n0.0,3,x,1.0\n",
        r"^tdoa\.csv, line 2, column 3 \(anchor_b\): not a number: 'x'$",
    ),
]


@pytest.mark.parametrize(("name", "text", "pattern"), CASES, ids=[f"{c[0]}-{i}" for i, c in enumerate(CASES)])
def test_a_bad_row_is_refused_naming_file_line_column_and_value(log, name, text, pattern):
    (log / name).write_text(text)
    with pytest.raises(LogError, match=pattern):
        read_log(log)


def test_the_baseline_tolerance_lets_a_rounded_difference_pass(log):
    # 3-5 are 4 m apart; a difference just inside the tolerance is rounding, just outside is refused
    (log / "tdoa.csv").write_text(
        f"t_s, anchor_a, anchor_b, ddist_m\n0.0,3,5,{4.0 + 0.9 * TDOA_BASELINE_TOL_M}\n"
    )
    assert read_log(log).tdoa_ddist[0] == pytest.approx(4.0 + 0.9 * TDOA_BASELINE_TOL_M)
    (log / "tdoa.csv").write_text(
        f"t_s, anchor_a, anchor_b, ddist_m\n0.0,3,5,-{4.0 + 1.1 * TDOA_BASELINE_TOL_M}\n"
    )
    with pytest.raises(LogError, match=r"ddist_m\): \|-4\.1"):
        read_log(log)


def test_a_uwb_csv_and_anchors_csv_without_rows_are_a_log_without_ranges(log):
    (log / "uwb.csv").write_text("t_s, anchor_id, range_m\n")
    (log / "anchors.csv").write_text("anchor_id, x_m, y_m, z_m\n")
    lg = read_log(log)
    assert len(lg.uwb_t) == 0 and lg.anchors_nav.shape == (0, 3) and len(lg.imu_t) == 3
    # a TDoA row then names an anchor that is not there
    (log / "tdoa.csv").write_text("t_s, anchor_a, anchor_b, ddist_m\n0.0,3,5,1.0\n")
    with pytest.raises(LogError, match=r"unknown anchor 3; anchors\.csv has none$"):
        read_log(log)


def test_imu_csv_without_rows_is_still_refused(log):
    (log / "imu.csv").write_text(IMU.splitlines()[0] + "\n")
    with pytest.raises(LogError, match=r"^imu\.csv: no data rows after the header$"):
        read_log(log)
