"""The dashboard's Zenoh side (:class:`dashboard.link.SwarmLink`) takes a message that arrives while it is
still being built. A restarted dashboard met the mothership's periodic anchors between its anchors
subscription and the creation of the event that callback sets: an AttributeError on a Zenoh thread,
logged with its traceback (a launch test caught the "Traceback" in the launcher's output). Here the anchors
arrive deterministically at that moment: the session hands them to the callback as it is declared."""

from __future__ import annotations

import logging
import time

import numpy as np
import zenoh

from dashboard.link import SwarmLink
from dashboard.state import SwarmState
from swarm.transport.keys import Keys
from swarm.transport.messages import Anchors, DropCounter, encode
from swarm.transport.session import ZenohArgs, open_session
from tests.transport.procs import free_port, loopback


class _Sample:
    kind = zenoh.SampleKind.PUT

    def __init__(self, key: str, payload: bytes) -> None:
        self.key_expr, self.payload = key, payload


class _DeliveringSession:
    """A real session whose anchors subscriber gets a sample the moment it is declared."""

    def __init__(self, session, key: str, payload: bytes) -> None:
        self._session, self._key, self._payload = session, key, payload

    def __getattr__(self, name):
        return getattr(self._session, name)

    def declare_subscriber(self, key, handler, **kw):
        sub = self._session.declare_subscriber(key, handler, **kw)
        if str(key) == self._key and callable(handler):
            handler(_Sample(self._key, self._payload))
        return sub


def test_anchors_arriving_while_the_link_is_built_are_taken_without_an_error(caplog):
    keys = Keys(f"link{free_port()}")
    anchors = Anchors((0, 1, 2, 3), np.arange(12.0).reshape(4, 3))
    state = SwarmState({"chaser": ("chaser", "target"), "target": ("target", None)}, np.zeros((0, 3)))
    with open_session(ZenohArgs(mode="peer", listen=(loopback(free_port()),))) as session:
        fake = _DeliveringSession(session, keys.anchors(), encode(anchors))
        with caplog.at_level(logging.ERROR):
            link = SwarmLink(fake, keys, state, DropCounter(), anchors_retry_s=0.05)
            try:
                assert link._have_anchors.is_set()  # the callback ran to its end: no anchors query needed
            finally:
                link.close()
    assert not [r for r in caplog.records if "raised" in r.getMessage()], caplog.text
    snap = state.snapshot()
    assert snap.anchors_version == 1 and np.array_equal(snap.anchors[1], anchors.positions_nav)


def _put_until_chaser_frame(
    keys: Keys, state: SwarmState, drops: DropCounter, key: str, payload: bytes
) -> None:
    """A link on a real peer session; another session on loopback puts ``payload`` on ``key`` (once the
    link's subscriber matches) and the link is polled until the chaser has a frame (10 s at most)."""
    endpoint = loopback(free_port())
    with open_session(ZenohArgs(mode="peer", listen=(endpoint,))) as session:
        link = SwarmLink(session, keys, state, drops, anchors_retry_s=0.05)
        try:
            with open_session(ZenohArgs(mode="peer", connect=(endpoint,))) as other:
                pub = other.declare_publisher(key)
                deadline = time.monotonic() + 10.0
                while not pub.matching_status.matching and time.monotonic() < deadline:
                    time.sleep(0.01)
                pub.put(payload)
                while (
                    state.snapshot().agents.get("chaser") is None
                    or state.snapshot().agents["chaser"].vision_rows is None
                ):
                    assert time.monotonic() < deadline, f"the frame on {key} never reached the dashboard"
                    link.poll()
                    time.sleep(0.01)
        finally:
            link.close()


def test_the_frames_of_a_world_vision_batch_reach_each_vehicle_and_a_bad_one_is_counted():
    """A swarm of agent hosts sends the chasers' frames in world/vision batches (docs/protocol.md): the
    dashboard draws each vehicle's frame from its entry, as from its own vision key, and an entry that does
    not decode is counted and loses no other frame. Two real sessions on loopback."""
    from swarm.transport.messages import Vision, VisionBatch

    keys = Keys(f"link{free_port()}")
    state = SwarmState({"chaser": ("chaser", "target"), "chaser2": ("chaser", "target2")}, np.zeros((0, 3)))
    frame = Vision(10, 0.1, "target", "+x", "features", np.full((6, 3), 0.2), (0, 1, 2, 3, 4, 5))
    batch = VisionBatch(10, 0.1, ("chaser", "chaser2"), (encode(frame), b"\x81\xa1v\x02"))
    drops = DropCounter()
    _put_until_chaser_frame(keys, state, drops, keys.world_vision(), encode(batch))
    snap = state.snapshot().agents
    assert snap["chaser"].vision_rows == 6 and snap["chaser"].vision_t_s == 0.1
    assert snap.get("chaser2") is None or snap["chaser2"].vision_rows is None
    assert drops.count(keys.world_vision()) == 1


def test_the_newest_frame_of_a_lockstep_bundle_is_drawn_and_a_bad_entry_is_counted():
    """A lockstep world sends a chaser's frames in its bundles (docs/protocol.md, "Bundles"): the dashboard
    draws the bundle's newest frame, skips its imu, and counts an entry that does not decode without losing
    the others. Two real sessions on loopback."""
    from swarm.transport.messages import Bundle, Imu, Vision

    keys = Keys(f"link{free_port()}")
    state = SwarmState({"chaser": ("chaser", "target")}, np.zeros((0, 3)))
    old = Vision(5, 0.05, "target", "+x", "features", np.full((6, 3), 0.2), (0, 1, 2, 3, 4, 5))
    new = Vision(10, 0.1, "target", "+x", "features", np.full((4, 3), 0.2), (0, 1, 2, 3))
    imu = Imu(10, 0.1, 0.01, np.zeros(3))
    bundle = Bundle(
        10, ("Vision", "Imu", "Vision", "Vision"), (encode(old), encode(imu), encode(new), b"\x81")
    )
    drops = DropCounter()
    _put_until_chaser_frame(keys, state, drops, keys.bundle("chaser"), encode(bundle))
    snap = state.snapshot().agents
    assert snap["chaser"].vision_rows == 4 and snap["chaser"].vision_t_s == 0.1
    assert drops.count(keys.bundle("chaser")) == 1
