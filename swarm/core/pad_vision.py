"""A landing pad's fiducial board seen by a downward camera: the rendered image, ArUco detection and PnP.

Paper section VI-B: the quadrotor must see the pad early enough to land on it precisely. Frames: the
**pad frame** has its origin at the pad's centre, z up out of the surface, the markers in its xy-plane;
the **camera frame** is OpenCV's (+z the optical axis, +x right, +y down in the image). The pad's pose in
the camera is ``(t_cam_m, q_cam_pad)``: ``X_cam = R(q_cam_pad) X_pad + t_cam_m``, OpenCV's ``(rvec,
tvec)`` with ``rvec = log(q_cam_pad)``.

Two measurement modes, one downstream (:func:`estimate_pose`):

* ``"rendered"``: the image the camera would see (:class:`Renderer`): the board's texture mapped through
  the plane-to-image homography of the pose, the camera's radial-tangential distortion (Brown-Conrady,
  OpenCV's ``k1, k2, p1, p2, k3``) by a precomputed undistortion map, 2x supersampling, and white
  intensity noise; then ``cv2.aruco`` finds the markers (sub-pixel corner refinement).
* ``"corners"``: each marker corner projected by ``cv2.projectPoints`` with white pixel noise of
  ``corner_sigma_px``, a marker kept when all four corners are in the image and its side spans at least
  ``min_marker_px``: the Monte Carlo mode, ~100x cheaper. Its corner noise is white, which is
  conservative in attitude: a rendered marker's four corners err together, and the rendered mode's
  attitude errors are 0.3-0.9 times the corner mode's; position errors and the NEES agree
  (tests/core/test_pad_vision.py).

:func:`estimate_pose` solves ``cv2.solvePnP`` (``SOLVEPNP_IPPE``: every corner is coplanar) refined by
Levenberg-Marquardt on the reprojection error, and gives the covariance of ``(dt_cam [m], dphi_cam
[rad])``, ``dphi`` a camera-frame left perturbation (``R_meas = exp([dphi x]) R``), by first-order
backward propagation of the corner noise (each marker's ``sigma`` from its size in the image, the
sandwich ``(J^T J)^-1 J^T Sigma J (J^T J)^-1`` of the unweighted fit) with ``J`` the pixel Jacobian
(``cv2.projectPoints``' with respect to ``rvec, tvec``, distortion included) mapped to ``dphi`` through
the left Jacobian of SO(3) (Hartley & Zisserman 2004 sec. 5.2; Sola, Deray & Atchuthan 2018, eq. 145).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np

from swarm.core import rotations as rot
from swarm.errors import ConfigError

MODES = ("rendered", "corners")


@dataclass(frozen=True)
class PadBoardParams:
    """The fiducial board on the pad: a grid of ArUco markers around a small centre marker (for the last
    decimetres, when the big ones leave the image)."""

    dictionary: str = "DICT_4X4_50"
    """An OpenCV ArUco dictionary (``cv2.aruco.<name>``)."""
    grid: int = 2
    """Markers per side of the outer grid."""
    marker_size_m: float = 0.2
    """Side of each grid marker [m] (black border included)."""
    pitch_m: float = 0.32
    """Centre-to-centre distance of neighbouring grid markers [m]."""
    centre_size_m: float = 0.06
    """Side of the centre marker [m] (0: none)."""
    first_id: int = 0
    """Id of the first grid marker; the centre marker has ``first_id + grid**2``."""

    def __post_init__(self) -> None:
        if not hasattr(cv2.aruco, self.dictionary):
            raise ConfigError(f"pad.dictionary must be an OpenCV ArUco dictionary, got {self.dictionary!r}")
        if not (isinstance(self.grid, int) and 1 <= self.grid <= 6):
            raise ConfigError(f"pad.grid must be an integer in [1, 6], got {self.grid!r}")
        if not (math.isfinite(self.marker_size_m) and self.marker_size_m > 0):
            raise ConfigError(f"pad.marker_size_m must be > 0, got {self.marker_size_m!r}")
        if not (math.isfinite(self.pitch_m) and self.pitch_m > self.marker_size_m):
            raise ConfigError(
                f"pad.pitch_m must exceed marker_size_m = {self.marker_size_m!r}, got {self.pitch_m!r}"
            )
        gap = self.pitch_m - self.marker_size_m
        if self.grid % 2 == 1 and self.centre_size_m > 0:
            raise ConfigError(
                "pad.centre_size_m must be 0 with an odd grid (a grid marker sits at the centre)"
            )
        if not (0 <= self.centre_size_m < self.pitch_m - 0.5 * gap):
            raise ConfigError(
                f"pad.centre_size_m must be in [0, pitch - gap / 2), got {self.centre_size_m!r}"
            )

    @cached_property
    def markers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(ids (M,), centres (M, 2) [m], sizes (M,) [m])`` in the pad frame."""
        ids, centres, sizes = [], [], []
        off = (self.grid - 1) / 2.0
        for r in range(self.grid):
            for c in range(self.grid):
                ids.append(self.first_id + r * self.grid + c)
                centres.append(((c - off) * self.pitch_m, (off - r) * self.pitch_m))
                sizes.append(self.marker_size_m)
        if self.centre_size_m > 0:
            ids.append(self.first_id + self.grid**2)
            centres.append((0.0, 0.0))
            sizes.append(self.centre_size_m)
        return np.array(ids), np.array(centres, dtype=float), np.array(sizes, dtype=float)

    @cached_property
    def corners(self) -> np.ndarray:
        """Corners (M, 4, 3) [m] in the pad frame, in OpenCV's order (top-left, top-right, bottom-right,
        bottom-left as the marker image is drawn: x right, y up on the pad)."""
        _, centres, sizes = self.markers
        h = sizes[:, None] / 2.0
        dx = np.array([-1.0, 1.0, 1.0, -1.0])
        dy = np.array([1.0, 1.0, -1.0, -1.0])
        out = np.zeros((len(sizes), 4, 3))
        out[:, :, 0] = centres[:, 0:1] + h * dx
        out[:, :, 1] = centres[:, 1:2] + h * dy
        return out

    @property
    def half_extent_m(self) -> float:
        """Half the side of the square the board covers [m]."""
        return (self.grid - 1) / 2.0 * self.pitch_m + self.marker_size_m / 2.0

    def aruco(self):
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))


