"""Tests for swarm.transport.messages: the wire codec of every message, its validation and the drop counter.

Oracles: round trips (encode then decode gives the message back, bit for bit), msgpack itself (payloads
built by hand with ``msgpack.packb``, as a client in another language would), hand-written expected error
messages, and the core's own enums for the mirrored constants.
"""

from __future__ import annotations

import logging
import math
import re
import subprocess
import sys
import threading
from pathlib import Path

import msgpack
import msgspec
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from swarm.core.mdp import DECISION_KEYS
from swarm.errors import ConfigError, MessageError
from swarm.transport import declared
from swarm.transport import messages as msgs
from swarm.transport.keys import ID_PATTERN
from swarm.transport.messages import (
    MAX_ITEMS,
    MAX_PAYLOAD_BYTES,
    MESSAGE_FOR_KIND,
    MESSAGE_TYPES,
    SCHEMA_VERSION,
    Anchors,
    Barometer,
    Bundle,
    Clock,
    Command,
    CommandBatch,
    DropCounter,
    Estimate,
    Event,
    Fault,
    Gnss,
    Guidance,
    Imu,
    ImuBatch,
    Rangefinder,
    RunControl,
    Tdoa,
    TdoaBatch,
    Truth,
    TruthBatch,
    Uwb,
    UwbBatch,
    Vision,
    VisionBatch,
    decode,
    encode,
    encode_tdoa,
    safe_decode,
)
from tests.budget import examples

NAN, INF = math.nan, math.inf
Q = [0.0, 0.0, 0.0, 1.0]
PROBS = {"A11", "A22", "A23", "A32", "A33", "pi1", "pi2"}
DECISION = {k: (None if k in {"A32", "A33", "pi1", "pi2"} else 0.5) for k in DECISION_KEYS}
ANCHORS_MS = [[1.0, -0.2, 0.5], [1.0, 0.2, -0.5], [-1.0, 0.2, -0.5], [-1.0, -0.2, 0.5]]  # the paper, sec. III

VALID = {
    Imu: Imu(1, 0.01, 0.01, [0.1, 0.2, 0.3], Q),
    ImuBatch: ImuBatch(
        1, 0.01, 0.01, ("chaser0", "target0", "chaser1"), [[0.1, 0.2, 0.3]] * 3, ("target0",), [Q]
    ),
    Uwb: Uwb(2, 0.02, 1, 1.5),
    UwbBatch: UwbBatch(2, 0.02, ("chaser0", "target0", "chaser1"), (1, 0, 3), (1.5, None, 2.25)),
    Vision: Vision(3, 0.05, "target", "+x", "features", np.full((6, 3), 0.1), (0, 1, 2, 3, 4, 5)),
    VisionBatch: VisionBatch(5, 0.05, ("chaser0", "chaser1"), (
        encode(Vision(5, 0.05, "target0", "+x", "features", np.full((6, 3), 0.1), (0, 1, 2, 3, 4, 5))),
        encode(Vision(5, 0.05, "target1", "+x", "features", np.zeros((0, 3)), ())),
    )),
    Estimate: Estimate(
        4, 0.04, [1.0, 2.0, 3.0], [0.0, 0.0, 0.0], Q, np.eye(9) * 1e-4, 0.01, 0.5, 0.0,
        {"range_accepted": 3, "range_rejected": 1},
    ),
    Guidance: Guidance(5, 0.05, "REORIENT", 0.25, 0.1, 0.3, 1.0, DECISION, "A22=0.5 > 0.4"),
    Command: Command(6, 0.06, np.zeros(10), "APPROACH", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
    CommandBatch: CommandBatch(("chaser0", "target0"), (
        encode(Command(6, 0.06, np.zeros(10), "APPROACH", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])),
        encode(Command(7, 0.07, np.zeros(10), "STATION", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])),
    )),
    Truth: Truth(7, 0.07, [1.0, 2.0, 1.0], [0.0, 0.0, 0.0], Q, [0.0, 0.0, 0.0]),
    TruthBatch: TruthBatch(
        7, 0.07, ("chaser0", "target0"), [[1.0, 2.0, 1.0], [0.0, 0.0, 0.0]], np.zeros((2, 3)), [Q, Q],
        np.zeros((2, 3)), [0.5, 0.0], (False, True), [0.0, 0.25],
    ),
    Bundle: Bundle(11, ("Imu", "Vision", "Imu", "Uwb"), (
        encode(Imu(10, 0.10, 0.01, [0.1, 0.2, 0.3], Q)),
        encode(Vision(11, 0.11, "target", "+x", "features", np.full((6, 3), 0.1), (0, 1, 2, 3, 4, 5))),
        encode(Imu(11, 0.11, 0.01, [0.1, 0.2, 0.3], Q)),
        encode(Uwb(10, 0.10, 1, 1.5)),
    )),
    Event: Event(0.08, "mode", {"from": "HOLD", "to": "APPROACH", "range_m": 1.0}),
    Clock: Clock(8, 0.08, "running", 42),
    Anchors: Anchors((0, 1, 2, 3), ANCHORS_MS),
    RunControl: RunControl("reset", 7),
    Fault: Fault("nlos_burst", 5.0, 12.5, None, 0.3),
    Gnss: Gnss(9, 0.2, [1.0, -2.0, 8.0], np.diag([1.0, 1.0, 2.25])),
    Rangefinder: Rangefinder(10, 0.1, 4.2, 0.03),
    Barometer: Barometer(11, 0.1, -3.25, 0.5),  # any offset: below the datum too
    Tdoa: Tdoa(12, 0.1, (0, 2, 7), (1, 5, 3), [0.25, -1.5, 0.0]),  # d_B - d_A: any sign
    TdoaBatch: TdoaBatch(12, 0.1, ("chaser0", "target0"), (
        encode(Tdoa(12, 0.1, (0, 2), (1, 5), [0.25, -1.5])),
        encode(Tdoa(12, 0.1)),  # a tag that heard nothing this slot: no rows, still a message
    )),
}  # fmt: skip

SILENT = logging.getLogger("tests.transport.silent")
SILENT.disabled = True  # the hypothesis tests drop thousands of messages on purpose


def wire(msg) -> dict:
    return msgpack.unpackb(encode(msg), raw=False)


def pack(obj) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def array_map(values, dtype="<f8", shape=None) -> dict:
    a = np.asarray(values, dtype=dtype)
    return {"dtype": dtype, "shape": list(a.shape if shape is None else shape), "data": a.tobytes()}


# ------------------------------------------------------------------------------------- strategies

finite = st.floats(-1e6, 1e6, allow_nan=False)
nonneg = st.floats(0.0, 1e6)
ticks = st.integers(0, 2**64 - 1)
times = st.floats(0.0, 1e7)
ids = st.from_regex(ID_PATTERN, fullmatch=True)


def vec(n: int):
    return arrays(np.float64, (n,), elements=finite)


quats = (
    arrays(np.float64, (4,), elements=st.floats(-1.0, 1.0))
    .filter(lambda q: np.linalg.norm(q) > 0.1)
    .map(lambda q: q / np.linalg.norm(q))
)


def _sym(a: np.ndarray) -> np.ndarray:
    p = a + a.T  # exactly symmetric: float addition commutes
    np.fill_diagonal(p, np.abs(np.diag(p)))
    return p


covs = arrays(np.float64, (9, 9), elements=st.floats(-1e3, 1e3)).map(_sym)


def marked(n_cols: int):
    return st.integers(1, MAX_ITEMS).flatmap(
        lambda n: st.tuples(
            arrays(np.float64, (n, n_cols), elements=finite),
            st.lists(st.integers(0, 2**31 - 1), min_size=n, max_size=n, unique=True).map(tuple),
        )
    )


def _depth(x) -> int:
    if isinstance(x, list):
        return 1 + max((_depth(v) for v in x), default=0)
    if isinstance(x, dict):
        return 1 + max((_depth(v) for v in x.values()), default=0)
    return 0


plain = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1) | finite | st.text(max_size=12),
    lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=8), c, max_size=4),
    max_leaves=16,
)
event_data = st.dictionaries(st.text(max_size=8), plain, max_size=5).filter(lambda d: _depth(d) <= 8)
decisions = st.fixed_dictionaries(
    {k: (st.none() | st.floats(0.0, 1.0)) if k in PROBS else nonneg for k in DECISION_KEYS}
)
counts = st.dictionaries(st.from_regex(r"[a-z_]{1,20}", fullmatch=True), ticks, max_size=10)


@st.composite
def visions(draw):
    kind = draw(st.sampled_from(msgs.VISION_KINDS))
    if kind == "pose":  # at most one pose: position, unit quaternion, a positive definite covariance
        data, marker_ids = np.zeros((0, msgs.POSE_LEN)), ()
        if draw(st.booleans()):
            sd = draw(arrays(np.float64, 6, elements=st.floats(1e-4, 1.0)))
            row = np.concatenate([draw(vec(3)), draw(quats), np.diag(sd**2).ravel()])
            data = row.reshape(1, -1)
            marker_ids = tuple(draw(st.lists(st.integers(0, 2**31 - 1), min_size=1, max_size=4, unique=True)))
    else:
        data, marker_ids = draw(marked(3 if kind == "features" else 2))
    face = draw(st.sampled_from(msgs.FACES))
    return Vision(draw(ticks), draw(times), draw(ids), face, kind, data, marker_ids)


@st.composite
def imu_batches(draw):
    vids = tuple(draw(st.lists(ids, min_size=1, max_size=8, unique=True)))
    n = len(vids)
    ahrs = tuple(v for v in vids if draw(st.booleans()))
    q = np.array([draw(quats) for _ in ahrs]).reshape(len(ahrs), 4)
    acc = draw(st.none() | arrays(np.float64, (n, 3), elements=finite))
    gyro = draw(arrays(np.float64, (n, 3), elements=finite))
    return ImuBatch(draw(ticks), draw(times), draw(st.floats(1e-6, 10.0)), vids, gyro, ahrs, q, acc)


@st.composite
def vision_batches(draw):
    vids = tuple(draw(st.lists(ids, min_size=1, max_size=4, unique=True)))
    k, t = draw(ticks), draw(times)
    frames = tuple(encode(msgspec.structs.replace(draw(visions()), tick=k, t_s=t)) for _ in vids)
    return VisionBatch(k, t, vids, frames)


STRATEGIES_COMMAND = st.builds(
    Command,
    ticks,
    times,
    arrays(np.float64, st.integers(0, MAX_ITEMS), elements=finite),
    st.sampled_from(msgs.MODES),
    st.none() | vec(3),
    st.none() | vec(3),
)


@st.composite
def tdoas(draw, k=None, t=None):
    n = draw(st.integers(0, 12))
    a = draw(st.lists(st.integers(0, 2**31 - 1), min_size=n, max_size=n))
    b = [draw(st.integers(0, 2**31 - 1).filter(lambda x, y=y: x != y)) for y in a]
    dd = draw(arrays(np.float64, n, elements=finite))
    return Tdoa(draw(ticks) if k is None else k, draw(times) if t is None else t, tuple(a), tuple(b), dd)


@st.composite
def tdoa_batches(draw):
    vids = tuple(draw(st.lists(ids, min_size=1, max_size=4, unique=True)))
    k, t = draw(ticks), draw(times)
    return TdoaBatch(k, t, vids, tuple(encode(draw(tdoas(k, t))) for _ in vids))


