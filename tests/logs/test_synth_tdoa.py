"""``swarm synth-log --tdoa``: the synthetic flight heard by a passive tag on the TDoA radio
(:mod:`swarm.logs.synth_tdoa`). Oracles: the flight's truth (:func:`swarm.logs.synthetic.truth_at`), the log's
own drawn biases, and the radio's closed-form rate (:func:`swarm.core.tdoa_radio.expected_rates`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm.cli.main import main
from swarm.core import rotations as rot
from swarm.core import tdoa_radio as tr
from swarm.logs.reader import read_log
from swarm.logs.synthetic import ANCHORS, SyntheticSpec, make_log, truth_at
from swarm.sensors.profile import ImuProfile, SensorProfile, UwbProfile

SPEC = SyntheticSpec(duration_s=25.0, tdoa="tdoa3")


def _residual(d, spec: SyntheticSpec, info: dict, steps_from_s: float):
    """Rows of ``tdoa.csv`` and their residual against the truth at the row's time minus the log's own
    per-anchor biases (and steps from ``steps_from_s``), entering as ``e_B - e_A``."""
    rows = np.loadtxt(d / "tdoa.csv", delimiter=",", skiprows=1)
    t, a, b = rows[:, 0], rows[:, 1].astype(int), rows[:, 2].astype(int)
    p, _, q, _, _ = truth_at(spec, t)
    tag = p + rot.quat_rotate(q, np.broadcast_to(np.asarray(spec.lever_arm_m), p.shape))
    geo = np.linalg.norm(tag - ANCHORS[b], axis=1) - np.linalg.norm(tag - ANCHORS[a], axis=1)
    b0, step = info["range_bias_static"], info["range_bias_step"]
    bias = b0[b] - b0[a] + (t >= steps_from_s) * (step[b] - step[a])
    return t, a, b, rows[:, 3] - geo - bias


def test_a_tdoa_log_has_the_same_flight_and_no_ranges(tmp_path):
    make_log(tmp_path / "twr", 4, SyntheticSpec(duration_s=12.0))
    info = make_log(tmp_path / "tdoa", 4, SyntheticSpec(duration_s=12.0, tdoa="tdoa3"))
    for name in ("imu.csv", "truth.csv", "anchors.csv"):
        assert (tmp_path / "twr" / name).read_bytes() == (tmp_path / "tdoa" / name).read_bytes()
    assert (tmp_path / "tdoa" / "uwb.csv").read_text().strip() == "t_s,anchor_id,range_m"
    log = read_log(tmp_path / "tdoa")
    written = info["tdoa"]["counts"]["rows"] - info["tdoa"]["beyond_baseline"]
    assert len(log.uwb_t) == 0 and len(log.tdoa_t) == written > 3000
    assert log.config.tdoa.sigma_m == pytest.approx(math.sqrt(2) * 0.05, rel=1e-5)
    # its anchors carry constant offsets of 0.2-0.5 m: the log says so, and the replay estimates them (a TDoA
    # log has no offset states by default, TdoaLog.offsets)
    assert log.config.tdoa.offsets
    assert not (tmp_path / "twr" / "tdoa.csv").exists()


def test_differences_against_the_truth_have_the_modelled_statistics(tmp_path):
    info = make_log(tmp_path, 2, SPEC)
    t, a, b, r = _residual(tmp_path, SPEC, info, SPEC.static_s + SPEC.takeoff_s)
    # white sqrt(2) 0.05 per difference; the truth taken at the row's time, not at the two receptions,
    # adds the motion over ~10 ms (< 1 cm at ~1 m/s, in quadrature 1 %): 7000 rows give the sd to ~1 %
    assert np.std(r) == pytest.approx(math.sqrt(2) * 0.05, rel=0.05)
    assert abs(np.mean(r)) < 0.003
    # each ordered pair's mean is its bias difference: nothing left per pair beyond 4 standard errors
    for i in range(8):
        for j in range(8):
            sel = (a == i) & (b == j)
            if sel.sum() > 20:
                assert abs(r[sel].mean()) < 4 * 0.0707 / math.sqrt(sel.sum()) + 0.002
    # the rate: the radio's closed form for a tag that misses range_loss of the packets (3 %: 4 sd)
    e = tr.expected_rates(tr.TdoaParams(tag_loss=SPEC.range_loss), 8)
    assert len(t) / SPEC.duration_s == pytest.approx(e.measurements_per_tag_hz, rel=0.03)


def test_an_nlos_anchor_makes_all_its_pairs_long_in_flight(tmp_path):
    spec = SyntheticSpec(duration_s=25.0, tdoa="tdoa3", tdoa_nlos_anchor=2)
    info = make_log(tmp_path, 5, spec)
    t, a, b, r = _residual(tmp_path, spec, info, spec.static_s + spec.takeoff_s)
    air = t >= spec.static_s + spec.takeoff_s
    # long on 60 % of its packets by an exponential of mean 1 m: +0.6 m on average as B, -0.6 m as A;
    # ~650 rows each with an sd of ~0.95 m: 4 standard errors ~0.15 m (12 seeds: 0.50-0.68 in size, the
    # rows beyond their baseline not written)
    assert np.mean(r[air & (b == 2)]) == pytest.approx(0.6, abs=0.15)
    assert np.mean(r[air & (a == 2)]) == pytest.approx(-0.6, abs=0.15)
    assert np.percentile(r[air & (b == 2)], 25) > -0.15  # mostly long, never much short
    clear = (a != 2) & (b != 2)
    assert np.std(r[air & clear]) == pytest.approx(math.sqrt(2) * 0.05, rel=0.08)
    ground = (t < spec.static_s) & ~clear
    assert np.std(r[ground]) == pytest.approx(
        math.sqrt(2) * 0.05, rel=0.15
    )  # on the pad: no NLOS (12 seeds: 5 %)
    assert info["tdoa"]["nlos_anchor"] == 2
    # rows longer than their baseline are not written (the reader would refuse them): a few of the NLOS ones
    rows = np.loadtxt(tmp_path / "tdoa.csv", delimiter=",", skiprows=1)
    base = np.linalg.norm(ANCHORS[rows[:, 1].astype(int)] - ANCHORS[rows[:, 2].astype(int)], axis=1)
    assert np.all(np.abs(rows[:, 3]) <= base) and info["tdoa"]["beyond_baseline"] > 0


def test_a_profile_gives_its_multipath_per_anchor_as_differences(tmp_path):
    # a fast multipath (tau 0.2 s: ~100 independent values per anchor in flight) so that its variance is
    # measured to a few per cent; no NLOS and no outliers, so the sd is the model's
    uwb = UwbProfile(
        sigma_m=0.02, ground_sigma_m=0.02, offset_m=-0.3, offset_spread_m=0.08, takeoff_step_m=0.05,
        takeoff_step_spread_m=0.04, gm_sigma_m=0.05, gm_tau_s=0.2,
    )  # fmt: skip
    profile = SensorProfile(name="fast-multipath", uwb=uwb, imu=ImuProfile())
    info = make_log(tmp_path, 7, SPEC, profile)
    t, _, _, r = _residual(tmp_path, SPEC, info, SPEC.static_s)
    air = t >= SPEC.static_s + 0.5
    ground = t < SPEC.static_s
    # in flight: white sqrt(2) 0.02 and two independent Gauss-Markov terms of 0.05: sqrt(0.0008 + 0.005)
    assert np.std(r[air]) == pytest.approx(math.sqrt(2 * 0.02**2 + 2 * 0.05**2), rel=0.08)
    # on the pad the multipath is off: the white noise alone
    assert np.std(r[ground]) == pytest.approx(math.sqrt(2) * 0.02, rel=0.1)
    # the offsets are the profile's spread around -0.3 (they cancel in part: only differences are seen)
    assert info["range_bias_static"].mean() == pytest.approx(-0.3, abs=0.1)


def test_the_cli_writes_a_tdoa_log(tmp_path, capsys):
    d = tmp_path / "log"
    assert main(["synth-log", str(d), "--duration", "10", "--tdoa", "tdoa2", "--tdoa-nlos", "1"]) == 0
    assert "tdoa.csv" in capsys.readouterr().out
    rows = np.loadtxt(d / "tdoa.csv", delimiter=",", skiprows=1)
    # TDoA2 pairs are mostly a slot's anchor and the previous slot's (8 anchors in a ring)
    assert np.mean((rows[:, 2] - rows[:, 1]) % 8 == 1) > 0.9
    with pytest.raises(SystemExit):
        main(["synth-log", str(d), "--tdoa", "tdoa4"])
