"""Pure mapping from swarm messages to what the dashboard draws: scene node names, poses, colours,
covariance ellipsoids, the camera FOV cone and the mothership outline. No Viser, no Zenoh, no threads:
every function here is tested without a server.

Quaternions on the wire are scalar-last ``(x, y, z, w)`` (``docs/protocol.md``); Viser wants scalar-first
``wxyz``. :func:`wxyz_from_xyzw` is the one place that converts: every other function here that returns
an orientation goes through it.

Frames: ``nav`` is the navigation frame (the mothership's, a table's, a landing site's), the Viser world
frame of the dashboard (``+z`` up); ``body`` a vehicle's body frame; the camera frame is OpenCV's (``+z``
optical axis).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from swarm.core.rotations import matrix_to_quat, quat_to_matrix
from swarm.transport.keys import check_id

__all__ = [
    "FOV_COLORS",
    "MODE_COLORS",
    "MODE_LEVELS",
    "NODE_PARTS",
    "RADII_COLORS",
    "anchor_node",
    "camera_pose_in_body",
    "covariance_ellipsoid",
    "fov_cone_mesh",
    "fov_state",
    "mode_color",
    "mode_level",
    "mothership_outline",
    "node_name",
    "pose_wxyz",
    "radii_of",
    "target_in_cone",
    "wxyz_from_xyzw",
]

Rgb = tuple[int, int, int]

MODE_COLORS: dict[str, Rgb] = {
    "HOLD": (149, 165, 166),
    "APPROACH": (52, 152, 219),
    "REORIENT": (243, 156, 18),
    "ALIGN": (155, 89, 182),
    "DOCK": (46, 204, 113),
    "DOCKED": (30, 132, 73),
    "ABORT": (231, 76, 60),
    "STATION": (93, 109, 126),
    "CRUISE": (41, 128, 185),
    "DEVIATE": (230, 126, 34),
    "DESCEND": (142, 68, 173),
    "FINAL": (39, 174, 96),
    "CLIMB": (241, 196, 15),
    "LANDED": (22, 160, 133),
}
"""Colour of each guidance mode (``messages.MODES``): a chaser's body is drawn in its mode's colour."""
UNKNOWN_COLOR: Rgb = (127, 127, 127)
"""Colour of a vehicle without a known mode."""
TARGET_COLOR: Rgb = (93, 109, 126)
"""Colour of a target's body (its mode is ``STATION``)."""

MODE_LEVELS: dict[str, int] = {
    "ABORT": -1,
    "HOLD": 0,
    "APPROACH": 1,
    "REORIENT": 2,
    "ALIGN": 3,
    "DOCK": 4,
    "DOCKED": 5,
    "STATION": 0,
    "CRUISE": 1,
    "DEVIATE": 2,
    "CLIMB": 2,
    "DESCEND": 3,
    "FINAL": 4,
    "LANDED": 5,
}
"""Height of each mode on the mode-timeline plot: the paper's stages in order (Fig. 1), HOLD at 0 and
ABORT below it."""

FOV_COLORS: dict[str, Rgb] = {
    "seen": (46, 204, 113),
    "in_cone": (241, 196, 15),
    "out": (231, 76, 60),
}
"""Camera FOV cone colour (paper Fig. 1: "availability of vision measurements is depicted with a change in
the color of the camera FOV cone"): ``seen`` markers measured recently, ``in_cone`` the target's centre is
inside the cone but no markers came (e.g. the wrong face), ``out`` the target is out of view."""

RADII_COLORS: dict[str, Rgb] = {
    "r_t": (52, 152, 219),
    "r2": (243, 156, 18),
    "r1": (155, 89, 182),
    "keepout": (231, 76, 60),
}
"""Switch spheres around a target: ``r_t`` where Algorithm 1 starts, ``r2`` (APPROACH -> REORIENT, the
REORIENT colour), ``r1`` (REORIENT -> ALIGN, the ALIGN colour), and the keep-out sphere."""

NODE_PARTS: tuple[str, ...] = (
    "truth",
    "truth/body",
    "truth/axes",
    "truth/label",
    "truth/fov",
    "estimate",
    "estimate/body",
    "cov",
    "trail/truth",
    "trail/estimate",
    "radii/r_t",
    "radii/r2",
    "radii/r1",
    "keepout",
)
"""The scene nodes of one vehicle, under ``/agents/<id>/``. ``truth`` and ``estimate`` are frames that move
with the vehicle; their children (body box, axes, label, the camera cone) move with them. ``radii/*`` are
a chaser's switch spheres, drawn around its target; ``keepout`` is a target's keep-out sphere."""


