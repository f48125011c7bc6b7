"""``swarm bench record`` launches a swarm with and without --record and reports the CPU difference (no
timing assertion: the numbers are checked for what they must be whatever the machine's load)."""

from __future__ import annotations

import json
import subprocess
import sys


def test_bench_record_measures_both_launches(tmp_path):
    out = tmp_path / "record.json"
    args = [sys.executable, "-m", "swarm.cli.main", "bench", "record", "--quick", "--json", str(out)]
    r = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rec = json.loads(out.read_text())
    for case in ("without", "with"):
        # 0: docked within the span, 1: the span ended first (the quick preset's 4 s); a crash is neither
        assert (
            rec[case]["status"] in (0, 1) and rec[case]["cpu_s"] > 1.0
        )  # the swarm's CPU, children included
    assert rec["with"]["file_mb"] > 0.1 and rec["without"]["file_mb"] is None
    assert rec["overhead"] == (rec["with"]["cpu_s"] - rec["without"]["cpu_s"]) / rec["without"]["cpu_s"]
    # the reported pair is the median of the pairs launched (one in the quick preset)
    assert len(rec["pairs_runs"]) == rec["repeats"] == 1
    assert rec["pairs_runs"][0]["overhead"] == rec["overhead"]
    assert "overhead" in r.stdout
