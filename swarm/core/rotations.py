"""Unit-quaternion rotations on numpy arrays with arbitrary leading batch axes.

Convention. Quaternions are scalar-last ``(x, y, z, w)`` and compose with the Hamilton product, as in
``scipy.spatial.transform.Rotation``: ``quat_to_matrix(q) == Rotation.from_quat(q).as_matrix()`` and
``quat_to_matrix(quat_mul(p, q)) == quat_to_matrix(p) @ quat_to_matrix(q)``. A quaternion named
``q_nav_body`` maps body-frame vectors into the navigation frame: ``v_nav = quat_rotate(q_nav_body, v_body)``.

Markley 2003 and Crassidis & Junkins ("Optimal Estimation of Dynamic Systems") write the same four
numbers in the same order, but compose with the Shuster (reversed) product, ``p (x)_S q == q (x)_H p``,
and their attitude matrix ``A(q)`` (reference -> body) is ``quat_to_matrix(q).T``. Their multiplicative
error ``dq = q (x)_S q_hat^-1`` is therefore, with the Hamilton product used here, the body-frame error
``q = q_hat (x) exp(dtheta)``: see :func:`attitude_error` and :func:`multiplicative_reset`.

Every function accepts float-like arrays, returns float64 and broadcasts over leading axes like numpy.
Functions that take ``q`` assume a unit quaternion unless they say otherwise. ``_rot_nb`` holds the
same math for one quaternion at a time, compiled with numba; keep the two in step.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from swarm.core import _rot_nb as _nb

__all__ = [
    "EXP_TAYLOR_THRESHOLD_RAD",
    "IDENTITY_QUAT",
    "LOG_TAYLOR_THRESHOLD",
    "attitude_error",
    "euler_to_quat",
    "matrix_to_quat",
    "multiplicative_reset",
    "quat_canonical",
    "quat_conj",
    "quat_log",
    "quat_mul",
    "quat_normalize",
    "quat_rotate",
    "quat_to_euler",
    "quat_to_matrix",
    "rotvec_exp",
    "skew",
]

IDENTITY_QUAT = np.array([0.0, 0.0, 0.0, 1.0])
"""The identity rotation, scalar-last ``(x, y, z, w)``; read-only."""
IDENTITY_QUAT.setflags(write=False)  # shared module state: no caller may modify it in place

EXP_TAYLOR_THRESHOLD_RAD = 1e-3
"""Below this rotation angle |phi| (rad) :func:`rotvec_exp` uses its Taylor series.

The first dropped terms are theta^6/645120 (vector coefficient) and theta^6/46080 (scalar part), under
3e-23 here: far below float64 resolution, so the branch switch is seamless.
"""

LOG_TAYLOR_THRESHOLD = 1e-3
"""Below this |vector part| / w (= tan(theta/2)) :func:`quat_log` uses its Taylor series.

The first dropped term of atan(r)/r is r^6/7, under 1.5e-19 here.
"""

FloatArray = NDArray[np.float64]

# Single quaternions/vectors (1-D float64 inputs) take the compiled twins in _rot_nb: the same formulas and
# branches (agreeing to 1-2 ulp, tested), without numpy's per-call overhead on 4-element arrays, which
# dominated the closed-loop simulation's profile.
_F64 = np.float64


def _single(*arrays) -> bool:
    for a in arrays:
        if type(a) is not np.ndarray or a.ndim != 1 or a.dtype != _F64:
            return False
    return True


def as_last(x: ArrayLike, n: int, name: str) -> FloatArray:
    """``x`` as float64, checked to have shape ``(..., n)``; ``name`` goes in the error message."""
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 0 or a.shape[-1] != n:
        raise ValueError(f"{name} must have shape (..., {n}), got {a.shape}")
    return a


def cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """Cross product over the last axis, written out (np.cross is slow for small batches)."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def quat_mul(p: ArrayLike, q: ArrayLike) -> FloatArray:
    """Hamilton product ``p (x) q``, shape ``(..., 4)``; ``R(p (x) q) = R(p) R(q)``.

    ``w = pw qw - pv . qv``, ``v = pw qv + qw pv + pv x qv`` (Sola 2017 Sec. 1.2.2, scalar moved last).
    ``q_a_c = quat_mul(q_a_b, q_b_c)``. Inputs need not be unit; broadcasts over leading axes.
    """
    if _single(p, q) and p.shape[0] == 4 and q.shape[0] == 4:
        return _nb.qmul(p, q)
    p = as_last(p, 4, "p")
    q = as_last(q, 4, "q")
    px, py, pz, pw = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qx, qy, qz, qw = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            pw * qx + qw * px + (py * qz - pz * qy),
            pw * qy + qw * py + (pz * qx - px * qz),
            pw * qz + qw * pz + (px * qy - py * qx),
            pw * qw - (px * qx + py * qy + pz * qz),
        ],
        axis=-1,
    )


