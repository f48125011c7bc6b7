"""The dashboard of a landing swarm without a browser (dashboard/landing.py, the landing panels): the camera
frustum's geometry and colour (a Vision frame with markers marks it detected, an empty one does not), the
pad's projection, the quadrotor drawer, the agents table with energy, and an app drawing a recorded landing
whose scenario it finds from the recording's run_start."""

from __future__ import annotations

import math
from pathlib import Path
from unittest.mock import MagicMock

import numpy as np
import pytest

from dashboard import kinds, landing
from dashboard.app import DashboardApp, DashboardParams
from dashboard.mapping import FOV_COLORS, MODE_COLORS
from dashboard.playback import Recording, load_recording, scenario_of
from dashboard.state import SwarmState
from swarm.core import rotations as rot
from swarm.kinds.quadrotor.dynamics import rotor_positions
from swarm.landing_scenario import LandingScenario, load_landing
from swarm.step.landing import LandingWorld
from swarm.transport.messages import Estimate, Guidance, Truth, Vision
from tests.dashboard.test_kinds import RecordingScene

LEVEL = np.array([0.0, 0.0, 0.0, 1.0])  # body = nav: the camera looks straight down


@pytest.fixture(scope="module")
def sc() -> LandingScenario:
    return load_landing("landing-swarm")


def _truth(p, effort=0.0, t=1.0, q=LEVEL):
    return Truth(100, t, np.asarray(p, float), np.array([0.5, 0.0, -0.3]), np.asarray(q, float), np.zeros(3),
                 effort)  # fmt: skip


def _vision(rows: int, t=1.0) -> Vision:
    return Vision(100, t, "pad-uav1", "+z", "pixels", np.full((rows, 2), 100.0), tuple(range(rows)))


def test_the_frustum_reaches_the_image_corners_through_the_intrinsics(sc):
    cam = sc.camera.intrinsics
    vertices, faces = landing.frustum_mesh(cam, depth_m=2.0)
    assert vertices.shape == (5, 3) and faces.shape == (6, 3) and faces.max() == 4
    np.testing.assert_array_equal(vertices[0], 0.0)
    # each base corner projects back onto an image corner (OpenCV pinhole)
    for (x, y, z), (u, v) in zip(vertices[1:], [(0, 0), (cam.width_px, 0), (cam.width_px, cam.height_px),
                                                 (0, cam.height_px)], strict=True):  # fmt: skip
        assert z == 2.0
        assert cam.fx_px * x / z + cam.cx_px == pytest.approx(u, abs=1e-3)
        assert cam.fy_px * y / z + cam.cy_px == pytest.approx(v, abs=1e-3)


def test_the_camera_looks_down_along_body_minus_z():
    wxyz = landing.camera_wxyz()
    r = rot.quat_to_matrix(np.array([*wxyz[1:], wxyz[0]]))
    np.testing.assert_allclose(r @ [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], atol=1e-12)


def test_a_pad_straight_below_is_at_the_principal_point_and_one_far_aside_is_out(sc):
    cam = sc.camera
    pad = np.array([8.0, 8.0, 0.0])
    above = pad + np.array([0.0, 0.0, 5.0]) - np.asarray(cam.pos_body_m)
    u, v = landing.pad_pixel(above, LEVEL, pad, np.asarray(cam.pos_body_m), cam.intrinsics)
    assert (u, v) == pytest.approx((cam.intrinsics.cx_px, cam.intrinsics.cy_px))
    # 20 m aside at 5 m height: 76 deg off the axis, outside a ~65 deg lens
    assert (
        landing.pad_pixel(
            pad + np.array([20.0, 0.0, 5.0]), LEVEL, pad, np.asarray(cam.pos_body_m), cam.intrinsics
        )
        is None
    )
    # rolled upside down the camera looks up: the pad is behind it
    flipped = rot.rotvec_exp(np.array([math.pi, 0.0, 0.0]))
    assert landing.pad_pixel(above, flipped, pad, np.asarray(cam.pos_body_m), cam.intrinsics) is None


