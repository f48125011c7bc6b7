"""Tests for ``swarm bench estimator`` (swarm/bench/estimator.py, swarm/cli/bench.py).

No timing is asserted (the machines are shared and noisy). What is checked: the JSON record has the
DESIGN.md section 8 fields, positive and finite; FilterPy runs the same model as the compounded filter
(oracle: our compiled filter, to 1e-9), so the comparison is apples to apples; a missing FilterPy is
reported, not raised.
"""

from __future__ import annotations

import json
import math
import sys

import numpy as np
import pytest

from swarm.bench import estimator as bench
from swarm.cli.main import main
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
    ours = PoseEstimator.create(params, inp.p0_ms, inp.v0_ms, inp.q0_ms_body, inp.cov0)
    fp = bench.FilterPyMekf(params, inp.p0_ms, inp.v0_ms, inp.q0_ms_body, inp.cov0, 0.01)
    q_gyro_only = inp.q0_ms_body
    for k in range(steps):
        q_gyro_only = rot.quat_normalize(rot.quat_mul(q_gyro_only, rot.rotvec_exp(inp.w_body[k] * 0.01)))
        ours.predict(inp.w_body[k], inp.a_ms[k], 0.01)
        assert ours.update_range(inp.anchor_ms[k], inp.range_m[k])[0] == UpdateStatus.ACCEPTED
        fp.step(inp.w_body[k], inp.a_ms[k], inp.anchor_ms[k], inp.range_m[k])
    np.testing.assert_allclose(fp.ekf.x[:3, 0], ours.p_ms[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(fp.ekf.x[3:6, 0], ours.v_ms[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(fp.q_ms_body, ours.q_ms_body[0], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(fp.ekf.x[6:, 0], 0.0)
    # the ranges moved the attitude by far more than the tolerance: the reset is covered too
    assert np.linalg.norm(rot.attitude_error(q_gyro_only, fp.q_ms_body)) > 1e-6
    # P entries are ~1e-4 .. 1e-9: a relative tolerance, so that an error in a small block still shows
    np.testing.assert_allclose(fp.ekf.P, ours.P[0], rtol=1e-9, atol=1e-18)


def test_missing_filterpy_is_reported_not_raised(monkeypatch):
    monkeypatch.setitem(sys.modules, "filterpy", None)  # makes `import filterpy...` raise ImportError
    monkeypatch.setitem(sys.modules, "filterpy.kalman", None)
    r = bench.run(TINY)
    assert r["filterpy_us"] is None
    assert r["goals"]["tandem_fifth_of_filterpy"]["met"] is None
    assert "pip install .[bench]" in bench.format_report(r)
