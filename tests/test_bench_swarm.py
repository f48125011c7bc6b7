"""``swarm bench swarm`` runs a real launched swarm and writes the fields issue 13 names (no timing
assertion: the numbers are checked for what they must be whatever the machine's load)."""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from swarm.cpu_latency import DEVICE
from swarm.scenario import load_scenario
from tests.inprocess import swarm_exit_status


def test_bench_swarm_measures_a_launched_swarm(tmp_path):
    out = tmp_path / "swarm.json"
    # agent hosts: the world sends the imu as one world/imu batch, whose stamp each vehicle's estimate carries
    args = [sys.executable, "-m", "swarm.cli.main", "bench", "swarm", "--vehicles", "4", "--clock",
            "lockstep", "--span", "3", "--vehicles-per-process", "2", "--json", str(out),
            "--cpu-latency", "0"]  # fmt: skip
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
    # every process stamped what it published (the bench's Zenoh configuration reached each of them), and
    # every estimate but the two initial ones (made before any imu) carried its imu's stamp
    assert case["unstamped"] == 0 and case["without_imu_stamp"] == 2
    # chaser0's estimates (and the fifth of target0's it sends), each with its imu's stamp (the host's imu
    # batch's, which it attached), over 300 ticks: 300 + 60, less the last tick or two whose estimate went
    # out as the run ended
    assert 350 <= case["samples"] <= 360
    assert 0 < case["latency_p50_us"] <= case["latency_p99_us"]
    # split: the chaser's camera ticks (the scenario's camera period: 60 in the span at 20 Hz) apart
    sc = load_scenario("docking")
    frames = case["ticks"] // sc.every(sc.camera.rate_hz)
    assert frames - 2 <= case["camera_samples"] <= frames
    for part in ("camera", "other"):
        assert 0 < case[f"latency_{part}_p50_us"] <= case[f"latency_{part}_p99_us"]
    # an estimate arrives after it was published, on one machine's clock: delivered >= published, tick by
    # tick, so at every percentile (a probe matching the wrong stamps, or two clocks, would break it)
    assert case["latency_delivered_p50_us"] >= case["latency_p50_us"]
    assert case["latency_delivered_p99_us"] >= case["latency_p99_us"]
    assert "CPU us/vehicle/tick" in r.stdout and "(camera ticks; others)  delivered" in r.stdout
    # the CPU latency request, held by the bench around the case where the machine lets it (root)
    held = os.access(DEVICE, os.W_OK)
    assert (case["cpu_latency_us"], case["cpu_latency_held"]) == (0, held)
    assert case["cpu_latency_effective_us"] == (0 if held else None)


class _Sample:
    """A Zenoh sample as the probe reads it: key, payload, the publisher's timestamp (or none) and the
    attachment (``imu_ns``: an agent's, with its imu's publication stamp; bytes: anybody's)."""

    def __init__(
        self, key: str, tick: int, published_ns: int | None, imu_ns: int | bytes | None = None
    ) -> None:
        import msgpack

        from swarm.transport.session import imu_stamp_attachment

        self.key_expr, self.payload = key, msgpack.packb({"tick": tick})
        self.timestamp = None if published_ns is None else _Stamp(published_ns)
        self.attachment = imu_stamp_attachment(imu_ns) if isinstance(imu_ns, int) else imu_ns


class _Stamp:
    def __init__(self, ns: int) -> None:
        self.ns = ns

    def get_time_as_ntp64(self):
        return self

    def as_nanos(self) -> int:
        return self.ns


def test_a_free_running_pair_that_wakes_at_its_control_rate_commands_and_batches_its_estimates(tmp_path):
    """``--agent-wake control`` (``agent.wake_at_control``) on a launched free-running pair, a process each:
    the agents command (not every tick late) and publish every estimate, a control period's at a time, so
    the sensor-to-estimate latency's median is tens of milliseconds (half a 100 ms period on average), where
    an agent woken by each imu publishes in about one (``BENCHMARKS.md``)."""
    out = tmp_path / "ctl.json"
    args = [sys.executable, "-m", "swarm.cli.main", "bench", "swarm", "--vehicles", "2", "--clock",
            "realtime", "--span", "3", "--agent-wake", "control", "--json", str(out)]  # fmt: skip
    r = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    (case,) = json.loads(out.read_text())["cases"]
    assert case["agent_wake"] == "control" and case["ticks"] == 300
    assert case["commanded_vehicle_ticks"] > 0 and case["late_tick_share"] < 0.5, case
    assert case["samples"] >= 300, case  # chaser's estimates (and a fifth of the target's), every one
    assert case["latency_p50_us"] > 5000, case  # batched per control period (an imu wake: ~1 ms)


