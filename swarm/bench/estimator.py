"""Estimator step benchmark (issue 2): one predict + one UWB range update, the unit of paper Table I.

Measured in one process, cases interleaved block by block so that machine noise hits them alike:

* **API**: :class:`~swarm.core.estimator.PoseEstimator` with ``n = 1``, ``predict`` + ``update_range``
  from Python, for the tandem and compounded structures (the bench's JSON record: ``tandem_us``,
  ``compounded_us``).
* **dispatch**: the compiled batch kernels (``_ekf_nb.predict_batch``, ``update_range_batch``) called
  directly from Python with ready-made arrays: what is left of the API once argument handling is gone.
* **kernel**: a compiled loop over ``_ekf_nb.predict_one`` + ``update_range_one`` on one filter, no
  Python at all: the structure's computational cost, which is what Table I compares.
* **kernel pieces**: compiled loops over one piece of that step at a time (:func:`_piece_loop`), to say
  where the kernel's time goes.
* **FilterPy**: ``filterpy.kalman.ExtendedKalmanFilter`` running the same 9-state multiplicative model
  (:class:`~swarm.bench.filterpy_mekf.FilterPyMekf`, tested equal to the compounded filter to 1e-9), an
  optional extra.
* **batched**: ``PoseEstimator`` with ``n`` filters, time per step divided by ``n``.

Every case replays the same precomputed run (:func:`make_inputs`): a slow drift inside the paper's four
anchors, gyro with VN-100 noise at 100 Hz, one 2 cm range per step in round robin; the gate accepts them
all (the report says how many). Compilation is excluded by a warm-up block, the garbage collector is off
inside a timed block, and each figure is the median (with p90 and min) over the blocks.
"""

from __future__ import annotations

import gc
import logging
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace

import numba
import numpy as np

from swarm.bench.filterpy_mekf import FILTERPY_MISSING, FilterPyMekf, filterpy_available
from swarm.core import _ekf_nb as nb
from swarm.core import rotations as rot
from swarm.core.estimator import EstimatorParams, MeasKind, PoseEstimator, Structure, chi2_gate
from swarm.sim.estimation import PAPER_ANCHORS_MS

log = logging.getLogger(__name__)

PAPER_TABLE_I = {
    "compounded": {"flops": 210_421, "memory_kb": 644, "runtime_ms": 7.054},
    "tandem": {"flops": 100_009, "memory_kb": 128, "runtime_ms": 3.407},
}
"""Paper Table I: one predict + one range update, a MATLAB script on an i5-1135G7 @ 2.4 GHz."""

GOALS = {  # key: (the ratio it reads, target, comparison, label)
    "tandem_fifth_of_filterpy": ("tandem_over_filterpy", 0.2, "<=", "tandem/FilterPy, API"),
    "tandem_0.6_compounded_api": ("tandem_over_compounded_api", 0.6, "<=", "tandem/compounded, API"),
    "tandem_0.6_compounded_kernel": ("tandem_over_compounded_kernel", 0.6, "<=", "tandem/compounded, kernel"),
    "tandem_200x_paper_api": ("paper_speedup_tandem_api", 200.0, ">=", "paper 3.407 ms/tandem, API"),
    "tandem_200x_paper_kernel": ("paper_speedup_tandem_kernel", 200.0, ">=", "paper 3.407 ms/tandem, kernel"),
}
"""Issue 2's performance goals: reported with the measured value, never asserted."""
STRUCTURES = ("tandem", "compounded")


@dataclass(frozen=True)
class BenchConfig:
    """How long to measure. :data:`FULL` and :data:`QUICK` are the presets."""

    steps: int = 2000
    """Steps (predict + one range update) per timed block of the single-filter cases."""
    repeats: int = 15
    """Timed blocks per single-filter case; statistics are over blocks."""
    batch_sizes: tuple[int, ...] = (100, 1000)
    """Numbers of filters ``n`` of the batched cases."""
    batch_steps: int = 100
    """Steps per timed block of the batched cases."""
    batch_repeats: int = 7
    """Timed blocks per batched case."""
    dt_s: float = 0.01
    """IMU period [s] (the paper's 100 Hz gyro)."""
    seed: int = 0
    """Root seed of the replayed run."""


FULL = BenchConfig()
QUICK = BenchConfig(steps=200, repeats=5, batch_sizes=(10, 100), batch_steps=20, batch_repeats=3)


