"""Compiled kernels of the IMU-driven error-state filter (:mod:`swarm.core.imu_filter`).

One filter per call, on its own rows of the batch arrays (``X[i]``, ``P[i]``); the batch functions loop over
the leading axis running the same code, so a filter gives bit-identical numbers alone or in a batch, as
the tandem filter's kernels (:mod:`swarm.core._ekf_nb`).

Nominal state ``X`` (16 + M): ``p`` (3) [m] and ``v`` (3) [m/s] in nav, ``q_nav_body`` (4, scalar-last),
accelerometer bias ``b_a`` (3) [m/s^2], gyro bias ``b_g`` (3) [rad/s], then M per-anchor range biases [m]
(M = 0 without them). Error state (15 + M): ``(dp, dv, dtheta, db_a, db_g, db_r)``, ``dtheta`` a body-frame
(local) rotation vector, ``q_true = q (x) exp(dtheta)``.

Equations: Sola 2017, "Quaternion kinematics for the error-state Kalman filter" (arXiv:1711.02508):
nominal kinematics sec. 5.3.1 and their discrete form sec. 5.4.1; error-state kinematics with the local
angular error sec. 5.3.3; the discrete error-state Jacobian ``F_x`` and perturbation covariances
``Q_i`` sec. 5.4.3; update, injection and reset sec. 6.1-6.3.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarm.core._rot_nb import qexp3, qmat9

# X layout
XP, XV, XQ, XBA, XBG, XRB = 0, 3, 6, 10, 13, 16
# error-state layout
EP, EV, ETH, EBA, EBG, ERB = 0, 3, 6, 9, 12, 15
N_CORE = 15

# PRM layout (ImuFilterParams.vector)
PRM_SIG_A = 0  # accelerometer white noise [m/s^2/sqrt(Hz)]
PRM_SIG_G = 1  # gyro white noise [rad/s/sqrt(Hz)]
PRM_SIG_BA = 2  # accelerometer bias random walk [m/s^3/sqrt(Hz)]
PRM_SIG_BG = 3  # gyro bias random walk [rad/s^2/sqrt(Hz)]
PRM_SIG_RB = 4  # range bias random walk [m/sqrt(s)]
PRM_G = 5  # 5:8 gravity in nav [m/s^2]
PRM_LEVER = 8  # 8:11 UWB tag lever arm, body [m]
PRM_GATE = 11  # hard gate on the squared Mahalanobis distance of a range
PRM_HUBER = 12  # Huber threshold on the normalised innovation (0: off)
N_PRM = 13
# Optional extension, one pair per error state past the core 15 (range-error model, barometer offset):
# PRM[N_PRM + 2 k] = the correlation time tau [s] of error state 15 + k (0: a random walk),
# PRM[N_PRM + 2 k + 1] = its sigma (a random walk's density [unit/sqrt(s)], or a first-order Gauss-Markov
# process's stationary standard deviation [unit]). Without the extension every such state is a random walk
# of density PRM_SIG_RB (the per-anchor range biases of the first model).

# outcome of an update
ACCEPTED, REJECTED, REFUSED = 0, 1, 2


@njit(cache=True)
def _rotmat(q, R):
    x, y, z, w = q[0], q[1], q[2], q[3]
    R[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[0, 1] = 2.0 * (x * y - z * w)
    R[0, 2] = 2.0 * (x * z + y * w)
    R[1, 0] = 2.0 * (x * y + z * w)
    R[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[1, 2] = 2.0 * (y * z - x * w)
    R[2, 0] = 2.0 * (x * z - y * w)
    R[2, 1] = 2.0 * (y * z + x * w)
    R[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@njit(cache=True)
def _qmul_exp(q, px, py, pz):
    """``q <- q (x) exp(phi)``, normalised (in place)."""
    ex, ey, ez, ew = qexp3(px, py, pz)
    x, y, z, w = q[0], q[1], q[2], q[3]
    nx = w * ex + x * ew + y * ez - z * ey
    ny = w * ey - x * ez + y * ew + z * ex
    nz = w * ez + x * ey - y * ex + z * ew
    nw = w * ew - x * ex - y * ey - z * ez
    n = math.sqrt(nx * nx + ny * ny + nz * nz + nw * nw)
    q[0], q[1], q[2], q[3] = nx / n, ny / n, nz / n, nw / n


@njit(cache=True)
def transition(X, gyro, acc, dt, F):
    """The discrete error-state Jacobian ``F_x`` (15 x 15 core; Sola 2017 sec. 5.4.3, local angular error)
    at the nominal state ``X`` before the step, written into ``F``:

    ``dp <- dp + dv dt``; ``dv <- dv - R [a_m - b_a]x dtheta dt - R db_a dt``;
    ``dtheta <- R{(w_m - b_g) dt}^T dtheta - db_g dt``; the biases are random walks (identity)."""
    R = np.empty((3, 3))
    _rotmat(X[XQ : XQ + 4], R)
    ax, ay, az = acc[0] - X[XBA], acc[1] - X[XBA + 1], acc[2] - X[XBA + 2]
    wx, wy, wz = (gyro[0] - X[XBG]) * dt, (gyro[1] - X[XBG + 1]) * dt, (gyro[2] - X[XBG + 2]) * dt
    F[:, :] = 0.0
    for i in range(15):
        F[i, i] = 1.0
    for i in range(3):
        F[EP + i, EV + i] = dt
        # -R [a]x: column j of [a]x is a x e_j
        F[EV + i, ETH + 0] = -(R[i, 1] * az - R[i, 2] * ay) * dt
        F[EV + i, ETH + 1] = -(R[i, 2] * ax - R[i, 0] * az) * dt
        F[EV + i, ETH + 2] = -(R[i, 0] * ay - R[i, 1] * ax) * dt
        for j in range(3):
            F[EV + i, EBA + j] = -R[i, j] * dt
        F[ETH + i, EBG + i] = -dt
    # R{w dt}^T = exp(-[w dt]x): the rotation matrix of exp(-w dt)
    ex, ey, ez, ew = qexp3(-wx, -wy, -wz)
    E = np.empty((3, 3))
    _rotmat(np.array([ex, ey, ez, ew]), E)
    for i in range(3):
        for j in range(3):
            F[ETH + i, ETH + j] = E[i, j]


@njit(cache=True)
def predict_one(X, P, gyro, acc, dt, PRM):
    """Propagate one filter over ``dt`` [s] with the IMU sample held over the interval: gyro rate ``gyro``
    [rad/s] and specific force ``acc`` [m/s^2], body frame (Sola 2017 sec. 5.4.1 for the nominal state,
    ``P <- F_x P F_x^T + F_i Q_i F_i^T`` of sec. 5.4.3 for the covariance, with ``Q_i`` from the noise
    densities: ``V_i = sigma_a^2 dt I``, ``Theta_i = sigma_g^2 dt I``, ``A_i = sigma_ba^2 dt I``,
    ``Omega_i = sigma_bg^2 dt I``, and ``sigma_rb^2 dt`` per range bias). ``F_x`` is that of
    :func:`transition`, applied block by block in place: ``F P`` on the rows of ``(dp, dv, dtheta)``, then
    ``. F^T`` on their columns of those rows, the bias rows mirrored (the comment below): only its
    non-identity blocks cost anything, and nothing is allocated. Returns False (and changes nothing) on a
    non-finite input."""
    for k in range(3):
        if not (np.isfinite(gyro[k]) and np.isfinite(acc[k])):
            return False
    if not (np.isfinite(dt) and dt >= 0.0):
        return False
    if dt == 0.0:
        return True
    n = P.shape[0]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = qmat9(X[XQ], X[XQ + 1], X[XQ + 2], X[XQ + 3])
    ax, ay, az = acc[0] - X[XBA], acc[1] - X[XBA + 1], acc[2] - X[XBA + 2]
    wx, wy, wz = (gyro[0] - X[XBG]) * dt, (gyro[1] - X[XBG + 1]) * dt, (gyro[2] - X[XBG + 2]) * dt
    # F_vtheta = -R [a]x dt, F_vba = -R dt, F_thetatheta = R(exp(-w dt))
    a00, a01, a02 = -(r01 * az - r02 * ay) * dt, -(r02 * ax - r00 * az) * dt, -(r00 * ay - r01 * ax) * dt
    a10, a11, a12 = -(r11 * az - r12 * ay) * dt, -(r12 * ax - r10 * az) * dt, -(r10 * ay - r11 * ax) * dt
    a20, a21, a22 = -(r21 * az - r22 * ay) * dt, -(r22 * ax - r20 * az) * dt, -(r20 * ay - r21 * ax) * dt
    ex, ey, ez, ew = qexp3(-wx, -wy, -wz)
    e00, e01, e02, e10, e11, e12, e20, e21, e22 = qmat9(ex, ey, ez, ew)
    # nominal state
    for i in range(3):
        if i == 0:
            an = r00 * ax + r01 * ay + r02 * az
        elif i == 1:
            an = r10 * ax + r11 * ay + r12 * az
        else:
            an = r20 * ax + r21 * ay + r22 * az
        an += PRM[PRM_G + i]
        X[XP + i] += X[XV + i] * dt + 0.5 * an * dt * dt
        X[XV + i] += an * dt
    _qmul_exp(X[XQ : XQ + 4], wx, wy, wz)
    # F = [[F_AA, F_AB], [0, I]] over A = (dp, dv, dtheta) and B = the rest (biases), so
    # F P F^T = [[F_A P F_A^T, F_A P_B], [., P_BB]]: P <- F P changes rows A only (every column j); then
    # P F^T on those rows alone gives the AA block; the BA block is the transpose of the new AB block
    # (one short loop per row: contiguous in j, so the compiler vectorises them)
    for r in range(3):
        for j in range(n):
            P[EP + r, j] += dt * P[EV + r, j]
    for r in range(3):
        if r == 0:
            c0, c1, c2, d0, d1, d2 = a00, a01, a02, r00, r01, r02
        elif r == 1:
            c0, c1, c2, d0, d1, d2 = a10, a11, a12, r10, r11, r12
        else:
            c0, c1, c2, d0, d1, d2 = a20, a21, a22, r20, r21, r22
        for j in range(n):
            P[EV + r, j] = (P[EV + r, j] + c0 * P[ETH, j] + c1 * P[ETH + 1, j] + c2 * P[ETH + 2, j]
                            - dt * (d0 * P[EBA, j] + d1 * P[EBA + 1, j] + d2 * P[EBA + 2, j]))  # fmt: skip
    for j in range(n):
        t0, t1, t2 = P[ETH, j], P[ETH + 1, j], P[ETH + 2, j]
        P[ETH, j] = e00 * t0 + e01 * t1 + e02 * t2 - dt * P[EBG, j]
        P[ETH + 1, j] = e10 * t0 + e11 * t1 + e12 * t2 - dt * P[EBG + 1, j]
        P[ETH + 2, j] = e20 * t0 + e21 * t1 + e22 * t2 - dt * P[EBG + 2, j]
    for i in range(9):  # the rows A: P F^T on their columns A (the column's B entries are P's B rows)
        v0, v1, v2 = P[i, EV], P[i, EV + 1], P[i, EV + 2]
        t0, t1, t2 = P[i, ETH], P[i, ETH + 1], P[i, ETH + 2]
        b0, b1, b2 = P[i, EBA], P[i, EBA + 1], P[i, EBA + 2]
        P[i, EP] += dt * v0
        P[i, EP + 1] += dt * v1
        P[i, EP + 2] += dt * v2
        P[i, EV] = v0 + a00 * t0 + a01 * t1 + a02 * t2 - dt * (r00 * b0 + r01 * b1 + r02 * b2)
        P[i, EV + 1] = v1 + a10 * t0 + a11 * t1 + a12 * t2 - dt * (r10 * b0 + r11 * b1 + r12 * b2)
        P[i, EV + 2] = v2 + a20 * t0 + a21 * t1 + a22 * t2 - dt * (r20 * b0 + r21 * b1 + r22 * b2)
        P[i, ETH] = e00 * t0 + e01 * t1 + e02 * t2 - dt * P[i, EBG]
        P[i, ETH + 1] = e10 * t0 + e11 * t1 + e12 * t2 - dt * P[i, EBG + 1]
        P[i, ETH + 2] = e20 * t0 + e21 * t1 + e22 * t2 - dt * P[i, EBG + 2]
    for i in range(9):  # exactly symmetric again: the AA block averaged with its transpose, BA mirrored
        for j in range(i + 1, 9):
            m = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = m
            P[j, i] = m
        for j in range(9, n):
            P[j, i] = P[i, j]
    qa, qg = PRM[PRM_SIG_A] ** 2 * dt, PRM[PRM_SIG_G] ** 2 * dt
    qba, qbg, qrb = PRM[PRM_SIG_BA] ** 2 * dt, PRM[PRM_SIG_BG] ** 2 * dt, PRM[PRM_SIG_RB] ** 2 * dt
    for i in range(3):
        P[EV + i, EV + i] += qa
        P[ETH + i, ETH + i] += qg
        P[EBA + i, EBA + i] += qba
        P[EBG + i, EBG + i] += qbg
    if PRM.shape[0] < N_PRM + 2 * (n - 15):
        for i in range(15, n):
            P[i, i] += qrb
        return True
    # the extra states (range-error model): a random walk adds sigma^2 dt; a first-order Gauss-Markov state
    # x' = -x / tau + w decays by phi = exp(-dt / tau) with the exact discrete variance sigma^2 (1 - phi^2)
    # (Maybeck 1979, vol. 1, sec. 4.11; Brown & Hwang 2012, sec. 4.2): its nominal value x <- phi x and F's
    # diagonal entry phi, so row and column of P scale by phi (F P F^T with F = diag(.., phi, ..))
    tau_prev, phi = -1.0, 1.0
    for i in range(15, n):
        k = N_PRM + 2 * (i - 15)
        tau, s = PRM[k], PRM[k + 1]
        if tau > 0.0:
            if tau != tau_prev:
                phi = math.exp(-dt / tau)
                tau_prev = tau
            X[XRB + i - ERB] *= phi
            for j in range(n):
                P[i, j] *= phi
            for j in range(n):
                P[j, i] *= phi
            P[i, i] += s * s * (1.0 - phi * phi)
        else:
            P[i, i] += s * s * dt
    return True


@njit(cache=True)
def range_row(X, anchor, bias_index, lever, H):
    """The predicted range ``|p + R(q) l - a| + b_r`` and its Jacobian row ``H`` (N,) with respect to the
    error state: ``u^T`` on ``dp``, ``-(u_b x l)`` on ``dtheta`` (``u_b = R^T u``, from
    ``R (I + [dtheta]x) l``), 1 on the anchor's bias (``bias_index`` >= 0, its error-state index)."""
    return range_row3(X, anchor, bias_index, -1, -1, lever, H)