def test_a_vision_frame_with_markers_marks_the_frustum_detected_and_an_empty_one_clears_it():
    state = SwarmState({"uav1": ("uav", None)}, np.zeros((1, 3)))
    assert state.snapshot().agents["uav1"].vision_rows is None
    state.on_message("vision", "uav1", _vision(8))
    rows = state.snapshot().agents["uav1"].vision_rows
    assert rows == 8 and landing.frustum_state(rows, pad_in_image=False) == "seen"
    state.on_message("vision", "uav1", _vision(0, t=1.05))
    rows = state.snapshot().agents["uav1"].vision_rows
    assert rows == 0
    assert landing.frustum_state(rows, pad_in_image=True) == "in_cone"
    assert landing.frustum_state(rows, pad_in_image=False) == "out"


def test_the_frustum_reaches_down_to_the_pad_plane_but_never_vanishes():
    assert landing.frustum_depth(6.5, 0.5) == 6.0
    assert landing.frustum_depth(0.05, 0.0) == landing.FRUSTUM_MIN_M


def test_a_quadrotor_is_a_hub_two_arms_and_four_rotor_discs_where_its_rotors_are(sc):
    scene = RecordingScene()
    body = kinds.draw_quadrotor(scene, "/u/truth/quad", landing._QuadKind(sc), (1, 2, 3))
    arm = sc.kinds.quadrotor.airframe.arm_m
    for i, p in enumerate(rotor_positions(arm)):
        shape, kw = scene.nodes[f"/u/truth/quad/rotor{i + 1}"]
        assert shape == "cylinder"
        np.testing.assert_allclose(kw["position"][:2], p[:2])
    assert {n for n in scene.nodes if "/arm" in n} == {"/u/truth/quad/arm1", "/u/truth/quad/arm2"}
    assert body.handles == ["/u/truth/quad/body", "/u/truth/quad/arm1", "/u/truth/quad/arm2"]


def test_the_mode_colour_goes_to_every_coloured_part_of_a_quadrotor():
    parts = kinds.Parts([MagicMock(), MagicMock()], (0, 0, 0))
    parts.color = MODE_COLORS["DESCEND"]
    assert [h.color for h in parts.handles] == [MODE_COLORS["DESCEND"]] * 2


def test_the_table_shows_each_uav_s_energy_altitude_and_pad_markers(sc):
    state = SwarmState(landing.uav_vehicles(sc), np.asarray(sc.uwb.anchors_m))
    state.on_message("truth", "uav2", _truth([-8.0, 8.0, 3.25], effort=12345.0))
    state.on_message("guidance", "uav2", Guidance(100, 1.0, "DESCEND", 0.42))
    state.on_message("vision", "uav2", _vision(20))
    pads = {u.id: u.pad_m for u in sc.uavs()}
    table = landing.landing_table(state.snapshot(), pads)
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]] for line in
            table.splitlines()[2:]}  # fmt: skip
    assert list(rows) == ["uav1", "uav2", "uav3", "uav4"]
    assert rows["uav2"] == ["DESCEND", "0.42", "3.25", "–", "5", "12.35", "unseen"]
    assert rows["uav1"][-2] == "–"  # nothing heard: no energy yet
    text = landing.landing_uav_markdown("uav2", state.snapshot().agents["uav2"], pads)
    assert "energy 12.35 kJ" in text and "DESCEND" in text and "pad markers in the latest frame 5" in text


def _estimate(p) -> Estimate:
    cov = np.diag([0.04, 0.04, 0.09, 0.01, 0.01, 0.01, 1e-4, 1e-4, 1e-4])
    return Estimate(100, 1.0, np.asarray(p, float), np.zeros(3), LEVEL, cov, 0.3, 0.5, 0.0, {})


def test_the_scene_colours_each_frustum_by_its_latest_frame_and_sizes_it_to_the_ground(sc):
    server = MagicMock()
    for method in ("add_frame", "add_mesh_simple", "add_icosphere", "add_line_segments", "add_box"):
        getattr(server.scene, method).side_effect = lambda *a, **k: MagicMock()  # a handle per node
    view = landing.LandingSceneView(server, sc, DashboardParams())
    state = SwarmState(landing.uav_vehicles(sc), np.asarray(sc.uwb.anchors_m))
    state.on_message("truth", "uav1", _truth([8.0, 8.0, 4.0]))  # above its pad: in the image
    state.on_message("truth", "uav3", _truth([-28.0, -10.0, 8.0]))  # 20 m away: out
    state.on_message("estimate", "uav1", _estimate([8.1, 8.0, 4.0]))
    state.on_message("vision", "uav1", _vision(8))
    view.update(state.snapshot(), trails_due=True)
    assert view.nodes["uav1"].fov.color == FOV_COLORS["seen"]
    assert view.nodes["uav1"].fov.scale == 4.0
    assert view.nodes["uav3"].fov.color == FOV_COLORS["out"]
    assert view.nodes["uav1"].cov.scale == pytest.approx((0.6, 0.6, 0.9))  # 3 sigma
    state.on_message("vision", "uav1", _vision(0, t=1.05))  # the markers are lost: pad still in the image
    view.update(state.snapshot(), trails_due=False)
    assert view.nodes["uav1"].fov.color == FOV_COLORS["in_cone"]
    names = {c.args[0] for c in server.scene.add_frame.call_args_list}
    assert {f"/pads/{u.id}" for u in sc.uavs()} <= names  # a pad for every UAV