# ---- the replayed run --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Inputs:
    """A precomputed run of ``K`` steps; every filter under test starts from the same estimate."""

    p0_nav: np.ndarray  # (3,) initial position estimate [m], frame c
    v0_nav: np.ndarray  # (3,) initial velocity estimate [m/s]
    q0_nav_body: np.ndarray  # (4,) initial attitude estimate, scalar-last
    cov0: np.ndarray  # (9, 9) initial error covariance, order (d_p, d_v, d_theta)
    w_body: np.ndarray  # (K, 3) gyro rates [rad/s]
    a_nav: np.ndarray  # (K, 3) known (commanded) acceleration [m/s^2], frame c
    anchor_nav: np.ndarray  # (K, 3) anchor ranged after step k's prediction
    range_true_m: np.ndarray  # (K,) noise-free range of that anchor [m]
    range_m: np.ndarray  # (K,) measured range, 2 cm white noise [m]
    dt_s: float


def make_inputs(steps: int, dt_s: float, params: EstimatorParams, seed: int = 0) -> Inputs:
    """A slow drift near the centre of the paper's anchors (``PAPER_ANCHORS_MS``) with smooth body rates;
    truth follows the filter's own kinematics, the gyro has the VN-100 angle random walk, ranges see the
    tag lever arm and ``params.sigma_range_m`` noise. Seeded: the same ``seed`` gives the same run."""
    rng_init, rng_gyro, rng_uwb = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3))
    t = dt_s * np.arange(steps)[:, None]
    w_true = 0.1 * np.concatenate([np.sin(0.5 * t), np.cos(0.4 * t), np.sin(0.3 * t + 1.0)], axis=-1)
    a_nav = 0.01 * np.concatenate([np.sin(0.3 * t), np.cos(0.2 * t), -np.sin(0.25 * t)], axis=-1)
    p, v = np.array([-0.2, 0.0, 0.1]), np.array([0.02, 0.005, -0.01])
    q = rot.rotvec_exp(np.array([0.1, -0.2, 0.3]))
    sig0 = np.array([0.02] * 3 + [0.01] * 3 + [0.02] * 3)
    e0 = rng_init.normal(size=9) * sig0
    p0, v0, q0 = p + e0[:3], v + e0[3:6], rot.multiplicative_reset(q, -e0[6:])
    lever = np.asarray(params.lever_arm_body_m)
    anchors = PAPER_ANCHORS_MS[np.arange(steps) % len(PAPER_ANCHORS_MS)]
    r_true = np.empty(steps)
    for k in range(steps):
        p = p + v * dt_s + 0.5 * a_nav[k] * dt_s**2
        v = v + a_nav[k] * dt_s
        q = rot.quat_normalize(rot.quat_mul(q, rot.rotvec_exp(w_true[k] * dt_s)))
        r_true[k] = np.linalg.norm(p + rot.quat_rotate(q, lever) - anchors[k])
    gyro = w_true + rng_gyro.normal(0.0, params.gyro_arw_rad_rts / np.sqrt(dt_s), w_true.shape)
    return Inputs(
        p0_nav=p0,
        v0_nav=v0,
        q0_nav_body=q0,
        cov0=np.diag(sig0**2),
        w_body=np.ascontiguousarray(gyro),
        a_nav=np.ascontiguousarray(a_nav),
        anchor_nav=np.ascontiguousarray(anchors),
        range_true_m=r_true,
        range_m=r_true + rng_uwb.normal(0.0, params.sigma_range_m, steps),
        dt_s=dt_s,
    )


# ---- compiled loops ----------------------------------------------------------------------------------


@numba.njit(cache=True)
def _kernel_loop(X, P, ST_I, ST_F, PRM, W, A, dt, anchors, Z, sigma, gate):
    """``len(W)`` steps of predict + one range on one filter, all compiled; returns the accepted count."""
    accepted = 0
    for k in range(W.shape[0]):
        nb.predict_one(X, P, ST_I, ST_F, W[k], A[k], dt, PRM)
        if nb.update_range_one(X, P, ST_I, ST_F, PRM, anchors[k], Z[k], sigma, gate) == nb.ST_ACCEPTED:
            accepted += 1
    return accepted


