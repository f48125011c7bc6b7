"""``swarm bench peer`` (swarm/bench/peer_util.py) without the UTIL authors' code: a stand-in
``eskf_class.py`` with their interface (``ESKF(X0, q0, P0, K)``, ``predict(imu, dt, imu_check, k)``,
``UWB_correct(uwb, anchor_position, k)``, module ``GRAVITY_MAGNITUDE``, ``DEG_TO_RAD``, ``Quaternion``) is
written by each test and records what the adapter hands it. Their ``main.py`` (util-uwb-dataset,
``scripts/estimation``) is the reference for what must arrive: specific force in g and rates in deg/s in
the Crazyflie body frame (x forward, z up: ours), ``(idA, idB, d_B - d_A)`` rows, anchors indexed by id,
every 8th sample of each stream, TDoA2 only on the ring pairs ``(i, i+1 mod 8)``."""

from __future__ import annotations

import json
import math
import textwrap

import numpy as np
import pytest

from swarm.bench import peer_util as pu
from swarm.errors import ConfigError

STAND_IN = textwrap.dedent(
    '''
    """A stand-in with the interface of the UTIL authors' eskf_class.py: it records its inputs, keeps its
    state still and its covariance at P0, and converts units as theirs does."""
    import math
    import numpy as np

    GRAVITY_MAGNITUDE = 9.81
    DEG_TO_RAD = math.pi / 180.0
    CALLS = []

    class Quaternion:
        def __init__(self, q):
            self.w, self.x, self.y, self.z = (float(v) for v in q)

    class ESKF:
        def __init__(self, X0, q0, P0, K):
            self.std_uwb_tdoa = math.sqrt(0.05)
            self.Xpr = np.zeros((K, 6)); self.Xpo = np.zeros((K, 6))
            self.Ppr = np.zeros((K, 9, 9)); self.Ppo = np.zeros((K, 9, 9))
            self.q_list = np.zeros((K, 4))
            self.Xpo[0] = X0.T; self.Ppo[0] = P0
            self.q_list[0] = [q0.w, q0.x, q0.y, q0.z]
            CALLS.append(("init", X0.copy(), P0.copy(), K))

        def predict(self, imu, dt, imu_check, k):
            f_si = imu[0:3] * GRAVITY_MAGNITUDE if imu_check else None
            w_si = imu[3:] * DEG_TO_RAD if imu_check else None
            CALLS.append(("predict", k, float(dt), bool(imu_check), np.array(imu), f_si, w_si))
            self.Xpr[k] = self.Xpo[k] = self.Xpo[k - 1]
            self.Ppr[k] = self.Ppo[k] = self.Ppo[k - 1]
            self.q_list[k] = self.q_list[k - 1]

        def UWB_correct(self, uwb, anchor_position, k):
            CALLS.append(("uwb", k, np.array(uwb), np.array(anchor_position)))
            if int(uwb[0]) == 9:  # a row it rejects (Ppo left equal to Ppr, as theirs does)
                return
            self.Ppo[k] = self.Ppr[k]
            self.Ppo[k, 8, 8] *= 0.999  # accepted: P changes (yaw only; the position block kept)
    '''
)

ANCHORS = {  # id -> position [m]; ids 0..7 of a TDoA2 ring, plus an id gap (8 absent, 9 present)
    0: (-4.0, -4.0, 0.2), 1: (-4.0, 4.0, 3.0), 2: (4.0, 4.0, 0.2), 3: (4.0, -4.0, 3.0),
    4: (-4.0, -4.0, 3.0), 5: (4.0, -4.0, 0.2), 6: (4.0, 4.0, 3.0), 7: (-4.0, 4.0, 0.2),
    9: (0.0, 0.0, 3.5),
}  # fmt: skip
P_TRUE = np.array([1.35, 0.0, 0.07])
"""The truth stands still here (the stand-in's estimate stays at X0)."""
GYRO = np.array([0.1, -0.2, 0.3])
"""Rad/s per axis, all different so that a swapped axis shows."""
ACC = np.array([1.0, -2.0, 9.81])
"""Specific force [m/s^2] per axis."""


def _ddist(a: int, b: int) -> float:
    p = P_TRUE
    return float(np.linalg.norm(p - ANCHORS[b]) - np.linalg.norm(p - ANCHORS[a]))


