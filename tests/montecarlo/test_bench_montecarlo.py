"""``swarm bench montecarlo`` runs real campaigns and reports their scaling (tiny cases here)."""

from __future__ import annotations

import json
import math

import swarm.bench.montecarlo as bench
from swarm.cli.main import main


def test_bench_montecarlo_measures_workers_and_runs_scaling(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(bench, "QUICK_CASES", ((1, 1), (2, 1), (2, 2)))
    js = tmp_path / "b.json"
    assert main(["bench", "montecarlo", "--quick", "--json", str(js)]) == 0
    rec = json.loads(js.read_text())
    assert [(c["workers"], c["runs"], c["tasks"]) for c in rec["cases"]] == [(1, 1, 2), (2, 1, 2), (2, 2, 4)]
    # timings are the machine's (shared, noisy): check they were measured, not what they are
    for c in rec["cases"]:
        assert c["docked"] == c["tasks"] and c["wall_s"] > 0 and c["efficiency"] > 0
    assert rec["speedup_2_vs_1_workers"] > 0 and math.isfinite(rec["predicted_500x2_wall_s"])
    assert rec["measured_500x2_wall_s"] is None and rec["target_wall_s"] == 30.0
    out = capsys.readouterr().out
    assert "2 workers vs 1" in out and "goal: 500 runs x 2 policies" in out