def test_the_probe_measures_from_the_publishers_stamps_the_imus_attached_to_each_estimate(monkeypatch):
    """The latency is the estimate's publication minus its imu's (the stamp the agent attached), to the
    nanosecond; delivered is the estimate's arrival here minus the imu's publication; an estimate without
    either stamp, or with an attachment of anybody else's making, is counted, not measured."""
    from swarm.bench import swarm as bench

    probe = bench.LatencyProbe()
    now = itertools.chain([5_000_900_000, 5_001_900_000, 5_002_900_000], itertools.repeat(0))
    monkeypatch.setattr(bench.time, "time_ns", lambda: next(now))
    probe.on_estimate(
        _Sample("ns/agent/chaser/estimate", 7, 5_000_412_345, 5_000_000_000)
    )  # arrives at .9 ms
    probe.on_estimate(_Sample("ns/agent/chaser/estimate", 8, 5_001_600_000, 5_001_000_000))
    probe.on_estimate(_Sample("ns/agent/target/estimate", 9, 5_002_500_000, 5_002_000_000))
    ok = pytest.approx
    assert probe.latency == [("chaser", 7, ok(412_345e-9, abs=1e-12)), ("chaser", 8, ok(600e-6)),
                             ("target", 9, ok(500e-6))]  # fmt: skip
    assert probe.delivered == [
        ("chaser", 7, ok(900e-6)),
        ("chaser", 8, ok(900e-6)),
        ("target", 9, ok(900e-6)),
    ]
    assert probe.unstamped == probe.without_imu == 0
    probe.on_estimate(_Sample("ns/agent/chaser/estimate", 10, None, 5_003_000_000))  # the agent's unstamped
    probe.on_estimate(_Sample("ns/agent/chaser/estimate", 11, 5_004_000_000))  # its imu's: no attachment
    probe.on_estimate(_Sample("ns/agent/chaser/estimate", 12, 5_005_000_000, b"\x81\xa1x\x01"))  # {"x": 1}
    assert len(probe.latency) == 3 and (probe.unstamped, probe.without_imu) == (1, 2)
    # a payload of someone else's making is not measured, and does not raise into Zenoh's thread
    bad = type("S", (), {"key_expr": "ns/agent/chaser/estimate", "payload": b"\xc1", "timestamp": None,
                         "attachment": None})()  # fmt: skip
    probe.on_estimate(bad)
    assert len(probe.latency) == 3 and (probe.unstamped, probe.without_imu) == (1, 2)


def test_the_latency_is_split_into_the_camera_ticks_and_the_others():
    """The probe's samples: the camera vehicle's at the camera ticks (a multiple of the camera's period)
    apart, a target's on those ticks not; each part's percentiles those of its own samples (numpy's linear
    interpolation); none of a kind gives None."""
    from swarm.bench.swarm import latency_split

    samples = [("c", k, (3e-3 if k % 10 == 0 else 1e-3) + 1e-6 * k) for k in range(1, 101)]
    samples += [("t", k, 2e-3) for k in range(10, 101, 10)]  # the target's, on the same ticks: no camera
    got = latency_split(samples, 10, {"c"})
    camera = [3e3 + k for k in range(10, 101, 10)]
    other = [1e3 + k for k in range(1, 101) if k % 10] + [2e3] * 10
    assert (got["samples"], got["camera_samples"]) == (110, 10)
    assert got["latency_camera_p50_us"] == pytest.approx(sorted(camera)[4] / 2 + sorted(camera)[5] / 2)
    assert got["latency_other_p99_us"] == pytest.approx(float(np.percentile(other, 99)))
    assert got["latency_p99_us"] > got["latency_other_p99_us"] > got["latency_other_p50_us"]
    assert latency_split([("c", 5, 1e-3)], 10, {"c"})["latency_camera_p50_us"] is None


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