STRATEGIES = {
    Tdoa: tdoas(),
    TdoaBatch: tdoa_batches(),
    Imu: st.builds(Imu, ticks, times, st.floats(1e-6, 10.0), vec(3), st.none() | quats, st.none() | vec(3)),
    ImuBatch: imu_batches(),
    Uwb: st.builds(Uwb, ticks, times, st.integers(0, 2**31 - 1), st.none() | nonneg),
    UwbBatch: st.lists(ids, min_size=1, max_size=8, unique=True).flatmap(
        lambda vids: st.builds(
            UwbBatch, ticks, times, st.just(tuple(vids)),
            st.lists(st.integers(0, 2**31 - 1), min_size=len(vids), max_size=len(vids)).map(tuple),
            st.lists(st.none() | nonneg, min_size=len(vids), max_size=len(vids)).map(tuple),
        )
    ),
    Vision: visions(),
    VisionBatch: vision_batches(),
    CommandBatch: st.lists(ids, min_size=1, max_size=4, unique=True).flatmap(
        lambda vids: st.builds(
            CommandBatch, st.just(tuple(vids)),
            st.lists(STRATEGIES_COMMAND.map(encode), min_size=len(vids), max_size=len(vids)).map(tuple),
        )
    ),
    Estimate: st.builds(
        Estimate, ticks, times, vec(3), vec(3), quats, covs, nonneg, nonneg, st.floats(0.0, 1.0), counts
    ),
    Guidance: st.builds(
        Guidance, ticks, times, st.sampled_from(msgs.MODES), st.none() | nonneg, st.none() | nonneg,
        st.none() | nonneg, st.none() | nonneg, st.none() | decisions, st.text(max_size=40),
    ),
    Command: STRATEGIES_COMMAND,
    Truth: st.builds(
        Truth, ticks, times, vec(3), vec(3), quats, vec(3), nonneg, st.booleans(), st.floats(0.0, 1.0)
    ),
    TruthBatch: st.lists(ids, min_size=1, max_size=8, unique=True).flatmap(
        lambda vids: st.builds(
            TruthBatch, ticks, times, st.just(tuple(vids)),
            *[arrays(np.float64, (len(vids), 3), elements=finite) for _ in range(2)],
            st.lists(quats, min_size=len(vids), max_size=len(vids)).map(np.array),
            arrays(np.float64, (len(vids), 3), elements=finite),
            arrays(np.float64, len(vids), elements=nonneg),
            st.lists(st.booleans(), min_size=len(vids), max_size=len(vids)).map(tuple),
            arrays(np.float64, len(vids), elements=st.floats(0.0, 1.0)),
        )
    ),
    Bundle: st.lists(
        st.sampled_from(("Imu", "Uwb")).flatmap(
            lambda name: st.builds(Imu if name == "Imu" else Uwb, st.integers(0, 10**6), times,
                                   *((st.floats(1e-6, 10.0), vec(3)) if name == "Imu" else
                                     (st.integers(0, 2**31 - 1), st.none() | nonneg)))
        ),
        min_size=1, max_size=12,
    ).flatmap(
        lambda msgs_: st.builds(
            Bundle, st.integers(max(m.tick for m in msgs_), 2**64 - 1),
            st.just(tuple(type(m).__name__ for m in msgs_)), st.just(tuple(encode(m) for m in msgs_)),
        )
    ),
    Event: st.builds(Event, times, st.from_regex(r"[a-z][a-z0-9_]{0,20}", fullmatch=True), event_data),
    Clock: st.builds(Clock, ticks, times, st.sampled_from(msgs.CLOCK_STATES), ticks),
    Anchors: marked(3).map(lambda m: Anchors(m[1], m[0])),
    Gnss: st.builds(Gnss, ticks, times, vec(3), covs.map(lambda c: c[0:3, 0:3])),
    Rangefinder: st.builds(Rangefinder, ticks, times, st.none() | nonneg, st.floats(1e-6, 1e3)),
    Barometer: st.builds(Barometer, ticks, times, st.none() | finite, st.floats(1e-6, 1e3)),
    RunControl: st.builds(RunControl, st.sampled_from(msgs.RUN_COMMANDS), st.none() | ticks),
    Fault: st.one_of(
        st.builds(Fault, st.sampled_from(("uwb_dropout", "camera_loss")), st.floats(1e-3, 1e3),
                  st.none() | times, st.none() | ids),
        st.builds(Fault, st.just("nlos_burst"), st.floats(1e-3, 1e3), st.none() | times, st.none(),
                  st.floats(1e-6, 1.0)),
        st.builds(Fault, st.just("gyro_bias_step"), st.none() | st.floats(1e-3, 1e3), st.none() | times,
                  st.none() | ids, st.none(), vec(3)),
        st.builds(Fault, st.just("sensor_delay"), st.floats(1e-3, 1e3), st.none() | times, st.none() | ids,
                  st.none(), st.none(), st.floats(1e-4, 10.0)),
    ),
}  # fmt: skip

ALL = list(VALID)


# --------------------------------------------------------------------------------------- round trips


def test_every_message_type_has_a_valid_example_and_a_strategy():
    assert set(VALID) == set(STRATEGIES) == set(MESSAGE_TYPES.values())


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.__name__)
@given(data=st.data())
def test_round_trip_gives_the_message_back(cls, data):
    msg = data.draw(STRATEGIES[cls])
    assert decode(encode(msg), cls) == msg


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.__name__)
@given(data=st.data())
def test_arrays_sent_as_plain_lists_decode_to_the_same_message(cls, data):
    msg = data.draw(STRATEGIES[cls])
    as_lists = {"v": SCHEMA_VERSION, "type": cls.__name__}
    for f in msgspec.structs.fields(msg):
        value = getattr(msg, f.name)
        as_lists[f.name] = value.tolist() if isinstance(value, np.ndarray) else value
    assert decode(pack(as_lists), cls) == msg


def test_wire_map_has_version_type_and_raw_little_endian_arrays():
    w = wire(Imu(3, 0.03, 0.01, [0.01, -0.02, 0.0]))
    assert w["v"] == SCHEMA_VERSION and w["type"] == "Imu"
    assert w["gyro_body"] == {
        "dtype": "<f8",
        "shape": [3],
        "data": np.array([0.01, -0.02, 0.0], "<f8").tobytes(),
    }
    assert w["q_ahrs_nav_body"] is None


@pytest.mark.parametrize("dtype", ["<f8", ">f8", "<f4", ">f4", "<f2", "<i4", ">i2", "<u8", "|u1", "|i1"])
def test_any_int_or_float_dtype_and_byte_order_decodes_to_float64(dtype):
    w = wire(VALID[Truth])
    w["p_nav"] = array_map([1, 2, 3], dtype)
    p = decode(pack(w), Truth).p_nav
    assert p.dtype == np.float64 and p.tolist() == [1.0, 2.0, 3.0]


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.__name__)
def test_decoded_arrays_are_writable_float64_copies(cls):
    payload = encode(VALID[cls])
    msg = decode(payload, cls)
    for f in msgspec.structs.fields(msg):
        a = getattr(msg, f.name)
        if isinstance(a, np.ndarray):
            assert a.dtype == np.float64 and a.flags.writeable and a.flags.owndata, f.name
            a[...] = 0.0  # would raise on a frombuffer view
    assert decode(payload, cls) == VALID[cls]  # the payload is untouched


def test_unknown_keys_are_ignored_for_forward_compatibility():
    w = wire(VALID[Estimate])
    w["innovation_nis"] = [1.0, 2.0]
    w["future"] = {"nested": True}
    assert decode(pack(w), Estimate) == VALID[Estimate]


@pytest.mark.parametrize(
    "cls, field, default",
    [(Imu, "q_ahrs_nav_body", None), (Uwb, "range_m", None), (Guidance, "decision", None),
     (Guidance, "reason", ""), (Event, "data", {}), (RunControl, "seed", None)],
)  # fmt: skip
def test_a_field_with_a_default_may_be_left_out(cls, field, default):
    w = wire(VALID[cls])
    del w[field]
    assert getattr(decode(pack(w), cls), field) == default


def test_lost_uwb_reply_is_a_null_range():
    assert decode(encode(Uwb(10, 0.1, 2, None)), Uwb).range_m is None


def test_payload_may_be_bytearray_memoryview_or_have_bytes_method():
    class FakeZBytes:  # like zenoh.ZBytes
        def __init__(self, b: bytes) -> None:
            self.b = b

        def __bytes__(self) -> bytes:
            return self.b

    b = encode(VALID[Uwb])
    for payload in (bytearray(b), memoryview(b), FakeZBytes(b)):
        assert decode(payload, Uwb) == VALID[Uwb]


# ---------------------------------------------------------------------------------------- validation

DELETE = object()
TOO_DEEP: dict = {}
_node = TOO_DEEP
for _ in range(8):
    _node["x"] = {}
    _node = _node["x"]

