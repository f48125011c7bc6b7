"""swarm bench real-flights: what a user reads off the truth (pad, heading, static segment only when the gyro
is quiet) and the row it reports, on synthetic flights the test makes."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.bench import real_flights
from swarm.logs.synthetic import SyntheticSpec, make_log


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    d = tmp_path_factory.mktemp("rf")
    info = make_log(d, seed=3, spec=SyntheticSpec(duration_s=20.0))
    # the synthetic log.toml states the calibration; a user's imported log does not: keep only the name
    (d / "log.toml").write_text('name = "imported"\n')
    return d, info


def test_the_pad_heading_and_static_segment_come_from_the_truth(flight):
    d, _ = flight
    keys = real_flights.user_keys(d)
    truth = np.loadtxt(d / "truth.csv", delimiter=",", skiprows=1)
    # the synthetic vehicle stands 5 s and rises after: the segment ends 1 s before the truth rises 5 cm
    rise = truth[np.argmax(truth[:, 3] > truth[0, 3] + 0.05), 0]
    assert keys["calibration.until_s"] == pytest.approx(rise - 1.0, abs=1e-3) and 4.0 < rise < 8.0
    assert keys["calibration.position_m"] == pytest.approx(list(truth[0, 1:4]), abs=1e-4)
    assert keys["initial.yaw_deg"] == pytest.approx(SyntheticSpec().yaw0_deg, abs=0.5)


def test_a_log_that_starts_with_the_rotors_spinning_gets_no_static_segment(flight, tmp_path):
    d, _ = flight
    spun = tmp_path / "spun"
    spun.mkdir()
    for f in d.iterdir():
        (spun / f.name).write_text(f.read_text())
    imu = np.loadtxt(spun / "imu.csv", delimiter=",", skiprows=1)
    imu[:, 3] += 0.09  # yawing at 0.09 rad/s before take-off, as the UTIL TDoA logs do
    header = (d / "imu.csv").read_text().splitlines()[0]
    np.savetxt(spun / "imu.csv", imu, delimiter=",", header=header, comments="", fmt="%.6f")
    keys = real_flights.user_keys(spun)
    assert keys["calibration.until_s"] == 0.0 and "initial.position_m" in keys


def test_the_row_reports_the_replay(flight):
    d, _ = flight
    record, table = real_flights.run([d])
    row = record["flights"][0]
    assert row["mode"] == "twr" and row["resets"] == 0 and row["rmse_m"] < 0.10
    assert 0.0 < row["rmse_airborne_m"] < 0.10  # the flight after the take-off, scored alone
    assert 0.0 < row["nees_in_band_share"] <= 1.0 and row["wall_per_60_s"] > 0
    assert d.name in table and "| twr |" in table