def _landing_recording(path: Path, sc) -> Recording:
    """A small recording's decoded items (what load_recording returns) of a landing: two UAVs' truth,
    guidance and camera frames over 2 s, with the run_start metadata the landing world writes."""
    items, times = [], []
    for k in range(0, 201, 10):
        t = k * 0.01
        for uid, pad in (("uav1", (8.0, 8.0, 0.0)), ("uav4", (8.0, -8.0, 0.0))):
            p = np.array(pad) + np.array([3.0 - t, 0.0, 6.0 - t])
            items += [("truth", uid, _truth(p, effort=200.0 * t, t=t)),
                      ("guidance", uid, Guidance(k, t, "CRUISE" if t < 1 else "DESCEND", 3.0 - t)),
                      ("vision", uid, _vision(4 if t >= 1 else 0, t=t))]  # fmt: skip
            times += [round(t * 1e9)] * 3
    meta = {"run_start": {"scenario": sc.name, "mission": "landing", "uavs": "['uav1', 'uav4']"}}
    return Recording(path, "tpods", tuple(items), tuple(times), meta, 0)


def test_a_landing_recording_is_drawn_with_its_landing_scenario(tmp_path, sc):
    rec = _landing_recording(tmp_path / "r.mcap", sc)
    assert isinstance(scenario_of(rec, None), LandingScenario)
    assert scenario_of(rec, None).name == "landing-swarm"
    app = DashboardApp(scenario_of(rec, None), None, None, "127.0.0.1", 0, recording=rec)
    try:
        app.player.seek(1.5)
        app.frame()
        app.gui.update_panels(app.state.snapshot(), 0)
        table = app.gui.table.content
        assert "| uav1 | DESCEND | 1.50 |" in table and "| uav4 | DESCEND |" in table
        assert "0.30 |" in table  # 200 J/s for 1.5 s
        assert isinstance(app.scene, landing.LandingSceneView)
        assert app.scene.nodes["uav1"].fov.color == FOV_COLORS["seen"]
        assert not app.gui.buttons  # the landing world takes no run control
        # a recording's Faults panel: the landing world's kinds, the recorded faults listed, nothing to inject
        assert (
            app.gui.faults.menu == landing.LandingDrawer.fault_menu(LandingWorld.FAULTS)
            and tuple(app.gui.faults.kind.options) == LandingWorld.FAULTS
        )
        assert not app.gui.faults.button.visible and app.gui.faults.log.content == "no fault applied yet"
        app.player.seek(0.5)  # backward: CRUISE, no markers yet
        app.frame()
        app.gui.update_panels(app.state.snapshot(), 0)
        assert "| uav1 | CRUISE |" in app.gui.table.content
        assert app.scene.nodes["uav1"].fov.color != FOV_COLORS["seen"]
    finally:
        app.close()


def _tdoa_rows_per_s(path: Path, t_s: float, window_s: float = 2.0) -> dict[str, float]:
    """Each UAV's distance differences a second over ``(t_s - window_s, t_s]``, counted in the recording with
    plain msgpack (each ``agent/<id>/tdoa`` message's rows by its ``t_s``)."""
    import msgpack

    from swarm.transport.recording import read_recording

    rows: dict[str, int] = {}
    for m in read_recording(path)[0]:
        if m.key.endswith("/tdoa"):
            obj = msgpack.unpackb(m.payload, raw=False)
            if t_s - window_s < obj["t_s"] <= t_s + 1e-9:
                uid = m.key.split("/")[-2]
                rows[uid] = rows.get(uid, 0) + len(obj["anchor_b"])
    return {uid: n / window_s for uid, n in rows.items()}


