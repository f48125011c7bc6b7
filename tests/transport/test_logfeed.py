"""``swarm replay DIR --zenoh``: a recorded log published on the swarm's keys by a real process over real
Zenoh on loopback, received by an independent subscriber, decoded by the codec; and the sequence of
messages it sends (``swarm.transport.logfeed.messages``), checked against the log's rows without a
process."""

from __future__ import annotations

import sys

import numpy as np

from swarm.logs.reader import read_log
from swarm.logs.synthetic import SyntheticSpec, make_log
from swarm.transport.keys import Keys
from swarm.transport.logfeed import messages
from swarm.transport.messages import Anchors, Barometer, Imu, Rangefinder, Uwb, Vision, decode
from swarm.transport.session import ZenohArgs, open_session
from tests.transport.procs import Inbox, Procs, free_port, loopback, wait_until


def test_a_log_published_on_the_swarm_keys_arrives_whole_in_order_and_paced(tmp_path):
    d = tmp_path / "log"
    make_log(d, seed=3, spec=SyntheticSpec(duration_s=10.0))
    log = read_log(d)
    ns, endpoint = f"feed-{free_port()}", loopback(free_port())
    keys = Keys(ns)
    inbox = Inbox("imu", "uwb")
    got, drops, on = inbox.got, inbox.drops, inbox.on

    with open_session(ZenohArgs(mode="peer", listen=(endpoint,))) as session, Procs() as procs:
        session.declare_subscriber(keys.imu("uav"), on("imu", Imu))
        session.declare_subscriber(keys.uwb("uav"), on("uwb", Uwb))
        speed = 10.0
        args = ["replay", str(d), "--zenoh", "--speed", str(speed), "--vehicle", "uav", "--namespace", ns]
        proc = procs.start([sys.executable, "-m", "swarm.cli.main", *args, "--connect", endpoint])
        wait_until(lambda: len(got["imu"]) > 100, 60.0, "the first IMU samples")
        # asked while it publishes: it answers the anchors query as the mothership does
        anchors = [decode(r.ok.payload, Anchors) for r in session.get(keys.anchors(), timeout=2.0) if r.ok]
        assert proc.wait(60.0) == 0, proc.output()
        wait_until(lambda: len(got["uwb"]) >= len(log.uwb_t), 5.0, "every range")
    out = proc.output()
    assert drops.total == 0 and "Traceback" not in out
    imu, uwb = got["imu"], got["uwb"]
    # every row the reader kept, once, in order, with the file's values
    assert len(imu) == len(log.imu_t) and len(uwb) == len(log.uwb_t)
    assert [m.tick for m in imu] == list(range(len(imu)))
    t_imu = np.array([m.t_s for m in imu])
    np.testing.assert_allclose(t_imu, log.imu_t - log.imu_t[0], atol=1e-12)
    np.testing.assert_array_equal(np.array([m.acc_body for m in imu]), log.acc)
    np.testing.assert_array_equal(np.array([m.gyro_body for m in imu]), log.gyro)
    np.testing.assert_allclose([m.dt_s for m in imu[1:]], np.diff(log.imu_t), atol=1e-12)
    assert [m.anchor_id for m in uwb] == [int(log.anchor_ids[a]) for a in log.uwb_anchor]
    np.testing.assert_array_equal([m.range_m for m in uwb], log.uwb_range)
    # the anchors, as the mothership serves them
    assert anchors and anchors[0].anchor_ids == tuple(range(8))
    np.testing.assert_array_equal(anchors[0].positions_nav, log.anchors_nav)
    # paced: 10 s of log at 10x real time takes about a second (not less: it never runs ahead)
    wall = float(out.split(" s of log in ")[1].split(" s")[0])
    assert 0.9 <= wall < 5.0


def test_the_feed_sends_every_height_and_barometer_row_in_time_order_with_its_sigma(tmp_path):
    d = tmp_path / "log"
    # rates that share instants with the 1 kHz IMU (0.04 s, 0.05 s, ...): ties are sent IMU first
    # 8 s: the camera sees its first marker after the take-off, at 6 s
    spec = SyntheticSpec(duration_s=8.0, height_rate_hz=25.0, baro_rate_hz=20.0, vision_rate_hz=15.0)
    make_log(d, seed=2, spec=spec)
    log = read_log(d)
    seq = list(messages(log))
    kinds = [k for _, k, _ in seq]
    t0 = float(log.imu_t[0])
    # every row of every stream, once, each on its key's message type
    types = {"imu": Imu, "uwb": Uwb, "rangefinder": Rangefinder, "barometer": Barometer, "vision": Vision}
    assert all(isinstance(m, types[k]) for _, k, m in seq)
    counts = {k: kinds.count(k) for k in types}
    assert counts == {"imu": len(log.imu_t), "uwb": len(log.uwb_t), "rangefinder": len(log.height_t),
                      "barometer": len(log.baro_t), "vision": len(log.vision_t)}  # fmt: skip
    assert counts["barometer"] == 160 and counts["vision"] > 0  # 8 s at 20 Hz: rows to send
    # in time order, and at one time in the replay's order: IMU, range, height, barometer, vision
    rank = {k: n for n, k in enumerate(("imu", "uwb", "rangefinder", "barometer", "vision"))}
    keys = [(t, rank[k]) for t, k, _ in seq]
    assert keys == sorted(keys)
    # the barometer's rows as read, its sigma [baro] sigma_m, stamped from the first IMU sample, with the
    # tick of the latest IMU sample sent before it (the one at the same instant included)
    baro = [m for _, k, m in seq if k == "barometer"]
    np.testing.assert_array_equal([m.height_m for m in baro], log.baro_height)
    assert {m.sigma_m for m in baro} == {log.config.baro.sigma_m}
    np.testing.assert_allclose([m.t_s for m in baro], log.baro_t - t0, atol=1e-12)
    latest = np.maximum(np.searchsorted(log.imu_t, log.baro_t, side="right") - 1, 0)
    assert [m.tick for m in baro] == latest.tolist()
    # the range finder's likewise, with [height] sigma_m
    rf = [m for _, k, m in seq if k == "rangefinder"]
    np.testing.assert_array_equal([m.range_m for m in rf], log.height_range)
    assert {m.sigma_m for m in rf} == {log.config.height.sigma_m}
