"""The dashboard's Zenoh side (:class:`dashboard.link.SwarmLink`) takes a message that arrives while it is
still being built. A restarted dashboard met the mothership's periodic anchors between its anchors
subscription and the creation of the event that callback sets: an AttributeError on a Zenoh thread,
logged with its traceback (a launch test caught the "Traceback" in the launcher's output). Here the anchors
arrive deterministically at that moment: the session hands them to the callback as it is declared."""

from __future__ import annotations

import logging

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