# (class, field path, bad value, expected start of the error message); DELETE removes the key
CASES = [
    (Tdoa, "ddist_m", [0.25, NAN, 0.0], "ddist_m: not finite"),
    (Tdoa, "ddist_m", array_map([0.25, INF, 0.0]), "ddist_m: not finite"),
    (Tdoa, "ddist_m", [0.25, -1.5], "ddist_m: 2 entries for 3 in anchor_a"),
    (Tdoa, "ddist_m", [[0.25], [-1.5], [0.0]], "ddist_m: nested deeper"),
    (Tdoa, "ddist_m", DELETE, "ddist_m: 0 entries for 3 in anchor_a"),  # (a default: no rows)
    (Tdoa, "anchor_a", [0, 2], "anchor_b: 3 entries for 2 in anchor_a"),
    (Tdoa, "anchor_a", [0, -2, 7], "anchor_a[1]: must be >= 0"),
    (Tdoa, "anchor_a", [0, 2**31, 7], "anchor_a[1]: must be <="),
    (Tdoa, "anchor_a", [0, 2.0, 7], "anchor_a[1]: expected an integer"),
    (Tdoa, "anchor_a", [0, True, 7], "anchor_a[1]: expected an integer"),
    (Tdoa, "anchor_a", "027", "anchor_a: expected an array"),
    (Tdoa, "anchor_b", [1, 5], "anchor_b: 2 entries for 3 in anchor_a"),
    (Tdoa, "anchor_b", [1, 2, 3], "anchor_b[1]: the same anchor as anchor_a[1] (2)"),
    (Tdoa, "anchor_b", [1, None, 3], "anchor_b[1]: expected an integer"),
    (Tdoa, "tick", -1, "tick: must be >= 0"),
    (Tdoa, "t_s", NAN, "t_s: not finite"),
    (TdoaBatch, "ids", ["chaser0"], "differences: 2 entries for 1 ids"),
    (TdoaBatch, "ids", ["chaser0", "chaser0"], "ids: duplicate ids"),
    (TdoaBatch, "differences", [b"\x80", "text"], "differences[1]: expected the bytes of a Tdoa message"),
    (TdoaBatch, "tick", -1, "tick: must be >= 0"),
    (Rangefinder, "range_m", -0.1, "range_m: must be >= 0"),
    (Rangefinder, "range_m", NAN, "range_m: not finite"),
    (Rangefinder, "sigma_m", 0.0, "sigma_m: must be > 0"),
    (Rangefinder, "sigma_m", DELETE, "sigma_m: missing"),
    (Barometer, "height_m", NAN, "height_m: not finite"),
    (Barometer, "height_m", INF, "height_m: not finite"),
    (Barometer, "height_m", "92.5", "height_m: expected a number or nil"),
    (Barometer, "height_m", DELETE, "height_m: missing"),
    (Barometer, "sigma_m", 0.0, "sigma_m: must be > 0"),
    (Barometer, "sigma_m", None, "sigma_m: expected a number"),
    (Barometer, "t_s", -0.1, "t_s: must be >= 0"),
    (Imu, "tick", -1, "tick: must be >= 0, got -1"),
    (Imu, "tick", 1.5, "tick: expected an integer"),
    (Imu, "tick", True, "tick: expected an integer"),
    (Imu, "tick", DELETE, "tick: missing"),
    (Imu, "t_s", NAN, "t_s: not finite"),
    (Imu, "t_s", INF, "t_s: not finite"),
    (Imu, "t_s", -0.5, "t_s: must be >= 0"),
    (Imu, "t_s", "0.1", "t_s: expected a number"),
    (Imu, "dt_s", 0.0, "dt_s: must be > 0"),
    (Imu, "dt_s", -0.01, "dt_s: must be > 0"),
    (Imu, "gyro_body", [1.0, 2.0, 3.0, 4.0], "gyro_body: expected shape (3,), got (4,)"),
    (Imu, "gyro_body", array_map([1.0, 2.0, 3.0, 4.0]), "gyro_body: expected shape (3,), got (4,)"),
    (Imu, "gyro_body", [[1.0, 2.0, 3.0]], "gyro_body: nested deeper"),
    (Imu, "gyro_body", [1.0, NAN, 3.0], "gyro_body: not finite"),
    (Imu, "gyro_body", array_map([1.0, INF, 3.0]), "gyro_body: not finite"),
    (Imu, "gyro_body", ["a", "b", "c"], "gyro_body: expected 1-level nested arrays of numbers"),
    (Imu, "gyro_body", [True, 0, 0], "gyro_body: expected 1-level nested arrays of numbers"),
    (Imu, "gyro_body", None, "gyro_body: expected an array"),
    (Imu, "gyro_body", DELETE, "gyro_body: missing"),
    (Imu, "gyro_body", {"dtype": "<c16", "shape": [3], "data": bytes(48)}, "gyro_body.dtype:"),
    (Imu, "gyro_body", {"dtype": "|O", "shape": [3], "data": bytes(24)}, "gyro_body.dtype:"),
    (Imu, "gyro_body", {"dtype": "f8", "shape": [3], "data": bytes(24)}, "gyro_body.dtype:"),
    (Imu, "gyro_body", {"dtype": "<f8", "shape": [3], "data": bytes(16)}, "gyro_body.data: 16 bytes"),
    (Imu, "gyro_body", {"dtype": "<f8", "shape": [3], "data": "abc"}, "gyro_body.data: expected bin"),
    (Imu, "gyro_body", {"dtype": "<f8", "shape": [-3], "data": bytes(24)}, "gyro_body.shape:"),
    (Imu, "gyro_body", {"dtype": "<f8", "shape": [1, 1, 3], "data": bytes(24)}, "gyro_body.shape:"),
    (Imu, "gyro_body", {"dtype": "<f8", "shape": [3]}, "gyro_body: an array map needs"),
    (Imu, "q_ahrs_nav_body", [0.0, 0.0, 0.0, 2.0], "q_ahrs_nav_body: norm 2 is not within 0.001 of 1"),
    (Imu, "q_ahrs_nav_body", [0.0, 0.0, 0.0, 0.998], "q_ahrs_nav_body: norm 0.998"),
    (Imu, "q_ahrs_nav_body", [0.0, 0.0, INF, 1.0], "q_ahrs_nav_body: not finite"),
    (Uwb, "anchor_id", -1, "anchor_id: must be >= 0"),
    (Uwb, "anchor_id", 2**31, "anchor_id: must be <="),
    (Uwb, "range_m", -0.1, "range_m: must be >= 0"),
    (Uwb, "range_m", INF, "range_m: not finite"),
    (Uwb, "range_m", "far", "range_m: expected a number or nil"),
    (Vision, "kind", "depth", "kind: expected one of ('features', 'pixels', 'pose')"),
    (Vision, "face", "+w", "face: expected one of"),
    (Vision, "target_id", "a/b", "target_id: must match"),
    (Vision, "target_id", 7, "target_id: expected a string"),
    (Vision, "data", np.ones((6, 2)).tolist(), "data: expected shape (N, 3), got (6, 2)"),
    (Vision, "data", [], "marker_ids: 6 ids for 0 rows"),
    (Vision, "data", [1.0, 2.0, 3.0], "data: expected 2-level nested arrays of numbers"),
    (Vision, "marker_ids", [0, 1, 2], "marker_ids: 3 ids for 6 rows"),
    (Vision, "marker_ids", [0, 0, 1, 2, 3, 4], "marker_ids: duplicate ids"),
    (Vision, "marker_ids", [-1, 1, 2, 3, 4, 5], "marker_ids[0]: must be >= 0"),
    (Vision, "marker_ids", [], "marker_ids: 0 ids for 6 rows"),
    (Vision, "marker_ids", "012345", "marker_ids: expected an array of integers"),
    (Estimate, "cov", (np.eye(9) + np.triu(np.ones((9, 9)), 1) * 1e-3).tolist(), "cov: not symmetric"),
    (Estimate, "cov", (-np.eye(9)).tolist(), "cov: negative diagonal entry -1 at index 0"),
    (Estimate, "cov", np.eye(6).tolist(), "cov: expected shape (9, 9), got (6, 6)"),
    (Estimate, "p_nav", [1.0, 2.0], "p_nav: expected shape (3,), got (2,)"),
    (Estimate, "v_nav", [0.0, NAN, 0.0], "v_nav: not finite"),
    (Estimate, "q_nav_body", [0.0, 0.0, 0.0, 0.0], "q_nav_body: norm 0"),
    (Estimate, "rejection_fraction", 1.5, "rejection_fraction: must be in [0, 1]"),
    (Estimate, "sigma_pos_max_m", -1.0, "sigma_pos_max_m: must be >= 0"),
    (Estimate, "mahalanobis_d", NAN, "mahalanobis_d: not finite"),
    (Estimate, "counts", {"range_accepted": -1}, "counts.range_accepted: must be >= 0"),
    (Estimate, "counts", {"range_accepted": 1.0}, "counts.range_accepted: expected an integer"),
    (Estimate, "counts", [1], "counts: expected a map"),
    (Estimate, "counts", {"bad key!": 1}, "counts key: must match"),
    (Estimate, "counts", {f"k{i}": 0 for i in range(MAX_ITEMS + 1)}, "counts: 65 entries, more than the 64"),
    (Guidance, "mode", "FLY", "mode: expected one of"),
    (Guidance, "mode", "approach", "mode: expected one of"),
    (Guidance, "range_m", -1.0, "range_m: must be >= 0"),
    (Guidance, "r1_m", NAN, "r1_m: not finite"),
    (Guidance, "decision", "x", "decision: expected a map or nil"),
    (Guidance, "decision.A11", 2.0, "decision.A11: a probability must be in [0, 1]"),
    (Guidance, "decision.A11", -0.5, "decision.A11: must be >= 0"),
    (Guidance, "decision.r_m", None, "decision.r_m: expected a number, got None"),
    (Guidance, "decision.pi2", NAN, "decision.pi2: not finite"),
    (Guidance, "decision.A22", DELETE, "decision.A22: missing"),
    (Guidance, "reason", 123, "reason: expected a string"),
    (Guidance, "reason", "x" * 1025, "reason: 1025 characters, more than the 1024"),
    (Command, "actuators", [float("nan")] + [0.0] * 9, "actuators: not finite"),
    (Command, "actuators", [0.0] * (MAX_ITEMS + 1), "actuators: 65 rows, more than the 64 allowed"),
    (Truth, "nlos_probability", 1.5, "nlos_probability: must be in [0, 1], got 1.5"),
    (Truth, "uwb_lost", 1, "uwb_lost: expected true or false, got 1"),
    (Command, "force_body_n", [0.0, 0.0], "force_body_n: expected shape (3,), got (2,)"),
    (Command, "torque_body_nm", [0.0, 0.0, NAN], "torque_body_nm: not finite"),
    (Command, "mode", "approach", "mode: expected one of"),
    (Truth, "q_nav_body", [1.0, 1.0, 0.0, 0.0], "q_nav_body: norm 1.41421"),
    (Truth, "w_body", [0.0, 0.0, INF], "w_body: not finite"),
    (Event, "kind", "", "kind: must match"),
    (Event, "kind", "Mode", "kind: must match"),
    (Event, "t_s", -1.0, "t_s: must be >= 0"),
    (Event, "data", [1, 2], "data: expected a map"),
    (Event, "data", {"x": NAN}, "data.x: not finite"),
    (Event, "data", {"a": {"b": [1.0, INF]}}, "data.a.b[1]: not finite"),
    (Event, "data", {"b": b"raw"}, "data.b: unsupported value"),
    (Event, "data", TOO_DEEP, "data.x.x.x.x.x.x.x.x: nested deeper than 8"),
    (ImuBatch, "ids", [], "ids: 0 entries, expected 1 to 256"),
    (ImuBatch, "ids", ["chaser0", "target0", "chaser0"], "ids: duplicate ids"),
    (ImuBatch, "ids", ["chaser0", "target/0", "chaser1"], "ids[1]: must match"),
    (ImuBatch, "ids", ["chaser0", 7, "chaser1"], "ids[1]: expected a string"),
    (ImuBatch, "ids", "chaser0", "ids: expected an array of vehicle ids"),
    (ImuBatch, "ids", ["chaser0", "target0"], "gyro_body: 3 rows for 2 ids"),
    (ImuBatch, "ids", [f"v{i}" for i in range(257)], "ids: 257 entries, expected 1 to 256"),
    (ImuBatch, "gyro_body", [[0.1, NAN, 0.3]] * 3, "gyro_body: not finite"),
    (ImuBatch, "gyro_body", [[0.1, 0.2]] * 3, "gyro_body: expected shape (N, 3), got (3, 2)"),
    (ImuBatch, "ahrs_ids", ["ghost"], "ahrs_ids: ['ghost'] not among ids"),
    (ImuBatch, "ahrs_ids", [], "q_ahrs_nav_body: 1 rows for 0 ahrs_ids"),
    (ImuBatch, "q_ahrs_nav_body", [[0.0, 0.0, 0.0, 2.0]], "q_ahrs_nav_body[0]: norm 2 is not within 0.001"),
    (ImuBatch, "q_ahrs_nav_body", [[0.0, 0.0, INF, 1.0]], "q_ahrs_nav_body: not finite"),
    (ImuBatch, "acc_body", [[0.0, 0.0, 9.8]] * 2, "acc_body: 2 rows for 3 ids"),
    (ImuBatch, "dt_s", 0.0, "dt_s: must be > 0"),
    (CommandBatch, "ids", [], "ids: 0 entries, expected 1 to 256"),
    (CommandBatch, "ids", ["chaser0", "chaser0"], "ids: duplicate ids"),
    (CommandBatch, "ids", ["chaser0"], "commands: 2 entries for 1 ids"),
    (CommandBatch, "ids", [[], "target0"], "ids[0]: expected a string"),  # unhashable: no cache lookup
    (CommandBatch, "commands", [b"\x80", 7], "commands[1]: expected the bytes of a Command message"),
    (VisionBatch, "ids", [], "ids: 0 entries, expected 1 to 256"),
    (VisionBatch, "ids", ["chaser0", "chaser0"], "ids: duplicate ids"),
    (VisionBatch, "ids", ["chaser0"], "frames: 2 entries for 1 ids"),
    (VisionBatch, "frames", "raw", "frames: expected an array"),
    (VisionBatch, "frames", [b"\x80", "text"], "frames[1]: expected the bytes of a Vision message"),
    (VisionBatch, "frames", [b"\x80", None], "frames[1]: expected the bytes of a Vision message"),
    (VisionBatch, "tick", -1, "tick: must be >= 0"),
    (VisionBatch, "t_s", NAN, "t_s: not finite"),
    (TruthBatch, "ids", ["chaser0"], "p_nav: expected shape (1, 3), got (2, 3)"),
    (TruthBatch, "ids", ["chaser0", "chaser0"], "ids: duplicate ids"),
    (TruthBatch, "q_nav_body", [Q, [0.0, 0.0, 0.0, 2.0]], "q_nav_body[1]: norm 2 is not within 0.001"),
    (TruthBatch, "p_nav", [[1.0, NAN, 1.0], [0.0, 0.0, 0.0]], "p_nav: not finite"),
    (TruthBatch, "effort", [0.5, -1.0], "effort[1]: must be >= 0"),
    (TruthBatch, "effort", [0.5], "effort: expected shape (2,), got (1,)"),
    (TruthBatch, "nlos_probability", [0.0, 1.5], "nlos_probability[1]: must be in [0, 1]"),
    (TruthBatch, "uwb_lost", [False], "uwb_lost: 1 entries for 2 ids"),
    (TruthBatch, "uwb_lost", [False, 1], "uwb_lost[1]: expected true or false, got 1"),
    (UwbBatch, "ids", [], "ids: 0 entries, expected 1 to 256"),
    (UwbBatch, "ids", ["chaser0", "chaser0", "chaser1"], "ids: duplicate ids"),
    (UwbBatch, "anchor_ids", [1, 0], "anchor_ids: 2 entries for 3 ids"),
    (UwbBatch, "anchor_ids", [1, -1, 3], "anchor_ids[1]: must be >= 0"),
    (UwbBatch, "anchor_ids", [1, True, 3], "anchor_ids[1]: expected an integer"),
    (UwbBatch, "anchor_ids", 7, "anchor_ids: expected an array"),
    (UwbBatch, "range_m", [1.5, None], "range_m: 2 entries for 3 ids"),
    (UwbBatch, "range_m", [1.5, NAN, 2.0], "range_m[1]: not finite"),
    (UwbBatch, "range_m", [1.5, None, INF], "range_m[2]: not finite"),
    (UwbBatch, "range_m", [1.5, -0.1, 2.0], "range_m[1]: must be >= 0"),
    (UwbBatch, "range_m", [1.5, "2", 2.0], "range_m[1]: expected a number"),
    (Clock, "state", "flying", "state: expected one of ('running', 'paused', 'stopped')"),
    (Clock, "seed", -1, "seed: must be >= 0"),
    (Clock, "seed", 1.0, "seed: expected an integer"),
    (Anchors, "anchor_ids", [0, 1, 2], "positions_nav: 4 rows for 3 anchor ids"),
    (Anchors, "anchor_ids", [0, 0, 1, 2], "anchor_ids: duplicate ids"),
    (Anchors, "positions_nav", [[1.0, 2.0]] * 4, "positions_nav: expected shape (N, 3), got (4, 2)"),
    (RunControl, "command", "explode", "command: expected one of ('pause', 'resume', 'reset', 'new_seed')"),
    (RunControl, "seed", -1, "seed: must be >= 0"),
]  # fmt: skip


