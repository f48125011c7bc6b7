"""Tests of swarm.core.guidance on synthetic NavInput sequences (no simulation, no estimator).

Set-up shared by most tests: the target sits at the origin with the identity attitude and docks on its +x
face, so the face normal is +x in nav, the alignment point is (0.25, 0, 0) m and the docked chaser centre is
(0.1, 0, 0) m. Switching uses the paper's fixed radii (r2 = 0.8 m, r1 = 0.3 m) unless a test says otherwise.
A "perfect follower" sets the next navigation position to the last reference position, so the reference
path is the vehicle path.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from swarm.core import rotations as rot
from swarm.core.guidance import (
    FACES,
    ChaserGuidance,
    GuidanceParams,
    Mode,
    NavInput,
    StationKeeping,
    StationParams,
    contact_state,
    docking_geometry,
    in_corridor,
)
from swarm.core.mdp import FixedParams, FixedSwitcher
from swarm.errors import ConfigError

G = GuidanceParams()
P_T = np.zeros(3)
Q_T = np.array([0.0, 0.0, 0.0, 1.0])
N_MS, P_DOCKED, Q_DOCK = docking_geometry(G, P_T, Q_T)
P_ALIGN = P_T + G.align_distance_m * N_MS
Q_MISSION = np.array([0.0, 0.0, 0.0, 1.0])
DT = 0.1  # the translation controller's period [s] (scenario translation_control.rate_hz = 10)
SPEED = {
    Mode.APPROACH: G.approach_speed_m_s,
    Mode.REORIENT: G.approach_speed_m_s,
    Mode.ALIGN: G.align_speed_m_s,
    Mode.DOCK: G.dock_speed_m_s,
    Mode.ABORT: G.abort_speed_m_s,
}


def nav(
    t_s, p_nav, *, v=(0.0, 0.0, 0.0), q=Q_DOCK, sigma=0.01, rejected=0.0, vision=False, d=0.0
) -> NavInput:
    """A navigation input around the fixed target; healthy (sigma 1 cm, nothing rejected) by default."""
    return NavInput(
        t_s=float(t_s),
        p_nav=np.asarray(p_nav, dtype=float),
        v_nav=np.asarray(v, dtype=float),
        q_nav_body=np.asarray(q, dtype=float),
        sigma_pos_max_m=float(sigma),
        mahalanobis_d=float(d),
        rejection_fraction=float(rejected),
        vision=vision,
        p_target_nav=P_T.copy(),
        q_nav_target=Q_T.copy(),
    )


def chaser(p_start, params: GuidanceParams = G) -> ChaserGuidance:
    return ChaserGuidance(params, FixedSwitcher(), Q_MISSION, p_start)


def follow(g: ChaserGuidance, p0, n_steps: int, t0: float = 0.0, until: Mode | None = None, **kw):
    """Perfect follower: step ``g`` with the navigation position at the last reference; returns the
    references (stops early once ``until`` is reached)."""
    p = np.asarray(p0, dtype=float)
    refs = []
    for i in range(n_steps):
        ref = g.step(nav(t0 + i * DT, p, **kw), DT)
        refs.append(ref)
        p = ref.p_nav
        if until is not None and ref.mode is until:
            break
    return refs


def modes(g: ChaserGuidance) -> list[str]:
    return [Mode.HOLD.value] + [ev["to"] for ev in g.history]


# ---- start-up HOLD ---------------------------------------------------------------------------------------


def test_starts_in_hold_and_keeps_the_reference_until_sigma_below_resume():
    p0 = np.array([1.5, 0.2, 0.0])
    g = chaser(p0)
    assert g.mode is Mode.HOLD
    for sigma in (
        0.2,
        G.hold_sigma_pos_m,
        0.05,
        G.resume_sigma_pos_m,
    ):  # resume needs sigma < resume (strict)
        ref = g.step(nav(0.0, p0 + 0.01, sigma=sigma), DT)
        assert ref.mode is Mode.HOLD, sigma
        assert ref.events == []
        np.testing.assert_array_equal(ref.p_nav, p0)
        np.testing.assert_array_equal(ref.v_nav, np.zeros(3))
    ref = g.step(nav(0.1, p0, sigma=G.resume_sigma_pos_m - 1e-3), DT)
    assert ref.mode is Mode.APPROACH
    assert [ev["to"] for ev in ref.events] == ["APPROACH"]
    assert "initial estimate converged" in ref.events[0]["reason"]


def test_initial_hold_keeps_the_mission_attitude():
    g = chaser([1.5, 0.0, 0.0])
    ref = g.step(nav(0.0, [1.5, 0.0, 0.0], sigma=0.1, q=Q_DOCK), DT)
    np.testing.assert_allclose(ref.q_nav_body, Q_MISSION)


def test_initial_hold_never_aborts_however_long():
    # abort_after_hold_s applies to a HOLD after start; before start the chaser has not moved yet
    g = chaser([1.5, 0.0, 0.0])
    for t in (0.0, G.abort_after_hold_s + 1.0, 10 * G.abort_after_hold_s):
        assert g.step(nav(t, [1.5, 0.0, 0.0], sigma=0.1), DT).mode is Mode.HOLD


# ---- health supervision ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("p0", "mode"),
    [
        ((1.5, 0.0, 0.0), Mode.APPROACH),  # r > r2
        ((0.5, 0.1, 0.0), Mode.REORIENT),  # r1 < r <= r2
        ((-0.28, 0.02, 0.0), Mode.ALIGN),  # r <= r1, behind the target: no corridor
    ],
)
def test_unhealthy_sigma_holds_with_a_reason_and_recovery_resumes_the_mode(p0, mode):
    g = chaser(p0)
    assert g.step(nav(0.0, p0), DT).mode is mode
    ref = g.step(nav(0.1, p0, sigma=G.hold_sigma_pos_m + 0.01), DT)
    assert ref.mode is Mode.HOLD
    assert ref.events[-1]["to"] == "HOLD"
    assert "estimate not trustworthy" in ref.events[-1]["reason"]
    assert "sigma_pos=0.070 m" in ref.events[-1]["reason"]
    # between resume and hold thresholds: hysteresis keeps HOLD
    assert g.step(nav(0.2, p0, sigma=0.05), DT).mode is Mode.HOLD
    ref = g.step(nav(0.3, p0, sigma=0.01), DT)
    assert ref.mode is mode
    assert ref.events[0]["from"] == "HOLD" and ref.events[0]["to"] == mode.value
    assert "estimate healthy again" in ref.events[0]["reason"]


def test_rejected_ranges_hold_with_the_fraction_in_the_reason():
    p0 = (1.5, 0.0, 0.0)
    g = chaser(p0)
    g.step(nav(0.0, p0), DT)
    ref = g.step(nav(0.1, p0, rejected=0.6), DT)
    assert ref.mode is Mode.HOLD
    assert "60% of recent ranges rejected" in ref.events[-1]["reason"]
    ref = g.step(nav(0.2, p0, rejected=G.hold_rejection_fraction), DT)  # at the threshold: healthy
    assert ref.mode is Mode.APPROACH


def test_large_mean_nis_holds_with_the_nis_in_the_reason_and_resumes_when_it_drops():
    p0 = (1.5, 0.0, 0.0)
    g = chaser(p0)
    g.step(nav(0.0, p0), DT)
    d_bad = np.sqrt(G.hold_nis_mean) * 1.1  # innovations accepted by the gate but consistently large
    ref = g.step(nav(0.1, p0, d=d_bad), DT)
    assert ref.mode is Mode.HOLD
    assert f"mean NIS of recent ranges {d_bad**2:.1f} > {G.hold_nis_mean}" in ref.events[-1]["reason"]
    ref = g.step(nav(0.2, p0, d=1.0), DT)  # a consistent filter: mean NIS 1
    assert ref.mode is Mode.APPROACH and "estimate healthy again" in ref.events[-1]["reason"]


def test_hold_freezes_the_reference_at_the_estimate():
    p0 = np.array([1.5, 0.0, 0.0])
    g = chaser(p0)
    follow(g, p0, 20)  # the carrot has moved toward the target
    p_now = np.array([1.47, 0.01, 0.0])
    ref = g.step(nav(2.0, p_now, sigma=0.1), DT)
    assert ref.mode is Mode.HOLD
    np.testing.assert_array_equal(ref.p_nav, p_now)
    np.testing.assert_array_equal(ref.v_nav, np.zeros(3))


def test_hold_longer_than_the_limit_after_start_aborts():
    p0 = (1.5, 0.0, 0.0)
    g = chaser(p0)
    g.step(nav(0.0, p0), DT)
    g.step(nav(1.0, p0, sigma=0.1), DT)
    assert g.step(nav(1.0 + G.abort_after_hold_s - 0.1, p0, sigma=0.1), DT).mode is Mode.HOLD
    ref = g.step(nav(1.0 + G.abort_after_hold_s + 0.1, p0, sigma=0.1), DT)
    assert ref.mode is Mode.ABORT
    assert "HOLD longer than" in ref.events[-1]["reason"]


def _in_dock() -> ChaserGuidance:
    """A chaser that reached DOCK: at the alignment point, docking attitude, at rest, no vision."""
    g = chaser(P_ALIGN)
    ref = g.step(nav(0.0, P_ALIGN), DT)
    assert ref.mode is Mode.DOCK
    return g


@pytest.mark.parametrize("bad", [{"sigma": 0.07}, {"rejected": 0.9}])
def test_unhealthy_in_dock_aborts(bad):
    g = _in_dock()
    ref = g.step(nav(0.1, P_ALIGN - 0.01 * N_MS, **bad), DT)
    assert ref.mode is Mode.ABORT
    assert "inside the keep-out sphere" in ref.events[-1]["reason"]


def test_abort_backs_away_from_the_target():
    g = _in_dock()
    refs = follow(g, P_ALIGN, 200, t0=0.1, sigma=0.07)
    assert refs[0].mode is Mode.ABORT
    r = [float(np.linalg.norm(ref.p_nav - P_T)) for ref in refs]
    assert all(b >= a - 1e-12 for a, b in itertools.pairwise(r))
    assert r[-1] == pytest.approx(G.keepout_radius_m + G.abort_retreat_m, abs=1e-9)


# ---- mode sequence and the ALIGN skip ---------------------------------------------------------------------


def test_full_approach_visits_the_modes_in_order():
    g = chaser((1.0, 0.3, 0.2))
    refs = follow(g, (1.0, 0.3, 0.2), 3000, until=Mode.DOCKED)
    assert refs[-1].mode is Mode.DOCKED
    assert modes(g) == ["HOLD", "APPROACH", "REORIENT", "ALIGN", "DOCK", "DOCKED"]
    ev = {e["to"]: e for e in g.history}
    assert ev["REORIENT"]["range_m"] <= 0.8 and ev["ALIGN"]["range_m"] <= 0.3


def test_align_is_skipped_only_in_the_corridor_with_vision_and_says_so():
    p0 = P_T + (G.align_distance_m + 0.5 * G.align_tolerance_m) * N_MS
    g = chaser(p0)
    ref = g.step(nav(0.0, p0, vision=True), DT)
    assert modes(g) == ["HOLD", "APPROACH", "REORIENT", "DOCK"]
    assert "ALIGN skipped" in ref.events[-1]["reason"]
    g = chaser(p0)
    g.step(nav(0.0, p0, vision=False), DT)  # same place without vision: ALIGN is flown
    assert "ALIGN" in modes(g)


def test_reorient_stalled_at_the_keepout_boundary_switches_to_align():
    # r1 below the keep-out sphere: REORIENT parks on the sphere and ALIGN starts after stall_timeout_s
    g = ChaserGuidance(G, FixedSwitcher(FixedParams(r2_m=0.8, r1_m=0.1)), Q_MISSION, (0.0, 0.5, 0.0))
    follow(g, (0.0, 0.5, 0.0), 1000, until=Mode.ALIGN)
    assert g.mode is Mode.ALIGN
    assert "held at the keep-out boundary" in g.history[-1]["reason"]


# ---- reference generation ---------------------------------------------------------------------------------


@pytest.mark.parametrize("p0", [(-0.28, 0.02, 0.0), (-0.28, 0.0, 0.0), (-0.1, -0.2, 0.15)])
def test_align_from_behind_the_target_goes_around_the_keepout_sphere(p0):
    g = chaser(p0)
    refs = follow(g, p0, 2000, until=Mode.DOCK)
    assert refs[0].mode is Mode.ALIGN
    path = np.array([p0] + [ref.p_nav for ref in refs])
    dist = np.linalg.norm(path - P_T, axis=1)
    assert dist.min() >= G.keepout_radius_m
    assert refs[-1].mode is Mode.DOCK
    # the switch is decided on the navigation position of that step, i.e. the reference before it
    assert np.linalg.norm(path[-2] - P_ALIGN) <= G.align_tolerance_m


def test_dock_stays_in_the_corridor_down_to_contact():
    g = _in_dock()
    refs = follow(g, P_ALIGN, 1000, t0=0.1, until=Mode.DOCKED)
    assert refs[-1].mode is Mode.DOCKED
    for ref in refs:
        if np.linalg.norm(ref.p_nav - P_T) < G.keepout_radius_m:
            assert in_corridor(G, ref.p_nav, P_T, N_MS)
    c = contact_state(G, refs[-1].p_nav, np.zeros(3), Q_DOCK, P_T, Q_T)
    assert c["gap_m"] <= G.contact_distance_m and c["lateral_m"] < 1e-9


def test_reference_speed_never_exceeds_the_mode_speed():
    g = chaser((1.0, 0.3, 0.2))
    refs = follow(g, (1.0, 0.3, 0.2), 3000, until=Mode.DOCKED)
    seen = set()
    prev = np.array([1.0, 0.3, 0.2])
    for ref in refs:
        if ref.mode in SPEED:
            seen.add(ref.mode)
            limit = SPEED[ref.mode] + 1e-12
            assert np.linalg.norm(ref.v_nav) <= limit, ref.mode
            assert np.linalg.norm(ref.p_nav - prev) <= limit * DT, ref.mode
        prev = ref.p_nav
    assert seen == {Mode.APPROACH, Mode.REORIENT, Mode.ALIGN, Mode.DOCK}


def test_carrot_waits_while_the_vehicle_lags_more_than_max_lead():
    p0 = np.array([1.5, 0.0, 0.0])
    g = chaser(p0)
    refs = [g.step(nav(i * DT, p0), DT) for i in range(100)]  # the vehicle does not move
    lead = np.linalg.norm(refs[-1].p_nav - p0)
    assert G.max_lead_m < lead <= G.max_lead_m + G.approach_speed_m_s * DT + 1e-12
    np.testing.assert_array_equal(refs[-1].v_nav, np.zeros(3))
    np.testing.assert_array_equal(refs[-1].p_nav, refs[-2].p_nav)
    ref = g.step(nav(10.0, refs[-1].p_nav), DT)  # the vehicle catches up: the carrot moves again
    assert np.linalg.norm(ref.v_nav) == pytest.approx(G.approach_speed_m_s)


def test_reference_brakes_into_the_keepout_stop_point():
    """With r1 inside keep-out + margin (MDP's 0.10 m), REORIENT ends at the stop point 0.18 m from the
    target. The reference must arrive there with a velocity that goes continuously to zero
    (``|v| <= sqrt(2 a d)``, ``a = stop_decel_m_s2``) and feed the braking forward (``a_ref = -a`` along the
    path while braking), not stop dead from the approach speed."""
    g = ChaserGuidance(G, FixedSwitcher(FixedParams(r2_m=0.8, r1_m=0.10)), Q_MISSION, (0.5, 0.0, 0.0))
    refs = follow(g, (0.5, 0.0, 0.0), 400, until=Mode.ALIGN)
    stop = G.keepout_radius_m + G.keepout_margin_m
    a = G.stop_decel_m_s2
    braking = 0
    for ref in refs:
        if ref.mode is not Mode.REORIENT:
            continue
        d = np.linalg.norm(ref.p_nav - P_T) - stop  # after this step
        speed = np.linalg.norm(ref.v_nav)
        d_before = d + speed * DT
        assert speed <= np.sqrt(2 * a * d_before) + 1e-12
        if speed > 0 and np.sqrt(2 * a * d_before) < G.approach_speed_m_s and d > 0:
            braking += 1
            np.testing.assert_allclose(ref.a_nav, -a * ref.v_nav / speed, atol=1e-15)
        else:
            np.testing.assert_array_equal(ref.a_nav, np.zeros(3))
    # braking from 2 cm/s at 0.01 m/s^2 takes 2 s: ~20 control steps of 0.1 s
    assert braking >= 0.8 * G.approach_speed_m_s / a / DT
    speeds = [np.linalg.norm(r.v_nav) for r in refs if r.mode is Mode.REORIENT]
    # no velocity step anywhere: a continuous profile changes by a DT per step; the discrete sqrt profile's
    # last steps (the stop point within one step) drop by up to ~1.6 a DT; the old dead stop dropped 20 a DT
    assert max(np.abs(np.diff(speeds))) <= 2 * a * DT
    assert refs[-1].mode is Mode.ALIGN  # reached the stop point, then the stall rule


def test_stop_decel_is_validated():
    with pytest.raises(ConfigError, match="stop_decel_m_s2"):
        GuidanceParams(stop_decel_m_s2=0.0)


def test_approach_keeps_the_mission_attitude_and_reorient_turns_to_docking():
    g = chaser((1.5, 0.0, 0.0))
    assert np.allclose(g.step(nav(0.0, (1.5, 0.0, 0.0)), DT).q_nav_body, Q_MISSION)
    g = chaser((0.5, 0.0, 0.0))
    ref = g.step(nav(0.0, (0.5, 0.0, 0.0)), DT)
    assert ref.mode is Mode.REORIENT
    np.testing.assert_allclose(ref.q_nav_body, Q_DOCK)


# ---- docking geometry -------------------------------------------------------------------------------------

Q_PAPER_TARGET = Rotation.from_euler("xyz", [-90.0, 0.0, -90.0], degrees=True).as_quat()


@pytest.mark.parametrize("face", FACES)
def test_docked_chaser_z_axis_is_the_face_normal_and_centres_are_two_half_sizes_apart(face):
    p = GuidanceParams(docking_face=face)
    p_t = np.array([1.0, 2.0, 1.0])
    n_nav, p_docked, q_dock = docking_geometry(p, p_t, Q_PAPER_TARGET)
    n_target = np.zeros(3)
    n_target["xyz".index(face[1])] = 1.0 if face[0] == "+" else -1.0
    np.testing.assert_allclose(n_nav, Rotation.from_quat(Q_PAPER_TARGET).apply(n_target), atol=1e-12)
    R = Rotation.from_quat(q_dock).as_matrix()
    np.testing.assert_allclose(R[:, 2], n_nav, atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(p_docked - p_t, 2 * p.half_size_m * n_nav, atol=1e-12)


def test_paper_target_docking_face_normal_is_minus_y():
    # docking.toml: the target's +x face points along -y in nav for Euler (-90, 0, -90) deg xyz
    n_nav, _, _ = docking_geometry(G, np.array([1.0, 2.0, 1.0]), Q_PAPER_TARGET)
    np.testing.assert_allclose(n_nav, [0.0, -1.0, 0.0], atol=1e-12)


def test_contact_state_of_the_exactly_docked_pose_is_zero():
    p_t = np.array([1.0, 2.0, 1.0])
    _, p_docked, q_dock = docking_geometry(G, p_t, Q_PAPER_TARGET)
    c = contact_state(G, p_docked, np.zeros(3), q_dock, p_t, Q_PAPER_TARGET)
    for key in ("gap_m", "lateral_m", "attitude_rad", "closing_m_s"):
        assert c[key] == pytest.approx(0.0, abs=1e-12), key


def test_contact_state_measures_gap_lateral_attitude_and_closing_speed():
    lateral = np.array([0.0, 0.003, -0.004])  # 5 mm, perpendicular to the +x normal
    p_c = P_DOCKED + 0.002 * N_MS + lateral
    q_c = rot.quat_mul(Q_DOCK, rot.rotvec_exp(np.array([0.0, 0.03, 0.04])))  # 0.05 rad body-frame error
    c = contact_state(G, p_c, -0.01 * N_MS, q_c, P_T, Q_T)
    assert c["gap_m"] == pytest.approx(0.002)
    assert c["lateral_m"] == pytest.approx(0.005)
    assert c["attitude_rad"] == pytest.approx(0.05)
    assert c["closing_m_s"] == pytest.approx(0.01)


def test_contact_closing_speed_is_relative_to_the_target():
    c = contact_state(G, P_DOCKED, -0.01 * N_MS, Q_DOCK, P_T, Q_T, v_t=-0.01 * N_MS)
    assert c["closing_m_s"] == pytest.approx(0.0)


def test_in_corridor_is_the_cone_around_the_face_normal():
    half = np.radians(G.corridor_half_angle_deg)
    off = np.array([0.0, 1.0, 0.0])

    def at(angle: float) -> np.ndarray:
        return 0.12 * (np.cos(angle) * N_MS + np.sin(angle) * off)

    assert in_corridor(G, at(0.0), P_T, N_MS)
    assert in_corridor(G, at(half - 0.01), P_T, N_MS)
    assert not in_corridor(G, at(half + 0.01), P_T, N_MS)
    assert not in_corridor(G, -0.12 * N_MS, P_T, N_MS)  # behind the target
    assert not in_corridor(G, P_T, P_T, N_MS)  # at the target centre: no direction


# ---- station keeping --------------------------------------------------------------------------------------

SP = StationParams()
P_STATION = np.array([1.0, 2.0, 1.0])
Q_STATION = Q_PAPER_TARGET


def station_nav(offset_m=0.0, speed=0.0, att_deg=0.0, sigma=0.005) -> NavInput:
    q = rot.quat_mul(Q_STATION, rot.rotvec_exp(np.array([0.0, 0.0, np.radians(att_deg)])))
    return NavInput(
        0.0, P_STATION + np.array([offset_m, 0.0, 0.0]), np.array([speed, 0.0, 0.0]), q, sigma, 0.0, 0.0,
        False, P_STATION, Q_STATION,
    )  # fmt: skip


def test_station_keeping_does_nothing_before_the_estimate_converges():
    s = StationKeeping(P_STATION, Q_STATION, SP)
    ref = s.step(station_nav(0.2, att_deg=10.0, sigma=SP.converged_sigma_m + 0.01), DT)
    assert not s.translate and not s.rotate
    assert ref.mode is Mode.STATION
    np.testing.assert_array_equal(ref.p_nav, P_STATION)


def test_station_keeping_translation_has_hysteresis():
    s = StationKeeping(P_STATION, Q_STATION, SP)
    steps = [
        (0.03, 0.0, False),  # inside the dead band: idle
        (0.05, 0.0, True),  # leaves the dead band: starts
        (0.03, 0.0, True),  # back inside the dead band but not settled: keeps going
        (0.005, 0.01, True),  # settled in position, too fast
        (0.005, 0.001, False),  # settled and slow: stops
        (0.03, 0.0, False),  # inside the dead band again: idle
    ]
    for offset, speed, expected in steps:
        s.step(station_nav(offset, speed), DT)
        assert bool(s.translate) == expected, (offset, speed)


def test_station_keeping_rotation_has_hysteresis():
    s = StationKeeping(P_STATION, Q_STATION, SP)
    for att, expected in ((2.0, False), (4.0, True), (1.0, True), (0.3, False), (2.0, False)):
        s.step(station_nav(att_deg=att), DT)
        assert bool(s.rotate) == expected, att


# Significance test (StationKeeping docstring): translation starts when |dp| > max(deadband_m, k sigma_max),
# k = sqrt(chi2.ppf(0.9999, 3)) = 4.5943 (the 99.99 % point of chi-square with 3 dof is 21.108, tables).
K_SIG = 4.5943


def test_significance_radius_is_the_chi_square_quantile_in_sigmas():
    assert SP.significance_sigmas == pytest.approx(K_SIG, abs=1e-4)


def test_station_keeping_holds_on_an_unsettled_estimate():
    # 5 cm out, beyond the 4 cm dead band, sigma 1.5 cm (below converged_sigma_m = 2 cm: the old gate was
    # open): 5 / 1.5 = 3.3 sigma < 4.59, the offset is within what the estimate resolves
    s = StationKeeping(P_STATION, Q_STATION, SP)
    s.step(station_nav(0.05, sigma=0.015), DT)
    assert not s.translate


def test_station_keeping_releases_on_a_settled_estimate():
    # the same 5 cm with the steady-state sigma of 8 mm: 6.25 sigma > 4.59, significant
    s = StationKeeping(P_STATION, Q_STATION, SP)
    s.step(station_nav(0.05, sigma=0.008), DT)
    assert s.translate


@pytest.mark.parametrize(
    ("offset_m", "sigma_m", "significant"),
    [
        (0.046, 0.01, True),  # 4.60 sigma > 4.5943
        (0.0459, 0.01, False),  # 4.59 sigma < 4.5943
        (0.01, 0.0, True),  # an exact estimate: every offset is significant
        (0.0, 0.0, False),  # no offset at all
    ],
)
def test_offset_significance_is_the_chi_square_test(offset_m, sigma_m, significant):
    s = StationKeeping(P_STATION, Q_STATION, SP)
    assert s.offset_significant(offset_m, sigma_m) is significant


def test_significant_offset_inside_the_dead_band_is_not_corrected():
    # 3 cm at sigma 5 mm is 6 sigma, significant, but inside the 4 cm dead band
    s = StationKeeping(P_STATION, Q_STATION, SP)
    s.step(station_nav(0.03, sigma=0.005), DT)
    assert not s.translate


def test_insignificant_offset_does_not_start_but_a_started_correction_completes():
    # the test decides when to start; the hysteresis (settle_m, settle_speed_m_s) when to stop
    s = StationKeeping(P_STATION, Q_STATION, SP)
    s.step(station_nav(0.05, sigma=0.008), DT)
    assert s.translate
    s.step(station_nav(0.05, sigma=0.015), DT)  # the sigma grows: 3.3 sigma, but the correction goes on
    assert s.translate


def test_station_keeping_reference_is_the_initial_pose():
    s = StationKeeping(P_STATION, Q_STATION, SP)
    ref = s.step(station_nav(0.1, att_deg=5.0), DT)
    np.testing.assert_array_equal(ref.p_nav, P_STATION)
    np.testing.assert_allclose(ref.q_nav_body, Q_STATION)
    assert ref.range_m == pytest.approx(0.1)


# ---- parameter validation ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"align_distance_m": 0.16}, "guidance.align_distance_m"),  # inside keep-out + margin (0.18 m)
        ({"docking_face": "+w"}, "guidance.docking_face"),
        ({"approach_speed_m_s": -0.02}, "guidance.approach_speed_m_s"),
        ({"dock_speed_m_s": float("nan")}, "guidance.dock_speed_m_s"),
        ({"keepout_margin_m": -0.01}, "guidance.keepout_margin_m"),
        (
            {"keepout_radius_m": 0.1, "align_distance_m": 0.3},
            "guidance.keepout_radius_m",
        ),  # = docked distance
        ({"resume_sigma_pos_m": 0.07}, "guidance.resume_sigma_pos_m"),
        ({"hold_rejection_fraction": 0.0}, "guidance.hold_rejection_fraction"),
        ({"max_retries": -1}, "guidance.max_retries"),
        ({"max_retries": 1.5}, "guidance.max_retries"),
    ],
)
def test_guidance_params_errors_name_the_field(kwargs, field):
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        GuidanceParams(**kwargs)


@pytest.mark.parametrize("name", ["deadband_m", "settle_m", "settle_speed_m_s", "converged_sigma_m"])
def test_station_params_errors_name_the_field(name):
    with pytest.raises(ConfigError, match=rf"station\.{name}"):
        StationParams(**{name: -1.0})


@pytest.mark.parametrize("value", [0.0, 1.0, float("nan"), -0.5])
def test_station_significance_probability_must_be_a_probability(value):
    with pytest.raises(ConfigError, match=r"station\.significance_probability"):
        StationParams(significance_probability=value)


def test_default_guidance_params_are_valid_and_hashable():
    assert hash(GuidanceParams()) == hash(GuidanceParams())
