"""Guidance-mode switchers: fixed radii and the Markov-model rule of the paper's Algorithm 1.

The docking guidance (paper section V, Fig. 1, Fig. 4) runs APPROACH -> REORIENT -> ALIGN -> DOCK. Two radii
around the target decide the first two switches: ``r2`` (APPROACH -> REORIENT) and ``r1`` (REORIENT ->
ALIGN). A switcher only *chooses* those radii; the guidance owns the modes and compares the range with them.

* :class:`FixedSwitcher`: ``r2 = 0.8 m``, ``r1 = 0.3 m`` (paper section V-C, the worst case of Fig. 6).
* :class:`MdpSwitcher`: paper Algorithm 1 (section V-B), transcribed from the paper. It starts
  with aggressive radii (``r1 = 0.1``, ``r2 = 0.3``) and, once the range ``r`` is inside the activation radius
  ``r_t``, moves them outward to the current range when the transition probabilities say so::

      while r <= r_t and r > r1:
          if r > r2:
              A11 = (r / r_t) * (1 / (1 + d)) * (1 / ||q_e[1:3]||)
              if A11 <= 0.4: r2 = r                                   # reorient now
          else:
              A22 = (r / r2) * (1 / (1 + d));  A23 = 1 - A22
              A32 = (max(sigma_pos) / sigma_UWB) * ((r2 - r) / (r2 - r_d));  A33 = 1 - A32
              [pi1, pi2] = steady state of [[A22, A23], [A32, A33]]
              if pi2 <= 0.6: r1 = r                                   # align now

  The paper's ``while`` is the guidance loop itself: :meth:`MdpSwitcher.evaluate` runs one pass of the
  body per call (one call per guidance step) and returns ``None`` when the loop condition is false.
  Every pass is recorded as a :class:`Decision` whose :meth:`Decision.as_dict` is the ``"decisions"``
  record of swarm/core/decision_keys.py.

Edge cases (Algorithm 1 is silent on them; each choice is tested):

* Every ``A_ij`` is clipped into ``[0, 1]`` (paper Fig. 4 caption: they are probabilities); ``A23`` and
  ``A33`` are computed from the *clipped* ``A22`` and ``A32`` so each row still sums to 1.
* ``||q_e[1:3]|| = 0`` (already at the docking attitude): ``1 / 0 = +inf``, so ``A11`` clips to 1 and the
  chaser keeps approaching; there is nothing to reorient.
* ``r2 - r_d <= 0``: unreachable with validated :class:`MdpParams` (``r2`` only grows from
  ``r2_init_m > r_d_m``), but guarded: the distance fraction ``(r2 - r) / (r2 - r_d)`` is taken as 1
  (the whole REORIENT-to-contact distance is used up), then ``A32`` is clipped as usual.
* ``A23 + A32 = 0`` (i.e. ``A22 = 1`` and ``A32 = 0``: both states absorbing, e.g. ``d = 0`` at ``r = r2``):
  the 2-state chain has no unique stationary distribution, so ``pi1 = pi2 = None`` and ``r1`` is left
  alone. Nothing in the inputs then says the alignment is at risk (``A32 = 0``), and the next pass at a
  smaller range has ``r / r2 < 1``, hence ``A23 > 0`` and a well-defined ``pi``.
* The state machine is not latched: if the range grows back above ``r1`` (or ``r2``), Algorithm 1 is
  evaluated again and may move the radius outward again; the guidance keeps its modes monotone.

Stationary distributions (paper section V-B, V-D; Norris 1998): :func:`stationary_2state` is the closed
form for two states, :func:`stationary_distribution` the general n-state linear solve, and
:func:`steady_state_probabilities` the [REORIENT, ALIGN] chain of Algorithm 1 as a function of the
position uncertainty, for the anchor-placement study of section V-D.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numba import njit

from swarm.core.decision_keys import DECISION_KEYS as DECISION_KEYS  # re-exported: the keys of its records
from swarm.errors import ConfigError

_ROW_SUM_TOL = 1e-9  # row sums / entries of a transition matrix may be off by rounding, not more


# ------------------------------------------------------------------------------------------- parameters


@dataclass(frozen=True)
class MdpParams:
    """Algorithm 1 of the paper (section V-B): activation, initial radii, thresholds, sensor noise."""

    r_t_m: float = 1.0
    """Activation radius ``r_t`` [m]: Algorithm 1 runs while the range is at most this. The MDP can only
    move ``r2`` outward to a range it has seen inside ``r_t``, so ``r_t`` must exceed the fixed policy's
    ``r2 = 0.8 m`` for the MDP to be able to pick both earlier and later switch points than the fixed
    policy (paper Fig. 6: the fixed radii are the MDP's worst-case picks). Not in the paper; 1.0 m here."""
    r_d_m: float = 0.12
    """Docking distance ``r_d`` [m]: centre-to-centre range between chaser and target at contact."""
    r1_init_m: float = 0.1
    """Initial (aggressive) REORIENT -> ALIGN radius ``r1`` [m] (Algorithm 1: ``r1 <- 0.1``)."""
    r2_init_m: float = 0.3
    """Initial (aggressive) APPROACH -> REORIENT radius ``r2`` [m] (Algorithm 1: ``r2 <- 0.3``)."""
    a11_threshold: float = 0.4
    """Switch to REORIENT (``r2 <- r``) when ``A11`` is at most this (Algorithm 1)."""
    pi2_threshold: float = 0.6
    """Switch to ALIGN (``r1 <- r``) when the stationary ALIGN probability is at most this (Algorithm 1)."""
    sigma_uwb_m: float = 0.02
    """UWB range noise standard deviation ``sigma_UWB`` [m] that normalises ``max(sigma_pos)`` (paper III)."""

    def __post_init__(self) -> None:
        for name in ("r_t_m", "r_d_m", "r1_init_m", "r2_init_m", "sigma_uwb_m"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"mdp.{name} must be a positive finite number, got {v!r}")
        for name in ("a11_threshold", "pi2_threshold"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and 0.0 <= v <= 1.0):
                raise ConfigError(f"mdp.{name} must be a probability in [0, 1], got {v!r}")
        if not self.r1_init_m < self.r2_init_m:
            raise ConfigError(
                f"mdp.r1_init_m must be below mdp.r2_init_m = {self.r2_init_m!r}, got {self.r1_init_m!r}"
            )
        if not self.r_d_m < self.r2_init_m:
            # keeps r2 - r_d > 0 in A32 for every r2 the algorithm can reach (r2 only grows)
            raise ConfigError(
                f"mdp.r_d_m must be below mdp.r2_init_m = {self.r2_init_m!r}, got {self.r_d_m!r}"
            )
        if not self.r2_init_m < self.r_t_m:
            raise ConfigError(f"mdp.r_t_m must exceed mdp.r2_init_m = {self.r2_init_m!r}, got {self.r_t_m!r}")


@dataclass(frozen=True)
class FixedParams:
    """Fixed switch radii (paper section V-C: the conservative ``r2 = 0.8``, ``r1 = 0.3``)."""

    r2_m: float = 0.8
    """APPROACH -> REORIENT radius [m]."""
    r1_m: float = 0.3
    """REORIENT -> ALIGN radius [m]."""

    def __post_init__(self) -> None:
        for name in ("r2_m", "r1_m"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"fixed.{name} must be a positive finite number, got {v!r}")
        if not self.r1_m < self.r2_m:
            raise ConfigError(f"fixed.r1_m must be below fixed.r2_m = {self.r2_m!r}, got {self.r1_m!r}")


# --------------------------------------------------------------------------------- stationary distributions


def _check_transition_matrix(A: Any) -> np.ndarray:
    a = np.asarray(A, dtype=float)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] == 0:
        raise ValueError(f"transition matrix must be square (n, n) with n >= 1, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"transition matrix must be finite, got {a.tolist()}")
    if np.any(a < -_ROW_SUM_TOL) or np.any(a > 1.0 + _ROW_SUM_TOL):
        raise ValueError(f"transition matrix entries must be probabilities in [0, 1], got {a.tolist()}")
    sums = a.sum(axis=1)
    bad = np.flatnonzero(np.abs(sums - 1.0) > _ROW_SUM_TOL)
    if bad.size:
        raise ValueError(
            f"transition matrix must be row-stochastic (each row sums to 1), row {int(bad[0])} sums to "
            f"{float(sums[bad[0]])!r}"
        )
    return a


def stationary_distribution(A: Any) -> np.ndarray:
    """Stationary distribution ``pi`` of a finite Markov chain: ``pi A = pi``, ``sum(pi) = 1``, ``pi >= 0``.

    Norris 1998, *Markov chains*, section 1.7 (Thm 1.7.7): an irreducible chain on a finite state space has
    a unique invariant distribution; more generally a finite chain has a unique one exactly when it has one
    closed communicating class (transient states then get probability 0). With ``k`` closed classes the
    eigenvalue 1 of ``A^T`` has ``k`` independent eigenvectors and ``rank(A^T - I) = n - k``.

    ``pi`` is the least-squares solution of the stacked, consistent system ``[(A^T - I); 1^T] pi = [0; 1]``.
    Its rank is ``n - k + 1`` (the normalisation row is independent of the rows of ``A^T - I``, which sum to
    zero), so it has full column rank exactly when ``pi`` is unique. Stewart 1994, *Introduction to the
    numerical solution of Markov chains*, ch. 2, replaces one equation by the normalisation instead; least
    squares needs no choice of row and reports the rank.

    Args:
        A: ``(n, n)`` row-stochastic transition matrix, ``A[i, j] = P(next = j | now = i)``.

    Returns:
        ``(n,)`` stationary probabilities, non-negative, summing to 1.

    Raises:
        ValueError: ``A`` is not square, not finite, has entries outside ``[0, 1]`` or rows not summing to 1
            (tolerance 1e-9); or the chain has no unique stationary distribution (more than one closed class,
            e.g. the identity), judged by the numerical rank of the stacked system.
    """
    a = _check_transition_matrix(A)
    n = a.shape[0]
    M = np.vstack([a.T - np.eye(n), np.ones((1, n))])
    b = np.zeros(n + 1)
    b[-1] = 1.0
    pi, _, rank, _ = np.linalg.lstsq(M, b, rcond=None)
    if rank < n:
        raise ValueError(
            f"transition matrix has no unique stationary distribution ({n - rank + 1} closed communicating "
            f"classes, numerically), got {a.tolist()}"
        )
    pi = np.clip(pi, 0.0, None)  # rounding can leave -1e-17 on transient states
    return pi / pi.sum()


def stationary_2state(a12: float, a21: float) -> tuple[float, float] | None:
    """Closed-form stationary distribution of ``[[1 - a12, a12], [a21, 1 - a21]]``.

    Balance of the flow between the two states, ``pi1 a12 = pi2 a21`` with ``pi1 + pi2 = 1``, gives
    ``(pi1, pi2) = (a21, a12) / (a12 + a21)`` (Norris 1998, section 1.1, the general two-state chain).

    Args:
        a12: probability of leaving state 1 for state 2, in ``[0, 1]``.
        a21: probability of leaving state 2 for state 1, in ``[0, 1]``.

    Returns:
        ``(pi1, pi2)``, or ``None`` when ``a12 + a21 == 0``: the chain is the identity, both states are
        absorbing and every distribution is stationary, so there is no unique answer.

    Raises:
        ValueError: an argument is not a probability.
    """
    for name, v in (("a12", a12), ("a21", a21)):
        if not (math.isfinite(v) and 0.0 <= v <= 1.0):
            raise ValueError(f"{name} must be a probability in [0, 1], got {v!r}")
    s = a12 + a21
    if s == 0.0:
        return None
    return float(a21 / s), float(a12 / s)


# ------------------------------------------------------------------------------- Algorithm 1 probabilities


@njit(cache=True)
def a11_kernel(r, r_t, d, visibility):
    """Algorithm 1's ``A11 = clip((r / r_t) (1 / (1 + d)) v, 0, 1)``, ``v`` the factor that says how ready
    the vehicle is to leave the first mode: docking ``1 / ||q_e[1:3]||`` (:func:`approach_probability`),
    landing the camera's footprint over ``3 sigma`` (:mod:`swarm.core.landing`). The one implementation
    both missions' compiled guidance calls."""
    return min(max((r / r_t) * (1.0 / (1.0 + d)) * visibility, 0.0), 1.0)


@njit(cache=True)
def chain_kernel(r, r2, d, sigma, sigma_ref, r_d):
    """Algorithm 1's second chain and its stationary distribution (:func:`reorient_align_probabilities`,
    :func:`stationary_2state`): ``(a22, a23, a32, a33, pi1, pi2)``, ``pi`` NaN when ``a23 + a32 = 0``. The
    one implementation both missions' compiled guidance calls (landing: ``r_d`` the acceptance radius,
    ``sigma_ref`` its reference sigma)."""
    a22 = min(max((r / r2) * (1.0 / (1.0 + d)), 0.0), 1.0)
    span = r2 - r_d
    frac = (r2 - r) / span if span > 0.0 else 1.0
    a32 = min(max((sigma / sigma_ref) * frac, 0.0), 1.0)
    a23 = 1.0 - a22
    s = a23 + a32  # stationary_2state(a23, a32): (pi1, pi2) = (a32, a23) / (a23 + a32)
    if s == 0.0:
        return a22, a23, a32, 1.0 - a32, np.nan, np.nan
    return a22, a23, a32, 1.0 - a32, a32 / s, a23 / s


def approach_probability(r_m: float, d: float, qe_vec_norm: float, r_t_m: float) -> float:
    """``A11`` of Algorithm 1: probability of staying in APPROACH, clipped into ``[0, 1]``.

    ``A11 = (r / r_t) * (1 / (1 + d)) * (1 / ||q_e[1:3]||)`` (paper Algorithm 1, section V-B). With
    ``||q_e[1:3]|| = 0`` the last factor is ``+inf`` and ``A11 = 1`` (nothing to reorient).

    Args:
        r_m: range chaser-target [m], > 0.
        d: Mahalanobis distance of the latest innovation (dimensionless, >= 0): filter consistency.
        qe_vec_norm: norm of the vector part of the attitude-error quaternion from the chaser's attitude to
            its docking attitude (``sin(angle / 2)``, in ``[0, 1]``).
        r_t_m: activation radius [m].
    """
    if qe_vec_norm == 0.0:
        return 1.0
    a11 = (r_m / r_t_m) * (1.0 / (1.0 + d)) * (1.0 / qe_vec_norm)
    return float(min(max(a11, 0.0), 1.0))


def reorient_align_probabilities(
    r_m: Any, r2_m: Any, d: Any, sigma_pos_max_m: Any, sigma_uwb_m: float, r_d_m: float
) -> tuple[Any, Any, Any, Any]:
    """``(A22, A23, A32, A33)`` of Algorithm 1: the [REORIENT, ALIGN] chain, each clipped into ``[0, 1]``.

    ``A22 = (r / r2) / (1 + d)``, ``A23 = 1 - A22``,
    ``A32 = (max(sigma_pos) / sigma_UWB) * (r2 - r) / (r2 - r_d)``, ``A33 = 1 - A32`` (paper Algorithm 1).
    ``A22`` and ``A32`` are clipped, then ``A23``, ``A33`` follow so each row sums to 1. Where
    ``r2 - r_d <= 0`` the distance fraction is taken as 1. Broadcasts over numpy arrays (section V-D maps).

    Args:
        r_m: range chaser-target [m].
        r2_m: current APPROACH -> REORIENT radius [m].
        d: Mahalanobis distance (dimensionless, >= 0).
        sigma_pos_max_m: largest position standard deviation of the estimate [m] (sqrt of the largest
            diagonal entry, or eigenvalue, of the position covariance; the caller chooses and documents).
        sigma_uwb_m: UWB range noise standard deviation [m].
        r_d_m: docking distance [m].

    Returns:
        Four floats, or four arrays of the broadcast shape.
    """
    if all(type(x) is float for x in (r_m, r2_m, d, sigma_pos_max_m)):  # one decision: the compiled pass's
        a22s, a23s, a32s, a33s, _, _ = chain_kernel(
            r_m, r2_m, d, sigma_pos_max_m, float(sigma_uwb_m), float(r_d_m)
        )
        return a22s, a23s, a32s, a33s
    r, r2, dd, sp = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (r_m, r2_m, d, sigma_pos_max_m))
    )
    a22 = np.clip((r / r2) * (1.0 / (1.0 + dd)), 0.0, 1.0)
    span = r2 - r_d_m
    safe_span = np.where(span > 0.0, span, 1.0)
    frac = np.where(span > 0.0, (r2 - r) / safe_span, 1.0)
    a32 = np.clip((sp / sigma_uwb_m) * frac, 0.0, 1.0)
    out = (a22, 1.0 - a22, a32, 1.0 - a32)
    if out[0].ndim == 0:
        return tuple(float(x) for x in out)  # type: ignore[return-value]
    return out