def quat_conj(q: ArrayLike) -> FloatArray:
    """Conjugate ``(-x, -y, -z, w)``, shape ``(..., 4)``: the inverse of a unit quaternion."""
    if _single(q) and q.shape[0] == 4:
        return _nb.qconj(q)
    q = as_last(q, 4, "q")
    return np.concatenate([-q[..., :3], q[..., 3:]], axis=-1)


def quat_normalize(q: ArrayLike) -> FloatArray:
    """``q / |q|``, shape ``(..., 4)``. A zero quaternion gives NaN (not checked)."""
    if _single(q) and q.shape[0] == 4:
        return _nb.qnormalize(q)
    q = as_last(q, 4, "q")
    return q / np.sqrt(np.sum(q * q, axis=-1, keepdims=True))


def quat_canonical(q: ArrayLike) -> FloatArray:
    """``q`` with its sign flipped where ``w < 0``, so ``w >= 0``; the same rotation, shape ``(..., 4)``."""
    q = as_last(q, 4, "q")
    return np.where(q[..., 3:] < 0.0, -q, q)


def quat_rotate(q: ArrayLike, v: ArrayLike) -> FloatArray:
    """``R(q) v``, shape ``(..., 3)``: e.g. ``v_nav = quat_rotate(q_nav_body, v_body)``.

    ``v + (2 / |q|^2) (w (u x v) + u x (u x v))``, ``u`` the vector part: ``q v q*`` expanded, equal to
    ``quat_to_matrix(q) @ v`` also for non-unit ``q``. Broadcasts ``q (..., 4)`` against ``v (..., 3)``.
    """
    if _single(q, v) and q.shape[0] == 4 and v.shape[0] == 3:
        return _nb.qrotate(q, v)
    q = as_last(q, 4, "q")
    v = as_last(v, 3, "v")
    u, w = q[..., :3], q[..., 3:]
    s = 2.0 / np.sum(q * q, axis=-1, keepdims=True)
    uxv = cross(u, v)
    return v + s * (w * uxv + cross(u, uxv))


