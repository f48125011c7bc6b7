"""A TDoA flight as the UTIL Crazyflie logs have them, written by this module (seeded; no real data): the
rotors spin from the first sample (no quiet segment), the vehicle stands on a known pad, climbs, moves,
descends at 0.6 m/s and touches down, and the radio's distance differences carry each anchor's slow error (a
first-order Gauss-Markov term) and under 0.1 m of height are those of a point metres up (the ground). The
flight phases (touchdown, pin, climb), the TDoA model of a TDoA log and the vibration's accelerometer
noise are checked on it and on the kernels (docs/logs.md, "TDoA flights")."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from swarm.core import _imu_nb as nb
from swarm.core.imu_filter import PhaseParams, RobustParams, robust_vector
from swarm.logs.online import OnlineNavigator
from swarm.logs.reader import read_log
from swarm.logs.replay import build_filter, replay_log
from tests.logs.feed import feed, in_time_order

RATE_HZ = 500.0
PAD = np.array([0.0, 0.0, 0.03])
ANCHORS = np.array([[x, y, z] for z in (0.2, 3.0) for x, y in ((-4, -4), (4, -4), (4, 4), (-4, 4))], float)
GHOST = np.array([0.5, -0.5, 5.0])
"""Where a tag on the ground seems to be, from where it is [m]."""
LIFT_S, CONTACT_DV = 3.0, 0.6
"""The climb starts at LIFT_S; the descent meets the ground at 0.6 m/s."""


def _acceleration(t):
    """The flight's acceleration (n, 3) [m/s^2]: a smooth climb of 1.17 m in 2 s, a 6 s excursion in x and y
    (zero velocity at both ends), a descent reaching -0.6 m/s in 0.5 s, and the contact, which stops it in
    50 ms once the height is back at the pad's (found by integrating; returned as the contact time)."""
    a = np.zeros((len(t), 3))
    s = (t - LIFT_S) / 2.0
    up = (s >= 0) & (s < 1)
    a[up, 2] = 1.17 * (math.pi**2 / 8.0) * np.cos(math.pi * s[up])  # z = 0.585 (1 - cos(pi s))
    u = t - 5.0
    mv = (u >= 0) & (u < 6)
    a[mv, 0] = 0.4 * (2 * math.pi / 3) ** 2 * np.cos(2 * math.pi * u[mv] / 3)
    a[mv, 1] = 0.3 * (2 * math.pi / 6) ** 2 * np.cos(2 * math.pi * u[mv] / 6)
    down = (t >= 11.0) & (t < 11.5)
    a[down, 2] = -1.2
    return a


def _trajectory(dt):
    """Times, positions, velocities, accelerations on the IMU grid, and the contact time [s]."""
    t = np.arange(0.0, 16.0, dt)
    a = _acceleration(t)
    p, v = np.zeros_like(a), np.zeros_like(a)
    p[0] = PAD
    contact = math.inf
    for k in range(1, len(t)):
        if t[k] >= contact and t[k] < contact + 0.05:
            a[k - 1, 2] = CONTACT_DV / 0.05
        elif t[k] >= contact + 0.05:
            a[k - 1, 2] = 0.0
            v[k - 1, 2] = 0.0
        v[k] = v[k - 1] + a[k - 1] * dt
        p[k] = p[k - 1] + v[k - 1] * dt + 0.5 * a[k - 1] * dt * dt
        if t[k] > 11.5 and contact == math.inf and p[k, 2] <= PAD[2] + 0.5 * CONTACT_DV * 0.05:
            contact = t[k]
    p[t >= contact + 0.05, 2] = PAD[2]
    v[t >= contact + 0.05] = 0.0
    return t, p, v, a, contact


