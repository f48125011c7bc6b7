"""The Crazyflie uSD-card event log (``swarm import cfusd``): decode it, and turn its estimator events into a
log folder (``docs/logs.md``).

The format (the firmware's ``usddeck.c`` writes it, ``tools/usdlog/cfusdlog.py`` of bitcraze/
crazyflie-firmware reads it): a header, byte 0 the magic ``0xBC``, a u16 version (1 or 2) and a u16 number
of event types, then each type's definition: u16 id, its NUL-terminated name, a u16 field count and each
field as a NUL-terminated ``name(T)`` with ``T`` a :mod:`struct` type letter. Then the events: u16 id, a
timestamp (version 1: u32 milliseconds; version 2: u64 microseconds) and the packed little-endian fields.
The last 4 bytes are the CRC32 (zlib) of everything before them. Every integer is little-endian.

Decoding walks the events once to find their offsets (they differ in size, so they must be walked), then
reads each event type's fields with one numpy structured view: a 4 MB log decodes in ~0.15-0.2 s.

Damage: a bad magic, an unknown version, a header cut short or malformed, an event id that no definition
names, or a CRC mismatch of a whole file is refused with a :class:`~swarm.errors.LogError` naming the file
and the byte offset. A file cut mid-write (the logger lost power: no CRC trailer, the last event partial)
keeps every event decoded before the cut, and says how many bytes were dropped at which offset.
"""

from __future__ import annotations

import struct
import zlib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarm.errors import LogError
from swarm.logs.importing import STANDARD_G_M_S2, Imported, LogFolder, pair_imu, read_anchor_file, time_order

MAGIC = 0xBC
VERSIONS = (1, 2)
TYPES = {
    "b": "<i1",
    "B": "<u1",
    "?": "<u1",
    "h": "<i2",
    "H": "<u2",
    "i": "<i4",
    "I": "<u4",
    "l": "<i4",
    "L": "<u4",
    "q": "<i8",
    "Q": "<u8",
    "e": "<f2",
    "f": "<f4",
    "d": "<f8",
}
"""The :mod:`struct` letters an event field may have, as little-endian numpy types (``<`` standard sizes)."""


@dataclass(frozen=True)
class EventType:
    """One event definition of the header."""

    id: int
    name: str
    fields: tuple[str, ...]
    dtype: np.dtype
    """The whole event as a packed structured type: ``_id``, ``_ts`` and the fields by name."""
    offset: int
    """Byte offset of the definition in the file."""


@dataclass
class UsdLog:
    """A decoded log: per event name, its times [s] (``t_s``), byte offsets and fields (numpy arrays)."""

    path: Path
    version: int
    size: int
    types: dict[int, EventType]
    events: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    counts: Counter = field(default_factory=Counter)
    """Events per name (every defined type that occurs)."""
    cut_at: int | None = None
    """Byte offset where a file cut mid-write stops being usable (None: a whole file, its CRC checked)."""
    dropped_bytes: int = 0
    """Bytes after :attr:`cut_at` (a partial event) that were not decoded."""


def _cstring(data: bytes, at: int, name: str, what: str) -> tuple[str, int]:
    end = data.find(b"\0", at)
    if end < 0:
        raise LogError(f"{name}, byte {at}: truncated header: {what} has no terminating NUL before the end")
    try:
        return data[at:end].decode("utf-8"), end + 1
    except UnicodeDecodeError:
        raise LogError(f"{name}, byte {at}: {what} is not UTF-8 text: {data[at:end]!r}") from None


def _u16(data: bytes, at: int, name: str, what: str) -> int:
    if at + 2 > len(data):
        raise LogError(
            f"{name}, byte {at}: truncated header: {what} needs 2 bytes, the file ends at {len(data)}"
        )
    return data[at] | data[at + 1] << 8