def test_each_case_is_run_alternately_with_each_cpu_latency_and_the_report_says_which(monkeypatch):
    from swarm.bench import swarm as bench
    from swarm.cpu_latency import CpuLatencyHold, describe_idle

    held_during: list = []

    def fake_hold(us):
        import contextlib

        @contextlib.contextmanager
        def cm():
            state = CpuLatencyHold(us, held=us == 0, effective_us=0 if us == 0 else None)
            held_during.append(us)
            yield state
            held_during.append(("end", us))

        return cm()

    def fake_case(v, c, span, n, stagger, tdma, t, w):
        assert held_during and held_during[-1] in (None, 0, 5)  # inside the request's block
        assert w is None  # (no --agent-wake: the launcher's plan)
        return {"vehicles": v, "per_process": n, "clock": c, "topology": "mesh",
                "cpu_us_per_vehicle_tick": 1.0, "world_cpu_us_per_tick": 1.0, "late_tick_share": 0.0,
                "realtime_factor": 1.0, "latency_p50_us": 1.0, "latency_p99_us": 2.0}  # fmt: skip

    monkeypatch.setattr("swarm.cpu_latency.hold", fake_hold)
    monkeypatch.setattr(bench, "_case", fake_case)
    lat = bench.parse_cpu_latencies("off,0,5")
    assert lat == (None, 0, 5)
    rec = bench.run({"vehicles": (2,), "clocks": ("realtime",), "span_s": 1.0, "per_process": (1,),
                     "cpu_latencies": lat, "repeat": 2})  # fmt: skip
    # round by round: off, 0, 5, off, 0, 5, each case inside its own request
    assert [u for u in held_during if not isinstance(u, tuple)] == [None, 0, 5, None, 0, 5]
    assert [(c["cpu_latency_us"], c["cpu_latency_held"]) for c in rec["cases"]] == [(None, False), (0, True),
                                                                                      (5, False)]  # fmt: skip
    lines = bench.format_report(rec).splitlines()
    assert lines[-1] == describe_idle(rec["cpu_idle"])  # the machine's idle states, read once for the record
    head = next(i for i, line in enumerate(lines) if line.startswith("vehicles"))
    # 5 us not granted: marked
    assert [r.split()[4] for r in lines[head + 1 : head + 4]] == ["off", "0", "5!"]


@pytest.mark.parametrize(
    ("flags", "expect"),
    [(["--vehicles", "3"], "--vehicles must be even integers in 2..128"),
     (["--vehicles", "two"], "--vehicles must be even integers separated by commas, got 'two'"),
     (["--clock", "scaled:2"], "--clock must be realtime, lockstep or both"),
     (["--span", "0"], "--span must be a number of seconds in 1..3600, got 0.0"),
     (["--vehicles-per-process", "0"], "--vehicles-per-process must be integers in 1..64"),
     (["--repeat", "0"], "--repeat must be an integer in 1..20, got 0"),
     (["--cpu-latency", "0,0"], "--cpu-latency must be off or microseconds in 0..2000000000, or several"),
     (["--cpu-latency", "fast"], "got 'fast'"),
     (["--agent-wake", "imu,sometimes"], "--agent-wake must be imu, control or both (comma-separated)")],
)  # fmt: skip
def test_bad_bench_swarm_flags_give_one_clear_error(flags, expect, capsys):
    # in this process (swarm.cli.main.main, what `python -m swarm.cli.main` runs): a started Python costs
    # ~1.6 s of CPU, nine of them ~15 s of the suite
    rc = swarm_exit_status(["bench", "swarm", *flags])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert expect in err and "Traceback" not in err


def test_the_control_rate_wake_is_a_case_of_its_own_for_free_running_processes_of_one_only(monkeypatch):
    """``--agent-wake imu,control``: each free-running case with a process per vehicle runs in both, round by
    round; lockstep and agent hosts, which ignore ``agent.wake_at_control``, run once."""
    from swarm.bench import swarm as bench

    ran: list = []

    def fake_case(v, c, span, n, stagger, tdma, t, w):
        ran.append((c, n, w))
        return {"vehicles": v, "per_process": n, "clock": c, "topology": "star", "agent_wake": w,
                "cpu_us_per_vehicle_tick": 1.0, "world_cpu_us_per_tick": 1.0, "late_tick_share": 0.0,
                "realtime_factor": 1.0, "latency_p50_us": 1.0, "latency_p99_us": 2.0}  # fmt: skip

    monkeypatch.setattr(bench, "_case", fake_case)
    wakes = bench.parse_agent_wakes("imu,control")
    rec = bench.run({"vehicles": (4,), "clocks": ("realtime", "lockstep"), "span_s": 1.0,
                     "per_process": (1, 2), "agent_wakes": wakes})  # fmt: skip
    assert ran == [("realtime", 1, "imu"), ("realtime", 1, "control"), ("realtime", 2, "imu"),
                   ("lockstep", 1, "imu"), ("lockstep", 2, "imu")]  # fmt: skip
    rows = bench.format_report(rec).splitlines()[2:]
    assert [r.split()[2:4] for r in rows][:2] == [["realtime", "star"], ["realtime", "ctl"]]