PIECES = ("predict", "update_scalar", "reset", "range_row", "all_finite", "finite_loop", "workspace")
"""What :func:`_piece_loop` times; the first two per structure, the rest are the same code for both."""


@numba.njit(cache=True)
def _piece_loop(piece, X, P, ST_I, ST_F, PRM, W, A, dt, anchors, sigma):
    """``len(W)`` calls of one piece of the step (index into :data:`PIECES`) on one filter, compiled:
    ``predict_one``; ``_update_scalar`` on a fixed range row with zero innovation (gain and Joseph
    algebra, no reset); ``_reset_attitude`` by a fixed 1e-5 rad correction; ``_range_row``;
    ``_all_finite`` of a 3-vector (a step makes three: gyro, acceleration, anchor); the same test written
    as three ``np.isfinite`` (no ``ravel``); the ``np.empty((3, 9))`` workspace of ``update_range_one``."""
    work = np.empty((3, 9))
    lever = PRM[nb.PRM_LEVER : nb.PRM_LEVER + 3]
    nb._range_row(X, anchors[0], lever, ST_F, nb.STF_WORK + 18)  # the row _update_scalar reads
    dth = np.array([1e-5, -2e-5, 3e-6])
    acc = 0.0
    for k in range(W.shape[0]):
        if piece == 0:
            nb.predict_one(X, P, ST_I, ST_F, W[k], A[k], dt, PRM)
        elif piece == 1:
            nb._update_scalar(X, P, ST_I, ST_F, PRM, nb.TYPE_RANGE, 0.0, sigma * sigma, np.inf)
        elif piece == 2:
            nb._reset_attitude(X, P, dth)
        elif piece == 3:
            acc += nb._range_row(X, anchors[k], lever, work[2])
        elif piece == 4:
            if nb._all_finite(anchors[k]):
                acc += 1.0
        elif piece == 5:
            a = anchors[k]
            if np.isfinite(a[0]) and np.isfinite(a[1]) and np.isfinite(a[2]):
                acc += 1.0
        else:
            w = np.empty((3, 9))
            w[0, 0] = dt
            acc += w[0, 0]
    return acc


# ---- timed blocks: each returns (seconds, steps x filters, accepted ranges) ----------------------------

Block = Callable[[], tuple[float, int, int]]


def _timed(loop: Callable[[], None]) -> float:
    gc.disable()
    try:
        t0 = time.perf_counter()
        loop()
        return time.perf_counter() - t0
    finally:
        gc.enable()


def _create(params: EstimatorParams, inp: Inputs, n: int = 1) -> PoseEstimator:
    return PoseEstimator.create(params, inp.p0_nav, inp.v0_nav, inp.q0_nav_body, inp.cov0, n=n)


def _accepted(est: PoseEstimator) -> int:
    return int(est.count(MeasKind.RANGE, "accepted").sum())


def _api_block(params: EstimatorParams, inp: Inputs) -> Block:
    def block():
        est = _create(params, inp)
        W, A, anc, Z, dt = inp.w_body, inp.a_nav, inp.anchor_nav, inp.range_m, inp.dt_s

        def loop():
            for k in range(len(Z)):
                est.predict(W[k], A[k], dt)
                est.update_range(anc[k], Z[k])

        return _timed(loop), len(Z), _accepted(est)

    return block


def _dispatch_block(params: EstimatorParams, inp: Inputs) -> Block:
    K = len(inp.range_m)
    W, A = inp.w_body.reshape(K, 1, 3), inp.a_nav.reshape(K, 1, 3)
    anc, Z = inp.anchor_nav.reshape(K, 1, 3), inp.range_m.reshape(K, 1)
    sigma, mask = np.full(1, params.sigma_range_m), np.ones(1, dtype=np.bool_)
    gate, prm, dt = chi2_gate(1, params.gate_probability), params.param_vector(), inp.dt_s

    def block():
        est = _create(params, inp)
        X, P, counts, book, status = est.X, est.P, est.counts, est.book, np.zeros(1, dtype=np.int64)

        def loop():
            for k in range(K):
                nb.predict_batch(X, P, counts, book, W[k], A[k], dt, prm, status)
                nb.update_range_batch(X, P, counts, book, prm, anc[k], Z[k], sigma, mask, gate, status)

        return _timed(loop), K, _accepted(est)

    return block