def wxyz_from_xyzw(q_xyzw: Sequence[float] | np.ndarray) -> np.ndarray:
    """The quaternion ``q_xyzw`` (scalar-last, as on the wire and in ``swarm.core``) in Viser's scalar-first
    order ``(w, x, y, z)``, normalised. Shape (4,) -> (4,); the one conversion of the dashboard."""
    q = np.asarray(q_xyzw, dtype=np.float64).reshape(4)
    n = float(np.linalg.norm(q))
    if not (math.isfinite(n) and n > 0.0):
        raise ValueError(f"quaternion must be finite and non-zero, got {q.tolist()!r}")
    return np.array([q[3], q[0], q[1], q[2]]) / n


def node_name(agent_id: str, part: str) -> str:
    """Scene node of ``part`` (one of :data:`NODE_PARTS`) of vehicle ``agent_id``: ``/agents/<id>/<part>``.
    An id is one key chunk (``[A-Za-z0-9_-]``), so it cannot escape its subtree."""
    if part not in NODE_PARTS:
        raise ValueError(f"part must be one of {NODE_PARTS}, got {part!r}")
    return f"/agents/{check_id(agent_id)}/{part}"


def anchor_node(anchor_id: int) -> str:
    """Scene node of UWB anchor ``anchor_id``: ``/mothership/anchors/<id>``."""
    if not (isinstance(anchor_id, int) and anchor_id >= 0):
        raise ValueError(f"anchor id must be an integer >= 0, got {anchor_id!r}")
    return f"/mothership/anchors/{anchor_id}"