def _header(data: bytes, name: str) -> tuple[int, dict[int, EventType], int]:
    """The version, the event types by id and the offset of the first event."""
    if len(data) < 1 or data[0] != MAGIC:
        got = f"0x{data[0]:02X}" if data else "an empty file"
        raise LogError(f"{name}, byte 0: magic {got}, expected 0xBC (a Crazyflie uSD event log)")
    version = _u16(data, 1, name, "the version")
    if version not in VERSIONS:
        raise LogError(f"{name}, byte 1: unknown version {version} (this reader knows 1 and 2)")
    count = _u16(data, 3, name, "the number of event types")
    ts = "<u4" if version == 1 else "<u8"
    types: dict[int, EventType] = {}
    at = 5
    for _ in range(count):
        start = at
        eid = _u16(data, at, name, "an event id")
        ename, at = _cstring(data, at + 2, name, f"the name of event {eid}")
        nf = _u16(data, at, name, f"the field count of {ename}")
        at += 2
        names, dts = [], [("_id", "<u2"), ("_ts", ts)]
        for _ in range(nf):
            f_at = at
            text, at = _cstring(data, at, name, f"a field of {ename}")
            if len(text) < 4 or text[-3] != "(" or text[-1] != ")":
                raise LogError(f"{name}, byte {f_at}: field {text!r} of {ename} is not name(T)")
            fname, letter = text[:-3], text[-2]
            if letter not in TYPES:
                raise LogError(
                    f"{name}, byte {f_at}: field {text!r} of {ename}: unknown type {letter!r} "
                    f"(known: {''.join(TYPES)})"
                )
            if fname in names or fname in ("_id", "_ts"):
                raise LogError(f"{name}, byte {f_at}: field {fname!r} of {ename} is defined twice")
            names.append(fname)
            dts.append((fname, TYPES[letter]))
        if eid in types:
            raise LogError(f"{name}, byte {start}: event id {eid} ({ename}) is defined twice")
        types[eid] = EventType(eid, ename, tuple(names), np.dtype(dts), start)
    return version, types, at


def _walk(data: bytes, start: int, sizes: dict[int, int], end: int, name: str) -> tuple[dict[int, list], int]:
    """Offsets of each event id's events from ``start`` while a whole event fits before ``end``; and the
    offset where the walk stopped. An id that no definition names is refused."""
    offsets: dict[int, list] = {eid: [] for eid in sizes}
    at = start
    get = sizes.get
    while at + 2 <= end:
        eid = data[at] | data[at + 1] << 8
        size = get(eid)
        if size is None:
            if end == len(data) and at == end - 4:
                _crc_error(data, name)
            raise LogError(
                f"{name}, byte {at}: event id {eid} is not defined in the header "
                f"(defined: {', '.join(str(i) for i in sorted(sizes))})"
            )
        if at + size > end:
            break
        offsets[eid].append(at)
        at += size
    return offsets, at


def _crc_error(data: bytes, name: str) -> None:
    n = len(data)
    stored = struct.unpack_from("<I", data, n - 4)[0]
    computed = zlib.crc32(data[: n - 4])
    raise LogError(
        f"{name}, byte {n - 4}: CRC mismatch: the trailer says 0x{stored:08X}, bytes 0-{n - 5} give "
        f"0x{computed:08X} (the file is damaged; or it was cut 4 bytes into an event)"
    )


