"""``swarm bench tdoa``: TWR-TDMA against TDoA3 per tag as the swarm grows (:mod:`swarm.bench.tdoa`)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from swarm.bench import tdoa as bench
from swarm.cli.main import main


def test_thinning_keeps_the_round_robin_and_the_rate():
    t = np.arange(0, 20.0, 1 / 80.0)
    rows = np.column_stack([t, np.arange(len(t)) % 8, np.ones(len(t))])
    for rate in (50.0, 7.44, 1.86):
        kept = bench.thin_ranges(rows, rate, 8)
        assert len(kept) == pytest.approx(20.0 * rate, abs=2)
        assert np.all(np.diff(kept[:, 0]) > 0)
        # every anchor gets its share: a uniform round robin, not one anchor (every 8th row would be)
        counts = np.bincount(kept[:, 1].astype(int), minlength=8)
        assert counts.max() - counts.min() <= 1


def test_the_bench_holds_tdoa_and_divides_twr(tmp_path):
    out = tmp_path / "tdoa.json"
    cfg = {"vehicles": (2, 32), "duration_s": 15.0, "seed": 2, "sim_s": 2.0}
    r = bench.run(cfg)
    a, b = r["rows"]
    assert a["twr_hz"] == 50.0 and b["twr_hz"] == pytest.approx(1 / (32 * 0.0042))
    assert b["twr_log_hz"] == pytest.approx(b["twr_hz"], rel=0.05)
    # TDoA3 per tag: the model's, whatever N (2 s of ~300 rows/s: a few per cent)
    for row in (a, b):
        assert row["tdoa3_sim_hz"] == pytest.approx(row["tdoa3_model_hz"], rel=0.06)
    assert a["tdoa3_rmse_m"] == b["tdoa3_rmse_m"] is not None
    assert "TWR-TDMA" in bench.format_report(r)
    assert main(["bench", "tdoa", "--quick", "--json", str(out)]) == 0
    assert [row["vehicles"] for row in json.loads(out.read_text())["rows"]] == [2, 8]
