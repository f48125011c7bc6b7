"""Estimator step benchmark (issue 2): one predict + one UWB range update, the unit of paper Table I.

Measured in one process, cases interleaved block by block so that machine noise hits them alike:

* **API**: :class:`~swarm.core.estimator.PoseEstimator` with ``n = 1``, ``predict`` + ``update_range``
  from Python, for the tandem and compounded structures (DESIGN.md section 8: ``tandem_us``,
  ``compounded_us``).
* **dispatch**: the compiled batch kernels (``_ekf_nb.predict_batch``, ``update_range_batch``) called
  directly from Python with ready-made arrays: what is left of the API once argument handling is gone.
* **kernel**: a compiled loop over ``_ekf_nb.predict_one`` + ``update_range_one`` on one filter, no
  Python at all: the structure's computational cost, which is what Table I compares.
* **FilterPy**: ``filterpy.kalman.ExtendedKalmanFilter`` running the same 9-state multiplicative model
  (:class:`FilterPyMekf`, tested equal to the compounded filter to 1e-9), an optional extra.
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
FILTERPY_MISSING = "filterpy not installed (pip install .[bench])"
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

    p0_ms: np.ndarray  # (3,) initial position estimate [m], frame c
    v0_ms: np.ndarray  # (3,) initial velocity estimate [m/s]
    q0_ms_body: np.ndarray  # (4,) initial attitude estimate, scalar-last
    cov0: np.ndarray  # (9, 9) initial error covariance, order (d_p, d_v, d_theta)
    w_body: np.ndarray  # (K, 3) gyro rates [rad/s]
    a_ms: np.ndarray  # (K, 3) known (commanded) acceleration [m/s^2], frame c
    anchor_ms: np.ndarray  # (K, 3) anchor ranged after step k's prediction
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
    a_ms = 0.01 * np.concatenate([np.sin(0.3 * t), np.cos(0.2 * t), -np.sin(0.25 * t)], axis=-1)
    p, v = np.array([-0.2, 0.0, 0.1]), np.array([0.02, 0.005, -0.01])
    q = rot.rotvec_exp(np.array([0.1, -0.2, 0.3]))
    sig0 = np.array([0.02] * 3 + [0.01] * 3 + [0.02] * 3)
    e0 = rng_init.normal(size=9) * sig0
    p0, v0, q0 = p + e0[:3], v + e0[3:6], rot.multiplicative_reset(q, -e0[6:])
    lever = np.asarray(params.lever_arm_body_m)
    anchors = PAPER_ANCHORS_MS[np.arange(steps) % len(PAPER_ANCHORS_MS)]
    r_true = np.empty(steps)
    for k in range(steps):
        p = p + v * dt_s + 0.5 * a_ms[k] * dt_s**2
        v = v + a_ms[k] * dt_s
        q = rot.quat_normalize(rot.quat_mul(q, rot.rotvec_exp(w_true[k] * dt_s)))
        r_true[k] = np.linalg.norm(p + rot.quat_rotate(q, lever) - anchors[k])
    gyro = w_true + rng_gyro.normal(0.0, params.gyro_arw_rad_rts / np.sqrt(dt_s), w_true.shape)
    return Inputs(
        p0_ms=p0,
        v0_ms=v0,
        q0_ms_body=q0,
        cov0=np.diag(sig0**2),
        w_body=np.ascontiguousarray(gyro),
        a_ms=np.ascontiguousarray(a_ms),
        anchor_ms=np.ascontiguousarray(anchors),
        range_true_m=r_true,
        range_m=r_true + rng_uwb.normal(0.0, params.sigma_range_m, steps),
        dt_s=dt_s,
    )


# ---- FilterPy on the same model ----------------------------------------------------------------------


class FilterPyMekf:
    """FilterPy's ``ExtendedKalmanFilter`` (dim_x=9, dim_z=1) running the compounded filter's model.

    The state is the error state ``(p, v, d_theta)`` around a reference quaternion ``q_ms_body`` that is
    propagated with the gyro outside FilterPy (paper eq. 3). Per step: ``F = [[I, dt I, 0], [0, I, 0],
    [0, 0, Phi]]`` with ``Phi = R(exp(w dt))^T`` (Crassidis & Junkins 2011 sec. 7.2.4), the known
    acceleration through ``B = [dt^2/2 I; dt I; 0]``, ``Q`` the white-noise-acceleration blocks
    ``q dt^3/3, q dt^2/2, q dt`` plus ``psd dt I`` on attitude; then ``ekf.update`` with the range model of
    ``_ekf_nb.range_model`` (``h = |p + R(q) P1 - a|``, ``H = [u^T, 0, -u^T R(q) [P1 x]]``) and the
    multiplicative reset ``q <- q (x) exp(d_theta)``, ``P <- T P T^T``, ``T = I - 1/2 [d_theta x]`` on
    the attitude block (Markley 2003; Mueller, Hehn & D'Andrea 2016). ``d_theta`` is zero before every
    update, so ``h`` and ``H`` are evaluated at the reference attitude, as in the compiled kernel.
    ``F`` changes with the gyro each step; ``Q`` and ``B`` depend only on ``dt`` and are built once.
    FilterPy has no gate: with every range accepted both filters do the same algebra.
    """

    def __init__(self, params: EstimatorParams, p_ms, v_ms, q_ms_body, cov0, dt_s: float) -> None:
        from filterpy.kalman import ExtendedKalmanFilter

        self.ekf = ExtendedKalmanFilter(dim_x=9, dim_z=1)
        self.ekf.x = np.concatenate([p_ms, v_ms, np.zeros(3)]).reshape(9, 1)
        self.ekf.P = np.array(cov0, dtype=float)
        self.q_ms_body = np.array(q_ms_body, dtype=float)
        self.dt_s = dt_s
        self.sigma_range_m = params.sigma_range_m
        self.lever_body_m = np.asarray(params.lever_arm_body_m, dtype=float)
        self._skew_lever = rot.skew(self.lever_body_m)
        eye3, q_acc = np.eye(3), params.accel_psd_m2_s3
        Q = np.zeros((9, 9))
        Q[:3, :3] = q_acc * dt_s**3 / 3.0 * eye3
        Q[:3, 3:6] = Q[3:6, :3] = q_acc * dt_s**2 / 2.0 * eye3
        Q[3:6, 3:6] = q_acc * dt_s * eye3
        Q[6:, 6:] = (params.gyro_arw_rad_rts**2 + params.attitude_rw_extra_rad_rts**2) * dt_s * eye3
        self.ekf.Q = Q
        self.ekf.B = np.vstack([0.5 * dt_s**2 * eye3, dt_s * eye3, np.zeros((3, 3))])
        self._F = np.eye(9)
        self._F[:3, 3:6] = dt_s * eye3
        self._R_ms_body = rot.quat_to_matrix(self.q_ms_body)

    def _tag_offset(self, x: np.ndarray, anchor_ms: np.ndarray) -> np.ndarray:
        return x[:3, 0] + self._R_ms_body @ self.lever_body_m - anchor_ms

    def _hx(self, x: np.ndarray, anchor_ms: np.ndarray) -> np.ndarray:
        d = self._tag_offset(x, anchor_ms)
        return np.array([[np.sqrt(d @ d)]])

    def _h_jacobian(self, x: np.ndarray, anchor_ms: np.ndarray) -> np.ndarray:
        d = self._tag_offset(x, anchor_ms)
        u = d / np.sqrt(d @ d)
        H = np.zeros((1, 9))
        H[0, :3] = u
        H[0, 6:] = -(u @ self._R_ms_body) @ self._skew_lever
        return H

    def step(self, w_body: np.ndarray, a_ms: np.ndarray, anchor_ms: np.ndarray, range_m: float) -> None:
        """One predict with gyro ``w_body`` [rad/s] and acceleration ``a_ms`` [m/s^2], then one range."""
        ekf = self.ekf
        dq = rot.rotvec_exp(w_body * self.dt_s)
        self.q_ms_body = rot.quat_normalize(rot.quat_mul(self.q_ms_body, dq))
        self._R_ms_body = rot.quat_to_matrix(self.q_ms_body)
        self._F[6:, 6:] = rot.quat_to_matrix(dq).T
        ekf.F = self._F
        ekf.predict(u=a_ms.reshape(3, 1))
        ekf.update(
            np.array([range_m]), self._h_jacobian, self._hx, R=self.sigma_range_m**2,
            args=(anchor_ms,), hx_args=(anchor_ms,),
        )  # fmt: skip
        dth = ekf.x[6:, 0].copy()
        self.q_ms_body = rot.multiplicative_reset(self.q_ms_body, dth)
        self._R_ms_body = rot.quat_to_matrix(self.q_ms_body)
        x, y, z = 0.5 * dth
        T = np.eye(9)
        T[6:, 6:] = ((1.0, z, -y), (-z, 1.0, x), (y, -x, 1.0))  # I - [dth x] / 2 (rot.skew is slow)
        ekf.P = T @ ekf.P @ T.T
        ekf.x[6:] = 0.0


def filterpy_available() -> bool:
    try:
        import filterpy.kalman  # noqa: F401
    except ImportError:
        return False
    return True


# ---- compiled loop -----------------------------------------------------------------------------------


@numba.njit(cache=True)
def _kernel_loop(X, P, ST_I, ST_F, PRM, W, A, dt, anchors, Z, sigma, gate):
    """``len(W)`` steps of predict + one range on one filter, all compiled; returns the accepted count."""
    accepted = 0
    for k in range(W.shape[0]):
        nb.predict_one(X, P, ST_I, ST_F, W[k], A[k], dt, PRM)
        if nb.update_range_one(X, P, ST_I, ST_F, PRM, anchors[k], Z[k], sigma, gate) == nb.ST_ACCEPTED:
            accepted += 1
    return accepted


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


def _api_block(params: EstimatorParams, inp: Inputs) -> Block:
    def block():
        est = PoseEstimator.create(params, inp.p0_ms, inp.v0_ms, inp.q0_ms_body, inp.cov0)
        W, A, anc, Z, dt = inp.w_body, inp.a_ms, inp.anchor_ms, inp.range_m, inp.dt_s

        def loop():
            for k in range(len(Z)):
                est.predict(W[k], A[k], dt)
                est.update_range(anc[k], Z[k])

        return _timed(loop), len(Z), int(est.count(MeasKind.RANGE, "accepted").sum())

    return block


def _dispatch_block(params: EstimatorParams, inp: Inputs) -> Block:
    K = len(inp.range_m)
    W, A = inp.w_body.reshape(K, 1, 3), inp.a_ms.reshape(K, 1, 3)
    anc, Z = inp.anchor_ms.reshape(K, 1, 3), inp.range_m.reshape(K, 1)
    sigma, mask = np.full(1, params.sigma_range_m), np.ones(1, dtype=np.bool_)
    gate, prm, dt = chi2_gate(1, params.gate_probability), params.param_vector(), inp.dt_s

    def block():
        est = PoseEstimator.create(params, inp.p0_ms, inp.v0_ms, inp.q0_ms_body, inp.cov0)
        X, P, counts, book, status = est.X, est.P, est.counts, est.book, np.zeros(1, dtype=np.int64)

        def loop():
            for k in range(K):
                nb.predict_batch(X, P, counts, book, W[k], A[k], dt, prm, status)
                nb.update_range_batch(X, P, counts, book, prm, anc[k], Z[k], sigma, mask, gate, status)

        return _timed(loop), K, int(est.count(MeasKind.RANGE, "accepted").sum())

    return block


def _kernel_block(params: EstimatorParams, inp: Inputs) -> Block:
    gate, prm = chi2_gate(1, params.gate_probability), params.param_vector()

    def block():
        est = PoseEstimator.create(params, inp.p0_ms, inp.v0_ms, inp.q0_ms_body, inp.cov0)
        X, P, ST_I, ST_F = est.X[0], est.P[0], est.counts[0], est.book[0]
        args = (inp.w_body, inp.a_ms, inp.dt_s, inp.anchor_ms, inp.range_m, params.sigma_range_m, gate)
        accepted = []
        seconds = _timed(lambda: accepted.append(_kernel_loop(X, P, ST_I, ST_F, prm, *args)))
        return seconds, len(inp.range_m), accepted[0]

    return block


def _filterpy_block(params: EstimatorParams, inp: Inputs) -> Block:
    def block():
        f = FilterPyMekf(params, inp.p0_ms, inp.v0_ms, inp.q0_ms_body, inp.cov0, inp.dt_s)
        W, A, anc, Z = inp.w_body, inp.a_ms, inp.anchor_ms, inp.range_m

        def loop():
            for k in range(len(Z)):
                f.step(W[k], A[k], anc[k], Z[k])

        return _timed(loop), len(Z), len(Z)  # no gate: every range is used

    return block


def _batched_block(params: EstimatorParams, inp: Inputs, n: int, seed: int) -> Block:
    K = len(inp.range_m)
    W = np.ascontiguousarray(np.broadcast_to(inp.w_body[:, None, :], (K, n, 3)))
    A = np.ascontiguousarray(np.broadcast_to(inp.a_ms[:, None, :], (K, n, 3)))
    rng = np.random.default_rng(seed)
    Z = inp.range_true_m[:, None] + rng.normal(0.0, params.sigma_range_m, (K, n))  # own noise per filter

    def block():
        est = PoseEstimator.create(params, inp.p0_ms, inp.v0_ms, inp.q0_ms_body, inp.cov0, n=n)

        def loop():
            for k in range(K):
                est.predict(W[k], A[k], inp.dt_s)
                est.update_range(inp.anchor_ms[k], Z[k])

        return _timed(loop), K * n, int(est.count(MeasKind.RANGE, "accepted").sum())

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


def _mm(a: int, b: int, c: int) -> int:
    """Dense ``(a x b) @ (b x c)``: ``a c`` dot products of ``b`` multiplies and ``b - 1`` adds."""
    return a * c * (2 * b - 1)


def _sandwich_dense(n: int) -> int:
    """``F P F^T`` as two dense n x n products: ``2 n^2 (2n - 1)`` (about ``4 n^3``)."""
    return 2 * _mm(n, n, n)


def _sandwich_kernel(n: int, nnz: int) -> int:
    """``_ekf_nb._sandwich``: ``F P`` skipping zeros of ``F`` (``2 n nnz(F)``), then only the upper
    triangle of ``(F P) F^T`` with one multiply-add per term (``n (n + 1) / 2`` entries x ``2 n``)."""
    return 2 * n * nnz + n * n * (n + 1)


# Scalar work, counted from swarm/core/_rot_nb.py (sqrt, sin, cos, division count as one FLOP each).
_QEXP, _QMUL, _QNORMALIZE, _QMAT = 17, 28, 12, 38
_PREDICT_SCALAR = 24 + 3 + _QEXP + _QMUL + _QNORMALIZE + _QMAT + 8 + 1
"""p += v dt + a dt^2/2 and v += a dt (24), w dt (3), q (x) exp(w dt) normalised, Phi = qmat(dq)^T,
the Q coefficients (8) and psd dt (1)."""
_RANGE_MODEL = _QMAT + _mm(3, 3, 1) + 3 + 3 + 5 + 1 + 3 + _mm(1, 3, 3) + _mm(1, 3, 3) + 2
"""R(q), R(q) P1, + p, - anchor, |d|^2, sqrt, u = d / h, u^T R(q), (u^T R(q)) [P1 x], nu and sigma^2."""


def _joseph_range(n: int, h_nnz: int, dense: bool) -> int:
    """``_ekf_nb._kalman_block`` with one range (m = 1) on an ``n``-state block whose ``H`` has ``h_nnz``
    non-zeros: ``P H^T``, ``H P H^T + R``, ``d2 = nu^2 / S``, ``K = P H^T / S``, ``A = I - K H``,
    Joseph ``A P A^T + K R K^T`` (Crassidis & Junkins 2011 eq. 5.39), ``dx = K nu``. The kernel's ``A``
    has ``n h_nnz`` non-zeros in the columns ``H`` touches plus ones on the rest of the diagonal."""
    n2 = n * n
    rest = _mm(n, n, 1) + _mm(1, n, 1) + 1 + 3 + n + 2 * n2 + _mm(n, 1, 1) + _mm(n, 1, n) + n2 + n
    nnz_a = n * h_nnz + (n - h_nnz)
    return rest + (_sandwich_dense(n) if dense else _sandwich_kernel(n, nnz_a))


def flops_per_step(structure: str, dense: bool = True) -> dict[str, int]:
    """FLOPs of one predict + one accepted range update, itemised, from the kernels in ``_ekf_nb``.

    ``dense=True`` counts every matrix product as dense (``_mm``), the textbook algorithm a MATLAB script
    runs; ``dense=False`` counts what the compiled kernel executes (zero-skipping, symmetric
    ``_sandwich``). Compounded (n = 9): ``F P F^T + Q``, the Joseph update on 9 states, and the
    multiplicative reset ``T P T^T`` that follows every range (the range corrects attitude). Tandem
    (6 + 3): ``F P F^T + Q`` on 6 states and ``Phi P Phi^T + Q`` on 3, the range's attitude partials
    folded into the noise (``R + H_a P_a H_a^T``; the kernel also forms ``R + H_t P_t H_t^T``, unused
    for a range), the Joseph update on 6 states and no reset (``d_theta`` stays zero).
    """
    if structure == "compounded":
        predict = _PREDICT_SCALAR + (_sandwich_dense(9) + 81 if dense else _sandwich_kernel(9, 18) + 39)
        update = _RANGE_MODEL + _joseph_range(9, 6, dense)
        reset_sandwich = _sandwich_dense(9) if dense else _sandwich_kernel(9, 15)
        correction = 6 + _QEXP + _QMUL + _QNORMALIZE + 18 + reset_sandwich
    elif structure == "tandem":
        if dense:
            predict = _PREDICT_SCALAR + _sandwich_dense(6) + 36 + _sandwich_dense(3) + 9
        else:
            predict = _PREDICT_SCALAR + _sandwich_kernel(6, 9) + 36 + _sandwich_kernel(3, 9) + 3
        consider = (_mm(1, 3, 3) + _mm(1, 3, 1) + 1) + (_mm(1, 6, 6) + _mm(1, 6, 1) + 1)
        update = _RANGE_MODEL + consider + _joseph_range(6, 3, dense)
        correction = 6
    else:
        raise ValueError(f"structure must be 'tandem' or 'compounded', got {structure!r}")
    total = predict + update + correction
    return {"predict": predict, "update": update, "correction": correction, "total": total}


# ---- the run -----------------------------------------------------------------------------------------


def _load_1m() -> float | None:
    return round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None


def machine_info() -> dict:
    """CPU model (from /proc/cpuinfo), core count, load and library versions, for the JSON record."""
    cpu = None
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), None)
    except OSError:
        pass
    try:
        import filterpy

        fp_version = filterpy.__version__
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


def _ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None else a / b


def run(config: BenchConfig = FULL) -> dict:
    """Measure every case (module docstring) in this process; returns the JSON record (DESIGN.md sec. 8)."""
    load_before = _load_1m()
    base = EstimatorParams()
    params = {s: replace(base, structure=Structure(s)) for s in STRUCTURES}
    inp = make_inputs(config.steps, config.dt_s, base, config.seed)
    blocks: dict[str, Block] = {}
    for s in STRUCTURES:
        blocks[f"api/{s}"] = _api_block(params[s], inp)
        blocks[f"dispatch/{s}"] = _dispatch_block(params[s], inp)
        blocks[f"kernel/{s}"] = _kernel_block(params[s], inp)
    has_filterpy = filterpy_available()
    if has_filterpy:
        blocks["filterpy"] = _filterpy_block(params["compounded"], inp)
    log.info("estimator bench: %d cases x %d blocks of %d steps", len(blocks), config.repeats, config.steps)
    single = _measure(blocks, config.repeats)

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
    flops = {
        s: {
            "dense": flops_per_step(s, dense=True),
            "kernel": flops_per_step(s, dense=False),
            "paper": PAPER_TABLE_I[s]["flops"],
        }
        for s in STRUCTURES
    }
    paper_ms = {st: PAPER_TABLE_I[st]["runtime_ms"] for st in STRUCTURES}
    ratios = {
        "tandem_over_compounded_api": api["tandem"] / api["compounded"],
        "tandem_over_compounded_kernel": kernel["tandem"] / kernel["compounded"],
        "tandem_over_filterpy": _ratio(api["tandem"], fp),
        "compounded_over_filterpy": _ratio(api["compounded"], fp),
        "paper_tandem_over_compounded": paper_ms["tandem"] / paper_ms["compounded"],
        "paper_flops_tandem_over_compounded": flops["tandem"]["paper"] / flops["compounded"]["paper"],
    }
    for kind in ("dense", "kernel"):
        tc = flops["tandem"][kind]["total"] / flops["compounded"][kind]["total"]
        ratios[f"flops_tandem_over_compounded_{kind}"] = tc
    for st in STRUCTURES:
        ratios[f"paper_speedup_{st}_api"] = paper_ms[st] * 1e3 / api[st]
        ratios[f"paper_speedup_{st}_kernel"] = paper_ms[st] * 1e3 / kernel[st]
    goals = {}
    for key, (ratio, target, op, _) in GOALS.items():
        value = ratios[ratio]
        met = None if value is None else bool(value <= target if op == "<=" else value >= target)
        goals[key] = {"value": value, "target": target, "met": met}
    return {
        "tandem_us": api["tandem"],
        "compounded_us": api["compounded"],
        "filterpy_us": fp,
        "paper_tandem_ms": PAPER_TABLE_I["tandem"]["runtime_ms"],
        "paper_compounded_ms": PAPER_TABLE_I["compounded"]["runtime_ms"],
        "filterpy_note": None if has_filterpy else FILTERPY_MISSING,
        "tandem_kernel_us": kernel["tandem"],
        "compounded_kernel_us": kernel["compounded"],
        "tandem_dispatch_us": single["dispatch/tandem"]["median"],
        "compounded_dispatch_us": single["dispatch/compounded"]["median"],
        "stats_us": single,
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
    """The record of :func:`run` as a printable table, ratios and goal verdicts."""
    st, cfg = r["stats_us"], r["config"]
    lines = [
        "Estimator step: one predict + one UWB range update, n = 1 filter",
        f"median [p90] us per step over {cfg['repeats']} interleaved blocks of {cfg['steps']} steps; "
        f"API = PoseEstimator, dispatch = compiled batch kernels called from Python, "
        f"kernel = compiled loop",
        "",
        f"{'structure':<11}| {'API us':>18} | {'dispatch us':>18} | {'kernel us':>18} | "
        f"{'FLOPs dense/kernel':>18} | {'paper FLOPs':>11} | {'paper ms':>8} | {'x faster API/kernel':>19}",
    ]
    for s in STRUCTURES:
        fl, paper = r["flops"][s], PAPER_TABLE_I[s]
        ra = r["ratios"]
        speed = f"{ra[f'paper_speedup_{s}_api']:.0f} / {ra[f'paper_speedup_{s}_kernel']:.0f}"
        lines.append(
            f"{s:<11}| {_fmt(st[f'api/{s}']):>18} | {_fmt(st[f'dispatch/{s}']):>18} | "
            f"{_fmt(st[f'kernel/{s}']):>18} | {fl['dense']['total']:>8,} / {fl['kernel']['total']:>7,} | "
            f"{paper['flops']:>11,} | {paper['runtime_ms']:>8.3f} | {speed:>19}"
        )
    if r["filterpy_us"] is None:
        lines.append(f"{'filterpy':<11}| {r['filterpy_note']}")
    else:
        lines.append(
            f"{'filterpy':<11}| {_fmt(st['filterpy']):>18} | {'-':>18} | {'-':>18} | "
            f"{'compounded model, numpy':>18}"
        )
    ra = r["ratios"]
    accepted = min(v["accepted_fraction"] for v in st.values())
    accepted_b = min(v["accepted_fraction"] for v in r["batched_stats_us_per_filter"].values())
    lines += [
        "",
        f"ranges accepted by the 99.99 % gate (lowest over cases): {100 * accepted:.2f} % single, "
        f"{100 * accepted_b:.2f} % batched",
        f"tandem / compounded: API {ra['tandem_over_compounded_api']:.2f}, "
        f"kernel {ra['tandem_over_compounded_kernel']:.2f} "
        f"(paper: runtime {ra['paper_tandem_over_compounded']:.2f}, "
        f"FLOPs {ra['paper_flops_tandem_over_compounded']:.2f}; FLOP model: dense "
        f"{ra['flops_tandem_over_compounded_dense']:.2f}, "
        f"kernel {ra['flops_tandem_over_compounded_kernel']:.2f})",
    ]
    if r["filterpy_us"] is not None:
        lines.append(
            f"tandem / FilterPy (API): {ra['tandem_over_filterpy']:.3f}; "
            f"compounded / FilterPy: {ra['compounded_over_filterpy']:.3f}"
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
    m = r["machine"]
    lines += [
        "",
        f"machine: {m['cpu_model']}, {m['cpu_count']} cores, 1-min load {m['load_avg_1m_before']} before, "
        f"{m['load_avg_1m']} after; "
        f"python {m['python']}, numpy {m['numpy']}, numba {m['numba']}, filterpy {m['filterpy']}",
    ]
    return "\n".join(lines)