def fig4_transition_matrix(a11: float, a22: float, a32: float) -> np.ndarray:
    """3-state [APPROACH, REORIENT, ALIGN] transition matrix of the paper's Fig. 4 (DOCK left out).

    ``[[A11, 1 - A11, 0], [0, A22, 1 - A22], [0, A32, 1 - A32]]``. APPROACH never returns, so for
    ``A11 < 1`` its stationary probability is 0 and the rest is the 2-state chain of Algorithm 1.
    """
    return np.array([[a11, 1.0 - a11, 0.0], [0.0, a22, 1.0 - a22], [0.0, a32, 1.0 - a32]])


def steady_state_probabilities(
    sigma_pos_max_m: Any, r_m: Any, r2_m: Any, d: Any = 0.0, params: MdpParams | None = None
) -> np.ndarray:
    """Stationary ``[pi_reorient, pi_align]`` of Algorithm 1's chain for given position uncertainty.

    Paper section V-D: the best- and worst-case steady-state position covariance that an anchor placement
    allows give, through the probability rules of Algorithm 1, the steady-state probabilities of the state
    machine. Pass both sigmas (or a grid of them) as an array to compare. ``pi_align`` decreases as
    ``sigma_pos_max_m`` grows: a low value means the chain doubts it can still align if it keeps going.

    Args:
        sigma_pos_max_m: largest position standard deviation [m], scalar or array.
        r_m: range chaser-target [m], with ``r_d < r <= r2``; broadcasts.
        r2_m: APPROACH -> REORIENT radius [m]; broadcasts.
        d: Mahalanobis distance (dimensionless); broadcasts.
        params: sigma_UWB and r_d come from here (default :class:`MdpParams`).

    Returns:
        ``(..., 2)`` array of the broadcast shape; NaN where ``A23 + A32 = 0`` (no unique distribution).
    """
    p = MdpParams() if params is None else params
    _, a23, a32, _ = reorient_align_probabilities(r_m, r2_m, d, sigma_pos_max_m, p.sigma_uwb_m, p.r_d_m)
    a23, a32 = np.asarray(a23), np.asarray(a32)
    s = a23 + a32
    ok = s > 0.0
    safe = np.where(ok, s, 1.0)
    pi = np.stack([a32 / safe, a23 / safe], axis=-1)  # Norris closed form, as stationary_2state
    return np.where(ok[..., None], pi, np.nan)


