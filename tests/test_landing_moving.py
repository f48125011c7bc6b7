"""The moving-platform landing (issue 44, the third mission; ``swarm/scenarios/landing-moving.toml``): the pad
rides a ground robot along its path (closed form), the camera sees the pad where the robot has it, a short
seeded run lands on the moving pad, a run restored mid-flight goes on to the bit, and a bad ``[platform]``
value is refused naming the key and the value. (The compiled landing equals the tick-by-tick one for this
scenario too: tests/test_landing.py's parametrisation.)"""

from __future__ import annotations

import math
import pickle

import cv2
import numpy as np
import pytest

from swarm.core import rotations as rot
from swarm.core.platform_path import path_pose, path_row
from swarm.errors import ConfigError
from swarm.landing_scenario import load_landing, platform_path
from swarm.sim.landing import run_landing
from swarm.step import landing_nb as lnb
from swarm.step.landing import LandingAgent, LandingWorld

NOMINAL = {"dispersions.enabled": False}

# A 4 x 3 m right triangle, driven at 1 m/s: the legs 4 and 3 m, the hypotenuse 5 m, a lap of 12 m.
TRIANGLE = ((0.0, 0.0), (4.0, 0.0), (4.0, 3.0))


@pytest.mark.parametrize(
    "t_s, closed, want",
    [
        (2.0, True, (2.0, 0.0, 1.0, 0.0, 0.0)),  # half the first leg
        (5.0, True, (4.0, 1.0, 0.0, 1.0, math.pi / 2)),  # 1 m up the second
        (9.5, True, (2.0, 1.5, -0.8, -0.6, math.atan2(-3.0, -4.0))),  # half the hypotenuse, back home
        (13.0, True, (1.0, 0.0, 1.0, 0.0, 0.0)),  # a lap and a metre: round again
        (20.0, False, (4.0, 3.0, 0.0, 0.0, math.pi / 2)),  # an open path: stopped at its last waypoint
    ],
)
def test_the_robot_is_where_its_path_says_at_any_time(t_s, closed, want):
    """Closed form (swarm.core.platform_path's docstring): arc length s = v t along the polyline, the
    segment's direction times v, its heading."""
    got = path_pose(path_row(TRIANGLE, closed, 1.0), 0.0, t_s)
    np.testing.assert_allclose(got, want, atol=1e-12)


def _world_at(sc, seed, k, above_m=None):
    """A landing world stepped to tick ``k`` on hover commands; with ``above_m``, the UAV's truth is first put
    that high over where the pad will be at tick ``k``, level."""
    world = LandingWorld(sc, seed)
    u = world.uavs["uav"]
    if above_m is not None:
        x, y = path_pose(world.PATH, u.setup.arc0_m, k * sc.dt_s)[:2]
        u.x[0:3] = (x, y, above_m)
        u.x[3:6] = 0.0
        u.x[6:10] = (0.0, 0.0, 0.0, 1.0)
        world.uavs["uav"].WSC[lnb.WSC_NEXT_ANCHOR] = 0.0
        inp = world.step(k)["uav"]
    else:
        for j in range(1, k + 1):
            inp = world.step(j)["uav"]
    return world, u, inp


def test_the_world_s_pad_moves_as_the_path_says():
    """Every tick the world's pad (position, velocity, attitude) is the path's pose at t = k dt from the
    robot's start, whose arc is dispersed per seed; the path's length is the toml's 54.64 m lap."""
    sc = load_landing("landing-moving", {"platform.speed_m_s": 0.6})
    assert math.isclose(platform_path(sc)[3], 54.6419, abs_tol=1e-3)
    world = LandingWorld(sc, 5)
    u = world.uavs["uav"]
    assert 0.0 <= u.setup.arc0_m < 54.65 and u.setup.arc0_m != sc.platform.start_arc_m
    for k in range(1, 301):
        world.step(k)
        x, y, vx, vy, yaw = path_pose(world.PATH, u.setup.arc0_m, k * sc.dt_s)
        np.testing.assert_allclose(u.WC[lnb.WC_PAD : lnb.WC_PAD + 3], (x, y, 0.0), atol=1e-12)
        np.testing.assert_allclose(u.WC[lnb.WC_PAD_V : lnb.WC_PAD_V + 3], (vx, vy, 0.0), atol=1e-12)
        R = u.WC[lnb.WC_R_NAV_PAD : lnb.WC_R_NAV_PAD + 9].reshape(3, 3)
        np.testing.assert_allclose(R, rot.quat_to_matrix(rot.rotvec_exp(np.array([0, 0, yaw]))), atol=1e-12)
    # 3 s at 0.6 m/s: 1.8 m along the track (a straight or a corner's chords, so at most that far as the crow
    # flies, and at least the chord of a 90 deg corner of 3 m radius's share of it)
    moved = np.linalg.norm(u.WC[lnb.WC_PAD : lnb.WC_PAD + 2] - u.setup.pad[:2])
    assert 1.6 < moved <= 1.8 + 1e-9


