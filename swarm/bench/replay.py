"""``swarm bench replay``: a recorded log through the IMU-driven filter, and its step against the tandem's
(issue 14).

* **Replay**: a synthetic 60 s log (1 kHz IMU, 80 Hz ranges to 8 anchors, :mod:`swarm.logs.synthetic`)
  read from its CSV files, then replayed (:func:`swarm.logs.replay.replay_log`) after one warm-up replay
  (compilation excluded); medians of the repeats.
* **Step**: one IMU-driven predict + one range update (15 + 8 error states, the log's filter; and with
  the 15 states alone, no range-bias states), compiled loops on one filter, against the tandem filter's
  step (:func:`swarm.bench.estimator._kernel_loop`, the unit of paper Table I), interleaved block by block
  so that the machine's noise hits both alike; and the same through the batched API (``ImuFilter`` with
  ``n`` filters, time per filter) against ``PoseEstimator`` with ``n`` filters.
"""

from __future__ import annotations

import tempfile
import time

import numba
import numpy as np

from swarm.core import _imu_nb as nb

FULL = {"duration_s": 60.0, "repeats": 5, "steps": 2000, "batch": 100, "blocks": 7}
QUICK = {"duration_s": 20.0, "repeats": 2, "steps": 300, "batch": 20, "blocks": 2}


@numba.njit(cache=True)
def _imu_step_loop(X, P, gyro, acc, dt, PRM, anchors, bias_of, Z, sigma, work, res):
    """``len(Z)`` steps of one IMU predict + one range update on one filter, all compiled."""
    accepted = 0
    for k in range(Z.shape[0]):
        nb.predict_one(X, P, gyro[k], acc[k], dt, PRM)
        a = k % anchors.shape[0]
        if nb.update_range_one(X, P, anchors[a], bias_of[a], Z[k], sigma, PRM, work, res) == nb.ACCEPTED:
            accepted += 1
    return accepted


def _imu_inputs(steps: int, seed: int = 0):
    from swarm.core.imu_filter import ImuFilter, ImuFilterParams
    from swarm.logs.synthetic import ANCHORS, SyntheticSpec, truth_at

    spec = SyntheticSpec()
    t = 10.0 + np.arange(steps) * 0.01
    p, v, q, w, f = truth_at(spec, t)
    rng = np.random.default_rng(seed)
    a = np.arange(steps) % len(ANCHORS)
    z = np.linalg.norm(p - ANCHORS[a], axis=1) + rng.normal(0.0, 0.05, steps)
    params = ImuFilterParams()

    def make(range_bias: bool = True):
        prm = params if range_bias else ImuFilterParams(range_bias=False)
        return ImuFilter.create(prm, ANCHORS, p[0], v[0], q[0], t[0], 0.05)

    return make, w, f, z, params