def write_flight(d: Path, seed: int = 0, nlos: tuple[int, float, float, float] | None = None) -> dict:
    """The log folder (module docstring); returns the contact time and the rotors' stop. ``nlos`` = (anchor,
    from [s], to [s], excess [m]): that anchor's packets come late (long) by the excess meanwhile."""
    rng = np.random.default_rng(seed)
    d.mkdir(parents=True, exist_ok=True)
    dt = 1.0 / RATE_HZ
    t, p, _, a, contact = _trajectory(dt)
    stop = contact + 1.5  # the rotors spin on after the touchdown, as on the UTIL logs
    rotors = t < stop
    # level attitude throughout: the specific force is the acceleration less gravity; the rotors add a 90 Hz
    # vibration (0.1 m/s^2 per axis) sampled 5.6 times a cycle, the sensor a white noise
    f = a + np.array([0.0, 0.0, 9.81]) + rng.normal(size=a.shape) * 0.02 * math.sqrt(RATE_HZ)
    phase = rng.uniform(0, 2 * math.pi, 3)
    f += rotors[:, None] * 0.1 * np.sin(2 * math.pi * 90.0 * t[:, None] + phase)
    gyro = rng.normal(size=a.shape) * 0.002 * math.sqrt(RATE_HZ)
    imu = np.column_stack([t, gyro, f])
    np.savetxt(d / "imu.csv", imu, delimiter=",", header="t_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,"
               "acc_x_m_s2,acc_y_m_s2,acc_z_m_s2", comments="")  # fmt: skip
    # TDoA3: 200 differences a second between random anchors, each anchor's error a Gauss-Markov term (0.1 m,
    # 0.5 s) plus white 0.05 m; under 0.1 m of height the tag hears the anchors as if it stood at GHOST from
    # where it is (the UTIL logs' ground rows are 1-3 m off and agree with one position metres up)
    td = np.arange(0.5, 16.0, 1.0 / 200.0)
    m = len(ANCHORS)
    gm = np.zeros(m)
    rows = []
    for tk in td:
        gm = gm * math.exp(-0.005 / 0.5) + rng.normal(size=m) * 0.1 * math.sqrt(1 - math.exp(-0.01 / 0.5))
        i = min(round(tk / dt), len(t) - 1)
        err = gm.copy()
        if nlos is not None and nlos[1] <= tk < nlos[2]:
            err[nlos[0]] += nlos[3]
        heard = p[i] + (GHOST if p[i, 2] < 0.1 else 0.0)
        ia, ib = rng.choice(m, 2, replace=False)
        dd = np.linalg.norm(heard - ANCHORS[ib]) - np.linalg.norm(heard - ANCHORS[ia]) + err[ib] - err[ia]
        dd += rng.normal() * 0.05
        if abs(dd) < np.linalg.norm(ANCHORS[ia] - ANCHORS[ib]):  # the firmware drops longer ones
            rows.append((tk, ia, ib, dd))
    with open(d / "tdoa.csv", "w") as fh:
        fh.write("t_s,anchor_a,anchor_b,ddist_m\n")
        fh.writelines(f"{r[0]:.6f},{r[1]},{r[2]},{r[3]:.6f}\n" for r in rows)
    with open(d / "anchors.csv", "w") as fh:
        fh.write("anchor_id,x_m,y_m,z_m\n")
        fh.writelines(f"{i},{x},{y},{z}\n" for i, (x, y, z) in enumerate(ANCHORS))
    (d / "uwb.csv").write_text("t_s,anchor_id,range_m\n")
    tt = t[::5]
    truth = np.column_stack([tt, p[::5], np.zeros((len(tt), 3)), np.ones(len(tt))])
    np.savetxt(d / "truth.csv", truth, delimiter=",", header="t_s,x_m,y_m,z_m,qx,qy,qz,qw", comments="")
    (d / "log.toml").write_text(
        'name = "synthetic TDoA landing"\n[calibration]\nuntil_s = 0.0\n'
        f"[initial]\nposition_m = [{PAD[0]}, {PAD[1]}, {PAD[2]}]\nyaw_deg = 0.0\n"
    )
    return {"contact_s": float(contact), "rotors_stop_s": float(stop)}


@pytest.fixture(scope="module")
def landing(tmp_path_factory):
    d = tmp_path_factory.mktemp("tdoa_landing")
    info = write_flight(d)
    return d, info, replay_log(read_log(d))


def _errors_after(r, t0):
    inside, e, _ = r.errors()
    return np.linalg.norm(e[r.t[inside] > t0], axis=1)


