"""A minimal ULog writer for tests (pyulog only reads): the file header, a flag-bits message, one format
('F') and one subscription ('A') per topic, then data ('D') messages in the order given.

The format (PX4 docs, "ULog File Format"): a 16-byte header, ``ULog`` + ``0x01 0x12 0x35``, a version byte
and a u64 start timestamp; then messages of a u16 payload size, a u8 type and the payload, little-endian.
"""

from __future__ import annotations

import struct

MAGIC = b"ULog\x01\x12\x35"
_PACK = {
    "uint64_t": "Q",
    "int64_t": "q",
    "uint32_t": "I",
    "int32_t": "i",
    "uint16_t": "H",
    "int16_t": "h",
    "uint8_t": "B",
    "int8_t": "b",
    "float": "f",
    "double": "d",
    "bool": "?",
}


def _msg(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


def _fmt(fields: list[tuple[str, str]]) -> str:
    """struct letters of a topic's fields (``float[3]`` -> ``fff``)."""
    out = "<"
    for typ, _ in fields:
        base, _, n = typ.partition("[")
        out += _PACK[base] * (int(n[:-1]) if n else 1)
    return out


def ulog_bytes(topics: dict[str, list[tuple[str, str]]], data: list[tuple], instances=None) -> bytes:
    """A ULog file: ``topics`` maps a topic name to its fields ``(type, name)`` (the first must be
    ``uint64_t timestamp``); ``data`` is ``(topic, values)`` or ``((topic, multi_id), values)`` in file
    order, values flat (an array field takes as many values as its length). ``instances`` maps a topic to
    its multi_ids (default ``(0,)``): one subscription each."""
    out = bytearray(MAGIC + bytes([1]) + struct.pack("<Q", 0))
    out += _msg(b"B", bytes(8) + bytes(8) + bytes(24))
    for name, fields in topics.items():
        text = name + ":" + "".join(f"{t} {n};" for t, n in fields)
        out += _msg(b"F", text.encode())
    ids = {}
    for name in topics:
        for mid in (instances or {}).get(name, (0,)):
            ids[(name, mid)] = len(ids)
            out += _msg(b"A", struct.pack("<BH", mid, ids[(name, mid)]) + name.encode())
    fmts = {name: _fmt(fields) for name, fields in topics.items()}
    for key, values in data:
        name, mid = key if isinstance(key, tuple) else (key, 0)
        out += _msg(b"D", struct.pack("<H", ids[(name, mid)]) + struct.pack(fmts[name], *values))
    return bytes(out)