# ------------------------------------------------------------------------------------------------- records


@dataclass(frozen=True)
class Decision:
    """One pass of Algorithm 1 with its inputs and outputs (a run summary's ``"decisions"``).

    Outputs a branch did not compute are ``None``. ``r1_m``/``r2_m`` are the radii *after* this pass.
    """

    t_s: float
    """Time of the decision [s] (the caller's clock)."""
    r_m: float
    """Range chaser-target used [m]."""
    d: float
    """Mahalanobis distance (dimensionless)."""
    qe_vec_norm: float
    """``||q_e[1:3]||`` to the docking attitude."""
    sigma_pos_max_m: float
    """Largest position standard deviation [m]."""
    sigma_uwb_m: float
    """UWB range noise [m] (parameter)."""
    r_t_m: float
    """Activation radius [m] (parameter)."""
    r_d_m: float
    """Docking distance [m] (parameter)."""
    A11: float | None
    """APPROACH self-transition probability (``r > r2`` branch), clipped."""
    A22: float | None
    """REORIENT self-transition probability (``r <= r2`` branch), clipped."""
    A23: float | None
    """REORIENT -> ALIGN probability, ``1 - A22``."""
    A32: float | None
    """ALIGN -> REORIENT probability, clipped."""
    A33: float | None
    """ALIGN self-transition probability, ``1 - A32``."""
    pi1: float | None
    """Stationary REORIENT probability (``None`` if not computed or not unique)."""
    pi2: float | None
    """Stationary ALIGN probability (``None`` if not computed or not unique)."""
    r1_m: float
    """REORIENT -> ALIGN radius after this pass [m]."""
    r2_m: float
    """APPROACH -> REORIENT radius after this pass [m]."""
    branch: str
    """``"A11"`` (``r > r2``) or ``"A22"`` (``r <= r2``)."""
    switched: str | None
    """``"r2"`` or ``"r1"`` when this pass set that radius to ``r``, else ``None``."""
    reason: str = field(default="")
    """Human-readable account, e.g. ``"A11=0.3875 <= 0.4: reorient at r=0.62 m"``."""

    def as_dict(self, diagnostics: bool = False) -> dict[str, float | str | None]:
        """The decision record: exactly :data:`DECISION_KEYS`; with ``diagnostics`` also
        ``branch``, ``switched`` and ``reason``."""
        keys = (*DECISION_KEYS, "branch", "switched", "reason") if diagnostics else DECISION_KEYS
        return {k: getattr(self, k) for k in keys}  # the fields are plain values: no deep copy needed


