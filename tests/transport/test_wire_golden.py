"""Every message's bytes are those of the codec before the declared messages (issue 44, item 4).

Oracle: ``data/wire_golden.json``, the bytes that ``encode`` and the sender fast paths (``encode_imu``, ...)
wrote at commit cb3395a, before the messages became msgspec declarations, captured by this file's
``cases()`` and ``fast_cases()`` (hex). A change of any byte fails here: the protocol is unchanged unless
docs/protocol.md says why its version changes.
"""

from __future__ import annotations

import json
from pathlib import Path

import msgpack
import numpy as np
import pytest

from swarm.transport import messages as m

GOLDEN = json.loads((Path(__file__).parent / "data" / "wire_golden.json").read_text())
Q = np.array([0.0, 0.0, 0.0, 1.0])
QT = np.array([0.1, -0.2, 0.3, 0.9273618495495703])
COV9 = np.diag(np.arange(1.0, 10.0)) * 1e-3
COV9[0, 1] = COV9[1, 0] = 1e-4
DECISION = {k: (None if k in {"A32", "A33", "pi1", "pi2"} else 0.5) for k in m.DECISION_KEYS}
POSE = np.array([[0.01, -0.02, 0.3, *Q, *np.diag([1e-6, 1e-6, 4e-6, 1e-4, 1e-4, 1e-4]).ravel()]])


def cases():
    imu = m.encode(m.Imu(10, 0.1, 0.01, [0.1, 0.2, 0.3], Q))
    vis = m.encode(m.Vision(11, 0.11, "target", "+x", "features", np.full((2, 3), 0.5), (0, 1)))
    cmd = m.encode(m.Command(6, 0.06, np.arange(4.0), "APPROACH"))
    tdoa = m.encode(m.Tdoa(12, 0.1, (0, 2), (1, 5), [0.25, -1.5]))
    return {
        "Imu": m.Imu(3, 0.03, 0.01, [0.01, -0.02, 0.0]),
        "Imu_ahrs_acc": m.Imu(2**40, 12.5, 0.01, np.array([1e-3, -2e-3, 3.5]), QT, [0.0, 0.1, 9.81]),
        "Imu_numpy_scalars": m.Imu(np.int64(7), np.float64(0.07), np.float32(0.01), np.ones(3, np.float32)),
        "ImuBatch": m.ImuBatch(1, 0.01, 0.01, ("c0", "t0", "c1"), [[0.1, 0.2, 0.3]] * 3, ("t0",), [list(Q)]),
        "ImuBatch_acc": m.ImuBatch(1, 0.01, 0.01, ("c0",), [[0.1, 0.2, 0.3]], acc_body=[[0.0, 0.0, 9.8]]),
        "Uwb": m.Uwb(2, 0.02, 1, 1.5),
        "Uwb_lost": m.Uwb(300, 3.0, 2**31 - 1),
        "UwbBatch": m.UwbBatch(2, 0.02, ("c0", "t0", "c1"), (1, 0, 3), (1.5, None, 2.25)),
        "Tdoa": m.Tdoa(12, 0.1, (0, 2, 7), (1, 5, 3), [0.25, -1.5, 0.0]),
        "Tdoa_empty": m.Tdoa(12, 0.1),
        "TdoaBatch": m.TdoaBatch(12, 0.1, ("c0", "t0"), (tdoa, m.encode(m.Tdoa(12, 0.1)))),
        "Vision": m.Vision(3, 0.05, "target", "+x", "features", np.full((3, 3), 0.1), (0, 1, 2)),
        "Vision_pixels": m.Vision(3, 0.05, "pad-u0", "+z", "pixels", [[1.0, 2.0], [3.5, 4.0]], [0, 1]),
        "Vision_none": m.Vision(4, 0.04, "target", "-y", "features", [], []),
        "Vision_pose": m.Vision(5, 0.05, "target", "+x", "pose", POSE, (0, 1, 2)),
        "VisionBatch": m.VisionBatch(11, 0.11, ("c0",), (vis,)),
        "Gnss": m.Gnss(9, 0.2, [1.0, -2.0, 8.0], np.diag([1.0, 1.0, 2.25])),
        "Rangefinder": m.Rangefinder(10, 0.1, 4.2, 0.03),
        "Rangefinder_none": m.Rangefinder(10, 0.1, None, 0.03),
        "Barometer": m.Barometer(11, 0.1, -3.25, 0.5),
        "Estimate": m.Estimate(
            4,
            0.04,
            [1.0, 2.0, 3.0],
            [0.0, 0.5, 0.0],
            QT,
            COV9,
            0.01,
            0.5,
            0.25,
            {"range_accepted": 3, "range_rejected": 1},
        ),
        "Guidance": m.Guidance(5, 0.05, "REORIENT", 0.25, 0.1, 0.3, 1.0, DECISION, "A22=0.5 > 0.4"),
        "Guidance_bare": m.Guidance(5, 0.05, "STATION"),
        "Command": m.Command(6, 0.06, np.zeros(10), "APPROACH", [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]),
        "Command_ground": m.Command(6, 0.06, [1.0, 2.0, 3.0, 4.0], "CRUISE"),
        "CommandBatch": m.CommandBatch(("c0",), (cmd,)),
        "Truth": m.Truth(7, 0.07, [1.0, 2.0, 1.0], [0.0, 0.0, 0.0], QT, [0.0, 0.1, 0.0], 2.5, True, 0.25),
        "Truth_defaults": m.Truth(7, 0.07, [1.0, 2.0, 1.0], [0.0, 0.0, 0.0], Q, [0.0, 0.0, 0.0]),
        "TruthBatch": m.TruthBatch(
            7,
            0.07,
            ("c0", "t0"),
            [[1.0, 2.0, 1.0], [0.0, 0.0, 0.0]],
            np.zeros((2, 3)),
            np.array([Q, QT]),
            np.zeros((2, 3)),
            [0.5, 0.0],
            (False, True),
            [0.0, 0.25],
        ),
        "Bundle": m.Bundle(11, ("Imu", "Vision", "Uwb"), (imu, vis, m.encode(m.Uwb(10, 0.1, 1, 1.5)))),
        "Event": m.Event(0.08, "mode", {"from": "HOLD", "to": "APPROACH", "range_m": 1.0, "n": [1, None]}),
        "Event_empty": m.Event(0.0, "run_start"),
        "Clock": m.Clock(8, 0.08, "running", 2**64 - 1),
        "Anchors": m.Anchors((0, 1, 2), [[1.0, -0.2, 0.5], [1.0, 0.2, -0.5], [-1.0, 0.2, -0.5]]),
        "RunControl": m.RunControl("reset", 7),
        "RunControl_bare": m.RunControl("pause"),
        "Fault": m.Fault("nlos_burst", 5.0, 12.5, None, 0.3),
        "Fault_gyro": m.Fault("gyro_bias_step", rate_rad_s=[0.0, 0.01, 0.0], vehicle="chaser0"),
    }


