"""Monocular camera on the chaser's bottom face seeing LED markers on the target's faces.

Frames. The camera frame follows OpenCV: +z is the optical axis, +x right and +y down in the image.
``q_body_cam`` maps camera vectors into the body frame (scalar-last, Hamilton, like every quaternion
here); the default ``(1, 0, 0, 0)`` is a half turn about body x, which points the optical axis along
body -z: the camera looks out of the bottom face (paper Fig. 5). The target's pose in the camera frame is
``(t_cam_m, q_cam_target)``: ``X_cam = R(q_cam_target) X_target + t_cam_m``, exactly OpenCV's
``(rvec, tvec)`` with ``rvec = log(q_cam_target)``.

Two measurement models (paper sec. III and IV-D):

* ``"features"`` (the paper's): the markers' positions in the camera frame with 1 mm white noise per axis;
  consumed by ``PoseEstimator.update_features``.
* ``"pnp"``: marker pixels from ``cv2.projectPoints`` plus white pixel noise, turned into a relative pose
  by :func:`solve_pnp` on the agent side with the covariance of ``(dt_cam, dphi_cam)``, where
  ``t_meas = t + dt_cam`` and ``R(q_cam_target_meas) = exp([dphi_cam x]) R(q_cam_target)`` (a
  camera-frame, left perturbation): consumed by ``PoseEstimator.update_pose``.
* ``"pose"``: a camera that solves PnP on board (the OpenMV's marker pose, paper sec. VI-A: "a pose at
  20 Hz") and reports the relative pose with its covariance: the true pose perturbed by a draw from the
  first-order covariance of PnP under white pixel noise, ``sigma_px^2 (J^T J)^-1`` at the true pose
  (:func:`pose_frame`; the covariance :func:`solve_pnp` reports, the Cramér-Rao bound of the fit). It
  keeps the pixel model's geometry (range, field of view, the pattern's conditioning) without solving PnP
  per simulated frame, and it is the model the compiled closed loop runs without Python; ``"pnp"`` keeps
  what a first-order model misses (the planar ambiguity's flips, outliers of the solver).

Markers. Six LEDs per face of the target cube (paper sec. IV-D: three for PnP, three more for
observability up close): a five-point X and one off-centre LED on a short standoff post, like the
standoff cross of a spacecraft centreline docking target. A flat pattern of this size seen by a 320 x 240
camera has the planar pose ambiguity (Schweighofer & Pinz 2006): beyond ~0.4 m the face's tilt is
observed only through weak perspective, solvePnP jumps between two mirror-tilted solutions, and the
first-order covariance stops describing the error (measured: mean NEES 12-38 instead of 6 at 0.5-0.8 m).
The standoff's parallax resolves the tilt (NEES ~6 from 0.15 m to 0.8 m and half the attitude
error at 0.3 m). Set its height to zero in ``pattern_m`` for a flat pattern.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from functools import cached_property, lru_cache

import cv2
import numba
import numpy as np
from numpy.typing import ArrayLike

from swarm.core._noise_nb import normals
from swarm.core._rot_nb import qconj, qexp, qlog, qmat, qmul, qnormalize
from swarm.errors import ConfigError

__all__ = [
    "DEFAULT_PATTERN_M",
    "FACES",
    "CameraModel",
    "CameraParams",
    "MarkerParams",
    "PnpResult",
    "camera_pose_nav",
    "face_markers",
    "face_normal",
    "facing_face",
    "feature_vectors",
    "pinhole",
    "pixel_jacobian",
    "pose_frame",
    "project_markers",
    "relative_pose",
    "solve_pnp",
    "visible",
]

FACES = ("+x", "-x", "+y", "-y", "+z", "-z")
"""Names of the target cube's faces: the sign and axis of the outward normal in the target body frame."""