@dataclass(frozen=True)
class PadCameraParams:
    """The downward camera of the quadrotor (a 640 x 480 global-shutter module with a ~65 deg lens)."""

    width_px: int = 640
    height_px: int = 480
    fx_px: float = 500.0
    fy_px: float = 500.0
    cx_px: float = 319.5
    cy_px: float = 239.5
    distortion: tuple[float, float, float, float, float] = (-0.08, 0.02, 0.0, 0.0, 0.0)
    """``k1, k2, p1, p2, k3`` (OpenCV's radial-tangential model)."""
    image_noise: float = 3.0
    """White noise of each pixel's intensity (0-255 scale) of a rendered image."""
    corner_sigma_px: float = 0.12
    """Noise of a detected corner, per axis [px], for a large marker; with ``corner_sigma_k_px2``,
    ``sigma = corner_sigma_px + corner_sigma_k_px2 / side_px`` for a marker whose side spans ``side_px``:
    the corner mode's noise, and the PnP covariance's in both modes. Fitted to the rendered detector's
    corner errors (0.15 px at 200 px, 0.24 at 50, 0.39 at 25; tests/core/test_pad_vision.py)."""
    corner_sigma_k_px2: float = 6.5
    """How the corner noise grows as a marker shrinks [px^2] (sub-pixel refinement on fewer edge pixels)."""
    min_marker_px: float = 12.0
    """A marker whose side spans fewer pixels is not detected (the corner mode's model of the detector's
    limit: a 4x4 ArUco needs ~2 px per bit)."""

    def __post_init__(self) -> None:
        for name in ("fx_px", "fy_px", "corner_sigma_px", "corner_sigma_k_px2", "min_marker_px"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"pad_camera.{name} must be a positive finite number, got {v!r}")
        if not (math.isfinite(self.image_noise) and self.image_noise >= 0):
            raise ConfigError(f"pad_camera.image_noise must be >= 0, got {self.image_noise!r}")
        if len(self.distortion) != 5 or not all(math.isfinite(d) for d in self.distortion):
            raise ConfigError(f"pad_camera.distortion must be five finite numbers, got {self.distortion!r}")

    def corner_sigma(self, side_px) -> np.ndarray:
        """Corner noise [px] of markers whose sides span ``side_px`` (the shortest side)."""
        return self.corner_sigma_px + self.corner_sigma_k_px2 / np.maximum(np.asarray(side_px, float), 1.0)

    @cached_property
    def K(self) -> np.ndarray:
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])

    @cached_property
    def dist(self) -> np.ndarray:
        return np.array(self.distortion, dtype=float)


