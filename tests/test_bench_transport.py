"""``swarm bench transport``'s floor: a ping-pong through a router between two client processes, the pong
publishing from Zenoh's callback thread or from a main thread the callback hands each message to (the
pattern of the swarm's processes). The full bench (launched swarms) runs from the CLI, not here."""

from __future__ import annotations

import math

import pytest

from swarm.bench.transport import _rtt


@pytest.mark.parametrize(
    ("style", "topology"), [("direct", "star"), ("handoff", "star"), ("handoff", "mesh")]
)
def test_every_ping_is_answered_and_the_pong_reports_its_cpu_per_echo(style, topology):
    # (mesh: two peers that met at the router and ping over their own link; _ping waits for it)
    r = _rtt(200, style, wake=style == "direct", topology=topology)
    assert r["n"] == 200  # none timed out: the handoff's main loop echoes every message it is handed
    assert 0 < r["median"] <= r["p99"] < 1e6
    # the pong's CPU over 250 echoes (50 warm-up pings): a Python client spends tens to hundreds of us per
    # message received and published; 5 us would mean it counted what it did not do, 10 ms a broken clock
    assert math.isfinite(r["pong_cpu_us_per_echo"]) and 5 < r["pong_cpu_us_per_echo"] < 10_000
    if style == "handoff":
        assert r["wake_cost_us"] is None  # not asked for
        return
    # the pinging thread's own CPU per put and per numpy sum, back to back and after 10 ms asleep, medians:
    # 0 would be a clock that does not tick for this thread, 10 ms of CPU for one 64 B put a broken
    # measurement; no order between warm and idle is asserted (on bare metal they can be alike)
    w = r["wake_cost_us"]
    assert set(w) == {"put_warm_us", "put_idle_us", "numpy_sum_warm_us", "numpy_sum_idle_us"}
    assert all(math.isfinite(v) and 0 < v < 10_000 for v in w.values()), w
    assert "after 10 ms idle" in format_report_line(r)


def format_report_line(rtt: dict) -> str:
    """The report's line of the wake cost, from a report of this ping-pong alone."""
    from swarm.bench.transport import format_report

    lat = {"median": 1.0, "p99": 1.0}
    star = {
        "tick_us": 1.0,
        "realtime_factor": 1.0,
        "world_cpu_us_per_tick": 1.0,
        "agent_cpu_us_per_tick": 1.0,
    }
    r = {"zenoh_rtt_us": rtt, "mesh_rtt_us": rtt, "handoff_rtt_us": rtt, "lockstep_tick_us": {},
         "lockstep_realtime_factor": {}, "lockstep_cpu_us_per_tick": {}, "star_one_pair": star,
         "one_pair_tick_over_rtt": 1.0, "star_one_pair_tick_over_rtt": 1.0,
         "one_pair_tick_over_router_rtt": 1.0, "latency_us": lat, "goals": {}}  # fmt: skip
    return next(line for line in format_report(r).splitlines() if "CPU of one put" in line)