def _compiled_block(params: EstimatorParams, inp: Inputs, piece: str = "step") -> Block:
    """The whole step (:func:`_kernel_loop`) or one of :data:`PIECES` (:func:`_piece_loop`)."""
    gate, prm, K = chi2_gate(1, params.gate_probability), params.param_vector(), len(inp.range_m)
    run_ = (inp.w_body, inp.a_nav, inp.dt_s, inp.anchor_nav)

    def block():
        est = _create(params, inp)
        state, out = (est.X[0], est.P[0], est.counts[0], est.book[0], prm), []
        if piece == "step":
            seconds = _timed(
                lambda: out.append(_kernel_loop(*state, *run_, inp.range_m, params.sigma_range_m, gate))
            )
            return seconds, K, out[0]
        index = PIECES.index(piece)
        return _timed(lambda: _piece_loop(index, *state, *run_, params.sigma_range_m)), K, K

    return block


def _filterpy_block(params: EstimatorParams, inp: Inputs) -> Block:
    def block():
        f = FilterPyMekf(params, inp.p0_nav, inp.v0_nav, inp.q0_nav_body, inp.cov0, inp.dt_s)
        W, A, anc, Z = inp.w_body, inp.a_nav, inp.anchor_nav, inp.range_m

        def loop():
            for k in range(len(Z)):
                f.step(W[k], A[k], anc[k], Z[k])

        return _timed(loop), len(Z), len(Z)  # no gate: every range is used

    return block


def _batched_block(params: EstimatorParams, inp: Inputs, n: int, seed: int) -> Block:
    K = len(inp.range_m)
    W = np.ascontiguousarray(np.broadcast_to(inp.w_body[:, None, :], (K, n, 3)))
    A = np.ascontiguousarray(np.broadcast_to(inp.a_nav[:, None, :], (K, n, 3)))
    rng = np.random.default_rng(seed)
    Z = inp.range_true_m[:, None] + rng.normal(0.0, params.sigma_range_m, (K, n))  # own noise per filter

    def block():
        est = _create(params, inp, n)

        def loop():
            for k in range(K):
                est.predict(W[k], A[k], inp.dt_s)
                est.update_range(inp.anchor_nav[k], Z[k])

        return _timed(loop), K * n, _accepted(est)

    return block


def _stats_us(seconds: list[float], units: int) -> dict[str, float]:
    us = np.asarray(seconds) / units * 1e6
    return {"median": float(np.median(us)), "p90": float(np.percentile(us, 90)), "min": float(us.min())}


def _measure(blocks: dict[str, Block], repeats: int) -> dict[str, dict]:
    """Warm up every block once (numba compiles or loads its cache here), then run ``repeats`` rounds,
    one block of each case per round, so slow phases of a noisy machine hit every case alike."""
    units, accepted = {}, {}
    for name, block in blocks.items():
        _, units[name], _ = block()
    seconds: dict[str, list[float]] = {name: [] for name in blocks}
    for _ in range(repeats):
        for name, block in blocks.items():
            s, _, accepted[name] = block()
            seconds[name].append(s)
    return {
        name: {**_stats_us(seconds[name], units[name]), "accepted_fraction": accepted[name] / units[name]}
        for name in blocks
    }


# ---- FLOP model --------------------------------------------------------------------------------------
# One FLOP per +, -, *, / and per sqrt, sin, cos; x**2 and x**3 are 1 and 2 multiplies; negation,
# comparisons and integer work are free.

_FLOP_PARTS = ("predict", "update", "correction")


def _mm(a: int, b: int, c: int) -> int:
    """Dense ``(a x b) @ (b x c)``: ``a c`` dot products of ``b`` multiplies and ``b - 1`` adds."""
    return a * c * (2 * b - 1)


def _sandwich_dense(n: int) -> int:
    """``F P F^T`` as two dense n x n products: ``2 n^2 (2n - 1)`` (about ``4 n^3``)."""
    return 2 * _mm(n, n, n)