def _mutated(base: dict, path: str, bad) -> dict:
    out = dict(base)
    head, _, sub = path.partition(".")
    if sub:
        out[head] = _mutated(out[head], sub, bad)
    elif bad is DELETE:
        del out[head]
    else:
        out[head] = bad
    return out


def _case_id(case) -> str:
    return f"{case[0].__name__}.{case[1]}={str(case[2])[:20]}"


@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_decoding_a_bad_field_raises_message_error_naming_it(case):
    cls, path, bad, expected = case
    payload = pack(_mutated(wire(VALID[cls]), path, bad))
    with pytest.raises(MessageError) as exc:
        decode(payload, cls)
    assert str(exc.value).startswith(expected), str(exc.value)


@pytest.mark.parametrize("case", [c for c in CASES if c[2] is not DELETE], ids=_case_id)
def test_building_a_bad_message_in_python_raises_the_same_error(case):
    cls, path, bad, expected = case
    kwargs = {f.name: getattr(VALID[cls], f.name) for f in msgspec.structs.fields(cls)}
    with pytest.raises(MessageError) as exc:
        cls(**_mutated(kwargs, path, bad))
    assert str(exc.value).startswith(expected), str(exc.value)


def test_more_than_64_markers_are_refused():
    w = wire(VALID[Vision])
    w["data"], w["marker_ids"] = np.zeros((MAX_ITEMS + 1, 3)).tolist(), list(range(MAX_ITEMS + 1))
    with pytest.raises(MessageError, match=r"^data: 65 rows, more than the 64 allowed"):
        decode(pack(w), Vision)


def test_64_markers_are_accepted():
    w = wire(VALID[Vision])
    w["data"], w["marker_ids"] = np.zeros((MAX_ITEMS, 3)).tolist(), list(range(MAX_ITEMS))
    assert decode(pack(w), Vision).data.shape == (MAX_ITEMS, 3)


def test_pixels_need_two_columns():
    w = wire(VALID[Vision])
    w["kind"] = "pixels"
    with pytest.raises(MessageError, match=r"^data: expected shape \(N, 2\), got \(6, 3\)"):
        decode(pack(w), Vision)


def test_covariance_asymmetry_within_the_relative_tolerance_is_accepted():
    p = np.eye(9)
    p[0, 1] = 1e-12  # 1e-12 <= 1e-9 * max|P| = 1e-9
    kwargs = {f.name: getattr(VALID[Estimate], f.name) for f in msgspec.structs.fields(Estimate)}
    assert Estimate(**{**kwargs, "cov": p}).cov[0, 1] == 1e-12


def test_quaternion_norm_within_tolerance_is_accepted_as_sent():
    q = [0.0, 0.0, 0.0, 1.0009]
    assert decode(encode(Truth(0, 0.0, [0, 0, 0], [0, 0, 0], q, [0, 0, 0])), Truth).q_nav_body[3] == 1.0009


@pytest.mark.parametrize(
    "mutate, expected",
    [
        (lambda w: {**w, "v": 7}, "v: unsupported schema version 7"),
        (lambda w: {**w, "v": "1"}, "v: unsupported schema version '1'"),
        (lambda w: {**w, "v": True}, "v: unsupported schema version True"),
        (lambda w: {k: x for k, x in w.items() if k != "v"}, "v: missing"),
        (lambda w: {**w, "type": "Uwb"}, "type: expected 'Imu', got 'Uwb'"),
        (lambda w: {k: x for k, x in w.items() if k != "type"}, "type: expected 'Imu', got None"),
        (lambda w: [w], "payload: not a msgpack map"),
        (lambda w: 3, "payload: not a msgpack map"),
    ],
)
def test_envelope_errors_name_version_type_or_payload(mutate, expected):
    with pytest.raises(MessageError) as exc:
        decode(pack(mutate(wire(VALID[Imu]))), Imu)
    assert str(exc.value).startswith(expected), str(exc.value)


def test_wrong_message_type_is_refused():
    with pytest.raises(MessageError, match=r"^type: expected 'Imu', got 'Uwb'"):
        decode(encode(VALID[Uwb]), Imu)


@pytest.mark.parametrize(
    "payload",
    [b"", b"\xc1", b"\x81\xa1", encode(Uwb(2, 0.02, 1, 1.5)) + b"\x00", b"\x81\x01\x02", b"\x81\xa1\xff\x01"],
    ids=["empty", "reserved-byte", "truncated", "trailing-bytes", "int-map-key", "bad-utf8"],
)
def test_bytes_that_are_not_msgpack_are_a_message_error(payload):
    with pytest.raises(MessageError, match=r"^payload: not valid msgpack"):
        decode(payload, Uwb)


def test_payload_over_64_kib_is_refused_before_unpacking():
    w = wire(VALID[Event])
    w["padding"] = "x" * MAX_PAYLOAD_BYTES
    with pytest.raises(MessageError, match=r"^payload: \d+ bytes, more than the 65536 allowed"):
        decode(pack(w), Event)


def test_encoding_a_message_over_64_kib_is_refused():
    with pytest.raises(MessageError, match=r"^payload: \d+ bytes, more than the 65536 allowed"):
        encode(Event(0.0, "log", {"text": "x" * MAX_PAYLOAD_BYTES}))


def test_a_payload_that_is_not_bytes_is_a_message_error():
    with pytest.raises(MessageError, match=r"^payload: expected bytes, got int"):
        decode(5, Uwb)


def test_encode_refuses_what_is_not_a_message():
    with pytest.raises(TypeError):
        encode({"v": 1})  # type: ignore[arg-type]


def test_building_from_numpy_scalars_and_enums_gives_plain_python_values():
    from swarm.core.guidance import Mode

    g = Guidance(np.int64(3), np.float32(0.5), Mode.ALIGN)
    assert type(g.tick) is int and type(g.t_s) is float and type(g.mode) is str and g.mode == "ALIGN"
    e = Event(0.0, "mode", {"k": np.int64(2), "x": np.float64(0.5), "a": np.arange(2.0), "b": np.bool_(True)})
    assert e.data == {"k": 2, "x": 0.5, "a": [0.0, 1.0], "b": True}
    assert decode(encode(e), Event) == e


# ------------------------------------------------------------------------------------- safe_decode


@settings(max_examples=examples(300))
@given(st.binary(max_size=512), st.sampled_from(ALL))
def test_arbitrary_bytes_never_raise_from_safe_decode_and_are_counted(payload, cls):
    counter = DropCounter(logger=SILENT)
    assert safe_decode(payload, cls, "tpods/agent/a/x", counter) is None
    assert counter.count("tpods/agent/a/x") == 1


msgpack_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1) | st.floats() | st.text(max_size=10)
    | st.binary(max_size=10),
    lambda c: st.lists(c, max_size=5) | st.dictionaries(st.text(max_size=10), c, max_size=5),
    max_leaves=20,
)  # fmt: skip


@settings(max_examples=examples(300))
@given(msgpack_values, st.sampled_from(ALL))
def test_arbitrary_msgpack_structures_are_dropped_and_counted(obj, cls):
    counter = DropCounter(logger=SILENT)
    assert safe_decode(pack(obj), cls, "k", counter) is None
    assert counter.total == 1


@st.composite
def envelopes(draw):
    """The right ``v`` and ``type`` with arbitrary values for some of the fields: mostly invalid."""
    cls = draw(st.sampled_from(ALL))
    names = [f.name for f in msgspec.structs.fields(cls)]
    body = draw(st.fixed_dictionaries({}, optional={n: msgpack_values for n in names}))
    return cls, {"v": SCHEMA_VERSION, "type": cls.__name__, **body}