def _write_log(d, pairs, n_imu=200, imu_dt=1e-3, tdoa_dt=2.5e-3, twr=False):
    """A tiny log folder: ``n_imu`` IMU rows, TDoA rows cycling over ``pairs`` (time offset from the IMU's
    by half a period, so the two streams never share a time), a still truth."""
    d.mkdir()
    imu_t = np.arange(n_imu) * imu_dt
    rows = [f"{t:.6f},{GYRO[0]},{GYRO[1]},{GYRO[2]},{ACC[0]},{ACC[1]},{ACC[2]}" for t in imu_t]
    (d / "imu.csv").write_text(
        "t_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,acc_x_m_s2,acc_y_m_s2,acc_z_m_s2\n"
        + "\n".join(rows)
        + "\n"
    )
    (d / "anchors.csv").write_text(
        "anchor_id,x_m,y_m,z_m\n" + "".join(f"{i},{x},{y},{z}\n" for i, (x, y, z) in ANCHORS.items())
    )
    uwb = "t_s,anchor_id,range_m\n"
    if twr:
        uwb += "".join(f"{t + 5e-4:.6f},{i % 8},3.0\n" for i, t in enumerate(imu_t[::10]))
    (d / "uwb.csv").write_text(uwb)
    truth_t = np.arange(0.0, imu_t[-1] + 0.01, 0.01)
    (d / "truth.csv").write_text(
        "t_s,x_m,y_m,z_m,qx,qy,qz,qw\n"
        + "".join(f"{t:.6f},{P_TRUE[0]},{P_TRUE[1]},{P_TRUE[2]},0,0,0,1\n" for t in truth_t)
    )
    if pairs:
        td_t = np.arange(5e-4, imu_t[-1], tdoa_dt)
        lines = []
        for j, t in enumerate(td_t):
            a, b = pairs[j % len(pairs)]
            lines.append(f"{t:.6f},{a},{b},{_ddist(a, b)!r}\n")
        (d / "tdoa.csv").write_text("t_s,anchor_a,anchor_b,ddist_m\n" + "".join(lines))
    return d


@pytest.fixture
def stand_in(tmp_path):
    folder = tmp_path / "estimation"
    folder.mkdir()
    (folder / "eskf_class.py").write_text(STAND_IN)
    return folder