# Per face: outward normal n and in-plane axes (s, t) with s x t = n, so a pattern reads the same (not
# mirrored) on every face when seen from outside.
_FACE_AXES = {
    "+x": ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    "-x": ((-1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    "+y": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)),
    "-y": ((0.0, -1.0, 0.0), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0)),
    "+z": ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    "-z": ((0.0, 0.0, -1.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
}

DEFAULT_PATTERN_M: tuple[tuple[float, float, float], ...] = (
    (0.0, 0.0, 0.0),
    (0.04, 0.04, 0.0),
    (-0.04, 0.04, 0.0),
    (-0.04, -0.04, 0.0),
    (0.04, -0.04, 0.0),
    (0.02, -0.015, 0.02),
)
"""Six markers ``(s, t, h)`` [m]: a five-point X and one off-centre LED 2 cm out on a standoff. ``s``,
``t`` are along the face's in-plane axes, ``h`` along its outward normal from the face plane. No
symmetry of the square maps the pattern onto itself, so the markers can be told apart by their layout."""


class CameraModel(enum.StrEnum):
    FEATURES = "features"  # paper: marker positions in the camera frame, 1 mm noise
    PNP = "pnp"  # pixels -> solvePnP -> relative pose with covariance
    POSE = "pose"  # the relative pose and covariance of an on-board PnP (first-order noise model)


def _finite_tuple(section: str, name: str, value, n: int) -> None:
    v = np.asarray(value, dtype=np.float64) if _is_numeric_seq(value) else None
    if v is None or v.shape != (n,) or not np.all(np.isfinite(v)):
        raise ConfigError(f"{section}.{name} must be {n} finite numbers, got {value!r}")


def _is_numeric_seq(value) -> bool:
    return isinstance(value, tuple | list) and all(isinstance(x, int | float) for x in value)


@dataclass(frozen=True)
class MarkerParams:
    """LED markers on every face of the target cube, in the target body frame."""

    half_size_m: float = 0.05
    """Half the edge of the target cube [m]: the face planes are at +-half_size from its centre."""
    pattern_m: tuple[tuple[float, float, float], ...] = DEFAULT_PATTERN_M
    """Markers ``(s, t, h)`` [m] on one face (see ``DEFAULT_PATTERN_M``); the same on every face."""

    def __post_init__(self) -> None:
        v = self.half_size_m
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise ConfigError(
                f"markers.half_size_m must be a positive finite number, got {self.half_size_m!r}"
            )
        pattern = tuple(tuple(p) for p in self.pattern_m)
        if len(pattern) < 4 or not all(_is_numeric_seq(p) and len(p) == 3 for p in pattern):
            raise ConfigError(
                f"markers.pattern_m must be at least 4 (s, t, h) triples, got {self.pattern_m!r}"
            )
        a = np.array(pattern, dtype=np.float64)
        if not np.all(np.isfinite(a)) or np.any(np.abs(a[:, :2]) > self.half_size_m):
            raise ConfigError(
                f"markers.pattern_m must be finite with |s|, |t| <= half_size_m, got {self.pattern_m!r}"
            )
        d = np.linalg.norm(a[:, None, :] - a[None, :, :], axis=-1) + np.eye(len(a))
        if np.min(d) < 1e-6:
            raise ConfigError(f"markers.pattern_m must hold distinct markers, got {self.pattern_m!r}")
        object.__setattr__(self, "pattern_m", pattern)

    def markers(self, face: str) -> np.ndarray:
        """Markers of ``face`` (N, 3) [m], target body frame (a fresh array); see :func:`face_markers`."""
        return self._markers_ro(face).copy()

    def _markers_ro(self, face: str) -> np.ndarray:
        """The cached, read-only marker array of ``face`` (for this module's per-frame calls)."""
        by_face = self._by_face
        if face not in by_face:
            raise ValueError(f"face must be one of {FACES}, got {face!r}")
        return by_face[face]

    @cached_property
    def _by_face(self) -> dict[str, np.ndarray]:
        return {face: _face_markers(face, float(self.half_size_m), self.pattern_m) for face in FACES}


_DEFAULT_MARKERS = MarkerParams()
_FACE_NORMALS = {face: np.array(axes[0]) for face, axes in _FACE_AXES.items()}
for _n in _FACE_NORMALS.values():
    _n.setflags(write=False)


def face_normal(face: str) -> np.ndarray:
    """Outward unit normal (3,) of ``face`` ("+x", "-x", "+y", "-y", "+z", "-z"), target body frame."""
    if face not in _FACE_AXES:
        raise ValueError(f"face must be one of {FACES}, got {face!r}")
    return np.array(_FACE_AXES[face][0])


def face_markers(
    face: str,
    half_size_m: float = 0.05,
    pattern_m: tuple[tuple[float, float, float], ...] = DEFAULT_PATTERN_M,
) -> np.ndarray:
    """Marker positions (N, 3) [m] on ``face`` in the target body frame (a fresh array):
    ``(half_size + h) n + s e_s + t e_t`` for each ``(s, t, h)`` of ``pattern_m``, with ``n`` the face's
    outward normal and ``(e_s, e_t, n)`` right-handed."""
    if face not in _FACE_AXES:
        raise ValueError(f"face must be one of {FACES}, got {face!r}")
    return _face_markers(
        face, float(half_size_m), tuple(tuple(float(x) for x in p) for p in pattern_m)
    ).copy()


@lru_cache(maxsize=64)
def _face_markers(face: str, half_size_m: float, pattern_m: tuple) -> np.ndarray:
    n, e_s, e_t = (np.array(v) for v in _FACE_AXES[face])
    p = np.array(pattern_m, dtype=np.float64)
    out = (half_size_m + p[:, 2:3]) * n + p[:, 0:1] * e_s + p[:, 1:2] * e_t
    out.setflags(write=False)  # shared by every caller through the cache
    return out


@dataclass(frozen=True)
class CameraParams:
    """A monocular camera of the OpenMV H7 class (paper sec. VI-A, Fig. 7): 320 x 240 pixels, ~70 deg
    horizontal field of view, on the chaser's bottom face, at 20 Hz."""

    rate_hz: float = 20.0
    """Frame rate [Hz] (paper sec. VI-A: vision at 20 Hz)."""
    fx_px: float = 228.0
    """Focal length along image x [px]; 2 atan(160 / 228) = 70.1 deg horizontal field of view."""
    fy_px: float = 228.0
    """Focal length along image y [px] (square pixels)."""
    cx_px: float = 159.5
    """Principal point x [px]: the image centre with OpenCV's integer pixel centres."""
    cy_px: float = 119.5
    """Principal point y [px]."""
    width_px: int = 320
    """Image width [px]; the sensor spans x in [-0.5, width - 0.5]."""
    height_px: int = 240
    """Image height [px]; the sensor spans y in [-0.5, height - 0.5]."""
    fov_half_angle_deg: float = 27.5
    """Half angle of the visibility cone around the optical axis [deg] (the FOV cone of paper Fig. 1):
    just inside the image's inscribed cone, atan(120.5 / 228) = 27.9 deg; it may not exceed the image
    diagonal's half angle."""
    min_range_m: float = 0.05
    """Nearest range at which the target face is measured [m] (focus, LED blooming)."""
    max_range_m: float = 1.0
    """Farthest range at which the target face is measured [m] (marker blobs too small beyond)."""
    pixel_sigma_px: float = 0.5
    """White noise of each marker's pixel coordinates, per axis [px]."""
    pos_body_m: tuple[float, float, float] = (0.0, 0.0, -0.05)
    """Optical centre in the chaser's body frame [m]: the centre of its bottom (-z) face. Must equal
    ``EstimatorParams.camera_pos_body_m``."""
    q_body_cam: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    """Camera-to-body rotation, scalar-last; the default turns the optical axis (+z) to body -z. Must equal
    ``EstimatorParams.q_body_cam``."""
    model: CameraModel = CameraModel.FEATURES
    """``features`` (paper: marker positions in the camera frame), ``pnp`` (pixels -> solvePnP) or ``pose``
    (an on-board PnP's pose and covariance, module docstring)."""
    feature_sigma_m: float = 0.001
    """Feature-vector noise per axis in the camera frame [m] (paper sec. III: 1 mm)."""
    pnp_refine_iterations: int = 1
    """Gauss-Newton steps on the reprojection error after SQPnP (0 keeps SQPnP's own estimate)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "model", _model(self.model))
        for name in ("rate_hz", "fx_px", "fy_px", "pixel_sigma_px", "feature_sigma_m", "max_range_m"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"camera.{name} must be a positive finite number, got {v!r}")
        for name in ("width_px", "height_px"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v > 0):
                raise ConfigError(f"camera.{name} must be a positive integer, got {v!r}")
        for name, hi in (("cx_px", self.width_px), ("cy_px", self.height_px)):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and -0.5 <= v <= hi - 0.5):
                raise ConfigError(f"camera.{name} must lie on the sensor, in [-0.5, {hi - 0.5}], got {v!r}")
        if not (isinstance(self.min_range_m, int | float) and 0 <= self.min_range_m < self.max_range_m):
            raise ConfigError(
                f"camera.min_range_m must be in [0, max_range_m = {self.max_range_m!r}), "
                f"got {self.min_range_m!r}"
            )
        limit = self.diagonal_half_angle_deg
        v = self.fov_half_angle_deg
        if not (isinstance(v, int | float) and 0 < v <= limit):
            raise ConfigError(
                f"camera.fov_half_angle_deg must be in (0, {limit:.2f}] (the image diagonal), got {v!r}"
            )
        _finite_tuple("camera", "pos_body_m", self.pos_body_m, 3)
        _finite_tuple("camera", "q_body_cam", self.q_body_cam, 4)
        for name in ("pos_body_m", "q_body_cam"):  # lists from a scenario file: keep the dataclass hashable
            object.__setattr__(self, name, tuple(float(x) for x in getattr(self, name)))
        if abs(math.hypot(*self.q_body_cam) - 1.0) > 1e-6:
            raise ConfigError(f"camera.q_body_cam must be a unit quaternion, got {self.q_body_cam!r}")
        it = self.pnp_refine_iterations
        if not (isinstance(it, int) and not isinstance(it, bool) and it >= 0):
            raise ConfigError(f"camera.pnp_refine_iterations must be a non-negative integer, got {it!r}")

    @property
    def diagonal_half_angle_deg(self) -> float:
        """Half angle [deg] of the cone through the farthest image corner (circumscribed cone)."""
        dx = max(self.cx_px + 0.5, self.width_px - 0.5 - self.cx_px) / self.fx_px
        dy = max(self.cy_px + 0.5, self.height_px - 0.5 - self.cy_px) / self.fy_px
        return math.degrees(math.atan(math.hypot(dx, dy)))

    @cached_property
    def K(self) -> np.ndarray:
        """Intrinsic matrix (3, 3) (Hartley & Zisserman 2004, sec. 6.1), read-only."""
        k = np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])
        k.setflags(write=False)
        return k

    @cached_property
    def visibility_vector(self) -> np.ndarray:
        """``[fx, fy, cx, cy, width, height, min_range, max_range, cos(fov_half_angle)]`` for the
        compiled visibility test, read-only."""
        a = np.array(
            [self.fx_px, self.fy_px, self.cx_px, self.cy_px, self.width_px, self.height_px,
             self.min_range_m, self.max_range_m, math.cos(math.radians(self.fov_half_angle_deg))]
        )  # fmt: skip
        a.setflags(write=False)
        return a

    @cached_property
    def pos_body(self) -> np.ndarray:
        """``pos_body_m`` as a read-only (3,) array [m]."""
        a = np.array(self.pos_body_m, dtype=np.float64)
        a.setflags(write=False)
        return a

    @cached_property
    def q_body_cam_arr(self) -> np.ndarray:
        """``q_body_cam`` as a read-only (4,) array."""
        a = np.array(self.q_body_cam, dtype=np.float64)
        a.setflags(write=False)
        return a


def _model(value) -> CameraModel:
    try:
        return CameraModel(value)
    except ValueError:
        raise ConfigError(
            f"camera.model must be one of {[m.value for m in CameraModel]}, got {value!r}"
        ) from None


# ---- geometry ------------------------------------------------------------------------------------------


def _vec(x: ArrayLike, n: int) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64).reshape(n)


def _f64(x: ArrayLike) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def camera_pose_nav(
    p_nav: ArrayLike, q_nav_body: ArrayLike, params: CameraParams
) -> tuple[np.ndarray, np.ndarray]:
    """Camera pose ``(p_cam_nav (3,) [m], q_nav_cam (4,))`` of a vehicle at ``p_nav`` (3,) [m] with attitude
    ``q_nav_body`` (4,): ``p_cam = p + R(q_nav_body) pos_body``, ``q_nav_cam = q_nav_body (x) q_body_cam``."""
    p = _vec(p_nav, 3)
    q = _vec(q_nav_body, 4)
    return p + qmat(q) @ params.pos_body, qmul(q, params.q_body_cam_arr)


def relative_pose(
    p_cam_nav: ArrayLike, q_nav_cam: ArrayLike, p_target_nav: ArrayLike, q_nav_target: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """The target's pose in the camera frame ``(t_cam_m (3,) [m], q_cam_target (4,))``:
    ``t = R(q_nav_cam)^T (p_target - p_cam)``, ``q_cam_target = q_nav_cam^-1 (x) q_nav_target``."""
    q_c = _vec(q_nav_cam, 4)
    t = qmat(q_c).T @ (_vec(p_target_nav, 3) - _vec(p_cam_nav, 3))
    return t, qmul(qconj(q_c), _vec(q_nav_target, 4))


# The kernels below run once per camera frame (20 Hz per vehicle). Compiled although the project compiles
# only >= 100 Hz code: in numpy, visible() + feature_vectors() measured ~30 us per frame, 0.6 ms of the
# 2 ms a vehicle may spend per simulated second at 500x real time; compiled, ~7 us.


@numba.njit(cache=True)
def _markers_in_camera(markers, p_t, q_t, p_c, q_c):
    """Markers (N, 3) [m, target frame] in the camera frame: ``R_c^T (p_t + R_t m - p_c)``."""
    R_t = qmat(q_t)
    R_c = qmat(q_c)
    n = markers.shape[0]
    out = np.empty((n, 3))
    for j in range(n):
        mx, my, mz = markers[j, 0], markers[j, 1], markers[j, 2]
        w0 = p_t[0] - p_c[0] + R_t[0, 0] * mx + R_t[0, 1] * my + R_t[0, 2] * mz
        w1 = p_t[1] - p_c[1] + R_t[1, 0] * mx + R_t[1, 1] * my + R_t[1, 2] * mz
        w2 = p_t[2] - p_c[2] + R_t[2, 0] * mx + R_t[2, 1] * my + R_t[2, 2] * mz
        for i in range(3):
            out[j, i] = R_c[0, i] * w0 + R_c[1, i] * w1 + R_c[2, i] * w2
    return out


@numba.njit(cache=True)
def _visible_kernel(markers, centre_t, normal_t, p_t, q_t, p_c, q_c, cam):
    """:func:`visible` for one face; ``cam = [fx, fy, cx, cy, width, height, r_min, r_max, cos_half]``."""
    R_t = qmat(q_t)
    R_c = qmat(q_c)
    los = p_t - p_c + R_t @ centre_t  # optical centre -> face centre, frame nav
    if (R_t @ normal_t) @ los >= 0.0:  # face turned away
        return False
    los_c = R_c.T @ los
    d = math.sqrt(los_c @ los_c)
    if d < cam[6] or d > cam[7] or los_c[2] < d * cam[8]:
        return False
    X = _markers_in_camera(markers, p_t, q_t, p_c, q_c)
    for j in range(X.shape[0]):
        if X[j, 2] <= 0.0:
            return False
        u = cam[0] * X[j, 0] / X[j, 2] + cam[2]
        v = cam[1] * X[j, 1] / X[j, 2] + cam[3]
        if u < -0.5 or u > cam[4] - 0.5 or v < -0.5 or v > cam[5] - 0.5:
            return False
    return True


def pinhole(points_cam: ArrayLike, params: CameraParams) -> np.ndarray:
    """Pin-hole pixels (N, 2) of camera-frame points (N, 3) [m] with zero distortion:
    ``u = fx X / Z + cx``, ``v = fy Y / Z + cy`` (Hartley & Zisserman 2004, sec. 6.1)."""
    X = np.asarray(points_cam, dtype=np.float64)
    iz = 1.0 / X[:, 2]
    return np.stack(
        [params.fx_px * X[:, 0] * iz + params.cx_px, params.fy_px * X[:, 1] * iz + params.cy_px], -1
    )


def facing_face(p_cam_nav: ArrayLike, p_target_nav: ArrayLike, q_nav_target: ArrayLike) -> str:
    """The target face whose outward normal points most nearly at the camera (the one worth testing with
    :func:`visible`)."""
    q_t = _vec(q_nav_target, 4)
    v = qmat(q_t).T @ (_vec(p_cam_nav, 3) - _vec(p_target_nav, 3))  # camera seen from the target
    i = int(np.argmax(np.abs(v)))
    return ("+" if v[i] >= 0 else "-") + "xyz"[i]


def visible(
    p_cam_nav: ArrayLike,
    q_nav_cam: ArrayLike,
    p_target_nav: ArrayLike,
    q_nav_target: ArrayLike,
    face: str,
    params: CameraParams,
    marker_params: MarkerParams | None = None,
) -> bool:
    """Whether the camera measures ``face`` of the target (paper sec. IV-D: only inside the FOV cone).

    True when the face centre is inside the FOV cone (``angle(optical axis, line of sight) <=
    fov_half_angle``) and within ``[min_range_m, max_range_m]`` of the optical centre, the face is turned
    towards the camera (outward normal . line of sight < 0), and every marker is in front of the camera
    and projects onto the sensor. Occlusion by the target's other faces is not modelled.
    """
    mp = _DEFAULT_MARKERS if marker_params is None else marker_params
    normal = _FACE_NORMALS[face] if face in _FACE_NORMALS else face_normal(face)
    return bool(
        _visible_kernel(
            mp._markers_ro(face), mp.half_size_m * normal, normal, _f64(p_target_nav), _f64(q_nav_target),
            _f64(p_cam_nav), _f64(q_nav_cam), params.visibility_vector,
        )
    )  # fmt: skip


# ---- measurement models ---------------------------------------------------------------------------------


def feature_vectors(
    markers_target: ArrayLike,
    p_target_nav: ArrayLike,
    q_nav_target: ArrayLike,
    p_cam_nav: ArrayLike,
    q_nav_cam: ArrayLike,
    params: CameraParams,
    rng: np.random.Generator | None,
) -> np.ndarray:
    """The paper's vision measurement: marker positions (N, 3) [m] in the camera frame plus white noise
    ``N(0, feature_sigma^2)`` per axis (paper sec. III: the pixels converted to camera-frame position
    vectors, then 1 mm noise; sec. IV-D). ``markers_target`` (N, 3) [m] in the target body frame; the
    target and camera poses in frame ``nav``. ``rng=None`` gives the noiseless vectors."""
    f = _markers_in_camera(
        _f64(markers_target), _f64(p_target_nav), _f64(q_nav_target), _f64(p_cam_nav), _f64(q_nav_cam)
    )
    if rng is not None:
        f += params.feature_sigma_m * rng.standard_normal(f.shape)
    return f


def project_markers(
    markers_target: ArrayLike,
    p_target_nav: ArrayLike,
    q_nav_target: ArrayLike,
    p_cam_nav: ArrayLike,
    q_nav_cam: ArrayLike,
    params: CameraParams,
    rng: np.random.Generator | None,
) -> np.ndarray:
    """Measured marker pixels (N, 2): ``cv2.projectPoints`` of ``markers_target`` (N, 3) [m, target
    frame] with the target's pose in the camera frame as ``(rvec, tvec)`` and zero distortion, plus white
    noise ``N(0, pixel_sigma^2)`` per coordinate. ``rng=None`` gives the noiseless pixels. Whether the
    markers are in view is :func:`visible`'s business."""
    t, q = relative_pose(p_cam_nav, q_nav_cam, p_target_nav, q_nav_target)
    obj = np.ascontiguousarray(markers_target, dtype=np.float64)
    uv, _ = cv2.projectPoints(obj, qlog(q), t, params.K, None)
    uv = uv.reshape(-1, 2)
    if rng is not None:
        uv += params.pixel_sigma_px * rng.standard_normal(uv.shape)
    return uv


# ---- PnP on the agent side -------------------------------------------------------------------------------


@dataclass(frozen=True)
class PnpResult:
    """A relative pose from :func:`solve_pnp`, ready for ``PoseEstimator.update_pose``."""

    t_cam_m: np.ndarray
    """Target origin in the camera frame (3,) [m]."""
    q_cam_target: np.ndarray
    """Target-to-camera rotation (4,), scalar-last, ``w >= 0``."""
    cov_cam: np.ndarray
    """Covariance (6, 6) of ``(dt_cam [m], dphi_cam [rad])``, camera frame, left perturbation."""
    reproj_rms_px: float
    """Root mean square over markers of the reprojection-error norm [px]."""


def _residual_jacobian(obj, img, t, q, params):
    """Reprojection residual ``r = img - h(t, q)`` (2N,) and ``J = dh/d(dt, dphi)`` (2N, 6), rows ordered
    ``u0, v0, u1, v1, ...``; None when a marker is not in front of the camera.

    With ``a = R m`` and ``X = a + t``, ``dX/d(dt) = I`` and ``dX/d(dphi) = -[a x]`` (from
    ``exp([dphi x]) a ~ a + dphi x a``); the pin-hole gradient rows are ``g_u = (fx/Z, 0, -fx X/Z^2)``,
    ``g_v = (0, fy/Z, -fy Y/Z^2)``, and ``-g [a x] = (a x g)^T``.
    """
    r = np.empty(2 * len(obj))
    J = np.zeros((2 * len(obj), 6))
    ok = _residual_jacobian_kernel(
        obj, img, t, q, params.fx_px, params.fy_px, params.cx_px, params.cy_px, r, J
    )
    return (r, J) if ok else None


@numba.njit(cache=True)
def _residual_jacobian_kernel(obj, img, t, q, fx, fy, cx, cy, r, J):
    """Fills ``r`` and ``J`` of :func:`_residual_jacobian` in place; False when a marker has ``Z <= 0``.
    Compiled: the numpy version cost 25 us, twice per :func:`solve_pnp`."""
    R = qmat(q)
    for j in range(obj.shape[0]):
        ax = R[0, 0] * obj[j, 0] + R[0, 1] * obj[j, 1] + R[0, 2] * obj[j, 2]
        ay = R[1, 0] * obj[j, 0] + R[1, 1] * obj[j, 1] + R[1, 2] * obj[j, 2]
        az = R[2, 0] * obj[j, 0] + R[2, 1] * obj[j, 1] + R[2, 2] * obj[j, 2]
        z = az + t[2]
        if not z > 0.0:
            return False
        iz = 1.0 / z
        xn = (ax + t[0]) * iz
        yn = (ay + t[1]) * iz
        r[2 * j] = img[j, 0] - (fx * xn + cx)
        r[2 * j + 1] = img[j, 1] - (fy * yn + cy)
        gu0 = fx * iz
        gu2 = -gu0 * xn
        gv1 = fy * iz
        gv2 = -gv1 * yn
        J[2 * j, 0] = gu0
        J[2 * j, 2] = gu2
        J[2 * j, 3] = ay * gu2
        J[2 * j, 4] = az * gu0 - ax * gu2
        J[2 * j, 5] = -ay * gu0
        J[2 * j + 1, 1] = gv1
        J[2 * j + 1, 2] = gv2
        J[2 * j + 1, 3] = ay * gv2 - az * gv1
        J[2 * j + 1, 4] = -ax * gv2
        J[2 * j + 1, 5] = ax * gv1
    return True


def pixel_jacobian(
    markers_target: ArrayLike, t_cam_m: ArrayLike, q_cam_target: ArrayLike, params: CameraParams
) -> np.ndarray:
    """Jacobian (2N, 6) of the marker pixels ``(u0, v0, u1, v1, ...)`` with respect to the pose
    perturbation ``(dt_cam, dphi_cam)`` of the module docstring, at the pose ``(t_cam_m, q_cam_target)``.
    Raises ValueError when a marker is not in front of the camera."""
    obj = np.asarray(markers_target, dtype=np.float64)
    out = _residual_jacobian(obj, np.zeros((len(obj), 2)), _vec(t_cam_m, 3), _vec(q_cam_target, 4), params)
    if out is None:
        raise ValueError("every marker must be in front of the camera (Z > 0)")
    return out[1]


def solve_pnp(pixels: ArrayLike, markers_target: ArrayLike, params: CameraParams) -> PnpResult | None:
    """Relative pose of the target from marker ``pixels`` (N, 2) of ``markers_target`` (N, 3) [m, target
    frame], N >= 4, with covariance; None when no pose is found (non-finite input, solver failure, a
    marker behind the camera, degenerate geometry).

    ``cv2.solvePnP`` with ``SOLVEPNP_SQPNP`` (Terzakis & Lourakis 2020): globally optimal over every
    minimum, planar or not, with no initial guess, so the standoff marker's non-coplanar pattern is
    fine (``SOLVEPNP_IPPE`` needs coplanar points; ``SOLVEPNP_ITERATIVE``'s DLT start is unstable with six
    non-coplanar points and failed in tests). SQPnP minimizes an object-space error;
    ``params.pnp_refine_iterations`` Gauss-Newton steps on the pixel reprojection error then give the
    maximum-likelihood pose under white pixel noise, using the same Jacobian as the covariance.

    Covariance: first-order backward propagation of the pixel noise through the least-squares fit,
    ``cov = sigma_px^2 (J^T J)^-1`` with ``J`` the pixel Jacobian with respect to ``(dt_cam, dphi_cam)``
    at the estimate (Hartley & Zisserman 2004, sec. 5.2, backward propagation of covariance).
    """
    img = np.ascontiguousarray(pixels, dtype=np.float64)
    obj = np.ascontiguousarray(markers_target, dtype=np.float64)
    if obj.ndim != 2 or obj.shape[1] != 3 or obj.shape[0] < 4 or img.shape != (obj.shape[0], 2):
        raise ValueError(
            f"need pixels (N, 2) and markers_target (N, 3) with N >= 4, got {img.shape}, {obj.shape}"
        )
    if not (np.all(np.isfinite(img)) and np.all(np.isfinite(obj))):
        return None
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, img, params.K, None, flags=cv2.SOLVEPNP_SQPNP)
    except cv2.error:
        return None
    if not ok:
        return None
    t = tvec.reshape(3).astype(np.float64)
    q = qexp(rvec.reshape(3).astype(np.float64))
    try:
        for _ in range(params.pnp_refine_iterations):
            rj = _residual_jacobian(obj, img, t, q, params)
            if rj is None:
                return None
            r, J = rj
            step = np.linalg.solve(J.T @ J, J.T @ r)
            t = t + step[:3]
            q = qnormalize(qmul(qexp(step[3:]), q))
        rj = _residual_jacobian(obj, img, t, q, params)
        if rj is None:
            return None
        r, J = rj
        cov = params.pixel_sigma_px**2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return None
    cov = 0.5 * (cov + cov.T)
    if not (np.all(np.isfinite(cov)) and np.all(np.isfinite(t)) and np.all(np.diag(cov) > 0.0)):
        return None
    if q[3] < 0.0:
        q = -q
    rms = math.sqrt(float(r @ r) / len(obj))
    return PnpResult(t, q, cov, rms)


