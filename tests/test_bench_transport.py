"""``swarm bench transport``'s floor: a ping-pong through a router between two client processes, the pong
publishing from Zenoh's callback thread or from a main thread the callback hands each message to (the
pattern of the swarm's processes). The full bench (launched swarms) runs from the CLI, not here."""

from __future__ import annotations

import math

import pytest

from swarm.bench.transport import _rtt


@pytest.mark.parametrize("style", ["direct", "handoff"])
def test_every_ping_is_answered_and_the_pong_reports_its_cpu_per_echo(style):
    r = _rtt(200, style)
    assert r["n"] == 200  # none timed out: the handoff's main loop echoes every message it is handed
    assert 0 < r["median"] <= r["p99"] < 1e6
    # the pong's CPU over 250 echoes (50 warm-up pings): a Python client spends tens to hundreds of us per
    # message received and published; 5 us would mean it counted what it did not do, 10 ms a broken clock
    assert math.isfinite(r["pong_cpu_us_per_echo"]) and 5 < r["pong_cpu_us_per_echo"] < 10_000