@dataclass(frozen=True)
class PadPose:
    """The pad's pose in the camera from one frame, with its covariance."""

    t_cam_m: np.ndarray
    q_cam_pad: np.ndarray
    cov_cam: np.ndarray
    """(6, 6) of ``(dt_cam [m], dphi_cam [rad])``, camera frame, left perturbation."""
    marker_ids: tuple[int, ...]
    reproj_rms_px: float


def _rvec(q: np.ndarray) -> np.ndarray:
    return rot.quat_log(np.asarray(q, dtype=float)).reshape(3, 1)


def _sides(px: np.ndarray) -> np.ndarray:
    """The shortest side [px] of each marker (M, 4, 2)."""
    return np.linalg.norm(px - np.roll(px, 1, axis=1), axis=2).min(axis=1)


def project_corners(board: PadBoardParams, cam: PadCameraParams, t_cam_m, q_cam_pad) -> np.ndarray:
    """Pixels (M, 4, 2) of every corner, distortion included (``cv2.projectPoints``)."""
    obj = board.corners.reshape(-1, 3)
    px, _ = cv2.projectPoints(
        obj, _rvec(q_cam_pad), np.asarray(t_cam_m, float).reshape(3, 1), cam.K, cam.dist
    )
    return px.reshape(-1, 4, 2)


def _in_front(board: PadBoardParams, t_cam_m, q_cam_pad) -> np.ndarray:
    R = rot.quat_to_matrix(np.asarray(q_cam_pad, float))
    pts = board.corners.reshape(-1, 3) @ R.T + np.asarray(t_cam_m, float)
    return (pts[:, 2] > 0.05).reshape(-1, 4).all(axis=1)


def corner_frame(board: PadBoardParams, cam: PadCameraParams, t_cam_m, q_cam_pad, rng: np.random.Generator):
    """The corner mode's detections ``(ids (K,), corners (K, 4, 2) [px])``: module docstring."""
    ids = board.markers[0]
    px = project_corners(board, cam, t_cam_m, q_cam_pad)
    inside = ((px[..., 0] >= 0) & (px[..., 0] <= cam.width_px - 1) & (px[..., 1] >= 0)
              & (px[..., 1] <= cam.height_px - 1)).all(axis=1)  # fmt: skip
    side = _sides(px)
    keep = inside & (side >= cam.min_marker_px) & _in_front(board, t_cam_m, q_cam_pad)
    sigma = cam.corner_sigma(side[keep])[:, None, None]
    noisy = px[keep] + rng.normal(0.0, 1.0, px[keep].shape) * sigma
    return ids[keep], noisy