def test_the_camera_sees_the_pad_where_the_robot_has_it_not_where_it_started():
    """The corner-mode camera's pixels at tick 100 (1 s: the pad 0.6 m on) are OpenCV's projection of the
    board at the robot's pose of that tick (cv2.projectPoints, the camera's distortion: an independent
    projection) within the corners' noise, and far from the board's projection where the pad started."""
    sc = load_landing("landing-moving", {**NOMINAL, "platform.speed_m_s": 0.6})
    k = 100  # a camera tick (20 Hz at 100 Hz)
    world, u, inp = _world_at(sc, 0, k, above_m=4.0)
    ids, px = inp.camera
    assert len(ids) >= 4  # the 2 x 2 grid, 4 m below the camera (the small centre marker too small there)

    def project(pad_nav, R_nav_pad):
        R_nb = rot.quat_to_matrix(u.x[6:10])
        p_cam = u.x[0:3] + R_nb @ np.asarray(sc.camera.pos_body_m)
        R_cn = (R_nb @ np.diag([1.0, -1.0, -1.0])).T  # the camera's axis along body -z
        R_cp, t_cp = R_cn @ R_nav_pad, R_cn @ (pad_nav - p_cam)
        cam = sc.camera.intrinsics
        K = np.array([[cam.fx_px, 0, cam.cx_px], [0, cam.fy_px, cam.cy_px], [0, 0, 1.0]])
        obj = sc.pad.board.corners[ids - sc.pad.board.first_id].reshape(-1, 3)
        img, _ = cv2.projectPoints(obj, cv2.Rodrigues(R_cp)[0], t_cp, K, np.asarray(cam.distortion))
        return img.reshape(-1, 4, 2)

    x, y, _, _, yaw = path_pose(world.PATH, u.setup.arc0_m, k * sc.dt_s)
    R_now = rot.quat_to_matrix(rot.rotvec_exp(np.array([0.0, 0.0, yaw])))
    # the corners' noise: 0.12 + 6.5 / side px, side ~ 50 px at 4 m: ~0.25 px; 2 px is 8 sigma
    assert np.abs(px - project(np.array([x, y, 0.0]), R_now)).max() < 2.0
    start = project(u.setup.pad, rot.quat_to_matrix(u.setup.q_nav_pad))
    assert np.abs(px - start).max() > 50.0  # 0.6 m at 4 m is ~75 px


def test_the_uav_lands_on_the_moving_pad_with_both_policies():
    """A short seeded run at 0.6 m/s: the touchdown within pad_tolerance_m of the moving pad's centre and
    slower than touchdown_speed_m_s relative to it (the scenario's rule); the robot shared its estimate
    (the UAV's pad), so its descent chased the pad: without the sharing it lands where the pad was."""
    sc = load_landing("landing-moving", {"platform.speed_m_s": 0.6})
    for policy in ("mdp", "fixed"):
        r = run_landing(sc, policy, 0, record_series=False)
        assert r["landed"] and r["final_mode"] == "LANDED", r
        assert r["landing_error_m"] <= sc.pad_tolerance_m
        assert r["touchdown_rel_speed_m_s"] <= sc.platform.touchdown_speed_m_s
        assert 0.0 < r["touchdown_vz_m_s"] < 0.6  # the final descent's 0.3 m/s, not a drop
    blind_sc = load_landing("landing-moving", {"platform.speed_m_s": 0.6, "platform.share_estimate": False})
    blind = run_landing(blind_sc, "mdp", 0)
    assert not blind["landed"]


