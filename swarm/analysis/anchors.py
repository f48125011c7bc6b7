"""Paper section V-D: steady-state position covariance from the UWB anchor layout, and from it the
steady-state probabilities of Algorithm 1's [REORIENT, ALIGN] chain, over a grid of deployment points.

**Filter model.** The translation filter of the estimator (paper sec. IV, tandem structure): state
``(p, v)`` in the navigation frame, white-noise acceleration of PSD ``q`` (``estimator.accel_psd_m2_s3``),
ranges to the anchors with noise ``sigma_r`` (``estimator.sigma_range_m``). The ranges come in round robin,
one anchor per exchange at ``uwb.rate_hz``; over one cycle of the ``m`` anchors (``T = m / rate``) the
filter sees every anchor once, which the steady-state analysis takes as one stacked measurement per cycle:

    F = [[I, T I], [0, I]],   Q = q [[T^3/3 I, T^2/2 I], [T^2/2 I, T I]]   (Bar-Shalom, Li & Kirubarajan
    2001, eq. 6.2.3-8, the exact discretisation the filter's predict composes tick by tick),
    H = [u_i^T, 0] for each anchor i, u_i the unit vector from anchor i to the point,  R = sigma_r^2 I_m.

The steady-state prior covariance solves the filter DARE
``P = F P F^T - F P H^T (H P H^T + R)^-1 H P F^T + Q``
(:func:`scipy.linalg.solve_discrete_are` with ``a = F^T``, ``b = H^T``: the dual of the control DARE,
Anderson & Moore 1979, *Optimal Filtering*, sec. 4.4); the posterior is ``P - P H^T S^-1 H P``.
``max(sigma_pos)`` is the square root of the largest eigenvalue of the posterior's position block, what
:attr:`swarm.core.estimator.PoseEstimator.sigma_pos_max_m` reports. Neglected, and small: the tag lever
arm (the point is the tag), the tandem filter's attitude consider term (5 cm x 0.5 deg ~ 0.4 mm against
2 cm), and the staggering of the ranges within a cycle (:func:`periodic_steady_state` iterates the
round robin tick by tick to measure it).

**Probabilities.** Algorithm 1's chain (:func:`swarm.core.mdp.steady_state_probabilities`) with
``sigma = max(sigma_pos)``, the switch radius ``r2`` and the Mahalanobis distance ``d`` of a consistent
filter (``d = 1``: the RMS of unit-variance innovations), taken at the worst point of the REORIENT leg,
``min over r in (r_d, r2]`` of the stationary ALIGN probability ``pi2``. ``pi2`` falls as ``sigma`` grows,
and Algorithm 1 turns to ALIGN when ``pi2 <= 0.6``.

**Beyond the paper.** :func:`optimise_layout` places the anchors anywhere on the faces of the mothership
(the box through the paper's four anchors) to maximise the worst-case ``pi2`` over the grid, with
:func:`scipy.optimize.differential_evolution` on a coarse grid and a batched doubling solution of the same
DARE (:func:`dare_batch`, structured doubling algorithm, Chu, Fan & Lin 2005), then evaluates the result on
the full grid with scipy's solver.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_discrete_are

from swarm.core.mdp import MdpParams, steady_state_probabilities
from swarm.errors import ConfigError

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class AnchorStudyParams:
    """Grid, chain and layout parameters of the section V-D study."""

    margin_m: float = 0.5
    """The grid is the box around the scenario's vehicles' initial positions, grown by this [m]."""
    spacing_m: float = 0.1
    """Grid spacing [m]."""
    r2_m: float | None = None
    """Switch radius ``r2`` of the chain [m]; None: the fixed policy's (the worst case of paper Fig. 6)."""
    d: float = 1.0
    """Mahalanobis distance of the chain (1: a consistent filter)."""
    r_samples: int = 64
    """Ranges sampled on ``(r_d, r2]`` for the worst-case ``pi2``."""
    mothership_half_extents_m: Vec3 = (1.0, 0.2, 0.5)
    """Half sides of the mothership box centred at the origin [m]: the box whose corners the paper's four
    anchors occupy. Anchors of the optimised layout lie on its faces."""
    optimise_spacing_m: float = 0.25
    """Coarser grid spacing used inside the optimiser [m] (the result is re-evaluated on the full grid)."""
    optimise_iterations: int = 25
    """Generations of differential evolution."""
    optimise_seed: int = 0
    """Seed of differential evolution."""

    def __post_init__(self) -> None:
        for name in ("spacing_m", "optimise_spacing_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"anchors.{name} must be a positive number, got {v!r}")
        if not (math.isfinite(self.margin_m) and self.margin_m >= 0):
            raise ConfigError(f"anchors.margin_m must be a non-negative number, got {self.margin_m!r}")
        if self.r2_m is not None and not (math.isfinite(self.r2_m) and self.r2_m > 0):
            raise ConfigError(f"anchors.r2_m must be a positive number, got {self.r2_m!r}")
        if not (math.isfinite(self.d) and self.d >= 0):
            raise ConfigError(f"anchors.d must be a non-negative number, got {self.d!r}")
        if any(not (h > 0) for h in self.mothership_half_extents_m):
            raise ConfigError(
                f"anchors.mothership_half_extents_m must be positive, got {self.mothership_half_extents_m!r}"
            )


# ----------------------------------------------------------------------------------------------- model


def cycle_model(sc) -> tuple[np.ndarray, np.ndarray, float, float]:
    """``(F, Q, T, sigma_r)`` of the translation filter over one round-robin cycle (module docstring)."""
    T = len(sc.anchors_m) / sc.uwb.rate_hz
    q = sc.estimator.accel_psd_m2_s3
    eye, zero = np.eye(3), np.zeros((3, 3))
    F = np.block([[eye, T * eye], [zero, eye]])
    Q = q * np.block([[T**3 / 3 * eye, T**2 / 2 * eye], [T**2 / 2 * eye, T * eye]])
    return F, Q, T, float(sc.estimator.sigma_range_m)


def range_jacobians(points_m: np.ndarray, anchors_m: np.ndarray) -> np.ndarray:
    """``(N, m, 6)`` range Jacobians ``[u^T, 0]`` at ``points_m (N, 3)`` for ``anchors_m (m, 3)`` (nav)."""
    d = np.asarray(points_m, dtype=float)[:, None, :] - np.asarray(anchors_m, dtype=float)[None, :, :]
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return np.concatenate([u, np.zeros_like(u)], axis=-1)


def dare_prior(F: np.ndarray, Q: np.ndarray, H: np.ndarray, sigma_r: float) -> np.ndarray:
    """Steady-state prior covariance (6, 6) of the filter DARE with scipy (module docstring)."""
    R = sigma_r**2 * np.eye(H.shape[0])
    return solve_discrete_are(F.T, H.T, Q, R)


def posterior(P: np.ndarray, H: np.ndarray, sigma_r: float) -> np.ndarray:
    """Covariance after the stacked update, ``P - P H^T (H P H^T + R)^-1 H P``; batched over leading axes."""
    R = sigma_r**2 * np.eye(H.shape[-2])
    PHt = P @ np.swapaxes(H, -1, -2)
    S = H @ PHt + R
    return P - PHt @ np.linalg.solve(S, np.swapaxes(PHt, -1, -2))


def sigma_pos_max(P: np.ndarray) -> np.ndarray:
    """Square root of the largest eigenvalue of the position block ``P[..., :3, :3]`` [m]."""
    return np.sqrt(np.linalg.eigvalsh(P[..., :3, :3])[..., -1])


def dare_batch(
    F: np.ndarray, Q: np.ndarray, H: np.ndarray, sigma_r: float, tol: float = 1e-13, max_iter: int = 60
) -> np.ndarray:
    """The prior DARE solution for a batch of measurement matrices ``H (N, m, 6)``: ``(N, 6, 6)``.

    Structured doubling algorithm (Chu, Fan & Lin 2005, "A structure-preserving doubling algorithm for
    discrete-time algebraic Riccati equations", Alg. SDA), for ``X = A^T X (I + G X)^-1 A + H0`` with
    ``A = F^T``, ``G = H^T R^-1 H``, ``H0 = Q``::

        A' = A (I + G X_k)^-1 A,  G' = G + A (I + G X_k)^-1 G A^T,  X' = X_k + A^T X_k (I + G X_k)^-1 A

    converging quadratically (``X_k`` doubles the horizon each step). Agrees with
    :func:`scipy.linalg.solve_discrete_are` (tested).
    """
    N = H.shape[0]
    n = F.shape[0]
    A = np.broadcast_to(F.T, (N, n, n)).copy()
    G = np.swapaxes(H, -1, -2) @ H / sigma_r**2
    X = np.broadcast_to(Q, (N, n, n)).copy()
    eye = np.eye(n)
    for _ in range(max_iter):
        M = np.linalg.inv(eye + G @ X)
        MA = M @ A
        At = np.swapaxes(A, -1, -2)
        X_new = X + At @ X @ MA
        G = G + A @ M @ G @ At
        A = A @ MA
        done = np.max(np.abs(X_new - X)) <= tol * np.max(np.abs(X_new))
        X = X_new
        if done:
            break
    return 0.5 * (X + np.swapaxes(X, -1, -2))


def periodic_steady_state(sc, point_m, anchors_m=None, cycles: int = 4000) -> tuple[float, float]:
    """``(max sigma_pos before, after)`` the last range of a cycle, iterating the filter's own round robin
    tick by tick (predict every IMU tick, one scalar range every ``imu/uwb`` ticks, anchors in turn) to
    steady state: the reference the stacked DARE approximates."""
    anchors = np.asarray(sc.anchors_m if anchors_m is None else anchors_m, dtype=float)
    dt = sc.dt_s
    every = sc.every(sc.uwb.rate_hz)
    q = sc.estimator.accel_psd_m2_s3
    sr2 = sc.estimator.sigma_range_m**2
    eye, zero = np.eye(3), np.zeros((3, 3))
    F = np.block([[eye, dt * eye], [zero, eye]])
    Qd = q * np.block([[dt**3 / 3 * eye, dt**2 / 2 * eye], [dt**2 / 2 * eye, dt * eye]])
    Hs = range_jacobians(np.asarray(point_m, dtype=float)[None], anchors)[0]
    P = np.diag([1.0, 1.0, 1.0, 0.1, 0.1, 0.1])
    before = after = math.nan
    for _ in range(cycles):
        for a in range(len(anchors)):
            for _ in range(every):
                P = F @ P @ F.T + Qd
            if a == len(anchors) - 1:
                before = float(sigma_pos_max(P))
            h = Hs[a]
            Ph = P @ h
            P = P - np.outer(Ph, Ph) / (h @ Ph + sr2)
        after = float(sigma_pos_max(P))
    return before, after


# ---------------------------------------------------------------------------------------- probabilities


def align_probability(sigma_m, sc, params: AnchorStudyParams) -> np.ndarray:
    """Worst-case stationary ALIGN probability ``pi2`` over the REORIENT leg ``r in (r_d, r2]`` for
    position uncertainty ``sigma_m`` (any shape) (module docstring)."""
    mdp: MdpParams = sc.mdp
    r2 = sc.fixed.r2_m if params.r2_m is None else params.r2_m
    r = np.linspace(mdp.r_d_m, r2, params.r_samples + 1)[1:]
    sig = np.asarray(sigma_m, dtype=float)
    pi = steady_state_probabilities(sig[..., None], r, r2, params.d, mdp)[..., 1]
    return np.nanmin(pi, axis=-1)


def reorient_probability(sigma_m, sc, params: AnchorStudyParams) -> np.ndarray:
    """``pi1 = 1 - pi2`` at the same worst point."""
    return 1.0 - align_probability(sigma_m, sc, params)


# ----------------------------------------------------------------------------------------------- grids


def grid(
    sc, params: AnchorStudyParams, spacing_m: float | None = None
) -> tuple[list[np.ndarray], np.ndarray]:
    """Axes ``[xs, ys, zs]`` and points ``(N, 3)`` (x fastest... as ``meshgrid(indexing="ij")`` ravels) of
    the deployment grid: the vehicles' initial bounding box grown by ``margin_m``; points inside the
    mothership box are left out of ``points`` (marked NaN)."""
    step = params.spacing_m if spacing_m is None else spacing_m
    pos = np.array([v.position_m for v in sc.vehicles.values()], dtype=float)
    lo, hi = pos.min(axis=0) - params.margin_m, pos.max(axis=0) + params.margin_m
    axes = [np.round(np.arange(lo[i], hi[i] + 1e-9, step), 10) for i in range(3)]
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=-1)
    inside = np.all(np.abs(pts) <= np.asarray(params.mothership_half_extents_m) + 1e-9, axis=1)
    pts[inside] = np.nan
    return axes, pts


