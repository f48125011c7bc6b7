"""The reader's numpy fast path (a well-formed CSV file in one loadtxt call) gives what the row-by-row
parser gives, skips and counts the same NaN rows, and hands every file it does not take to that parser,
which names the error."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.errors import LogError
from swarm.logs.reader import read_log
from swarm.logs.synthetic import SyntheticSpec, make_log


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    d = tmp_path_factory.mktemp("fast")
    make_log(d, seed=5, spec=SyntheticSpec(duration_s=8.0))
    return d


def test_the_fast_path_equals_the_careful_parser(flight, tmp_path):
    fast = read_log(flight)
    # the same files with a comment line: the fast path declines them, the careful parser reads them
    slow_dir = tmp_path / "slow"
    slow_dir.mkdir()
    for f in flight.iterdir():
        text = f.read_text()
        if f.suffix == ".csv":
            head, _, body = text.partition("\n")
            text = f"{head}\n# a comment sends this file to the careful parser\n{body}"
        (slow_dir / f.name).write_text(text)
    slow = read_log(slow_dir)
    for name in ("imu_t", "gyro", "acc", "uwb_t", "uwb_anchor", "uwb_range", "anchors_nav", "truth_p"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name), err_msg=name)
    assert fast.skipped == slow.skipped and fast.skipped["uwb.csv"] > 0  # lost replies written as nan


def test_a_bad_value_is_still_named_by_file_line_and_column(flight, tmp_path):
    d = tmp_path / "bad"
    d.mkdir()
    for f in flight.iterdir():
        (d / f.name).write_text(f.read_text())
    lines = (d / "imu.csv").read_text().splitlines()
    fields = lines[5].split(",")
    fields[4] = "inf"
    lines[5] = ",".join(fields)
    (d / "imu.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(
        LogError, match=r"imu\.csv, line 6, column 5 \(acc_x_m_s2\): inf is not a finite number"
    ):
        read_log(d)
