"""``swarm bench replay`` replays a synthetic log and times the step against the tandem's (no timing
assertion: the numbers are checked for what they must be whatever the machine's load)."""

from __future__ import annotations

import json
import subprocess
import sys


def test_bench_replay_reports_the_replay_and_both_steps(tmp_path):
    out = tmp_path / "replay.json"
    args = [sys.executable, "-m", "swarm.cli.main", "bench", "replay", "--quick", "--json", str(out)]
    r = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rec = json.loads(out.read_text())
    assert rec["imu_samples"] > 19_000 and rec["ranges"] > 1400  # 20 s at 1 kHz and 80 Hz, less dropouts
    assert 0 < rec["replay_s"] and 0 < rec["read_s"] and rec["rmse_m"] < 0.2
    steps = rec["step_us"]
    assert set(steps) == {
        "imu_single",
        "tandem_single",
        "imu_batched",
        "tandem_batched",
        "imu_single_no_range_bias",
    }
    assert all(v > 0 for v in steps.values())
    assert rec["imu_over_tandem_single"] == steps["imu_single"] / steps["tandem_single"]
    assert "goal <= 2x" in r.stdout