def sigma_map(sc, points_m: np.ndarray, anchors_m=None, method: str = "scipy") -> np.ndarray:
    """Steady-state posterior ``max(sigma_pos)`` [m] at each point (N,) (NaN points stay NaN).

    ``method``: ``"scipy"`` (one :func:`scipy.linalg.solve_discrete_are` per point) or ``"doubling"``
    (:func:`dare_batch`, all points at once).
    """
    anchors = np.asarray(sc.anchors_m if anchors_m is None else anchors_m, dtype=float)
    F, Q, _, sr = cycle_model(sc)
    out = np.full(len(points_m), np.nan)
    ok = np.all(np.isfinite(points_m), axis=1)
    H = range_jacobians(points_m[ok], anchors)
    if method == "doubling":
        P = dare_batch(F, Q, H, sr)
    elif method == "scipy":
        P = np.stack([dare_prior(F, Q, h, sr) for h in H])
    else:
        raise ValueError(f"method must be 'scipy' or 'doubling', got {method!r}")
    out[ok] = sigma_pos_max(posterior(P, H, sr))
    return out


# ------------------------------------------------------------------------------------------ optimisation


def box_point(direction: np.ndarray, half_extents: np.ndarray) -> np.ndarray:
    """The point of the box surface ``|x_i| = h_i`` hit by the ray from the centre along ``direction``."""
    d = np.asarray(direction, dtype=float)
    with np.errstate(divide="ignore"):
        s = np.min(np.where(np.abs(d) > 0, np.asarray(half_extents) / np.abs(d), np.inf), axis=-1)
    return d * s[..., None]