def test_a_moving_landing_restored_mid_flight_goes_on_to_the_bit():
    """World and agent snapshotted at tick 900 (the pad's pose and the robot's last shared estimate in
    them) and restored into new ones: every later command and the outcome are the uninterrupted run's."""
    sc = load_landing("landing-moving", {"platform.speed_m_s": 0.6})

    def fleet():
        return LandingWorld(sc, 1), LandingAgent(sc, 1, 0, "mdp")

    def run(world, agent, ticks):
        out = []
        for k in ticks:
            inputs = world.step(k)
            if not inputs:
                break
            cmd = agent.tick(inputs["uav"])
            world.hold("uav", cmd)
            out.append((k, cmd.u.tobytes(), str(cmd.mode)))
        return out

    w1, a1 = fleet()
    run(w1, a1, range(1, 901))
    ws, as_ = pickle.loads(pickle.dumps(w1.snapshot())), pickle.loads(pickle.dumps(a1.snapshot()))
    w2, a2 = fleet()
    w2.restore(ws)
    a2.restore(as_)
    n = round(sc.max_duration_s / sc.dt_s)
    assert run(w1, a1, range(901, n + 1)) == run(w2, a2, range(901, n + 1))
    assert w1.outcome("uav") == w2.outcome("uav") and a1.outcome() == a2.outcome()
    assert a1.outcome()["final_mode"] == "LANDED"


@pytest.mark.parametrize(
    "overrides, expected",
    [
        ({"platform.speed_m_s": -0.5}, r"platform\.speed_m_s must be a finite number > 0, got -0\.5"),
        ({"platform.share_rate_hz": 0}, r"platform\.share_rate_hz must be a finite number > 0, got 0"),
        ({"platform.waypoints_m": [[1.0, 2.0]]}, r"waypoints_m must list at least two .* \[\[1\.0, 2\.0\]\]"),
        (
            {"platform.waypoints_m": [[0.0, 0.0], [3.0, 0.0], [3.0, 0.0]]},
            r"platform\.waypoints_m\[1\] and the next are the same point \[3\.0, 0\.0\]",
        ),
        ({"platform.id": "a/b"}, r"platform\.id must be 1-64 letters, digits, '_' or '-', got 'a/b'"),
        ({"platform.start_arc_m": -1.0}, r"platform\.start_arc_m must be a finite number >= 0, got -1\.0"),
    ],
)
def test_a_bad_platform_is_refused_naming_the_key_and_the_value(overrides, expected):
    with pytest.raises(ConfigError, match=expected):
        load_landing("landing-moving", overrides)


def test_a_platform_with_a_fleet_is_refused(tmp_path):
    """One robot carries one pad: a [[fleet]] beside [platform] is refused, naming the file."""
    text = (load_landing.__globals__["SCENARIO_DIR"] / "landing-moving.toml").read_text()
    path = tmp_path / "two.toml"
    path.write_text(text + '\n[[fleet]]\nid = "a"\nstart_m = [1.0, 1.0, 5.0]\npad_m = [0.0, 0.0, 0.0]\n')
    with pytest.raises(ConfigError, match=r"two\.toml.*platform: a moving pad carries one UAV's pad"):
        load_landing(path)


def test_the_committed_moving_platform_campaign_reproduces_run_by_run():
    """docs/results/landing-moving-0.6-200-seed0 was written by `swarm montecarlo landing-moving --runs 200
    --set platform.speed_m_s=0.6`: its first runs, flown again from their seeds with its scenario.toml, give
    the same rows (touchdown included)."""
    import csv
    from pathlib import Path

    d = Path(__file__).resolve().parents[1] / "docs" / "results" / "landing-moving-0.6-200-seed0"
    rows = [r for r in csv.DictReader((d / "runs.csv").open()) if int(r["run"]) < 2]
    sc = load_landing(d / "scenario.toml")
    assert len(rows) == 4 and sc.platform.speed_m_s == 0.6
    for row in rows:
        r = run_landing(sc, row["policy"], int(row["seed"]), record_series=False)
        assert str(r["landed"]) == row["landed"]
        for key in ("energy_j", "landing_time_s", "landing_error_m", "touchdown_rel_speed_m_s",
                    "platform_start_arc_m"):  # fmt: skip
            assert repr(float(r[key])) == row[key] or str(r[key]) == row[key], key
