"""``swarm launch docking --set uwb.mode=tdoa3`` equals ``swarm sim docking`` with the same settings, bit for
bit (issue 45): the mothership runs the TDoA radio (swarm.step.radio.UwbNetwork) and sends each vehicle the
distance differences its tag heard, one ``Tdoa`` per UWB slot (in the lockstep bundles), and each agent fuses
them as the in-process run does (docs/protocol.md, "Tdoa"). One lockstep launch, real processes over real
Zenoh on loopback, both vehicles in one agent host (the costly part of the suite is launches: one)."""

from __future__ import annotations

import itertools
import json
import sys
import threading
import time
import uuid
import warnings

import pytest

from swarm.scenario import load_scenario
from swarm.sim.docking import run_docking
from swarm.transport.keys import Keys
from swarm.transport.session import ZenohArgs, open_session
from swarm.transport.wire import estimate_payload
from tests.transport.procs import Procs, free_port, loopback

SEED = 3
# eight anchors on the corners of a 2 m cube (tests/test_docking_tdoa.py's CUBE: the paper's four leave the
# differences blind along y, and the chaser would only hold)
CUBE = [list(c) for c in itertools.product([-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0])]
# the first 30 s of the docking (the whole one takes ~113 s of simulated time, minutes of wall time on the
# per-tick path TDoA takes): the chaser approaches on ~8,000 differences, enough to tell any lost,
# reordered or altered row (each moves the filter's state, and the estimates are compared as bytes)
OVERRIDES = ["uwb.mode=tdoa3", f"anchors_m={json.dumps(CUBE)}", "sim.max_duration_s=30.0"]
RUN_S = 400.0  # wall-time ceiling of the launched run (two cores shared with other work)
FIELDS = ("docked", "docking_time_s", "effort", "position_error_m", "attitude_error_rad", "r1_m", "r2_m",
          "keepout_violated", "closest_approach_m", "final_mode", "modes", "estimator",
          "decisions")  # fmt: skip


class _Estimates:
    """A tap of the in-process run (:class:`swarm.sim.docking.DockingSim`) that keeps the chaser's
    ``estimate(k)`` payload of every tick, as its agent process encodes it."""

    def __init__(self, vid: str) -> None:
        self.vid, self.by_tick = vid, {}

    def agent(self, sim, vid: str, k: int, _cmd) -> None:
        if vid == self.vid:
            self.by_tick[k] = estimate_payload(sim.agents[vid], k)

    def start(self, sim) -> None: ...
    def world(self, sim, k, frames) -> None: ...
    def uwb(self, sim, k) -> None: ...
    def keepout(self, *a) -> None: ...
    def contact(self, *a) -> None: ...
    def end(self, *a) -> None: ...


# one launched docking on the TDoA radio: ~20 s of wall time here (the launch 19 s, the in-process run 3 s)
def test_a_lockstep_launch_on_tdoa3_equals_the_in_process_run(tmp_path):
    from swarm.config import parse_override

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        sc = load_scenario("docking", dict(parse_override(o) for o in OVERRIDES))
    assert sc.uwb.mode == "tdoa3" and len(sc.anchors_m) == 8
    tap = _Estimates("chaser")
    want = run_docking(sc, "mdp", SEED, record_series=False, tap=tap)
    ns = f"test-{uuid.uuid4().hex[:8]}"
    endpoint = loopback(free_port())
    out = tmp_path / "launch.json"
    args = [sys.executable, "-m", "swarm.cli.main", "launch", "docking", "--headless", "--seed", str(SEED),
            "--policy", "mdp", "--namespace", ns, "--listen", endpoint, "--until-docked", "--json", str(out),
            "--vehicles-per-process", "2", "--timeout", str(RUN_S)]  # fmt: skip
    for o in OVERRIDES:
        args += ["--set", o]
    got_estimates: dict[int, bytes] = {}
    with Procs() as procs:
        proc = procs.start(args)
        m = proc.wait_for_line(r"^swarm listening on \S+ \(clients: --mode client --connect (\S+)\)", 60.0)
        session = open_session(ZenohArgs(mode="client", connect=(m.group(1),)))
        try:
            from swarm.transport.messages import Estimate, decode

            def on_estimate(sample) -> None:
                payload = sample.payload.to_bytes()
                got_estimates[decode(payload, Estimate).tick] = payload

            session.declare_subscriber(Keys(ns).estimate("chaser"), on_estimate)
            t0 = time.monotonic()
            rc = proc.wait(RUN_S)
            wall = time.monotonic() - t0
        finally:
            session.close()
        text = proc.output()
    print(f"launched TDoA3 docking: {wall:.1f} s of wall time")
    assert rc == (0 if want["chasers"]["chaser"]["docked"] else 1), text  # 1: not docked (30 s)
    assert "Traceback" not in text
    got = json.loads(out.read_text())
    w, g = want["chasers"]["chaser"], got["chasers"]["chaser"]
    assert w["estimator"]["accepted_ranges"] > 5000  # the differences were fused (~260 a second)
    for field in FIELDS:
        assert g[field] == w[field], (field, g[field], w[field])
    assert got["target_effort"] == want["target_effort"]
    # the chaser's estimates, as published: the same bytes as the in-process agent's, tick by tick, to the
    # last tick of the run (a subscriber joins a few ticks late: the first ones may be missing)
    assert max(got_estimates) == max(tap.by_tick)
    assert len(got_estimates) > 0.9 * len(tap.by_tick)
    for k, payload in got_estimates.items():
        assert payload == tap.by_tick[k], k


