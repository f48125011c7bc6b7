"""Replay of synthetic logs made by our own flight simulator (swarm.logs.synthetic) with what real logs have:
1 kHz IMU with biases, ranges with 0.2-0.5 m per-anchor biases that drift, one NLOS anchor, dropouts and
clock jitter. Bounds are stated next to each assertion."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy.stats import chi2

from swarm.core import _imu_nb as nb
from swarm.logs.reader import read_log
from swarm.logs.replay import replay_log
from swarm.logs.synthetic import SyntheticSpec, make_log


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    d = tmp_path_factory.mktemp("flight")
    info = make_log(d, seed=1)
    return d, info, replay_log(read_log(d))


def test_replay_is_accurate_and_consistent_on_a_realistic_log(flight):
    _, _, r = flight
    s = r.summary()
    # 8 anchors, 5 cm ranging noise, one NLOS anchor: the issue's ~0.15 m for a real flight is the bar;
    # synthetic data that match the model do 3x better (0.04-0.07 m over seeds)
    assert s["rmse_m"] < 0.10
    assert max(s["rmse_axis_m"]) < 0.08
    # a consistent filter's position NEES averages 3; one run's mean lies well inside [1, 6]
    assert 1.0 < s["nees_mean"] < 6.0
    # 95 % nominal, counted in flight: on the pad the pinned estimate does not move from the surveyed
    # position (zero-velocity pin, docs/logs.md), so its NEES sits under the band's lower end there
    inside, e, _ = r.errors()
    flying = r.t[inside] > s["events"][0]["t_s"]
    nees = np.einsum("ni,ni->n", e, np.linalg.solve(r.P[inside, :3, :3], e[..., None])[..., 0])[flying]
    lo, hi = s["nees_band"]
    assert np.mean((nees >= lo) & (nees <= hi)) > 0.85
    assert 0.7 < s["nis_mean"] < 1.5  # accepted ranges' NIS: chi-square(1) mean 1, gate-truncated
    assert [e["kind"] for e in s["events"]] == ["takeoff"]  # no false divergence on a healthy flight
    # the synthetic vehicle leaves the pad at 5 s; its IMU has no rotor vibration, so the take-off is seen
    # when the estimate is 0.3 m over the pad ([phases] takeoff_height_m) for 0.5 s
    assert 5.0 < s["events"][0]["t_s"] < 8.0
    assert s["dropped_out_of_order"] == 0 and s["skipped_rows"]["uwb.csv"] > 0


def test_the_bias_states_converge(flight):
    _, info, r = flight
    # range biases 0.2-0.5 m that drift: each estimate within 5 cm of the truth at the end (~4 sigma of its
    # final 1 cm standard deviation, with margin for the drift since the last ranges)
    # (the model's range bias is the common offset plus the anchor's own); the NLOS anchor's to 10 cm: its
    # ranges that pass the gate still carry some of the exponential excess
    clear = np.arange(len(r.offset_total_m)) != info["nlos_anchor"]
    np.testing.assert_allclose(r.offset_total_m[clear], info["range_bias_final"][clear], atol=0.05)
    assert abs(r.offset_total_m[~clear][0] - info["range_bias_final"][~clear][0]) < 0.10
    # the gyro bias (5 mrad/s drawn) to 1.5 mrad/s: observable through attitude-dependent specific force
    np.testing.assert_allclose(r.gyro_bias, info["gyro_bias"], atol=1.5e-3)
    # the accelerometer bias along gravity (z) to 2 cm/s^2; the horizontal parts are weakly observable
    assert abs(r.accel_bias[2] - info["accel_bias"][2]) < 0.02


def test_the_nlos_anchor_is_mostly_rejected_and_the_others_are_not(flight):
    _, info, r = flight
    a = info["nlos_anchor"]
    nlos = np.zeros(len(r.nis_t), dtype=bool)
    idx = np.searchsorted(r.nis_t, info["nlos_t"]).clip(1, len(r.nis_t) - 1)
    idx -= np.abs(r.nis_t[idx - 1] - info["nlos_t"]) < np.abs(r.nis_t[idx] - info["nlos_t"])  # the nearest
    close = np.abs(r.nis_t[idx] - info["nlos_t"]) < 1e-5  # the CSV keeps microseconds
    nlos[idx[close]] = True
    assert nlos.sum() > 200
    # an NLOS excess is exponential with a 1 m mean: most exceed the ~3.7 sigma gate (~0.2 m here)
    assert (r.nis_outcome[nlos] == nb.REJECTED).mean() > 0.7
    # the other anchors' ranges (the NLOS anchor's clean ones between its long ones are held out with them
    # while its episode detector holds it)
    clean = ~nlos & (r.nis_outcome >= 0) & (r.nis_anchor != a)
    assert (r.nis_outcome[clean] == nb.REJECTED).mean() < 0.01  # 0.05 % gate, plus the bias drift
    shares = r.summary()["rejected_share_by_anchor"]
    assert shares[str(a)] == max(shares.values())


def test_recovery_after_a_forced_divergence(flight):
    """The position jumps 5 m with a 1 cm sigma (an overconfident, wrong filter): the gate then rejects every
    range, the windowed test says so within a window of ranges, and the fix from ranges brings it back."""
    d, _, _ = flight
    for mode, action in (
        ("inflate", "position and velocity covariance inflated"),
        ("refix", "position re-initialised from ranges"),
    ):
        r = replay_log(read_log(d, {"faults.jump_at_s": 30.0, "recovery.mode": mode}))
        resets = [e for e in r.events if e["kind"] not in ("takeoff", "landing")]
        assert [e["kind"] for e in resets] == ["fault", "estimator_reset"]  # one reset, no second
        reset = resets[1]
        assert 30.0 < reset["t_s"] < 31.0  # 50 ranges at 80 Hz: 0.6 s
        assert reset["reject_share"] > 0.5 and reset["action"] == action
        inside, e, _ = r.errors()
        t = r.t[inside]
        after = np.linalg.norm(e[t > reset["t_s"] + 5.0], axis=1)
        assert np.sqrt(np.mean(after**2)) < 0.10  # back to the accuracy of the healthy flight
    # inflating covers the 5 m error: the added sigma is of the jump's size (the largest innovations)
    assert 2.0 < resets[1]["sigma_added_m"] if mode == "inflate" else True
    # without recovery the same fault is only reported, and the filter stays lost
    lost = replay_log(read_log(d, {"faults.jump_at_s": 30.0, "recovery.enabled": False}))
    lost_resets = [e for e in lost.events if e["kind"] == "estimator_reset"]
    assert lost_resets[0]["action"].startswith("reported only")
    inside, e, _ = lost.errors()
    # (5 s after the fault, when the recovered filter is back under 0.1 m; a lone filter creeps back only
    # over tens of seconds, as its offsets re-open)
    t_lost = lost.t[inside]
    assert np.median(np.linalg.norm(e[(t_lost > 35.0) & (t_lost < 40.0)], axis=1)) > 1.0


def test_monte_carlo_nees_stays_inside_its_band(tmp_path):
    """Ten synthetic flights (30 s, seeds 0-9) with the model's range noise (uwb.sigma_m = 0.05: a
    calibrated sigma from 50 static ranges is itself +-10 % off, which is a tuning error, not the filter's).
    The average position NEES of N runs is chi-square(3N)/N at each time for a consistent filter; its 95 %
    band must hold at >= 90 % of the flight's times (after the 8 s of static start and take-off, where the
    error starts at ~0 by construction). Measured: 95 % for these seeds (71 % with the default Gauss-Markov
    term, which this log does not have: a conservative filter)."""
    runs = 10
    nees = []
    for seed in range(runs):
        d = tmp_path / str(seed)
        make_log(d, seed=seed, spec=SyntheticSpec(duration_s=30.0))
        # this log's range errors are white plus a slow per-anchor drift: no Gauss-Markov term in the model
        r = replay_log(read_log(d, {"uwb.sigma_m": 0.05, "estimator.range_gm": False}))
        inside, e, _ = r.errors()
        P = r.P[inside, 0:3, 0:3]
        nees.append(np.einsum("ni,ni->n", e, np.linalg.solve(P, e[..., None])[..., 0]))
        t = r.t[inside]
    n = min(len(x) for x in nees)
    mean = np.mean([x[:n] for x in nees], axis=0)
    lo, hi = chi2.ppf([0.025, 0.975], 3 * runs) / runs
    flight_times = t[:n] >= 8.0
    inside_band = (mean[flight_times] >= lo) & (mean[flight_times] <= hi)
    assert inside_band.mean() >= 0.90


def test_the_cli_writes_the_report_the_series_and_the_plot(flight, tmp_path):
    d, _, _ = flight
    out, series, png = tmp_path / "r.json", tmp_path / "s.csv", tmp_path / "p.png"
    args = [
        sys.executable,
        "-m",
        "swarm.cli.main",
        "replay",
        str(d),
        "--json",
        str(out),
        "--series",
        str(series),
        "--plot",
        str(png),
        "--set",
        "estimator.huber_k=3",
    ]
    r = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    rep = json.loads(out.read_text())
    for key in ("rmse_m", "rmse_axis_m", "nees_mean", "rejected_share_by_anchor"):
        assert key in rep
    assert len(rep["rmse_axis_m"]) == 3 and set(rep["rejected_share_by_anchor"]) == {str(i) for i in range(8)}
    header = series.read_text().splitlines()[0].split(",")
    assert header[:4] == ["t_s", "x_m", "y_m", "z_m"] and "err_x_m" in header
    assert png.stat().st_size > 10_000 and "RMSE" in r.stdout


def test_the_cli_refuses_a_bad_log_with_one_clear_line(flight, tmp_path):
    import shutil

    d, _, _ = flight
    bad = tmp_path / "bad"
    shutil.copytree(d, bad)
    lines = (bad / "uwb.csv").read_text().splitlines()
    lines[3] = "x" + lines[3]
    (bad / "uwb.csv").write_text("\n".join(lines) + "\n")
    r = subprocess.run(
        [sys.executable, "-m", "swarm.cli.main", "replay", str(bad), "--series", "-"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2
    assert (
        r.stderr.strip().startswith("swarm: error: uwb.csv, line 4, column 1 (t_s): not a number")
        and "Traceback" not in r.stderr
    )
