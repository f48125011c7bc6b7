"""Pure mapping of the dashboard (dashboard.mapping): messages to scene node names, poses, colours and
geometry, without a server. Oracles: scipy's Rotation for quaternions, closed-form geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dashboard import mapping
from swarm.errors import ConfigError
from swarm.transport.messages import MODES, Truth

CAM_POS_BODY = (0.0, 0.0, -0.05)  # the docking scenario's camera: bottom face, looking along body -z
Q_BODY_CAM = (1.0, 0.0, 0.0, 0.0)
HALF_ANGLE_DEG = 27.5


def _in_cone(p_chaser, q_chaser, p_target) -> bool:
    return mapping.target_in_cone(
        np.asarray(p_chaser, float), np.asarray(q_chaser, float), np.asarray(p_target, float),
        CAM_POS_BODY, Q_BODY_CAM, HALF_ANGLE_DEG, 0.05, 1.0,
    )  # fmt: skip


# ------------------------------------------------------------------------------------------ quaternions


def test_wxyz_of_identity_is_scalar_first() -> None:
    assert mapping.wxyz_from_xyzw([0.0, 0.0, 0.0, 1.0]).tolist() == [1.0, 0.0, 0.0, 0.0]


def test_wxyz_matches_scipy_scalar_first_order() -> None:
    rng = np.random.default_rng(5)
    for q in Rotation.random(20, random_state=rng).as_quat():
        expected = Rotation.from_quat(q).as_quat(scalar_first=True)
        np.testing.assert_allclose(mapping.wxyz_from_xyzw(q), expected, atol=1e-15)


def test_wxyz_is_normalised() -> None:
    np.testing.assert_allclose(np.linalg.norm(mapping.wxyz_from_xyzw([0.0, 0.0, 2.0, 2.0])), 1.0)


def test_wxyz_refuses_a_zero_quaternion() -> None:
    with pytest.raises(ValueError, match="non-zero"):
        mapping.wxyz_from_xyzw([0.0, 0.0, 0.0, 0.0])


def test_pose_of_a_truth_rotates_body_vectors_like_q_nav_body() -> None:
    q = Rotation.from_euler("xyz", [-90.0, 0.0, -90.0], degrees=True).as_quat()  # the paper's target
    truth = Truth(
        tick=1, t_s=0.01, p_nav=[1.0, 2.0, 1.0], v_nav=np.zeros(3), q_nav_body=q, w_body=np.zeros(3)
    )
    position, wxyz = mapping.pose_wxyz(truth.p_nav, truth.q_nav_body)
    v_body = np.array([0.3, -0.2, 0.9])
    viser_rotation = Rotation.from_quat(wxyz, scalar_first=True)  # how Viser reads a node's wxyz
    np.testing.assert_allclose(viser_rotation.apply(v_body), Rotation.from_quat(q).apply(v_body), atol=1e-12)
    assert position.tolist() == [1.0, 2.0, 1.0]


# ------------------------------------------------------------------------------------------ names, colours


def test_node_names_live_under_the_agent() -> None:
    assert mapping.node_name("chaser", "truth") == "/agents/chaser/truth"
    assert mapping.node_name("chaser", "truth/fov") == "/agents/chaser/truth/fov"
    assert mapping.node_name("target-2", "keepout") == "/agents/target-2/keepout"


def test_every_node_part_names_a_distinct_node() -> None:
    names = {mapping.node_name("a", part) for part in mapping.NODE_PARTS}
    assert len(names) == len(mapping.NODE_PARTS)


def test_node_name_refuses_an_unknown_part() -> None:
    with pytest.raises(ValueError, match="part must be one of"):
        mapping.node_name("chaser", "wheels")


def test_node_name_refuses_an_id_that_would_escape_its_subtree() -> None:
    with pytest.raises(ConfigError, match="agent id"):
        mapping.node_name("chaser/../target", "truth")


def test_anchor_node_name() -> None:
    assert mapping.anchor_node(3) == "/mothership/anchors/3"


def test_every_mode_has_its_own_colour() -> None:
    colors = [mapping.mode_color(m) for m in MODES if m != "STATION"]
    assert len(set(colors)) == len(colors)
    assert set(mapping.MODE_COLORS) == set(MODES)


def test_a_target_is_drawn_in_the_target_colour_whatever_its_mode() -> None:
    assert mapping.mode_color("DOCK", "target") == mapping.TARGET_COLOR


def test_no_mode_or_an_unknown_mode_is_grey() -> None:
    assert mapping.mode_color(None) == mapping.UNKNOWN_COLOR
    assert mapping.mode_color("WARP") == mapping.UNKNOWN_COLOR


def test_mode_levels_follow_the_paper_order() -> None:
    levels = [mapping.mode_level(m) for m in ("APPROACH", "REORIENT", "ALIGN", "DOCK", "DOCKED")]
    assert levels == sorted(levels) and len(set(levels)) == 5
    assert mapping.mode_level("ABORT") < mapping.mode_level("HOLD") < mapping.mode_level("APPROACH")


# ------------------------------------------------------------------------------------------ ellipsoid


def test_ellipsoid_reproduces_the_covariance() -> None:
    rng = np.random.default_rng(11)
    for _ in range(20):
        a = rng.normal(size=(3, 3)) * 0.02
        cov = a @ a.T + 1e-6 * np.eye(3)
        radii, wxyz = mapping.covariance_ellipsoid(cov, n_sigma=3.0, min_radius_m=0.0, min_ratio=0.0)
        r = Rotation.from_quat(wxyz, scalar_first=True).as_matrix()
        np.testing.assert_allclose(r @ np.diag(radii**2) @ r.T, 9.0 * cov, atol=1e-12)


def test_ellipsoid_of_a_diagonal_covariance_has_the_sigmas_as_radii() -> None:
    radii, _ = mapping.covariance_ellipsoid(np.diag([0.01**2, 0.02**2, 0.03**2]), n_sigma=1.0)
    np.testing.assert_allclose(np.sort(radii), [0.01, 0.02, 0.03])


def test_ellipsoid_of_a_collapsed_axis_keeps_a_drawable_radius() -> None:
    radii, _ = mapping.covariance_ellipsoid(np.diag([1e-4, 1e-4, 0.0]), n_sigma=3.0, min_radius_m=1e-4)
    assert radii.min() == pytest.approx(0.05 * 0.03)  # 5 % of the largest (3 x 1 cm), the default ratio


def test_a_planar_vehicles_ellipsoid_is_a_disc_not_a_degenerate_scale() -> None:
    """Height known to 0.03 mm against 1.2 cm in the plane (the ground filter's constraint): the drawn
    radius is floored at 5 % of the largest and at 1 mm, a thin disc rather than a near-singular scale."""
    radii, _ = mapping.covariance_ellipsoid(np.diag([1.2e-2**2, 1.2e-2**2, 3e-5**2]), n_sigma=3.0)
    assert np.sort(radii) == pytest.approx([0.05 * 0.036, 0.036, 0.036])
    radii, _ = mapping.covariance_ellipsoid(np.diag([1e-8, 1e-8, 0.0]), n_sigma=3.0)
    assert np.all(radii == 1e-3)


def test_ellipsoid_refuses_a_non_finite_covariance() -> None:
    with pytest.raises(ValueError, match="finite"):
        mapping.covariance_ellipsoid(np.full((3, 3), np.nan), 3.0)


# ------------------------------------------------------------------------------------------ camera


def test_cone_mesh_side_vertices_lie_at_the_half_angle() -> None:
    vertices, faces = mapping.fov_cone_mesh(HALF_ANGLE_DEG, 1.0, segments=16)
    assert vertices.shape == (18, 3) and faces.shape == (32, 3)
    assert vertices[0].tolist() == [0.0, 0.0, 0.0]
    ring = vertices[1:-1].astype(float)
    angles = np.degrees(np.arctan2(np.linalg.norm(ring[:, :2], axis=1), ring[:, 2]))
    np.testing.assert_allclose(angles, HALF_ANGLE_DEG, atol=1e-4)
    assert faces.min() == 0 and faces.max() == len(vertices) - 1


def test_camera_pose_in_body_converts_the_scenario_quaternion() -> None:
    pos, wxyz = mapping.camera_pose_in_body(CAM_POS_BODY, Q_BODY_CAM)
    optical_axis_body = Rotation.from_quat(wxyz, scalar_first=True).apply([0.0, 0.0, 1.0])
    np.testing.assert_allclose(optical_axis_body, [0.0, 0.0, -1.0], atol=1e-15)  # the bottom face
    assert pos.tolist() == list(CAM_POS_BODY)


def test_target_below_the_chaser_is_in_its_cone() -> None:
    assert _in_cone([0, 0, 0], [0, 0, 0, 1], [0.0, 0.0, -0.6])


def test_target_above_the_chaser_is_not_in_its_cone() -> None:
    assert not _in_cone([0, 0, 0], [0, 0, 0, 1], [0.0, 0.0, 0.6])


def test_target_beyond_the_camera_range_is_not_in_its_cone() -> None:
    assert not _in_cone([0, 0, 0], [0, 0, 0, 1], [0.0, 0.0, -1.2])


def test_cone_edge_is_the_half_angle_from_the_optical_centre() -> None:
    d = 0.5  # below the optical centre, which is 5 cm below the body centre
    for angle, inside in ((HALF_ANGLE_DEG - 0.5, True), (HALF_ANGLE_DEG + 0.5, False)):
        lateral = d * math.tan(math.radians(angle))
        assert _in_cone([0, 0, 0], [0, 0, 0, 1], [lateral, 0.0, -0.05 - d]) is inside


def test_cone_turns_with_the_chaser() -> None:
    flipped = Rotation.from_euler("x", 180.0, degrees=True).as_quat()  # bottom face now looks up
    assert _in_cone([0, 0, 0], flipped, [0.0, 0.0, 0.6])
    assert not _in_cone([0, 0, 0], flipped, [0.0, 0.0, -0.6])


def test_fov_is_seen_only_with_recent_markers() -> None:
    assert mapping.fov_state(9.8, 10.0, in_cone=False, recent_s=0.5) == "seen"
    assert mapping.fov_state(9.0, 10.0, in_cone=True, recent_s=0.5) == "in_cone"
    assert mapping.fov_state(None, 10.0, in_cone=False, recent_s=0.5) == "out"
    assert mapping.fov_state(12.0, 10.0, in_cone=False, recent_s=0.5) == "out"  # a previous run's frame


def test_every_fov_state_has_a_distinct_colour() -> None:
    assert len(set(mapping.FOV_COLORS.values())) == 3


# ------------------------------------------------------------------------------------------ radii, hull


def test_radii_hide_missing_and_zero_spheres() -> None:
    assert mapping.radii_of(1.0, 0.3, None) == {"r_t": 1.0, "r2": 0.3, "r1": None}
    assert mapping.radii_of(None, 0.0, 0.1) == {"r_t": None, "r2": None, "r1": 0.1}


def test_mothership_outline_is_the_padded_box_of_the_anchors() -> None:
    anchors = np.array([[1, -0.2, 0.5], [1, 0.2, -0.5], [-1, 0.2, -0.5], [-1, -0.2, 0.5]])
    segments = mapping.mothership_outline(anchors, pad_m=0.05)
    assert segments.shape == (12, 2, 3)
    lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    np.testing.assert_allclose(np.sort(lengths), [0.5] * 4 + [1.1] * 4 + [2.1] * 4)
    corners = {tuple(p) for p in segments.reshape(-1, 3).round(9)}
    assert len(corners) == 8
    np.testing.assert_allclose(segments.reshape(-1, 3).min(axis=0), [-1.05, -0.25, -0.55])