@pytest.mark.parametrize("layout", ["cube", "paper"])
def test_a_rejoining_agent_on_tdoa_reinitialises_by_multilateration(layout):
    """A restarted agent on a TDoA radio has no ranges: it holds (no agent) until it has
    ``agent.reinit_tdoa_rows`` differences naming every anchor, then multilaterates
    (swarm.core.ranging.position_from_tdoa) and flies from the fix, its covariance the fix's. On the
    eight-anchor cube the fix is within centimetres; the paper's four anchors hardly see y in differences,
    so the restarted filter reports metres and the chaser holds on it."""
    import numpy as np

    from agents.process import AgentProcess
    from swarm.core import rotations as rot
    from swarm.transport.messages import Event, Imu, Tdoa, decode
    from swarm.transport.process import ClockSpec

    overrides = {"uwb.mode": "tdoa3"} | ({"anchors_m": CUBE} if layout == "cube" else {})
    sc = load_scenario("docking", overrides)
    proc = AgentProcess(sc, "chaser", SEED, "mdp", None, Keys("t"), ClockSpec.parse("lockstep"),
                        threading.Event(), rejoin=True)  # fmt: skip
    sent = []
    proc.pub_event = type("Pub", (), {"put": staticmethod(sent.append)})  # no session: keep what it says
    anchors = np.asarray(sc.anchors_m, dtype=float)
    q = np.array([0.0, 0.0, 0.0, 1.0])
    lever = rot.quat_rotate(q, np.asarray(sc.kind("chaser").mounts.tag_lever_arm_body_m, dtype=float))
    p_true = np.asarray(sc.vehicles["chaser"].position_m, dtype=float) + np.array([0.10, -0.05, 0.02])
    rng = np.random.default_rng(SEED)
    sigma = sc.estimator.sigma_tdoa_m
    n = len(anchors)
    imu = Imu(5, 0.05, 0.01, np.zeros(3), q)
    # a row the filter skips is skipped here too: an unknown anchor (a bad packet must neither stop the
    # process nor enter the fix; a row naming one anchor twice is refused by the message's own check)
    junk = Tdoa(4, 0.03, (0, 99), (1, 3), np.array([5.0, 0.1]))
    assert not proc._collect_init(imu, junk)
    assert len(proc._init_rows) == 1
    for k in range(40):  # six differences a tick, as a TDoA3 tag on 8 anchors hears ~300 a second
        a = rng.integers(0, n, 6)
        b = (a + rng.integers(1, n, 6)) % n
        d = np.linalg.norm(p_true + lever - anchors[b], axis=1) - np.linalg.norm(
            p_true + lever - anchors[a], axis=1
        )
        msg = Tdoa(5 + k, 0.05 + 0.02 * k, tuple(a.tolist()), tuple(b.tolist()), d + rng.normal(0, sigma, 6))
        if proc._collect_init(imu, msg):
            break
        assert proc.agent is None  # holds while the differences do not yet name every anchor
    assert proc.agent is not None and k >= 1  # one tick's six differences cannot name every anchor
    p0 = proc.agent.est.X[0][:3]
    var = np.diag(proc.agent.est.P[0])[:3]
    (event,) = [decode(m, Event) for m in sent]
    assert event.kind == "restarted" and np.allclose(event.data["p_nav"], p0)
    if layout == "cube":
        # 64 differences of sigma 5 cm: the fix's own sigma is ~2 cm per axis (tests/core/test_ranging.py)
        assert np.linalg.norm(p0 - p_true) < 0.1
        assert np.all(var < 0.01)
    else:
        assert np.all(np.sqrt(var) > 1.0)  # metres: the chaser's guidance holds on such an estimate
