"""The agent host's wiring between its vehicles (no Zenoh: the processes are built, not opened)."""

from __future__ import annotations

import threading

import pytest

from agents.host import AgentHost
from agents.process import AgentProcess
from swarm.scenario import load_scenario
from swarm.transport.keys import Keys
from swarm.transport.process import ClockSpec


def _host(ids, sc, clock="lockstep"):
    cond, ready, stop = threading.Condition(), set(), threading.Event()
    spec, n = ClockSpec.parse(clock), len(ids)
    procs = [
        AgentProcess(sc, v, 0, "mdp", None, Keys("t"), spec, stop, hosted=n, cond=cond, ready=ready)
        for v in ids
    ]
    return AgentHost(procs, None, Keys("t"), stop), {p.id: p for p in procs}


def test_a_chaser_takes_its_targets_estimates_from_the_host_only_when_the_target_is_hosted_there():
    """chaser0 and target0 share the host: target0 hands its estimates to chaser0, which subscribes to none;
    chaser1's target is in another process: chaser1 subscribes to it as before, and no one hands it over."""
    sc = load_scenario("docking").with_pairs(2)
    _, p = _host(["chaser0", "target0", "chaser1"], sc)
    assert p["chaser0"].target_local and p["target0"].local_chasers == [p["chaser0"]]
    assert not p["chaser1"].target_local
    assert p["chaser0"].local_chasers == [] and p["chaser1"].local_chasers == []


def test_a_host_refuses_vehicles_that_do_not_share_its_condition():
    sc = load_scenario("docking")
    stop = threading.Event()
    procs = [AgentProcess(sc, v, 0, "mdp", None, Keys("t"), ClockSpec.parse("lockstep"), stop, hosted=2,
                          cond=threading.Condition(), ready=set()) for v in ("chaser", "target")]  # fmt: skip
    with pytest.raises(ValueError, match="share one condition"):
        AgentHost(procs, None, Keys("t"), stop)
