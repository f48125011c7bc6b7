"""Compiled kernels of the multiplicative EKF (paper section IV), one filter per call of ``*_one``.

The public API is :class:`swarm.core.estimator.PoseEstimator`; this module is its inner loop. Each
``*_batch`` kernel loops over a leading batch axis and calls the same ``*_one`` code, so a batch of one
and a batch of a thousand give bit-identical results per filter.

Array layout of one filter (all float64 unless said otherwise):

``X`` (10,)
    ``[p_nav(3), v_nav(3), q_nav_body(4)]``: centre-of-mass position [m] and velocity [m/s] in the mothership
    frame ``c`` and the reference attitude quaternion, scalar-last (x, y, z, w), Hamilton product, mapping
    body vectors into ``c``.
``P`` (9, 9)
    Covariance of the error state ``zeta = (d_p, d_v, d_theta)`` (paper eq. 4); ``d_theta`` is the
    body-frame rotation vector with ``q_true = q_ref (x) exp(d_theta)``, the Hamilton-product form of
    Markley 2003's ``dq = q (x) q_ref^-1`` (Shuster product). For the tandem structure the cross blocks
    between translation and attitude are identically zero.
``ST_I`` (3, N_TYPES) int64
    Counters per measurement type: row ``COUNT_ACCEPTED``, ``COUNT_REJECTED`` (Mahalanobis gate),
    ``COUNT_REFUSED`` (non-finite or invalid input).
``ST_F`` (N_STF,) (the tail, from ``STF_WORK``, is scratch space)
    ``[since_update_s, underweight_left, last_d2[N_TYPES]...]`` book-keeping.

Parameter vector ``PRM`` (N_PRM,): see the ``PRM_*`` indices.

Range-error model (optional; ``PRM`` extended to ``N_PRM_RE``, see ``PRM_RE_*``): the filter then also
estimates, past the 9 core error states and in this order, a range offset common to every anchor, one offset
per anchor and one first-order Gauss-Markov term per anchor (each part present or not), so that
``range = ||p + R(q) P1 - a_j|| + c + b_j + g_j + v``. ``X`` grows to ``10 + M`` (nominal value of extra
error state ``9 + k`` at ``X[10 + k]``) and ``P`` to ``9 + M``. This is the state augmentation of
correlated measurement errors (Maybeck 1979, *Stochastic Models, Estimation and Control* vol. 1, sec. 6.7;
Groves 2013, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed.,
sec. 3.4.2 for the Gauss-Markov process and its exact discrete form), the same model as the IMU-driven filter
(:mod:`swarm.core._imu_nb`). Tandem: the extra states belong to the translation filter (the range depends on
them and on position), with full cross-covariance to position and velocity; the attitude filter is unchanged.
Without the extension (``M = 0``) every kernel runs the arithmetic of before, unchanged.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from swarm.core._rot_nb import _LOG_TAYLOR_THRESHOLD as _QLOG_TAYLOR
from swarm.core._rot_nb import qconj, qexp, qexp3, qlog, qmat, qmat9, qmul, qnormalize, skew3

# Measurement types (columns of the counters).
TYPE_RANGE = 0
TYPE_FEATURES = 1
TYPE_POSE = 2
TYPE_ATTITUDE = 3
TYPE_PREDICT = 4
N_TYPES = 5

COUNT_ACCEPTED = 0
COUNT_REJECTED = 1
COUNT_REFUSED = 2

# Status codes returned per filter.
ST_ACCEPTED = 0
ST_REJECTED = 1
ST_REFUSED_NONFINITE = 2
ST_REFUSED_INVALID = 3
ST_SKIPPED = 4

# Parameter vector layout.
PRM_TANDEM = 0  # 1.0 for the tandem structure, 0.0 for compounded
PRM_ACCEL_PSD = 1  # white-acceleration power spectral density [m^2/s^3]
PRM_ATT_PSD = 2  # attitude random-walk PSD (gyro ARW^2 + unmodelled bias) [rad^2/s]
PRM_UW_BETA = 3  # underweighting factor beta (Zanetti et al. 2010); 0 disables
PRM_UW_GAP_S = 4  # a prediction span at least this long arms underweighting [s]
PRM_UW_COUNT = 5  # number of accepted updates underweighted after such a span
PRM_UW_RATIO = 6  # underweight only while tr(H P H^T) > ratio * tr(R)
PRM_LEVER = 7  # 7:10 UWB tag lever arm P1 in the body frame [m]
N_PRM = 10
# range-error model extension (present when len(PRM) == N_PRM_RE)
PRM_RE_ANCHORS = 10  # number of anchors A
PRM_RE_COMMON = 11  # 1.0: one range offset common to every anchor (a tag's antenna delay)
PRM_RE_OFFSET = 12  # 1.0: one range offset per anchor (an anchor's antenna delay, a fixed multipath)
PRM_RE_GM = 13  # 1.0: one first-order Gauss-Markov term per anchor (slow multipath)
PRM_RE_COMMON_RW = 14  # the common offset's random walk density [m/sqrt(s)]
PRM_RE_OFFSET_RW = 15  # each anchor offset's random walk density [m/sqrt(s)]
PRM_RE_GM_SIGMA = 16  # the Gauss-Markov term's stationary standard deviation [m]
PRM_RE_GM_TAU = 17  # its correlation time [s]
N_PRM_RE = 18

STF_SINCE = 0
STF_UW_LEFT = 1
STF_D2 = 2  # 2 : 2 + N_TYPES, squared Mahalanobis distance of the last gated update per type
STF_WORK = 2 + N_TYPES  # 27 floats of scratch for the scalar update: no allocation per range
N_STF = STF_WORK + 27


@njit(cache=True)
def _all_finite(a):
    for v in a.ravel():
        if not np.isfinite(v):
            return False
    return True


@njit(cache=True)
def _finite3(a):
    """``_all_finite`` for a 3-vector, without ``ravel`` (~4x cheaper on the per-step path)."""
    return np.isfinite(a[0]) and np.isfinite(a[1]) and np.isfinite(a[2])


@njit(cache=True)
def _sandwich(F, P):
    """F P F^T for small dense matrices (explicit loops: no BLAS call overhead)."""
    n = F.shape[0]
    FP = np.zeros((n, n))
    for i in range(n):
        for k in range(n):
            f = F[i, k]
            if f != 0.0:
                for j in range(n):
                    FP[i, j] += f * P[k, j]
    out = np.zeros((n, n))
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for k in range(n):
                s += FP[i, k] * F[j, k]
            out[i, j] = s
            out[j, i] = s
    return out


@njit(cache=True)
def re_index(PRM, j):
    """Error-state indices ``(common, offset, gm)`` of anchor ``j``'s range-error terms (-1: a part absent,
    or ``j`` outside ``[0, A)``; the common offset does not depend on ``j``)."""
    ic, io, ig = -1, -1, -1
    if PRM.shape[0] < N_PRM_RE:
        return ic, io, ig
    a = int(PRM[PRM_RE_ANCHORS])
    k = 9
    if PRM[PRM_RE_COMMON] != 0.0:
        ic = k
        k += 1
    if PRM[PRM_RE_OFFSET] != 0.0:
        if 0 <= j < a:
            io = k + j
        k += a
    if PRM[PRM_RE_GM] != 0.0 and 0 <= j < a:
        ig = k + j
    return ic, io, ig


@njit(cache=True)
def re_transition(PRM, k, dt):
    """``(phi, q)`` of extra error state ``k`` (index ``>= 9``) over ``dt`` [s]: ``x <- phi x + w``,
    ``w ~ N(0, q)``. A random walk of density ``s``: ``phi = 1``, ``q = s^2 dt``; a first-order Gauss-Markov
    process of stationary sigma ``s`` and correlation time ``tau``: the exact discrete form
    ``phi = exp(-dt / tau)``, ``q = s^2 (1 - phi^2)`` (Groves 2013 sec. 3.4.2; Maybeck 1979 sec. 4.11)."""
    a = int(PRM[PRM_RE_ANCHORS])
    i = k - 9
    if PRM[PRM_RE_COMMON] != 0.0:
        if i == 0:
            return 1.0, PRM[PRM_RE_COMMON_RW] ** 2 * dt
        i -= 1
    if PRM[PRM_RE_OFFSET] != 0.0:
        if i < a:
            return 1.0, PRM[PRM_RE_OFFSET_RW] ** 2 * dt
        i -= a
    phi = np.exp(-dt / PRM[PRM_RE_GM_TAU])
    return phi, PRM[PRM_RE_GM_SIGMA] ** 2 * (1.0 - phi * phi)


@njit(cache=True)
def _predict_extra(X, P, PRM, dt, f00, f01, f02, f10, f11, f12, f20, f21, f22):
    """The extra states' share of the prediction: their nominal values ``x <- phi x``, and of
    ``P <- F P F^T + Q`` (``F`` block-diagonal: the core's and
    ``diag(phi)``), after the core blocks: the cross block with position and velocity picks up
    ``dt`` times the velocity rows, compounded also the attitude rows turn by ``Phi``; every extra column
    scales by its ``phi``, the extra block by ``phi_a phi_b``, plus ``q`` on its diagonal."""
    n = P.shape[0]
    tandem = PRM[PRM_TANDEM] != 0.0
    for c in range(9, n):
        phi, _ = re_transition(PRM, c, dt)
        X[c + 1] *= phi  # the nominal value follows the same model (a Gauss-Markov term decays to zero)
        for i in range(3):
            P[i, c] += dt * P[3 + i, c]
        if not tandem:
            c0, c1, c2 = P[6, c], P[7, c], P[8, c]
            P[6, c] = f00 * c0 + f01 * c1 + f02 * c2
            P[7, c] = f10 * c0 + f11 * c1 + f12 * c2
            P[8, c] = f20 * c0 + f21 * c1 + f22 * c2
        for r in range(9):
            P[r, c] *= phi
            P[c, r] = P[r, c]
    for a in range(9, n):
        pa, qa = re_transition(PRM, a, dt)
        for b in range(a, n):
            pb, _ = re_transition(PRM, b, dt)
            v = P[a, b] * pa * pb
            P[a, b] = v
            P[b, a] = v
        P[a, a] += qa


@njit(cache=True)
def _estimated(PRM, n):
    """Error-state indices the (translation) filter estimates: all ``n`` compounded; tandem the
    translation ``0:6`` and the extra states ``9:n`` (the attitude filter is updated on its own)."""
    if PRM[PRM_TANDEM] == 0.0:
        return np.arange(n)
    idx = np.empty(n - 3, dtype=np.int64)
    for i in range(6):
        idx[i] = i
    for i in range(9, n):
        idx[i - 3] = i
    return idx


@njit(cache=True)
def _inject(X, P, idx, dx):
    """Add the correction ``dx`` of the error states ``idx`` to the nominal state (an extra state ``k`` at
    ``X[k + 1]``) and do the multiplicative attitude reset of its attitude part, if any."""
    d0, d1, d2 = 0.0, 0.0, 0.0
    for t in range(idx.shape[0]):
        i = idx[t]
        if i < 6:
            X[i] += dx[t]
        elif i < 9:
            if i == 6:
                d0 = dx[t]
            elif i == 7:
                d1 = dx[t]
            else:
                d2 = dx[t]
        else:
            X[i + 1] += dx[t]
    _reset_attitude3(X, P, d0, d1, d2)


@njit(cache=True)
def _update_scalar_extra(X, P, ST_I, ST_F, PRM, kind, H, nu, r, gate):
    """:func:`_update_scalar` for a filter with extra states (``H`` (n,), the full row): the gate, the
    underweighting and the Joseph form ``P+ = P - K u^T - u K^T + (s + r') K K^T`` (``u = P H^T``,
    ``s = H P H^T``, ``r'`` the noise plus, tandem, the attitude block's share) on the estimated indices."""
    n = P.shape[0]
    idx = _estimated(PRM, n)
    m = idx.shape[0]
    u = np.zeros(m)
    for a in range(m):
        acc = 0.0
        for b in range(m):
            acc += P[idx[a], idx[b]] * H[idx[b]]
        u[a] = acc
    s = 0.0
    for a in range(m):
        s += H[idx[a]] * u[a]
    rr = r
    if PRM[PRM_TANDEM] != 0.0:
        for i in range(6, 9):
            for k in range(6, 9):
                rr += H[i] * P[i, k] * H[k]
    status, S, Sg = _gate_scalar(ST_I, ST_F, PRM, kind, nu, s, rr, gate)
    if status != ST_ACCEPTED:
        return status
    K = u / Sg
    if not np.all(np.isfinite(K)):
        ST_I[COUNT_REFUSED, kind] += 1
        return ST_REFUSED_INVALID
    for a in range(m):
        for b in range(a, m):
            v = P[idx[a], idx[b]] - K[a] * u[b] - u[a] * K[b] + S * K[a] * K[b]
            P[idx[a], idx[b]] = v
            P[idx[b], idx[a]] = v
    _inject(X, P, idx, K * nu)
    ST_I[COUNT_ACCEPTED, kind] += 1
    ST_F[STF_SINCE] = 0.0
    if ST_F[STF_UW_LEFT] > 0.0:
        ST_F[STF_UW_LEFT] -= 1.0
    return ST_ACCEPTED


@njit(cache=True)
def predict_one(X, P, ST_I, ST_F, w_body, a_nav, dt, PRM):
    """Propagate one filter over ``dt`` [s] with gyro rate ``w_body`` [rad/s] (paper eq. 3, an input,
    not a state) and known acceleration ``a_nav`` [m/s^2] (commanded thrust / mass, frame ``c``).

    Translation: constant-acceleration kinematics over the step, ``F = [[I, dt I], [0, I]]``. Attitude:
    ``q <- q (x) exp(w dt)``; the error transition is ``Phi = exp(-[w dt x])`` (Crassidis & Junkins 2011,
    sec. 7.2.4, body-frame error). ``P <- F P F^T + Q`` is evaluated block by block, in place, using the
    structure of ``F``: tandem updates the 6x6 and 3x3 blocks, compounded also the 6x3 cross blocks (the
    extra work the paper's Table I charges to the compounded structure).
    """
    if not (np.isfinite(dt) and _finite3(w_body) and _finite3(a_nav)):
        ST_I[COUNT_REFUSED, TYPE_PREDICT] += 1
        return ST_REFUSED_NONFINITE
    if dt < 0.0:
        ST_I[COUNT_REFUSED, TYPE_PREDICT] += 1
        return ST_REFUSED_INVALID
    for i in range(3):
        X[i] += X[3 + i] * dt + 0.5 * a_nav[i] * dt * dt
        X[3 + i] += a_nav[i] * dt
    bx, by, bz, bw = qexp3(w_body[0] * dt, w_body[1] * dt, w_body[2] * dt)
    ax, ay, az, aw = X[6], X[7], X[8], X[9]
    # q <- q (x) dq (Hamilton product, as _rot_nb.qmul), renormalised
    nx = aw * bx + bw * ax + (ay * bz - az * by)
    ny = aw * by + bw * ay + (az * bx - ax * bz)
    nz = aw * bz + bw * az + (ax * by - ay * bx)
    nw = aw * bw - (ax * bx + ay * by + az * bz)
    inv = 1.0 / np.sqrt(nx * nx + ny * ny + nz * nz + nw * nw)
    X[6], X[7], X[8], X[9] = nx * inv, ny * inv, nz * inv, nw * inv
    # Phi = R(dq)^T, as scalars f_ij = R_ji
    f00, f10, f20, f01, f11, f21, f02, f12, f22 = qmat9(bx, by, bz, bw)
    # translation block: P_pp += dt (P_pv + P_vp) + dt^2 P_vv, P_pv += dt P_vv, P_vp += dt P_vv
    for i in range(3):
        for j in range(3):
            pv = P[i, 3 + j]
            vp = P[3 + i, j]
            vv = P[3 + i, 3 + j]
            P[i, j] += dt * (pv + vp) + dt * dt * vv
            P[i, 3 + j] = pv + dt * vv
            P[3 + i, j] = vp + dt * vv
    # white-noise-acceleration Q, Bar-Shalom, Li & Kirubarajan 2001 eq. 6.2.3-8
    q_acc = PRM[PRM_ACCEL_PSD]
    for i in range(3):
        P[i, i] += q_acc * dt**3 / 3.0
        P[i, 3 + i] += q_acc * dt**2 / 2.0
        P[3 + i, i] += q_acc * dt**2 / 2.0
        P[3 + i, 3 + i] += q_acc * dt
    if PRM[PRM_TANDEM] == 0.0:
        # cross blocks: P_xth <- F_x P_xth Phi^T (rows p pick up dt times rows v first)
        for i in range(3):
            for j in range(3):
                P[i, 6 + j] += dt * P[3 + i, 6 + j]
        for r in range(6):
            c0, c1, c2 = P[r, 6], P[r, 7], P[r, 8]
            v0 = f00 * c0 + f01 * c1 + f02 * c2
            v1 = f10 * c0 + f11 * c1 + f12 * c2
            v2 = f20 * c0 + f21 * c1 + f22 * c2
            P[r, 6], P[r, 7], P[r, 8] = v0, v1, v2
            P[6, r], P[7, r], P[8, r] = v0, v1, v2
    # attitude block: Phi P_thth Phi^T + Q_th
    # attitude block T = Phi P_thth, then T Phi^T (symmetric)
    t00 = f00 * P[6, 6] + f01 * P[7, 6] + f02 * P[8, 6]
    t01 = f00 * P[6, 7] + f01 * P[7, 7] + f02 * P[8, 7]
    t02 = f00 * P[6, 8] + f01 * P[7, 8] + f02 * P[8, 8]
    t10 = f10 * P[6, 6] + f11 * P[7, 6] + f12 * P[8, 6]
    t11 = f10 * P[6, 7] + f11 * P[7, 7] + f12 * P[8, 7]
    t12 = f10 * P[6, 8] + f11 * P[7, 8] + f12 * P[8, 8]
    t20 = f20 * P[6, 6] + f21 * P[7, 6] + f22 * P[8, 6]
    t21 = f20 * P[6, 7] + f21 * P[7, 7] + f22 * P[8, 7]
    t22 = f20 * P[6, 8] + f21 * P[7, 8] + f22 * P[8, 8]
    P[6, 6] = t00 * f00 + t01 * f01 + t02 * f02
    P[7, 7] = t10 * f10 + t11 * f11 + t12 * f12
    P[8, 8] = t20 * f20 + t21 * f21 + t22 * f22
    P[6, 7] = P[7, 6] = t00 * f10 + t01 * f11 + t02 * f12
    P[6, 8] = P[8, 6] = t00 * f20 + t01 * f21 + t02 * f22
    P[7, 8] = P[8, 7] = t10 * f20 + t11 * f21 + t12 * f22
    qa = PRM[PRM_ATT_PSD] * dt
    for i in range(3):
        P[6 + i, 6 + i] += qa
    if P.shape[0] > 9:
        _predict_extra(X, P, PRM, dt, f00, f01, f02, f10, f11, f12, f20, f21, f22)
    ST_F[STF_SINCE] += dt
    if PRM[PRM_UW_BETA] > 0.0 and ST_F[STF_SINCE] >= PRM[PRM_UW_GAP_S]:
        ST_F[STF_UW_LEFT] = PRM[PRM_UW_COUNT]
    ST_I[COUNT_ACCEPTED, TYPE_PREDICT] += 1
    return ST_ACCEPTED


@njit(cache=True)
def _gate_scalar(ST_I, ST_F, PRM, kind, nu, s, rr, gate):
    """The gate of a scalar update with ``s = H P H^T`` and noise ``rr``: ``S = s + rr``, the squared
    Mahalanobis distance ``d2 = nu^2 / S`` booked, refused when not finite, rejected past ``gate``
    (counted); else ``(ST_ACCEPTED, S, Sg)`` with ``Sg`` the underweighted ``S`` the gain divides by
    (:func:`_kalman_block`). One rule for :func:`_update_scalar` and :func:`_update_scalar_extra`."""
    S = s + rr
    d2 = nu * nu / S
    ST_F[STF_D2 + kind] = d2
    if not (np.isfinite(d2) and S > 0.0):
        ST_I[COUNT_REFUSED, kind] += 1
        return ST_REFUSED_INVALID, S, S
    if d2 > gate:
        ST_I[COUNT_REJECTED, kind] += 1
        return ST_REJECTED, S, S
    Sg = S
    if ST_F[STF_UW_LEFT] > 0.0 and PRM[PRM_UW_BETA] > 0.0 and s > PRM[PRM_UW_RATIO] * rr:
        Sg = S + PRM[PRM_UW_BETA] * s
    return ST_ACCEPTED, S, Sg


@njit(cache=True)
def _update_scalar(X, P, ST_I, ST_F, PRM, kind, nu, r, gate):
    """One scalar measurement ``z = h(x) + v``, ``v ~ N(0, r)``, Jacobian row ``H`` (9,): the same update
    as :func:`_update` (gate, underweighting, Joseph form, reset) in O(n^2) without temporaries.

    The Joseph form is evaluated exactly through the rank-one structure of ``A = I - K H``:
    with ``u = P H^T`` and ``s = H P H^T``, ``A P A^T = M - (u - K s) K^T`` where ``M = P - K u^T``,
    so ``P+ = M - (u - K s) K^T + r K K^T`` (Crassidis & Junkins 2011 eq. 5.39 expanded). Tandem: only
    the translation block (``n = 6``) is estimated; the attitude block's uncertainty is considered as
    extra noise ``H_th P_thth H_th^T`` (see :func:`_update`).
    """
    n = 6 if PRM[PRM_TANDEM] != 0.0 else 9
    # u, K and the Jacobian row H live in ST_F's scratch tail (offsets U, KO, HO): no allocation and no
    # array views (each view costs reference counting) in the innermost update
    U, KO, HO = STF_WORK, STF_WORK + 9, STF_WORK + 18
    for i in range(n):
        acc = 0.0
        for k in range(n):
            acc += P[i, k] * ST_F[HO + k]
        ST_F[U + i] = acc
    s = 0.0
    for i in range(n):
        s += ST_F[HO + i] * ST_F[U + i]
    rr = r
    if n == 6:
        for i in range(6, 9):
            for k in range(6, 9):
                rr += ST_F[HO + i] * P[i, k] * ST_F[HO + k]
    status, _, Sg = _gate_scalar(ST_I, ST_F, PRM, kind, nu, s, rr, gate)
    if status != ST_ACCEPTED:
        return status
    for i in range(n):
        ST_F[KO + i] = ST_F[U + i] / Sg
        if not np.isfinite(ST_F[KO + i]):  # S > 0 and finite P make this unreachable short of overflow
            ST_I[COUNT_REFUSED, kind] += 1
            return ST_REFUSED_INVALID
    for i in range(n):
        ST_F[U + i] -= ST_F[KO + i] * s  # u - K s
    for i in range(n):  # symmetric by construction: fill the upper triangle and mirror it
        ki, ui = ST_F[KO + i], ST_F[U + i]
        for j in range(i, n):
            kj, uj = ST_F[KO + j], ST_F[U + j]
            a = P[i, j] - ki * (uj + kj * s) - ui * kj + rr * ki * kj
            b = P[j, i] - kj * (ui + ki * s) - uj * ki + rr * kj * ki
            v = 0.5 * (a + b)
            P[i, j] = v
            P[j, i] = v
    for i in range(min(n, 6)):
        X[i] += ST_F[KO + i] * nu
    if n == 9:
        _reset_attitude3(X, P, ST_F[KO + 6] * nu, ST_F[KO + 7] * nu, ST_F[KO + 8] * nu)
    ST_I[COUNT_ACCEPTED, kind] += 1
    ST_F[STF_SINCE] = 0.0
    if ST_F[STF_UW_LEFT] > 0.0:
        ST_F[STF_UW_LEFT] -= 1.0
    return ST_ACCEPTED


@njit(cache=True)
def _reset_attitude3(X, P, d0, d1, d2):
    """Multiplicative reset (Markley 2003): ``q <- q (x) exp(d_theta)``, ``d_theta <- 0``; the covariance
    is mapped by ``G = I - 0.5 [d_theta x]`` on the attitude rows and columns (first-order reset
    Jacobian, Mueller, Hehn & D'Andrea 2016 eq. 11-12), in O(n^2)."""
    if d0 == 0.0 and d1 == 0.0 and d2 == 0.0:
        return
    dth = np.empty(3)
    dth[0], dth[1], dth[2] = d0, d1, d2
    X[6:10] = qnormalize(qmul(X[6:10], qexp(dth)))
    G = np.eye(3) - 0.5 * skew3(dth)
    tmp = np.empty(3)
    for c in range(P.shape[0]):  # rows 6..8 <- G rows
        for i in range(3):
            tmp[i] = G[i, 0] * P[6, c] + G[i, 1] * P[7, c] + G[i, 2] * P[8, c]
        for i in range(3):
            P[6 + i, c] = tmp[i]
    for rrow in range(P.shape[0]):  # columns 6..8 <- columns G^T
        for i in range(3):
            tmp[i] = P[rrow, 6] * G[i, 0] + P[rrow, 7] * G[i, 1] + P[rrow, 8] * G[i, 2]
        for i in range(3):
            P[rrow, 6 + i] = tmp[i]


@njit(cache=True)
def _reset_attitude3_noalloc(X, P, d0, d1, d2):
    """:func:`_reset_attitude3` on scalars, operation for operation (bit-identical results) but without
    its temporary arrays (``qexp``, ``qmul``, ``qnormalize``, ``G``): the reset of the fast attitude
    update. ``G = I - 0.5 [d_theta x]`` has ones on its diagonal, so ``G[i, i] * x`` is written ``x``."""
    if d0 == 0.0 and d1 == 0.0 and d2 == 0.0:
        return
    bx, by, bz, bw = qexp3(d0, d1, d2)
    ax, ay, az, aw = X[6], X[7], X[8], X[9]
    # qmul(X[6:10], qexp(dth)), then qnormalize (a division by the norm, as there)
    x = aw * bx + bw * ax + (ay * bz - az * by)
    y = aw * by + bw * ay + (az * bx - ax * bz)
    z = aw * bz + bw * az + (ax * by - ay * bx)
    w = aw * bw - (ax * bx + ay * by + az * bz)
    n = np.sqrt(x * x + y * y + z * z + w * w)
    X[6], X[7], X[8], X[9] = x / n, y / n, z / n, w / n
    # np.eye(3) - 0.5 * skew3(dth), entry by entry
    g01, g02 = 0.0 - 0.5 * (-d2), 0.0 - 0.5 * d1
    g10, g12 = 0.0 - 0.5 * d2, 0.0 - 0.5 * (-d0)
    g20, g21 = 0.0 - 0.5 * (-d1), 0.0 - 0.5 * d0
    for c in range(P.shape[0]):  # rows 6..8 <- G rows
        p6, p7, p8 = P[6, c], P[7, c], P[8, c]
        P[6, c] = p6 + g01 * p7 + g02 * p8
        P[7, c] = g10 * p6 + p7 + g12 * p8
        P[8, c] = g20 * p6 + g21 * p7 + p8
    for r in range(P.shape[0]):  # columns 6..8 <- columns G^T
        p6, p7, p8 = P[r, 6], P[r, 7], P[r, 8]
        P[r, 6] = p6 + p7 * g01 + p8 * g02
        P[r, 7] = p6 * g10 + p7 + p8 * g12
        P[r, 8] = p6 * g20 + p7 * g21 + p8


@njit(cache=True)
def constrain_plane_one(X, P, PRM, z0, sigma_z, sigma_vz):
    """A vehicle that moves in a horizontal plane (a module on a table): the pseudo-measurements
    ``p_z = z0`` and ``v_z = 0`` with standard deviations ``sigma_z`` [m] and ``sigma_vz`` [m/s], each a
    scalar Kalman update ``K = P h^T / s``, ``s = h P h^T + sigma^2``, ``P <- P - K s K^T`` (the
    measurement-augmentation way of imposing a state constraint, Simon 2010, "Kalman filtering with state
    constraints: a survey of linear and nonlinear algorithms", IET Control Theory Appl. 4(8), sec. 2.1).
    Not gated, not counted, and it leaves the underweighting book-keeping alone: it is a model of the
    vehicle, not a sensor. ``sigma_z == 0`` does nothing. Tandem: the translation filter only."""
    if not sigma_z > 0.0:
        return
    if P.shape[0] > 9:
        _constrain_plane_extra(X, P, PRM, z0, sigma_z, sigma_vz)
        return
    n = 6 if PRM[PRM_TANDEM] != 0.0 else 9
    K = np.empty(9)
    for idx, target, sig in ((2, z0, sigma_z), (5, 0.0, sigma_vz)):
        s = P[idx, idx] + sig * sig
        if not (s > 0.0 and np.isfinite(s)):
            continue
        nu = target - X[idx]
        for i in range(n):
            K[i] = P[i, idx] / s
        for i in range(n):
            for j in range(i, n):
                v = P[i, j] - K[i] * K[j] * s
                P[i, j] = v
                P[j, i] = v
        for i in range(6):
            X[i] += K[i] * nu
        if n == 9:
            _reset_attitude3(X, P, K[6] * nu, K[7] * nu, K[8] * nu)


@njit(cache=True)
def _constrain_plane_extra(X, P, PRM, z0, sigma_z, sigma_vz):
    """:func:`constrain_plane_one` for a filter with extra states (the estimated indices of
    :func:`_estimated`)."""
    idx = _estimated(PRM, P.shape[0])
    m = idx.shape[0]
    K = np.empty(m)
    for c, target, sig in ((2, z0, sigma_z), (5, 0.0, sigma_vz)):
        s = P[c, c] + sig * sig
        if not (s > 0.0 and np.isfinite(s)):
            continue
        nu = target - X[c]
        for a in range(m):
            K[a] = P[idx[a], c] / s
        for a in range(m):
            for b in range(a, m):
                v = P[idx[a], idx[b]] - K[a] * K[b] * s
                P[idx[a], idx[b]] = v
                P[idx[b], idx[a]] = v
        _inject(X, P, idx, K * nu)


@njit(cache=True)
def _reset_attitude(X, P, dth):
    """:func:`_reset_attitude3` for a rotation-vector array."""
    _reset_attitude3(X, P, dth[0], dth[1], dth[2])


@njit(cache=True)
def _kalman_block(Pb, H, nu, R, gate, ST_F, PRM):
    """Joseph-form update of one (sub)filter; returns (status, d2, dx, P_new).

    ``d2 = nu^T S^-1 nu`` is the squared Mahalanobis distance (paper sec. IV-D) with
    ``S = H P H^T + R``; the update is refused outright when ``d2 > gate``. Underweighting
    (Lear's rule as analysed by Zanetti, DeMars & Bishop 2010, "Underweighting nonlinear
    measurements", JGCD 33(5)) uses ``S_uw = (1 + beta) H P H^T + R`` in the gain for the first updates
    after a long prediction while the prior dominates the noise. The Joseph form
    ``(I - K H) P (I - K H)^T + K R K^T`` (Crassidis & Junkins 2011 eq. 5.39) keeps P symmetric positive
    and is the exact covariance for any gain, the underweighted one included.
    """
    n = Pb.shape[0]
    m = H.shape[0]
    PHt = Pb @ H.T
    HPHt = H @ PHt
    S = HPHt + R
    if m == 1:
        d2 = nu[0] * nu[0] / S[0, 0]
    else:
        d2 = nu @ np.linalg.solve(S, nu)
    if not np.isfinite(d2) or d2 < 0.0:
        return ST_REFUSED_INVALID, d2, np.zeros(n), Pb
    if d2 > gate:
        return ST_REJECTED, d2, np.zeros(n), Pb
    Sg = S
    if ST_F[STF_UW_LEFT] > 0.0 and PRM[PRM_UW_BETA] > 0.0:
        if np.trace(HPHt) > PRM[PRM_UW_RATIO] * np.trace(R):
            Sg = S + PRM[PRM_UW_BETA] * HPHt
    if m == 1:
        K = PHt / Sg[0, 0]
    else:
        K = np.linalg.solve(Sg, PHt.T).T
    A = np.eye(n) - K @ H
    Pn = _sandwich(A, Pb) + K @ R @ K.T
    dx = K @ nu
    if not (_all_finite(Pn) and _all_finite(dx)):
        return ST_REFUSED_INVALID, d2, np.zeros(n), Pb
    return ST_ACCEPTED, d2, dx, Pn


@njit(cache=True)
def _apply_correction(X, P, dx9):
    """Add the translation correction and do the multiplicative attitude reset (:func:`_reset_attitude`)."""
    for i in range(6):
        X[i] += dx9[i]
    _reset_attitude(X, P, dx9[6:9].copy())


@njit(cache=True)
def _commit(X, P, ST_I, ST_F, kind, status, d2, dx9, P_new):
    ST_F[STF_D2 + kind] = d2
    if status == ST_ACCEPTED:
        P[:, :] = P_new
        _apply_correction(X, P, dx9)
        ST_I[COUNT_ACCEPTED, kind] += 1
        ST_F[STF_SINCE] = 0.0
        if ST_F[STF_UW_LEFT] > 0.0:
            ST_F[STF_UW_LEFT] -= 1.0
    elif status == ST_REJECTED:
        ST_I[COUNT_REJECTED, kind] += 1
    else:
        ST_I[COUNT_REFUSED, kind] += 1
    return status


@njit(cache=True)
def _update(X, P, ST_I, ST_F, PRM, kind, H, nu, R, gate, tandem_att):
    """Shared measurement step for both structures.

    Compounded: one 9-state Joseph update. Tandem: the 6-state translation filter and the 3-state
    attitude filter are updated separately, each treating the other block's uncertainty as extra
    measurement noise (``R + H_other P_other H_other^T``, a "consider" treatment without
    cross-covariance), and the gate is tested once on the joint innovation covariance, which is the same
    for both blocks. A measurement that involves both blocks (vision) updates the translation filter
    first and then the attitude filter with the residual left over and the updated translation covariance
    considered: the measurement is used twice with its noise counted once per filter, the tandem's
    approximation (the compounded structure is the reference). A block the measurement does not involve
    (zero columns of ``H``) is left untouched, and so is the attitude filter for a range
    (``tandem_att`` false): the range's attitude partials only enter the translation filter's noise.
    """
    if P.shape[0] > 9:
        return _update_extra(X, P, ST_I, ST_F, PRM, kind, H, nu, R, gate, tandem_att)
    if PRM[PRM_TANDEM] == 0.0:
        status, d2, dx, Pn = _kalman_block(P, H, nu, R, gate, ST_F, PRM)
        return _commit(X, P, ST_I, ST_F, kind, status, d2, dx, Pn)
    Ht = np.ascontiguousarray(H[:, :6])
    Ha = np.ascontiguousarray(H[:, 6:])
    Pt = P[:6, :6].copy()
    Pa = P[6:, 6:].copy()
    use_t = _all_nonzero(Ht)
    use_a = tandem_att and _all_nonzero(Ha)
    Rt = R + Ha @ Pa @ Ha.T  # noise seen by the translation filter
    Ra = R + Ht @ Pt @ Ht.T  # noise seen by the attitude filter
    dx9 = np.zeros(9)
    Pn = P.copy()
    if use_t:
        status, d2, dxt, Ptn = _kalman_block(Pt, Ht, nu, Rt, gate, ST_F, PRM)
        if status != ST_ACCEPTED:
            return _commit(X, P, ST_I, ST_F, kind, status, d2, dx9, Pn)
        dx9[:6] = dxt
        Pn[:6, :6] = Ptn
        if use_a:
            # attitude filter: the translation it considers is the one just updated
            Ra = R + Ht @ Ptn @ Ht.T
            nu_a = nu - Ht @ dxt
            status_a, _, dxa, Pan = _kalman_block(Pa, Ha, nu_a, Ra, np.inf, ST_F, PRM)
            if status_a == ST_ACCEPTED:
                dx9[6:] = dxa
                Pn[6:, 6:] = Pan
        return _commit(X, P, ST_I, ST_F, kind, status, d2, dx9, Pn)
    status, d2, dxa, Pan = _kalman_block(Pa, Ha, nu, Ra, gate, ST_F, PRM)
    dx9[6:] = dxa
    Pn[6:, 6:] = Pan
    return _commit(X, P, ST_I, ST_F, kind, status, d2, dx9, Pn)


@njit(cache=True)
def _update_extra(X, P, ST_I, ST_F, PRM, kind, H9, nu, R, gate, tandem_att):
    """:func:`_update` for a filter with extra states, which no vector measurement (vision, attitude)
    depends on: ``H`` is ``H9`` with zero columns for them, and the (translation) filter estimates them
    through their cross-covariance with position and velocity."""
    n = P.shape[0]
    m = H9.shape[0]
    H = np.zeros((m, n))
    H[:, :9] = H9
    if PRM[PRM_TANDEM] == 0.0:
        idx = np.arange(n)
        status, d2, dx, Pn = _kalman_block(P, H, nu, R, gate, ST_F, PRM)
        if status == ST_ACCEPTED:
            P[:, :] = Pn
            _inject(X, P, idx, dx)
        return _commit_gated_or_accepted(ST_I, ST_F, kind, status, d2)
    idx = _estimated(PRM, n)
    Ht = np.ascontiguousarray(H[:, idx])
    Ha = np.ascontiguousarray(H9[:, 6:])
    Pt = np.empty((idx.shape[0], idx.shape[0]))
    for a in range(idx.shape[0]):
        for b in range(idx.shape[0]):
            Pt[a, b] = P[idx[a], idx[b]]
    Pa = P[6:9, 6:9].copy()
    use_t = _all_nonzero(Ht)
    use_a = tandem_att and _all_nonzero(Ha)
    if use_t:
        status, d2, dxt, Ptn = _kalman_block(Pt, Ht, nu, R + Ha @ Pa @ Ha.T, gate, ST_F, PRM)
        if status != ST_ACCEPTED:
            return _commit_gated_or_accepted(ST_I, ST_F, kind, status, d2)
        dxa = np.zeros(3)
        Pan = Pa
        if use_a:
            nu_a = nu - Ht @ dxt
            status_a, _, dxa_, Pan_ = _kalman_block(Pa, Ha, nu_a, R + Ht @ Ptn @ Ht.T, np.inf, ST_F, PRM)
            if status_a == ST_ACCEPTED:
                dxa, Pan = dxa_, Pan_
    else:
        status, d2, dxa, Pan = _kalman_block(Pa, Ha, nu, R + Ht @ Pt @ Ht.T, gate, ST_F, PRM)
        if status != ST_ACCEPTED:
            return _commit_gated_or_accepted(ST_I, ST_F, kind, status, d2)
        dxt = np.zeros(idx.shape[0])
        Ptn = Pt
    for a in range(idx.shape[0]):
        for b in range(idx.shape[0]):
            P[idx[a], idx[b]] = Ptn[a, b]
    P[6:9, 6:9] = Pan
    _inject(X, P, idx, dxt)
    _reset_attitude3(X, P, dxa[0], dxa[1], dxa[2])
    return _commit_gated_or_accepted(ST_I, ST_F, kind, status, d2)


@njit(cache=True)
def _commit_gated_or_accepted(ST_I, ST_F, kind, status, d2):
    """The book-keeping of :func:`_commit` once the state has been written (or left alone)."""
    ST_F[STF_D2 + kind] = d2
    if status == ST_ACCEPTED:
        ST_I[COUNT_ACCEPTED, kind] += 1
        ST_F[STF_SINCE] = 0.0
        if ST_F[STF_UW_LEFT] > 0.0:
            ST_F[STF_UW_LEFT] -= 1.0
    elif status == ST_REJECTED:
        ST_I[COUNT_REJECTED, kind] += 1
    else:
        ST_I[COUNT_REFUSED, kind] += 1
    return status


@njit(cache=True)
def _all_nonzero(H):
    """True when the block ``H`` has any non-zero entry (the measurement involves that block)."""
    for v in H.ravel():
        if v != 0.0:
            return True
    return False


@njit(cache=True)
def range_model(X, anchor_nav, lever_body):
    """UWB range to an anchor with the tag lever arm ``P1`` (paper eq. 1, Fig. 2).

    ``h = || p + R(q) P1 - a ||``; ``dh/dp = u^T``, ``dh/dv = 0``,
    ``dh/dtheta = -u^T R(q) [P1 x]`` with ``u`` the unit line of sight anchor -> tag.
    Returns ``(h, H (1, 9))``; the arithmetic is :func:`_range_row`'s.
    """
    H = np.zeros((1, 9))
    h = _range_row(X, anchor_nav, lever_body, H[0])
    return h, H


@njit(cache=True)
def _range_row(X, anchor_nav, lever_body, H, ho=0):
    """:func:`range_model` written out in scalars, filling ``H[ho : ho + 9]`` in place; returns ``h``."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = qmat9(X[6], X[7], X[8], X[9])
    lx, ly, lz = lever_body[0], lever_body[1], lever_body[2]
    dx = X[0] + r00 * lx + r01 * ly + r02 * lz - anchor_nav[0]
    dy = X[1] + r10 * lx + r11 * ly + r12 * lz - anchor_nav[1]
    dz = X[2] + r20 * lx + r21 * ly + r22 * lz - anchor_nav[2]
    h = np.sqrt(dx * dx + dy * dy + dz * dz)
    for i in range(9):
        H[ho + i] = 0.0
    if h > 0.0:
        ux, uy, uz = dx / h, dy / h, dz / h
        H[ho + 0], H[ho + 1], H[ho + 2] = ux, uy, uz
        # with w = R^T u (the line of sight in the body frame): dh/dtheta = -w^T [P1 x] = (P1 x w)^T
        wx = r00 * ux + r10 * uy + r20 * uz
        wy = r01 * ux + r11 * uy + r21 * uz
        wz = r02 * ux + r12 * uy + r22 * uz
        H[ho + 6] = ly * wz - lz * wy
        H[ho + 7] = lz * wx - lx * wz
        H[ho + 8] = lx * wy - ly * wx
    return h


@njit(cache=True)
def update_range_one(X, P, ST_I, ST_F, PRM, anchor_nav, z_m, sigma_m, gate):
    if not (np.isfinite(z_m) and np.isfinite(sigma_m) and _finite3(anchor_nav)):
        ST_I[COUNT_REFUSED, TYPE_RANGE] += 1
        return ST_REFUSED_NONFINITE
    if z_m < 0.0 or sigma_m <= 0.0:
        ST_I[COUNT_REFUSED, TYPE_RANGE] += 1
        return ST_REFUSED_INVALID
    if P.shape[0] > 9:
        return _update_range_extra(X, P, ST_I, ST_F, PRM, anchor_nav, -1, z_m, sigma_m, gate)
    h = _range_row(X, anchor_nav, PRM[PRM_LEVER : PRM_LEVER + 3], ST_F, STF_WORK + 18)
    if h == 0.0:
        ST_I[COUNT_REFUSED, TYPE_RANGE] += 1
        return ST_REFUSED_INVALID
    return _update_scalar(X, P, ST_I, ST_F, PRM, TYPE_RANGE, z_m - h, sigma_m * sigma_m, gate)


@njit(cache=True)
def range_extra_model(X, PRM, anchor_nav, j):
    """The range to anchor ``j`` at ``anchor_nav`` with the range-error model: ``h = ||p + R(q) P1 - a_j||
    + c + b_j + g_j`` (the parts the filter has) and its Jacobian row ``H`` (``9 + M``,): the geometric
    partials of :func:`range_model` and a 1 for each error term of anchor ``j``."""
    H = np.zeros(X.shape[0] - 1)
    h = _range_row(X, anchor_nav, PRM[PRM_LEVER : PRM_LEVER + 3], H, 0)
    if h == 0.0:
        return h, H
    ic, io, ig = re_index(PRM, j)
    for k in (ic, io, ig):
        if k >= 0:
            H[k] = 1.0
            h += X[k + 1]
    return h, H


@njit(cache=True)
def _update_range_extra(X, P, ST_I, ST_F, PRM, anchor_nav, j, z_m, sigma_m, gate):
    h, H = range_extra_model(X, PRM, anchor_nav, j)
    if h == 0.0:
        ST_I[COUNT_REFUSED, TYPE_RANGE] += 1
        return ST_REFUSED_INVALID
    return _update_scalar_extra(X, P, ST_I, ST_F, PRM, TYPE_RANGE, H, z_m - h, sigma_m * sigma_m, gate)


@njit(cache=True)
def update_range_anchor_one(X, P, ST_I, ST_F, PRM, anchor_nav, j, z_m, sigma_m, gate):
    """:func:`update_range_one` for anchor index ``j``, whose range-error terms enter when the filter has
    them (``P`` larger than 9 x 9); without them, exactly :func:`update_range_one`."""
    if P.shape[0] == 9:
        return update_range_one(X, P, ST_I, ST_F, PRM, anchor_nav, z_m, sigma_m, gate)
    if not (np.isfinite(z_m) and np.isfinite(sigma_m) and _finite3(anchor_nav)):
        ST_I[COUNT_REFUSED, TYPE_RANGE] += 1
        return ST_REFUSED_NONFINITE
    if z_m < 0.0 or sigma_m <= 0.0:
        ST_I[COUNT_REFUSED, TYPE_RANGE] += 1
        return ST_REFUSED_INVALID
    return _update_range_extra(X, P, ST_I, ST_F, PRM, anchor_nav, j, z_m, sigma_m, gate)


@njit(cache=True)
def tdoa_model(X, PRM, anchor_a_nav, anchor_b_nav, ia, ib):
    """A time difference of arrival as a distance difference, ``h = d_b - d_a`` with ``d_x = ||p + R(q) P1 -
    a_x|| + b_x + g_x`` (the Crazyflie's ``distanceDiff``, idB minus idA; the common offset cancels), and its
    Jacobian row ``H`` (``9 + M``,): the difference of the two range rows of :func:`range_extra_model`, i.e.
    ``u_b - u_a`` on ``dp``, the attitude partials' difference on ``dtheta``, +1 on anchor b's error terms
    and -1 on anchor a's (the TDoA measurement model of Ledergerber, Hamer & D'Andrea 2015, "A robot
    self-localization system using one-way ultra-wideband communication", IROS, eq. 2, as the Crazyflie's
    ``mm_tdoa.c`` fuses it). ``h`` is NaN when the tag sits on an anchor (no line of sight)."""
    n = X.shape[0] - 1
    H = np.zeros(n)
    Hb = np.zeros(n)
    lever = PRM[PRM_LEVER : PRM_LEVER + 3]
    ha = _range_row(X, anchor_a_nav, lever, H, 0)
    hb = _range_row(X, anchor_b_nav, lever, Hb, 0)
    if ha == 0.0 or hb == 0.0:
        return np.nan, H
    for k in range(9):
        H[k] = Hb[k] - H[k]
    for sign, j in ((1.0, ib), (-1.0, ia)):
        _, io, ig = re_index(PRM, j)
        for k in (io, ig):
            if k >= 0:
                H[k] += sign
                hb += sign * X[k + 1]
    return hb - ha, H


@njit(cache=True)
def update_tdoa_one(X, P, ST_I, ST_F, PRM, anchor_a_nav, anchor_b_nav, ia, ib, z_m, sigma_m, gate):
    """One distance difference ``z_m = d_b - d_a`` [m] with white noise ``sigma_m`` [m] (:func:`tdoa_model`):
    refused when not finite, when ``ia == ib``, or when it is longer than the anchors' baseline (no geometry
    gives it); gated and fused as a range is (:func:`_update_scalar`), and counted with the ranges
    (``TYPE_RANGE``: both are the UWB measurement of the health ring)."""
    if not (np.isfinite(z_m) and np.isfinite(sigma_m) and _finite3(anchor_a_nav) and _finite3(anchor_b_nav)):
        ST_I[COUNT_REFUSED, TYPE_RANGE] += 1
        return ST_REFUSED_NONFINITE
    base = 0.0
    for k in range(3):
        base += (anchor_b_nav[k] - anchor_a_nav[k]) ** 2
    if ia == ib or sigma_m <= 0.0 or abs(z_m) > np.sqrt(base) + 3.0 * sigma_m:
        ST_I[COUNT_REFUSED, TYPE_RANGE] += 1
        return ST_REFUSED_INVALID
    h, H = tdoa_model(X, PRM, anchor_a_nav, anchor_b_nav, ia, ib)
    if not np.isfinite(h):
        ST_I[COUNT_REFUSED, TYPE_RANGE] += 1
        return ST_REFUSED_INVALID
    if P.shape[0] > 9:
        return _update_scalar_extra(X, P, ST_I, ST_F, PRM, TYPE_RANGE, H, z_m - h, sigma_m * sigma_m, gate)
    for k in range(9):
        ST_F[STF_WORK + 18 + k] = H[k]
    return _update_scalar(X, P, ST_I, ST_F, PRM, TYPE_RANGE, z_m - h, sigma_m * sigma_m, gate)


@njit(cache=True)
def camera_point_model(X, w_nav, cam_pos_body, R_body_cam):
    """A point ``w`` (frame ``c``) seen in the camera frame: ``f = R_bc^T (R(q)^T (w - p) - c_b)``.

    ``df/dp = -R_bc^T R(q)^T``, ``df/dtheta = R_bc^T [y x]`` with ``y = R(q)^T (w - p)`` (from
    ``R(q (x) exp(dth))^T = (I - [dth x]) R(q)^T``). Returns ``(f (3,), H (3, 9))``.
    """
    Rq = qmat(X[6:10])
    y = Rq.T @ (w_nav - X[0:3])
    f = R_body_cam.T @ (y - cam_pos_body)
    H = np.zeros((3, 9))
    H[:, 0:3] = -(R_body_cam.T @ Rq.T)
    H[:, 6:9] = R_body_cam.T @ skew3(y)
    return f, H


@njit(cache=True)
def update_features_one(
    X, P, ST_I, ST_F, PRM, markers_nav, f_cam, sigma_m, target_cov_nav, cam_pos_body, R_body_cam, gate
):
    """Marker feature vectors in the camera frame (paper sec. III and IV-D, 1 mm noise), all markers
    stacked into one vector measurement. The target position uncertainty ``target_cov_nav`` (3x3, frame c)
    shifts every marker alike, so it enters every block of ``R``, cross blocks included."""
    if not (
        _all_finite(markers_nav)
        and _all_finite(f_cam)
        and np.isfinite(sigma_m)
        and _all_finite(target_cov_nav)
    ):
        ST_I[COUNT_REFUSED, TYPE_FEATURES] += 1
        return ST_REFUSED_NONFINITE
    n = markers_nav.shape[0]
    if n == 0 or sigma_m <= 0.0:
        ST_I[COUNT_REFUSED, TYPE_FEATURES] += 1
        return ST_REFUSED_INVALID
    H = np.zeros((3 * n, 9))
    nu = np.zeros(3 * n)
    for j in range(n):
        f, Hj = camera_point_model(X, markers_nav[j], cam_pos_body, R_body_cam)
        H[3 * j : 3 * j + 3, :] = Hj
        nu[3 * j : 3 * j + 3] = f_cam[j] - f
    M = R_body_cam.T @ qmat(X[6:10]).T
    C = M @ target_cov_nav @ M.T
    R = np.zeros((3 * n, 3 * n))
    for j in range(n):
        for k in range(n):
            R[3 * j : 3 * j + 3, 3 * k : 3 * k + 3] = C
        for i in range(3):
            R[3 * j + i, 3 * j + i] += sigma_m * sigma_m
    return _update(X, P, ST_I, ST_F, PRM, TYPE_FEATURES, H, nu, R, gate, True)


@njit(cache=True)
def pose_residual(X, p_target_nav, q_nav_target, t_cam, q_cam_target, cam_pos_body, R_body_cam, q_body_cam):
    """Residual ``(nu (6,), H (6, 9))`` of a PnP pose: ``nu[:3] = t_cam - f(p_target)`` (camera point model)
    and ``nu[3:] = log(q_ref^-1 (x) q_meas)`` with the implied body attitude
    ``q_meas = q_nav_target (x) q_cam_target^-1 (x) q_body_cam^-1``; ``H[3:] = [0 0 I]``."""
    f, Hp = camera_point_model(X, p_target_nav, cam_pos_body, R_body_cam)
    q_meas = qmul(qmul(q_nav_target, qconj(qnormalize(q_cam_target))), qconj(q_body_cam))
    H = np.zeros((6, 9))
    H[0:3, :] = Hp
    for i in range(3):
        H[3 + i, 6 + i] = 1.0
    nu = np.zeros(6)
    nu[0:3] = t_cam - f
    nu[3:6] = qlog(qmul(qconj(X[6:10]), qnormalize(q_meas)))
    return nu, H


@njit(cache=True)
def attitude_residual(X, q_meas):
    """Residual ``(nu (3,), H (3, 9))`` of an attitude measurement: ``log(q_ref^-1 (x) q_meas)``,
    ``H = [0 0 I]`` (body-frame error)."""
    nu = qlog(qmul(qconj(X[6:10]), qnormalize(q_meas)))
    H = np.zeros((3, 9))
    for i in range(3):
        H[i, 6 + i] = 1.0
    return nu, H


@njit(cache=True)
def update_pose_one(
    X, P, ST_I, ST_F, PRM, p_target_nav, q_nav_target, t_cam, q_cam_target, cov_cam, target_cov_nav,
    cam_pos_body, R_body_cam, q_body_cam, gate,
):  # fmt: skip
    """Relative pose of the target from PnP: position ``t_cam`` of the target origin in the camera frame
    and attitude ``q_cam_target``, with covariance ``cov_cam`` (6x6) of ``(dt_cam, dphi_cam)`` where
    ``R_ct_meas = exp([dphi_cam x]) R_ct``. The attitude residual is the body-frame rotation vector
    ``log(q_ref^-1 (x) q_meas)`` of the implied body attitude
    ``q_meas = q_nav_target (x) q_cam_target^-1 (x) q_body_cam^-1``, whose noise is ``-R_bc dphi_cam``."""
    if not (
        _all_finite(p_target_nav)
        and _all_finite(q_nav_target)
        and _all_finite(t_cam)
        and _all_finite(q_cam_target)
        and _all_finite(cov_cam)
        and _all_finite(target_cov_nav)
    ):
        ST_I[COUNT_REFUSED, TYPE_POSE] += 1
        return ST_REFUSED_NONFINITE
    nq = q_cam_target @ q_cam_target
    if nq < 0.5 or nq > 2.0:
        ST_I[COUNT_REFUSED, TYPE_POSE] += 1
        return ST_REFUSED_INVALID
    nu, H = pose_residual(
        X, p_target_nav, q_nav_target, t_cam, q_cam_target, cam_pos_body, R_body_cam, q_body_cam
    )
    T = np.eye(6)
    T[3:, 3:] = -R_body_cam
    R = T @ cov_cam @ T.T
    M = R_body_cam.T @ qmat(X[6:10]).T
    R[0:3, 0:3] += M @ target_cov_nav @ M.T
    R = 0.5 * (R + R.T)
    return _update(X, P, ST_I, ST_F, PRM, TYPE_POSE, H, nu, R, gate, True)


@njit(cache=True)
def _update_attitude_generic(X, P, ST_I, ST_F, PRM, q_meas, cov_body, gate):
    """:func:`update_attitude_one` through the generic :func:`_update` (dense ``H``, ``np.linalg.solve``,
    dense Joseph form): the reference the fast kernel is tested against, and its fallback for inputs
    large enough to overflow."""
    if not (_all_finite(q_meas) and _all_finite(cov_body)):
        ST_I[COUNT_REFUSED, TYPE_ATTITUDE] += 1
        return ST_REFUSED_NONFINITE
    nq = q_meas @ q_meas
    if nq < 0.5 or nq > 2.0:
        ST_I[COUNT_REFUSED, TYPE_ATTITUDE] += 1
        return ST_REFUSED_INVALID
    nu, H = attitude_residual(X, q_meas)
    R = 0.5 * (cov_body + cov_body.T)
    return _update(X, P, ST_I, ST_F, PRM, TYPE_ATTITUDE, H, nu, R, gate, True)


_FAST_BOUND = 1e100
"""Magnitude (of any ``P`` entry, gain or noise entry) above which :func:`update_attitude_one` hands the
update to the generic path: below it no product of the closed-form Joseph update can overflow, so its
result is finite whenever its inputs are and it may be written in place."""


@njit(cache=True)
def _commit_gated(ST_I, ST_F, kind, status, d2):
    """:func:`_commit` of an update that leaves the state alone (rejected by the gate, or refused)."""
    ST_F[STF_D2 + kind] = d2
    if status == ST_REJECTED:
        ST_I[COUNT_REJECTED, kind] += 1
    else:
        ST_I[COUNT_REFUSED, kind] += 1
    return status


@njit(cache=True)
def _attitude_residual3(X, q_meas):
    """The residual of :func:`attitude_residual` on scalars, operation for operation (bit-identical):
    ``qlog(qmul(qconj(q_ref), qnormalize(q_meas)))`` without its temporary arrays."""
    qx, qy, qz, qw = q_meas[0], q_meas[1], q_meas[2], q_meas[3]
    n = np.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    px, py, pz, pw = -X[6], -X[7], -X[8], X[9]
    x = pw * qx + qw * px + (py * qz - pz * qy)
    y = pw * qy + qw * py + (pz * qx - px * qz)
    z = pw * qz + qw * pz + (px * qy - py * qx)
    w = pw * qw - (px * qx + py * qy + pz * qz)
    if w < 0.0:  # qlog: the w >= 0 hemisphere, Taylor series of atan(r) / r below its threshold
        x, y, z, w = -x, -y, -z, -w
    n2 = x * x + y * y + z * z
    if n2 < (_QLOG_TAYLOR * _QLOG_TAYLOR) * (w * w):
        r2 = n2 / (w * w)
        k = (2.0 / w) * (1.0 - r2 / 3.0 + r2 * r2 / 5.0)
    else:
        nn = np.sqrt(n2)
        k = 2.0 * np.arctan2(nn, w) / nn
    return k * x, k * y, k * z


@njit(cache=True)
def _inv3(a):
    """Inverse of the 3x3 matrix ``a`` (a row-major 9-tuple, returned likewise) by its adjugate over its
    determinant (Cramer's rule), after scaling by ``1 / (|a00| + |a11| + |a22|)`` so that the
    determinant neither under- nor overflows whatever the units. A singular or non-finite ``a`` gives
    non-finite (NaN) entries."""
    s = abs(a[0]) + abs(a[4]) + abs(a[8])
    if not (s > 0.0 and s < np.inf):
        s = 1.0
    t = 1.0 / s
    b00, b01, b02 = a[0] * t, a[1] * t, a[2] * t
    b10, b11, b12 = a[3] * t, a[4] * t, a[5] * t
    b20, b21, b22 = a[6] * t, a[7] * t, a[8] * t
    c00 = b11 * b22 - b12 * b21
    c01 = b12 * b20 - b10 * b22
    c02 = b10 * b21 - b11 * b20
    det = b00 * c00 + b01 * c01 + b02 * c02
    if det == 0.0:  # (numba raises ZeroDivisionError on a float division by zero)
        nan = np.nan
        return (nan, nan, nan, nan, nan, nan, nan, nan, nan)
    f = t / det
    return (
        c00 * f, (b02 * b21 - b01 * b22) * f, (b01 * b12 - b02 * b11) * f,
        c01 * f, (b00 * b22 - b02 * b20) * f, (b02 * b10 - b00 * b12) * f,
        c02 * f, (b01 * b20 - b00 * b21) * f, (b00 * b11 - b01 * b10) * f,
    )  # fmt: skip


@njit(cache=True)
def _mm3(a, b):
    """``a @ b`` for 3x3 matrices given as row-major 9-tuples."""
    return (
        a[0] * b[0] + a[1] * b[3] + a[2] * b[6],
        a[0] * b[1] + a[1] * b[4] + a[2] * b[7],
        a[0] * b[2] + a[1] * b[5] + a[2] * b[8],
        a[3] * b[0] + a[4] * b[3] + a[5] * b[6],
        a[3] * b[1] + a[4] * b[4] + a[5] * b[7],
        a[3] * b[2] + a[4] * b[5] + a[5] * b[8],
        a[6] * b[0] + a[7] * b[3] + a[8] * b[6],
        a[6] * b[1] + a[7] * b[4] + a[8] * b[7],
        a[6] * b[2] + a[7] * b[5] + a[8] * b[8],
    )


@njit(cache=True)
def _mmt3(a, b):
    """``a @ b.T`` for 3x3 matrices given as row-major 9-tuples."""
    return (
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2],
        a[0] * b[3] + a[1] * b[4] + a[2] * b[5],
        a[0] * b[6] + a[1] * b[7] + a[2] * b[8],
        a[3] * b[0] + a[4] * b[1] + a[5] * b[2],
        a[3] * b[3] + a[4] * b[4] + a[5] * b[5],
        a[3] * b[6] + a[4] * b[7] + a[5] * b[8],
        a[6] * b[0] + a[7] * b[1] + a[8] * b[2],
        a[6] * b[3] + a[7] * b[4] + a[8] * b[5],
        a[6] * b[6] + a[7] * b[7] + a[8] * b[8],
    )


@njit(cache=True)
def update_attitude_one(X, P, ST_I, ST_F, PRM, q_meas, cov_body, gate):
    """AHRS attitude: residual ``log(q_ref^-1 (x) q_meas)`` (body frame), ``H = [0 0 I]``.

    The update of :func:`_update_attitude_generic` (same refusals, gate, underweighting, Joseph form,
    multiplicative reset, status and book-keeping) written out for this ``H``, in place and without
    allocation. ``P H^T = P[:, 6:9]`` and ``H P H^T = P_thth``: ``S = P_thth + R`` and the underweighted
    ``S_uw = S + beta P_thth`` are 3x3, inverted in closed form (:func:`_inv3`), ``K = P[:, 6:9] S_uw^-T``
    (the rows of ``solve(S_uw, (P H^T)^T)``). The Joseph form ``(I - K H) P (I - K H)^T + K R K^T``
    (Crassidis & Junkins 2011 eq. 5.39) is evaluated as :func:`_sandwich` does, through the structure of
    ``A = I - K H`` (identity on the translation columns, ``I - K_th`` on the attitude ones): rows
    ``i < 6`` of ``A P`` are ``P[i] - K[i] P[6:9]``, so only their attitude columns ``b_i`` are kept, and
    ``P+[i, j] = (A P)[i, j] - b_i . K[j] + (K R)[i] . K[j]`` for ``j < 6``,
    ``P+[i, 6 + s] = b_i . A_th[s] + (K R)[i] . K_th[s]``, ``P+_thth = A_th P_thth A_th^T + K_th R K_th^T``,
    the upper triangle evaluated and mirrored; the translation rows of ``K`` live in ST_F's scratch tail.
    Tandem: the attitude filter alone (``H_t = 0``: the translation filter is not updated and the
    attitude filter's noise is ``R``).

    Departures from the generic path beyond rounding (~1e-16 relative, the closed-form inverse against
    LAPACK's LU): a non-finite ``P`` entry the update reads, or a singular ``S``, is refused
    (``ST_REFUSED_INVALID``) where ``np.linalg.solve`` would raise ``LinAlgError``; and an update whose
    ``P``, ``R`` or gain has an entry beyond ``_FAST_BOUND`` (where a product could overflow) is handed to
    the generic path whole.
    """
    kind = TYPE_ATTITUDE
    if P.shape[0] > 9:  # extra states: the generic path (which updates their cross-covariance too)
        return _update_attitude_generic(X, P, ST_I, ST_F, PRM, q_meas, cov_body, gate)
    if not (_all_finite(q_meas) and _all_finite(cov_body)):
        ST_I[COUNT_REFUSED, kind] += 1
        return ST_REFUSED_NONFINITE
    nq = q_meas @ q_meas
    if nq < 0.5 or nq > 2.0:
        ST_I[COUNT_REFUSED, kind] += 1
        return ST_REFUSED_INVALID
    n0, n1, n2 = _attitude_residual3(X, q_meas)
    # R = (cov + cov^T) / 2 (exactly symmetric), S = H P H^T + R
    r00 = 0.5 * (cov_body[0, 0] + cov_body[0, 0])
    r01 = 0.5 * (cov_body[0, 1] + cov_body[1, 0])
    r02 = 0.5 * (cov_body[0, 2] + cov_body[2, 0])
    r11 = 0.5 * (cov_body[1, 1] + cov_body[1, 1])
    r12 = 0.5 * (cov_body[1, 2] + cov_body[2, 1])
    r22 = 0.5 * (cov_body[2, 2] + cov_body[2, 2])
    rr = (r00, r01, r02, r01, r11, r12, r02, r12, r22)
    a = (P[6, 6], P[6, 7], P[6, 8], P[7, 6], P[7, 7], P[7, 8], P[8, 6], P[8, 7], P[8, 8])
    S = (
        a[0] + r00, a[1] + r01, a[2] + r02,
        a[3] + r01, a[4] + r11, a[5] + r12,
        a[6] + r02, a[7] + r12, a[8] + r22,
    )  # fmt: skip
    v = _inv3(S)
    d2 = (
        n0 * (v[0] * n0 + v[1] * n1 + v[2] * n2)
        + n1 * (v[3] * n0 + v[4] * n1 + v[5] * n2)
        + n2 * (v[6] * n0 + v[7] * n1 + v[8] * n2)
    )
    if not np.isfinite(d2) or d2 < 0.0:
        return _commit_gated(ST_I, ST_F, kind, ST_REFUSED_INVALID, d2)
    if d2 > gate:
        return _commit_gated(ST_I, ST_F, kind, ST_REJECTED, d2)
    w = v  # inverse of the S the gain uses
    if ST_F[STF_UW_LEFT] > 0.0 and PRM[PRM_UW_BETA] > 0.0:
        if a[0] + a[4] + a[8] > PRM[PRM_UW_RATIO] * (r00 + r11 + r22):
            beta = PRM[PRM_UW_BETA]
            w = _inv3(
                (
                    S[0] + beta * a[0], S[1] + beta * a[1], S[2] + beta * a[2],
                    S[3] + beta * a[3], S[4] + beta * a[4], S[5] + beta * a[5],
                    S[6] + beta * a[6], S[7] + beta * a[7], S[8] + beta * a[8],
                )
            )  # fmt: skip
    ka = _mmt3(a, w)  # K_th = P_thth S_uw^-T
    tandem = PRM[PRM_TANDEM] != 0.0
    # every entry the update reads or forms must be finite (x * 0.0 is NaN for inf and NaN) and below
    # _FAST_BOUND; the translation rows of K go to ST_F[STF_WORK + 3 i + m] on the way
    fin = 0.0
    big = 0.0
    for x in ka:
        fin += x * 0.0
        big = max(big, abs(x))
    for x in rr:
        fin += x * 0.0
        big = max(big, abs(x))
    if tandem:
        for x in a:
            fin += x * 0.0
            big = max(big, abs(x))
    else:
        for i in range(9):
            for j in range(9):
                x = P[i, j]
                fin += x * 0.0
                big = max(big, abs(x))
        for i in range(6):
            c0, c1, c2 = P[i, 6], P[i, 7], P[i, 8]
            k0 = c0 * w[0] + c1 * w[1] + c2 * w[2]
            k1 = c0 * w[3] + c1 * w[4] + c2 * w[5]
            k2 = c0 * w[6] + c1 * w[7] + c2 * w[8]
            ST_F[STF_WORK + 3 * i] = k0
            ST_F[STF_WORK + 3 * i + 1] = k1
            ST_F[STF_WORK + 3 * i + 2] = k2
            fin += (k0 + k1 + k2) * 0.0
            big = max(big, max(abs(k0), max(abs(k1), abs(k2))))
    if fin != 0.0:
        return _commit_gated(ST_I, ST_F, kind, ST_REFUSED_INVALID, d2)
    if big > _FAST_BOUND:
        return _update_attitude_generic(X, P, ST_I, ST_F, PRM, q_meas, cov_body, gate)
    # A_th = I - K_th
    e = (
        1.0 - ka[0], 0.0 - ka[1], 0.0 - ka[2],
        0.0 - ka[3], 1.0 - ka[4], 0.0 - ka[5],
        0.0 - ka[6], 0.0 - ka[7], 1.0 - ka[8],
    )  # fmt: skip
    if not tandem:
        # translation rows, in place: row i reads P[i, j >= i], P[6:9, j >= i] and the attitude block
        # (kept in `a`), none of which an earlier row has written
        for i in range(6):
            k0, k1, k2 = ST_F[STF_WORK + 3 * i], ST_F[STF_WORK + 3 * i + 1], ST_F[STF_WORK + 3 * i + 2]
            b0 = P[i, 6] - k0 * a[0] - k1 * a[3] - k2 * a[6]  # (A P)[i, 6:9]
            b1 = P[i, 7] - k0 * a[1] - k1 * a[4] - k2 * a[7]
            b2 = P[i, 8] - k0 * a[2] - k1 * a[5] - k2 * a[8]
            q0 = k0 * r00 + k1 * r01 + k2 * r02  # (K R)[i]
            q1 = k0 * r01 + k1 * r11 + k2 * r12
            q2 = k0 * r02 + k1 * r12 + k2 * r22
            for j in range(i, 6):
                l0, l1, l2 = ST_F[STF_WORK + 3 * j], ST_F[STF_WORK + 3 * j + 1], ST_F[STF_WORK + 3 * j + 2]
                fp = P[i, j] - k0 * P[6, j] - k1 * P[7, j] - k2 * P[8, j]  # (A P)[i, j]
                pn = (fp - b0 * l0 - b1 * l1 - b2 * l2) + (q0 * l0 + q1 * l1 + q2 * l2)
                P[i, j] = pn
                P[j, i] = pn
            pn = (b0 * e[0] + b1 * e[1] + b2 * e[2]) + (q0 * ka[0] + q1 * ka[1] + q2 * ka[2])
            P[i, 6] = pn
            P[6, i] = pn
            pn = (b0 * e[3] + b1 * e[4] + b2 * e[5]) + (q0 * ka[3] + q1 * ka[4] + q2 * ka[5])
            P[i, 7] = pn
            P[7, i] = pn
            pn = (b0 * e[6] + b1 * e[7] + b2 * e[8]) + (q0 * ka[6] + q1 * ka[7] + q2 * ka[8])
            P[i, 8] = pn
            P[8, i] = pn
            X[i] += k0 * n0 + k1 * n1 + k2 * n2
    # attitude block: A_th P_thth A_th^T + K_th R K_th^T, upper triangle mirrored
    ea = _mm3(e, a)
    kr = _mm3(ka, rr)
    P[6, 6] = (ea[0] * e[0] + ea[1] * e[1] + ea[2] * e[2]) + (kr[0] * ka[0] + kr[1] * ka[1] + kr[2] * ka[2])
    P[6, 7] = (ea[0] * e[3] + ea[1] * e[4] + ea[2] * e[5]) + (kr[0] * ka[3] + kr[1] * ka[4] + kr[2] * ka[5])
    P[6, 8] = (ea[0] * e[6] + ea[1] * e[7] + ea[2] * e[8]) + (kr[0] * ka[6] + kr[1] * ka[7] + kr[2] * ka[8])
    P[7, 7] = (ea[3] * e[3] + ea[4] * e[4] + ea[5] * e[5]) + (kr[3] * ka[3] + kr[4] * ka[4] + kr[5] * ka[5])
    P[7, 8] = (ea[3] * e[6] + ea[4] * e[7] + ea[5] * e[8]) + (kr[3] * ka[6] + kr[4] * ka[7] + kr[5] * ka[8])
    P[8, 8] = (ea[6] * e[6] + ea[7] * e[7] + ea[8] * e[8]) + (kr[6] * ka[6] + kr[7] * ka[7] + kr[8] * ka[8])
    P[7, 6] = P[6, 7]
    P[8, 6] = P[6, 8]
    P[8, 7] = P[7, 8]
    _reset_attitude3_noalloc(
        X,
        P,
        ka[0] * n0 + ka[1] * n1 + ka[2] * n2,
        ka[3] * n0 + ka[4] * n1 + ka[5] * n2,
        ka[6] * n0 + ka[7] * n1 + ka[8] * n2,
    )
    ST_F[STF_D2 + kind] = d2
    ST_I[COUNT_ACCEPTED, kind] += 1
    ST_F[STF_SINCE] = 0.0
    if ST_F[STF_UW_LEFT] > 0.0:
        ST_F[STF_UW_LEFT] -= 1.0
    return ST_ACCEPTED


# ---- batch loops: the same per-filter code over a leading axis ---------------------------------------


@njit(cache=True)
def predict_batch(X, P, ST_I, ST_F, W, A, dt, PRM, out):
    for b in range(X.shape[0]):
        out[b] = predict_one(X[b], P[b], ST_I[b], ST_F[b], W[b], A[b], dt, PRM)


@njit(cache=True)
def update_range_batch(X, P, ST_I, ST_F, PRM, anchors, z, sigma, mask, gate, out):
    for b in range(X.shape[0]):
        if mask[b]:
            out[b] = update_range_one(X[b], P[b], ST_I[b], ST_F[b], PRM, anchors[b], z[b], sigma[b], gate)
        else:
            out[b] = ST_SKIPPED


@njit(cache=True)
def update_features_batch(
    X, P, ST_I, ST_F, PRM, markers, f_cam, sigma, target_cov, cam_pos_body, R_body_cam, mask, gate, out
):
    for b in range(X.shape[0]):
        if mask[b]:
            out[b] = update_features_one(
                X[b], P[b], ST_I[b], ST_F[b], PRM, markers[b], f_cam[b], sigma[b], target_cov[b],
                cam_pos_body, R_body_cam, gate,
            )  # fmt: skip
        else:
            out[b] = ST_SKIPPED


@njit(cache=True)
def update_pose_batch(
    X, P, ST_I, ST_F, PRM, p_t, q_t, t_cam, q_ct, cov_cam, target_cov, cam_pos_body, R_body_cam, q_body_cam,
    mask, gate, out,
):  # fmt: skip
    for b in range(X.shape[0]):
        if mask[b]:
            out[b] = update_pose_one(
                X[b], P[b], ST_I[b], ST_F[b], PRM, p_t[b], q_t[b], t_cam[b], q_ct[b], cov_cam[b],
                target_cov[b], cam_pos_body, R_body_cam, q_body_cam, gate,
            )  # fmt: skip
        else:
            out[b] = ST_SKIPPED


@njit(cache=True)
def update_attitude_batch(X, P, ST_I, ST_F, PRM, q_meas, cov_body, mask, gate, out):
    for b in range(X.shape[0]):
        if mask[b]:
            out[b] = update_attitude_one(X[b], P[b], ST_I[b], ST_F[b], PRM, q_meas[b], cov_body[b], gate)
        else:
            out[b] = ST_SKIPPED


@njit(cache=True)
def max_eig_sym3(a00, a01, a02, a11, a12, a22):
    """Largest eigenvalue of a symmetric 3x3 matrix in closed form (Smith 1961, "Eigenvalues of a
    symmetric 3 x 3 matrix", Comm. ACM 4(4)): the trigonometric solution of the characteristic cubic."""
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    if p1 == 0.0:
        return max(a00, max(a11, a22))
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p = np.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1) / 6.0)
    det = b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02) + a02 * (a01 * a12 - b11 * a02)
    r = det / (2.0 * p * p * p)
    r = min(1.0, max(-1.0, r))
    return q + 2.0 * p * np.cos(np.arccos(r) / 3.0)


@njit(cache=True)
def max_sigma_pos_batch(P, out):
    """``sqrt`` of the largest eigenvalue of each filter's position covariance block: the largest
    position standard deviation [m] (Algorithm 1's max(sigma_pos))."""
    for b in range(P.shape[0]):
        lam = max_eig_sym3(P[b, 0, 0], P[b, 0, 1], P[b, 0, 2], P[b, 1, 1], P[b, 1, 2], P[b, 2, 2])
        out[b] = np.sqrt(max(lam, 0.0))
