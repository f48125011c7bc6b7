r"""Ten cold-gas nozzles of a TPODS module: geometry, force/torque allocation, total impulse.

Paper sec. II: "ten nozzles arranged in 'X' configuration on each opposite face to enable 6-DOF" [18].
The exact layout of the hardware is not in the paper; this module builds one with the stated properties.

Geometry (``face_axis = "x"``; ``"y"`` and ``"z"`` permute the axes cyclically: (x, y, z) -> (y, z, x) ->
(z, x, y)). On each of the two faces with outward normal ``n = +x`` and ``n = -x`` (at ``x = +-h``,
``h = half_size_m``) sit five nozzles: one at the face centre and four at the corners of an "X", at
``+-c`` (``c = corner_offset_m``) along both in-plane axes. The +x face seen from outside (x towards
the viewer, y right, z up)::

         +z
     2 .   |   . 1        0, 5  centre nozzles: thrust -n, no torque
        \  |  /           1-4   corners of the +x face, 6-9 of the -x face, both in the (y, z) order
         \ | /                  (+c, +c), (-c, +c), (-c, -c), (+c, -c)
    ------ 0 ------ +y    swirl sign s_k of the k-th corner of a face (k = 0..3): + - + -
         / | \
        /  |  \
     3 .   |   . 4

Direction convention: a nozzle's *thrust direction* ``d`` is the force it puts on the vehicle, the
opposite of its exhaust. Centre nozzles push along ``-n`` (exhaust straight out of the face). A corner
nozzle's thrust is tilted by ``cant_deg`` from ``-n``; its in-plane part points at the face centre
(``-e_r``: the exhaust leans outward, so the four plumes diverge), turned by ``swirl_deg`` towards the
tangent ``s_k e_t`` (``e_r`` the in-plane unit vector from the face centre to the nozzle, ``e_t = n x e_r``)::

    d = cos(cant) (-n) + sin(cant) (-cos(swirl) e_r + s_k sin(swirl) e_t)

Why it positively spans R^6 (every wrench is reachable with thrusts >= 0). Two diagonally opposite
corners of a face (same ``s_k``, opposite ``e_r`` and ``e_t``) fired together cancel each other's
in-plane force and pitch/yaw torque and leave ``-2 cos(cant) n`` and a roll torque
``2 s_k sin(cant) sin(swirl) sqrt(2) c n``; one corner alone adds in-plane force and pitch/yaw torque of
a sign set by its corner. The two diagonals of a face roll in opposite senses and the two faces push in
opposite senses, so firing all ten nozzles equally gives zero net wrench: ``B 1 = 0``. A set of vectors
that spans R^6 and has a strictly positive combination equal to zero spans R^6 positively (Davis 1954,
"Theory of positive linear dependence", Amer. J. Math. 76(4)). ``B`` has rank 6 throughout
``0 < cant, swirl < 90 deg`` (checked on a 60 x 60 grid for every ``face_axis``), so the layout spans
positively for every valid parameter set; :func:`spans_positively` checks any ``B``. Losing one
corner nozzle breaks it; losing a centre nozzle does not (the canted corners also push along ``-n``),
the centre nozzles are there for efficient translation along the face axis.

Allocation: :func:`allocate` solves ``min |B f - w|`` for ``f >= 0`` with :func:`nnls_nb`, a compiled
(numba) implementation of algorithm NNLS of Lawson & Hanson 1974, *Solving Least Squares Problems*, ch. 23,
and then scales the whole thrust vector down uniformly if any nozzle exceeds its limit.
:func:`allocate_nb` does the same inside ``numba.njit`` code (a closed loop compiled as a whole).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linprog

from swarm.errors import ConfigError

__all__ = [
    "N_NOZZLES",
    "Allocation",
    "ThrusterParams",
    "allocate",
    "allocate_nb",
    "allocation_matrix",
    "nnls_nb",
    "nnls_workspace",
    "nozzle_geometry",
    "spans_positively",
    "total_impulse",
]

N_NOZZLES = 10
"""Number of nozzles: five on each of two opposite faces."""

FloatArray = NDArray[np.float64]

_AXES = {"x": (0, 1, 2), "y": (1, 2, 0), "z": (2, 0, 1)}  # face normal, first and second in-plane axis
_CORNERS = ((1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0))  # in-plane signs, counter-clockwise


@dataclass(frozen=True)
class ThrusterParams:
    """Layout and strength of the ten cold-gas nozzles (see the module docstring for the sketch)."""

    face_axis: str = "x"
    """Body axis normal to the two nozzle faces: ``"x"`` puts the nozzles on the +x and -x faces."""
    half_size_m: float = 0.05
    """Distance from the centre of mass to each nozzle face [m]: half the 10 cm cube."""
    corner_offset_m: float = 0.035
    """Offset of each corner nozzle from the face centre along both in-plane axes [m]."""
    cant_deg: float = 30.0
    """Tilt of each corner nozzle's thrust from the inward face normal [deg], in (0, 90)."""
    swirl_deg: float = 45.0
    """Azimuth of the corner thrust's in-plane part from the face-centre direction towards the tangent
    [deg], in (0, 90); its sign alternates around the face so both roll directions exist."""
    max_thrust_n: float = 0.1
    """Largest thrust of one nozzle [N]."""

    def __post_init__(self) -> None:
        if self.face_axis not in _AXES:
            raise ConfigError(f"thrusters.face_axis must be one of 'x', 'y', 'z', got {self.face_axis!r}")
        for name in ("half_size_m", "corner_offset_m", "max_thrust_n"):
            v = getattr(self, name)
            if not (_is_real(v) and math.isfinite(v) and v > 0):
                raise ConfigError(f"thrusters.{name} must be a positive finite number, got {v!r}")
        if self.corner_offset_m > self.half_size_m:
            raise ConfigError(
                f"thrusters.corner_offset_m must be at most half_size_m = {self.half_size_m!r} "
                f"(on the face), got {self.corner_offset_m!r}"
            )
        for name in ("cant_deg", "swirl_deg"):
            v = getattr(self, name)
            if not (_is_real(v) and 0.0 < v < 90.0):
                raise ConfigError(f"thrusters.{name} must be in (0, 90) deg, got {v!r}")