@settings(max_examples=examples(300), suppress_health_check=[HealthCheck.too_slow])
@given(envelopes())
def test_well_formed_envelopes_with_arbitrary_fields_decode_or_are_counted(case):
    cls, obj = case
    counter = DropCounter(logger=SILENT)
    msg = safe_decode(pack(obj), cls, "k", counter)
    if msg is None:
        assert counter.count("k") == 1
    else:  # the fields happened to be valid: then it is a real message
        assert isinstance(msg, cls) and counter.total == 0 and decode(encode(msg), cls) == msg


def test_safe_decode_returns_the_message_when_valid_and_counts_nothing():
    counter = DropCounter(logger=SILENT)
    assert safe_decode(encode(VALID[Clock]), Clock, "k", counter) == VALID[Clock]
    assert counter.counts() == {}


def test_safe_decode_counts_an_unexpected_exception_instead_of_raising(monkeypatch):
    def broken(payload, expected):
        raise RuntimeError("codec bug")

    monkeypatch.setattr(msgs, "decode", broken)
    counter = DropCounter(logger=SILENT)
    assert safe_decode(encode(VALID[Clock]), Clock, "k", counter) is None
    assert counter.count("k") == 1


def test_safe_decode_logs_the_reason_naming_key_and_field(caplog):
    w = wire(VALID[Imu])
    w["gyro_body"] = [0.0, NAN, 0.0]
    with caplog.at_level(logging.WARNING, logger="swarm.transport.messages"):
        safe_decode(pack(w), Imu, "tpods/agent/a/imu", DropCounter())
    assert "tpods/agent/a/imu" in caplog.text and "gyro_body: not finite" in caplog.text


# ------------------------------------------------------------------------------------- DropCounter


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_drop_counter_logs_at_most_once_per_key_per_interval(caplog):
    clock = FakeClock()
    log = logging.getLogger("tests.transport.drops")
    counter = DropCounter(log_interval_s=10.0, logger=log, clock=clock)
    with caplog.at_level(logging.WARNING, logger=log.name):
        for t, reason in [(0.0, "r0"), (1.0, "r1"), (2.0, "r2"), (10.5, "r3")]:
            clock.t = t
            counter.drop("k", reason)
        counter.drop("other", "q0")  # another key has its own interval
    lines = [r.getMessage() for r in caplog.records]
    assert lines == [
        "dropped 1 invalid message on k (total 1); last: r0",
        "dropped 3 invalid messages on k (total 4); last: r3",
        "dropped 1 invalid message on other (total 1); last: q0",
    ]
    assert counter.counts() == {"k": 4, "other": 1} and counter.total == 5


def test_drop_counter_flush_reports_pending_drops_once(caplog):
    clock = FakeClock()
    log = logging.getLogger("tests.transport.flush")
    counter = DropCounter(log_interval_s=10.0, logger=log, clock=clock)
    with caplog.at_level(logging.WARNING, logger=log.name):
        counter.drop("k", "a")
        counter.drop("k", "b")
        counter.flush()
        counter.flush()
    assert [r.getMessage() for r in caplog.records] == [
        "dropped 1 invalid message on k (total 1); last: a",
        "dropped 1 invalid message on k (total 2); last: b",
    ]


def test_drop_counter_is_thread_safe():
    counter = DropCounter(logger=SILENT)

    def work(i: int) -> None:
        for _ in range(2000):
            counter.drop(f"k{i % 4}", "x")

    threads = [threading.Thread(target=work, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert counter.counts() == {f"k{i}": 4000 for i in range(4)}


def test_drop_counter_bounds_the_number_of_keys_it_tracks():
    counter = DropCounter(logger=SILENT, max_keys=2)
    for i in range(5):
        counter.drop(f"k{i}", "x")
    assert counter.counts() == {"k0": 1, "k1": 1, DropCounter.OTHER: 3}


@pytest.mark.parametrize("kwargs", [{"log_interval_s": 0.0}, {"log_interval_s": NAN}, {"max_keys": 0}])
def test_drop_counter_refuses_bad_settings(kwargs):
    with pytest.raises(ConfigError, match=r"^transport\."):
        DropCounter(**kwargs)


# ----------------------------------------------------------------------------- contract with the core


def test_mirrored_modes_and_faces_agree_with_the_core():
    from swarm.core.camera import FACES
    from swarm.core.guidance import Mode
    from swarm.core.landing import LandingMode

    assert msgs.DOCKING_MODES == tuple(m.value for m in Mode)
    assert msgs.LANDING_MODES == tuple(m.value for m in LandingMode)
    assert set(msgs.MODES) == set(msgs.DOCKING_MODES) | set(msgs.LANDING_MODES)
    assert msgs.FACES == FACES


def test_a_real_decision_record_passes_validation():
    from swarm.core.mdp import MdpSwitcher

    sw = MdpSwitcher()
    dec = sw.evaluate(t_s=1.0, r_m=0.5, d=0.3, qe_vec_norm=0.2, sigma_pos_max_m=0.01)
    g = Guidance(1, 1.0, "APPROACH", 0.5, sw.r1_m, sw.r2_m, 1.0, dec.as_dict(diagnostics=True), dec.reason)
    assert set(g.decision) == set(DECISION_KEYS) and decode(encode(g), Guidance) == g


def test_every_key_kind_maps_to_a_message():
    from swarm.transport.keys import AGENT_KINDS

    assert set(MESSAGE_FOR_KIND) == {
        *AGENT_KINDS,
        "world_clock",
        "world_event",
        "world_vision",
        "world_imu",
        "anchors",
        "mothership_uwb",
        "mothership_tdoa",
        "world_truth",
        "world_bundle",
        "run_control",
        "fault",
    }


def test_the_codec_does_not_import_zenoh_or_the_heavy_core():
    code = "import sys, swarm.transport; print(sorted({'zenoh', 'scipy', 'cv2', 'numba'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_protocol_doc_byte_example_is_what_the_codec_writes():
    doc = (Path(__file__).parents[2] / "docs" / "protocol.md").read_text()
    block = re.search(r"<!-- imu-example-hex -->\s*```\n(.*?)```", doc, re.S)
    assert block is not None, "docs/protocol.md lost its byte-level example"
    hex_bytes = "".join(re.sub(r"#.*", "", line) for line in block.group(1).splitlines())
    assert bytes.fromhex(hex_bytes) == encode(Imu(3, 0.03, 0.01, [0.01, -0.02, 0.0]))


def test_a_vision_frame_without_markers_round_trips_from_lists_and_arrays():
    """A camera reports every frame; one in which nothing was detected has zero rows (lockstep needs it)."""
    for data in ([], np.zeros((0, 3))):
        msg = Vision(4, 0.04, target_id="target", face="+x", kind="features", data=data, marker_ids=[])
        back = decode(encode(msg), Vision)
        assert back == msg and back.data.shape == (0, 3) and not back.seen
    seen = Vision(4, 0.04, "target", "+x", "pixels", np.ones((1, 2)), (3,))
    assert seen.seen


def test_truth_carries_the_effort_and_refuses_a_negative_one():
    t = Truth(1, 0.01, np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3), effort=0.25)
    assert decode(encode(t), Truth).effort == 0.25
    with pytest.raises(MessageError, match="effort: must be >= 0"):
        Truth(1, 0.01, np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3), effort=-1.0)


def _pose_row(cov=None) -> list[float]:
    cov = np.diag([1e-6, 1e-6, 4e-6, 1e-4, 1e-4, 1e-4]) if cov is None else np.asarray(cov)
    return [0.01, -0.02, 0.3, *Q, *cov.ravel()]


@pytest.mark.parametrize(("data", "ids", "expected"), [
    ([_pose_row(), _pose_row()], (0, 1), "data: a pose frame holds at most one pose, got 2 rows"),
    ([_pose_row()], (), "marker_ids: 0 ids for 1 poses"),
    ([], (3,), "marker_ids: 1 ids for 0 poses"),
    ([_pose_row()[:42]], (0,), "data: expected shape (N, 43), got (1, 42)"),
    ([_pose_row(np.diag([1e-6, 1e-6, -4e-6, 1e-4, 1e-4, 1e-4]))], (0,), "data: a pose's covariance"),
    ([_pose_row(np.eye(6) + np.triu(np.ones((6, 6)), 1) * 0.1)], (0,), "data: a pose's covariance"),
    ([_pose_row(np.ones((6, 6)))], (0,), "data: a pose's covariance (columns 7-42) is not positive definite"),
])  # fmt: skip
def test_a_bad_pose_frame_is_refused_on_the_wire_and_in_python(data, ids, expected):
    """A pose frame feeds the filter a measurement and its covariance: one pose at most, its markers named,
    and a covariance the filter can invert (symmetric, positive definite), or the frame is dropped."""
    arr = np.asarray(data, dtype=float).reshape(len(data), len(data[0]) if data else msgs.POSE_LEN)
    with pytest.raises(MessageError) as exc:
        Vision(3, 0.05, "target", "+x", "pose", arr, ids)
    assert str(exc.value).startswith(expected), str(exc.value)
    good = wire(Vision(3, 0.05, "target", "+x", "pose", np.asarray([_pose_row()]), (0, 1)))
    good["data"], good["marker_ids"] = [list(map(float, r)) for r in data], list(ids)
    with pytest.raises(MessageError) as exc:
        decode(pack(good), Vision)
    assert str(exc.value).startswith(expected), str(exc.value)


# ------------------------------------------------------------------------- plain msgpack, the fast path


def _plain_fields(obj: dict, cls) -> dict:
    """The fields of a message decoded with plain ``msgpack`` and numpy, as any client would."""
    out = {}
    for f in msgspec.structs.fields(cls):
        value = obj[f.name]
        if isinstance(value, dict) and set(value) == {"dtype", "shape", "data"}:
            value = np.frombuffer(value["data"], value["dtype"]).reshape(value["shape"])
        out[f.name] = value
    return out


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.__name__)
@given(data=st.data())
def test_every_message_type_decodes_with_plain_msgpack(cls, data):
    msg = data.draw(STRATEGIES[cls])
    obj = msgpack.unpackb(encode(msg), raw=False)
    assert obj["v"] == SCHEMA_VERSION and obj["type"] == cls.__name__
    plain = _plain_fields(obj, cls)
    for f in msgspec.structs.fields(cls):
        mine, theirs = getattr(msg, f.name), plain[f.name]
        if isinstance(mine, np.ndarray):
            assert isinstance(theirs, np.ndarray) and np.array_equal(mine, theirs), f.name
        elif isinstance(mine, tuple):
            assert theirs == list(mine), f.name
        else:
            assert theirs == mine and type(theirs) is type(mine), f.name
    assert cls(**plain) == msg  # and the plain decoding builds the same message


FAST = ALL  # msgspec decodes every message: its declaration is its decoder


@pytest.mark.parametrize("cls", FAST, ids=lambda c: c.__name__)
@settings(suppress_health_check=[HealthCheck.too_slow])  # (the Tdoa and batch strategies draw a lot)
@given(data=st.data())
def test_the_fast_path_takes_every_message_this_codec_writes(cls, data):
    msg = data.draw(STRATEGIES[cls])
    fast = msgs._decode_fast(encode(msg), cls)
    assert fast is not None and fast == msg