_QEXP, _QMUL, _QNORMALIZE, _QMAT = 17, 28, 12, 38
"""``swarm.core._rot_nb``: ``qexp3`` on its small-angle branch (``|phi| < 1e-3`` rad, which the reset's
corrections and most 10 ms gyro increments take; the sin/cos branch is 4 fewer), ``qmul``, ``qnormalize``
and ``qmat``."""
_PREDICT_SCALAR = 24 + 3 + _QEXP + _QMUL + _QNORMALIZE + _QMAT + 8 + 1
"""Textbook predict outside ``P``: p += v dt + a dt^2/2 and v += a dt (24), w dt (3), q (x) exp(w dt)
normalised, Phi = R(dq)^T, the Q coefficients (8) and psd dt (1)."""
_RANGE_MODEL = _QMAT + _mm(3, 3, 1) + 3 + 3 + 5 + 1 + 3 + _mm(1, 3, 3) + _mm(1, 3, 3) + 2
"""Textbook range model: R(q), R(q) P1, + p, - anchor, |d|^2, sqrt, u = d / h, u^T R(q),
(u^T R(q)) [P1 x], then nu and sigma^2."""


def _joseph_dense(n: int) -> int:
    """Textbook update of an ``n``-state filter with one range: ``P H^T``, ``S = H P H^T + R``,
    ``d2 = nu^2 / S``, ``K = P H^T / S``, ``A = I - K H``, dense Joseph ``A P A^T + K R K^T``
    (Crassidis & Junkins 2011 eq. 5.39), ``dx = K nu``."""
    n2 = n * n
    gain = _mm(n, n, 1) + _mm(1, n, 1) + 1 + 3 + n
    joseph = 2 * n2 + _sandwich_dense(n) + _mm(n, 1, 1) + _mm(n, 1, n) + n2
    return gain + joseph + n


def _dense_items(tandem: bool) -> dict[str, int]:
    if tandem:  # two filters: 6-state translation, 3-state attitude; the range only updates the first
        cov = _sandwich_dense(6) + 36 + _sandwich_dense(3) + 9
        consider = _mm(1, 3, 3) + _mm(1, 3, 1) + 1  # R + H_th P_thth H_th^T
        reset = 0
    else:
        cov, consider = _sandwich_dense(9) + 81, 0
        reset = _QEXP + _QMUL + _QNORMALIZE + 18 + _sandwich_dense(9)  # q (x) exp(dth), T = I - [dth x]/2
    return {
        "predict/state": _PREDICT_SCALAR,
        "predict/covariance": cov,
        "update/range_model": _RANGE_MODEL,
        "update/consider": consider,
        "update/gain_joseph": _joseph_dense(6 if tandem else 9),
        "correction/state": 6,
        "correction/reset": reset,
    }


def _executed_items(tandem: bool) -> dict[str, int]:
    """The statements of ``predict_one``, ``update_range_one`` (``_range_row``, ``_update_scalar``) and
    ``_reset_attitude`` in ``swarm/core/_ekf_nb.py``, counted as written (the compiler may hoist a few
    loop invariants such as ``dt * dt``)."""
    n = 6 if tandem else 9
    return {
        "predict/kinematics": 3 * (6 + 2),  # p += v dt + 0.5 a dt dt, v += a dt
        "predict/quaternion": 3 + _QEXP + _QMUL + 9 + 4,  # w dt, exp, q (x) dq, 1 / |q|, scale
        "predict/phi": 3 * 5 + 6 * 4,  # Phi = R(dq)^T as scalars
        "predict/P_translation": 9 * 10 + 3 * 15,  # P_pp, P_pv, P_vp elementwise; Q (15 per axis)
        "predict/P_cross": 0 if tandem else 9 * 2 + 6 * 3 * 5,  # rows p += dt rows v; 6 rows times Phi^T
        "predict/P_attitude": 9 * 5 + 6 * 5 + 1 + 3,  # T = Phi P, upper triangle of T Phi^T, + psd dt
        "predict/bookkeeping": 1,  # time since the last update
        "update/range_model": 39 + 21 + 6 + 3 + 15 + 9 + 2,  # R(q), d, |d|, u, R^T u, P1 x (R^T u); nu, r
        # u = P H^T, s = H u, consider H_th P_thth H_th^T (tandem), S and d2, K = u / S, u - K s
        "update/gain": 2 * n * n + 2 * n + (27 if tandem else 0) + 3 + n + 2 * n,
        "update/joseph": 10 * n * (n + 1),  # 2 x 9 per upper-triangle entry and their mean (2)
        "correction/state": 6 * 2,  # p, v += K nu
        # dth = K nu, q (x) exp(dth) normalised, G = I - [dth x]/2 (18), G on rows and on columns
        "correction/reset": 0 if tandem else 3 + _QEXP + _QMUL + _QNORMALIZE + 18 + 2 * 9 * 3 * 5,
    }