# ------------------------------------------------------------------------------- Algorithm 1, compiled

# switcher state SW (float64): the policy, the current radii and Algorithm 1's parameters
SW_POLICY, SW_R1, SW_R2, SW_RT, SW_A11_THR, SW_PI2_THR, SW_SIGMA_UWB, SW_RD = range(8)
SW_N = 8
POLICY_FIXED = 0.0
POLICY_MDP = 1.0

# one pass, a row of D_N floats (None as NaN)
(D_T, D_R, D_D, D_QE, D_SIGMA, D_A11, D_A22, D_A23, D_A32, D_A33, D_PI1, D_PI2, D_R1, D_R2, D_BRANCH,
 D_SWITCHED) = range(16)  # fmt: skip
D_N = 16
BRANCH_A11 = 0.0
BRANCH_A22 = 1.0
SWITCHED_NONE, SWITCHED_R2, SWITCHED_R1 = 0.0, 1.0, 2.0


@njit(cache=True)
def mdp_pass(SW, t_s, r, d, qe_vec_norm, sigma_pos_max_m, row):
    """One pass of Algorithm 1's loop body on the switcher state ``SW`` (module docstring), recorded in
    ``row`` (:data:`D_N`,); returns False (nothing recorded, nothing changed) for the fixed policy or when
    the ``while`` condition ``r <= r_t and r > r1`` is false. The arithmetic of
    :func:`approach_probability`, :func:`reorient_align_probabilities` and :func:`stationary_2state`."""
    if SW[SW_POLICY] != POLICY_MDP:
        return False
    if not (r <= SW[SW_RT] and r > SW[SW_R1]):
        return False
    for i in range(D_N):
        row[i] = np.nan
    row[D_T] = t_s
    row[D_R] = r
    row[D_D] = d
    row[D_QE] = qe_vec_norm
    row[D_SIGMA] = sigma_pos_max_m
    row[D_SWITCHED] = SWITCHED_NONE
    r2 = SW[SW_R2]
    if r > r2:
        row[D_BRANCH] = BRANCH_A11
        a11 = 1.0 if qe_vec_norm == 0.0 else a11_kernel(r, SW[SW_RT], d, 1.0 / qe_vec_norm)
        row[D_A11] = a11
        if a11 <= SW[SW_A11_THR]:
            SW[SW_R2] = r
            row[D_SWITCHED] = SWITCHED_R2
    else:
        row[D_BRANCH] = BRANCH_A22
        a22, a23, a32, a33, pi1, pi2 = chain_kernel(r, r2, d, sigma_pos_max_m, SW[SW_SIGMA_UWB], SW[SW_RD])
        row[D_A22] = a22
        row[D_A23] = a23
        row[D_A32] = a32
        row[D_A33] = a33
        if not np.isnan(pi2):
            row[D_PI1] = pi1
            row[D_PI2] = pi2
            if pi2 <= SW[SW_PI2_THR]:
                SW[SW_R1] = r
                row[D_SWITCHED] = SWITCHED_R1
    row[D_R1] = SW[SW_R1]
    row[D_R2] = SW[SW_R2]
    return True