def pose_wxyz(p_nav: np.ndarray, q_nav_body: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Viser pose ``(position (3,) [m], wxyz (4,))`` of a vehicle at ``p_nav`` with attitude
    ``q_nav_body`` (x, y, z, w; body -> nav), as in a Truth or an Estimate message. Viser's node orientation
    maps local (body) vectors into the parent (nav) frame, like ``q_nav_body``."""
    return np.asarray(p_nav, dtype=np.float64).reshape(3).copy(), wxyz_from_xyzw(q_nav_body)


def mode_color(mode: str | None, role: str = "chaser") -> Rgb:
    """Body colour of a vehicle: a target's fixed colour, else its mode's (:data:`MODE_COLORS`); grey for no
    mode or an unknown one."""
    if role == "target":
        return TARGET_COLOR
    if mode is None:
        return UNKNOWN_COLOR
    return MODE_COLORS.get(mode, UNKNOWN_COLOR)


def mode_level(mode: str) -> int:
    """Height of ``mode`` on the timeline plot (:data:`MODE_LEVELS`); unknown modes at 0."""
    return MODE_LEVELS.get(mode, 0)


def covariance_ellipsoid(
    cov_pos: np.ndarray, n_sigma: float, min_radius_m: float = 1e-3, min_ratio: float = 0.05
) -> tuple[np.ndarray, np.ndarray]:
    """The ``n_sigma`` ellipsoid of a position covariance: ``(radii (3,) [m], wxyz (4,))`` for a unit sphere
    scaled by ``radii`` along its local axes, then rotated by ``wxyz``.

    ``cov_pos`` (3, 3) [m^2] in the nav frame (the ``d_p`` block of ``Estimate.cov``). With the eigen-
    decomposition ``P = V diag(lambda) V^T`` (V a rotation, det +1), the surface ``x^T P^-1 x = n^2`` is
    the unit sphere scaled by ``n sqrt(lambda_i)`` along ``V``'s columns. Radii are floored at
    ``min_radius_m`` and at ``min_ratio`` times the largest, so a collapsed axis draws as a thin disc (a
    planar vehicle's filter knows its height to ~0.03 mm against a centimetre in the plane) and never as a
    near-singular scale, whose normals the renderer would have to invert.
    """
    p = np.asarray(cov_pos, dtype=np.float64).reshape(3, 3)
    if not np.isfinite(p).all():
        raise ValueError("cov_pos must be finite")
    if not (math.isfinite(n_sigma) and n_sigma > 0):
        raise ValueError(f"n_sigma must be a positive finite number, got {n_sigma!r}")
    lam, v = np.linalg.eigh(0.5 * (p + p.T))
    if np.linalg.det(v) < 0.0:
        v[:, 2] = -v[:, 2]
    radii = n_sigma * np.sqrt(np.clip(lam, 0.0, None))
    radii = np.maximum(radii, max(min_radius_m, min_ratio * float(radii.max())))
    return radii, wxyz_from_xyzw(matrix_to_quat(v))


def camera_pose_in_body(
    pos_body_m: Sequence[float], q_body_cam: Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """Pose of the camera frame in the body frame: ``(position (3,) [m], wxyz (4,))`` from the scenario's
    ``camera.pos_body_m`` and ``camera.q_body_cam`` (x, y, z, w; camera -> body)."""
    return np.asarray(pos_body_m, dtype=np.float64).reshape(3).copy(), wxyz_from_xyzw(q_body_cam)


def fov_cone_mesh(
    half_angle_deg: float, length_m: float, segments: int = 24
) -> tuple[np.ndarray, np.ndarray]:
    """Triangle mesh of the camera's visibility cone in the camera frame (paper Fig. 1): apex at the optical
    centre, axis ``+z``, half angle ``half_angle_deg``, base at ``z = length_m``. Returns vertices
    ``(S + 2, 3)`` float32 (apex, ``S`` base-ring points, base centre) and faces ``(2 S, 3)`` uint32 (sides
    and base)."""
    if not (0.0 < half_angle_deg < 90.0):
        raise ValueError(f"half_angle_deg must be in (0, 90), got {half_angle_deg!r}")
    if not (length_m > 0.0 and segments >= 3):
        raise ValueError(f"need length_m > 0 and segments >= 3, got {length_m!r}, {segments!r}")
    radius = length_m * math.tan(math.radians(half_angle_deg))
    phi = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.full(segments, length_m)], axis=1)
    vertices = np.vstack([np.zeros((1, 3)), ring, [[0.0, 0.0, length_m]]]).astype(np.float32)
    i = np.arange(segments)
    j = (i + 1) % segments
    sides = np.stack([np.zeros(segments, dtype=int), 1 + i, 1 + j], axis=1)
    base = np.stack([np.full(segments, segments + 1), 1 + j, 1 + i], axis=1)
    return vertices, np.vstack([sides, base]).astype(np.uint32)


def target_in_cone(
    p_chaser_nav: np.ndarray,
    q_nav_chaser: np.ndarray,
    p_target_nav: np.ndarray,
    pos_body_m: Sequence[float],
    q_body_cam: Sequence[float],
    half_angle_deg: float,
    min_range_m: float,
    max_range_m: float,
) -> bool:
    """Whether the target's centre lies inside the chaser camera's visibility cone: within ``half_angle_deg``
    of the optical axis and at a range in ``[min_range_m, max_range_m]`` from the optical centre.

    ``p_cam = R_body_cam^T (R_nav_chaser^T (p_target - p_chaser) - pos_body)``, ``R(q)`` the matrix of a
    scalar-last quaternion (camera frame: OpenCV, ``+z`` optical axis)."""
    r_nav_body = quat_to_matrix(np.asarray(q_nav_chaser, dtype=np.float64))
    r_body_cam = quat_to_matrix(np.asarray(q_body_cam, dtype=np.float64))
    d_body = r_nav_body.T @ (np.asarray(p_target_nav, float) - np.asarray(p_chaser_nav, float))
    p_cam = r_body_cam.T @ (d_body - np.asarray(pos_body_m, dtype=np.float64))
    rng = float(np.linalg.norm(p_cam))
    if not (min_range_m <= rng <= max_range_m) or rng == 0.0:
        return False
    return bool(p_cam[2] >= rng * math.cos(math.radians(half_angle_deg)))


def fov_state(vision_t_s: float | None, now_t_s: float | None, in_cone: bool, recent_s: float) -> str:
    """Key of :data:`FOV_COLORS` for a chaser's camera: ``seen`` if markers were measured within ``recent_s``
    [s] of swarm time before ``now_t_s`` (the latest time known for that chaser), else ``in_cone`` if the
    target's centre is inside the cone, else ``out``."""
    if vision_t_s is not None and now_t_s is not None and 0.0 <= now_t_s - vision_t_s <= recent_s:
        return "seen"
    return "in_cone" if in_cone else "out"


def radii_of(r_t_m: float | None, r2_m: float | None, r1_m: float | None) -> dict[str, float | None]:
    """A chaser's switch spheres by name (``r_t``, ``r2``, ``r1``) from its Guidance message's radii [m];
    ``None`` (no switcher, or a zero radius) hides a sphere."""
    return {
        name: (float(r) if r is not None and r > 0.0 else None)
        for name, r in (("r_t", r_t_m), ("r2", r2_m), ("r1", r1_m))
    }


def mothership_outline(anchors_nav: np.ndarray, pad_m: float = 0.05) -> np.ndarray:
    """Line segments (12, 2, 3) [m, nav] of the mothership's outline: the box around its UWB anchors (the
    anchors sit on the mothership's hull; the scenario has no other geometry), grown by ``pad_m`` on each
    side so that a flat anchor layout still draws a box."""
    a = np.asarray(anchors_nav, dtype=np.float64).reshape(-1, 3)
    if a.shape[0] == 0 or not np.isfinite(a).all():
        raise ValueError(f"anchors_nav must be a non-empty finite (N, 3) array, got shape {a.shape}")
    lo, hi = a.min(axis=0) - pad_m, a.max(axis=0) + pad_m
    corners = np.array([[(lo, hi)[(k >> i) & 1][i] for i in range(3)] for k in range(8)])
    edges = [(k, k | (1 << i)) for k in range(8) for i in range(3) if not k & (1 << i)]
    return np.array([[corners[s], corners[e]] for s, e in edges])
