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

Allocation: :func:`allocate` solves ``min |B f - w|`` for ``f >= 0`` with ``scipy.optimize.nnls``
(Lawson & Hanson 1974, *Solving Least Squares Problems*, ch. 23) and then scales the whole thrust vector
down uniformly if any nozzle exceeds its limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linprog, nnls

from swarm.errors import ConfigError

__all__ = [
    "N_NOZZLES",
    "Allocation",
    "ThrusterParams",
    "allocate",
    "allocation_matrix",
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


def allocate(wrench_body: ArrayLike, B: ArrayLike, max_thrust_n: float) -> Allocation:
    """Non-negative nozzle thrusts (10,) [N] producing the wanted body wrench, within the limit.

    ``wrench_body`` (6,) is ``[F_body (N), tau_body (N m)]`` about the centre of mass, ``B`` (6, 10) from
    :func:`allocation_matrix`, ``max_thrust_n`` the per-nozzle limit [N] (``inf`` disables saturation).

    1. ``f = argmin |B f - w|`` subject to ``f >= 0``: ``scipy.optimize.nnls`` (Lawson & Hanson 1974,
       active-set NNLS). For a positively spanning ``B`` the fit is exact. The solution is a basic one
       (at most 6 nozzles on), neither minimum-impulse nor minimum-peak.
    2. If ``max(f) > max_thrust_n``, ``f <- f * max_thrust_n / max(f)``. One common factor keeps the
       achieved wrench parallel to the request (same direction of force and torque together, shorter),
       which keeps the attitude and translation loops from being steered off their axes by saturation.

    Cost (scipy 1.17, AMD EPYC, ``timeit`` best of 7 on the default ``B``): the NNLS 6-12 us, a whole
    call 13-23 us depending on load, i.e. under 0.25 % of one core per vehicle at 100 Hz.
    """
    w = np.asarray(wrench_body, dtype=np.float64)
    if w.shape != (6,):
        raise ValueError(f"wrench_body must have shape (6,), got {w.shape}")
    if not np.isfinite(w).all():
        raise ValueError(f"wrench_body must be finite, got {w!r}")
    B = np.asarray(B, dtype=np.float64)
    if B.ndim != 2 or B.shape[0] != 6:
        raise ValueError(f"B must have shape (6, n), got {B.shape}")
    if not (max_thrust_n > 0):
        raise ValueError(f"max_thrust_n must be positive, got {max_thrust_n!r}")
    f, residual = nnls(B, w)
    peak = float(f.max()) if f.size else 0.0
    saturated = peak > max_thrust_n
    if saturated:
        f = f * (max_thrust_n / peak)
    return Allocation(thrusts_n=f, wrench_achieved=B @ f, saturated=saturated, residual=float(residual))


def total_impulse(thrusts_n: ArrayLike, dt_s: ArrayLike) -> float:
    """Total impulse [N s]: sum over samples and nozzles of ``|f| dt`` (DESIGN.md sec. 3, the paper's
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