# ---------------------------------------------------------------------------------------------- switchers


class Switcher(Protocol):
    """What guidance needs from a switcher: the current radii, one evaluation per step, the record."""

    @property
    def r1_m(self) -> float: ...

    @property
    def r2_m(self) -> float: ...

    @property
    def decisions(self) -> list[Decision]: ...

    def evaluate(
        self, t_s: float, r_m: float, d: float, qe_vec_norm: float, sigma_pos_max_m: float
    ) -> Decision | None: ...


def _check_inputs(**kwargs: float) -> None:
    for name, v in kwargs.items():
        if type(v) is float and math.isfinite(v) and (v >= 0 or name == "t_s"):
            continue  # the common case, checked without isinstance
        if not (isinstance(v, int | float | np.floating | np.integer) and math.isfinite(v)):
            raise ValueError(f"{name} must be a finite number, got {v!r}")
        if name != "t_s" and v < 0:
            raise ValueError(f"{name} must be non-negative, got {v!r}")


DECISION_STAGING = 64
"""Rows of a switcher's staging buffer :attr:`MdpSwitcher.staged`: compiled code appends passes there and
the switcher turns them into :class:`Decision` records when asked (a runner drains a full buffer)."""


def nan_to_none(x: float) -> float | None:
    """A compiled kernel's absent value (NaN) as Python's (None)."""
    return None if math.isnan(x) else float(x)