# ---- the "pose" model: an on-board PnP's output, compiled ------------------------------------------------
POSE_N = 43
"""Length of a ``"pose"`` frame: ``t_cam_m`` (3) [m], ``q_cam_target`` (4), ``cov_cam`` (6 x 6, row-major)."""


@numba.njit(cache=True)
def pose_frame(markers, centre_t, normal_t, p_t, q_t, p_c, q_c, cam, sigma_px, key, counter, out):
    """One frame of the ``"pose"`` model (module docstring): when the face with ``markers`` (N, 3) [m,
    target frame], centre ``centre_t`` and outward normal ``normal_t`` is :func:`visible` to the camera at
    ``(p_c, q_c)`` (``cam`` its visibility vector), writes ``out`` (:data:`POSE_N`,) and returns True.

    With ``J`` the pixel Jacobian (:func:`pixel_jacobian`) at the true pose ``(t, q)`` of the target in the
    camera frame, ``cov = sigma_px^2 (J^T J)^-1`` and ``(dt, dphi) = chol(cov) z`` for the standard normals
    ``z`` of ``(key, counter)`` (:func:`swarm.core._noise_nb.normals`): ``t_meas = t + dt``,
    ``R(q_meas) = exp([dphi x]) R(q)`` (``q_meas`` with ``w >= 0``), reported with ``cov``."""
    if not _visible_kernel(markers, centre_t, normal_t, p_t, q_t, p_c, q_c, cam):
        return False
    R_c = qmat(q_c)
    t = np.empty(3)
    for i in range(3):
        t[i] = R_c[0, i] * (p_t[0] - p_c[0]) + R_c[1, i] * (p_t[1] - p_c[1]) + R_c[2, i] * (p_t[2] - p_c[2])
    q = qmul(qconj(q_c), q_t)
    n = markers.shape[0]
    r = np.empty(2 * n)
    J = np.zeros((2 * n, 6))
    if not _residual_jacobian_kernel(markers, np.zeros((n, 2)), t, q, cam[0], cam[1], cam[2], cam[3], r, J):
        return False
    info = np.zeros((6, 6))
    for a in range(6):
        for b in range(a, 6):
            s = 0.0
            for k in range(2 * n):
                s += J[k, a] * J[k, b]
            info[a, b] = s
            info[b, a] = s
    cov = np.linalg.inv(info) * (sigma_px * sigma_px)
    cov = 0.5 * (cov + cov.T)
    L = np.linalg.cholesky(cov)
    z = np.empty(6)
    normals(key, counter, z)
    d = L @ z
    for i in range(3):
        out[i] = t[i] + d[i]
    qm = qnormalize(qmul(qexp(d[3:6]), q))
    sign = -1.0 if qm[3] < 0.0 else 1.0
    for i in range(4):
        out[3 + i] = sign * qm[i]
    for a in range(6):
        for b in range(6):
            out[7 + 6 * a + b] = cov[a, b]
    return True


@numba.njit(cache=True)
def features_frame(markers, centre_t, normal_t, p_t, q_t, p_c, q_c, cam, sigma_m, key, counter, out):
    """One frame of the ``"features"`` model (the paper's, :func:`feature_vectors`), compiled: when the
    face with ``markers`` (N, 3) [m, target frame] is :func:`visible` to the camera at ``(p_c, q_c)``,
    writes the marker positions in the camera frame plus ``sigma_m`` times the standard normals of ``(key,
    counter)`` (:func:`swarm.core._noise_nb.normals`, 3 N of them, marker by marker) into ``out`` (3 N,)
    and returns True."""
    if not _visible_kernel(markers, centre_t, normal_t, p_t, q_t, p_c, q_c, cam):
        return False
    f = _markers_in_camera(markers, p_t, q_t, p_c, q_c)
    n = markers.shape[0]
    z = np.empty(3 * n)
    normals(key, counter, z)
    for j in range(n):
        for i in range(3):
            out[3 * j + i] = f[j, i] + sigma_m * z[3 * j + i]
    return True