def layout_from_angles(x: np.ndarray, half_extents) -> np.ndarray:
    """Anchors ``(m, 3)`` on the mothership's faces from ``x = [az_1, el_1, ..., az_m, el_m]`` [rad]:
    the ray from the box centre at azimuth ``az`` and elevation ``el`` hits the face where the anchor is."""
    a = np.asarray(x, dtype=float).reshape(-1, 2)
    d = np.stack(
        [np.cos(a[:, 1]) * np.cos(a[:, 0]), np.cos(a[:, 1]) * np.sin(a[:, 0]), np.sin(a[:, 1])], axis=-1
    )
    return box_point(d, np.asarray(half_extents, dtype=float))


def angles_from_layout(anchors_m: np.ndarray) -> np.ndarray:
    """The inverse of :func:`layout_from_angles` for anchors on the box surface."""
    a = np.asarray(anchors_m, dtype=float)
    az = np.arctan2(a[:, 1], a[:, 0])
    el = np.arctan2(a[:, 2], np.hypot(a[:, 0], a[:, 1]))
    return np.stack([az, el], axis=-1).ravel()


def optimise_layout(sc, params: AnchorStudyParams) -> dict:
    """Anchors on the mothership's faces minimising the worst-case ``max(sigma_pos)`` over the (coarse)
    grid, which maximises the worst-case ``pi2`` (``pi2`` falls as ``sigma`` grows).

    Two searches: every choice of ``m`` of the box's 8 corners (the widest spreads, where a geometric
    dilution-of-precision optimum tends to sit), then differential evolution over placements anywhere on
    the faces (azimuth/elevation of a ray from the centre, :func:`layout_from_angles`) started from the
    best corner layout. Returns the layout (``"anchors_m"``), its worst ``max(sigma_pos)`` on the coarse
    grid and the paper's, the best, second best and median corner layouts' scores, the face search's,
    and the number of evaluations.
    """
    from itertools import combinations

    from scipy.optimize import differential_evolution

    _, pts = grid(sc, params, params.optimise_spacing_m)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    half = np.asarray(params.mothership_half_extents_m, dtype=float)
    F, Q, _, sr = cycle_model(sc)
    m = len(sc.anchors_m)
    evaluations = 0

    def worst(anchors: np.ndarray) -> float:
        nonlocal evaluations
        evaluations += 1
        H = range_jacobians(pts, anchors)
        with np.errstate(invalid="ignore"):
            s = sigma_pos_max(posterior(dare_batch(F, Q, H, sr), H, sr))
        return float(np.max(s)) if np.all(np.isfinite(s)) else math.inf  # coplanar anchors: unobservable

    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    corners = signs * half
    ranked = sorted((worst(corners[list(c)]), c) for c in combinations(range(len(corners)), m))
    best_corner = ranked[0]
    corner_layout = corners[list(best_corner[1])]
    finite_scores = [w for w, _ in ranked if math.isfinite(w)]
    res = differential_evolution(
        lambda x: worst(layout_from_angles(x, half)),
        [(-math.pi, math.pi), (-math.pi / 2, math.pi / 2)] * m,
        seed=params.optimise_seed,
        maxiter=params.optimise_iterations,
        popsize=10,
        tol=1e-6,
        polish=False,
        x0=angles_from_layout(corner_layout),
        init="sobol",
    )
    anchors = layout_from_angles(res.x, half) if res.fun < best_corner[0] else corner_layout
    return {
        "anchors_m": anchors,
        "worst_sigma_coarse_m": float(min(res.fun, best_corner[0])),
        "paper_worst_sigma_coarse_m": worst(np.asarray(sc.anchors_m, dtype=float)),
        "best_corner_anchors_m": corner_layout.tolist(),
        "best_corner_worst_sigma_coarse_m": float(best_corner[0]),
        "corner_layouts": len(ranked),
        "corner_layouts_observable": len(finite_scores),
        "second_corner_worst_sigma_coarse_m": float(ranked[1][0]),
        "median_corner_worst_sigma_coarse_m": float(np.median(finite_scores)),
        "face_search_worst_sigma_coarse_m": float(res.fun),
        "evaluations": evaluations,
        "message": str(res.message),
    }