class MdpSwitcher:
    """Paper Algorithm 1: picks ``r2`` and ``r1`` from transition probabilities, one pass per call.

    Its state is the array :attr:`SW` (layout ``SW_*``) that the compiled guidance updates
    (:func:`mdp_pass`); the passes made in compiled code wait in :attr:`staged` (``staged_n[0]`` rows) until
    :attr:`decisions` turns them into records."""

    def __init__(self, params: MdpParams | None = None) -> None:
        self.params = p = MdpParams() if params is None else params
        self.SW = np.array(
            [POLICY_MDP, p.r1_init_m, p.r2_init_m, p.r_t_m, p.a11_threshold, p.pi2_threshold, p.sigma_uwb_m,
             p.r_d_m], dtype=np.float64,
        )  # fmt: skip
        self.staged = np.zeros((DECISION_STAGING, D_N))
        self.staged_n = np.zeros(1, dtype=np.int64)
        self._decisions: list[Decision] = []

    @property
    def r1_m(self) -> float:
        """Current REORIENT -> ALIGN radius [m]."""
        return float(self.SW[SW_R1])

    @property
    def r2_m(self) -> float:
        """Current APPROACH -> REORIENT radius [m]."""
        return float(self.SW[SW_R2])

    @property
    def decisions(self) -> list[Decision]:
        """Every pass so far, oldest first (a copy)."""
        self.drain()
        return list(self._decisions)

    def drain(self) -> Decision | None:
        """Turn the staged passes into records; returns the last one (None when none was staged)."""
        n = int(self.staged_n[0])
        last = None
        for i in range(n):
            last = self.record(self.staged[i])
            self._decisions.append(last)
        self.staged_n[0] = 0
        return last

    def record(self, row: np.ndarray) -> Decision:
        """The :class:`Decision` of one pass's row (layout ``D_*``), with its reason in words."""
        p = self.params
        r = float(row[D_R])
        switched = {SWITCHED_R2: "r2", SWITCHED_R1: "r1"}.get(float(row[D_SWITCHED]))
        a11, pi2 = nan_to_none(row[D_A11]), nan_to_none(row[D_PI2])
        if row[D_BRANCH] == BRANCH_A11:
            branch = "A11"
            if switched == "r2":
                reason = f"A11={a11:.4g} <= {p.a11_threshold:g}: reorient at r={r:.4g} m"
            else:
                reason = f"A11={a11:.4g} > {p.a11_threshold:g}: keep approaching"
        else:
            branch = "A22"
            if pi2 is None:
                reason = "A23 + A32 = 0: no unique stationary distribution, keep reorienting"
            elif switched == "r1":
                reason = f"pi2={pi2:.4g} <= {p.pi2_threshold:g}: align at r={r:.4g} m"
            else:
                reason = f"pi2={pi2:.4g} > {p.pi2_threshold:g}: keep reorienting"
        return Decision(
            t_s=float(row[D_T]), r_m=r, d=float(row[D_D]), qe_vec_norm=float(row[D_QE]),
            sigma_pos_max_m=float(row[D_SIGMA]), sigma_uwb_m=float(p.sigma_uwb_m), r_t_m=float(p.r_t_m),
            r_d_m=float(p.r_d_m), A11=a11, A22=nan_to_none(row[D_A22]), A23=nan_to_none(row[D_A23]),
            A32=nan_to_none(row[D_A32]), A33=nan_to_none(row[D_A33]), pi1=nan_to_none(row[D_PI1]), pi2=pi2,
            r1_m=float(row[D_R1]), r2_m=float(row[D_R2]),
            branch=branch, switched=switched, reason=reason,
        )  # fmt: skip

    def evaluate(
        self, t_s: float, r_m: float, d: float, qe_vec_norm: float, sigma_pos_max_m: float
    ) -> Decision | None:
        """One pass of Algorithm 1's loop body, or ``None`` when its ``while`` condition is false
        (:func:`mdp_pass`, the compiled pass the guidance makes).

        Args:
            t_s: time of the decision [s], only recorded.
            r_m: estimated range chaser-target (centres of mass) [m], >= 0.
            d: Mahalanobis distance of the latest innovation (dimensionless, >= 0).
            qe_vec_norm: ``||q_e[1:3]||``, vector-part norm of the attitude error to the docking attitude.
            sigma_pos_max_m: largest position standard deviation of the estimate [m], >= 0.

        Returns:
            The recorded :class:`Decision`, or ``None`` if ``r > r_t`` or ``r <= r1`` (nothing recorded).

        Raises:
            ValueError: an input is not finite, or (except ``t_s``) negative.
        """
        _check_inputs(t_s=t_s, r_m=r_m, d=d, qe_vec_norm=qe_vec_norm, sigma_pos_max_m=sigma_pos_max_m)
        self.drain()
        row = np.empty(D_N)
        if not mdp_pass(self.SW, float(t_s), float(r_m), float(d), float(qe_vec_norm), float(sigma_pos_max_m),
                        row):  # fmt: skip
            return None
        dec = self.record(row)
        self._decisions.append(dec)
        return dec