def flops_per_step(structure: str, dense: bool = False) -> dict:
    """FLOPs of one predict + one accepted range update: ``predict``, ``update``, ``correction`` (state
    correction and multiplicative reset), ``total``, and ``items``, the itemised counts they sum.

    ``dense=False`` ("as executed") counts what the compiled kernels in ``swarm/core/_ekf_nb.py`` execute:
    ``F P F^T + Q`` block by block in place (translation elementwise, cross blocks only for compounded,
    the 3x3 attitude block with scalars), the range model in scalars, the O(n^2) scalar Joseph update of
    ``_update_scalar`` (tandem ``n = 6`` with the attitude block considered as noise, compounded ``n = 9``)
    and, for compounded, ``_reset_attitude`` on the attitude rows and columns.
    ``tests/test_bench_estimator.py`` checks these counts against the kernels' Python source run on
    counting scalars.

    ``dense=True`` is the textbook algorithm as a straightforward MATLAB script executes it, to compare
    with the paper's Table I: ``F P F^T`` as dense products (tandem: a 6x6 and a 3x3 filter), the dense
    Joseph form ``(I - K H) P (I - K H)^T + K R K^T`` (Crassidis & Junkins 2011 eq. 5.39), and for
    compounded the dense reset sandwich ``T P T^T``, ``T = I - [dth x]/2`` on attitude (Markley 2003).
    """
    if structure not in STRUCTURES:
        raise ValueError(f"structure must be 'tandem' or 'compounded', got {structure!r}")
    items = (_dense_items if dense else _executed_items)(structure == "tandem")
    out = {part: sum(v for k, v in items.items() if k.startswith(part + "/")) for part in _FLOP_PARTS}
    return {**out, "total": sum(items.values()), "items": items}


# ---- the run -----------------------------------------------------------------------------------------


def _load_1m() -> float | None:
    return round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None


def machine_info() -> dict:
    """CPU model (from /proc/cpuinfo), core count, load and library versions, for the JSON record."""
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), None)
    except OSError:
        cpu = None
    try:
        from filterpy import __version__ as fp_version
    except ImportError:
        fp_version = None
    return {
        "cpu_model": cpu or platform.processor() or None,
        "cpu_count": os.cpu_count(),
        "load_avg_1m": _load_1m(),
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "numba": numba.__version__,
        "filterpy": fp_version,
    }


