"""Tests for ``swarm bench estimator`` (swarm/bench/estimator.py, swarm/bench/filterpy_mekf.py,
swarm/cli/bench.py).

No timing is asserted (the machines are shared and noisy). What is checked: the JSON record has the
the bench's JSON fields, positive and finite; FilterPy runs the same model as the compounded filter
(oracle: our compiled filter, to 1e-9), so the comparison is apples to apples; the "as executed" FLOP
model counts what the kernels execute (oracle: the kernels' own Python source run on counting scalars);
a missing FilterPy is reported, not raised.
"""

from __future__ import annotations

import json
import math
import sys
import types

import numpy as np
import pytest

from swarm.bench import estimator as bench
from swarm.bench.filterpy_mekf import FilterPyMekf
from swarm.cli.main import main
from swarm.core import _ekf_nb as nb
from swarm.core import _rot_nb as rn
from swarm.core import rotations as rot
from swarm.core.estimator import EstimatorParams, PoseEstimator, Structure, UpdateStatus

TINY = bench.BenchConfig(steps=20, repeats=1, batch_sizes=(3,), batch_steps=5, batch_repeats=1)


def _positive_finite(x) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) and x > 0


def test_cli_quick_writes_section_8_fields(tmp_path):
    pytest.importorskip("filterpy")
    out = tmp_path / "b.json"
    assert main(["bench", "estimator", "--quick", "--json", str(out)]) == 0
    r = json.loads(out.read_text())
    for key in ("tandem_us", "compounded_us", "filterpy_us", "tandem_kernel_us", "compounded_kernel_us"):
        assert _positive_finite(r[key]), (key, r[key])
    assert r["paper_tandem_ms"] == 3.407
    assert r["paper_compounded_ms"] == 7.054
    for s in ("tandem", "compounded"):
        per_filter = r["batched_us_per_filter"][s]
        assert set(per_filter) == {str(n) for n in bench.QUICK.batch_sizes}
        assert all(_positive_finite(v) for v in per_filter.values()), per_filter
        assert _positive_finite(r["flops"][s]["dense"]["total"])
        assert _positive_finite(r["flops"][s]["kernel"]["total"])
        assert {"step", "predict", "update_scalar"} <= set(r["kernel_pieces_ns"][s])
    assert set(r["kernel_pieces_ns"]["shared"]) == set(bench.PIECES[2:])
    assert all(_positive_finite(v) for v in r["ratios"].values()), r["ratios"]
    assert r["machine"]["numba"]


def test_every_range_of_the_replayed_run_passes_the_gate():
    r = bench.run(TINY)
    assert {k: v["accepted_fraction"] for k, v in r["stats_us"].items()} == dict.fromkeys(r["stats_us"], 1.0)
    assert {k: v["accepted_fraction"] for k, v in r["batched_stats_us_per_filter"].items()} == dict.fromkeys(
        r["batched_stats_us_per_filter"], 1.0
    )