@njit(cache=True)
def range_row3(X, anchor, i0, i1, i2, lever, H):
    """:func:`range_row` with up to three additive error terms of the range-error model, each an error-state
    index or -1: ``h = |p + R(q) l - a| + x[i0] + x[i1] + x[i2]`` (a common offset, the anchor's offset and
    its Gauss-Markov multipath term), each with a 1 in ``H``."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = qmat9(X[XQ], X[XQ + 1], X[XQ + 2], X[XQ + 3])
    l0, l1, l2 = lever[0], lever[1], lever[2]
    d0 = X[XP] + r00 * l0 + r01 * l1 + r02 * l2 - anchor[0]
    d1 = X[XP + 1] + r10 * l0 + r11 * l1 + r12 * l2 - anchor[1]
    d2 = X[XP + 2] + r20 * l0 + r21 * l1 + r22 * l2 - anchor[2]
    r = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    H[:] = 0.0
    if r < 1e-9:
        return r
    u0, u1, u2 = d0 / r, d1 / r, d2 / r
    b0 = r00 * u0 + r10 * u1 + r20 * u2
    b1 = r01 * u0 + r11 * u1 + r21 * u2
    b2 = r02 * u0 + r12 * u1 + r22 * u2
    H[EP], H[EP + 1], H[EP + 2] = u0, u1, u2
    H[ETH] = -(b1 * l2 - b2 * l1)
    H[ETH + 1] = -(b2 * l0 - b0 * l2)
    H[ETH + 2] = -(b0 * l1 - b1 * l0)
    h = r
    if i0 >= 0:
        H[i0] = 1.0
        h += X[XRB + i0 - ERB]
    if i1 >= 0:
        H[i1] = 1.0
        h += X[XRB + i1 - ERB]
    if i2 >= 0:
        H[i2] = 1.0
        h += X[XRB + i2 - ERB]
    return h


@njit(cache=True)
def inject(X, P, dx):
    """Add the observed error to the nominal state and reset it (Sola 2017 sec. 6.2-6.3): ``q <- q (x)
    exp(dtheta)`` and ``P <- G P G^T`` with ``G = I - [dtheta / 2]x`` on the attitude block (sec. 6.3.1)."""
    n = P.shape[0]
    for i in range(3):
        X[XP + i] += dx[EP + i]
        X[XV + i] += dx[EV + i]
        X[XBA + i] += dx[EBA + i]
        X[XBG + i] += dx[EBG + i]
    for i in range(15, n):
        X[XRB + i - ERB] += dx[i]
    _qmul_exp(X[XQ : XQ + 4], dx[ETH], dx[ETH + 1], dx[ETH + 2])
    hx, hy, hz = 0.5 * dx[ETH], 0.5 * dx[ETH + 1], 0.5 * dx[ETH + 2]
    # G = [[1, hz, -hy], [-hz, 1, hx], [hy, -hx, 1]]: rows of P, then columns
    for j in range(n):
        t0, t1, t2 = P[ETH, j], P[ETH + 1, j], P[ETH + 2, j]
        P[ETH, j] = t0 + hz * t1 - hy * t2
        P[ETH + 1, j] = -hz * t0 + t1 + hx * t2
        P[ETH + 2, j] = hy * t0 - hx * t1 + t2
    for i in range(n):
        t0, t1, t2 = P[i, ETH], P[i, ETH + 1], P[i, ETH + 2]
        P[i, ETH] = t0 + hz * t1 - hy * t2
        P[i, ETH + 1] = -hz * t0 + t1 + hx * t2
        P[i, ETH + 2] = hy * t0 - hx * t1 + t2


@njit(cache=True)
def update_range_one(X, P, anchor, bias_index, z, sigma, PRM, work, out):
    """One UWB range ``z`` [m] (noise ``sigma`` [m]) to ``anchor``: gated on its squared Mahalanobis
    distance (``PRM_GATE``), then, if the normalised innovation ``e`` exceeds the Huber threshold ``k``,
    underweighted by inflating its variance by ``|e| / k`` (Huber's M-estimator as an iteratively reweighted
    Kalman update; an NLOS range that passes the gate pulls with a bounded influence). ``work`` (3, N) is
    scratch; ``out`` receives ``(outcome, d2, innovation)``; returns the outcome."""
    return update_range3(X, P, anchor, bias_index, -1, -1, z, sigma, PRM, work, out)


@njit(cache=True)
def range_innovation(X, P, anchor, i0, i1, i2, PRM, work):
    """The predicted range of :func:`range_row3` and ``H P H^T``; leaves ``H`` in ``work[0]`` and ``P H^T``
    in ``work[1]`` for :func:`apply_scalar`."""
    n = P.shape[0]
    H, b = work[0], work[1]
    h = range_row3(X, anchor, i0, i1, i2, PRM[PRM_LEVER : PRM_LEVER + 3], H)
    hph = 0.0
    for i in range(n):  # b = P H^T over H's nonzero entries: dp, dtheta and the range-error terms
        s = (P[i, 0] * H[0] + P[i, 1] * H[1] + P[i, 2] * H[2] + P[i, 6] * H[6] + P[i, 7] * H[7]
             + P[i, 8] * H[8])  # fmt: skip
        if i0 >= 0:
            s += P[i, i0]
        if i1 >= 0:
            s += P[i, i1]
        if i2 >= 0:
            s += P[i, i2]
        b[i] = s
        hph += H[i] * s
    return h, hph


@njit(cache=True)
def update_range3(X, P, anchor, i0, i1, i2, z, sigma, PRM, work, out):
    """:func:`update_range_one` with the range-error terms of :func:`range_row3`."""
    out[1] = 0.0
    out[2] = 0.0
    if not (np.isfinite(z) and np.isfinite(sigma) and sigma > 0.0 and z >= 0.0):
        out[0] = REFUSED
        return REFUSED
    h, hph = range_innovation(X, P, anchor, i0, i1, i2, PRM, work)
    nu = z - h
    r = sigma * sigma
    S = hph + r
    d2 = nu * nu / S
    out[1], out[2] = d2, nu
    if d2 > PRM[PRM_GATE]:
        out[0] = REJECTED
        return REJECTED
    huber_apply(X, P, work, nu, hph, r, d2, PRM[PRM_HUBER])
    out[0] = ACCEPTED
    return ACCEPTED


@njit(cache=True)
def apply_scalar(X, P, work, nu, S):
    """The Kalman update of a scalar innovation ``nu`` of variance ``S`` with ``P H^T`` in ``work[1]``:
    ``dx = P H^T nu / S``, ``P <- P - P H^T H P / S``, then the injection and reset (:func:`inject`)."""
    n = P.shape[0]
    b, dx = work[1], work[2]
    for i in range(n):
        dx[i] = b[i] * nu / S
    # P <- P - b b^T / S over the whole matrix, row by row (contiguous, vectorised); ``(b_i b_j) (1 / S)``
    # is the same number for (i, j) and (j, i), so P stays exactly symmetric
    inv_s = 1.0 / S
    for i in range(n):
        bi = b[i]
        for j in range(n):
            P[i, j] -= (bi * b[j]) * inv_s
    inject(X, P, dx)


@njit(cache=True)
def huber_apply(X, P, work, nu, hph, r, d2, k):
    """:func:`apply_scalar` with the measurement variance ``r`` [m^2] inflated by ``sqrt(d2) / k`` when the
    squared Mahalanobis distance ``d2`` passes ``k^2`` (``k`` 0: off): the Huber M-estimator's weight
    ``k / |e|`` as a variance (Huber 1964, the M-estimator as an iteratively reweighted Kalman update): an
    outlier that passes the gate pulls with a bounded influence."""
    if k > 0.0 and d2 > k * k:
        r *= math.sqrt(d2) / k
    apply_scalar(X, P, work, nu, hph + r)


# ------------------------------------------------------------------------------------------------ TDoA


@njit(cache=True)
def tdoa_row(X, anchor_a, anchor_b, ia, ib, lever, H):
    """A time difference of arrival as a distance difference, ``h = |t - a_b| - |t - a_a| + e_b - e_a``
    (``t = p + R(q) l`` the tag; the Crazyflie's ``distanceDiff``, idB minus idA), with ``e`` an anchor's
    range-error terms (``ia``, ``ib`` (3,) error indices or -1: its offset and Gauss-Markov term enter as a
    difference; the common offset cancels, so index 0 is skipped), and its Jacobian row ``H``:
    ``u_b - u_a`` on ``dp``, ``-((u_b - u_a)_body x l)`` on ``dtheta``, +1 on b's terms and -1 on a's (the
    difference of two :func:`range_row3` rows; the TDoA measurement model of Ledergerber, Hamer & D'Andrea
    2015, IROS, as the Crazyflie's ``mm_tdoa.c`` fuses it)."""
    n = H.shape[0]
    Hb = np.empty(n)
    hb = range_row3(X, anchor_b, -1, ib[1], ib[2], lever, Hb)
    ha = range_row3(X, anchor_a, -1, ia[1], ia[2], lever, H)
    for k in range(n):
        H[k] = Hb[k] - H[k]
    return hb - ha


@njit(cache=True)
def tdoa_innovation(X, P, anchor_a, anchor_b, ia, ib, PRM, work):
    """The predicted distance difference of :func:`tdoa_row` and ``H P H^T``; leaves ``H`` in ``work[0]``
    and ``P H^T`` in ``work[1]`` for :func:`apply_scalar`."""
    n = P.shape[0]
    H, b = work[0], work[1]
    h = tdoa_row(X, anchor_a, anchor_b, ia, ib, PRM[PRM_LEVER : PRM_LEVER + 3], H)
    hph = 0.0
    for i in range(n):
        s = 0.0
        for j in range(n):
            if H[j] != 0.0:
                s += P[i, j] * H[j]
        b[i] = s
        hph += H[i] * s
    return h, hph


@njit(cache=True)
def update_tdoa(X, P, anchor_a, anchor_b, ia, ib, z, sigma, PRM, work, res):
    """One distance difference ``z`` [m] with white noise ``sigma`` [m] (:func:`tdoa_row`): refused when not
    finite, gated on its squared Mahalanobis distance (``PRM_GATE``), underweighted past the Huber threshold
    as a range is, then the scalar update. ``res`` receives ``(outcome, d2, nu, H P H^T)``; returns the
    outcome."""
    res[0], res[1], res[2] = REFUSED, 0.0, 0.0
    if not (np.isfinite(z) and np.isfinite(sigma) and sigma > 0.0):
        return REFUSED
    h, hph = tdoa_innovation(X, P, anchor_a, anchor_b, ia, ib, PRM, work)
    nu = z - h
    r = sigma * sigma
    d2 = nu * nu / (hph + r)
    res[1], res[2], res[3] = d2, nu, hph
    if d2 > PRM[PRM_GATE]:
        res[0] = REJECTED
        return REJECTED
    huber_apply(X, P, work, nu, hph, r, d2, PRM[PRM_HUBER])
    res[0] = ACCEPTED
    return ACCEPTED


TV_VAR, TV_C2, TV_HPH, TV_PRIOR = range(4)
N_TV = 4
"""An anchor pair's noise state (``TV`` (M, M, N_TV)): the white variance in use [m^2], the exponentially
weighted means of its accepted squared innovations and of their ``H P H^T`` (NaN: none yet), the prior."""


@njit(cache=True)
def _ess_now(RS, x):
    """Anchor ``x``'s current worth of one innovation (:func:`_ess_weight`), without a new one."""
    if RS[x, RS_E2] > 0.0 and np.isfinite(RS[x, RS_EPREV]):
        rho = min(max(RS[x, RS_EE] / RS[x, RS_E2], 0.0), 0.95)
        return (1.0 - rho * rho) / (1.0 + rho * rho)
    return 1.0


@njit(cache=True)
def _ess_weight(RS, RP, x, e):
    """Anchor ``x``'s signed normalised innovation ``e`` into its lag-1 autocorrelation (weighted means of
    ``e_k e_{k-1}`` and ``e_k^2`` in ``RS``); returns the worth ``(1 - rho^2) / (1 + rho^2)`` of one
    innovation in the window test (the AR(1) effective sample size, Wilks 2011 sec. 5.2.4; Isserlis)."""
    w = 1.0
    ep = RS[x, RS_EPREV]
    al = RP[RP_ADAPT_ALPHA]
    if np.isfinite(ep):
        RS[x, RS_EE] += al * (e * ep - RS[x, RS_EE])
        RS[x, RS_E2] += al * (e * e - RS[x, RS_E2])
        if RS[x, RS_E2] > 0.0:
            rho = min(max(RS[x, RS_EE] / RS[x, RS_E2], 0.0), 0.95)
            w = (1.0 - rho * rho) / (1.0 + rho * rho)
    else:
        RS[x, RS_E2] = e * e
    RS[x, RS_EPREV] = e
    return w


@njit(cache=True)
def fuse_tdoa(X, P, PRM, RP, anchors, ridx, a, b, z, t, TV, RS, work, res, pinned=False):
    """One distance difference ``z`` [m] of anchors ``a`` and ``b`` (indices into ``anchors`` (M, 3) and
    ``ridx``) at ``t`` [s] through the robust TDoA model; returns the outcome and leaves ``(outcome, d2, nu,
    weight)`` in ``res`` (``weight``: its worth of an independent innovation in the window test, -1 held
    out). Each anchor's error enters as a difference (:func:`tdoa_row`), so the anchor, not the pair, is
    what goes wrong, and the range model's per-anchor state ``RS`` serves (a TDoA log has no ranges):

    1. **NLOS** (``RP_NLOS``): each anchor's CUSUM (:func:`_nlos_cusum`, as :func:`fuse_range`) takes the
       normalised innovation ``e = nu / sqrt(S)`` with its sign in the difference, ``+e`` for ``b`` and
       ``-e`` for ``a``: an anchor whose packets come late (NLOS: always long) drives its own sum up in every
       pair and the other anchors' down. Each increment is weighted by the anchor's worth of an independent
       innovation (item 4): an anchor is in a quarter of 200-400 differences a second whose errors
       correlate over half a second, and unweighted sums of them cross the threshold on the anchor's own
       (modelled) slow error. A difference with a held anchor is held out (rejected, out of the window).
    2. **Gate, Huber and update** as :func:`update_tdoa`, with the pair's white variance ``TV[a, b]``.
    3. **Noise adaptation** (``RP_ADAPT``): covariance matching on the pair's accepted innovations as
       :func:`fuse_range` adapts a range's, but only upward from the prior (``[tdoa] sigma_m``), to
       ``RP_VAR_CEIL``: a pair's spread grows in flight, and the heavy tails would otherwise pull it below
       the prior (measured: a divergence).
    4. **Effective sample size** (``RP_ESS``): per anchor, the lag-1 autocorrelation of its signed ``e``;
       a difference is worth the smaller of its two anchors' ``(1 - rho^2) / (1 + rho^2)``.

    While the vehicle is ``pinned`` on the ground (:func:`pin_step`) every difference is held out, refused
    (its squared distance still reported): a TDoA tag on the ground hears the anchors 1-3 m off (the UTIL
    logs, before the take-off and after the touchdown), consistently enough that the gate passes some and
    they move a standing estimate; the pad or the touchdown point is known better."""
    tv = TV[a, b]
    res[0], res[1], res[2], res[3] = REFUSED, 0.0, 0.0, 1.0
    var = tv[TV_VAR]
    if not (np.isfinite(z) and np.isfinite(var) and var > 0.0):
        return REFUSED
    h, hph = tdoa_innovation(X, P, anchors[a], anchors[b], ridx[a], ridx[b], PRM, work)
    nu = z - h
    S = hph + var
    d2 = nu * nu / S
    e = nu / math.sqrt(S)
    res[1], res[2] = d2, nu
    if pinned:
        res[0], res[3] = REFUSED, -1.0
        return REFUSED
    if RP[RP_NLOS] > 0.0:
        wa, wb = 1.0, 1.0
        if RP[RP_ESS] > 0.0:
            wa, wb = _ess_now(RS, a), _ess_now(RS, b)
        held_a = _nlos_cusum(RS, RP, P, a, -e, t, ridx[a, 1], wa)
        held_b = _nlos_cusum(RS, RP, P, b, e, t, ridx[b, 1], wb)
        if held_a or held_b:
            if held_a:
                RS[a, RS_NLOS_RANGES] += 1.0
            if held_b:
                RS[b, RS_NLOS_RANGES] += 1.0
            res[0], res[3] = REJECTED, -1.0
            return REJECTED
    if d2 > PRM[PRM_GATE]:
        res[0] = REJECTED
        return REJECTED
    if RP[RP_ESS] > 0.0:
        res[3] = min(_ess_weight(RS, RP, a, -e), _ess_weight(RS, RP, b, e))
    r = var
    huber_apply(X, P, work, nu, hph, r, d2, PRM[PRM_HUBER])
    if RP[RP_ADAPT] > 0.0:  # upward only: the prior is the floor
        match_noise(tv, TV_VAR, TV_C2, TV_HPH, nu, hph, RP[RP_ADAPT_ALPHA], tv[TV_PRIOR], RP[RP_VAR_CEIL])
    res[0] = ACCEPTED
    return ACCEPTED


# ------------------------------------------------------------------------------------------ log replay

EV_DONE, EV_DIVERGED, EV_PAUSE = 0, 1, 2

# ST (int64 state of a replay): cursors and counters
(ST_I_IMU, ST_I_RNG, ST_I_OUT, ST_WIN_FILL, ST_WIN_POS, ST_HELD, ST_DROPPED, ST_IMU_REFUSED, ST_I_AUX,
 ST_N_PHASE, ST_I_TDOA) = range(11)  # fmt: skip
N_ST = 11

# RS (anchors, N_RS): the range-error model's per-anchor robust state, float64
RS_VAR = 0  # the white-noise variance in use [m^2] (the prior, then adapted in flight)
RS_C2 = 1  # exponentially weighted mean of the squared innovation of accepted ranges [m^2] (NaN: none yet)
RS_HPH = 2  # exponentially weighted mean of H P H^T of those ranges [m^2]
RS_CUSUM = 3  # one-sided CUSUM of the normalised innovation (NLOS detection)
RS_NLOS = 4  # 1 while the anchor is held as NLOS
RS_NLOS_SINCE = 5  # when the current episode was declared [s]
RS_EPREV = 6  # the previous accepted normalised innovation (NaN: none)
RS_EE = 7  # exponentially weighted mean of e_k e_{k-1}
RS_E2 = 8  # exponentially weighted mean of e_k^2
RS_EPISODES = 9  # NLOS episodes declared
RS_NLOS_RANGES = 10  # ranges held out as NLOS
RS_AIR_VAR_SUM = 11  # sum of RS_VAR over the ranges taken while airborne (the in-flight sigma reported)
RS_AIR_N = 12
RS_STEPS = 13  # episodes longer than the longest NLOS episode: taken as an offset change
RS_GRACE_UNTIL = 14  # no NLOS episode is declared before this time [s] (set by a recovery)
N_RS = 15

# RP: the robust settings of a replay (swarm.core.imu_filter.RobustParams.vector)
RP_ADAPT = 0  # 1: per-anchor noise adaptation (covariance matching)
RP_ADAPT_ALPHA = 1  # weight of one range in its exponentially weighted means
RP_VAR_FLOOR = 2  # smallest adapted variance [m^2]
RP_VAR_CEIL = 3  # largest [m^2]
RP_NLOS = 4  # 1: per-anchor CUSUM NLOS detection
RP_CUSUM_K = 5  # its reference value (allowance) on the normalised innovation
RP_CUSUM_H = 6  # its decision threshold
RP_CUSUM_CLIP = 7  # a single normalised innovation's largest contribution
RP_NLOS_MAX_S = 8  # an episode held longer than this is an offset change: released, the offset re-opened
RP_VIB_TAU = 9  # time constant of the vibration detector [s]
RP_VIB_THRESHOLD = 10  # airborne above this vibration level [m/s^2] (a ratio times the level standing still)
RP_TAKEOFF_HEIGHT = 11  # airborne above this height over the ground reference [m] (0: height not used)
RP_DWELL = 12  # a phase change holds this long before it is declared [s]
RP_REOPEN_VAR = 13  # variance added to each anchor's offset at a phase change [m^2]
RP_GROUND_Z = 14  # the ground reference height [m, nav z]
RP_ESS = 15  # 1: the window test counts correlated innovations by their effective sample size
RP_PHASES = 16  # 1: detect take-off and landing
RP_REOPEN_BARO_VAR = 17  # variance added to the barometer offset at a phase change [m^2]
RP_BARO_INDEX = 18  # the barometer offset's error index (-1: none)
RP_NLOS_MAX_HELD = 19  # at most this many anchors held out as NLOS at once
RP_VIB_RATIO = 20  # landed when the vibration falls this many times below its level in flight
RP_LAND_HEIGHT = 21  # touchdown: the estimate under this height over the ground reference [m] (0: off)
RP_LAND_SPEED = 22  # touchdown: its speed under this [m/s]
RP_DESCENT_SPEED = 23  # touchdown: after descending faster than this [m/s] ...
RP_DESCENT_S = 24  # ... at most this long before [s]
RP_CLIMB_ACCEL = 25  # take-off: the vertical specific force over gravity by this [m/s^2] (0: off)
RP_G_NORM = 26  # the magnitude of gravity [m/s^2]
RP_PIN_VEL_VAR = 27  # while pinned: variance of the zero-velocity pseudo-measurement [(m/s)^2] (0: no pin)
RP_PIN_Z_VAR = 28  # while pinned: variance of the height pseudo-measurement at the ground reference [m^2]
RP_PIN_PERIOD = 29  # while pinned: the pseudo-measurements at most this often [s]
RP_VIB_ACCEL_K = 30  # accelerometer noise density added per axis: this times the axis' vibration [sqrt(s)]
N_RP = 31

# PH: flight-phase detector state
(PH_VIB, PH_A0, PH_A1, PH_A2, PH_HAVE, PH_AIR, PH_SINCE, PH_PINNED, PH_AIR_VIB, PH_DESC_T, PH_FZ, PH_PIN_T,
 PH_VX, PH_VY, PH_VZ, PH_ARMED, PH_TOUCH, PH_CHANGE_T, PH_VIB_AIR_SEEN, PH_NEAR, PH_M0, PH_M1, PH_M2, PH_H0,
 PH_H1, PH_H2) = range(26)  # fmt: skip
N_PH = 26
VIB_MEAN_TAU_S = 0.01
"""The vibration's power is taken around the specific force's mean over this [s] (what changes faster than
~16 Hz: rotor vibration, not the flight's own accelerations)."""
# PH_PINNED: 1 while the vehicle stands on the ground: on its known pad, or where it landed. PH_DESC_T: the
# last time the estimate descended faster than RP_DESCENT_SPEED [s]; PH_FZ: the low-passed vertical specific
# force over gravity [m/s^2]; PH_PIN_T: the last pin's time [s]; PH_VX..PH_VZ: each body axis' vibration
# power, the slow mean of the lag-1 product of the specific force's deviations from its VIB_MEAN_TAU_S mean
# [(m/s^2)^2] (PH_M0..PH_M2 that mean, PH_H0..PH_H2 the previous deviation); PH_ARMED: 1 when a rise of the
# vibration may declare a take-off (the rotors stood still since the landing, or the log began); PH_TOUCH: 1
# if the last landing was a touchdown; PH_CHANGE_T: the last change's time [s]; PH_VIB_AIR_SEEN: 1 once the
# vibration rose over its threshold in this flight (so that its fall means something); PH_NEAR: 1 while
# airborne near the ground on the way down or just after the take-off (under RP_LAND_HEIGHT, within
# RP_DESCENT_S of a descent or of the change)

# aux samples (height.csv, baro.csv) and AUX parameters
AUX_HEIGHT, AUX_BARO = 0, 1
(AX_H_SIGMA, AX_H_GROUND, AX_H_COS, AX_H_MAX, AX_H_GATE, AX_B_SIGMA, AX_B_INDEX, AX_B_GATE, AX_H_ON,
 AX_B_ON) = range(10)  # fmt: skip
AX_H_RESET_N = 10  # the height re-opens after this many range-finder readings rejected in a row (0: never)
AX_H_REJECTED = 11  # the readings rejected in a row so far (the aux stream's state)
N_AX = 12


@njit(cache=True)
def match_noise(v, i_var, i_c2, i_hph, nu, hph, alpha, floor, ceil):
    """Covariance matching of one accepted scalar innovation ``nu`` (``H P H^T`` = ``hph``) into the noise
    state ``v`` (an anchor's ``RS`` row or a pair's ``TV`` cell): exponentially weighted means (weight
    ``alpha``) of ``nu^2`` (``v[i_c2]``, NaN: none yet, then it starts from the variance in use plus
    ``hph``) and of ``hph`` (``v[i_hph]``), and the variance ``v[i_var] = E[nu^2] - E[H P H^T]`` clipped
    into ``[floor, ceil]`` (Mehra 1972; Mohamed & Schwarz 1999, eq. 20-21; the window of Myers & Tapley
    1976). :func:`fuse_range` floors it at ``RP_VAR_FLOOR``, :func:`fuse_tdoa` at the pair's prior."""
    if np.isfinite(v[i_c2]):
        v[i_c2] += alpha * (nu * nu - v[i_c2])
        v[i_hph] += alpha * (hph - v[i_hph])
    else:
        v[i_c2] = v[i_var] + hph
        v[i_hph] = hph
    v[i_var] = min(max(v[i_c2] - v[i_hph], floor), ceil)


@njit(cache=True)
def robust_init(RS, sigma):
    """Per-anchor robust state at the start of a replay, from the prior sigmas ``sigma`` (M,) [m]."""
    RS[:, :] = 0.0
    for a in range(RS.shape[0]):
        RS[a, RS_VAR] = sigma[a] * sigma[a]
        RS[a, RS_C2] = np.nan
        RS[a, RS_EPREV] = np.nan
        RS[a, RS_NLOS_SINCE] = -np.inf


@njit(cache=True)
def _nlos_cusum(RS, RP, P, a, e, t, i1, w=1.0):
    """Anchor ``a``'s one-sided CUSUM of NLOS (:func:`fuse_range`, item 1) on the normalised innovation
    ``e`` at ``t``, its increment weighted by ``w`` (the innovation's worth of an independent one);
    ``i1`` its offset's error index (re-opened at an offset change). Returns whether the anchor is held out
    now."""
    if t < RS[a, RS_GRACE_UNTIL]:
        RS[a, RS_CUSUM] = 0.0  # re-converging after a recovery: large innovations are the filter's
        return False
    hc = RP[RP_CUSUM_H]
    c = RS[a, RS_CUSUM] + w * (min(e, RP[RP_CUSUM_CLIP]) - RP[RP_CUSUM_K])
    c = min(max(c, 0.0), 2.0 * hc)
    RS[a, RS_CUSUM] = c
    if RS[a, RS_NLOS] > 0.0:
        if c < 0.5 * hc:
            RS[a, RS_NLOS] = 0.0
        elif t - RS[a, RS_NLOS_SINCE] > RP[RP_NLOS_MAX_S]:
            RS[a, RS_NLOS] = 0.0
            RS[a, RS_CUSUM] = 0.0
            RS[a, RS_STEPS] += 1.0
            if i1 >= 0:
                P[i1, i1] += RP[RP_REOPEN_VAR]
    elif c > hc:
        held = 0
        for b in range(RS.shape[0]):
            held += RS[b, RS_NLOS] > 0.0
        if held < RP[RP_NLOS_MAX_HELD]:
            RS[a, RS_NLOS] = 1.0
            RS[a, RS_NLOS_SINCE] = t
            RS[a, RS_EPISODES] += 1.0
    return RS[a, RS_NLOS] > 0.0


@njit(cache=True)
def fuse_range(X, P, PRM, RP, anchor_pos, ridx, a, z, t, RS, work, res):
    """One range ``z`` [m] to anchor ``a`` (position ``anchor_pos``, error-state indices ``ridx[a]`` of its
    range-error terms) through the robust range model; returns the outcome and leaves ``(outcome, d2, nu,
    weight)`` in ``res`` (``weight``: this range's share of an independent one in the window test).

    1. **NLOS** (``RP_NLOS``): a one-sided CUSUM (Page 1954) of the normalised innovation
       ``e = nu / sqrt(S)``,
       ``c <- min(max(0, c + min(e, clip) - k), 2 h)``: NLOS ranges are always long, so a sustained positive
       ``e`` drives ``c`` over ``h`` and the anchor is held out (its ranges rejected, counted) until ``c``
       falls under ``h / 2``; at most ``RP_NLOS_MAX_HELD`` anchors at once (when most anchors disagree, the
       estimate is wrong, not the anchors: that is the divergence test's to say, and held ranges stay out
       of its window, ``weight`` -1). An episode held longer than ``RP_NLOS_MAX_S`` is not NLOS but an
       offset change
       (the take-off step of a real anchor): released, and the anchor's offset variance re-opened so that
       the filter learns the new offset.
    2. **Gate and Huber** as :func:`update_range3`.
    3. **Noise adaptation** (``RP_ADAPT``): covariance matching on the accepted innovations (Mehra 1972;
       Mohamed & Schwarz 1999, eq. 20-21, with an exponentially weighted window as Myers & Tapley 1976):
       ``R = E[nu^2] - E[H P H^T]``, clipped into ``[RP_VAR_FLOOR, RP_VAR_CEIL]``; the prior (the ground
       calibration) is where it starts.
    4. **Effective sample size**: the lag-1 autocorrelation ``rho`` of the anchor's accepted ``e`` (weighted
       means of ``e_k e_{k-1}`` and ``e_k^2``); for jointly Gaussian ``e`` the squares correlate with
       ``rho^2`` (Isserlis), so a range counts as ``(1 - rho^2) / (1 + rho^2)`` independent ones in the
       window's NIS test (the AR(1) effective sample size, Wilks 2011 sec. 5.2.4)."""
    res[0], res[1], res[2], res[3] = REFUSED, 0.0, 0.0, 1.0
    var = RS[a, RS_VAR]
    if not (np.isfinite(z) and z >= 0.0 and np.isfinite(var) and var > 0.0):
        return REFUSED
    i0, i1, i2 = ridx[a, 0], ridx[a, 1], ridx[a, 2]
    h, hph = range_innovation(X, P, anchor_pos, i0, i1, i2, PRM, work)
    nu = z - h
    S = hph + var
    d2 = nu * nu / S
    e = nu / math.sqrt(S)
    res[1], res[2] = d2, nu
    if RP[RP_NLOS] > 0.0 and _nlos_cusum(RS, RP, P, a, e, t, i1):
        RS[a, RS_NLOS_RANGES] += 1.0
        res[0], res[3] = REJECTED, -1.0
        return REJECTED
    if d2 > PRM[PRM_GATE]:
        res[0] = REJECTED
        return REJECTED
    w = 1.0
    if RP[RP_ESS] > 0.0:
        ep = RS[a, RS_EPREV]
        al = RP[RP_ADAPT_ALPHA]
        if np.isfinite(ep):
            RS[a, RS_EE] += al * (e * ep - RS[a, RS_EE])
            RS[a, RS_E2] += al * (d2 - RS[a, RS_E2])
            if RS[a, RS_E2] > 0.0:
                rho = min(max(RS[a, RS_EE] / RS[a, RS_E2], 0.0), 0.95)
                w = (1.0 - rho * rho) / (1.0 + rho * rho)
        else:
            RS[a, RS_E2] = d2
        RS[a, RS_EPREV] = e
    res[3] = w
    r = var
    huber_apply(X, P, work, nu, hph, r, d2, PRM[PRM_HUBER])
    if RP[RP_ADAPT] > 0.0:
        match_noise(
            RS[a], RS_VAR, RS_C2, RS_HPH, nu, hph, RP[RP_ADAPT_ALPHA], RP[RP_VAR_FLOOR], RP[RP_VAR_CEIL]
        )
    res[0] = ACCEPTED
    return ACCEPTED


@njit(cache=True)
def phase_step(X, P, RP, PH, ridx, acc, dt, t):
    """The flight-phase detector on one IMU sample (specific force ``acc`` [m/s^2], ``dt`` [s] since the
    previous one); returns +1 at a take-off, -1 at a landing, 0 otherwise. A change holds for ``RP_DWELL``
    before it is declared (as PX4's land detector's hysteresis).

    **Take-off** (on the ground): the RMS change of the specific force between samples (rotor vibration:
    ~0.01 m/s^2 standing, ~0.1 in flight on a small quadrotor, docs/logs.md; low-passed with
    ``RP_VIB_TAU``) rises over ``RP_VIB_THRESHOLD`` (after a landing only once the rotors stopped,
    ``RP_VIB_RATIO`` under the flight's level: ``PH_ARMED``; rotors spinning on, or cut with a jolt, are not
    a take-off); or the estimated height
    above the ground reference exceeds ``RP_TAKEOFF_HEIGHT``; or the vertical specific force (body specific
    force less the accelerometer bias, turned to nav), low-passed as the vibration, exceeds gravity by
    ``RP_CLIMB_ACCEL``: the vehicle accelerates upward, the one sign of a lift-off a pinned estimate
    (:func:`pin_step`) cannot hide (not in the ``RP_DESCENT_S`` after a change: the contact's jolt).

    **Landing** (airborne): the vibration falls ``RP_VIB_RATIO`` times below its own level in flight
    (``PH_AIR_VIB``, a slow mean taken while airborne: the rotors stopped, whatever the estimate's height);
    or neither take-off sign of the first two holds, if the vibration rose over its threshold in this
    flight (where the rotors spin from the log's first sample it tells nothing); or a **touchdown**: the
    estimate, which descended faster than ``RP_DESCENT_SPEED`` at most ``RP_DESCENT_S`` ago, is within two
    of its sigmas of ``RP_LAND_HEIGHT`` over the ground reference (it may stand on the ground) and its
    vertical speed under ``RP_LAND_SPEED`` (a descent
    stopped near the ground: the IMU's deceleration at the contact is in the estimate's velocity before any
    radio measurement; PX4's land detector tests the vertical velocity the same way). After a touchdown
    the vehicle is pinned (``PH_TOUCH``).

    At a change each anchor's offset variance grows by ``RP_REOPEN_VAR``: the offsets move when the vehicle
    leaves or meets the ground (docs/logs.md), a step a slow random walk cannot follow; so does a
    barometer's offset (``RP_REOPEN_BARO_VAR``). Each body axis' vibration variance is kept too (a slow
    mean, ``PH_VX``..``PH_VZ``) for :func:`vibration_noise`: the lag-1 autocovariance of its deviations
    from its own ``VIB_MEAN_TAU_S`` mean, which a white sensor noise leaves at zero (successive samples
    independent) and the rotors' vibration, sampled many times a cycle, at its power."""
    if RP[RP_PHASES] <= 0.0:
        return 0
    have = PH[PH_HAVE] > 0.0 and dt > 0.0
    g = 0.0
    if have:
        d0, d1, d2 = acc[0] - PH[PH_A0], acc[1] - PH[PH_A1], acc[2] - PH[PH_A2]
        g = 1.0 - math.exp(-dt / RP[RP_VIB_TAU])
        PH[PH_VIB] += g * ((d0 * d0 + d1 * d1 + d2 * d2) / 6.0 - PH[PH_VIB])  # per axis, diff var = 2 s^2
        gs = 1.0 - math.exp(-dt / (10.0 * RP[RP_VIB_TAU]))
        gm = 1.0 - math.exp(-dt / VIB_MEAN_TAU_S)
        for i in range(3):
            PH[PH_M0 + i] += gm * (acc[i] - PH[PH_M0 + i])
            h = acc[i] - PH[PH_M0 + i]
            PH[PH_VX + i] += gs * (h * PH[PH_H0 + i] - PH[PH_VX + i])
            PH[PH_H0 + i] = h
    elif PH[PH_HAVE] <= 0.0:
        PH[PH_M0], PH[PH_M1], PH[PH_M2] = acc[0], acc[1], acc[2]
    PH[PH_A0], PH[PH_A1], PH[PH_A2], PH[PH_HAVE] = acc[0], acc[1], acc[2], 1.0
    _, _, _, _, _, _, r20, r21, r22 = qmat9(X[XQ], X[XQ + 1], X[XQ + 2], X[XQ + 3])
    fz = r20 * (acc[0] - X[XBA]) + r21 * (acc[1] - X[XBA + 1]) + r22 * (acc[2] - X[XBA + 2]) - RP[RP_G_NORM]
    PH[PH_FZ] += g * (fz - PH[PH_FZ])
    if X[XV + 2] < -RP[RP_DESCENT_SPEED]:
        PH[PH_DESC_T] = t
    vib = math.sqrt(PH[PH_VIB])
    now = PH[PH_AIR] > 0.0
    stopped = PH[PH_AIR_VIB] > 0.0 and vib * RP[RP_VIB_RATIO] < math.sqrt(PH[PH_AIR_VIB])
    if not now and vib <= RP[RP_VIB_THRESHOLD] and (stopped or PH[PH_AIR_VIB] <= 0.0):
        PH[PH_ARMED] = 1.0
    height = X[XP + 2] - RP[RP_GROUND_Z]
    hmin = RP[RP_TAKEOFF_HEIGHT]
    high = hmin > 0.0 and height > hmin
    shaking = vib > RP[RP_VIB_THRESHOLD]
    if now and shaking:
        PH[PH_VIB_AIR_SEEN] = 1.0
    if now:  # quiet and low lands only where the vibration told the flight from the ground
        air = shaking or high or PH[PH_VIB_AIR_SEEN] <= 0.0
    else:
        air = (shaking and PH[PH_ARMED] > 0.0) or high
        if (
            RP[RP_CLIMB_ACCEL] > 0.0
            and PH[PH_FZ] > RP[RP_CLIMB_ACCEL]
            and t - PH[PH_CHANGE_T] > RP[RP_DESCENT_S]  # not the contact's own jolt
        ):
            air = True
    touch = False
    sz = math.sqrt(max(P[EP + 2, EP + 2], 0.0))
    low = RP[RP_LAND_HEIGHT] > 0.0 and height - 2.0 * sz < RP[RP_LAND_HEIGHT]
    landing = t - PH[PH_DESC_T] <= RP[RP_DESCENT_S]
    PH[PH_NEAR] = 1.0 if now and low and (landing or t - PH[PH_CHANGE_T] <= RP[RP_DESCENT_S]) else 0.0
    if now and low and landing:
        touch = abs(X[XV + 2]) < RP[RP_LAND_SPEED]
    if touch:
        air = False
    if stopped:
        air = False  # the rotors stopped (after a flight): whatever the estimate's height says
    elif now and dt > 0.0:
        PH[PH_AIR_VIB] += (1.0 - math.exp(-dt / (10.0 * RP[RP_VIB_TAU]))) * (PH[PH_VIB] - PH[PH_AIR_VIB])
    if air == now:
        PH[PH_SINCE] = -1.0
        return 0
    if PH[PH_SINCE] < 0.0:
        PH[PH_SINCE] = t
        return 0
    if t - PH[PH_SINCE] < RP[RP_DWELL]:
        return 0
    PH[PH_AIR] = 1.0 if air else 0.0
    PH[PH_SINCE] = -1.0
    PH[PH_PINNED] = 0.0 if air else 1.0
    PH[PH_TOUCH] = 2.0 if touch else 0.0
    PH[PH_CHANGE_T] = t
    PH[PH_FZ] = 0.0
    PH[PH_ARMED] = 0.0  # after a landing, a take-off by the vibration needs the rotors to stop first
    if air:
        PH[PH_AIR_VIB] = PH[PH_VIB]  # the flight's level starts from the take-off's
        PH[PH_VIB_AIR_SEEN] = 1.0 if shaking else 0.0
    for a in range(ridx.shape[0]):
        i1 = ridx[a, 1]
        if i1 >= 0:
            P[i1, i1] += RP[RP_REOPEN_VAR]
    ib = int(RP[RP_BARO_INDEX])
    if ib >= 0:  # the rotors' downwash moves a barometer's reading at take-off as much as a metre
        P[ib, ib] += RP[RP_REOPEN_BARO_VAR]
    return 1 if air else -1


@njit(cache=True)
def in_window(PH):
    """Whether a gated sample enters the divergence test's window: not while the vehicle stands on the
    ground (``PH_PINNED``: measurements that disagree there are bad, not the estimate), nor while a phase
    change waits out its dwell, nor near the ground on the way down or just after the take-off
    (``PH_NEAR``): there the radio goes bad (the UTIL TDoA logs: 0.4-0.6 m off under 0.2 m of height, ~3 m
    on the ground), and the recovery would open the covariance to it."""
    return PH[PH_PINNED] == 0.0 and PH[PH_SINCE] < 0.0 and PH[PH_NEAR] == 0.0


@njit(cache=True)
def pin_step(X, P, RP, PH, t, work):
    """While the vehicle stands on the ground where it is known to stand (``PH_PINNED`` and ``PH_TOUCH``: 1
    on its known pad before the take-off, 2 after a touchdown), at most every ``RP_PIN_PERIOD``: zero
    velocity (variance ``RP_PIN_VEL_VAR`` per axis) and, after a touchdown, the height of the ground
    reference (``RP_PIN_Z_VAR``; 0: not used; on the pad the estimate starts at its surveyed height) as
    scalar pseudo-measurements. A zero-velocity update (Foxlin 2005, the pedestrian ZUPT; PX4's EKF2
    fuses a zero velocity when landed without aiding): a vehicle standing cannot move, so the IMU's errors
    and the biases are observed, and the covariance stays as tight as the pad is known, which holds the
    radio measurements that disagree out at the gate. The height: a touchdown is declared only near the
    ground reference's height (:func:`phase_step`), and the vehicle stands on that ground. Not while a
    take-off waits out its dwell or the vertical specific force says it climbs."""
    if RP[RP_PIN_VEL_VAR] <= 0.0 or PH[PH_PINNED] <= 0.0 or PH[PH_TOUCH] <= 0.0:
        return
    if PH[PH_SINCE] >= 0.0 or (RP[RP_CLIMB_ACCEL] > 0.0 and PH[PH_FZ] > RP[RP_CLIMB_ACCEL]):
        return  # a take-off may be under way: the IMU alone says how far it went
    if t - PH[PH_PIN_T] < RP[RP_PIN_PERIOD]:
        return
    PH[PH_PIN_T] = t
    n = P.shape[0]
    b = work[1]
    for k in range(4):
        if k < 3:
            idx, nu, var = EV + k, -X[XV + k], RP[RP_PIN_VEL_VAR]
        else:
            idx, nu, var = EP + 2, RP[RP_GROUND_Z] - X[XP + 2], RP[RP_PIN_Z_VAR]
            if var <= 0.0 or PH[PH_TOUCH] < 2.0:
                break
        for i in range(n):
            b[i] = P[i, idx]
        apply_scalar(X, P, work, nu, P[idx, idx] + var)


@njit(cache=True)
def predict_step(X, P, gyro, acc, dt, PRM, RP, PH):
    """:func:`predict_one` and the vibration's accelerometer noise (:func:`vibration_noise`) over ``dt``: the
    prediction of the replay loop, its vision pauses and the live navigator. Returns predict_one's."""
    ok = predict_one(X, P, gyro, acc, dt, PRM)
    if ok:
        vibration_noise(X, P, RP, PH, dt)
    return ok


@njit(cache=True)
def vibration_noise(X, P, RP, PH, dt):
    """The accelerometer noise the rotors' vibration adds over ``dt`` [s]: per body axis a white density of
    ``RP_VIB_ACCEL_K`` times that axis' vibration power (``PH_VX``..``PH_VZ``, :func:`phase_step`), turned to
    nav, ``R diag(q) R^T dt`` on the velocity block (``Q_i``'s ``V_i`` of Sola
    2017 sec. 5.4.3, per axis). A vibrating MEMS accelerometer does not average its vibration out: the
    rectified part (clipping, its nonlinearity: IEEE Std 1293-1998 annex, vibration rectification) is a slow
    error that grows with the vibration's power (measured on the development TDoA flights, docs/logs.md)."""
    k = RP[RP_VIB_ACCEL_K]
    if k <= 0.0 or dt <= 0.0:
        return
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = qmat9(X[XQ], X[XQ + 1], X[XQ + 2], X[XQ + 3])
    k2 = k * k * dt
    v0, v1, v2 = max(PH[PH_VX], 0.0), max(PH[PH_VY], 0.0), max(PH[PH_VZ], 0.0)
    q0, q1, q2 = k2 * v0 * v0, k2 * v1 * v1, k2 * v2 * v2
    P[EV, EV] += r00 * r00 * q0 + r01 * r01 * q1 + r02 * r02 * q2
    P[EV + 1, EV + 1] += r10 * r10 * q0 + r11 * r11 * q1 + r12 * r12 * q2
    P[EV + 2, EV + 2] += r20 * r20 * q0 + r21 * r21 * q1 + r22 * r22 * q2
    c01 = r00 * r10 * q0 + r01 * r11 * q1 + r02 * r12 * q2
    c02 = r00 * r20 * q0 + r01 * r21 * q1 + r02 * r22 * q2
    c12 = r10 * r20 * q0 + r11 * r21 * q1 + r12 * r22 * q2
    P[EV, EV + 1] += c01
    P[EV + 1, EV] += c01
    P[EV, EV + 2] += c02
    P[EV + 2, EV] += c02
    P[EV + 1, EV + 2] += c12
    P[EV + 2, EV + 1] += c12


@njit(cache=True)
def fuse_aux(X, P, AX, kind, z, res):
    """One height sample: ``AUX_HEIGHT`` a downward rangefinder's distance ``z`` [m]
    (:func:`update_height_one`, refused beyond ``AX_H_MAX`` or past the tilt limit), ``AUX_BARO`` a
    barometric height ``z`` [m] with its offset state: ``h = p_z + b_baro`` (``AX_B_INDEX``). Gated on the
    squared Mahalanobis distance; returns the outcome (``res``: outcome, d2).

    A range finder rejected ``AX_H_RESET_N`` times in a row re-opens the height: its variance grows by the
    squared height difference the reading implies, and that reading is fused. A 2 cm sensor that keeps
    disagreeing says the height is wrong, not itself: the gate otherwise locks it out while the
    estimate is a few of its sigmas off (a take-off the pin on the pad held down: the UTIL flights 0425
    traj10, 11, 16, 17 lagged 0.3-0.6 m for 1.5 s). PX4's EKF2 likewise resets its height to the height
    source whose fusion has timed out (``height_control.cpp``)."""
    res[0], res[1] = REFUSED, 0.0
    if not np.isfinite(z):
        return REFUSED
    if kind == AUX_HEIGHT:
        if AX[AX_H_ON] <= 0.0 or z < 0.0 or z > AX[AX_H_MAX]:
            return REFUSED
        out = update_height_one(X, P, AX[AX_H_GROUND], z, AX[AX_H_SIGMA], AX[AX_H_COS], AX[AX_H_GATE], res)
        if out != REJECTED:
            if out == ACCEPTED:
                AX[AX_H_REJECTED] = 0.0
            return out
        AX[AX_H_REJECTED] += 1.0
        if AX[AX_H_RESET_N] <= 0.0 or AX[AX_H_REJECTED] < AX[AX_H_RESET_N]:
            return out
        r22 = qmat9(X[XQ], X[XQ + 1], X[XQ + 2], X[XQ + 3])[8]
        dz = z * r22 - (X[XP + 2] - AX[AX_H_GROUND])  # the height the reading says, less the estimate's
        P[EP + 2, EP + 2] += dz * dz
        AX[AX_H_REJECTED] = 0.0
        return update_height_one(X, P, AX[AX_H_GROUND], z, AX[AX_H_SIGMA], AX[AX_H_COS], AX[AX_H_GATE], res)
    ib = int(AX[AX_B_INDEX])
    if AX[AX_B_ON] <= 0.0 or ib < 0:
        return REFUSED
    n = P.shape[0]
    H = np.zeros((1, n))
    H[0, EP + 2] = 1.0
    H[0, ib] = 1.0
    nu = np.empty(1)
    nu[0] = z - (X[XP + 2] + X[XRB + ib - ERB])
    R_meas = np.empty((1, 1))
    R_meas[0, 0] = AX[AX_B_SIGMA] ** 2
    return _vector_update(X, P, H, nu, R_meas, AX[AX_B_GATE], res)


@njit(cache=True)
def replay(
    X, P, PRM, tf, t_stop, imu_t, imu_gyro, imu_acc, rng_t, rng_anchor, rng_z, anchors, ridx, RS, RP,
    aux_t, aux_kind, aux_z, AX, aux_outcome, PH, phase_t, phase_air,
    tdoa_t, tdoa_a, tdoa_b, tdoa_z, TV, tdoa_counts, tdoa_d2, tdoa_outcome,
    ST, counts, win_rej, win_d2, win_w, win_all, nis_limit, reject_share_max, last_range, last_range_t,
    out_every, out_t, out_X, out_P, nis_t, nis_anchor, nis_d2, nis_outcome,
):  # fmt: skip
    """Run the filter over a log from the cursors in ``ST`` until its end (returns ``EV_DONE``), a divergence
    (``EV_DIVERGED``, the cursors left after the range that declared it, for the caller to recover and call
    again) or the first sample after ``t_stop`` (``EV_PAUSE``). Samples are processed in time order (at one
    time: IMU, range, TDoA, then height samples); an IMU sample is held over the interval that follows it
    (zero-order hold), so the filter predicts to each sample's own time stamp. Ranges go through
    :func:`fuse_range`, distance differences through :func:`fuse_tdoa` (white noise per pair in ``TV`` (M, M,
    N_TV), the per-anchor NLOS and correlation state in ``RS``; outcomes per anchor pair in ``tdoa_counts``
    (M, M, 3); they enter the divergence window as ranges do), heights through :func:`fuse_aux`, and each IMU
    sample through the phase detector (:func:`phase_step`; a change is written to ``phase_t``/``phase_air``: 1
    a take-off, 0 a landing, -1 a touchdown) and the pin (:func:`pin_step`); each prediction adds the
    vibration's accelerometer noise (:func:`predict_step`). While the vehicle stands on the ground
    (``PH_PINNED``: on its known pad before its first take-off, or where it landed) or a phase change waits
    out its dwell, gated samples stay out of the divergence window (:func:`in_window`): it stands still, so
    measurements that disagree are bad (a tag on the ground, a TDoA engine not yet in sync), not the
    estimate."""
    n_imu, n_rng, n_aux, n_td = imu_t.shape[0], rng_t.shape[0], aux_t.shape[0], tdoa_t.shape[0]
    n = P.shape[0]
    work = np.empty((3, n))
    res = np.empty(4)
    tcur = tf[0]
    while ST[ST_I_IMU] < n_imu or ST[ST_I_RNG] < n_rng or ST[ST_I_AUX] < n_aux or ST[ST_I_TDOA] < n_td:
        i, j, q, u = ST[ST_I_IMU], ST[ST_I_RNG], ST[ST_I_AUX], ST[ST_I_TDOA]
        kind = 0
        t = imu_t[i] if i < n_imu else np.inf
        if j < n_rng and rng_t[j] < t:
            kind, t = 1, rng_t[j]
        if u < n_td and tdoa_t[u] < t:
            kind, t = 3, tdoa_t[u]
        if q < n_aux and aux_t[q] < t:
            kind, t = 2, aux_t[q]
        if t > t_stop:
            tf[0] = tcur
            return EV_PAUSE
        if t < tcur:  # older than the filter: dropped, counted
            ST[ST_DROPPED] += 1
            if kind == 0:
                ST[ST_I_IMU] += 1
            elif kind == 1:
                ST[ST_I_RNG] += 1
            elif kind == 3:
                ST[ST_I_TDOA] += 1
            else:
                ST[ST_I_AUX] += 1
            continue
        dt = t - tcur
        if ST[ST_HELD] >= 0:
            h = ST[ST_HELD]
            if not predict_step(X, P, imu_gyro[h], imu_acc[h], dt, PRM, RP, PH):
                ST[ST_IMU_REFUSED] += 1
        tcur = t
        if kind == 0:
            h_prev = ST[ST_HELD]
            ST[ST_HELD] = i
            ST[ST_I_IMU] += 1
            ch = phase_step(
                X, P, RP, PH, ridx, imu_acc[i], imu_t[i] - imu_t[h_prev] if h_prev >= 0 else 0.0, t
            )
            if ch != 0 and ST[ST_N_PHASE] < phase_t.shape[0]:
                phase_t[ST[ST_N_PHASE]] = t
                phase_air[ST[ST_N_PHASE]] = 1 if ch > 0 else (-1 if PH[PH_TOUCH] > 0.0 else 0)
                ST[ST_N_PHASE] += 1
            pin_step(X, P, RP, PH, t, work)
            if i % out_every == 0 and ST[ST_I_OUT] < out_t.shape[0]:
                o = ST[ST_I_OUT]
                out_t[o] = t
                out_X[o, :] = X
                for a in range(9):
                    for b in range(9):
                        out_P[o, a, b] = P[a, b]
                ST[ST_I_OUT] += 1
            continue
        if kind == 2:
            ST[ST_I_AUX] += 1
            aux_outcome[q] = fuse_aux(X, P, AX, aux_kind[q], aux_z[q], res)
            continue
        if kind == 3:
            ST[ST_I_TDOA] += 1
            a, b = tdoa_a[u], tdoa_b[u]
            pinned = PH[PH_PINNED] > 0.0 and PH[PH_TOUCH] > 0.0
            outcome = fuse_tdoa(X, P, PRM, RP, anchors, ridx, a, b, tdoa_z[u], t, TV, RS, work, res, pinned)
            tdoa_d2[u], tdoa_outcome[u] = res[1], outcome
            tdoa_counts[a, b, outcome] += 1
            if window_gated(PH, res, win_rej, win_d2, win_w, win_all, ST, nis_limit, reject_share_max):
                tf[0] = tcur
                return EV_DIVERGED
            continue
        ST[ST_I_RNG] += 1
        a = rng_anchor[j]
        outcome = fuse_range(X, P, PRM, RP, anchors[a], ridx, a, rng_z[j], t, RS, work, res)
        nis_t[j], nis_anchor[j], nis_d2[j], nis_outcome[j] = t, a, res[1], outcome
        counts[a, outcome] += 1
        if outcome == REFUSED:
            continue
        if PH[PH_AIR] > 0.0:
            RS[a, RS_AIR_VAR_SUM] += RS[a, RS_VAR]
            RS[a, RS_AIR_N] += 1.0
        last_range[a], last_range_t[a] = rng_z[j], t
        if window_gated(PH, res, win_rej, win_d2, win_w, win_all, ST, nis_limit, reject_share_max):
            tf[0] = tcur
            return EV_DIVERGED
    tf[0] = tcur
    return EV_DONE


@njit(cache=True)
def window_push(win_rej, win_d2, win_w, win_all, ST, outcome, d2, nu, w, nis_limit, reject_share_max):
    """One gated range (``outcome`` accepted or rejected, squared distance ``d2``, innovation ``nu`` [m] (its
    square kept in ``win_all`` for the recovery), worth ``w`` independent ranges) into the divergence test's
    window (cursors in ``ST``); True if the full window now declares the
    filter inconsistent: the share rejected above ``reject_share_max``, or the mean NIS of the accepted ones
    above ``nis_limit[n_eff]``, ``n_eff`` the accepted ranges' summed weights rounded down (correlated
    innovations carry less evidence than independent ones, so the limit of fewer is wider). Shared by
    :func:`replay` and the live navigator (:mod:`swarm.logs.online`), so both decide alike."""
    W = win_rej.shape[0]
    pos = ST[ST_WIN_POS]
    win_rej[pos] = 1.0 if outcome == REJECTED else 0.0
    win_d2[pos] = d2 if outcome == ACCEPTED else 0.0
    win_w[pos] = w if outcome == ACCEPTED else 0.0
    win_all[pos] = nu * nu
    ST[ST_WIN_POS] = (pos + 1) % W
    if ST[ST_WIN_FILL] < W:
        ST[ST_WIN_FILL] += 1
    if ST[ST_WIN_FILL] < W:
        return False
    rej = 0.0
    s = 0.0
    sw = 0.0
    for k in range(W):
        rej += win_rej[k]
        s += win_d2[k]
        sw += win_w[k]
    n_acc = W - int(rej)
    n_eff = min(max(int(sw + 1e-9), 1), n_acc) if n_acc > 0 else 0
    return rej / W > reject_share_max or (n_acc > 0 and s / n_acc > nis_limit[n_eff])


@njit(cache=True)
def window_gated(PH, res, win_rej, win_d2, win_w, win_all, ST, nis_limit, reject_share_max):
    """The outcome that :func:`fuse_range` or :func:`fuse_tdoa` left in ``res`` into the divergence window
    (:func:`window_push`) when it counts: not refused, not held out (weight -1), in the phase the window
    watches (:func:`in_window`). True if the window now declares the filter inconsistent. Shared by
    :func:`replay` and the live navigator."""
    if res[0] == REFUSED or res[3] < 0.0 or not in_window(PH):
        return False
    return window_push(
        win_rej, win_d2, win_w, win_all, ST, int(res[0]), res[1], res[2], res[3], nis_limit, reject_share_max
    )


# ------------------------------------------------------------------------------------------- batches


@njit(cache=True)
def predict_batch(X, P, gyro, acc, dt, PRM, refused):
    """:func:`predict_one` on every filter of the batch (``gyro``, ``acc`` (n, 3)); counts refusals."""
    for i in range(X.shape[0]):
        if not predict_one(X[i], P[i], gyro[i], acc[i], dt, PRM):
            refused[0] += 1


@njit(cache=True)
def update_range_batch(X, P, anchor, idx3, z, sigma, PRM, work, res, out, d2):
    """:func:`update_range3` (range-error terms ``idx3`` (3,)) on every filter of the batch (``z`` (n,)):
    outcomes and squared distances."""
    for i in range(X.shape[0]):
        out[i] = update_range3(X[i], P[i], anchor, idx3[0], idx3[1], idx3[2], z[i], sigma, PRM, work, res)
        d2[i] = res[1]


# ------------------------------------------------------------------------------------ pad-relative vision


@njit(cache=True)
def pad_row(X, p_pad, cam_pos, R_bc, H):
    """The pad origin in the camera frame, ``t = R_bc^T (R(q)^T (p_pad - p) - c)``, and its Jacobian ``H``
    (3, N) with respect to the error state: ``-R_bc^T R^T`` on ``dp`` and ``R_bc^T [R^T (p_pad - p)]x`` on
    ``dtheta`` (from ``R(q exp(dtheta))^T = (I - [dtheta]x) R^T``)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = qmat9(X[XQ], X[XQ + 1], X[XQ + 2], X[XQ + 3])
    d0, d1, d2 = p_pad[0] - X[XP], p_pad[1] - X[XP + 1], p_pad[2] - X[XP + 2]
    b0 = r00 * d0 + r10 * d1 + r20 * d2  # R^T d: the pad from the centre of mass, body frame
    b1 = r01 * d0 + r11 * d1 + r21 * d2
    b2 = r02 * d0 + r12 * d1 + r22 * d2
    e0, e1, e2 = b0 - cam_pos[0], b1 - cam_pos[1], b2 - cam_pos[2]
    t = np.empty(3)
    H[:, :] = 0.0
    for i in range(3):
        t[i] = R_bc[0, i] * e0 + R_bc[1, i] * e1 + R_bc[2, i] * e2
        # -R_bc^T R^T on dp: row i of R_bc^T times R^T
        H[i, EP + 0] = -(R_bc[0, i] * r00 + R_bc[1, i] * r01 + R_bc[2, i] * r02)
        H[i, EP + 1] = -(R_bc[0, i] * r10 + R_bc[1, i] * r11 + R_bc[2, i] * r12)
        H[i, EP + 2] = -(R_bc[0, i] * r20 + R_bc[1, i] * r21 + R_bc[2, i] * r22)
        # R_bc^T [b]x on dtheta: [b]x = [[0, -b2, b1], [b2, 0, -b0], [-b1, b0, 0]]
        H[i, ETH + 0] = R_bc[1, i] * b2 - R_bc[2, i] * b1
        H[i, ETH + 1] = -R_bc[0, i] * b2 + R_bc[2, i] * b0
        H[i, ETH + 2] = R_bc[0, i] * b1 - R_bc[1, i] * b0
    return t


@njit(cache=True)
def _vector_update(X, P, H, nu, R_meas, gate, out):
    """A vector measurement's update, shared by the pad and position fixes: innovation ``nu`` with Jacobian
    ``H`` and noise ``R_meas``, gated on its squared Mahalanobis distance, then the Joseph form and the
    injection. ``out[1]`` receives the distance; returns the outcome (also ``out[0]``). A non-finite
    measurement (so a non-finite innovation) is refused with distance 0."""
    out[1] = 0.0
    for i in range(nu.shape[0]):
        if not np.isfinite(nu[i]):
            out[0] = REFUSED
            return REFUSED
    n = P.shape[0]
    PHt = P @ H.T
    S = H @ PHt + R_meas
    d2 = nu @ np.linalg.solve(S, nu)
    out[1] = d2
    if not (np.isfinite(d2) and d2 >= 0.0):
        out[0] = REFUSED
        return REFUSED
    if d2 > gate:
        out[0] = REJECTED
        return REJECTED
    K = np.linalg.solve(S, PHt.T).T
    A = np.eye(n) - K @ H
    Pn = A @ P @ A.T + K @ R_meas @ K.T
    P[:, :] = 0.5 * (Pn + Pn.T)
    inject(X, P, K @ nu)
    out[0] = ACCEPTED
    return ACCEPTED


@njit(cache=True)
def update_pad_one(X, P, p_pad, cam_pos, R_bc, t_meas, R_meas, gate, out):
    """The pad's position in the camera frame ``t_meas`` (3,) with covariance ``R_meas`` (3, 3) (the
    translation block of the PnP covariance, :mod:`swarm.core.pad_vision`), of a pad surveyed at ``p_pad``
    in nav: gated on the squared Mahalanobis distance (``gate``, chi-square(3)), then a Kalman update with
    the Joseph form. ``out`` receives ``(outcome, d2)``; returns the outcome."""
    n = P.shape[0]
    H = np.zeros((3, n))
    h = pad_row(X, p_pad, cam_pos, R_bc, H)
    nu = t_meas - h
    return _vector_update(X, P, H, nu, R_meas, gate, out)


@njit(cache=True)
def update_position_one(X, P, z, R_meas, gate, out):
    """A position fix ``z`` (3,) [m, nav] with covariance ``R_meas`` (3, 3) (a GNSS receiver): gated on its
    squared Mahalanobis distance, then a Joseph-form update. ``out`` receives ``(outcome, d2)``."""
    n = P.shape[0]
    H = np.zeros((3, n))
    for i in range(3):
        H[i, EP + i] = 1.0
    nu = z - X[XP : XP + 3]
    return _vector_update(X, P, H, nu, R_meas, gate, out)


# ------------------------------------------------------------------------------------- downward rangefinder


@njit(cache=True)
def height_row(X, ground_z, H):
    """A downward rangefinder's distance from the body origin along body ``-z`` to flat ground at height
    ``ground_z``, ``h = (p_z - ground_z) / R_22`` with ``R_22 = e_z^T R(q) e_z`` (the cosine of the tilt),
    and its Jacobian ``H`` (1, N): ``1 / R_22`` on ``dp_z`` and, from ``R(q exp(dtheta)) e_z = R (e_z +
    dtheta x e_z)``, ``dR_22 = (e_z x a) . dtheta`` with ``a = R^T e_z``, so ``(h / R_22) (a_1, -a_0, 0)`` on
    ``dtheta``."""
    _, _, _, _, _, _, r20, r21, r22 = qmat9(X[XQ], X[XQ + 1], X[XQ + 2], X[XQ + 3])
    dz = X[XP + 2] - ground_z
    h = dz / r22
    H[:, :] = 0.0
    H[0, EP + 2] = 1.0 / r22
    H[0, ETH + 0] = h / r22 * r21
    H[0, ETH + 1] = -h / r22 * r20
    return h


@njit(cache=True)
def update_height_one(X, P, ground_z, z, sigma, min_cos_tilt, gate, out):
    """A rangefinder's distance ``z`` [m] with white noise ``sigma`` [m] (:func:`height_row`): refused when
    the estimated tilt's cosine is below ``min_cos_tilt`` (the beam misses the modelled ground), else gated
    on its squared Mahalanobis distance (``gate``, chi-square(1)) and a Joseph-form update. ``out`` receives
    ``(outcome, d2)``."""
    r22 = qmat9(X[XQ], X[XQ + 1], X[XQ + 2], X[XQ + 3])[8]
    if not r22 >= min_cos_tilt:
        out[0], out[1] = REFUSED, 0.0
        return REFUSED
    n = P.shape[0]
    H = np.zeros((1, n))
    h = height_row(X, ground_z, H)
    nu = np.empty(1)
    nu[0] = z - h
    R_meas = np.empty((1, 1))
    R_meas[0, 0] = sigma * sigma
    return _vector_update(X, P, H, nu, R_meas, gate, out)