def test_the_climb_takes_off_and_the_touchdown_lands_where_the_radio_cannot_say(landing):
    _, info, r = landing
    s = r.summary()
    kinds = [(e["kind"], e.get("touchdown")) for e in s["events"]]
    # one take-off, one touchdown, no divergence: the ground's metres of TDoA error stay out of the window
    assert kinds == [("takeoff", None), ("landing", True)], kinds
    takeoff, land = s["events"][0]["t_s"], s["events"][1]["t_s"]
    # the rotors spin from the first sample, so the vibration cannot tell the take-off, and the pinned
    # estimate cannot rise: the climb's specific force (1.4 m/s^2 at the lift-off) is seen after its 0.1 s
    # low-pass and the 0.3 s dwell
    assert LIFT_S + 0.1 < takeoff < LIFT_S + 0.8
    # the contact stops a 0.6 m/s descent: declared after the dwell, well before the rotors stop
    assert info["contact_s"] < land < info["contact_s"] + 0.8 < info["rotors_stop_s"]
    # pinned on the ground: the estimate stays where it touched down while the differences are metres off
    # (0.15 m: the radio's slow errors of 0.1 m per anchor at the contact)
    assert _errors_after(r, land).max() < 0.15
    assert s["rmse_m"] < 0.15


def test_without_the_touchdown_the_ground_drags_the_estimate_away(landing):
    d, info, r = landing
    off = replay_log(read_log(d, {"phases.land_height_m": 0.0}))
    # the landing is then the rotors' stop, 1.5 s after the contact; meanwhile the ground's differences fire
    # the divergence test and the recovery opens the covariance to them
    assert _errors_after(off, info["contact_s"] + 0.3).max() > 1.0
    assert any(e["kind"] == "estimator_reset" for e in off.events)
    # with it, 0.4 m at most: the last differences before the touchdown is declared come from the ground
    assert _errors_after(r, info["contact_s"] + 0.3).max() < 0.4


def test_the_live_navigator_pins_and_lands_as_the_replay_does(landing):
    d, _, _ = landing
    # the navigator wants a range sigma without a calibration segment; a TDoA log never uses it
    log = read_log(d, {"uwb.sigma_m": 0.1})
    r = replay_log(log)
    nav = feed(
        OnlineNavigator(log.config, log.anchor_ids, log.anchors_nav, 0.05), in_time_order(log, "imu", "tdoa")
    )
    X = np.array([e.X for e in nav.estimates])
    P = np.array([e.P9 for e in nav.estimates])
    assert np.array_equal(X, r.X) and np.array_equal(P, r.P)
    assert nav.events == r.events
    assert np.array_equal(nav.tdoa_counts, r.tdoa.counts)


def test_a_tdoa_log_models_each_anchor_with_the_tdoa_keys(landing):
    d, _, _ = landing
    keys = {"tdoa.gm_sigma_m": 0.2, "tdoa.gm_tau_s": 0.7, "tdoa.offset_sigma_m": 0.08}
    log = read_log(d, {**keys, "tdoa.offsets": True})
    f, _, _ = build_filter(log)
    lay = f.layout
    # every difference cancels a common offset: no state for it; each anchor's Gauss-Markov term has the
    # [tdoa] sigma and time constant, its offset the [tdoa] prior
    assert lay.common == -1
    ext = lay.ext.reshape(-1, 2)  # (tau, sigma) per extra error state
    assert np.allclose(ext[lay.gm - nb.N_CORE], [0.7, 0.2])
    assert np.allclose(np.sqrt(np.diag(f.P[0])[lay.offset]), 0.08)
    assert np.allclose(np.sqrt(np.diag(f.P[0])[lay.gm]), 0.2)
    # by default no offset per anchor (a height error hides in them, TdoaLog.offsets): the Gauss-Markov
    # terms alone, right after the 15 core states
    f, _, _ = build_filter(read_log(d, keys))
    assert (f.layout.offset == -1).all() and f.layout.common == -1
    assert np.array_equal(f.layout.gm, nb.N_CORE + np.arange(len(f.anchors)))
    assert f.layout.n_err == nb.N_CORE + len(f.anchors)


def test_without_offsets_the_height_is_what_the_differences_tell(landing):
    """Anchors in two layers (0.2 and 3 m): from the cruise's 1.2 m a height error moves each difference as
    offsets of about -0.3 and +0.2 of it on the two layers would, so with an offset state per anchor the
    height is far less certain (TdoaLog.offsets); this flight's anchors have none (Gauss-Markov errors
    only)."""
    d, _, _ = landing
    sig = {}
    for off in (False, True):
        r = replay_log(read_log(d, {"tdoa.offsets": off}))
        cruise = (r.t > 5.0) & (r.t < 11.0)  # at one height, moving in x and y
        sig[off] = np.sqrt(np.median(r.P[cruise][:, [0, 1, 2], [0, 1, 2]], axis=0))
    # measured: height 0.136 m without, 0.217 m with; x and y 0.072 and 0.101 (the offsets cost them less)
    assert sig[False][2] < 0.15 < 0.2 < sig[True][2]
    assert sig[True][2] / sig[False][2] > 1.4


