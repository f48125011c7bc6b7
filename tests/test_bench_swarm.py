"""``swarm bench swarm`` runs a real launched swarm and writes the fields issue 13 names (no timing
assertion: the numbers are checked for what they must be whatever the machine's load)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


def test_bench_swarm_measures_a_launched_swarm(tmp_path):
    out = tmp_path / "swarm.json"
    # agent hosts: the world sends the imu as one world/imu batch, which the latency probe must read
    args = [sys.executable, "-m", "swarm.cli.main", "bench", "swarm", "--vehicles", "4", "--clock",
            "lockstep", "--span", "3", "--vehicles-per-process", "2", "--json", str(out)]  # fmt: skip
    r = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rec = json.loads(out.read_text())
    (case,) = rec["cases"]
    keys = {"vehicles", "per_process", "clock", "cpu_us_per_vehicle_tick", "late_tick_share",
            "realtime_factor", "latency_p99_us"}  # fmt: skip
    assert keys <= set(case)
    assert (case["vehicles"], case["per_process"], case["clock"]) == (4, 2, "lockstep")  # two agent hosts
    assert case["ticks"] == 300  # the 3 s span, whole
    assert case["cpu_us_per_vehicle_tick"] > 0 and case["world_cpu_us_per_tick"] > 0
    assert case["late_tick_share"] is None  # lockstep: no tick is late by construction
    assert case["realtime_factor"] > 0
    # chaser0's estimates (and the fifth of target0's it sends) matched to their imu, over 300 ticks
    assert case["samples"] > 200
    assert 0 < case["latency_p50_us"] <= case["latency_p99_us"]
    assert "CPU us/vehicle/tick" in r.stdout


def test_late_share_counts_a_swarm_that_never_commanded_as_all_late():
    from swarm.bench.swarm import format_report, late_share

    assert late_share("lockstep", None) == (None, None)
    assert late_share("realtime", [3, 400]) == (3 / 400, 400)
    assert late_share("realtime", [0, 0]) == (1.0, 0)  # no vehicle commanded in the span
    assert late_share("scaled:2", None) == (None, None)  # a world that did not say
    case = {"vehicles": 128, "per_process": 16, "clock": "realtime", "cpu_us_per_vehicle_tick": 80.0,
            "world_cpu_us_per_tick": 6000.0, "late_tick_share": 1.0, "commanded_vehicle_ticks": 0,
            "realtime_factor": 0.99, "latency_p50_us": 1.0, "latency_p99_us": 2.0}  # fmt: skip
    report = format_report({"span_s": 10, "cores": 2, "load_1min": 1.0, "cases": [case]})
    assert "no command" in report and "100.0 %" not in report
    # the late ticks and the stricter late commands (of the control ticks' commands), both shown
    ok = {**case, "late_tick_share": 0.012, "late_command_share": 0.105, "commanded_vehicle_ticks": 64000}
    report = format_report({"span_s": 10, "cores": 2, "load_1min": 1.0, "cases": [ok]})
    assert "1.2 % / 10.5 %" in report


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
