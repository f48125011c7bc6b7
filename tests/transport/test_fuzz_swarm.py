"""Property test against a live swarm (issue 7, bad input everywhere): thousands of arbitrary payloads —
random bytes, arbitrary msgpack values, and valid messages with one field replaced by an arbitrary value —
published on every key of the swarm while a lockstep docking runs, and garbage queries to the anchors
queryable. Every payload sent is checked, on the test's side, to be one the codec refuses for that key (a
*valid* message from an intruder is for access control: ``--secure``, tests/transport/test_security.py).

Oracle: the in-process simulation of the same seed. The launched run must be that run exactly, and every
process must survive (no traceback, launcher exit 0).
"""

from __future__ import annotations

import json
import logging
import sys
import time

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarm.scenario import load_scenario
from swarm.sim.docking import run_docking
from swarm.transport.keys import AGENT_KINDS, Keys
from swarm.transport.messages import (
    MESSAGE_FOR_KIND,
    Bundle,
    Clock,
    Command,
    CommandBatch,
    DropCounter,
    Estimate,
    Fault,
    Imu,
    ImuBatch,
    MessageError,
    RunControl,
    Truth,
    TruthBatch,
    Uwb,
    UwbBatch,
    Vision,
    VisionBatch,
    bundle_messages,
    decode,
    encode,
)
from swarm.transport.session import ZenohArgs, open_session
from tests.transport.procs import Procs, free_port, loopback

_SILENT = logging.getLogger("tests.transport.fuzz.silent")
_SILENT.disabled = True

SEED = 3
EXAMPLES = 2500  # payloads per run: "thousands", while the docking (~25 s of wall time here) is under way

_int64 = st.integers(-(2**63), 2**64 - 1)
_values = st.recursive(
    st.none() | st.booleans() | _int64 | st.floats() | st.text(max_size=16) | st.binary(max_size=32),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)

_Q = np.array([0.0, 0.0, 0.0, 1.0])
_VALID = {
    "imu": Imu(7, 0.07, 0.01, np.zeros(3), _Q),
    "uwb": Uwb(8, 0.08, 1, 1.5),
    "command": Command(7, 0.07, np.zeros(10), "HOLD", np.zeros(3), np.zeros(3)),
    "commands": CommandBatch(
        ("chaser",), (encode(Command(7, 0.07, np.zeros(10), "HOLD", np.zeros(3), np.zeros(3))),)
    ),
    "truth": Truth(7, 0.07, np.zeros(3), np.zeros(3), _Q, np.zeros(3)),
    "estimate": Estimate(7, 0.07, np.zeros(3), np.zeros(3), _Q, np.eye(9), 0.1, 0.0, 0.0, {}),
    "world_clock": Clock(7, 0.07, "running", 0),
    "world_truth": TruthBatch(
        7,
        0.07,
        ("chaser", "target"),
        np.zeros((2, 3)),
        np.zeros((2, 3)),
        np.tile(_Q, (2, 1)),
        np.zeros((2, 3)),
        np.zeros(2),
        (False, False),
        np.zeros(2),
    ),
    "mothership_uwb": UwbBatch(8, 0.08, ("chaser", "target"), (1, 2), (1.5, None)),
    "world_imu": ImuBatch(7, 0.07, 0.01, ("chaser", "target"), np.zeros((2, 3)), ("chaser",), _Q[None, :]),
    "world_vision": VisionBatch(
        10, 0.1, ("chaser",), (encode(Vision(10, 0.1, "target", "+x", "features", np.zeros((0, 3)), ())),)
    ),
    "bundle": Bundle(
        8, ("Imu", "Uwb"), (encode(Imu(7, 0.07, 0.01, np.zeros(3), _Q)), encode(Uwb(8, 0.08, 1, 1.5)))
    ),
    "run_control": RunControl("pause"),
    "fault": Fault("camera_loss", duration_s=1.0, vehicle="chaser"),
}


def _keys(ns: str) -> list[tuple[str, str]]:
    k = Keys(ns)
    out = [(kind, getattr(k, kind)(vid)) for kind in AGENT_KINDS for vid in ("chaser", "target")]
    fixed = [("world_clock", k.world_clock()), ("world_event", k.world_event()), ("world_imu", k.world_imu()),
             ("world_vision", k.world_vision()), ("world_truth", k.world_truth()),
             ("world_bundle", k.world_bundle()),
             ("mothership_uwb", k.mothership_uwb()), ("anchors", k.anchors()),
             ("run_control", k.run_control()), ("fault", k.fault())]  # fmt: skip
    return [*out, *fixed]


@st.composite
def _mutated(draw, kind: str) -> bytes:
    """A valid message of ``kind`` (or a close one) with one field replaced by an arbitrary value."""
    base = _VALID.get(kind, _VALID["imu"])
    wire = msgpack.unpackb(encode(base), raw=False)
    field = draw(st.sampled_from(sorted(wire)))
    wire[field] = draw(_values)
    return msgpack.packb(wire, use_bin_type=True)