def quat_to_matrix(q: ArrayLike) -> FloatArray:
    """Rotation matrix ``R(q)``, shape ``(..., 3, 3)``; maps body vectors into the reference frame.

    The transpose of Crassidis & Junkins' attitude matrix ``A(q)`` (theirs maps reference -> body); scaled
    by ``2 / |q|^2`` so a non-unit ``q`` gives the matrix of ``q / |q|``, like scipy's ``from_quat``.
    """
    if _single(q) and q.shape[0] == 4:
        return _nb.qmat(q)
    q = as_last(q, 4, "q")
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    s = 2.0 / (x * x + y * y + z * z + w * w)
    xx, yy, zz = s * x * x, s * y * y, s * z * z
    xy, xz, yz = s * x * y, s * x * z, s * y * z
    wx, wy, wz = s * w * x, s * w * y, s * w * z
    rows = [
        [1.0 - (yy + zz), xy - wz, xz + wy],
        [xy + wz, 1.0 - (xx + zz), yz - wx],
        [xz - wy, yz + wx, 1.0 - (xx + yy)],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def matrix_to_quat(R: ArrayLike) -> FloatArray:
    """Unit quaternion of rotation matrix ``R (..., 3, 3)``, canonical ``w >= 0``, shape ``(..., 4)``.

    Shepperd 1978 ("Quaternion from rotation matrix", J. Guidance and Control 1(3)): build it from the
    largest of ``4w^2 = 1 + tr R`` and ``4x^2, 4y^2, 4z^2`` (equivalently the largest of ``tr R, R00,
    R11, R22``), so nothing divides by a small number, 180-degree rotations included; then normalize.
    """
    R = np.asarray(R, dtype=np.float64)
    if R.ndim < 2 or R.shape[-2:] != (3, 3):
        raise ValueError(f"R must have shape (..., 3, 3), got {R.shape}")
    r00, r01, r02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    r10, r11, r12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    r20, r21, r22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    tr = r00 + r11 + r22
    # Each candidate is 4 * (the quaternion) * (its pivot component); row k pivots on component k.
    candidates = np.stack(
        [
            np.stack([1.0 + 2.0 * r00 - tr, r01 + r10, r02 + r20, r21 - r12], axis=-1),
            np.stack([r01 + r10, 1.0 + 2.0 * r11 - tr, r12 + r21, r02 - r20], axis=-1),
            np.stack([r02 + r20, r12 + r21, 1.0 + 2.0 * r22 - tr, r10 - r01], axis=-1),
            np.stack([r21 - r12, r02 - r20, r10 - r01, 1.0 + tr], axis=-1),
        ],
        axis=-2,
    )
    choice = np.argmax(np.stack([r00, r11, r22, tr], axis=-1), axis=-1)
    q = np.take_along_axis(candidates, choice[..., None, None], axis=-2)[..., 0, :]
    return quat_canonical(quat_normalize(q))


def skew(v: ArrayLike) -> FloatArray:
    """Cross-product matrix ``[v x]``, shape ``(..., 3, 3)``: ``skew(a) @ b == cross(a, b)``."""
    v = as_last(v, 3, "v")
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    zero = np.zeros_like(x)
    rows = [[zero, -z, y], [z, zero, -x], [-y, x, zero]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def rotvec_exp(phi: ArrayLike) -> FloatArray:
    """Unit quaternion of rotation vector ``phi`` (rad, ``(..., 3)``), shape ``(..., 4)``.

    ``exp(phi) = (sin(theta/2) phi / theta, cos(theta/2))``, ``theta = |phi|`` (Sola 2017 Sec. 2.4, the
    quaternion Exp map). Below :data:`EXP_TAYLOR_THRESHOLD_RAD` the coefficients are their Taylor series
    ``1/2 - theta^2/48 + theta^4/3840`` and ``1 - theta^2/8 + theta^4/384``, so ``exp(0)`` is exactly
    the identity and nothing divides by zero.
    """
    if _single(phi) and phi.shape[0] == 3:
        return _nb.qexp(phi)
    phi = as_last(phi, 3, "phi")
    t2 = np.sum(phi * phi, axis=-1, keepdims=True)
    small = t2 < EXP_TAYLOR_THRESHOLD_RAD**2
    theta = np.sqrt(np.where(small, 1.0, t2))
    half = 0.5 * theta
    t4 = t2 * t2
    k = np.where(small, 0.5 - t2 / 48.0 + t4 / 3840.0, np.sin(half) / theta)
    w = np.where(small, 1.0 - t2 / 8.0 + t4 / 384.0, np.cos(half))
    return np.concatenate([k * phi, w], axis=-1)


def quat_log(q: ArrayLike) -> FloatArray:
    """Rotation vector (rad, ``(..., 3)``, ``|phi| <= pi``) of unit quaternion ``q (..., 4)``.

    Inverse of :func:`rotvec_exp` on the ``w >= 0`` hemisphere: ``phi = 2 atan2(|u|, w) u / |u|`` with
    ``u`` the vector part (Sola 2017 Sec. 2.4, Log map); atan2 keeps full precision near 0 and 180 deg
    (``w = 0`` gives ``|phi| = pi``, where either axis sign is the same rotation). Below
    :data:`LOG_TAYLOR_THRESHOLD` (``r = |u| / w``) the coefficient is ``(2 / w)(1 - r^2/3 + r^4/5)``.
    """
    if _single(q) and q.shape[0] == 4:
        return _nb.qlog(q)
    q = quat_canonical(q)
    u, w = q[..., :3], q[..., 3:]
    n2 = np.sum(u * u, axis=-1, keepdims=True)
    small = n2 < (LOG_TAYLOR_THRESHOLD**2) * (w * w)
    n = np.sqrt(np.where(small, 1.0, n2))
    w_safe = np.where(small, w, 1.0)
    r2 = n2 / (w_safe * w_safe)
    k = np.where(small, (2.0 / w_safe) * (1.0 - r2 / 3.0 + r2 * r2 / 5.0), 2.0 * np.arctan2(n, w) / n)
    return k * u


def attitude_error(q_ref: ArrayLike, q: ArrayLike) -> FloatArray:
    """Body-frame error ``dtheta`` (rad, ``(..., 3)``) with ``q = q_ref (x) exp(dtheta)``.

    ``dtheta = log(conj(q_ref) (x) q)``: Markley 2003 ("Attitude error representations for Kalman
    filtering", JGCD 26(2)) multiplicative error ``dq = q (x)_S q_ref^-1`` rewritten with the Hamilton
    product (see the module docstring). Both inputs are unit ``(..., 4)``.
    """
    q_ref = as_last(q_ref, 4, "q_ref")
    q = as_last(q, 4, "q")
    return quat_log(quat_mul(quat_conj(q_ref), q))


def multiplicative_reset(q_ref: ArrayLike, dtheta: ArrayLike) -> FloatArray:
    """``normalize(q_ref (x) exp(dtheta))``, shape ``(..., 4)``: the MEKF reset (Markley 2003).

    ``q_ref (..., 4)`` is the reference attitude, ``dtheta (..., 3)`` the body-frame error estimate (rad).
    """
    q_ref = as_last(q_ref, 4, "q_ref")
    dtheta = as_last(dtheta, 3, "dtheta")
    return quat_normalize(quat_mul(q_ref, rotvec_exp(dtheta)))


def euler_to_quat(angles_rad: ArrayLike, seq: str) -> FloatArray:
    """Canonical quaternion ``(..., 4)`` of Euler angles ``(..., len(seq))`` (rad), scipy's convention.

    ``seq`` is as in ``Rotation.from_euler``: lower case ``"xyz"`` extrinsic, upper case ``"XYZ"``
    intrinsic. ``euler_to_quat([yaw, pitch, roll], "ZYX")`` gives ``q_ref_body`` of the aerospace sequence.
    """
    angles = as_last(angles_rad, len(seq), "angles_rad")
    q = Rotation.from_euler(seq, angles.reshape(-1, len(seq))).as_quat()
    return quat_canonical(q.reshape(*angles.shape[:-1], 4))


def quat_to_euler(q: ArrayLike, seq: str) -> FloatArray:
    """Euler angles (rad, ``(..., 3)``) of quaternion ``q (..., 4)``, scipy's ``Rotation.as_euler``.

    ``seq`` is three axes, lower case extrinsic or upper case intrinsic; ranges and gimbal-lock handling
    are scipy's (it warns at gimbal lock).
    """
    q = as_last(q, 4, "q")
    angles = Rotation.from_quat(q.reshape(-1, 4)).as_euler(seq)
    return angles.reshape(*q.shape[:-1], 3)