@dataclass(frozen=True)
class Allocation:
    """Result of :func:`allocate`."""

    thrusts_n: FloatArray
    """Commanded thrust of each nozzle (10,) [N], in ``[0, max_thrust_n]``."""
    wrench_achieved: FloatArray
    """``B @ thrusts_n`` (6,): ``[F_body (N), tau_body (N m)]`` about the centre of mass, body frame."""
    saturated: bool
    """True when the least-squares thrusts exceeded the limit and were scaled down."""
    residual: float
    """``|B f - wrench|`` of the non-negative least-squares thrusts before saturation (0 when the
    wrench is reachable at all, which is always for a positively spanning ``B``)."""


def _is_real(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def nozzle_geometry(params: ThrusterParams) -> tuple[FloatArray, FloatArray]:
    """Nozzle positions (10, 3) [m] relative to the centre of mass and unit thrust directions (10, 3),
    both in the body frame; rows 0-4 on the ``+face_axis`` face (centre first), 5-9 on the ``-`` face.

    The formula for ``d`` is in the module docstring.
    """
    i_n, i_a, i_b = _AXES[params.face_axis]
    h, c = params.half_size_m, params.corner_offset_m
    cant, swirl = math.radians(params.cant_deg), math.radians(params.swirl_deg)
    positions = np.zeros((N_NOZZLES, 3))
    directions = np.zeros((N_NOZZLES, 3))
    row = 0
    for face_sign in (1.0, -1.0):
        n = np.zeros(3)
        n[i_n] = face_sign
        positions[row] = h * n
        directions[row] = -n
        row += 1
        for k, (sa, sb) in enumerate(_CORNERS):
            e_r = np.zeros(3)
            e_r[i_a], e_r[i_b] = sa, sb
            e_r /= math.sqrt(2.0)
            e_t = np.cross(n, e_r)
            swirl_sign = 1.0 if k % 2 == 0 else -1.0
            positions[row] = h * n + c * math.sqrt(2.0) * e_r
            in_plane = -math.cos(swirl) * e_r + swirl_sign * math.sin(swirl) * e_t
            directions[row] = math.cos(cant) * (-n) + math.sin(cant) * in_plane
            row += 1
    return positions, directions


def allocation_matrix(params: ThrusterParams) -> FloatArray:
    """Wrench per newton of each nozzle, ``B`` (6, 10): column ``i = [d_i; r_i x d_i]``.

    Rows are ``[F_body (N); tau_body (N m)]`` about the centre of mass in the body frame, so a thrust
    vector ``f`` (10,) [N] gives the wrench ``B @ f`` (rigid-body statics: ``tau = sum r_i x F_i``).
    """
    r, d = nozzle_geometry(params)
    return np.vstack([d.T, np.cross(r, d).T])


def spans_positively(B: ArrayLike, tol: float = 1e-9) -> bool:
    """True when non-negative combinations of the columns of ``B`` (m, n) reach all of R^m.

    Davis 1954 (module docstring): the columns must span R^m (rank m, singular values above ``tol``
    times the largest) and some strictly positive ``f`` must give ``B f = 0``. The second test is the
    linear program ``max t  s.t.  B f = 0, t <= f_i <= 1`` (``scipy.optimize.linprog``, HiGHS);
    ``B`` spans positively iff the optimum is ``t > tol``.
    """
    B = np.asarray(B, dtype=np.float64)
    if B.ndim != 2:
        raise ValueError(f"B must be a 2-D array, got shape {B.shape}")
    m, n = B.shape
    sv = np.linalg.svd(B, compute_uv=False)
    if len(sv) < m or sv[-1] <= tol * sv[0]:
        return False
    # Variables (f_1..f_n, t): maximise t, f_i - t >= 0, B f = 0, 0 <= f_i <= 1.
    cost = np.zeros(n + 1)
    cost[-1] = -1.0
    res = linprog(
        cost,
        A_ub=np.hstack([-np.eye(n), np.ones((n, 1))]),
        b_ub=np.zeros(n),
        A_eq=np.hstack([B, np.zeros((m, 1))]),
        b_eq=np.zeros(m),
        bounds=[(0.0, 1.0)] * n + [(None, None)],
        method="highs",
    )
    return bool(res.status == 0 and -res.fun > tol)


# ------------------------------------------------------------------------------ compiled NNLS (numba)

_EPS = float(np.finfo(np.float64).eps)
_TOL_FACTOR = 10.0
"""The tolerances of :func:`nnls_nb` are ``_TOL_FACTOR * max(m, n) * eps`` times the problem's scale."""


@numba.njit(cache=True)
def nnls_workspace(m: int, n: int) -> tuple[FloatArray, NDArray[np.int64]]:
    """Scratch arrays ``(work, iwork)`` for :func:`nnls_nb` on an ``(m, n)`` problem (allocated here, once;
    reuse them for every call). With ``k = min(m, n)``: ``work`` float64 ``(m k + 2 k + 2 m + n,)``,
    ``iwork`` int64 ``(1 + n + k,)``. Compiled; also callable from Python."""
    k = min(m, n)
    return np.empty(m * k + 2 * k + 2 * m + n), np.empty(1 + n + k, dtype=np.int64)


@numba.njit(cache=True)
def _apply_reflector(qr, m, q, tau, y, off):
    """``y[off + q : off + m] <- H_q y[...]``: the Householder reflector ``H_q = I - tau u u^T`` stored in
    column ``q`` of ``qr`` (``u = [1, qr[q m + q + 1 : q m + m]]``, acting on rows ``q..m-1``)."""
    if tau == 0.0:
        return
    base = q * m
    s = y[off + q]
    for i in range(q + 1, m):
        s += qr[base + i] * y[off + i]
    s *= tau
    y[off + q] -= s
    for i in range(q + 1, m):
        y[off + i] -= s * qr[base + i]


@numba.njit(cache=True)
def _load_column(A, j, work, p, m, o_tau):
    """Column ``j`` of ``A`` into column ``p`` of the QR storage (``work[:m k]``) with the reflectors
    ``H_0..H_{p-1}`` applied (their ``tau`` at ``work[o_tau:]``); returns ``(|A[:, j]|, |rows p..m-1|)``:
    the column's norm and the norm of its part orthogonal to the first ``p`` passive columns."""
    base = p * m
    cn2 = 0.0
    for i in range(m):
        a = A[i, j]
        work[base + i] = a
        cn2 += a * a
    for q in range(p):
        _apply_reflector(work, m, q, work[o_tau + q], work, base)
    pn2 = 0.0
    for i in range(p, m):
        pn2 += work[base + i] * work[base + i]
    return math.sqrt(cn2), math.sqrt(pn2)


@numba.njit(cache=True)
def _make_reflector(qr, p, m, perp):
    """Householder reflector zeroing rows ``p+1..m-1`` of column ``p`` of ``qr`` (LAPACK ``dlarfg``
    convention, ``perp > 0`` the norm of rows ``p..m-1``): stores ``R[p, p] = beta = -sign(alpha) perp``
    and ``u[1:]`` in place, returns ``tau`` (in [1, 2])."""
    base = p * m
    alpha = qr[base + p]
    if perp == 0.0:
        return 0.0  # a zero column: never passive (the independence test rejects it)
    beta = -perp if alpha >= 0.0 else perp
    scale = 1.0 / (alpha - beta)
    for i in range(p + 1, m):
        qr[base + i] *= scale
    qr[base + p] = beta
    return (beta - alpha) / beta


@numba.njit(cache=True)
def nnls_nb(A, b, x, work, iwork, maxiter=-1):
    """``x = argmin |A x - b|_2`` subject to ``x >= 0``; returns ``|A x - b|_2``. Compiled (numba).

    Algorithm NNLS of Lawson & Hanson, *Solving Least Squares Problems*, Prentice-Hall 1974 (SIAM 1995),
    ch. 23 (the active-set method ``scipy.optimize.nnls`` also implements). Variables are either zero
    (set Z) or passive (set P, free).

    * Outer loop: the dual vector ``w = A^T (b - A x)`` (minus the gradient of ``|A x - b|^2 / 2``); if no
      ``w_j`` with ``j`` in Z exceeds ``tol_w``, ``x`` satisfies the KKT conditions and is returned.
      Otherwise the ``j`` with the largest ``w_j`` moves to P (ties within ``tol_w``: the lowest ``j``;
      the cube's symmetry makes exact ties, which round-off would otherwise break either way), provided
      its column is independent of the passive ones (its part orthogonal to them exceeds
      ``tol |A[:, j]|``) and its value in the least-squares solution on P + {j} is positive (L&H's guard
      against round-off); else it is skipped for this outer iteration and the next ``w_j`` is tried.
    * Inner loop: ``z`` = the unconstrained least-squares solution on the columns of P (zero on Z). If
      ``z > 0`` on P, ``x = z``, back to the outer loop. Otherwise step from ``x`` towards ``z`` as far as
      feasibility allows (``alpha = min x_j / (x_j - z_j)`` over ``z_j <= 0``), move the variable that
      hit zero (and any other that is ``<= 0``) back to Z, and solve again.

    The passive least-squares problems are solved by Householder QR of the passive columns (``R`` and the
    reflectors stored column by column in ``work``, with ``Q^T b``): a column entering P is appended in
    ``O(m p)``; after a column leaves, the ``p <= min(m, n)`` passive columns are refactored from scratch
    (``O(m p^2)``, simpler than L&H's Givens down-dates and as cheap at these sizes).

    Tolerances, with ``tol = 10 max(m, n) eps`` (``eps`` = 2.2e-16), scale-invariant in ``A`` and ``b``:
    the dual test is ``w_j > tol_w = tol |A| (|b| + |A| |x|_1)`` with ``|A|`` the largest column norm (a
    bound on the round-off in ``A^T (b - A x)``; L&H and scipy test ``w_j > 0`` and rely on the two
    guards alone), the independence test ``> tol |A[:, j]|`` (L&H: 100 ulp of the column's part in the
    span of P). ``b = 0`` or ``A = 0`` give ``x = 0`` at once.

    Iteration cap: each passive least-squares solve counts as one iteration, at most ``maxiter``
    (``< 0``: ``3 n``, scipy's default; the cube needs 6-10). On reaching it the current iterate is
    returned, with its residual: feasible (``x >= 0``) and no worse than the earlier iterates (the
    residual never increases), but not necessarily optimal; ``iwork[0]`` is then 1 (0 after
    convergence). scipy raises ``RuntimeError`` instead.

    Args:
        A: ``(m, n)`` float64, C-contiguous, finite (not checked here).
        b: ``(m,)`` float64, finite.
        x: ``(n,)`` float64, overwritten with the solution.
        work, iwork: scratch from :func:`nnls_workspace` (or longer); ``iwork[0]`` is the status on return.
        maxiter: the iteration cap, ``< 0`` for ``3 n``.

    Nothing is allocated. The solution is a basic one: at most ``min(m, n)`` positive entries, on
    linearly independent columns. Cost on the cube's ``B`` (6, 10), random wrenches (AMD EPYC, ``timeit``
    best of 15, mean over 1000 wrenches, 6.3 iterations on average): 1.6 us per call from compiled code,
    2.4 us from Python; ``scipy.optimize.nnls`` 12.8 us.
    """
    m, n = A.shape
    k = min(m, n)
    if b.shape[0] != m or x.shape[0] != n:
        raise ValueError("nnls_nb: b must have shape (m,) and x shape (n,) for A of shape (m, n)")
    if work.shape[0] < m * k + 2 * k + 2 * m + n or iwork.shape[0] < 1 + n + k:
        raise ValueError("nnls_nb: work or iwork too short (use nnls_workspace(m, n))")
    if maxiter < 0:
        maxiter = 3 * n
    # work: qr (m, k) column-major | tau (k) | z (k) | qtb (m) | r (m) | w (n)
    # iwork: status | in_p (n): 1 if passive | P (k): the passive indices, in QR order
    o_tau = m * k
    o_z = o_tau + k
    o_qtb = o_z + k
    o_r = o_qtb + m
    o_w = o_r + m
    o_p = 1 + n
    tol = _TOL_FACTOR * max(m, n) * _EPS
    a2 = 0.0
    for j in range(n):
        s = 0.0
        for i in range(m):
            s += A[i, j] * A[i, j]
        a2 = max(a2, s)
    anorm = math.sqrt(a2)
    bnorm = 0.0
    for i in range(m):
        bnorm += b[i] * b[i]
        work[o_qtb + i] = b[i]
    bnorm = math.sqrt(bnorm)
    for j in range(n):
        x[j] = 0.0
        iwork[1 + j] = 0
    p = 0
    iterations = 0
    status = 0
    while p < k:
        # ---- outer loop: dual vector on Z, residual of the current (feasible) x
        for i in range(m):
            work[o_r + i] = b[i]
        xnorm1 = 0.0
        for q in range(p):  # x is zero off P
            j = iwork[o_p + q]
            xj = x[j]
            xnorm1 += xj
            for i in range(m):
                work[o_r + i] -= A[i, j] * xj
        tol_w = tol * anorm * (bnorm + anorm * xnorm1)
        for j in range(n):
            s = 0.0
            if iwork[1 + j] == 0:
                for i in range(m):
                    s += A[i, j] * work[o_r + i]
            work[o_w + j] = s
        entered = False
        while True:
            jmax = -1
            wmax = tol_w
            for j in range(n):
                if iwork[1 + j] == 0 and work[o_w + j] > wmax:
                    wmax = work[o_w + j]
                    jmax = j
            if jmax < 0:
                break
            for j in range(jmax):  # ties (to round-off): the lowest index
                if iwork[1 + j] == 0 and work[o_w + j] > tol_w and work[o_w + j] >= wmax - tol_w:
                    jmax = j
                    break
            cnorm, perp = _load_column(A, jmax, work, p, m, o_tau)
            if perp > tol * cnorm:
                # trial reflector for the new column; R[p, p] = beta. ztest = new variable's value in
                # the least-squares solution on P + {jmax} (the last unknown of the triangular system).
                t = _make_reflector(work, p, m, perp)
                base = p * m
                s = work[o_qtb + p]
                for i in range(p + 1, m):
                    s += work[base + i] * work[o_qtb + i]
                s *= t
                ztest = (work[o_qtb + p] - s) / work[base + p]
                if ztest > 0.0:
                    work[o_tau + p] = t
                    _apply_reflector(work, m, p, t, work, o_qtb)
                    iwork[o_p + p] = jmax
                    iwork[1 + jmax] = 1
                    p += 1
                    entered = True
                    break
            work[o_w + jmax] = 0.0  # rejected until the next outer iteration
        if not entered:
            break  # KKT conditions hold
        # ---- inner loop: least squares on P, step back to stay feasible
        while True:
            iterations += 1
            if iterations > maxiter:
                status = 1
                break
            for q in range(p - 1, -1, -1):  # back substitution R z = (Q^T b)[:p]
                s = work[o_qtb + q]
                for c in range(q + 1, p):
                    s -= work[c * m + q] * work[o_z + c]
                work[o_z + q] = s / work[q * m + q]
            alpha = 2.0
            qmin = -1
            for q in range(p):
                zq = work[o_z + q]
                if zq <= 0.0:
                    xq = x[iwork[o_p + q]]
                    t = xq / (xq - zq)
                    if t < alpha:
                        alpha = t
                        qmin = q
            if qmin < 0:
                for q in range(p):
                    x[iwork[o_p + q]] = work[o_z + q]
                break
            for q in range(p):
                j = iwork[o_p + q]
                x[j] += alpha * (work[o_z + q] - x[j])
            x[iwork[o_p + qmin]] = 0.0
            kept = 0
            for q in range(p):
                j = iwork[o_p + q]
                if x[j] > 0.0:
                    iwork[o_p + kept] = j
                    kept += 1
                else:
                    x[j] = 0.0
                    iwork[1 + j] = 0
            p = kept
            for i in range(m):
                work[o_qtb + i] = b[i]
            for q in range(p):  # refactor the remaining passive columns
                _, perp = _load_column(A, iwork[o_p + q], work, q, m, o_tau)
                work[o_tau + q] = _make_reflector(work, q, m, perp)
                _apply_reflector(work, m, q, work[o_tau + q], work, o_qtb)
        if status != 0:
            break
    iwork[0] = status
    r2 = 0.0
    for i in range(m):
        s = b[i]
        for j in range(n):
            s -= A[i, j] * x[j]
        r2 += s * s
    return math.sqrt(r2)


@numba.njit(cache=True)
def allocate_nb(wrench, B, max_thrust_n, f_out, wrench_out):
    """:func:`allocate` for compiled code: thrusts into ``f_out`` (n,), ``B @ f_out`` into ``wrench_out``
    (6,); returns ``saturated``.

    ``wrench`` (6,) ``[F_body (N), tau_body (N m)]``, ``B`` (6, n) from :func:`allocation_matrix`, both
    float64, C-contiguous and finite (not checked here), ``max_thrust_n`` > 0 (``inf``: no saturation).
    :func:`nnls_nb`, then if ``max(f) > max_thrust_n`` all thrusts scaled by ``max_thrust_n / max(f)``.
    Allocates only the two small scratch arrays of :func:`nnls_workspace`.
    """
    m, n = B.shape
    if m != 6 or wrench.shape[0] != 6 or wrench_out.shape[0] != 6 or f_out.shape[0] != n:
        raise ValueError("allocate_nb: wrench and wrench_out must have shape (6,), B (6, n), f_out (n,)")
    work, iwork = nnls_workspace(m, n)
    nnls_nb(B, wrench, f_out, work, iwork)
    peak = 0.0
    for j in range(n):
        peak = max(peak, f_out[j])
    saturated = peak > max_thrust_n
    if saturated:
        scale = max_thrust_n / peak
        for j in range(n):
            f_out[j] *= scale
    for i in range(m):
        s = 0.0
        for j in range(n):
            s += B[i, j] * f_out[j]
        wrench_out[i] = s
    return saturated


@numba.njit(cache=True)
def _nnls_checked(A, b, x):
    """:func:`nnls_nb` with its own scratch, one compiled call for :func:`allocate`; ``nan`` (and ``x``
    untouched) when ``A`` is not finite."""
    m, n = A.shape
    for i in range(m):
        for j in range(n):
            if not math.isfinite(A[i, j]):
                return math.nan
    work, iwork = nnls_workspace(m, n)
    return nnls_nb(A, b, x, work, iwork)


def allocate(wrench_body: ArrayLike, B: ArrayLike, max_thrust_n: float) -> Allocation:
    """Non-negative nozzle thrusts (10,) [N] producing the wanted body wrench, within the limit.

    ``wrench_body`` (6,) is ``[F_body (N), tau_body (N m)]`` about the centre of mass, ``B`` (6, 10) from
    :func:`allocation_matrix`, ``max_thrust_n`` the per-nozzle limit [N] (``inf`` disables saturation).

    1. ``f = argmin |B f - w|`` subject to ``f >= 0``: :func:`nnls_nb` (Lawson & Hanson 1974, active-set
       NNLS, compiled; it gives the same thrusts as ``scipy.optimize.nnls``, which this used before, to
       round-off). For a positively spanning ``B`` the fit is exact. The solution is a basic one (at
       most 6 nozzles on), neither minimum-impulse nor minimum-peak.
    2. If ``max(f) > max_thrust_n``, ``f <- f * max_thrust_n / max(f)``. One common factor keeps the
       achieved wrench parallel to the request (same direction of force and torque together, shorter),
       which keeps the attitude and translation loops from being steered off their axes by saturation.

    :func:`allocate_nb` is the same for compiled callers (without the checks and the dataclass).

    Cost (AMD EPYC, ``timeit`` on the default ``B``, random wrenches): the NNLS 1.6 us (scipy's was
    13 us), a whole call 9-13 us depending on load, almost all of it the Python-side checks, array
    handling and the dataclass; :func:`allocate_nb` from compiled code 1.7 us.
    """
    w = np.asarray(wrench_body, dtype=np.float64)
    if w.shape != (6,):
        raise ValueError(f"wrench_body must have shape (6,), got {w.shape}")
    if not np.isfinite(w).all():
        raise ValueError(f"wrench_body must be finite, got {w!r}")
    B = np.ascontiguousarray(B, dtype=np.float64)
    if B.ndim != 2 or B.shape[0] != 6:
        raise ValueError(f"B must have shape (6, n), got {B.shape}")
    if not (max_thrust_n > 0):
        raise ValueError(f"max_thrust_n must be positive, got {max_thrust_n!r}")
    f = np.empty(B.shape[1])
    residual = _nnls_checked(B, np.ascontiguousarray(w), f)
    if math.isnan(residual):
        raise ValueError("B must be finite")
    peak = float(f.max()) if f.size else 0.0
    saturated = peak > max_thrust_n
    if saturated:
        f = f * (max_thrust_n / peak)
    return Allocation(thrusts_n=f, wrench_achieved=B @ f, saturated=saturated, residual=float(residual))


def total_impulse(thrusts_n: ArrayLike, dt_s: ArrayLike) -> float:
    """Total impulse [N s]: sum over samples and nozzles of ``|f| dt`` (the paper's
    Table II "total impulse").

    ``thrusts_n`` is a thrust history ``(T, n_nozzles)`` [N] (or one sample ``(n_nozzles,)``), each row
    held for ``dt_s`` [s]: a scalar or one duration per row ``(T,)``.
    """
    f = np.asarray(thrusts_n, dtype=np.float64)
    if f.ndim == 1:
        f = f[None, :]
    if f.ndim != 2:
        raise ValueError(f"thrusts_n must have shape (T, n) or (n,), got {np.shape(thrusts_n)}")
    dt = np.asarray(dt_s, dtype=np.float64)
    if dt.ndim == 0:
        dt = np.full(f.shape[0], float(dt))
    if dt.shape != (f.shape[0],):
        raise ValueError(f"dt_s must be a scalar or have shape ({f.shape[0]},), got {dt.shape}")
    if np.any(dt < 0) or not np.all(np.isfinite(dt)) or not np.all(np.isfinite(f)):
        raise ValueError("thrusts_n and dt_s must be finite and dt_s non-negative")
    return float(np.sum(np.abs(f).sum(axis=1) * dt))