@pytest.mark.parametrize("steps", [1, 50])
def test_filterpy_model_equals_the_compounded_filter(steps):
    """Same initial state and inputs: FilterPy's EKF and our compounded kernel agree to 1e-9."""
    pytest.importorskip("filterpy")
    params = EstimatorParams(structure=Structure.COMPOUNDED)
    inp = bench.make_inputs(steps, 0.01, params, seed=3)
    ours = PoseEstimator.create(params, inp.p0_nav, inp.v0_nav, inp.q0_nav_body, inp.cov0)
    fp = FilterPyMekf(params, inp.p0_nav, inp.v0_nav, inp.q0_nav_body, inp.cov0, 0.01)
    q_gyro_only = inp.q0_nav_body
    for k in range(steps):
        q_gyro_only = rot.quat_normalize(rot.quat_mul(q_gyro_only, rot.rotvec_exp(inp.w_body[k] * 0.01)))
        ours.predict(inp.w_body[k], inp.a_nav[k], 0.01)
        assert ours.update_range(inp.anchor_nav[k], inp.range_m[k])[0] == UpdateStatus.ACCEPTED
        fp.step(inp.w_body[k], inp.a_nav[k], inp.anchor_nav[k], inp.range_m[k])
    np.testing.assert_allclose(fp.ekf.x[:3, 0], ours.p_nav[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(fp.ekf.x[3:6, 0], ours.v_nav[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(fp.q_nav_body, ours.q_nav_body[0], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(fp.ekf.x[6:, 0], 0.0)
    # the ranges moved the attitude by far more than the tolerance: the reset is covered too
    assert np.linalg.norm(rot.attitude_error(q_gyro_only, fp.q_nav_body)) > 1e-6
    # P entries are ~1e-4 .. 1e-9: a relative tolerance, so that an error in a small block still shows
    np.testing.assert_allclose(fp.ekf.P, ours.P[0], rtol=1e-9, atol=1e-18)


# ---- the FLOP model against the kernels' source ------------------------------------------------------


class _Counted:
    """A float that counts every +, -, *, / it takes part in, and x**k as k - 1 multiplies: the FLOP
    rules of ``flops_per_step``. Negation and comparisons are free."""

    flops = 0
    __slots__ = ("v",)
    __hash__ = None

    def __init__(self, v) -> None:
        self.v = float(v)

    def _op(self, other, f):
        _Counted.flops += 1
        return _Counted(f(self.v, float(other)))

    def __add__(self, o):
        return self._op(o, lambda a, b: a + b)

    def __radd__(self, o):
        return self._op(o, lambda a, b: b + a)

    def __sub__(self, o):
        return self._op(o, lambda a, b: a - b)

    def __rsub__(self, o):
        return self._op(o, lambda a, b: b - a)

    def __mul__(self, o):
        return self._op(o, lambda a, b: a * b)

    def __rmul__(self, o):
        return self._op(o, lambda a, b: b * a)

    def __truediv__(self, o):
        return self._op(o, lambda a, b: a / b)

    def __rtruediv__(self, o):
        return self._op(o, lambda a, b: b / a)

    def __pow__(self, k):
        _Counted.flops += int(k) - 1
        return _Counted(self.v**k)

    def __neg__(self):
        return _Counted(-self.v)

    def __float__(self) -> float:
        return self.v

    def __lt__(self, o):
        return self.v < float(o)

    def __le__(self, o):
        return self.v <= float(o)

    def __gt__(self, o):
        return self.v > float(o)

    def __ge__(self, o):
        return self.v >= float(o)

    def __eq__(self, o):
        return self.v == float(o)

    def __ne__(self, o):
        return self.v != float(o)


def _counted(a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    out = np.empty(a.shape, dtype=object)
    for i in np.ndindex(a.shape):
        out[i] = _Counted(a[i])
    return out


def _counting(f):
    def g(x):
        _Counted.flops += 1
        return _Counted(f(float(x)))

    return g


def _count_in_python(monkeypatch) -> None:
    """Route the kernels' Python source (``py_func``) through counting scalars: numba helpers replaced by
    their ``py_func``, and the ``np`` / ``math`` they call by shims that count sqrt, sin, cos and
    allocate object arrays of counted zeros (what numba allocates is float64 work too). Call it after
    any setup that runs compiled code (``rotations`` has compiled fast paths): a function numba compiles
    while this is in place fails to type."""
    np_shim = types.SimpleNamespace(
        inf=np.inf,
        isfinite=lambda v: math.isfinite(float(v)),
        sqrt=_counting(math.sqrt),
        empty=lambda shape: _counted(np.zeros(shape)),
        zeros=lambda shape: _counted(np.zeros(shape)),
        eye=lambda n: _counted(np.eye(n)),
    )
    math_shim = types.SimpleNamespace(
        sqrt=_counting(math.sqrt), sin=_counting(math.sin), cos=_counting(math.cos), atan2=math.atan2
    )
    for name in ("qexp3", "qexp", "qmat9", "qmul", "qnormalize", "skew3"):
        monkeypatch.setattr(nb, name, getattr(rn, name).py_func, raising=False)
    for name in (
        "_all_finite",
        "_finite3",
        "_range_row",
        "_update_scalar",
        "_gate_scalar",
        "_reset_attitude",
        "_reset_attitude3",
    ):
        monkeypatch.setattr(nb, name, getattr(nb, name).py_func)
    monkeypatch.setattr(rn, "qexp3", rn.qexp3.py_func)
    for module in (nb, rn):
        monkeypatch.setattr(module, "np", np_shim)
    monkeypatch.setattr(rn, "math", math_shim)


@pytest.mark.parametrize("structure", ["tandem", "compounded"])
def test_executed_flop_model_counts_what_the_kernels_execute(monkeypatch, structure):
    """``flops_per_step(dense=False)`` equals the operations of ``predict_one`` and of an accepted
    ``update_range_one`` (with the compounded reset) run as Python on counting scalars. The gyro
    increment and the correction are below 1e-3 rad, the ``qexp3`` branch the model assumes."""
    params = EstimatorParams(structure=Structure(structure))
    prm = params.param_vector()
    inp = bench.make_inputs(1, 0.01, params, seed=0)
    x0 = np.concatenate([inp.p0_nav, inp.v0_nav, inp.q0_nav_body])
    w_body, dt = np.array([0.02, -0.05, 0.04]), 0.01  # |w| dt = 6.7e-4 rad
    # compiled, before patching: the predicted range, so that the counted update sees a 1 mm innovation
    x1, stat = x0.copy(), (np.zeros((3, nb.N_TYPES), dtype=np.int64), np.zeros(nb.N_STF))
    nb.predict_one(x1, inp.cov0.copy(), *stat, w_body, inp.a_nav[0], dt, prm)
    h, _ = nb.range_model(x1, inp.anchor_nav[0], np.asarray(params.lever_arm_body_m))
    X, P = _counted(x0), _counted(inp.cov0)
    counts, book = np.zeros((3, nb.N_TYPES), dtype=np.int64), _counted(np.zeros(nb.N_STF))
    model = bench.flops_per_step(structure)
    _count_in_python(monkeypatch)

    _Counted.flops = 0
    status = nb.predict_one.py_func(
        X, P, counts, book, _counted(w_body), _counted(inp.a_nav[0]), _Counted(dt), prm
    )
    assert status == nb.ST_ACCEPTED
    assert _Counted.flops == model["predict"]
    _Counted.flops = 0
    z, sigma = _Counted(h + 0.001), _Counted(params.sigma_range_m)
    status = nb.update_range_one.py_func(X, P, counts, book, prm, inp.anchor_nav[0], z, sigma, 20.0)
    assert status == nb.ST_ACCEPTED
    assert _Counted.flops == model["update"] + model["correction"]


def test_dense_flop_model_keeps_the_textbook_counts():
    """The dense model is the textbook algorithm: ``F P F^T`` for n = 9 alone is 2 * 81 * 17 FLOPs, and
    the compounded step (9-state sandwich, Joseph and reset sandwich) stays above 3 of them."""
    compounded, tandem = bench.flops_per_step("compounded", dense=True), bench.flops_per_step("tandem", True)
    assert bench._sandwich_dense(9) == 2 * 81 * 17
    assert compounded["total"] > 3 * bench._sandwich_dense(9)
    assert tandem["total"] < compounded["total"] / 3
    for r in (compounded, tandem):
        assert r["total"] == r["predict"] + r["update"] + r["correction"] == sum(r["items"].values())


def test_missing_filterpy_is_reported_not_raised(monkeypatch):
    monkeypatch.setitem(sys.modules, "filterpy", None)  # makes `import filterpy...` raise ImportError
    monkeypatch.setitem(sys.modules, "filterpy.kalman", None)
    r = bench.run(TINY)
    assert r["filterpy_us"] is None
    assert r["goals"]["tandem_fifth_of_filterpy"]["met"] is None
    assert "pip install .[bench]" in bench.format_report(r)