def _phase_state():
    PH = np.zeros(nb.N_PH)
    PH[nb.PH_SINCE] = -1.0
    PH[nb.PH_DESC_T] = PH[nb.PH_PIN_T] = PH[nb.PH_CHANGE_T] = -np.inf
    PH[nb.PH_ARMED] = 1.0
    return PH


def test_the_vibration_noise_is_the_rotors_power_and_nothing_of_a_white_noise():
    """Per axis: a white noise of 0.6 m/s^2 per sample (0.02 m/s^2/sqrt(Hz) at 1 kHz) adds nothing; a 120 Hz
    vibration of amplitude 0.3 m/s^2 adds the density k times its power on that axis alone."""
    rng = np.random.default_rng(1)
    dt = 1e-3
    t = np.arange(0.0, 5.0, dt)
    k = 0.8
    RP = robust_vector(RobustParams(), PhaseParams(), 0.02, 0.0, -1, 8, 0.01, k)
    X = np.zeros(16)
    X[nb.XQ + 3] = 1.0
    ridx = np.full((8, 3), -1, dtype=np.int64)
    # the power the kernel sees: A^2 / 2 of the part over its 10 ms mean (the discrete first-order high-pass
    # h = a - m, m += g (a - m): H(z) = (1 - g)(1 - 1/z) / (1 - (1 - g)/z)) times the lag-1 correlation
    # cos(w dt) of a sinusoid sampled every dt
    w = 2 * math.pi * 120.0
    g = 1.0 - math.exp(-dt / nb.VIB_MEAN_TAU_S)
    z = complex(math.cos(w * dt), math.sin(w * dt))
    hp = abs((1 - g) * (1 - 1 / z) / (1 - (1 - g) / z)) ** 2
    seen = 0.5 * 0.3**2 * hp * math.cos(w * dt)
    for amp, noise, expect in ((0.0, 0.6, 0.0), (0.3, 0.0, k * seen)):
        PH = _phase_state()
        acc = np.zeros((len(t), 3))
        acc[:, 2] = 9.81
        acc += rng.normal(size=acc.shape) * noise
        acc[:, 0] += amp * np.sin(2 * math.pi * 120.0 * t)
        P = np.zeros((15, 15))
        for j in range(len(t)):
            nb.phase_step(X, P, RP, PH, ridx, acc[j], dt if j else 0.0, t[j])
        P[:, :] = 0.0
        nb.vibration_noise(X, P, RP, PH, 1.0)
        # the density squared over 1 s; a 5 s slow mean of a sampled sinusoid's lag-1 product: within 10 %
        assert math.sqrt(P[nb.EV, nb.EV]) == pytest.approx(expect, rel=0.1, abs=2e-3)
        assert P[nb.EV + 1, nb.EV + 1] < 1e-5 and P[nb.EV + 2, nb.EV + 2] < 1e-5


def test_an_anchor_whose_packets_come_late_is_held_out_and_the_others_are_not(tmp_path):
    """Anchor 5 (a ceiling corner) 0.8 m long for 3 s in flight (NLOS): its own CUSUM (the signed innovation,
    +e as anchor b and -e as a, weighted by its worth) holds its differences out, the other anchors' never,
    and the estimate stays as accurate as without the episode."""
    d = tmp_path / "nlos"
    write_flight(d, seed=3, nlos=(5, 6.0, 9.0, 0.8))
    r = replay_log(read_log(d))
    s = r.summary()
    by = s["range_model"]["by_anchor"]
    # 200 differences a second, a quarter with anchor 5: ~150 over the episode; held within ~0.1 s of its
    # start (its innovations ~3 sigmas against the allowance of 2) and released within ~0.5 s of its end
    assert by["5"]["nlos_episodes"] >= 1 and 100 < by["5"]["nlos_ranges"] < 250
    # the clean anchors' slow errors (0.1 m, 0.5 s: the modelled ones) hold none of them out for long
    assert all(by[a]["nlos_ranges"] < 20 for a in by if a != "5"), by
    assert not any(e["kind"] == "estimator_reset" for e in s["events"])
    clean = replay_log(read_log(d, {"robust.nlos": False}))
    assert s["rmse_m"] < clean.summary()["rmse_m"]
