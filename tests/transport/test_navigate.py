"""``swarm navigate``: the log replay's filter as a process, fed by ``swarm replay DIR --zenoh`` (IMU, ranges,
marker detections, range finder and barometer) over real Zenoh on loopback, gives the offline replay's
estimates bit for bit, and publishes them and its events on the vehicle's keys (counted by an independent
subscriber)."""

from __future__ import annotations

import sys

import numpy as np

from swarm.logs.reader import read_log
from swarm.logs.replay import replay_log
from swarm.logs.synthetic import SyntheticSpec, make_log
from swarm.transport.keys import Keys
from swarm.transport.messages import Estimate, Event
from swarm.transport.session import ZenohArgs, open_session
from tests.transport.procs import Inbox, Procs, free_port, loopback, wait_until


def test_a_navigator_on_replayed_sensors_gives_the_offline_replay_bit_for_bit(tmp_path):
    d = tmp_path / "log"
    # a live feed carries no per-detection sigma: both sides use log.toml's vision.sigma_m
    # with a downward range finder and a barometer too: height.csv and baro.csv go over the wire as
    # Rangefinder and Barometer messages (the barometer is off by default: both sides switch it on)
    spec = SyntheticSpec(
        duration_s=12.0,
        vision_rate_hz=15.0,
        vision_sigma_columns=False,
        height_rate_hz=25.0,
        baro_rate_hz=20.0,
    )
    make_log(d, seed=5, spec=spec)
    # a forced divergence: the event and the recovery go out too
    settings = {"faults.jump_at_s": 9.0, "baro.enabled": True}
    offline = replay_log(read_log(d, settings))
    ns, endpoint = f"nav-{free_port()}", loopback(free_port())
    keys = Keys(ns)
    inbox = Inbox("estimate", "event")
    got, drops, on = inbox.got, inbox.drops, inbox.on

    series = tmp_path / "online.csv"
    with Procs() as procs:
        # the navigator listens; the feed and the test's subscriber connect to it
        nav = procs.start(
            [sys.executable, "-m", "swarm.cli.main", "navigate", str(d / "log.toml"), "--id", "uav",
             "--namespace", ns, "--set", "faults.jump_at_s=9.0", "--set", "baro.enabled=true",
             "--delay", "2.0", "--until-idle", "1.5", "--series", str(series), "--listen", endpoint]
        )  # fmt: skip
        with open_session(ZenohArgs(mode="peer", connect=(endpoint,))) as session:
            session.declare_subscriber(keys.estimate("uav"), on("estimate", Estimate))
            session.declare_subscriber(keys.event("uav"), on("event", Event))
            # 12 s of log at 3x: 4 s of wall time; the 2 s horizon of sensor time absorbs ~0.7 s of skew
            # between the IMU and the UWB streams' threads on a loaded machine
            feed = procs.start(
                [sys.executable, "-m", "swarm.cli.main", "replay", str(d), "--zenoh", "--speed", "3",
                 "--vehicle", "uav", "--namespace", ns, "--connect", endpoint]
            )  # fmt: skip
            nav.wait_for_line(r"^navigator uav ready", timeout=60.0)
            assert feed.wait(90.0) == 0, feed.output()
            assert nav.wait(60.0) == 0, nav.output()
            # returns as soon as they are in; on a loaded machine this subscriber's callbacks ran more
            # than 5 s behind the navigator's end (a fresh-clone `make test` beside other launches)
            wait_until(lambda: len(got["estimate"]) >= len(offline.t), 30.0, "every estimate")
    out = nav.output()
    assert "Traceback" not in out and "dropped (older than the filter) 0" in out and "undecodable 0" in out
    v = offline.summary()["vision"]
    assert v["accepted"] > 0 and f"vision accepted {v['accepted']} rejected {v['rejected']}," in out
    # both height sensors fused, each reading with the replay's outcome (a barometer reading the navigator
    # never got, or one fed with the feature off, would change these counts and the estimates below)
    h = offline.summary()["height"]
    rf, baro = h["rangefinder"], h["barometer"]
    assert baro["accepted"] > 0 and rf["accepted"] > 0
    assert (
        f"rangefinder accepted {rf['accepted']} rejected {rf['rejected']}, "
        f"barometer accepted {baro['accepted']} rejected {baro['rejected']}," in out
    ), out
    rows = np.loadtxt(series, delimiter=",", skiprows=1)
    # the same samples in the same order through the same kernels: equal to the last bit
    assert np.array_equal(rows[:, 0], offline.t)
    assert np.array_equal(rows[:, 2:12], offline.X[:, 0:10])
    assert np.array_equal(rows[:, 12:15], np.sqrt(np.diagonal(offline.P[:, 0:3, 0:3], axis1=1, axis2=2)))
    # on the wire: every estimate once, in order, and the events the replay reports
    est = got["estimate"]
    assert drops.total == 0 and len(est) == len(offline.t)
    assert [e.t_s for e in est] == offline.t.tolist()
    np.testing.assert_array_equal(np.array([e.p_nav for e in est]), offline.X[:, 0:3])
    assert [e.kind for e in got["event"]] == [e["kind"] for e in offline.events]
    resets = [e for e in got["event"] if e.kind not in ("takeoff", "landing")]
    assert [e.kind for e in resets] == ["fault", "estimator_reset"]
    offline_reset = next(e for e in offline.events if e["kind"] == "estimator_reset")
    assert resets[1].data["reason"] == offline_reset["reason"]
