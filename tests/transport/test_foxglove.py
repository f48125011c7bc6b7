"""``swarm foxglove``: the live bridge advertises the swarm's channels, raw and views, to a plain WebSocket
client speaking Foxglove's protocol (a real bridge process on a real router)."""

from __future__ import annotations

import json
import sys
import time

import numpy as np
from websockets.sync.client import connect

from swarm.transport.keys import Keys
from swarm.transport.messages import Anchors, Event, Truth, encode
from swarm.transport.process import declare_reliable
from swarm.transport.session import ZenohArgs, open_session
from tests.transport.procs import Procs, free_port, loopback

PY = [sys.executable, "-m", "swarm.cli.main"]


def test_the_bridge_advertises_raw_and_view_channels_to_a_websocket_client():
    ns, ep, port = f"fox-{free_port()}", loopback(free_port()), free_port()
    keys = Keys(ns)
    with Procs() as procs:
        procs.start([*PY, "router", "--listen", ep]).wait_for_line(r"^router listening on ", 60.0)
        bridge = procs.start([*PY, "foxglove", "--port", str(port), "--namespace", ns, "--mode", "client",
                              "--connect", ep])  # fmt: skip
        bridge.wait_for_line(rf"^foxglove bridge on ws://127\.0\.0\.1:{port}", 60.0)
        with open_session(ZenohArgs(mode="client", connect=(ep,))) as session:
            pubs = {k: declare_reliable(session, k) for k in (keys.truth("chaser"), keys.event("chaser"),
                                                               keys.anchors())}  # fmt: skip
            q = np.array([0.0, 0.0, 0.0, 1.0])
            payloads = {
                keys.truth("chaser"): encode(
                    Truth(5, 0.05, np.array([1.0, 2.0, 0.5]), np.zeros(3), q, np.zeros(3))
                ),
                keys.event("chaser"): encode(Event(0.05, "mode", {"to": "APPROACH"})),
                keys.anchors(): encode(Anchors((0, 1), np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))),
            }
            topics: dict[str, dict] = {}
            deadline = time.monotonic() + 30.0
            with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"],
                         open_timeout=10) as ws:  # fmt: skip
                info = json.loads(ws.recv(timeout=10))
                assert info["op"] == "serverInfo"
                want = set(payloads) | {"/tf", "/events", "/scene"}
                while not want <= set(topics) and time.monotonic() < deadline:
                    for k, pub in pubs.items():
                        pub.put(payloads[k])
                    try:
                        msg = ws.recv(timeout=0.5)
                    except TimeoutError:
                        continue
                    if isinstance(msg, str):
                        obj = json.loads(msg)
                        if obj.get("op") == "advertise":
                            topics.update({c["topic"]: c for c in obj["channels"]})
    assert want <= set(topics), sorted(topics)
    assert topics[keys.truth("chaser")]["encoding"] == "msgpack"
    assert topics["/tf"]["schemaName"] == "foxglove.FrameTransforms"
    assert topics["/events"]["schemaName"] == "foxglove.Log"
    assert topics["/scene"]["schemaName"] == "foxglove.SceneUpdate"
    assert "Traceback" not in bridge.output()