def _step_blocks(cfg: dict) -> dict:
    from swarm.bench import estimator as eb
    from swarm.core.estimator import EstimatorParams, chi2_gate
    from swarm.core.imu_filter import ImuFilter

    steps, n = cfg["steps"], cfg["batch"]
    make, w, f, z, params = _imu_inputs(steps)
    tparams = EstimatorParams()
    tin = eb.make_inputs(steps, 0.01, tparams)
    gate, tprm = chi2_gate(1, tparams.gate_probability), tparams.param_vector()

    def imu_single(range_bias: bool = True):
        flt = make(range_bias)
        args = (
            flt.X[0],
            flt.P[0],
            w,
            f,
            0.01,
            flt.prm,
            flt.anchors,
            flt.bias_of,
            z,
            0.05,
            flt._work,
            flt._res,
        )
        t0 = time.perf_counter()
        _imu_step_loop(*args)
        return (time.perf_counter() - t0) / steps

    def tandem_single():
        est = eb._create(tparams, tin)
        t0 = time.perf_counter()
        eb._kernel_loop(est.X[0], est.P[0], est.counts[0], est.book[0], tprm, tin.w_body, tin.a_nav, tin.dt_s,
                        tin.anchor_nav, tin.range_m, tparams.sigma_range_m, gate)  # fmt: skip
        return (time.perf_counter() - t0) / steps

    def imu_batched():
        one = make()
        flt = ImuFilter(params, one.anchors, np.repeat(one.X, n, 0), np.repeat(one.P, n, 0), one.t, 0.05)
        k_max = min(steps, 200)
        t0 = time.perf_counter()
        for k in range(k_max):
            flt.imu(one.t + 0.01 * (k + 1), w[k], f[k])
            flt.update_range(one.t + 0.01 * (k + 1), k % len(one.anchors), z[k])
        return (time.perf_counter() - t0) / (k_max * n)

    def tandem_batched():
        est = eb._create(tparams, tin, n)
        k_max = min(steps, 200)
        t0 = time.perf_counter()
        for k in range(k_max):
            est.predict(tin.w_body[k], tin.a_nav[k], tin.dt_s)
            est.update_range(tin.anchor_nav[k], tin.range_m[k])
        return (time.perf_counter() - t0) / (k_max * n)

    cases = {"imu_single": imu_single, "tandem_single": tandem_single, "imu_batched": imu_batched,
             "tandem_batched": tandem_batched,
             "imu_single_no_range_bias": lambda: imu_single(False)}  # fmt: skip
    for fn in cases.values():  # compile
        fn()
    out: dict[str, list[float]] = {k: [] for k in cases}
    for _ in range(cfg["blocks"]):
        for k, fn in cases.items():
            out[k].append(fn())
    return {k: float(np.median(v)) * 1e6 for k, v in out.items()}


def run(cfg: dict) -> dict:
    from swarm.logs.reader import read_log
    from swarm.logs.replay import replay_log
    from swarm.logs.synthetic import SyntheticSpec, make_log

    with tempfile.TemporaryDirectory(prefix="swarm-bench-replay-") as d:
        make_log(d, seed=0, spec=SyntheticSpec(duration_s=cfg["duration_s"]))
        t0 = time.perf_counter()
        log = read_log(d)
        read_s = time.perf_counter() - t0
        replay_log(log)  # compile / load the kernels
        walls, reads = [], [read_s]
        for _ in range(cfg["repeats"]):
            t0 = time.perf_counter()
            log = read_log(d)
            reads.append(time.perf_counter() - t0)
            walls.append(replay_log(log).wall_s)
        summary = replay_log(log).summary()
    steps = _step_blocks(cfg)
    return {
        "bench": "replay",
        **cfg,
        "imu_samples": summary["imu_samples"],
        "ranges": summary["ranges"],
        "read_s": float(np.median(reads)),
        "replay_s": float(np.median(walls)),
        "rmse_m": summary["rmse_m"],
        "step_us": steps,
        "imu_over_tandem_single": steps["imu_single"] / steps["tandem_single"],
        "imu_over_tandem_batched": steps["imu_batched"] / steps["tandem_batched"],
        "imu_no_range_bias_over_tandem_single": steps["imu_single_no_range_bias"] / steps["tandem_single"],
    }


def format_report(r: dict) -> str:
    s = r["step_us"]
    return "\n".join([
        f"replay of a {r['duration_s']:g} s log ({r['imu_samples']} IMU samples, {r['ranges']} ranges): "
        f"filter {r['replay_s']:.3f} s, reading the CSV files {r['read_s']:.3f} s (goal: <= 1 s on one "
        f"core); RMSE {r['rmse_m']:.3f} m",
        "one predict + one range update per filter [us]:",
        f"  single  IMU-driven {s['imu_single']:.2f}, tandem {s['tandem_single']:.2f}: "
        f"{r['imu_over_tandem_single']:.2f}x (goal <= 2x)",
        f"  single  IMU-driven without range-bias states (15 error states) "
        f"{s['imu_single_no_range_bias']:.2f}: {r['imu_no_range_bias_over_tandem_single']:.2f}x",
        f"  batched IMU-driven {s['imu_batched']:.2f}, tandem {s['tandem_batched']:.2f}: "
        f"{r['imu_over_tandem_batched']:.2f}x (goal <= 2x)",
    ])  # fmt: skip