class Renderer:
    """Renders the camera's image of the pad (module docstring). The undistortion map of the camera is
    computed once; a frame costs a remap of twice the image's size and a resize."""

    SUPERSAMPLE = 2
    TEXTURE_PX_PER_M = 2000.0
    BACKGROUND = 150  # the ground around the pad (grey)

    def __init__(self, board: PadBoardParams, cam: PadCameraParams) -> None:
        self.board, self.cam = board, cam
        s = self.SUPERSAMPLE
        w, h = cam.width_px * s, cam.height_px * s
        # the normalised undistorted coordinates of every supersampled pixel of the distorted image
        u, v = np.meshgrid((np.arange(w) + 0.5) / s - 0.5, (np.arange(h) + 0.5) / s - 0.5)
        pts = np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64).reshape(-1, 1, 2)
        und = cv2.undistortPoints(pts, cam.K, cam.dist).reshape(h, w, 2)
        self._xn = und[..., 0].astype(np.float64)
        self._yn = und[..., 1].astype(np.float64)
        tex, self._tex_origin = self._make_texture()
        # a mip-map: the level sampled has about twice the pixels per metre of the supersampled image at
        # the pad, so the bilinear remap never skips texels (no aliasing on the marker edges)
        self._levels = [(self.TEXTURE_PX_PER_M, tex)]
        while self._levels[-1][1].shape[0] > 64:
            k, t = self._levels[-1]
            self._levels.append(
                (k / 2, cv2.resize(t, (t.shape[1] // 2, t.shape[0] // 2), interpolation=cv2.INTER_AREA))
            )

    def _make_texture(self) -> tuple[np.ndarray, float]:
        b = self.board
        k = self.TEXTURE_PX_PER_M
        half = b.half_extent_m + 0.05  # a white margin around the markers
        n = round(2 * half * k)
        tex = np.full((n, n), 255, dtype=np.uint8)
        ids, centres, sizes = b.markers
        dictionary = b.aruco()
        for i, c, size in zip(ids, centres, sizes, strict=True):
            side = round(size * k)
            img = cv2.aruco.generateImageMarker(dictionary, int(i), side)
            col = round((c[0] + half) * k - side / 2)
            row = round((half - c[1]) * k - side / 2)
            tex[row : row + side, col : col + side] = img
        return tex, half

    def render(self, t_cam_m, q_cam_pad, rng: np.random.Generator | None = None) -> np.ndarray:
        """The 8-bit grey image (height, width) of the pad at pose ``(t_cam_m, q_cam_pad)``."""
        R = rot.quat_to_matrix(np.asarray(q_cam_pad, float))
        t = np.asarray(t_cam_m, float)
        # plane z = 0 of the pad to normalised camera coordinates: [x, y, 1] ~ [r1 r2 t] [X, Y, 1]
        Hm = np.column_stack([R[:, 0], R[:, 1], t])
        Hi = np.linalg.inv(Hm)
        a = Hi[0, 0] * self._xn + Hi[0, 1] * self._yn + Hi[0, 2]
        b = Hi[1, 0] * self._xn + Hi[1, 1] * self._yn + Hi[1, 2]
        c = Hi[2, 0] * self._xn + Hi[2, 1] * self._yn + Hi[2, 2]
        ok = c > 1e-9  # rays that meet the plane in front of the camera
        c = np.where(ok, c, 1.0)
        image_px_per_m = self.SUPERSAMPLE * self.cam.fx_px / max(float(t[2]), 1e-3)
        k, texture = next(
            ((k, x) for k, x in reversed(self._levels) if k >= 2.0 * image_px_per_m), self._levels[0]
        )
        half = self._tex_origin
        mapx = np.where(ok, (a / c + half) * k - 0.5, -1e6).astype(np.float32)
        mapy = np.where(ok, (half - b / c) * k - 0.5, -1e6).astype(np.float32)
        big = cv2.remap(texture, mapx, mapy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                        borderValue=self.BACKGROUND)  # fmt: skip
        img = cv2.resize(big, (self.cam.width_px, self.cam.height_px), interpolation=cv2.INTER_AREA)
        if rng is not None and self.cam.image_noise > 0:
            noisy = img.astype(np.float64) + rng.normal(0.0, self.cam.image_noise, img.shape)
            img = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
        return img


def make_detector(board: PadBoardParams):
    """An ``ArucoDetector`` for the board's dictionary, with sub-pixel corner refinement."""
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(board.aruco(), params)


def detect(image: np.ndarray, board: PadBoardParams, detector=None):
    """The board's markers found in ``image``: ``(ids (K,), corners (K, 4, 2) [px])``; ids not on the
    board are dropped."""
    detector = detector if detector is not None else make_detector(board)
    corners, ids, _ = detector.detectMarkers(image)
    if ids is None or len(ids) == 0:
        return np.zeros(0, dtype=int), np.zeros((0, 4, 2))
    ids = ids.ravel()
    known = np.isin(ids, board.markers[0])
    return ids[known], np.array(corners, dtype=float).reshape(-1, 4, 2)[known]


def _left_jacobian(phi: np.ndarray) -> np.ndarray:
    """``J_l`` of SO(3): ``exp(phi + d) ~ exp(J_l(phi) d) exp(phi)``."""
    th = float(np.linalg.norm(phi))
    K = rot.skew(phi)
    if th < 1e-8:
        return np.eye(3) + 0.5 * K
    return np.eye(3) + (1 - math.cos(th)) / th**2 * K + (th - math.sin(th)) / th**3 * (K @ K)


def estimate_pose(ids, corners_px, board: PadBoardParams, cam: PadCameraParams) -> PadPose | None:
    """The pad's pose from detected markers (module docstring); None with no marker or a failed solve."""
    if len(ids) == 0:
        return None
    index = {int(i): k for k, i in enumerate(board.markers[0])}
    obj = np.concatenate([board.corners[index[int(i)]] for i in ids]).astype(np.float64)
    img = np.asarray(corners_px, dtype=np.float64).reshape(-1, 2)
    if not (np.isfinite(img).all() and len(obj) >= 4):
        return None
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, img, cam.K, cam.dist, flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            return None
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, cam.K, cam.dist, rvec, tvec)
        proj, jac = cv2.projectPoints(obj, rvec, tvec, cam.K, cam.dist)
    except cv2.error:
        return None
    r = img - proj.reshape(-1, 2)
    J = jac[:, 0:6]  # d pixels / d (rvec, tvec)
    # each corner's noise from its marker's size; the fit is unweighted, so its covariance is the sandwich
    # (J^T J)^-1 J^T Sigma J (J^T J)^-1
    var = np.repeat(cam.corner_sigma(_sides(np.asarray(corners_px, float).reshape(-1, 4, 2))) ** 2, 8)
    try:
        inv = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return None
    cov_rt = inv @ (J.T * var) @ J @ inv
    phi = rvec.ravel()
    A = np.zeros((6, 6))
    A[0:3, 3:6] = np.eye(3)  # dt from tvec
    A[3:6, 0:3] = _left_jacobian(phi)  # dphi from rvec
    cov = A @ cov_rt @ A.T
    cov = 0.5 * (cov + cov.T)
    q = rot.rotvec_exp(phi)
    if q[3] < 0:
        q = -q
    if not (np.isfinite(cov).all() and np.all(np.diag(cov) > 0) and tvec.ravel()[2] > 0):
        return None
    rms = math.sqrt(float(np.mean(np.sum(r * r, axis=1))))
    return PadPose(tvec.ravel().astype(float), q, cov, tuple(int(i) for i in ids), rms)


def pose_error(est: PadPose, t_cam_m, q_cam_pad) -> np.ndarray:
    """``(dt_cam, dphi_cam)`` (6,) of an estimate against the true pose (left perturbation)."""
    dt = est.t_cam_m - np.asarray(t_cam_m, float)
    dq = rot.quat_mul(est.q_cam_pad, rot.quat_conj(np.asarray(q_cam_pad, float)))
    return np.concatenate([dt, rot.quat_log(dq)])
