"""A Crazyflie uSD event-log writer for tests (the firmware writes them; nothing public does in Python):
the header (magic 0xBC, version, event definitions), the events, and the CRC32 trailer, as
``swarm/logs/cfusd.py`` documents the format. Offsets of every part are returned so that a test can
name the byte a reader must report."""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

DEFS = {
    1: ("estGyroscope", (("gyro.x", "f"), ("gyro.y", "f"), ("gyro.z", "f"))),
    2: ("estAcceleration", (("acc.x", "f"), ("acc.y", "f"), ("acc.z", "f"))),
    3: ("estDistance", (("id", "B"), ("distance", "f"))),
    4: ("estTDOA", (("idA", "B"), ("idB", "B"), ("distanceDiff", "f"))),
    5: (
        "estPose",
        tuple((f"locSrv.{k}", "f") for k in ("x", "y", "z", "qx", "qy", "qz", "qw")),
    ),
    6: ("estTOF", (("range.zrange", "H"),)),
    7: ("estBarometer", (("baro.asl", "f"),)),
    8: ("estFlow", (("motion.deltaX", "h"), ("motion.deltaY", "h"))),
}
ID = {name: eid for eid, (name, _) in DEFS.items()}


@dataclass
class Built:
    data: bytes
    header_end: int
    """Offset of the first event."""
    offsets: list[int] = field(default_factory=list)
    """Offset of each event, in file order."""
    defs_at: dict[int, int] = field(default_factory=dict)
    """Offset of each event definition by id."""


def header(version: int = 2, defs: dict | None = None, magic: int = 0xBC) -> tuple[bytes, dict[int, int]]:
    defs = DEFS if defs is None else defs
    out = bytearray([magic]) + struct.pack("<HH", version, len(defs))
    at = {}
    for eid, (name, fields) in defs.items():
        at[eid] = len(out)
        out += struct.pack("<H", eid) + name.encode() + b"\0" + struct.pack("<H", len(fields))
        for fname, letter in fields:
            out += f"{fname}({letter})".encode() + b"\0"
    return bytes(out), at


def build(events: list[tuple[str, int, tuple]], version: int = 2, crc: bool = True, defs=None) -> Built:
    """``events``: ``(name, stamp, values)`` with the stamp in the version's unit (1: ms, 2: us)."""
    defs = DEFS if defs is None else defs
    ids = {name: eid for eid, (name, _) in defs.items()}
    head, at = header(version, defs)
    out = bytearray(head)
    offsets = []
    stamp = "<HI" if version == 1 else "<HQ"
    for name, ts, values in events:
        fields = defs[ids[name]][1]
        offsets.append(len(out))
        out += struct.pack(stamp, ids[name], ts) + struct.pack("<" + "".join(f[1] for f in fields), *values)
    if crc:
        out += struct.pack("<I", zlib.crc32(bytes(out)))
    return Built(bytes(out), len(head), offsets, at)


def imu_events(n: int, version: int = 2, rate_hz: float = 1000.0, acc_lag_us: int = 17):
    """``n`` gyroscope and accelerometer events: gyro ``(10 + t, -20, 30)`` deg/s, accelerometer ``(0.01 t,
    0, 1 + 0.1 t)`` g with t in seconds (linear, so interpolation is exact), the accelerometer ``acc_lag_us``
    before the gyroscope, as in a Crazyflie log."""
    unit = 1000 if version == 1 else 1_000_000
    out = []
    for k in range(n):
        tg_us = 1_000_000 + round(k * 1e6 / rate_hz)
        ta_us = tg_us - acc_lag_us
        ta = ta_us / 1e6
        tg = tg_us / 1e6
        out.append(("estAcceleration", ta_us * unit // 1_000_000, (0.01 * ta, 0.0, 1.0 + 0.1 * ta)))
        out.append(("estGyroscope", tg_us * unit // 1_000_000, (10.0 + tg, -20.0, 30.0)))
    return out


def big_log(n_pairs: int) -> bytes:
    """A large version-2 log of gyroscope and accelerometer events, built with numpy (fast)."""
    head, _ = header(2)
    ev = np.dtype([("id", "<u2"), ("ts", "<u8"), ("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    rec = np.zeros(2 * n_pairs, dtype=ev)
    t_us = 1_000_000 + np.arange(n_pairs, dtype=np.uint64) * 1000
    rec["id"][0::2], rec["ts"][0::2] = ID["estAcceleration"], t_us - 17
    rec["id"][1::2], rec["ts"][1::2] = ID["estGyroscope"], t_us
    rec["z"][0::2] = 1.0
    rec["x"][1::2] = np.sin(np.arange(n_pairs) * 1e-3)
    body = head + rec.tobytes()
    return body + struct.pack("<I", zlib.crc32(body))