def run(config: BenchConfig = FULL) -> dict:
    """Measure every case (module docstring) in this process; returns the JSON record."""
    load_before = _load_1m()
    base = EstimatorParams()
    params = {s: replace(base, structure=Structure(s)) for s in STRUCTURES}
    inp = make_inputs(config.steps, config.dt_s, base, config.seed)
    blocks: dict[str, Block] = {}
    for s in STRUCTURES:
        blocks[f"api/{s}"] = _api_block(params[s], inp)
        blocks[f"dispatch/{s}"] = _dispatch_block(params[s], inp)
        blocks[f"kernel/{s}"] = _compiled_block(params[s], inp)
    has_filterpy = filterpy_available()
    if has_filterpy:
        blocks["filterpy"] = _filterpy_block(params["compounded"], inp)
    for i, piece in enumerate(PIECES):
        for s in STRUCTURES if i < 2 else ("shared",):
            blocks[f"piece/{s}/{piece}"] = _compiled_block(params.get(s, params["compounded"]), inp, piece)
    log.info("estimator bench: %d cases x %d blocks of %d steps", len(blocks), config.repeats, config.steps)
    single = _measure(blocks, config.repeats)
    pieces: dict[str, dict[str, float]] = {s: {} for s in (*STRUCTURES, "shared")}
    for key in [k for k in single if k.startswith("piece/")]:
        _, group, piece = key.split("/")
        pieces[group][piece] = 1e3 * single.pop(key)["median"]

    binp = make_inputs(config.batch_steps, config.dt_s, base, config.seed)
    bblocks = {
        f"{s}/{n}": _batched_block(params[s], binp, n, config.seed + 1)
        for s in STRUCTURES
        for n in config.batch_sizes
    }
    log.info("estimator bench: batched, n in %s", config.batch_sizes)
    batched = _measure(bblocks, config.batch_repeats)

    api = {s: single[f"api/{s}"]["median"] for s in STRUCTURES}
    kernel = {s: single[f"kernel/{s}"]["median"] for s in STRUCTURES}
    fp = single["filterpy"]["median"] if has_filterpy else None
    for s in STRUCTURES:
        pieces[s]["step"] = 1e3 * kernel[s]
        pieces[s]["range_update"] = 1e3 * kernel[s] - pieces[s]["predict"]  # derived: step - predict
    flops = {
        s: {"dense": flops_per_step(s, True), "kernel": flops_per_step(s), "paper": PAPER_TABLE_I[s]["flops"]}
        for s in STRUCTURES
    }
    paper_ms = {s: PAPER_TABLE_I[s]["runtime_ms"] for s in STRUCTURES}
    ratios = {
        "tandem_over_compounded_api": api["tandem"] / api["compounded"],
        "tandem_over_compounded_kernel": kernel["tandem"] / kernel["compounded"],
        "tandem_over_filterpy": None if fp is None else api["tandem"] / fp,
        "compounded_over_filterpy": None if fp is None else api["compounded"] / fp,
        "paper_tandem_over_compounded": paper_ms["tandem"] / paper_ms["compounded"],
    }
    for kind in ("paper", "dense", "kernel"):
        tandem, compounded = (flops[s][kind] for s in STRUCTURES)
        key = (
            "paper_flops_tandem_over_compounded"
            if kind == "paper"
            else f"flops_tandem_over_compounded_{kind}"
        )
        ratios[key] = tandem / compounded if kind == "paper" else tandem["total"] / compounded["total"]
    for s in STRUCTURES:
        ratios[f"paper_speedup_{s}_api"] = paper_ms[s] * 1e3 / api[s]
        ratios[f"paper_speedup_{s}_kernel"] = paper_ms[s] * 1e3 / kernel[s]
    goals = {}
    for key, (ratio, target, op, _) in GOALS.items():
        value = ratios[ratio]
        met = None if value is None else bool(value <= target if op == "<=" else value >= target)
        goals[key] = {"value": value, "target": target, "met": met}
    return {
        "tandem_us": api["tandem"],
        "compounded_us": api["compounded"],
        "filterpy_us": fp,
        "paper_tandem_ms": paper_ms["tandem"],
        "paper_compounded_ms": paper_ms["compounded"],
        "filterpy_note": None if has_filterpy else FILTERPY_MISSING,
        "tandem_kernel_us": kernel["tandem"],
        "compounded_kernel_us": kernel["compounded"],
        "tandem_dispatch_us": single["dispatch/tandem"]["median"],
        "compounded_dispatch_us": single["dispatch/compounded"]["median"],
        "stats_us": single,
        "kernel_pieces_ns": pieces,
        "batched_us_per_filter": {
            s: {str(n): batched[f"{s}/{n}"]["median"] for n in config.batch_sizes} for s in STRUCTURES
        },
        "batched_stats_us_per_filter": batched,
        "flops": flops,
        "ratios": ratios,
        "goals": goals,
        "config": asdict(config),
        "machine": {**machine_info(), "load_avg_1m_before": load_before},
    }


# ---- report ------------------------------------------------------------------------------------------


def _fmt(stats: dict | None) -> str:
    return "-" if stats is None else f"{stats['median']:8.2f} [{stats['p90']:7.2f}]"