class FixedSwitcher:
    """Constant radii (paper section V-C); same interface as :class:`MdpSwitcher`, never decides."""

    def __init__(self, params: FixedParams | None = None) -> None:
        self.params = p = FixedParams() if params is None else params
        self.SW = np.array([POLICY_FIXED, p.r1_m, p.r2_m, 0.0, 0.0, 0.0, 1.0, 0.0], dtype=np.float64)
        self.staged = np.zeros((1, D_N))
        self.staged_n = np.zeros(1, dtype=np.int64)

    @property
    def r1_m(self) -> float:
        """REORIENT -> ALIGN radius [m]."""
        return float(self.params.r1_m)

    @property
    def r2_m(self) -> float:
        """APPROACH -> REORIENT radius [m]."""
        return float(self.params.r2_m)

    @property
    def decisions(self) -> list[Decision]:
        """Always empty: the fixed policy makes no decisions."""
        return []

    def drain(self) -> None:
        """Nothing is ever staged."""
        return None

    def evaluate(
        self, t_s: float, r_m: float, d: float, qe_vec_norm: float, sigma_pos_max_m: float
    ) -> Decision | None:
        """No-op (returns ``None``); the arguments are accepted so guidance can call either switcher."""
        return None


class Policy(enum.StrEnum):
    FIXED = "fixed"
    MDP = "mdp"


def make_switcher(
    policy: str, mdp: MdpParams | None = None, fixed: FixedParams | None = None
) -> MdpSwitcher | FixedSwitcher:
    """A fresh switcher for ``policy`` (``"fixed"`` or ``"mdp"``), from the matching parameters.

    Raises:
        ConfigError: ``policy`` is neither, naming the value.
    """
    try:
        pol = Policy(policy)
    except ValueError:
        raise ConfigError(f"policy must be one of {[p.value for p in Policy]}, got {policy!r}") from None
    if pol is Policy.MDP:
        return MdpSwitcher(mdp)
    return FixedSwitcher(fixed)
