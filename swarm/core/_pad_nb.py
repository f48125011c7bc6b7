"""The corner-mode pad camera compiled: numba twins of :func:`swarm.core.pad_vision.project_corners` and
:func:`~swarm.core.pad_vision.corner_frame` without OpenCV, for the compiled landing tick (the module
docstring of :mod:`swarm.core.pad_vision` says what they model); the pose solve on its corners is
:mod:`swarm.core._pnp_nb`.

Only float64 arrays and scalars cross the boundary; every output is preallocated by the caller. The camera
is the row ``cam`` (:data:`CAM_N`,) of :func:`camera_vector`. Frames and conventions as in ``pad_vision``:
``X_cam = R_cam_pad X_pad + t_cam`` [m], OpenCV's camera frame (+z the optical axis).

* :func:`project_point`: OpenCV's radial-tangential (Brown-Conrady) projection, ``cv2.projectPoints``'
  model with ``k1, k2, p1, p2, k3``; :func:`undistort_point` inverts it by the fixed-point iteration of
  ``cv2.undistortPoints``.
* :func:`corner_frame_nb`: the corner mode's detections; its noise is read from an array of standard normal
  draws in the order ``rng.normal`` would draw them, so a seeded run gives the Python function's numbers.
* :func:`pack_frame_nb`: detections as the pose solve's rows, each corner's variance from its marker's size
  in the image.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

if TYPE_CHECKING:
    from swarm.core.pad_vision import PadCameraParams

# ---- camera row CAM ---------------------------------------------------------------------------------------
CAM_FX = 0  # focal lengths [px]
CAM_FY = 1
CAM_CX = 2  # principal point [px]
CAM_CY = 3
CAM_K1 = 4  # radial-tangential distortion k1, k2, p1, p2, k3 (OpenCV's order)
CAM_K2 = 5
CAM_P1 = 6
CAM_P2 = 7
CAM_K3 = 8
CAM_WIDTH = 9  # image size [px]
CAM_HEIGHT = 10
CAM_MIN_MARKER = 11  # shortest detectable marker side [px]
CAM_SIGMA = 12  # corner noise of a large marker [px]
CAM_SIGMA_K = 13  # its growth as a marker shrinks [px^2]
CAM_N = 14

MIN_DEPTH_M = 0.05
"""A marker is seen when every corner is this far in front of the camera (``pad_vision._in_front``)."""
UNDISTORT_ITERS = 10
"""Fixed-point iterations of :func:`undistort_point`: the iteration contracts by ~``2 |k1| r^2`` per step
(<= 0.1 over this project's images), so 10 leave ~1e-13 of the starting error (OpenCV's default, 5, leaves
~1e-7). Only the initial poses use them."""


def camera_vector(cam: PadCameraParams) -> np.ndarray:
    """The row ``cam`` (:data:`CAM_N`,) of a :class:`~swarm.core.pad_vision.PadCameraParams`."""
    k1, k2, p1, p2, k3 = (float(d) for d in cam.distortion)
    return np.array(
        [cam.fx_px, cam.fy_px, cam.cx_px, cam.cy_px, k1, k2, p1, p2, k3, cam.width_px, cam.height_px,
         cam.min_marker_px, cam.corner_sigma_px, cam.corner_sigma_k_px2],
        dtype=np.float64,
    )  # fmt: skip


# ---- projection ------------------------------------------------------------------------------------------


@njit(cache=True)
def project_point(cam: np.ndarray, X: float, Y: float, Z: float) -> tuple[float, float]:
    """Pixel ``(u, v)`` of the camera-frame point ``(X, Y, Z)`` [m], ``Z > 0`` (OpenCV's camera model;
    Brown 1966): ``x = X / Z``, ``y = Y / Z``, ``r^2 = x^2 + y^2``, ``xd = x (1 + k1 r^2 + k2 r^4 + k3 r^6)
    + 2 p1 x y + p2 (r^2 + 2 x^2)``, ``yd = y (...) + p1 (r^2 + 2 y^2) + 2 p2 x y``, ``u = fx xd + cx``,
    ``v = fy yd + cy``."""
    iz = 1.0 / Z
    x = X * iz
    y = Y * iz
    r2 = x * x + y * y
    radial = 1.0 + cam[CAM_K1] * r2 + cam[CAM_K2] * r2 * r2 + cam[CAM_K3] * r2 * r2 * r2
    p1 = cam[CAM_P1]
    p2 = cam[CAM_P2]
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return cam[CAM_FX] * xd + cam[CAM_CX], cam[CAM_FY] * yd + cam[CAM_CY]


@njit(cache=True)
def distortion_jacobian(cam, x, y):
    """For normalised coordinates ``(x, y)``: the radial factor, its derivative with respect to ``r^2``, and
    the Jacobian of the distorted ``(xd, yd)`` (:func:`project_point`): ``(radial, d radial / d r^2,
    dxd/dx, dxd/dy (= dyd/dx), dyd/dy)``."""
    r2 = x * x + y * y
    k1, k2, k3 = cam[CAM_K1], cam[CAM_K2], cam[CAM_K3]
    p1, p2 = cam[CAM_P1], cam[CAM_P2]
    radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    d1 = k1 + 2.0 * k2 * r2 + 3.0 * k3 * r2 * r2
    xd_x = radial + 2.0 * x * x * d1 + 2.0 * p1 * y + 6.0 * p2 * x
    xd_y = 2.0 * x * y * d1 + 2.0 * p1 * x + 2.0 * p2 * y
    yd_y = radial + 2.0 * y * y * d1 + 6.0 * p1 * y + 2.0 * p2 * x
    return radial, d1, xd_x, xd_y, yd_y


@njit(cache=True)
def _project_jac(cam, X, Y, Z):
    """:func:`project_point` and its Jacobian: ``(u, v, du/dX, du/dY, du/dZ, dv/dX, dv/dY, dv/dZ)``."""
    iz = 1.0 / Z
    x = X * iz
    y = Y * iz
    r2 = x * x + y * y
    p1, p2 = cam[CAM_P1], cam[CAM_P2]
    radial, _, xd_x, xd_y, yd_y = distortion_jacobian(cam, x, y)
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    fx, fy = cam[CAM_FX], cam[CAM_FY]
    # x = X / Z: dx/dX = 1/Z, dx/dZ = -x/Z (and y alike)
    u_X = fx * xd_x * iz
    u_Y = fx * xd_y * iz
    u_Z = -(u_X * x + u_Y * y)
    v_X = fy * xd_y * iz
    v_Y = fy * yd_y * iz
    v_Z = -(v_X * x + v_Y * y)
    return fx * xd + cam[CAM_CX], fy * yd + cam[CAM_CY], u_X, u_Y, u_Z, v_X, v_Y, v_Z


@njit(cache=True)
def undistort_point(cam: np.ndarray, u: float, v: float) -> tuple[float, float]:
    """Normalised undistorted coordinates ``(x, y)`` of pixel ``(u, v)``: ``cv2.undistortPoints``' fixed-point
    iteration ``x <- (x0 - dx_tangential(x, y)) / radial(x, y)`` from the distorted ``x0 = (u - cx) / fx``,
    :data:`UNDISTORT_ITERS` times; ``(x0, y0)`` when the radial factor turns non-positive (OpenCV's rule)."""
    x0 = (u - cam[CAM_CX]) / cam[CAM_FX]
    y0 = (v - cam[CAM_CY]) / cam[CAM_FY]
    k1, k2, k3 = cam[CAM_K1], cam[CAM_K2], cam[CAM_K3]
    p1, p2 = cam[CAM_P1], cam[CAM_P2]
    x, y = x0, y0
    for _ in range(UNDISTORT_ITERS):
        r2 = x * x + y * y
        radial = 1.0 + ((k3 * r2 + k2) * r2 + k1) * r2
        if not radial > 0.0:
            return x0, y0
        dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        x = (x0 - dx) / radial
        y = (y0 - dy) / radial
    return x, y


# ---- the corner mode ---------------------------------------------------------------------------------------


@njit(cache=True)
def corner_frame_nb(
    corners: np.ndarray,
    R_cam_pad: np.ndarray,
    t_cam: np.ndarray,
    cam: np.ndarray,
    Z: np.ndarray,
    pos: int,
    out_idx: np.ndarray,
    out_px: np.ndarray,
) -> tuple[int, int]:
    """The corner mode's detections, twin of :func:`swarm.core.pad_vision.corner_frame`.

    ``corners`` (M, 4, 3) [m] the board's corners in the pad frame (``PadBoardParams.corners``);
    ``R_cam_pad`` (3, 3), ``t_cam`` (3,) [m] the pad's pose in the camera. A marker is kept when its four
    corners are at least :data:`MIN_DEPTH_M` in front of the camera, inside the image (``[0, width - 1] x
    [0, height - 1]`` px) and its shortest side (corner to corner, 3 to 0 included) spans at least
    ``min_marker_px``. Each kept corner gets ``sigma z`` per axis, ``sigma = corner_sigma_px +
    corner_sigma_k_px2 / max(side, 1)`` of its marker and ``z`` the standard normals ``Z[pos], Z[pos + 1],
    ...`` taken kept marker by kept marker, corner by corner, u then v (``rng.normal(0, 1, (K, 4, 2))``'s
    order). Writes the kept markers' board indices (0..M-1, board order) to ``out_idx[:K]`` (int array,
    (M,)) and their noisy pixels to ``out_px[:K]`` ((M, 4, 2)); returns ``(K, pos + 8 K)``. ``Z`` must hold
    ``pos + 8 M`` draws.
    """
    M = corners.shape[0]
    if pos + 8 * M > Z.shape[0]:
        raise ValueError("corner_frame_nb: Z holds fewer than pos + 8 M draws")
    r00, r01, r02 = R_cam_pad[0, 0], R_cam_pad[0, 1], R_cam_pad[0, 2]
    r10, r11, r12 = R_cam_pad[1, 0], R_cam_pad[1, 1], R_cam_pad[1, 2]
    r20, r21, r22 = R_cam_pad[2, 0], R_cam_pad[2, 1], R_cam_pad[2, 2]
    umax = cam[CAM_WIDTH] - 1.0
    vmax = cam[CAM_HEIGHT] - 1.0
    K = 0
    for m in range(M):
        seen = True
        for c in range(4):
            X, Y, W = corners[m, c, 0], corners[m, c, 1], corners[m, c, 2]
            zc = r20 * X + r21 * Y + r22 * W + t_cam[2]
            if not zc > MIN_DEPTH_M:
                seen = False
                break
            xc = r00 * X + r01 * Y + r02 * W + t_cam[0]
            yc = r10 * X + r11 * Y + r12 * W + t_cam[1]
            u, v = project_point(cam, xc, yc, zc)
            if not (u >= 0.0 and u <= umax and v >= 0.0 and v <= vmax):
                seen = False
                break
            out_px[K, c, 0] = u
            out_px[K, c, 1] = v
        if not seen:
            continue
        side = _shortest_side(out_px, K)
        if not side >= cam[CAM_MIN_MARKER]:
            continue
        sigma = cam[CAM_SIGMA] + cam[CAM_SIGMA_K] / max(side, 1.0)
        for c in range(4):
            out_px[K, c, 0] += Z[pos] * sigma
            out_px[K, c, 1] += Z[pos + 1] * sigma
            pos += 2
        out_idx[K] = m
        K += 1
    return K, pos


@njit(cache=True)
def _shortest_side(px, k):
    """The shortest side [px] of marker ``px[k]`` (4, 2), ``pad_vision._sides``."""
    side = np.inf
    for c in range(4):
        du = px[k, c, 0] - px[k, c - 1, 0]  # c - 1 = -1: corner 3 to 0
        dv = px[k, c, 1] - px[k, c - 1, 1]
        side = min(side, math.sqrt(du * du + dv * dv))
    return side


@njit(cache=True)
def pack_frame_nb(
    corners: np.ndarray,
    idx: np.ndarray,
    px: np.ndarray,
    K: int,
    cam: np.ndarray,
    obj: np.ndarray,
    img: np.ndarray,
    var: np.ndarray,
) -> int:
    """The rows :func:`solve_pose_nb` takes from ``K`` detections (``idx[:K]``, ``px[:K]`` as
    :func:`corner_frame_nb` writes them): each marker's pad-frame corners into ``obj`` (>= 4 K, 3), its
    pixels into ``img`` (>= 4 K, 2), and the variance [px^2] of each of its pixel coordinates,
    ``corner_sigma(side)^2`` of the *observed* shortest side, into ``var`` (>= 4 K,), as ``estimate_pose``
    builds them. Returns ``n = 4 K``."""
    for k in range(K):
        m = idx[k]
        side = _shortest_side(px, k)
        s = cam[CAM_SIGMA] + cam[CAM_SIGMA_K] / max(side, 1.0)
        for c in range(4):
            i = 4 * k + c
            obj[i, 0] = corners[m, c, 0]
            obj[i, 1] = corners[m, c, 1]
            obj[i, 2] = corners[m, c, 2]
            img[i, 0] = px[k, c, 0]
            img[i, 1] = px[k, c, 1]
            var[i] = s * s
    return 4 * K