RING_PAIRS = [(7, 0), (0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (5, 6), (6, 7)]


def _run(stand_in, log_dir, **cfg):
    module = pu.load_eskf(stand_in)
    lg = pu.read_log(log_dir)
    c = pu.PeerConfig(**cfg)
    inp = pu.peer_inputs(lg, module, c)
    X0, P0 = pu.initial_state(lg, c, inp.t0_s)
    eskf, _, _, rejected = pu.drive(module, inp, X0, P0)
    return module.CALLS, inp, eskf, rejected


def test_imu_reaches_their_filter_in_g_and_deg_s_body_axes_kept(stand_in, tmp_path):
    calls, inp, _, _ = _run(stand_in, _write_log(tmp_path / "log", RING_PAIRS))
    assert len(inp.imu_t_s) == 200 // 8  # every 8th IMU sample (main.py's three halvings)
    preds = [c for c in calls if c[0] == "predict" and c[3]]
    assert len(preds) == np.sum(inp.imu_t_s < inp.t_s[-1])  # the last step's sample has no step after it
    imu = preds[0][4]
    # their predict multiplies by GRAVITY_MAGNITUDE and DEG_TO_RAD: what arrives is g and deg/s
    np.testing.assert_allclose(imu[0:3], ACC / 9.81, rtol=1e-12)
    np.testing.assert_allclose(imu[3:], np.degrees(GYRO), rtol=1e-12)
    # ...so once converted their filter holds exactly our SI values, axis by axis (no frame change)
    np.testing.assert_allclose(preds[0][5], ACC, rtol=1e-12)
    np.testing.assert_allclose(preds[0][6], GYRO, rtol=1e-12)


def test_driver_steps_as_main_py(stand_in, tmp_path):
    calls, inp, _, _ = _run(stand_in, _write_log(tmp_path / "log", RING_PAIRS))
    t = inp.t_s
    imu_times, uwb_times = set(inp.imu_t_s.tolist()), set(inp.uwb_t_s.tolist())
    preds = [c for c in calls if c[0] == "predict"]
    assert [c[1] for c in preds] == list(range(1, len(t)))
    for _, k, dt, imu_check, *_ in preds:  # step k: the IMU sample of t[k-1], over t[k] - t[k-1]
        assert dt == pytest.approx(t[k] - t[k - 1], abs=1e-12)
        assert imu_check == (t[k - 1] in imu_times)
    corrected = [c[1] for c in calls if c[0] == "uwb"]
    assert corrected == [k for k in range(1, len(t)) if t[k - 1] in uwb_times]
    assert calls[0][3] == len(t)  # K: one row per step


def test_tdoa2_keeps_ring_pairs_every_8th_with_sign_and_ids(stand_in, tmp_path):
    # 5 % of rows on a non-ring pair: still TDoA2 (>= 90 % ring), and those rows are dropped
    pairs = RING_PAIRS * 5 + [(0, 4), (2, 9)]
    calls, inp, _, _ = _run(stand_in, _write_log(tmp_path / "log", pairs, n_imu=400, tdoa_dt=1e-3))
    assert inp.mode == "tdoa2"
    rows = [c[2] for c in calls if c[0] == "uwb"]
    seen = {(int(r[0]), int(r[1])) for r in rows}
    assert seen <= set(RING_PAIRS)
    all_rows = np.genfromtxt(tmp_path / "log" / "tdoa.csv", delimiter=",", skip_header=1)
    for a, b in RING_PAIRS:  # each pair's stream downsampled on its own: rows 0, 8, 16, ... of it
        mine = all_rows[(all_rows[:, 1] == a) & (all_rows[:, 2] == b)]
        got = inp.uwb[(inp.uwb[:, 0] == a) & (inp.uwb[:, 1] == b)]
        np.testing.assert_array_equal(got[:, 2], mine[::8, 3])
    for r in rows:  # d_B - d_A, the anchor id order and sign untouched
        assert r[2] == pytest.approx(_ddist(int(r[0]), int(r[1])), abs=1e-12)


def test_tdoa3_takes_every_8th_row_of_all_pairs(stand_in, tmp_path):
    pairs = [(a, b) for a in range(8) for b in range(8) if a != b]
    calls, inp, _, _ = _run(stand_in, _write_log(tmp_path / "log", pairs, n_imu=400, tdoa_dt=1e-3))
    assert inp.mode == "tdoa3"
    n_rows = len(np.genfromtxt(tmp_path / "log" / "tdoa.csv", delimiter=",", skip_header=1))
    assert len(inp.uwb_t_s) == math.ceil(n_rows / 8)
    # each is applied but one at the last step, which has no step after it (main.py's loop)
    assert sum(c[0] == "uwb" for c in calls) == np.sum(inp.uwb_t_s < inp.t_s[-1])


def test_anchor_table_row_is_the_anchor_id(stand_in, tmp_path):
    calls, _, _, _ = _run(stand_in, _write_log(tmp_path / "log", [(2, 9), (9, 2)]), mode="tdoa3")
    table = next(c[3] for c in calls if c[0] == "uwb")
    assert table.shape == (10, 3)
    for i, p in ANCHORS.items():
        np.testing.assert_array_equal(table[i], p)
    assert np.isnan(table[8]).all()  # an id the log lacks


def test_rejected_rows_are_counted(stand_in, tmp_path):
    # the stand-in rejects the rows from anchor 9 (Ppo left equal to Ppr, as their innovation test does)
    pairs = [(2, 9), (9, 2), (2, 0)]  # 3 pairs: every 8th row cycles through all three
    calls, inp, _, rejected = _run(stand_in, _write_log(tmp_path / "log", pairs), mode="tdoa3")
    from_9 = sum(1 for c in calls if c[0] == "uwb" and int(c[2][0]) == 9)
    assert 0 < from_9 < len(inp.uwb_t_s)
    assert rejected == from_9


def test_twr_only_log_is_refused(stand_in, tmp_path):
    d = _write_log(tmp_path / "log", [], twr=True)
    with pytest.raises(ConfigError, match="TDoA only"):
        pu.run_peer(d, stand_in)


def test_missing_eskf_names_the_folder(tmp_path):
    with pytest.raises(ConfigError, match=r"no eskf_class\.py"):
        pu.load_eskf(tmp_path)


def test_cli_scores_against_truth(stand_in, tmp_path):
    """End to end through ``swarm bench peer``: the stand-in's estimate stays at main.py's X0, the truth
    0.1 m away along x, the covariance at P0 = 0.01 I: RMSE 0.1 m all on x, NEES 0.1^2 / 0.01 = 1."""
    from swarm.cli.main import main

    d = _write_log(tmp_path / "log", RING_PAIRS)
    out = tmp_path / "peer.json"
    argv = ["bench", "peer", str(d), "--util-eskf", str(stand_in.parent), "--initial", "authors"]
    (stand_in.parent / "scripts").mkdir()  # --util-eskf may name a checkout's root
    stand_in.rename(stand_in.parent / "scripts" / "estimation")
    assert main([*argv, "--json", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["mode"] == "tdoa2"
    assert r["initial_position_m"] == list(pu.AUTHORS_X0_M)
    assert r["rmse_m"] == pytest.approx(0.1, abs=1e-9)
    np.testing.assert_allclose(r["rmse_axis_m"], [0.1, 0.0, 0.0], atol=1e-9)
    assert r["nees_mean"] == pytest.approx(1.0, abs=1e-9)
    assert r["nees_in_band_share"] == 1.0  # 1 lies in chi-square(3)'s 95 % band [0.22, 9.35]
    assert r["attitude_rmse_deg"] == pytest.approx(0.0, abs=1e-9)
    assert r["diverged"] is False
    assert r["peer"]["settings"]["std_uwb_tdoa_m"] == pytest.approx(math.sqrt(0.05))