def fast_cases():
    """The sender fast paths' bytes (encode_imu, ...), with plain and odd arguments."""
    x = np.arange(26.0).reshape(2, 13)
    x[:, 6:10] = [Q, QT]
    return {
        "encode_imu": m.encode_imu(5, 0.05, 0.01, np.full(3, 0.01), Q),
        "encode_imu_acc": m.encode_imu(5, 0.05, 0.01, np.full(3, 0.01), None, np.array([0.0, 0.0, 9.81])),
        "encode_imu_lists": m.encode_imu(5, 0.05, 0.01, [0.01, 0.02, 0.03]),
        "encode_uwb": m.encode_uwb(5, 0.05, 3, 2.5),
        "encode_uwb_lost": m.encode_uwb(5, 0.05, 3, None),
        "encode_vision": m.encode_vision(5, 0.05, "target", "+x", "features", np.ones((2, 3)), (0, 1)),
        "encode_vision_pose": m.encode_vision(5, 0.05, "target", "+x", "pose", POSE, (0,)),
        "encode_estimate": m.encode_estimate(
            5, 0.05, np.ones(3), np.ones(3), QT, COV9, 0.1, 1.0, 0.1, {"range_accepted": 5}
        ),
        "encode_estimate_asym": m.encode_estimate(
            5, 0.05, np.ones(3), np.ones(3), Q, COV9 + np.triu(np.full((9, 9), 1e-19), 1), 0.1, 1.0, 0.1, {}
        ),
        "encode_command": m.encode_command(5, 0.05, np.ones(10), "APPROACH", np.ones(3), np.ones(3)),
        "encode_command_bare": m.encode_command(5, 0.05, np.ones(4), "CRUISE"),
        "encode_truth": m.encode_truth(5, 0.05, np.ones(3), np.ones(3), QT, np.ones(3), 1.5, False, 0.0),
        "encode_truth_batch": m.encode_truth_batch(5, 0.05, ("c0", "t0"), x, np.array([0.5, 1.0]), True, 0.5),
        "encode_tdoa": m.encode_tdoa(5, 0.05, np.array([[0.0, 1.0, 0.25], [2.0, 3.0, -0.5]])),
    }


CASES, FAST = cases(), fast_cases()


def test_every_message_type_has_a_golden_case():
    assert {type(msg).__name__ for msg in CASES.values()} == set(m.MESSAGE_TYPES)
    assert set(GOLDEN) == set(CASES) | set(FAST)


@pytest.mark.parametrize("name", list(CASES))
def test_encode_writes_the_bytes_of_before(name):
    got = m.encode(CASES[name])
    assert got.hex() == GOLDEN[name], msgpack.unpackb(got)


@pytest.mark.parametrize("name", list(FAST))
def test_the_sender_fast_paths_write_the_bytes_of_before(name):
    assert FAST[name].hex() == GOLDEN[name], msgpack.unpackb(FAST[name])


@pytest.mark.parametrize("name", list(CASES))
def test_the_bytes_of_before_decode_to_the_same_message(name):
    msg = CASES[name]
    assert m.decode(bytes.fromhex(GOLDEN[name]), type(msg)) == msg