def test_repeated_runs_of_a_case_are_summarised_by_their_median_and_spread():
    """``--repeat N``: a case's figures are the medians of its runs (those that have the figure), its late
    ticks, late commands, real-time factor and latency p99 with their [min, max]; the runs are kept; the
    report gives the count and the late ticks' spread. One run stays as it was."""
    from swarm.bench.swarm import format_report, summarise

    def one(late, rtf, p99, cpu):
        return {"vehicles": 128, "per_process": 64, "clock": "realtime", "staggered": True,
                "cpu_us_per_vehicle_tick": cpu, "world_cpu_us_per_tick": 2000.0, "late_tick_share": late,
                "late_command_share": None if late is None else 10 * late, "commanded_vehicle_ticks": 64000,
                "realtime_factor": rtf, "latency_p50_us": 2500.0, "latency_p99_us": p99, "samples": 1200,
                "ticks": 1000}  # fmt: skip

    runs = [one(0.033, 1.0, 9000.0, 60.0), one(0.005, 0.99, 7000.0, 50.0), one(0.013, 1.0, None, 55.0)]
    c = summarise(runs)
    assert c["late_tick_share"] == 0.013 and c["late_tick_share_range"] == [0.005, 0.033]
    assert c["late_command_share"] == 0.13 and c["late_command_share_range"] == [0.05, 0.33]
    assert c["realtime_factor"] == 1.0 and c["realtime_factor_range"] == [0.99, 1.0]
    assert c["latency_p99_us"] == 8000.0 and c["latency_p99_us_range"] == [7000.0, 9000.0]  # the two with one
    assert c["cpu_us_per_vehicle_tick"] == 55.0 and "cpu_us_per_vehicle_tick_range" not in c
    assert (c["vehicles"], c["ticks"], c["staggered"], c["repeat"], c["runs"]) == (128, 1000, True, 3, runs)
    report = format_report({"span_s": 10, "cores": 2, "load_1min": 1.0, "cases": [c]})
    assert "1.3 % / 13.0 %" in report and "3 runs, late ticks [0.5-3.3 %]" in report
    assert "TDMA" not in report and "one TDMA UWB channel" in format_report(
        {"span_s": 10, "cores": 2, "load_1min": 1.0, "cases": [{**c, "tdma": True}]}
    )
    assert summarise(runs[:1]) is runs[0]
    lock = summarise([one(None, 5.0, 1.0, 1.0), one(None, 6.0, 1.0, 1.0)])
    assert lock["late_tick_share"] is None and "late_tick_share_range" not in lock
    assert "2 runs, real-time [5.00-6.00x]" in format_report(
        {"span_s": 10, "cores": 2, "load_1min": 1.0, "cases": [{**lock, "clock": "lockstep"}]}
    )


def test_a_launch_that_fails_is_reported_with_what_it_said(tmp_path, monkeypatch):
    """A case whose launcher ends without a result (here before its router listens) raises with the
    launcher's exit status and the last lines of its stderr (its children's too), not only "failed"."""
    from swarm.bench import swarm as bench

    fake = tmp_path / "launch.py"
    said = ["warming up", "swarm launch: error: scenario: the reason, named"]
    lines = "".join(f"print({s!r}, file=sys.stderr)\n" for s in said)
    fake.write_text(f"import sys\n{lines}sys.exit(2)\n")
    monkeypatch.setattr(bench, "LAUNCH", [sys.executable, str(fake)])
    with pytest.raises(RuntimeError) as err:
        bench._case(4, "realtime", 1.0, 2)
    msg = str(err.value)
    assert "swarm launch --agents 2 --clock realtime --topology mesh failed (2)" in msg
    assert "warming up" in msg and "scenario: the reason, named" in msg


def test_a_hung_launch_is_bounded_and_reported_with_the_stacks_it_wrote(tmp_path, monkeypatch):
    """A case's launch gets ``--timeout`` (its start plus ten times its span), and when it fails after its
    launcher had every process write its stacks (a stall or that timeout), the error keeps the dump from its
    first line, not only the last lines (which would hold the end of the last process's stacks)."""
    from swarm.bench import swarm as bench

    fake = tmp_path / "launch.py"
    fake.write_text(
        "import sys\n"
        "print('WARNING swarm.launch: the world clock has stood at tick 40 for 30.0 s in a running run: '"
        "      'the stacks of the launcher (pid 7), then of world (pid 8) follow', file=sys.stderr)\n"
        "print('  File \"/x/swarm/world/process.py\", line 480 in _take_commands', file=sys.stderr)\n"
        "for i in range(50):\n"
        "    print(f'  frame {i}', file=sys.stderr)\n"
        "print('called with', ' '.join(sys.argv[1:]), file=sys.stderr)\n"
        "sys.exit(1)\n"
    )
    monkeypatch.setattr(bench, "LAUNCH", [sys.executable, str(fake)])
    with pytest.raises(RuntimeError) as err:
        bench._case(4, "realtime", 5.0, 2, stagger=True, tdma=True)
    msg = str(err.value)
    assert f"--timeout {bench.LAUNCH_START_S + bench.LAUNCH_SLOWEST * 5.0:g}" in msg  # the command it got
    assert "--set swarm.stagger_control=true --set uwb.tdma=true" in msg  # --stagger, --tdma
    assert "the stacks of the launcher (pid 7), then of world (pid 8) follow" in msg
    assert "line 480 in _take_commands" in msg and "frame 49" in msg
