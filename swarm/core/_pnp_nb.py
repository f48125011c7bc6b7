"""The planar pose solve compiled: the numba twin of :func:`swarm.core.pad_vision.estimate_pose` without
OpenCV, for the compiled landing tick. The camera row and projection are :mod:`swarm.core._pad_nb`'s; a pose
perturbation ``(dt, dphi)`` is ``t <- t + dt``, ``R <- exp([dphi x]) R`` (camera frame, left; Sola, Deray &
Atchuthan 2018, eq. 27), in that order in every Jacobian and covariance.

* :func:`solve_pose_nb`: the pose of the planar board from its corners. :func:`ippe_poses_nb` gives two
  initial poses from the plane-to-image homography (a Hartley-normalised DLT, Hartley & Zisserman 2004 alg.
  4.2, on undistorted normalised coordinates), decomposed by IPPE (Collins & Bartoli 2014, "Infinitesimal
  Plane-based Pose Estimation", IJCV 109; OpenCV's ``SOLVEPNP_IPPE``): the two rotations a plane's
  homography admits to first order, each with its least-squares translation. Both are refined on the pixel
  reprojection error, distortion included, by Newton's method (Gauss-Newton where the Hessian is not
  positive definite), and the lower minimum is kept: IPPE's twofold ambiguity is decided after the
  refinement, where OpenCV decides it before (and keeps the higher of two minima in ~0.15 % of the landing
  envelope's frames). Newton, not Gauss-Newton: a far board's tilt is weakly observed and Gauss-Newton
  converges there only linearly, at rates up to ~0.9 (for that reason OpenCV's LM stops ~1e-6 rad short
  of the minimum in a typical frame, 1e-4 rad in 1 %, up to 0.15 rad in a few per 10000). The covariance
  is ``estimate_pose``'s: the unweighted fit's sandwich ``(J^T J)^-1 J^T Sigma J (J^T J)^-1`` (Hartley &
  Zisserman 2004 sec. 5.2), ``J`` the pixel Jacobian with respect to ``(dt, dphi)``, which equals OpenCV's
  ``(rvec, tvec)`` covariance mapped through the left Jacobian of SO(3) (Sola et al. 2018 eq. 145).

Zhang's decomposition of the homography (Zhang 2000, "A flexible new technique for camera calibration",
sec. 3.1 and appendix C) gives one pose, near one of IPPE's two; IPPE gives both, as exact rotations (no
orthonormalisation), so it is used instead.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarm.core._pad_nb import (
    CAM_FX,
    CAM_FY,
    CAM_K2,
    CAM_K3,
    CAM_P1,
    CAM_P2,
    _project_jac,
    distortion_jacobian,
    project_point,
    undistort_point,
)
from swarm.core._rot_nb import qexp3, qmat9

MAX_ITERS = 20
"""Newton steps per initial pose, twice over (5-8 are typical, 15 the most seen)."""
STEP_TOL = 1e-12
"""The refinement stops when ``|(dt [m], dphi [rad])|`` falls below this (the solve's rounding floor is
~1e-14 m at 7 m)."""
MAX_HALVINGS = 12
COST_RTOL = 1e-12
"""A step is halved while it raises the cost by more than this fraction."""
JOIN_TOL = 1e-4
"""A refinement that comes this close [m + rad] to a minimum already found is heading for it (Newton
converges quadratically there; the planar ambiguity's two minima lie 0.1 rad or more apart)."""
_UNFINISHED, _CONVERGED, _JOINED = 0, 1, 2  # how a refinement ended
PIVOT_TOL = 1e-14
"""A Jacobi-scaled normal matrix whose Cholesky pivot falls below this is singular (condition > 1e14)."""


# ---- small dense linear algebra ----------------------------------------------------------------------------


@njit(cache=True)
def _chol_factor(A, m, L, d):
    """Cholesky ``D A D = L L^T`` of the symmetric ``A[:m, :m]`` with Jacobi scaling ``D = diag(d)``,
    ``d_i = A_ii^-1/2`` (writes ``L``, ``d``); False when ``A`` is not positive definite to
    :data:`PIVOT_TOL`."""
    for i in range(m):
        if not A[i, i] > 0.0:
            return False
        d[i] = 1.0 / math.sqrt(A[i, i])
    for j in range(m):
        s = A[j, j] * d[j] * d[j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > PIVOT_TOL:
            return False
        ljj = math.sqrt(s)
        L[j, j] = ljj
        for i in range(j + 1, m):
            s = A[i, j] * d[i] * d[j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / ljj
    return True


@njit(cache=True)
def _chol_solve(L, d, m, b, x):
    """``x = A^-1 b`` from :func:`_chol_factor`'s ``L``, ``d``: ``A^-1 = D (L L^T)^-1 D``."""
    for i in range(m):
        s = b[i] * d[i]
        for k in range(i):
            s -= L[i, k] * x[k]
        x[i] = s / L[i, i]
    for i in range(m - 1, -1, -1):
        s = x[i]
        for k in range(i + 1, m):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
    for i in range(m):
        x[i] *= d[i]


# ---- initial poses: homography and IPPE ------------------------------------------------------------------


@njit(cache=True)
def _homography(P, q, n, H, A, b, L, d, h):
    """The homography ``H`` (3, 3), ``H[2, 2] = 1``, with ``q_i ~ H [P_i, 1]`` for the plane points ``P``
    (n, 2) (centred) and image points ``q`` (n, 2): the DLT with Hartley's isotropic normalisation (Hartley
    & Zisserman 2004 alg. 4.2). The constraint ``h33 = 1`` replaces the SVD's ``|h| = 1``: ``h33`` is the
    depth of the points' centroid, positive for a plane in view (H&Z sec. 4.1.2). False when degenerate."""
    dP = 0.0
    for i in range(n):
        dP += math.sqrt(P[i, 0] * P[i, 0] + P[i, 1] * P[i, 1])
    mx = 0.0
    my = 0.0
    for i in range(n):
        mx += q[i, 0]
        my += q[i, 1]
    mx /= n
    my /= n
    dq = 0.0
    for i in range(n):
        dq += math.sqrt((q[i, 0] - mx) ** 2 + (q[i, 1] - my) ** 2)
    if not (dP > 0.0 and dq > 0.0):
        return False
    sP = math.sqrt(2.0) * n / dP
    sq = math.sqrt(2.0) * n / dq
    A[:8, :8] = 0.0
    b[:8] = 0.0
    for i in range(n):
        X = sP * P[i, 0]
        Y = sP * P[i, 1]
        x = sq * (q[i, 0] - mx)
        y = sq * (q[i, 1] - my)
        # rows [X Y 1 0 0 0 -xX -xY] h = x and [0 0 0 X Y 1 -yX -yY] h = y, into the normal equations
        a = (X, Y, 1.0, -x * X, -x * Y)
        c = (X, Y, 1.0, -y * X, -y * Y)
        iu = (0, 1, 2, 6, 7)
        iv = (3, 4, 5, 6, 7)
        for r in range(5):
            b[iu[r]] += a[r] * x
            b[iv[r]] += c[r] * y
            for s in range(5):
                A[iu[r], iu[s]] += a[r] * a[s]
                A[iv[r], iv[s]] += c[r] * c[s]
    if not _chol_factor(A, 8, L, d):
        return False
    _chol_solve(L, d, 8, b, h)
    # H = T_q^-1 H_n T_P, T_q = [[sq, 0, -sq mx], [0, sq, -sq my], [0, 0, 1]], T_P = diag(sP, sP, 1)
    h20 = h[6] * sP
    h21 = h[7] * sP
    H[0, 0] = (h[0] * sP / sq) + mx * h20
    H[0, 1] = (h[1] * sP / sq) + mx * h21
    H[0, 2] = (h[2] / sq) + mx
    H[1, 0] = (h[3] * sP / sq) + my * h20
    H[1, 1] = (h[4] * sP / sq) + my * h21
    H[1, 2] = (h[5] / sq) + my
    H[2, 0] = h20
    H[2, 1] = h21
    H[2, 2] = 1.0
    for i in range(3):
        for j in range(3):
            if not math.isfinite(H[i, j]):
                return False
    return True


@njit(cache=True)
def _ippe_rotations(H, Ra, Rb):
    """IPPE's two rotations (Collins & Bartoli 2014; OpenCV's ``IPPE::PoseSolver::computeRotations``) of
    the plane whose homography ``H`` (``H[2, 2] = 1``) maps its origin to ``(H02, H12)``: ``J`` the 2x2
    Jacobian of ``H`` at the origin, ``R_v`` the rotation taking the line of sight ``v = (p, q, 1)`` to +z,
    ``A = B^-1 J``, ``gamma`` its largest singular value; the two rotations share their first two rows up
    to the sign of the third component. False when degenerate."""
    p = H[0, 2]
    q = H[1, 2]
    j00 = H[0, 0] - H[2, 0] * p
    j01 = H[0, 1] - H[2, 1] * p
    j10 = H[1, 0] - H[2, 0] * q
    j11 = H[1, 1] - H[2, 1] * q
    # R_v^T: rotateVec2ZAxis(v) transposed
    nrm = math.sqrt(p * p + q * q + 1.0)
    ax = p / nrm
    ay = q / nrm
    az = 1.0 / nrm
    dd = 1.0 / (1.0 + az)
    rv00 = 1.0 - ax * ax * dd
    rv01 = -ax * ay * dd
    rv02 = ax
    rv10 = -ax * ay * dd
    rv11 = 1.0 - ay * ay * dd
    rv12 = ay
    rv20 = -ax
    rv21 = -ay
    rv22 = 1.0 - (ax * ax + ay * ay) * dd
    b00 = rv00 - p * rv20
    b01 = rv01 - p * rv21
    b10 = rv10 - q * rv20
    b11 = rv11 - q * rv21
    det = b00 * b11 - b01 * b10
    if not abs(det) > 0.0:
        return False
    a00 = (b11 * j00 - b01 * j10) / det
    a01 = (b11 * j01 - b01 * j11) / det
    a10 = (-b10 * j00 + b00 * j10) / det
    a11 = (-b10 * j01 + b00 * j11) / det
    ata00 = a00 * a00 + a01 * a01
    ata01 = a00 * a10 + a01 * a11
    ata11 = a10 * a10 + a11 * a11
    gamma2 = 0.5 * (ata00 + ata11 + math.sqrt((ata00 - ata11) ** 2 + 4.0 * ata01 * ata01))
    if not gamma2 > 1e-14:
        return False
    gamma = math.sqrt(gamma2)
    t00 = a00 / gamma
    t01 = a01 / gamma
    t10 = a10 / gamma
    t11 = a11 / gamma
    c0 = math.sqrt(max(1.0 - t00 * t00 - t10 * t10, 0.0))
    c1 = math.sqrt(max(1.0 - t01 * t01 - t11 * t11, 0.0))
    if -t00 * t01 - t10 * t11 < 0.0:
        c1 = -c1
    rvm = ((rv00, rv01, rv02), (rv10, rv11, rv12), (rv20, rv21, rv22))
    for i in range(3):
        r0, r1, r2 = rvm[i]
        Ra[i, 0] = t00 * r0 + t10 * r1 + c0 * r2
        Ra[i, 1] = t01 * r0 + t11 * r1 + c1 * r2
        Ra[i, 2] = (c1 * t10 - c0 * t11) * r0 + (c0 * t01 - c1 * t00) * r1 + (t00 * t11 - t01 * t10) * r2
        Rb[i, 0] = t00 * r0 + t10 * r1 - c0 * r2
        Rb[i, 1] = t01 * r0 + t11 * r1 - c1 * r2
        Rb[i, 2] = (c0 * t11 - c1 * t10) * r0 + (c1 * t00 - c0 * t01) * r1 + (t00 * t11 - t01 * t10) * r2
    return True


@njit(cache=True)
def _ippe_translation(P, q, n, R, t):
    """The least-squares translation of rotation ``R`` for plane points ``P`` (n, 2) and normalised image
    points ``q`` (n, 2): ``min_t sum |[I | -q_i] (R [P_i, 0] + t)|^2`` (Collins & Bartoli 2014; OpenCV's
    ``computeTranslation``). False when singular."""
    s02 = 0.0
    s12 = 0.0
    s22 = 0.0
    b0 = 0.0
    b1 = 0.0
    b2 = 0.0
    for i in range(n):
        rx = R[0, 0] * P[i, 0] + R[0, 1] * P[i, 1]
        ry = R[1, 0] * P[i, 0] + R[1, 1] * P[i, 1]
        rz = R[2, 0] * P[i, 0] + R[2, 1] * P[i, 1]
        a2 = -q[i, 0]
        c2 = -q[i, 1]
        s02 += a2
        s12 += c2
        s22 += a2 * a2 + c2 * c2
        bx = -a2 * rz - rx
        by = -c2 * rz - ry
        b0 += bx
        b1 += by
        b2 += a2 * bx + c2 * by
    nn = float(n)
    # A^T A = [[n, 0, s02], [0, n, s12], [s02, s12, s22]], by Cramer's rule
    det = nn * nn * s22 - nn * s12 * s12 - nn * s02 * s02
    if not abs(det) > 0.0:
        return False
    t[0] = ((nn * s22 - s12 * s12) * b0 + s02 * s12 * b1 - nn * s02 * b2) / det
    t[1] = (s12 * s02 * b0 + (nn * s22 - s02 * s02) * b1 - nn * s12 * b2) / det
    t[2] = (-nn * s02 * b0 - nn * s12 * b1 + nn * nn * b2) / det
    return True


# ---- refinement and covariance ---------------------------------------------------------------------------


@njit(cache=True)
def _cost(obj, img, n, cam, R, t):
    """Sum of squared pixel residuals [px^2] of pose ``(R, t)``; inf when a point is not in front."""
    c = 0.0
    for i in range(n):
        X, Y, W = obj[i, 0], obj[i, 1], obj[i, 2]
        zc = R[2, 0] * X + R[2, 1] * Y + R[2, 2] * W + t[2]
        if not zc > 0.0:
            return np.inf
        xc = R[0, 0] * X + R[0, 1] * Y + R[0, 2] * W + t[0]
        yc = R[1, 0] * X + R[1, 1] * Y + R[1, 2] * W + t[1]
        u, v = project_point(cam, xc, yc, zc)
        c += (img[i, 0] - u) ** 2 + (img[i, 1] - v) ** 2
    return c


@njit(cache=True)
def _project_hess(cam, X, Y, Z, wu, wv):
    """``wu Hu + wv Hv``, ``Hu``, ``Hv`` the Hessians of :func:`project_point`'s ``u``, ``v`` with respect to
    the camera-frame point (the chain rule through ``(x, y) = (X, Y) / Z`` and the distortion), as its
    entries ``(00, 01, 02, 11, 12, 22)``."""
    iz = 1.0 / Z
    x = X * iz
    y = Y * iz
    r2 = x * x + y * y
    k2, k3 = cam[CAM_K2], cam[CAM_K3]
    p1, p2 = cam[CAM_P1], cam[CAM_P2]
    _, d1, xd_x, xd_y, yd_y = distortion_jacobian(cam, x, y)  # d1 = d radial / d r^2
    d2 = 2.0 * k2 + 6.0 * k3 * r2  # its derivative
    xd_xx = 6.0 * x * d1 + 4.0 * x * x * x * d2 + 6.0 * p2
    xd_xy = 2.0 * y * d1 + 4.0 * x * x * y * d2 + 2.0 * p1  # = yd_xx
    xd_yy = 2.0 * x * d1 + 4.0 * x * y * y * d2 + 2.0 * p2  # = yd_xy
    yd_yy = 6.0 * y * d1 + 4.0 * y * y * y * d2 + 6.0 * p1
    fu = wu * cam[CAM_FX]
    fv = wv * cam[CAM_FY]
    # the weighted second derivatives with respect to (x, y), and the first (for d^2 x / d(X, Y, Z)^2)
    hxx = fu * xd_xx + fv * xd_xy
    hxy = fu * xd_xy + fv * xd_yy
    hyy = fu * xd_yy + fv * yd_yy
    ex = fu * xd_x + fv * xd_y
    ey = fu * xd_y + fv * yd_y
    # d(x, y) / d(X, Y, Z) = [[1, 0, -x], [0, 1, -y]] / Z; d^2 x / dX dZ = -1 / Z^2, d^2 x / dZ^2 = 2 x / Z^2
    iz2 = iz * iz
    h00 = hxx * iz2
    h01 = hxy * iz2
    h11 = hyy * iz2
    h02 = -(hxx * x + hxy * y + ex) * iz2
    h12 = -(hxy * x + hyy * y + ey) * iz2
    h22 = (hxx * x * x + 2.0 * hxy * x * y + hyy * y * y + 2.0 * (ex * x + ey * y)) * iz2
    return h00, h01, h02, h11, h12, h22


@njit(cache=True)
def _normal_equations(obj, img, var, n, cam, R, t, A, b, B, S):
    """At pose ``(R, t)``: ``A = J^T J`` (6, 6) and ``b = J^T r`` (6,) (r = observed - projected), ``J``
    (2n, 6) the pixel Jacobian with respect to ``(dt, dphi)``: ``d X_cam = dt - [p x] dphi``, ``p = R
    X_pad`` (Sola et al. 2018 eq. 27), chained with :func:`_project_jac`; when ``var`` has rows, ``B = J^T
    diag(var) J``; when ``S`` has rows, ``S = -sum r d^2 pi / d(dt, dphi)^2``, the second-order term of the
    cost's Hessian ``J^T J + S`` (Nocedal & Wright 2006 eq. 10.5), through ``exp([dphi x]) p = p + dphi x p
    + dphi x (dphi x p) / 2 + ...``. Returns the cost ``r^T r`` [px^2], inf when a point is not in front of
    the camera."""
    with_var = var.shape[0] > 0
    newton = S.shape[0] > 0
    A[:, :] = 0.0
    B[:, :] = 0.0
    S[:, :] = 0.0
    b[:] = 0.0
    cost = 0.0
    for i in range(n):
        X, Y, W = obj[i, 0], obj[i, 1], obj[i, 2]
        px = R[0, 0] * X + R[0, 1] * Y + R[0, 2] * W
        py = R[1, 0] * X + R[1, 1] * Y + R[1, 2] * W
        pz = R[2, 0] * X + R[2, 1] * Y + R[2, 2] * W
        zc = pz + t[2]
        if not zc > 0.0:
            return np.inf
        u, v, uX, uY, uZ, vX, vY, vZ = _project_jac(cam, px + t[0], py + t[1], zc)
        ru = img[i, 0] - u
        rv = img[i, 1] - v
        cost += ru * ru + rv * rv
        # the rows [g^T, (p x g)^T] of u and v: g^T (-[p x]) w = (p x g) . w
        gu = (uX, uY, uZ, py * uZ - pz * uY, pz * uX - px * uZ, px * uY - py * uX)
        gv = (vX, vY, vZ, py * vZ - pz * vY, pz * vX - px * vZ, px * vY - py * vX)
        for j in range(6):
            b[j] += gu[j] * ru + gv[j] * rv
            for k in range(j, 6):
                A[j, k] += gu[j] * gu[k] + gv[j] * gv[k]
        if with_var:
            s = var[i]
            for j in range(6):
                for k in range(j, 6):
                    B[j, k] += s * (gu[j] * gu[k] + gv[j] * gv[k])
        if newton:
            # -sum_c r_c d^2 pi_c / d(dt, dphi)^2 = -G^T H G - the rotation's own curvature, with H = sum_c
            # r_c d^2 pi_c / dX^2, G = [I, -P], P = [p x] (blocks H, -H P, -P H P, as P^T = -P), and the
            # curvature sum_c r_c g_c . d^2 X / d dphi^2 = (g p^T + p g^T) / 2 - (g . p) I, g = sum_c r_c g_c
            h00, h01, h02, h11, h12, h22 = _project_hess(cam, px + t[0], py + t[1], pz + t[2], ru, rv)
            # H P, P's columns being (0, pz, -py), (-pz, 0, px), (py, -px, 0)
            q00, q01, q02 = h01 * pz - h02 * py, h02 * px - h00 * pz, h00 * py - h01 * px
            q10, q11, q12 = h11 * pz - h12 * py, h12 * px - h01 * pz, h01 * py - h11 * px
            q20, q21, q22 = h12 * pz - h22 * py, h22 * px - h02 * pz, h02 * py - h12 * px
            gx, gy, gz = ru * uX + rv * vX, ru * uY + rv * vY, ru * uZ + rv * vZ
            gp = gx * px + gy * py + gz * pz
            S[0, 0] -= h00
            S[0, 1] -= h01
            S[0, 2] -= h02
            S[1, 1] -= h11
            S[1, 2] -= h12
            S[2, 2] -= h22
            S[0, 3] += q00
            S[0, 4] += q01
            S[0, 5] += q02
            S[1, 3] += q10
            S[1, 4] += q11
            S[1, 5] += q12
            S[2, 3] += q20
            S[2, 4] += q21
            S[2, 5] += q22
            # P (H P) by rows, P's rows being (0, -pz, py), (pz, 0, -px), (-py, px, 0); minus the curvature
            S[3, 3] += py * q20 - pz * q10 - gx * px + gp
            S[3, 4] += py * q21 - pz * q11 - 0.5 * (gx * py + px * gy)
            S[3, 5] += py * q22 - pz * q12 - 0.5 * (gx * pz + px * gz)
            S[4, 4] += pz * q01 - px * q21 - gy * py + gp
            S[4, 5] += pz * q02 - px * q22 - 0.5 * (gy * pz + py * gz)
            S[5, 5] += px * q12 - py * q02 - gz * pz + gp
    for j in range(6):
        for k in range(j):
            A[j, k] = A[k, j]
            B[j, k] = B[k, j]
            if newton:
                S[j, k] = S[k, j]
    return cost


@njit(cache=True)
def _retract(R, t, dx, s, R_out, t_out):
    """``t_out = t + s dt``, ``R_out = exp([s dphi x]) R`` (Sola et al. 2018 eq. 27, left plus)."""
    x, y, z, w = qexp3(s * dx[3], s * dx[4], s * dx[5])
    e = qmat9(x, y, z, w)
    for i in range(3):
        t_out[i] = t[i] + s * dx[i]
        for j in range(3):
            R_out[i, j] = e[3 * i] * R[0, j] + e[3 * i + 1] * R[1, j] + e[3 * i + 2] * R[2, j]


@njit(cache=True)
def _refine(obj, img, n, cam, R, t, ws, max_iters, R_other, t_other):
    """Minimise the reprojection error from ``(R, t)``, in place: Newton steps on the full Hessian where it
    is positive definite, Gauss-Newton steps elsewhere (Nocedal & Wright 2006 sec. 10.3; Gauss-Newton alone
    converges only linearly, at rates up to ~0.9, when a far board's tilt is weakly observed), each halved
    until the cost does not grow. ``ws`` (5, 6, 6) is scratch. Stops when a step falls below
    :data:`STEP_TOL` (converged), after ``max_iters`` steps, or when the pose comes within
    :data:`JOIN_TOL` of ``(R_other, t_other)``, a minimum already found (``t_other[2]`` NaN: none).
    Returns ``(cost [px^2], status)``: :data:`_CONVERGED`, :data:`_JOINED` or :data:`_UNFINISHED`; cost inf
    on failure."""
    A, S, L, sc = ws[0], ws[2], ws[3], ws[4]
    b, d, dx = sc[3], sc[4], sc[5]
    R_try = np.empty((3, 3))
    t_try = np.empty(3)
    no_var = np.empty(0)
    # one loop evaluates every pose, the start, each step and each halving of it (one call site: numba
    # inlines it, and it is the largest function here)
    dx[:] = 0.0
    s = 1.0
    c_max = np.inf
    halvings = 0
    it = 0
    while True:
        _retract(R, t, dx, s, R_try, t_try)
        c = _normal_equations(obj, img, no_var, n, cam, R_try, t_try, A, b, ws[1], S)
        if c > c_max and halvings < MAX_HALVINGS:
            s *= 0.5
            halvings += 1
            continue
        if not math.isfinite(c):
            return np.inf, _UNFINISHED
        R[:, :] = R_try
        t[:] = t_try
        if _pose_distance(R, t, R_other, t_other) < JOIN_TOL:
            return c, _JOINED
        if it == max_iters:
            return c, _UNFINISHED
        it += 1
        for j in range(6):
            for k in range(6):
                S[j, k] += A[j, k]
        if not _chol_factor(S, 6, L, d) and not _chol_factor(A, 6, L, d):
            return np.inf, _UNFINISHED
        _chol_solve(L, d, 6, b, dx)
        step = math.sqrt(dx[0] ** 2 + dx[1] ** 2 + dx[2] ** 2 + dx[3] ** 2 + dx[4] ** 2 + dx[5] ** 2)
        if not math.isfinite(step):
            return np.inf, _UNFINISHED
        if step < STEP_TOL:
            _retract(R, t, dx, 1.0, R_try, t_try)
            R[:, :] = R_try
            t[:] = t_try
            return c, _CONVERGED
        # the cost's rounding (~1e-16 of it) must not reject a step whose decrease it cannot resolve
        c_max = c * (1.0 + COST_RTOL) + 1e-20
        s = 1.0
        halvings = 0


@njit(cache=True)
def _pose_distance(R1, t1, R2, t2):
    """``|t1 - t2| [m] + |log(R1 R2^T)| [rad]`` to first order (the rotation angle from the skew part);
    inf when ``t2[2]`` is NaN."""
    if not math.isfinite(t2[2]):
        return np.inf
    wx = wy = wz = 0.0
    for k in range(3):
        # the skew part of D = R1 R2^T: (D21 - D12, D02 - D20, D10 - D01) / 2
        wx += 0.5 * (R1[2, k] * R2[1, k] - R1[1, k] * R2[2, k])
        wy += 0.5 * (R1[0, k] * R2[2, k] - R1[2, k] * R2[0, k])
        wz += 0.5 * (R1[1, k] * R2[0, k] - R1[0, k] * R2[1, k])
    dt = math.sqrt((t1[0] - t2[0]) ** 2 + (t1[1] - t2[1]) ** 2 + (t1[2] - t2[2]) ** 2)
    return dt + math.sqrt(wx * wx + wy * wy + wz * wz)


@njit(cache=True)
def _finish(obj, img, var, n, cam, R, t, ws, t_out, R_out, cov_out):
    """The covariance of the refined pose ``(R, t)`` (module docstring) and ``estimate_pose``'s checks;
    writes the outputs and returns True when they pass."""
    if not t[2] > 0.0:
        return False
    A, B, inv, L, sc = ws[0], ws[1], ws[2], ws[3], ws[4]
    b, d, e = sc[3], sc[4], sc[5]
    if not math.isfinite(_normal_equations(obj, img, var, n, cam, R, t, A, b, B, np.empty((0, 0)))):
        return False
    if not _chol_factor(A, 6, L, d):
        return False
    for j in range(6):
        e[:] = 0.0
        e[j] = 1.0
        _chol_solve(L, d, 6, e, inv[:, j])
    IB = A  # J^T J is no longer needed
    for i in range(6):
        for j in range(6):
            IB[i, j] = 0.0
            for k in range(6):
                IB[i, j] += inv[i, k] * B[k, j]
    for i in range(6):
        for j in range(i + 1):
            c = 0.0
            for k in range(6):
                c += IB[i, k] * inv[k, j]
            cov_out[i, j] = c
    for i in range(6):
        if not (math.isfinite(cov_out[i, i]) and cov_out[i, i] > 0.0):
            return False
        for j in range(i):
            if not math.isfinite(cov_out[i, j]):
                return False
            cov_out[j, i] = cov_out[i, j]
    t_out[:] = t
    R_out[:, :] = R
    return True


@njit(cache=True)
def _inputs_ok(obj, img, n):
    """At least 4 rows, all finite."""
    if n < 4 or n > obj.shape[0] or n > img.shape[0]:
        return False
    for i in range(n):
        for j in range(3):
            if not math.isfinite(obj[i, j]):
                return False
        if not (math.isfinite(img[i, 0]) and math.isfinite(img[i, 1])):
            return False
    return True


@njit(cache=True)
def solve_pose_nb(
    obj: np.ndarray,
    img: np.ndarray,
    var: np.ndarray,
    n: int,
    cam: np.ndarray,
    t_out: np.ndarray,
    R_out: np.ndarray,
    cov_out: np.ndarray,
) -> bool:
    """The pad's pose from ``n`` corners, twin of :func:`swarm.core.pad_vision.estimate_pose` (module
    docstring).

    ``obj`` (>= n, 3) [m] the corners in the pad frame (on its plane z = 0), ``img`` (>= n, 2) [px] their
    observed pixels, ``var`` (>= n,) [px^2] each corner's noise variance per axis (:func:`pack_frame_nb`
    builds the three); the first ``n`` rows are used. Writes ``t_out`` (3,) [m] = ``t_cam``, ``R_out``
    (3, 3) = ``R_cam_pad`` and ``cov_out`` (6, 6), the covariance of ``(dt [m], dphi [rad])`` (camera frame,
    left perturbation), and returns True; returns False, the outputs unspecified, where ``estimate_pose``
    returns None: ``n < 4``, a non-finite point, a degenerate geometry (singular normal equations), a
    non-finite or non-positive covariance diagonal, or ``t_z <= 0``.
    """
    if not _inputs_ok(obj, img, n):
        return False
    Rs = np.empty((2, 3, 3))
    ts = np.empty((2, 3))
    costs = np.empty(2)
    if not ippe_poses_nb(obj, img, n, cam, Rs, ts, costs):
        return False
    # IPPE's first to convergence, then its second until it converges too or joins the first's minimum;
    # the lower minimum wins
    ws = np.empty((5, 6, 6))
    nowhere = np.full(3, np.nan)
    found = np.full(2, np.inf)
    best = -1
    for k in range(2):
        if not math.isfinite(costs[k]):
            continue
        t_first = ts[0] if best == 0 else nowhere
        found[k], status = _refine(obj, img, n, cam, Rs[k], ts[k], ws, 2 * MAX_ITERS, Rs[0], t_first)
        if status == _CONVERGED and (best < 0 or found[k] < found[best] * (1.0 - COST_RTOL)):
            best = k
    if best < 0:
        return False
    return _finish(obj, img, var, n, cam, Rs[best], ts[best], ws, t_out, R_out, cov_out)


@njit(cache=True)
def ippe_poses_nb(
    obj: np.ndarray,
    img: np.ndarray,
    n: int,
    cam: np.ndarray,
    Rs: np.ndarray,
    ts: np.ndarray,
    costs: np.ndarray,
) -> bool:
    """IPPE's two poses of the plane (module docstring): the homography of the first ``n`` pad-frame points
    ``obj`` (on z = 0) to their undistorted pixels ``img``, decomposed; writes ``Rs`` (2, 3, 3) ``R_cam_pad``,
    ``ts`` (2, 3) [m] ``t_cam`` and ``costs`` (2,) [px^2] their reprojection errors (inf: no translation),
    the lower first (OpenCV's order). False when the geometry is degenerate or ``n < 4``."""
    if n < 4:
        return False
    # IPPE's canonical frame: the plane points about their centroid; the undistorted normalised image points
    c = np.zeros(3)
    for i in range(n):
        for j in range(3):
            c[j] += obj[i, j] / n
    pq = np.empty((n, 4))
    for i in range(n):
        pq[i, 0] = obj[i, 0] - c[0]
        pq[i, 1] = obj[i, 1] - c[1]
        pq[i, 2], pq[i, 3] = undistort_point(cam, img[i, 0], img[i, 1])
    P, q = pq[:, 0:2], pq[:, 2:4]
    hw = np.empty((19, 8))
    H = np.empty((3, 3))
    if not _homography(P, q, n, H, hw[0:8], hw[16], hw[8:16], hw[17], hw[18]):
        return False
    if not _ippe_rotations(H, Rs[0], Rs[1]):
        return False
    for k in range(2):
        costs[k] = np.inf
        if _ippe_translation(P, q, n, Rs[k], ts[k]):
            for i in range(3):  # back to the pad frame: X_cam = R (X - c) + t_c
                ts[k, i] -= Rs[k, i, 0] * c[0] + Rs[k, i, 1] * c[1] + Rs[k, i, 2] * c[2]
            costs[k] = _cost(obj, img, n, cam, Rs[k], ts[k])
    if costs[1] < costs[0]:
        for i in range(3):
            ts[0, i], ts[1, i] = ts[1, i], ts[0, i]
            for j in range(3):
                Rs[0, i, j], Rs[1, i, j] = Rs[1, i, j], Rs[0, i, j]
        costs[0], costs[1] = costs[1], costs[0]
    return math.isfinite(costs[0])


@njit(cache=True)
def refine_pose_nb(
    obj: np.ndarray,
    img: np.ndarray,
    var: np.ndarray,
    n: int,
    cam: np.ndarray,
    R0: np.ndarray,
    t0: np.ndarray,
    t_out: np.ndarray,
    R_out: np.ndarray,
    cov_out: np.ndarray,
) -> bool:
    """:func:`solve_pose_nb` from the initial pose ``(R0 (3, 3), t0 (3,) [m])`` instead of the homography's
    (a warm start, e.g. from the previous frame): the same refinement, covariance, outputs and refusals."""
    if not _inputs_ok(obj, img, n):
        return False
    R = R0.copy()
    t = t0.copy()
    ws = np.empty((5, 6, 6))
    if _refine(obj, img, n, cam, R, t, ws, 2 * MAX_ITERS, R, np.full(3, np.nan))[1] != _CONVERGED:
        return False
    return _finish(obj, img, var, n, cam, R, t, ws, t_out, R_out, cov_out)


@njit(cache=True)
def reproj_rms_nb(
    obj: np.ndarray, img: np.ndarray, n: int, cam: np.ndarray, R: np.ndarray, t: np.ndarray
) -> float:
    """RMS [px] over the first ``n`` points of the reprojection error at ``(R, t)``
    (``PadPose.reproj_rms_px``); NaN when ``n < 1``."""
    if n < 1:
        return np.nan
    return math.sqrt(_cost(obj, img, n, cam, R, t) / n)