# values at the edges of the checks: the fast path must refuse (leave to the reference) what the reference
# refuses, so every field is replaced by values either side of its limits
edge_values = st.sampled_from(
    [None, True, False, 0, -1, 1, 2**63, 2**64 - 1, 0.0, -0.0, -1e-300, 1.0, 1.0 + 1e-9, 1e308, math.nan,
     math.inf, -math.inf, "", "x", "+x", "APPROACH", "running", "pose", "features", "a" * 65, [], [0, 0],
     [1, 2, 3], {}, b"\x00"]
)  # fmt: skip


@st.composite
def arrays_at_edges(draw, shape=None):
    """An array map, mostly of ``shape`` (the field's own) and our dtype, with values at the checks' edges."""
    if shape is None or draw(st.integers(0, 4)) == 0:
        shape = draw(st.sampled_from([[3], [4], [9, 9], [0, 3], [1, 43], [2, 2], [10], [65], [4, 3]]))
    n = math.prod(shape)
    edge = st.sampled_from([0.0, 1.0, -1.0, 0.5, math.nan, math.inf, -math.inf, 1e308])
    a = np.array(draw(st.lists(edge, min_size=n, max_size=n)), "<f8").reshape(shape)
    if shape == [4] and draw(st.booleans()):
        a = np.array([0.0, 0.0, 0.0, draw(st.sampled_from([1.0, 1.0005, 1.002, -1.0, math.nan]))])
    if shape == [9, 9] and draw(st.booleans()):
        a = np.eye(9) * draw(st.sampled_from([1.0, -1.0, 0.0, math.nan]))
        a[0, 1] += draw(st.sampled_from([0.0, 1e-12, 1e-3]))
    data = a.tobytes()
    if draw(st.integers(0, 4)) == 0:
        data = data[: draw(st.integers(0, len(data)))]
    dtype = "<f8" if draw(st.integers(0, 4)) else draw(st.sampled_from([">f8", "<f4", "<i8"]))
    return {"dtype": dtype, "shape": shape, "data": data}


@st.composite
def mutated(draw):
    cls = draw(st.sampled_from(FAST))
    obj = wire(draw(STRATEGIES[cls]))
    for name in draw(st.lists(st.sampled_from([f.name for f in msgspec.structs.fields(cls)] + ["v", "type"]),
                              min_size=1, max_size=3)):  # fmt: skip
        old = obj.get(name)
        shape = old["shape"] if isinstance(old, dict) and "shape" in old else None  # an array field's
        choice = draw(st.integers(0, 3))
        if choice == 0:
            obj.pop(name, None)
        elif choice == 1 or shape is not None:
            obj[name] = draw(arrays_at_edges(shape))
        else:
            obj[name] = draw(edge_values | msgpack_values)
    return cls, obj


