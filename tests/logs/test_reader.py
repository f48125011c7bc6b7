"""A bad log is refused with the file, line and column named; a NaN sample is skipped and counted."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from swarm.errors import ConfigError, LogError
from swarm.logs.reader import read_log
from swarm.logs.synthetic import SyntheticSpec, make_log


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    d = tmp_path_factory.mktemp("log") / "good"
    make_log(d, seed=2, spec=SyntheticSpec(duration_s=10.0))
    return d


@pytest.fixture
def log(good, tmp_path):
    d = tmp_path / "log"
    shutil.copytree(good, d)
    return d


def _edit(path, line_no, new):
    lines = path.read_text().splitlines()
    lines[line_no - 1] = new(lines[line_no - 1]) if callable(new) else new
    path.write_text("\n".join(lines) + "\n")


def _field(i, value):
    def edit(line):
        parts = line.split(",")
        parts[i] = value
        return ",".join(parts)

    return edit


def test_the_synthetic_log_reads_back_whole(good):
    lg = read_log(good)
    assert len(lg.imu_t) > 9900 and len(lg.anchors_nav) == 8 and lg.truth_p is not None
    assert np.all(np.diff(lg.imu_t) > 0) and np.isfinite(lg.uwb_range).all()
    assert lg.skipped["uwb.csv"] > 0  # the lost replies the logger wrote as nan


CASES = [
    (
        "imu.csv",
        1,
        lambda ln: ln.replace("acc_z_m_s2", "acc_z"),
        r"^imu\.csv, line 1: missing column 'acc_z_m_s2'",
    ),
    (
        "imu.csv",
        5,
        lambda ln: _field(0, "0.5")(ln),
        r"^imu\.csv, line 6, column 1 \(t_s\): time .* is not after the previous sample's 0\.5 \(line 5\)",
    ),
    ("imu.csv", 7, _field(0, "nan"), r"^imu\.csv, line 7, column 1 \(t_s\): nan is not a finite number"),
    ("imu.csv", 9, _field(4, "abc"), r"^imu\.csv, line 9, column 5 \(acc_x_m_s2\): not a number: 'abc'"),
    ("imu.csv", 11, lambda ln: ln + ",1.0", r"^imu\.csv, line 11: 8 fields, the header has 7"),
    (
        "imu.csv",
        13,
        _field(2, "inf"),
        r"^imu\.csv, line 13, column 3 \(gyro_y_rad_s\): inf is not a finite number",
    ),
    (
        "uwb.csv",
        4,
        _field(1, "9"),
        r"^uwb\.csv, line 4, column 2 \(anchor_id\): unknown anchor 9; anchors\.csv has 0, 1, 2",
    ),
    ("uwb.csv", 6, _field(2, "-1.5"), r"^uwb\.csv, line 6, column 3 \(range_m\): negative range -1\.5"),
    (
        "uwb.csv",
        8,
        _field(0, "0.0"),
        r"^uwb\.csv, line 8, column 1 \(t_s\): time 0\.0 is not at or after the previous sample's .* "
        r"\(line 7\)",
    ),
    ("anchors.csv", 3, _field(2, "x"), r"^anchors\.csv, line 3, column 3 \(y_m\): not a number: 'x'"),
    ("anchors.csv", 3, _field(0, "0"), r"^anchors\.csv: anchor 0 is listed twice"),
    ("truth.csv", 5, _field(7, "0.5"), r"^truth\.csv, line 5, column 5 \(qx\): quaternion norm"),
]


@pytest.mark.parametrize("name, line, edit, expected", CASES, ids=[c[3][1:40] for c in CASES])
def test_each_kind_of_bad_file_is_refused_naming_file_line_and_column(log, name, line, edit, expected):
    _edit(log / name, line, edit)
    with pytest.raises(LogError, match=expected):
        read_log(log)


def test_a_missing_file_or_folder_is_named(log, tmp_path):
    (log / "uwb.csv").unlink()
    with pytest.raises(
        LogError, match=r"uwb\.csv: missing \(a log folder needs imu\.csv, uwb\.csv and anchors\.csv"
    ):
        read_log(log)
    with pytest.raises(LogError, match=r"not a folder"):
        read_log(tmp_path / "nowhere")


def test_an_empty_file_and_a_header_without_rows_are_refused(log):
    (log / "imu.csv").write_text("")
    with pytest.raises(LogError, match=r"^imu\.csv: empty \(expected a header line: t_s, gyro_x_rad_s"):
        read_log(log)
    (log / "imu.csv").write_text(
        "t_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,acc_x_m_s2,acc_y_m_s2,acc_z_m_s2\n"
    )
    with pytest.raises(LogError, match=r"^imu\.csv: no data rows after the header"):
        read_log(log)


def test_a_nan_sample_is_skipped_and_counted_never_fed(log, good):
    before = read_log(good)
    _edit(log / "imu.csv", 20, _field(3, "nan"))
    _edit(log / "imu.csv", 30, _field(6, ""))
    lg = read_log(log)
    assert lg.skipped["imu.csv"] == 2 and len(lg.imu_t) == len(before.imu_t) - 2
    assert np.isfinite(lg.gyro).all() and np.isfinite(lg.acc).all()


def test_columns_may_come_in_any_order_and_extra_columns_are_ignored(log, good):
    text = (log / "anchors.csv").read_text().splitlines()
    rows = [ln.split(",") for ln in text]
    (log / "anchors.csv").write_text(
        "\n".join(",".join([r[3], r[0], r[1], r[2], "note"]) for r in rows[:1])
        + "\n"
        + "\n".join(",".join([r[3], r[0], r[1], r[2], "x"]) for r in rows[1:])
        + "\n"
    )
    assert np.array_equal(read_log(log).anchors_nav, read_log(good).anchors_nav)


def test_a_bad_log_toml_names_the_file_and_the_key(log):
    with open(log / "log.toml", "a") as fh:
        fh.write("\n[uwb]\nsigma_m = -1\n")
    with pytest.raises(ConfigError, match=r"log\.toml: uwb\.sigma_m must be a finite number > 0, got -1"):
        read_log(log)
    (log / "log.toml").write_text("[estimator\n")
    with pytest.raises(ConfigError, match=r"log\.toml: invalid TOML: .*line 1"):
        read_log(log)


def test_an_override_names_itself(good):
    with pytest.raises(
        ConfigError, match=r"estimator\.huber_k must be >= 0 .* \(value set by override estimator\.huber_k\)"
    ):
        read_log(good, {"estimator.huber_k": -2})
