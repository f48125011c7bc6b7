"""``swarm bench codec``: what one message of every tick costs to build, encode and decode (issue 13).

For each message type of the hot path (``swarm/transport/messages.py``): building it in Python (its
constructor's checks), :func:`~swarm.transport.messages.encode`, the sender's fast path where the world, the
mothership or an agent has one (``encode_imu``, ``encode_uwb``, ``encode_vision``, ``encode_estimate``,
``encode_command``, ``encode_truth``), and decoding its payload by the msgspec decoding (what every
receiver runs: the message's declaration is its decoder) and by the reference checks alone (what it runs for
a payload the msgspec decoding leaves to it). Times are medians of repeated blocks, so a burst of load on a
shared machine moves them less than a mean; the ratio of the two decodes is measured in one run.
"""

from __future__ import annotations

import time

import numpy as np

FULL = {"repeat": 7, "number": 2000}
QUICK = {"repeat": 3, "number": 300}


def examples() -> list:
    """One realistic message of each hot-path type (the docking chaser's sizes; the batches of agent hosts
    for a swarm of 32 vehicles, an AHRS tick's, its 16 chasers' frames each of six markers; a host of 16's
    commands of a round; a lockstep chaser's bundle of a control period)."""
    from swarm.core.decision_keys import DECISION_KEYS
    from swarm.transport import messages as m

    rng = np.random.default_rng(0)
    a = rng.normal(size=(9, 9))
    q = np.array([0.0, 0.0, 0.0, 1.0])
    counts = {"range_accepted": 5, "range_rejected": 1, "features_accepted": 2}
    ids = tuple(f"{kind}{i}" for i in range(16) for kind in ("chaser", "target"))
    return [
        m.Imu(5, 0.05, 0.01, np.full(3, 0.01), q),
        m.ImuBatch(5, 0.05, 0.01, ids, rng.normal(size=(32, 3)), ids, np.tile(q, (32, 1))),
        m.Uwb(5, 0.05, 3, 2.5),
        m.UwbBatch(5, 0.05, ids, tuple(i % 4 for i in range(32)), tuple(1.0 + 0.1 * i for i in range(32))),
        m.Vision(5, 0.05, "target", "+x", "features", rng.normal(size=(4, 3)), (0, 1, 2, 3)),
        m.VisionBatch(
            5,
            0.05,
            ids[::2],
            tuple(
                m.encode(
                    m.Vision(
                        5, 0.05, f"target{i}", "+x", "features", rng.normal(size=(6, 3)), tuple(range(6))
                    )
                )
                for i in range(16)
            ),
        ),
        m.Estimate(5, 0.05, np.ones(3), np.ones(3), q, a @ a.T, 0.1, 1.0, 0.1, counts),
        m.Guidance(5, 0.05, "APPROACH", 1.0, 0.5, 1.0, 2.0, dict.fromkeys(DECISION_KEYS, 0.5), "x" * 60),
        m.Command(5, 0.05, np.ones(10), "APPROACH", np.ones(3), np.ones(3)),
        m.CommandBatch(
            ids[:16],
            tuple(
                m.encode(m.Command(5, 0.05, np.ones(10), "APPROACH", np.ones(3), np.ones(3)))
                for _ in range(16)
            ),
        ),
        m.Truth(5, 0.05, np.ones(3), np.ones(3), q, np.ones(3)),
        m.TruthBatch(
            5,
            0.05,
            ids,
            np.ones((32, 3)),
            np.ones((32, 3)),
            np.tile(q, (32, 1)),
            np.ones((32, 3)),
            np.ones(32),
            (False,) * 32,
            np.zeros(32),
        ),
        m.Bundle(10, *_period(m, rng, q)),
        m.Clock(5, 0.05, "running", 3),
    ]


def _period(m, rng, q) -> tuple[tuple, tuple]:
    """A lockstep world's bundle of a control period for a chaser (docs/protocol.md, "Bundles"): the imu of
    ticks 1-10 and its camera frames of ticks 5 and 10 (each of six markers, before that tick's imu)."""
    types, entries = [], []
    for k in range(1, 11):
        if k % 5 == 0:
            markers = rng.normal(size=(6, 3))
            frame = m.Vision(k, 0.01 * k, "target", "+x", "features", markers, tuple(range(6)))
            types.append("Vision")
            entries.append(m.encode(frame))
        types.append("Imu")
        entries.append(m.encode(m.Imu(k, 0.01 * k, 0.01, np.full(3, 0.01), q)))
    return tuple(types), tuple(entries)


def fast_encoders() -> dict:
    """By message type, the sender fast path that the world or an agent runs every tick instead of
    ``encode(Message(...))`` (the same bytes, without building the message)."""
    from swarm.transport import messages as m

    return {"Imu": m.encode_imu, "Estimate": m.encode_estimate, "Command": m.encode_command,
            "Truth": m.encode_truth, "Uwb": m.encode_uwb, "Vision": m.encode_vision}  # fmt: skip


def _us(fn, repeat: int, number: int) -> float:
    blocks = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        blocks.append((time.perf_counter() - t0) / number)
    return float(np.median(blocks)) * 1e6


def run(preset: dict) -> dict:
    from swarm.transport import messages as m

    encoders = fast_encoders()
    rows = []
    for msg in examples():
        cls, payload = type(msg), m.encode(msg)
        kwargs = {name: getattr(msg, name) for name in msg.__struct_fields__}
        assert m._decode_fast(payload, cls) == msg  # the fast path takes it: what is timed is what runs
        r, n = preset["repeat"], preset["number"]
        fast = encoders.get(cls.__name__)
        if fast is not None:
            args = tuple(kwargs.values())
            assert fast(*args) == payload  # the sender's fast path gives these bytes
        rows.append({
            "type": cls.__name__,
            "bytes": len(payload),
            "build_us": _us(lambda c=cls, k=kwargs: c(**k), r, n),
            "encode_us": _us(lambda x=msg: m.encode(x), r, n),
            "decode_us": _us(lambda p=payload, c=cls: m.decode(p, c), r, n),
            "decode_reference_us": _us(lambda p=payload, c=cls: m._decode_reference(p, c), r, n),
            # the sender's fast path (messages.encode_imu, ...): the same bytes without building the message
            "fast_encode_us": None if fast is None else _us(lambda f=fast, a=args: f(*a), r, n),
        })  # fmt: skip
    return {"bench": "codec", **preset, "messages": rows}


def format_report(record: dict) -> str:
    lines = [
        "one message of each hot-path type: median of blocks [us]",
        f"{'type':10s} {'bytes':>6s} {'build':>8s} {'encode':>8s} {'fast enc':>9s} {'decode':>8s}"
        f" {'reference':>10s} {'ratio':>6s}",
    ]
    for r in record["messages"]:
        fast = "-" if r.get("fast_encode_us") is None else f"{r['fast_encode_us']:.1f}"
        lines.append(
            f"{r['type']:10s} {r['bytes']:6d} {r['build_us']:8.1f} {r['encode_us']:8.1f} {fast:>9s} "
            f"{r['decode_us']:8.1f} {r['decode_reference_us']:10.1f}"
            f" {r['decode_reference_us'] / r['decode_us']:5.1f}x"
        )
    return "\n".join(lines)
