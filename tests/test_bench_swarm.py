"""``swarm bench swarm`` runs a real launched swarm and writes the fields issue 13 names (no timing
assertion: the numbers are checked for what they must be whatever the machine's load)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


def test_bench_swarm_measures_a_launched_swarm(tmp_path):
    out = tmp_path / "swarm.json"
    args = [sys.executable, "-m", "swarm.cli.main", "bench", "swarm", "--vehicles", "2", "--clock",
            "lockstep", "--span", "3", "--vehicles-per-process", "2", "--json", str(out)]  # fmt: skip
    r = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rec = json.loads(out.read_text())
    (case,) = rec["cases"]
    keys = {"vehicles", "per_process", "clock", "cpu_us_per_vehicle_tick", "late_tick_share",
            "realtime_factor", "latency_p99_us"}  # fmt: skip
    assert keys <= set(case)
    assert (case["vehicles"], case["per_process"], case["clock"]) == (2, 2, "lockstep")  # one agent host
    assert case["ticks"] == 300  # the 3 s span, whole
    assert case["cpu_us_per_vehicle_tick"] > 0 and case["world_cpu_us_per_tick"] > 0
    assert case["late_tick_share"] is None  # lockstep: no tick is late by construction
    assert case["realtime_factor"] > 0
    assert case["samples"] > 200  # both vehicles' estimates matched to their imu over most of 300 ticks
    assert 0 < case["latency_p50_us"] <= case["latency_p99_us"]
    assert "CPU us/vehicle/tick" in r.stdout


@pytest.mark.parametrize(
    ("flags", "expect"),
    [(["--vehicles", "3"], "--vehicles must be even integers in 2..128"),
     (["--vehicles", "two"], "--vehicles must be even integers separated by commas, got 'two'"),
     (["--clock", "scaled:2"], "--clock must be realtime, lockstep or both"),
     (["--span", "0"], "--span must be a number of seconds in 1..3600, got 0.0"),
     (["--vehicles-per-process", "0"], "--vehicles-per-process must be integers in 1..64")],
)  # fmt: skip
def test_bad_bench_swarm_flags_give_one_clear_error(flags, expect):
    r = subprocess.run([sys.executable, "-m", "swarm.cli.main", "bench", "swarm", *flags],
                       capture_output=True, text=True, timeout=60)  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert expect in r.stderr and "Traceback" not in r.stderr