def _refused(kind: str, payload: bytes) -> bool:
    try:
        msg = decode(payload, MESSAGE_FOR_KIND[kind])
    except MessageError:
        return True
    if isinstance(msg, VisionBatch | CommandBatch):  # its entries are decoded by whoever takes them: refused
        return not any(_frame_ok(msg, vid) for vid in msg.ids)  # if none decodes
    if isinstance(msg, Bundle):  # likewise, each entry as the receiver takes it
        return not bundle_messages(msg, "fuzz", DropCounter(logger=_SILENT))
    return False  # a valid message: not this test's business (see the module docstring)


def _frame_ok(batch: VisionBatch | CommandBatch, vid: str) -> bool:
    try:
        batch.sample(vid)
    except MessageError:
        return False
    return True


@st.composite
def _attack(draw, keys: list[tuple[str, str]]) -> tuple[str, bytes]:
    kind, key = draw(st.sampled_from(keys))
    payload = draw(
        st.binary(max_size=256) | _values.map(lambda v: msgpack.packb(v, use_bin_type=True)) | _mutated(kind)
    )
    return key, payload


@pytest.fixture(
    scope="module",
    # both vehicles in one agent host (issue 13) by default; one process per vehicle, the launcher's default,
    # in the --runslow job (test_launch.py's garbage run covers it by default)
    params=[2, pytest.param(1, marks=pytest.mark.slow)],
    ids=["agent host", "a process per vehicle"],
)
def swarm(request, tmp_path_factory):
    ns = f"fuzz-{free_port()}"
    out = tmp_path_factory.mktemp("fuzz") / "launch.json"
    endpoint = loopback(free_port())
    with Procs() as procs:
        proc = procs.start([sys.executable, "-m", "swarm.cli.main", "launch", "docking", "--headless",
                            "--until-docked", "--seed", str(SEED), "--namespace", ns, "--listen", endpoint,
                            "--json", str(out), "--vehicles-per-process", str(request.param)])  # fmt: skip
        proc.wait_for_line(r"^swarm up:", 180.0)
        with open_session(ZenohArgs(mode="client", connect=(endpoint,))) as session:
            yield {"proc": proc, "session": session, "keys": _keys(ns), "ns": ns, "out": out, "sent": [0]}


def test_a_viewer_that_subscribes_to_the_truths_gets_them(swarm):
    """The world sends its mothership one world/truth batch per UWB slot (agent hosts or not) and a
    vehicle's own truth only while a viewer subscribes to it (a Zenoh matching listener): this viewer,
    subscribing in the middle of the run, gets both vehicles' truths from then on."""
    session, ns = swarm["session"], swarm["ns"]
    got: dict[str, list[int]] = {"chaser": [], "target": []}

    def on_truth(sample) -> None:
        vid = str(sample.key_expr).split("/")[-2]
        got[vid].append(decode(sample.payload.to_bytes(), Truth).tick)

    sub = session.declare_subscriber(f"{ns}/agent/*/truth", on_truth)
    try:
        deadline = time.monotonic() + 30.0
        while min(len(v) for v in got.values()) < 20 and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        sub.undeclare()
    assert min(len(v) for v in got.values()) >= 20, {v: len(t) for v, t in got.items()}
    assert all(t == sorted(t) for t in got.values())  # in tick order, one per UWB slot


def test_thousands_of_refused_payloads_on_every_key_and_query(swarm):
    session, keys = swarm["session"], swarm["keys"]

    @settings(max_examples=EXAMPLES, deadline=None, database=None, derandomize=True,
              suppress_health_check=list(HealthCheck))  # fmt: skip
    @given(_attack(keys))
    def attack(item):
        key, payload = item
        kind = next(k for k, kk in keys if kk == key)
        if not _refused(kind, payload):
            return
        session.put(key, payload)
        swarm["sent"][0] += 1
        if swarm["sent"][0] % 100 == 0:  # and the queryable, with a garbage query payload
            for _reply in session.get(
                key if kind == "anchors" else keys[-2][1], payload=payload, timeout=1.0
            ):
                pass

    attack()
    assert swarm["sent"][0] > 1000  # most generated payloads are refused ones (the rest are skipped)


def test_the_run_is_still_the_in_process_run(swarm):
    proc = swarm["proc"]
    assert proc.wait(300.0) == 0, proc.output()
    text = proc.output()
    assert "Traceback" not in text
    got = json.loads(swarm["out"].read_text())["chasers"]["chaser"]
    want = run_docking(load_scenario("docking"), seed=SEED, record_series=False)["chasers"]["chaser"]
    for field in ("docked", "docking_time_s", "total_impulse_ns", "position_error_m", "modes"):
        assert got[field] == want[field], field
    assert "dropped" in text  # the processes counted and logged the drops