def decode(path: str | Path) -> UsdLog:
    """Decode the uSD event log at ``path`` (module docstring): every event type's times and fields.
    Raises LogError (file and byte offset) for a damaged file; a file cut mid-write keeps what decoded
    before the cut (:attr:`UsdLog.cut_at`, :attr:`UsdLog.dropped_bytes`)."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise LogError(f"{p}: cannot read: {exc.strerror or exc}") from None
    name = p.name
    version, types, start = _header(data, name)
    n = len(data)
    sizes = {eid: et.dtype.itemsize for eid, et in types.items()}
    whole = n - start >= 4 and zlib.crc32(data[: n - 4]) == struct.unpack_from("<I", data, n - 4)[0]
    result = UsdLog(p, version, n, types)
    if whole:
        offsets, at = _walk(data, start, sizes, n - 4, name)
        if at != n - 4:
            eid = data[at] | data[at + 1] << 8 if at + 2 <= n - 4 else None
            raise LogError(
                f"{name}, byte {at}: {n - 4 - at} bytes before the CRC trailer are not a whole event"
                + (f" ({types[eid].name} needs {sizes[eid]})" if eid in types else "")
            )
    else:
        offsets, at = _walk(data, start, sizes, n, name)
        left = n - at
        if left == 4:
            _crc_error(data, name)
        result.cut_at, result.dropped_bytes = at, left
    buf = np.frombuffer(data, dtype=np.uint8)
    scale = 1e-3 if version == 1 else 1e-6  # v1 stamps in ms, v2 in us (cfusdlog.py)
    for eid, offs in offsets.items():
        if not offs:
            continue
        et = types[eid]
        o = np.asarray(offs, dtype=np.int64)
        raw = buf[o[:, None] + np.arange(et.dtype.itemsize)]
        rec = np.ascontiguousarray(raw).view(et.dtype).reshape(-1)
        cols = {f: rec[f].astype(np.float64) for f in et.fields}
        cols["t_s"] = rec["_ts"].astype(np.float64) * scale
        cols["offset"] = o
        result.events[et.name] = cols
        result.counts[et.name] = len(o)
    return result


def need(usd: UsdLog, event: str, fields: tuple[str, ...]) -> dict[str, np.ndarray] | None:
    """The columns of ``event`` (None if the log has none), refused if its definition lacks a field."""
    cols = usd.events.get(event)
    if cols is None:
        return None
    missing = [f for f in fields if f not in cols]
    if missing:
        et = next(t for t in usd.types.values() if t.name == event)
        raise LogError(
            f"{usd.path.name}, byte {et.offset}: event {event} has no field {missing[0]!r} "
            f"(it has {', '.join(et.fields)})"
        )
    return cols


TOF_MAX_MM = 5000
"""The Flow deck v2's VL53L1x range [mm] at and beyond which a reading is no return: the firmware's
``RANGE_OUTLIER_LIMIT`` (``zranger2.c``); 0 is no return too."""

CF_TWR_SIGMA_M = 0.25
"""The range noise the Crazyflie firmware gives its own filter for a two-way range [m] (``dist.stdDev =
0.25`` in ``lpsTwrTag.c``): suggested, commented out, as ``[uwb] sigma_m`` of an imported TWR log: a
static start segment (``[calibration] until_s``) calibrates it per anchor, and an explicit ``sigma_m``
would take its place (the replay refuses a log with neither, saying so)."""

USED = {
    "estGyroscope": ("gyro.x", "gyro.y", "gyro.z"),
    "estAcceleration": ("acc.x", "acc.y", "acc.z"),
    "estDistance": ("id", "distance"),
    "estTDOA": ("idA", "idB", "distanceDiff"),
    "estPose": ("locSrv.x", "locSrv.y", "locSrv.z", "locSrv.qx", "locSrv.qy", "locSrv.qz", "locSrv.qw"),
    "estTOF": ("range.zrange",),
    "estBarometer": ("baro.asl",),
}
"""The events the importer reads and the fields it needs of each; other events are counted and ignored."""


def _stack(cols: dict[str, np.ndarray], names: tuple[str, ...]) -> np.ndarray:
    return np.stack([cols[f] for f in names], axis=1)


def _anchor_check(usd: UsdLog, event: str, cols, fields: tuple[str, ...], ids: np.ndarray, anchors_name: str):
    """Refuse an event naming an anchor the anchors file does not have (the byte offset of the first)."""
    for f in fields:
        bad = np.flatnonzero(~np.isin(cols[f], ids))
        if len(bad):
            k = int(bad[0])
            raise LogError(
                f"{usd.path.name}, byte {int(cols['offset'][k])}: {event} {f} {int(cols[f][k])} is not in "
                f"{anchors_name} (it has {', '.join(str(int(i)) for i in ids)})"
            )


def import_cfusd(
    raw: str | Path,
    out: str | Path,
    anchors: str | Path | None = None,
    *,
    g_m_s2: float = STANDARD_G_M_S2,
    tof_max_mm: float = TOF_MAX_MM,
    force: bool = False,
) -> Imported:
    """Import the uSD log ``raw`` into the log folder ``out`` (``docs/logs.md``, Importing logs).

    estGyroscope (deg/s) and estAcceleration (g, times ``g_m_s2``) become ``imu.csv`` in rad/s and m/s^2,
    paired by :func:`~swarm.logs.importing.pair_imu` (rows at the gyroscope's times, the accelerometer
    interpolated); estDistance ``uwb.csv``; estTDOA ``tdoa.csv`` (``ddist_m = distanceDiff = |p - a_idB| -
    |p - a_idA|``: the firmware's ``kalmanCoreUpdateWithTdoa``, ``mm_tdoa.c``, predicts ``d1 - d0`` with
    anchor 0 = idA and 1 = idB, ``estimator.c``; the UTIL authors' ESKF predicts ``d_B - d_A``); estPose
    (motion capture streamed to the vehicle) ``truth.csv``; estTOF (mm) ``height.csv`` in m, 0 or
    ``>= tof_max_mm`` written empty (no return); estBarometer (``baro.asl``, m) ``baro.csv``. A TDoA row
    with the same anchor twice or ``|ddist| >=`` the anchors' baseline is dropped and counted, as the
    firmware's ``outlierFilterTdoa.c`` does. ``anchors`` (our anchors.csv or the UTIL survey) is required
    when the log has ranges; a range from an anchor it lacks is refused with the event's byte offset."""
    usd = decode(raw)
    src = Path(raw)
    rep = Imported(
        Path(out), f"source: {src.name} (Crazyflie uSD event log, version {usd.version}, {usd.size} bytes)"
    )
    for ev, fields in USED.items():
        need(usd, ev, fields)
    rep.notes.append("events: " + ", ".join(f"{k} {v}" for k, v in sorted(usd.counts.items())))
    ignored = {k: v for k, v in usd.counts.items() if k not in USED}
    if ignored:
        rep.notes.append("ignored: " + ", ".join(f"{k} {v}" for k, v in sorted(ignored.items())))
    if usd.cut_at is not None:
        if usd.dropped_bytes:
            rep.warn(
                f"{src.name} was cut mid-write: {usd.dropped_bytes} bytes of a partial event dropped at byte "
                f"offset {usd.cut_at}; the events before it are kept"
            )
        else:
            rep.warn(f"{src.name} ends at byte {usd.cut_at} without its CRC trailer (cut between two events)")
    gy, ac = usd.events.get("estGyroscope"), usd.events.get("estAcceleration")
    if gy is None or ac is None:
        raise LogError(
            f"{src.name}: no {'estGyroscope' if gy is None else 'estAcceleration'} events: imu.csv needs them"
        )
    ranges = "estDistance" in usd.events or "estTDOA" in usd.events
    if ranges and anchors is None:
        raise LogError(
            f"{src.name}: has UWB events (estDistance or estTDOA): give the anchors file (--anchors)"
        )
    folder = LogFolder(out, force, rep, time_decimals=3 if usd.version == 1 else 6)
    ids, xyz = (np.empty(0, np.int64), np.empty((0, 3))) if anchors is None else read_anchor_file(anchors)
    anchors_name = Path(anchors).name if anchors is not None else "the anchors file"

    t, gyro, acc, dropped = pair_imu(
        gy["t_s"],
        np.radians(_stack(gy, USED["estGyroscope"])),
        ac["t_s"],
        _stack(ac, USED["estAcceleration"]) * g_m_s2,
    )
    folder.write_imu(t, gyro, acc)
    rep.notes.append(
        f"imu.csv: gyro deg/s -> rad/s; acceleration g -> m/s^2 times {g_m_s2:g}; rows at the gyroscope's "
        f"times, accelerometer interpolated; {dropped} gyroscope samples without one around them dropped"
    )
    folder.write_anchors(ids, xyz)
    d = usd.events.get("estDistance")
    if d is not None:
        _anchor_check(usd, "estDistance", d, ("id",), ids, anchors_name)
        o, _ = time_order(d["t_s"], strict=False)
        folder.write_uwb(d["t_s"][o], d["id"][o], d["distance"][o])
    else:
        folder.write_uwb(np.empty(0), np.empty(0), np.empty(0))
    td = usd.events.get("estTDOA")
    if td is not None:
        _anchor_check(usd, "estTDOA", td, ("idA", "idB"), ids, anchors_name)
        pos = dict(zip(ids.tolist(), xyz, strict=True))
        a, b, dd = td["idA"].astype(int), td["idB"].astype(int), td["distanceDiff"]
        base = np.array(
            [np.linalg.norm(pos[i] - pos[j]) for i, j in zip(a.tolist(), b.tolist(), strict=True)]
        )
        ok = (a != b) & np.isfinite(dd) & (np.abs(dd) < base)
        o, _ = time_order(td["t_s"][ok], strict=False)
        folder.write_tdoa(td["t_s"][ok][o], a[ok][o], b[ok][o], dd[ok][o])
        rep.notes.append(
            f"tdoa.csv: ddist_m = distanceDiff = |p - a_idB| - |p - a_idA|; {int((~ok).sum())} dropped "
            "(the same anchor twice, or longer than the anchors' baseline: the firmware's outlier filter "
            "drops them)"
        )
    pose = usd.events.get("estPose")
    if pose is not None:
        o, dup = time_order(pose["t_s"], strict=True)
        f = USED["estPose"]
        folder.write_truth(pose["t_s"][o], _stack(pose, f[:3])[o], _stack(pose, f[3:])[o])
        rep.notes.append(
            f"truth.csv: estPose (motion capture sent to the vehicle); {dup} repeated times dropped"
        )
    tof = usd.events.get("estTOF")
    if tof is not None:
        o, dup = time_order(tof["t_s"], strict=True)
        mm = tof["range.zrange"][o]
        none = (mm <= 0) | (mm >= tof_max_mm) | ~np.isfinite(mm)
        folder.write_height(tof["t_s"][o], np.where(none, np.nan, mm * 1e-3))
        rep.notes.append(
            f"height.csv: range.zrange mm -> m; {int(none.sum())} without a return (0 or >= "
            f"{tof_max_mm:g} mm) written empty; {dup} repeated times dropped"
        )
    baro = usd.events.get("estBarometer")
    if baro is not None:
        o, dup = time_order(baro["t_s"], strict=True)
        folder.write_baro(baro["t_s"][o], baro["baro.asl"][o])
        rep.notes.append(f"baro.csv: baro.asl [m]; {dup} repeated times dropped")
    tables = ""
    if d is not None:
        tables = (
            "[uwb]\n# a static start segment ([calibration] until_s, position_m) calibrates each anchor's "
            "noise;\n"
            "# without one, the Crazyflie firmware's TWR range noise (lpsTwrTag.c):\n"
            f"# sigma_m = {CF_TWR_SIGMA_M}"
        )
    return folder.finish(src.name, tables)