@settings(max_examples=examples(1000), suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_the_fast_path_never_accepts_what_the_reference_refuses(case):
    """The fast path (msgspec) only ever takes a payload the reference checks accept, to the same message;
    everything else is left to the reference, whose error names the field."""
    cls, obj = case
    payload = pack(obj)
    _left_to_the_reference_unless_it_agrees(msgs._decode_fast(payload, cls), payload, cls)


def _left_to_the_reference_unless_it_agrees(fast, payload: bytes, cls):
    """The fast path's ``fast`` decoding of ``payload``: ``None`` (left to the reference) where the reference
    refuses it, else ``None`` or the reference's own message; the reference's message (or ``None``)."""
    try:
        reference = msgs._decode_reference(payload, cls)
    except MessageError:
        assert fast is None
        return None
    assert fast is None or fast == reference
    return reference


@st.composite
def estimates_at_edges(draw):
    """An estimate's payload, its arrays (and a few other fields) at the checks' edges or left as written."""
    msg = draw(STRATEGIES[Estimate])
    obj = wire(msg)
    for name in draw(st.lists(st.sampled_from(["p_nav", "v_nav", "q_nav_body", "cov", "t_s"]), max_size=3)):
        old = obj.get(name)
        shape = old["shape"] if isinstance(old, dict) and "shape" in old else None
        obj[name] = draw(arrays_at_edges(shape)) if shape is not None else draw(edge_values)
    return msg, obj


@pytest.fixture(scope="module")
def compiled_checks():
    """The compiled covariance check, loaded (numba: ~0.4 s the first time, outside hypothesis' deadline)."""
    declared.load_compiled()
    return declared._COV_KERNEL


@pytest.mark.parametrize("compiled", [False, True], ids=["numpy checks", "compiled checks"])
@settings(max_examples=examples(400), suppress_health_check=[HealthCheck.too_slow])
@given(case=estimates_at_edges())
def test_an_estimate_decodes_the_same_with_the_compiled_covariance_check_or_without(
    compiled_checks, compiled, case
):
    """A process that encodes estimates has the compiled covariance check loaded (``_codec_nb``), and its
    decoder then checks an estimate's covariance in one call (a chaser decodes its target's on its imu's
    path); one that never encodes (a viewer) keeps numpy's checks. Either way the fast path takes exactly
    what the reference accepts, to the same message, and leaves the rest to it."""
    msg, obj = case
    payload = pack(obj)
    try:
        declared._COV_KERNEL = compiled_checks if compiled else None
        fast = msgs._decode_fast(payload, Estimate)
    finally:
        declared._COV_KERNEL = compiled_checks
    reference = _left_to_the_reference_unless_it_agrees(fast, payload, Estimate)
    if reference is not None and obj == wire(msg):  # as written: the fast path takes it
        assert fast == msg


def test_with_the_compiled_check_loaded_a_plain_covariance_skips_numpys(monkeypatch):
    """The compiled check, not numpy's, decides a plain covariance once loaded (else the test above would
    test one path twice); numpy's still decides one it does not call plain (here: off symmetry)."""
    rng = np.random.default_rng(3)
    args = _estimate_args(rng)
    payload = msgs.encode_estimate(*args)  # (loads the compiled check)
    assert declared._COV_KERNEL is not None
    with monkeypatch.context() as m:
        m.setattr(declared, "check_covariance", lambda p, name: pytest.fail("numpy's covariance check ran"))
        got = msgs._decode_fast(payload, Estimate)
    assert got is not None and np.array_equal(got.cov, args[5]) and got.tick == args[0]
    obj = msgpack.unpackb(payload)
    cov = np.frombuffer(obj["cov"]["data"], "<f8").reshape(9, 9).copy()
    cov[0, 1] += 1.0  # not symmetric: refused, by the reference's own error
    obj["cov"]["data"] = cov.tobytes()
    assert msgs._decode_fast(pack(obj), Estimate) is None
    with pytest.raises(MessageError, match="cov: not symmetric"):
        msgs._decode_reference(pack(obj), Estimate)


# ------------------------------------------------------------------------------ encode_estimate


def _estimate_args(rng):
    a = rng.normal(size=(9, 9))
    cov = a @ a.T
    q = rng.normal(size=4)
    counts = {"range_accepted": int(rng.integers(0, 99)), "features_refused": 0}
    return [int(rng.integers(0, 10**6)), float(rng.uniform(0, 100)), rng.normal(size=3), rng.normal(size=3),
            q / np.linalg.norm(q), cov, float(rng.uniform(0, 1)), float(rng.uniform(0, 5)),
            float(rng.uniform(0, 1)), counts]  # fmt: skip


def _same_as(fast, reference, args):
    """``fast(*args)``'s bytes, or the error it raises, against ``encode(reference(*args))``: a sender fast
    path (``encode_estimate``, ...) against the message's own checks and encoding."""
    try:
        want = encode(reference(*args))
    except MessageError as exc:
        with pytest.raises(MessageError) as got:
            fast(*args)
        assert str(got.value) == str(exc)
        return None
    assert fast(*args) == want
    return want


def _same(args):
    """encode_estimate against ``encode(estimate_message(...))``."""
    return _same_as(msgs.encode_estimate, msgs.estimate_message, args)


def _through_the_fast_path(monkeypatch, fast, reference, make, rng, n=200):
    """``n`` seeded cases of ``make(rng)``, each given the message's bytes by ``fast``, and the sender's
    arrays left as they were (the fast path checks them without a copy, and must not change them)."""
    for _ in range(n):
        args = make(rng)
        before = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
        assert _same_as(fast, reference, args) is not None
        for a, b in zip(args, before, strict=True):
            assert not isinstance(a, np.ndarray) or np.array_equal(a, b)


def _decided_as_the_message(fast, reference, make, rng, variants, accepted):
    """Each variant (a change to a fresh ``make(rng)``) gives the message's bytes or its error through
    ``fast``; the message accepts exactly the variants named in ``accepted``."""
    outcomes = {}
    for name, change in variants.items():
        args = make(rng)
        change(args)
        outcomes[name] = _same_as(fast, reference, args) is not None
    assert outcomes == {name: name in accepted for name in variants}


def test_encode_estimate_gives_the_bytes_and_the_errors_of_the_message_encode(monkeypatch):
    """Oracle: ``encode(estimate_message(...))``, the reference path it replaces on the agent's hot path."""
    rng = np.random.default_rng(7)
    _through_the_fast_path(monkeypatch, msgs.encode_estimate, msgs.estimate_message, _estimate_args, rng)
    variants = {
        "covariance off symmetry by rounding": lambda a: a.__setitem__(5, a[5] + np.triu(1e-12 * a[5], 1)),
        "covariance not symmetric": lambda a: a.__setitem__(5, a[5] + np.triu(np.ones((9, 9)), 1)),
        "negative variance": lambda a: a[5].__setitem__((2, 2), -1.0),
        "NaN position": lambda a: a[2].__setitem__(1, np.nan),
        "infinite covariance": lambda a: a[5].__setitem__((0, 1), np.inf),
        "not a unit quaternion": lambda a: a.__setitem__(4, a[4] * 1.01),
        "quaternion of 3": lambda a: a.__setitem__(4, a[4][:3]),
        "float32 position": lambda a: a.__setitem__(2, a[2].astype(np.float32)),
        "list velocity": lambda a: a.__setitem__(3, [0.0, 1.0, 2.0]),
        "numpy tick": lambda a: a.__setitem__(0, np.int64(5)),
        "negative tick": lambda a: a.__setitem__(0, -1),
        "numpy sigma": lambda a: a.__setitem__(6, np.float64(0.25)),
        "negative time": lambda a: a.__setitem__(1, -0.5),
        "rejection fraction above 1": lambda a: a.__setitem__(8, 1.5),
        "NaN distance": lambda a: a.__setitem__(7, float("nan")),
        "bool sigma": lambda a: a.__setitem__(6, True),
        "counter key with a slash": lambda a: a[9].__setitem__("a/b", 1),
        "negative counter": lambda a: a[9].__setitem__("x", -2),
        "float counter": lambda a: a[9].__setitem__("x", 2.0),
    }  # fmt: skip
    # the variants the message accepts, and those it refuses, each as the reference path decides (it
    # publishes the symmetric part of any covariance that is not symmetric, estimate_message)
    accepted = ("covariance off symmetry by rounding", "covariance not symmetric", "float32 position",
                "list velocity", "numpy tick", "numpy sigma")  # fmt: skip
    _decided_as_the_message(
        msgs.encode_estimate, msgs.estimate_message, _estimate_args, rng, variants, accepted
    )


def test_estimate_and_payload_gives_what_a_receiver_decodes():
    """An agent host hands a target's estimate to its chaser as ``estimate_and_payload``'s message instead of
    decoding the bytes it sends: every field must be what decoding those bytes gives, and the arrays must be
    copies the sender's filter cannot change afterwards."""
    from swarm.transport.messages import estimate_and_payload

    rng = np.random.default_rng(8)
    cases = [_estimate_args(rng) for _ in range(100)]
    skewed = _estimate_args(rng)
    skewed[5] = skewed[5] + np.triu(1e-12 * skewed[5], 1)  # published as its symmetric part
    cases += [
        skewed,
        [*_estimate_args(rng)[:3], [0.0, 1.0, 2.0], *_estimate_args(rng)[4:]],
    ]  # a list: reference
    for args in cases:
        msg, payload = estimate_and_payload(*args)
        assert payload == _same(args)
        want = decode(payload, Estimate)
        for f in msgspec.structs.fields(Estimate):
            got, exp = getattr(msg, f.name), getattr(want, f.name)
            if isinstance(exp, np.ndarray):
                assert got.dtype == exp.dtype and got.shape == exp.shape and np.array_equal(got, exp), f.name
            else:
                assert type(got) is type(exp) and got == exp, f.name
        for i in (2, 3, 4, 5):
            if isinstance(args[i], np.ndarray):
                args[i][...] = 9.0  # the sender's arrays move on; the message keeps what was sent
        assert decode(payload, Estimate).p_nav.tolist() == msg.p_nav.tolist()
    with pytest.raises(MessageError, match="p_nav"):
        estimate_and_payload(*_estimate_args(rng)[:2], np.array([np.nan, 0.0, 0.0]), *_estimate_args(rng)[3:])


# ------------------------------------------------------------------------------ encode_command


def _command_args(rng):
    n = int(rng.integers(0, 12))
    force, torque = (None, None) if rng.uniform() < 0.3 else (rng.normal(size=3), rng.normal(size=3))
    mode = str(rng.choice(["HOLD", "APPROACH", "DOCK", "STATION"]))
    return [int(rng.integers(0, 10**6)), float(rng.uniform(0, 100)), np.abs(rng.normal(size=n)), mode,
            force, torque]  # fmt: skip


def test_encode_command_gives_the_bytes_and_the_errors_of_the_message_encode(monkeypatch):
    """Oracle: ``encode(Command(...))``, the reference path it replaces on the agent's hot path."""
    rng = np.random.default_rng(11)
    _through_the_fast_path(monkeypatch, msgs.encode_command, msgs.Command, _command_args, rng)
    variants = {
        "NaN actuator": lambda a: a.__setitem__(2, np.append(a[2], np.nan)),
        "infinite force": lambda a: a.__setitem__(4, np.array([np.inf, 0.0, 0.0])),
        "NaN torque": lambda a: a.__setitem__(5, np.array([0.0, np.nan, 0.0])),
        "force of 2": lambda a: a.__setitem__(4, np.zeros(2)),
        "actuators of 2 x 2": lambda a: a.__setitem__(2, np.zeros((2, 2))),
        "too many actuators": lambda a: a.__setitem__(2, np.zeros(msgs.MAX_ITEMS + 1)),
        "unknown mode": lambda a: a.__setitem__(3, "WARP"),
        "mode not a string": lambda a: a.__setitem__(3, 3),
        "negative time": lambda a: a.__setitem__(1, -0.5),
        "NaN time": lambda a: a.__setitem__(1, float("nan")),
        "negative tick": lambda a: a.__setitem__(0, -1),
        "bool tick": lambda a: a.__setitem__(0, True),
        "float tick": lambda a: a.__setitem__(0, 2.0),
        "numpy tick": lambda a: a.__setitem__(0, np.int64(5)),
        "int time": lambda a: a.__setitem__(1, 3),
        "float32 actuators": lambda a: a.__setitem__(2, np.ones(4, dtype=np.float32)),
        "list actuators": lambda a: a.__setitem__(2, [1.0, 2.0]),
        "integer force": lambda a: a.__setitem__(4, np.array([1, 2, 3])),
        "strided actuators": lambda a: a.__setitem__(2, np.arange(8.0)[::2]),
    }  # fmt: skip
    accepted = ("numpy tick", "int time", "float32 actuators", "list actuators", "integer force",
                "strided actuators")  # fmt: skip
    _decided_as_the_message(msgs.encode_command, msgs.Command, _command_args, rng, variants, accepted)


# ------------------------------------------------------------------------------ encode_imu, encode_truth


def _unit(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def _imu_args(rng):
    has_q, has_acc = rng.uniform() < 0.5, rng.uniform() < 0.3
    q, acc = (_unit(rng) if has_q else None), (rng.normal(size=3) if has_acc else None)
    return [int(rng.integers(0, 10**6)), float(rng.uniform(0, 100)), float(rng.uniform(1e-3, 0.1)),
            rng.normal(size=3), q, acc]  # fmt: skip


def _truth_args(rng):
    return [int(rng.integers(0, 10**6)), float(rng.uniform(0, 100)), rng.normal(size=3), rng.normal(size=3),
            _unit(rng), rng.normal(size=3), float(rng.uniform(0, 50)), bool(rng.uniform() < 0.2),
            float(rng.uniform(0, 1))]  # fmt: skip


def test_encode_imu_and_truth_give_the_bytes_and_the_errors_of_the_message_encode(monkeypatch):
    """Oracle: ``encode(Imu(...))`` and ``encode(Truth(...))``, the reference paths they replace on the
    world's hot path. Every seeded case goes through the fast path (the module's ``encode``, their fallback,
    raises meanwhile); each variant is decided as the message decides."""
    from swarm.transport.messages import encode_imu, encode_truth

    rng = np.random.default_rng(12)
    for fast, ref, make in ((encode_imu, Imu, _imu_args), (encode_truth, Truth, _truth_args)):
        _through_the_fast_path(monkeypatch, fast, ref, make, rng)
    q_edge = np.array([0.0, 0.0, 0.0, 1.0 + 0.9 * msgs.QUAT_NORM_TOL])  # the message's own check decides
    imu_variants = {
        "NaN gyro": (lambda a: a[3].__setitem__(1, np.nan), False),
        "infinite time": (lambda a: a.__setitem__(1, math.inf), False),
        "zero period": (lambda a: a.__setitem__(2, 0.0), False),
        "negative time": (lambda a: a.__setitem__(1, -1.0), False),
        "not a unit quaternion": (lambda a: a.__setitem__(4, np.array([0.0, 0.0, 0.0, 1.1])), False),
        "quaternion near the tolerance": (lambda a: a.__setitem__(4, q_edge), True),
        "NaN accelerometer": (lambda a: a.__setitem__(5, np.array([0.0, np.nan, 9.8])), False),
        "gyro of 4": (lambda a: a.__setitem__(3, np.zeros(4)), False),
        "bool tick": (lambda a: a.__setitem__(0, True), False),
        "numpy tick": (lambda a: a.__setitem__(0, np.int64(3)), True),
        "int period": (lambda a: a.__setitem__(2, 1), True),
        "list gyro": (lambda a: a.__setitem__(3, [0.0, 0.1, 0.2]), True),
        "float32 gyro": (lambda a: a.__setitem__(3, np.ones(3, dtype=np.float32)), True),
    }
    truth_variants = {
        "NaN position": (lambda a: a[2].__setitem__(0, np.nan), False),
        "infinite rate": (lambda a: a[5].__setitem__(2, -np.inf), False),
        "not a unit quaternion": (lambda a: a.__setitem__(4, a[4] * 1.01), False),
        "quaternion near the tolerance": (lambda a: a.__setitem__(4, q_edge), True),
        "negative effort": (lambda a: a.__setitem__(6, -0.5), False),
        "NLOS probability above 1": (lambda a: a.__setitem__(8, 1.5), False),
        "uwb_lost not a bool": (lambda a: a.__setitem__(7, 1), False),
        "numpy bool uwb_lost": (lambda a: a.__setitem__(7, np.bool_(True)), True),
        "int effort": (lambda a: a.__setitem__(6, 2), True),
        "velocity view of a state row": (lambda a: a.__setitem__(3, np.arange(13.0)[3:6]), True),
    }
    for fast, ref, make, variants in (
        (encode_imu, Imu, _imu_args, imu_variants),
        (encode_truth, Truth, _truth_args, truth_variants),
    ):
        changes = {name: change for name, (change, _) in variants.items()}
        accepted = [name for name, (_, ok) in variants.items() if ok]
        _decided_as_the_message(fast, ref, make, rng, changes, accepted)


def test_encode_vision_gives_the_bytes_and_the_errors_of_the_message_encode(monkeypatch):
    """Oracle: ``encode(Vision(...))``, the world's reference path for a camera frame; seeded frames of
    marker features and pixels (none to six markers) through the fast path, variants decided as the message
    decides (a pose always takes the message's checks)."""
    from swarm.transport.messages import encode_vision

    rng = np.random.default_rng(14)

    def args():
        kind = "features" if rng.uniform() < 0.7 else "pixels"
        n = int(rng.integers(0, 7))
        ids = tuple(int(i) for i in rng.permutation(8)[:n])
        face = str(rng.choice(msgs.FACES))
        data = rng.normal(size=(n, 3 if kind == "features" else 2))
        return [int(rng.integers(0, 10**6)), float(rng.uniform(0, 100)), "target3", face, kind, data, ids]

    _through_the_fast_path(monkeypatch, encode_vision, Vision, lambda _rng: args(), rng)
    pose = np.zeros((1, msgs.POSE_LEN))
    pose[0, 6], pose[0, 7:] = 1.0, np.eye(6).ravel()

    def six(a, value=None, i=None):  # six markers' features, then one field changed
        a[4], a[5], a[6] = "features", rng.normal(size=(6, 3)), (0, 1, 2, 3, 4, 5)
        if i is not None:
            a[i] = value

    variants = {
        "six markers": (six, True),
        "NaN marker": (lambda a: (six(a), a[5].__setitem__((2, 1), np.nan)), False),
        "infinite time": (lambda a: a.__setitem__(1, math.inf), False),
        "negative time": (lambda a: a.__setitem__(1, -0.5), False),
        "rows and ids apart": (lambda a: six(a, (0, 1, 2), 6), False),
        "duplicate ids": (lambda a: six(a, (0, 1, 2, 3, 4, 4), 6), False),
        "negative id": (lambda a: six(a, (0, 1, 2, 3, 4, -5), 6), False),
        "bool id": (lambda a: six(a, (0, 1, 2, 3, 4, True), 6), False),
        "numpy id": (lambda a: six(a, (0, 1, 2, 3, 4, np.int64(5)), 6), True),
        "ids as a list": (lambda a: six(a, [0, 1, 2, 3, 4, 5], 6), True),
        "pixels of 3 columns": (lambda a: six(a, "pixels", 4), False),
        "unknown kind": (lambda a: six(a, "lidar", 4), False),
        "unknown face": (lambda a: a.__setitem__(3, "+w"), False),
        "target id with a slash": (lambda a: a.__setitem__(2, "target/3"), False),
        "float32 markers": (lambda a: six(a, np.ones((6, 3), dtype=np.float32), 5), True),
        "a pose": (
            lambda a: (a.__setitem__(4, "pose"), a.__setitem__(5, pose), a.__setitem__(6, (0, 1))),
            True,
        ),
        "65 markers": (lambda a: (six(a, np.ones((65, 3)), 5), a.__setitem__(6, tuple(range(65)))), False),
        "numpy tick": (lambda a: a.__setitem__(0, np.int64(3)), True),
    }
    changes = {name: change for name, (change, _) in variants.items()}
    accepted = [name for name, (_, ok) in variants.items() if ok]
    _decided_as_the_message(encode_vision, Vision, lambda _rng: args(), rng, changes, accepted)


def test_encode_uwb_gives_the_bytes_and_the_errors_of_the_message_encode(monkeypatch):
    """Oracle: ``encode(Uwb(...))``, the mothership's reference path; seeded ranges (and lost ones) through
    the fast path, variants decided as the message decides."""
    from swarm.transport.messages import encode_uwb

    rng = np.random.default_rng(13)

    def args():
        r = None if rng.uniform() < 0.2 else float(rng.uniform(0, 30))
        return [int(rng.integers(0, 10**6)), float(rng.uniform(0, 100)), int(rng.integers(0, 8)), r]

    _through_the_fast_path(monkeypatch, encode_uwb, Uwb, lambda _rng: args(), rng)
    variants = {
        "negative range": (3, -0.1, False), "NaN range": (3, math.nan, False),
        "infinite range": (3, math.inf, False), "negative anchor": (2, -1, False),
        "huge anchor": (2, 2**40, False),
        "bool anchor": (2, True, False), "infinite time": (1, math.inf, False), "int range": (3, 2, True),
        "numpy range": (3, np.float64(2.5), True), "numpy anchor": (2, np.int64(1), True),
    }  # fmt: skip
    for name, (i, value, accepted) in variants.items():
        a = args()
        a[i] = value
        assert (_same_as(encode_uwb, Uwb, a) is not None) == accepted, name


# ----------------------------------------------------------------------------------------------- bundles


def test_a_bundle_gives_its_entries_in_order_and_drops_only_the_bad_ones():
    """A receiver takes a lockstep bundle's samples as their own keys would have brought them, in order; an
    entry that does not decode, claims another type or a tick after the bundle's is dropped, counted and
    named, and costs no other entry (docs/protocol.md, "Bundles")."""
    b = VALID[Bundle]
    drops = DropCounter(logger=SILENT)
    got = msgs.bundle_messages(b, "k", drops)
    assert [type(m).__name__ for m in got] == ["Imu", "Vision", "Imu", "Uwb"]
    assert got[1] == decode(b.entries[1], Vision) and got[3] == decode(b.entries[3], Uwb)
    assert drops.total == 0
    # a viewer takes the frames only
    assert [type(m) for m in msgs.bundle_messages(b, "k", drops, ("Vision",))] == [Vision]
    bad = Bundle(11, ("Imu", "Imu", "Uwb", "Imu"), (
        b.entries[0],
        b.entries[1],  # a Vision said to be an Imu
        encode(Uwb(12, 0.12, 1, 1.5)),  # after the bundle's tick
        encode(Imu(11, 0.11, 0.01, [0.1, 0.2, 0.3], Q))[:-3],  # cut short
    ))  # fmt: skip
    got = msgs.bundle_messages(bad, "tpods/agent/chaser/bundle", drops)
    assert got == [decode(b.entries[0], Imu)]
    assert drops.total == 3
    reasons = drops.counts()
    assert reasons == {"tpods/agent/chaser/bundle": 3}


@pytest.mark.parametrize(
    ("change", "error"),
    [
        (lambda w: w.__setitem__("types", ["Imu", "Estimate"]), "types[1]: expected one of Imu, Uwb, Vision"),
        (lambda w: w.__setitem__("types", []), "types: expected 1 to 256 message types"),
        (lambda w: w.__setitem__("entries", w["entries"][:1]), "entries: expected one per type (2)"),
        (lambda w: w["entries"].__setitem__(0, "text"), "entries[0]: expected the bytes of a wire message"),
        (lambda w: w.__setitem__("tick", -1), "tick: "),
    ],
)
def test_a_bad_bundle_is_refused_naming_the_field(change, error):
    w = wire(Bundle(3, ("Imu", "Uwb"), (encode(VALID[Imu]), encode(VALID[Uwb]))))
    change(w)
    with pytest.raises(MessageError) as got:
        decode(pack(w), Bundle)
    assert str(got.value).startswith(error)


def test_pack_bundle_splits_at_the_payload_limit_and_keeps_the_order():
    """The world's and the mothership's bundles: every entry once, in order, no message above
    :data:`MAX_PAYLOAD_BYTES` or :data:`MAX_BATCH` entries, each message's tick its newest entry's."""
    frame = encode(Vision(0, 0.0, "target", "+x", "features", np.full((60, 3), 0.5), tuple(range(60))))
    entries = []
    for k in range(1, 60):  # ~1.5 kB frames and imu: a few messages
        frame_k = Vision(k, k * 0.01, "target", "+x", "features", np.full((60, 3), 0.5), tuple(range(60)))
        entries.append(("Vision", encode(frame_k), k))
        entries.append(("Imu", encode(Imu(k, k * 0.01, 0.01, [0.1, 0.2, 0.3], Q)), k))
    assert len(frame) * 59 > MAX_PAYLOAD_BYTES  # (so that it must split)
    out = msgs.pack_bundle(entries)
    assert len(out) > 1 and all(len(p) <= MAX_PAYLOAD_BYTES for p in out)
    bundles = [decode(p, Bundle) for p in out]
    assert [e for b in bundles for e in b.entries] == [e for _, e, _ in entries]
    assert [n for b in bundles for n in b.types] == [n for n, _, _ in entries]
    for b in bundles:
        assert b.tick == max(m.tick for m in msgs.bundle_messages(b, "k", DropCounter(logger=SILENT)))
    many = [("Uwb", encode(Uwb(k, 0.01 * k, 1, 1.0)), k) for k in range(600)]
    assert [len(decode(p, Bundle).types) for p in msgs.pack_bundle(many)] == [256, 256, 88]


def _truth_batch_args(rng):
    n = int(rng.integers(1, 6))
    X = rng.normal(size=(n, 13))
    X[:, 6:10] = np.array([_unit(rng) for _ in range(n)])
    vids = tuple(f"v{i}" for i in range(n))
    msgs._vehicle_ids(vids, "ids", 1)  # (a world's id list is known after its first batch)
    return [int(rng.integers(0, 10**6)), float(rng.uniform(0, 100)), vids, X, rng.uniform(0, 5, size=n),
            bool(rng.uniform() < 0.2), float(rng.uniform(0, 1))]  # fmt: skip


def _truth_batch(k, t, vids, X, effort, lost, p_nlos):
    n = len(vids)
    x = np.asarray(X, dtype=np.float64)
    return TruthBatch(k, t, vids, x[:, 0:3], x[:, 3:6], x[:, 6:10], x[:, 10:13], effort, (lost,) * n,
                      np.full(n, p_nlos))  # fmt: skip


def test_encode_truth_batch_gives_the_bytes_and_the_errors_of_the_message_encode(monkeypatch):
    """Oracle: ``encode(TruthBatch(...))``, the world's reference path for a UWB slot's truths."""
    rng = np.random.default_rng(15)
    _through_the_fast_path(monkeypatch, msgs.encode_truth_batch, _truth_batch, _truth_batch_args, rng)
    variants = {
        "NaN position": (lambda a: a[3].__setitem__((0, 0), np.nan), False),
        "infinite rate": (lambda a: a[3].__setitem__((0, 12), np.inf), False),
        "not a unit quaternion": (lambda a: a[3].__setitem__((0, slice(6, 10)), [0.0, 0.0, 0.0, 1.1]), False),
        "negative effort": (lambda a: a[4].__setitem__(0, -0.5), False),
        "NLOS probability above 1": (lambda a: a.__setitem__(6, 1.5), False),
        "negative time": (lambda a: a.__setitem__(1, -1.0), False),
        "bad id": (lambda a: a.__setitem__(2, ("v 0", *a[2][1:])), False),
        "float32 state": (lambda a: a.__setitem__(3, a[3].astype(np.float32)), True),
        "numpy tick": (lambda a: a.__setitem__(0, np.int64(3)), True),
    }
    changes = {name: change for name, (change, _) in variants.items()}
    _decided_as_the_message(msgs.encode_truth_batch, _truth_batch, _truth_batch_args, rng, changes,
                            [name for name, (_, ok) in variants.items() if ok])  # fmt: skip


def test_the_next_runs_seed_is_the_one_asked_for_else_the_same_after_a_reset_and_the_next_otherwise():
    from swarm.transport.messages import NEW_RUN_COMMANDS, next_run_seed

    assert NEW_RUN_COMMANDS == ("reset", "new_seed")
    assert next_run_seed({"reason": "reset", "next_seed": None}, 4) == 4
    assert next_run_seed({"reason": "new_seed", "next_seed": None}, 4) == 5
    assert next_run_seed({"reason": "new_seed", "next_seed": 11}, 4) == 11
    assert next_run_seed({"reason": "reset", "next_seed": 0}, 4) == 0  # a seed 0 asked for is kept
    assert next_run_seed({"reason": "done"}, 4) == 5  # --repeat


# ------------------------------------------------------------------------------------------------ TDoA


def test_tdoa_rows_round_trip_bit_for_bit_and_no_rows_is_a_message():
    """The radio step's rows (K, 3) (anchor A, anchor B, d_B - d_A) come out of ``Tdoa.rows`` as they went
    into :func:`encode_tdoa`, bit for bit (launch == sim rests on it), and a slot with none is a message
    with no rows (so a lockstep agent knows not to wait)."""
    rng = np.random.default_rng(7)
    rows = np.column_stack([rng.integers(0, 8, 40), rng.integers(0, 8, 40), rng.normal(0.0, 1.0, 40)])
    rows = rows[rows[:, 0] != rows[:, 1]].astype(np.float64)
    got = decode(encode_tdoa(5, 0.05, rows), Tdoa)
    assert got.tick == 5 and got.anchor_a == tuple(int(a) for a in rows[:, 0])
    assert got.rows().tobytes() == rows.tobytes()
    empty = decode(encode_tdoa(6, 0.06, np.zeros((0, 3))), Tdoa)
    assert empty.anchor_a == () and empty.rows().shape == (0, 3)


def test_a_tdoa_row_with_a_fractional_anchor_is_refused():
    with pytest.raises(MessageError, match=r"^anchor_a\[0\]: expected an integer"):
        encode_tdoa(1, 0.0, np.array([[0.5, 1.0, 0.2]]))


def test_more_than_the_tdoa_row_cap_is_refused():
    n = msgs.MAX_TDOA_ROWS + 1
    with pytest.raises(MessageError, match=r"^anchor_a: 1025 entries, more than the 1024 allowed"):
        Tdoa(1, 0.0, (0,) * n, (1,) * n, np.zeros(n))


def test_a_tdoa_batch_entry_of_another_tick_is_refused_naming_it():
    batch = TdoaBatch(3, 0.03, ("a", "b"), (encode(Tdoa(3, 0.03)), encode(Tdoa(4, 0.04))))
    assert batch.sample("a") == Tdoa(3, 0.03)
    with pytest.raises(MessageError, match=r"^differences\[1\]: tick 4"):
        batch.sample("b")


def test_the_twr_range_bytes_are_unchanged_by_tdoa():
    """TDoA travels in its own message on its own key: a ``Uwb`` is the same bytes as before it."""
    assert encode(Uwb(2, 0.02, 1, 1.5)) == pack(
        {"v": SCHEMA_VERSION, "type": "Uwb", "tick": 2, "t_s": 0.02, "anchor_id": 1, "range_m": 1.5}
    )
