"""Numba twins of :mod:`swarm.core.rotations` for one quaternion or vector at a time.

For use inside ``numba.njit`` estimator kernels. Same convention (scalar-last ``(x, y, z, w)``, Hamilton
product, ``qmat(q)`` maps body -> reference), same formulas, branches and thresholds as ``rotations.py``,
so results agree to ~1e-15; ``tests/core/test_rotations.py`` checks every pair. Inputs are 1-D float64
arrays of shape (4,) or (3,), unchecked; every function returns a new array.
"""

from __future__ import annotations

import math

import numba
import numpy as np

# Copies of rotations.EXP_TAYLOR_THRESHOLD_RAD / LOG_TAYLOR_THRESHOLD (a test asserts they match). Kept
# here rather than imported because numba freezes globals into its on-disk cache, which is invalidated
# only when this file changes.
_EXP_TAYLOR_THRESHOLD_RAD = 1e-3
_LOG_TAYLOR_THRESHOLD = 1e-3


@numba.njit(cache=True)
def qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p (x) q`` of two (4,) quaternions; twin of ``rotations.quat_mul``."""
    px, py, pz, pw = p[0], p[1], p[2], p[3]
    qx, qy, qz, qw = q[0], q[1], q[2], q[3]
    out = np.empty(4)
    out[0] = pw * qx + qw * px + (py * qz - pz * qy)
    out[1] = pw * qy + qw * py + (pz * qx - px * qz)
    out[2] = pw * qz + qw * pz + (px * qy - py * qx)
    out[3] = pw * qw - (px * qx + py * qy + pz * qz)
    return out


@numba.njit(cache=True)
def qconj(q: np.ndarray) -> np.ndarray:
    """Conjugate ``(-x, -y, -z, w)`` of a (4,) quaternion; twin of ``rotations.quat_conj``."""
    out = np.empty(4)
    out[0] = -q[0]
    out[1] = -q[1]
    out[2] = -q[2]
    out[3] = q[3]
    return out


@numba.njit(cache=True)
def qnormalize(q: np.ndarray) -> np.ndarray:
    """``q / |q|`` for a (4,) quaternion; twin of ``rotations.quat_normalize``."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    out = np.empty(4)
    for i in range(4):
        out[i] = q[i] / n
    return out


@numba.njit(cache=True)
def qexp(phi: np.ndarray) -> np.ndarray:
    """Unit quaternion (4,) of rotation vector ``phi`` (3,) in rad; twin of ``rotations.rotvec_exp``.

    Taylor series below ``_EXP_TAYLOR_THRESHOLD_RAD`` (Sola 2017 Sec. 2.4), exactly identity at zero.
    """
    x, y, z, w = qexp3(phi[0], phi[1], phi[2])
    out = np.empty(4)
    out[0] = x
    out[1] = y
    out[2] = z
    out[3] = w
    return out


@numba.njit(cache=True)
def qexp3(px: float, py: float, pz: float) -> tuple[float, float, float, float]:
    """:func:`qexp` on scalars, returning the tuple ``(x, y, z, w)``: no array allocation, for the
    innermost kernels."""
    t2 = px * px + py * py + pz * pz
    if t2 < _EXP_TAYLOR_THRESHOLD_RAD * _EXP_TAYLOR_THRESHOLD_RAD:
        t4 = t2 * t2
        k = 0.5 - t2 / 48.0 + t4 / 3840.0
        w = 1.0 - t2 / 8.0 + t4 / 384.0
    else:
        theta = math.sqrt(t2)
        half = 0.5 * theta
        k = math.sin(half) / theta
        w = math.cos(half)
    return k * px, k * py, k * pz, w


@numba.njit(cache=True)
def qlog(q: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) in rad, ``|phi| <= pi``, of unit ``q`` (4,); twin of ``rotations.quat_log``.

    ``w >= 0`` hemisphere first, then ``2 atan2(|u|, w) u / |u|``, Taylor series of ``atan(r)/r``
    below ``_LOG_TAYLOR_THRESHOLD`` (``r = |u| / w``).
    """
    x, y, z, w = q[0], q[1], q[2], q[3]
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    n2 = x * x + y * y + z * z
    if n2 < (_LOG_TAYLOR_THRESHOLD * _LOG_TAYLOR_THRESHOLD) * (w * w):
        r2 = n2 / (w * w)
        k = (2.0 / w) * (1.0 - r2 / 3.0 + r2 * r2 / 5.0)
    else:
        n = math.sqrt(n2)
        k = 2.0 * math.atan2(n, w) / n
    out = np.empty(3)
    out[0] = k * x
    out[1] = k * y
    out[2] = k * z
    return out


@numba.njit(cache=True)
def qmat(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of ``q`` (4,), body -> reference; twin of ``rotations.quat_to_matrix``."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    s = 2.0 / (x * x + y * y + z * z + w * w)
    xx, yy, zz = s * x * x, s * y * y, s * z * z
    xy, xz, yz = s * x * y, s * x * z, s * y * z
    wx, wy, wz = s * w * x, s * w * y, s * w * z
    R = np.empty((3, 3))
    R[0, 0] = 1.0 - (yy + zz)
    R[0, 1] = xy - wz
    R[0, 2] = xz + wy
    R[1, 0] = xy + wz
    R[1, 1] = 1.0 - (xx + zz)
    R[1, 2] = yz - wx
    R[2, 0] = xz - wy
    R[2, 1] = yz + wx
    R[2, 2] = 1.0 - (xx + yy)
    return R


@numba.njit(cache=True)
def skew3(v: np.ndarray) -> np.ndarray:
    """``[v x]`` (3, 3) of ``v`` (3,): ``skew3(a) @ b == cross(a, b)``; twin of ``rotations.skew``."""
    S = np.zeros((3, 3))
    S[0, 1] = -v[2]
    S[0, 2] = v[1]
    S[1, 0] = v[2]
    S[1, 2] = -v[0]
    S[2, 0] = -v[1]
    S[2, 1] = v[0]
    return S


@numba.njit(cache=True)
def qrotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``R(q) v`` (3,) for quaternion ``q`` (4,) and vector ``v`` (3,); twin of ``rotations.quat_rotate``."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    s = 2.0 / (x * x + y * y + z * z + w * w)
    # c = u x v, d = u x c, with u = (x, y, z)
    cx = y * v[2] - z * v[1]
    cy = z * v[0] - x * v[2]
    cz = x * v[1] - y * v[0]
    dx = y * cz - z * cy
    dy = z * cx - x * cz
    dz = x * cy - y * cx
    out = np.empty(3)
    out[0] = v[0] + s * (w * cx + dx)
    out[1] = v[1] + s * (w * cy + dy)
    out[2] = v[2] + s * (w * cz + dz)
    return out


@numba.njit(cache=True)
def qmat9(x: float, y: float, z: float, w: float) -> tuple:
    """The entries ``(r00, r01, r02, r10, r11, r12, r20, r21, r22)`` of ``R(q)`` for a unit quaternion
    given as scalars (Crassidis & Junkins 2011 eq. 2.125 in the Hamilton, scalar-last form): no array
    allocation, for the innermost kernels."""
    return (
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
    )  # fmt: skip