def format_report(r: dict) -> str:
    """The record of :func:`run` as a printable table, ratios, kernel pieces and goal verdicts."""
    st, cfg, ra, fl, pc, m = (
        r[k] for k in ("stats_us", "config", "ratios", "flops", "kernel_pieces_ns", "machine")
    )
    lines = [
        "Estimator step: one predict + one UWB range update, n = 1 filter",
        f"median [p90] us per step over {cfg['repeats']} interleaved blocks of {cfg['steps']} steps; API = "
        "PoseEstimator, dispatch = compiled batch kernels called from Python, kernel = compiled loop",
        "",
        f"{'structure':<11}| {'API us':>18} | {'dispatch us':>18} | {'kernel us':>18} | "
        f"{'FLOPs dense/exec.':>18} | {'paper FLOPs':>11} | {'paper ms':>8} | {'x faster API/kernel':>19}",
    ]
    for s in STRUCTURES:
        speed = f"{ra[f'paper_speedup_{s}_api']:.0f} / {ra[f'paper_speedup_{s}_kernel']:.0f}"
        lines.append(
            f"{s:<11}| {_fmt(st[f'api/{s}']):>18} | {_fmt(st[f'dispatch/{s}']):>18} | "
            f"{_fmt(st[f'kernel/{s}']):>18} | {fl[s]['dense']['total']:>8,} / "
            f"{fl[s]['kernel']['total']:>7,} | {fl[s]['paper']:>11,} | "
            f"{PAPER_TABLE_I[s]['runtime_ms']:>8.3f} | {speed:>19}"
        )
    fp_cells = (
        f"{_fmt(st['filterpy']):>18} | {'-':>18} | {'-':>18} | compounded model" if r["filterpy_us"] else ""
    )
    lines.append(f"{'filterpy':<11}| {fp_cells or r['filterpy_note']}")
    accepted = min(v["accepted_fraction"] for v in st.values())
    accepted_b = min(v["accepted_fraction"] for v in r["batched_stats_us_per_filter"].values())
    lines += [
        "",
        f"ranges accepted by the 99.99 % gate (lowest over cases): {100 * accepted:.2f} % single, "
        f"{100 * accepted_b:.2f} % batched",
        f"tandem / compounded: API {ra['tandem_over_compounded_api']:.2f}, kernel "
        f"{ra['tandem_over_compounded_kernel']:.2f} (paper: runtime "
        f"{ra['paper_tandem_over_compounded']:.2f}, FLOPs {ra['paper_flops_tandem_over_compounded']:.2f}; "
        f"FLOP model: dense {ra['flops_tandem_over_compounded_dense']:.2f}, "
        f"as executed {ra['flops_tandem_over_compounded_kernel']:.2f})",
    ]
    if r["filterpy_us"] is not None:
        lines.append(
            f"tandem / FilterPy (API): {ra['tandem_over_filterpy']:.3f}; "
            f"compounded / FilterPy: {ra['compounded_over_filterpy']:.3f}"
        )
    for s in STRUCTURES:
        parts = ", ".join(f"{k} {fl[s]['kernel'][k]:,} ({fl[s]['dense'][k]:,})" for k in _FLOP_PARTS)
        lines.append(f"FLOPs {s} as executed (dense): {parts}")
    lines.append("kernel pieces, ns per call (compiled loops, median; range update = step - predict):")
    for s in STRUCTURES:
        p = pc[s]
        lines.append(
            f"  {s:<11} step {p['step']:.0f} = predict {p['predict']:.0f} + range update "
            f"{p['range_update']:.0f}; _update_scalar without reset {p['update_scalar']:.0f}"
        )
    sh = pc["shared"]
    lines.append(
        f"  {'shared':<11} _reset_attitude {sh['reset']:.0f} (compounded), _range_row {sh['range_row']:.0f}, "
        f"_all_finite of a 3-vector {sh['all_finite']:.0f} (3 per step; as three np.isfinite "
        f"{sh['finite_loop']:.0f}), np.empty((3, 9)) {sh['workspace']:.0f}"
    )
    lines.append("batched, us per filter per step (PoseEstimator with n filters, median [p90]):")
    for s in STRUCTURES:
        cells = [f"n={n}: {_fmt(r['batched_stats_us_per_filter'][f'{s}/{n}'])}" for n in cfg["batch_sizes"]]
        lines.append(f"  {s:<11} " + "   ".join(cells))
    lines += ["", "goals (reported, not asserted):"]
    for key, (_, target, op, label) in GOALS.items():
        g = r["goals"][key]
        verdict = {True: "met    ", False: "NOT met", None: "n/a    "}[g["met"]]
        value = "-" if g["value"] is None else f"{g['value']:.3g}"
        lines.append(f"  [{verdict}] {label:<32} {value:>6} (target {op} {target:g})")
    lines += [
        "",
        f"machine: {m['cpu_model']}, {m['cpu_count']} cores, 1-min load {m['load_avg_1m_before']} before, "
        f"{m['load_avg_1m']} after; python {m['python']}, numpy {m['numpy']}, numba {m['numba']}, "
        f"filterpy {m['filterpy']}",
    ]
    return "\n".join(lines)