def test_a_tdoa_landing_s_dashboard_shows_its_radio_rates_and_labels_its_anchors(tmp_path):
    """``swarm sim landing-swarm --set uwb.mode=tdoa3 --mcap`` (the landing world's wire, in process; 6 s of
    the approach) played in the landing dashboard: the Radio panel has a row for every anchor of the scenario
    and every UAV, each UAV's differences a second are those of the recording (counted with plain msgpack,
    within 3 %: the panel's window starts at a slot, the count at an instant), accepted at most as many, and
    each anchor's label in the scene says its panel rate."""
    from tests.inprocess import swarm_exit_status

    path = tmp_path / "tdoa.mcap"
    argv = ["sim", "landing-swarm", "--seed", "0", "--set", "uwb.mode=tdoa3", "--set", "max_duration_s=6",
            "--mcap", str(path)]  # fmt: skip
    assert swarm_exit_status(argv) == 1  # (not landed in 6 s: the run is cut short)
    rec = load_recording(path)
    sc = scenario_of(rec, None)
    app = DashboardApp(sc, None, None, "127.0.0.1", 0, recording=rec)
    try:
        t = 5.9
        app.player.seek(t)
        app.frame()
        snap = app.state.snapshot(radio=True)
        app.gui.update_panels(snap, 0)
        app.scene.update(snap, False)
        radio = snap.radio
        assert radio.mode == "tdoa" and "**TDOA**" in app.gui.radio.content
        assert [a.anchor for a in radio.anchors] == list(range(len(sc.uwb.anchors_m)))
        counted = _tdoa_rows_per_s(path, t)
        tags = {x.tag: x for x in radio.tags}
        assert set(tags) == {u.id for u in sc.uavs()} and max(counted.values()) > 50.0
        for uid, x in tags.items():
            assert x.heard_hz == pytest.approx(counted.get(uid, 0.0), rel=0.03, abs=1.0), uid
            assert x.accepted_hz <= x.heard_hz + 1e-9, uid
            assert f"| {uid} | {x.heard_hz:.1f} | {x.accepted_hz:.1f} |" in app.gui.radio.content
        for a in radio.anchors:
            assert f"| {a.anchor} | {a.best_hz:.1f} |" in app.gui.radio.content
            label = app.scene._anchor_labels[a.anchor].text
            assert label == f"anchor {a.anchor} · {a.best_hz:.0f}/s", label
    finally:
        app.close()


def test_a_moving_pad_is_drawn_where_its_robot_s_estimate_puts_it_and_the_robot_is_no_uav():
    """landing-moving: the robot's shared Estimate (agent/robot/estimate) moves the pad's frame (position at
    the deck's height, the robot's heading); the frustum's pad is that one (the UAV above the moved pad sees
    it in its image, where the pad started it would not); the robot gets no UAV nodes and no table row."""
    sc = load_landing("landing-moving")
    server = MagicMock()
    for method in ("add_frame", "add_mesh_simple", "add_icosphere", "add_line_segments", "add_box"):
        getattr(server.scene, method).side_effect = lambda *a, **k: MagicMock()
    view = landing.LandingSceneView(server, sc, DashboardParams())
    state = SwarmState(landing.uav_vehicles(sc), np.asarray(sc.uwb.anchors_m))
    yaw = math.radians(30.0)
    q = np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])
    cov = np.diag([0.0025] * 3 + [0.0004] * 3 + [0.0] * 3)
    moved = np.array([-3.0, 5.0, 0.4])  # 11 m from where the pad started, (7, -5)
    state.on_message("estimate", "robot", Estimate(100, 1.0, moved, np.array([-0.6, 0, 0]), q, cov, 0.05, 0.0,
                                                   0.0, {}))  # fmt: skip
    state.on_message("truth", "uav", _truth([-3.0, 5.0, 4.0]))  # 4 m above the moved pad
    view.update(state.snapshot(), trails_due=True)
    frame = view.pad_frames["uav"]
    assert frame.position == (-3.0, 5.0, 0.0)  # the deck's height, not the estimate's z
    np.testing.assert_allclose(frame.wxyz, [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    assert set(view.nodes) == {"uav"}
    assert view.nodes["uav"].fov.color == FOV_COLORS["in_cone"]  # the moved pad in the image, no frame yet
    pads = {u.id: u.pad_m for u in sc.uavs()}
    assert "robot" not in landing.landing_table(state.snapshot(), pads)
