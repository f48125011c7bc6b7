"""Every wire message of the swarm, and the one codec that turns them into bytes and back.

Wire format (``docs/protocol.md`` is the reference for drivers and other languages): one msgpack map per
Zenoh sample, ``{"v": SCHEMA_VERSION, "type": "<class name>", "<field>": <value>, ...}`` with the field
names of the dataclasses below. Floats may arrive as msgpack ints; integers must be ints; tuples are
arrays; a numpy array is the map ``{"dtype": "<f8", "shape": [...], "data": <bin>}`` of its raw C-order
bytes (measured here: 2-3 us per array where ``tolist`` of 1000 x 3 costs ~300 us), and plain nested
arrays of numbers are accepted too, so a client in any language can send lists. A field with a default
may be left out (its default applies); unknown keys are ignored, so a newer sender can add fields
without breaking an older receiver. A change that breaks old readers bumps :data:`SCHEMA_VERSION`.

Validation lives in each message's ``__post_init__``: a message that exists is valid, whether it was
built in Python or decoded from the wire. Every field is checked for type, shape, finiteness (no NaN or
Inf anywhere), obvious ranges and size caps, and :class:`~swarm.errors.MessageError` names the field
(``"gyro_body: expected shape (3,), got (4,)"``). Arrays are stored as writable float64 copies (never a
read-only ``frombuffer`` view of the payload). :func:`safe_decode` is what a Zenoh callback calls: it
never raises; a bad message is dropped, counted per key in a :class:`DropCounter` and logged at a
limited rate, so it never reaches a filter.

Conventions (notes/conventions.md): frames ``nav`` (mothership, inertial) and ``body``; quaternions
scalar-last ``(x, y, z, w)``, ``q_nav_body`` maps body vectors into ``nav``; SI units.
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from collections.abc import Callable, Container, Sequence
from dataclasses import MISSING, dataclass, field, fields
from typing import Annotated, Any, Literal, TypeVar

import msgpack
import msgspec
import numpy as np

from swarm.core.decision_keys import DECISION_KEYS
from swarm.errors import ConfigError, MessageError
from swarm.transport.keys import ID_PATTERN

__all__ = [
    "BUNDLE_TYPES",
    "CLOCK_STATES",
    "DOCKING_MODES",
    "EVENT_KINDS",
    "FACES",
    "FAULT_KINDS",
    "LANDING_MODES",
    "MAX_BATCH",
    "MAX_ITEMS",
    "MAX_PAYLOAD_BYTES",
    "MAX_TDOA_ROWS",
    "MESSAGE_FOR_KIND",
    "MESSAGE_TYPES",
    "MODES",
    "NEW_RUN_COMMANDS",
    "QUAT_NORM_TOL",
    "RUN_COMMANDS",
    "SCHEMA_VERSION",
    "VISION_KINDS",
    "Anchors",
    "Barometer",
    "Bundle",
    "Clock",
    "Command",
    "CommandBatch",
    "DropCounter",
    "Estimate",
    "Event",
    "Fault",
    "Gnss",
    "Guidance",
    "Imu",
    "ImuBatch",
    "Message",
    "Rangefinder",
    "RunControl",
    "Tdoa",
    "TdoaBatch",
    "Truth",
    "TruthBatch",
    "Uwb",
    "UwbBatch",
    "Vision",
    "VisionBatch",
    "batch_rows",
    "bundle_messages",
    "decode",
    "encode",
    "encode_command",
    "encode_estimate",
    "encode_imu",
    "encode_tdoa",
    "encode_truth",
    "encode_truth_batch",
    "encode_uwb",
    "encode_vision",
    "estimate_and_payload",
    "estimate_message",
    "next_run_seed",
    "pack_bundle",
    "pack_entries",
    "safe_decode",
]

_LOG = logging.getLogger(__name__)

SCHEMA_VERSION = 2
"""Value of the ``"v"`` key of every message; a receiver drops any other version."""

MAX_PAYLOAD_BYTES = 65536
"""Largest accepted payload [bytes]; larger ones are refused before unpacking."""
MAX_ITEMS = 64
"""Largest number of markers, nozzles, anchors, counters per message."""
MAX_BATCH = 256
"""Most vehicles in one batch message (:class:`ImuBatch`); a larger swarm's world sends several."""
QUAT_NORM_TOL = 1e-3
"""A quaternion's norm must be within this of 1."""
COV_SYMMETRY_RTOL = 1e-9
"""``max |P - P^T| <= COV_SYMMETRY_RTOL * max |P|`` for a covariance."""
_MAX_TEXT = 1024  # reasons and free text [characters]
_MAX_NAME = 64  # modes, kinds, counter names [characters]
_MAX_DEPTH = 8  # nesting of event data
_MAX_ID = 2**31 - 1  # marker and anchor ids fit an int32 in any language
_U64_MAX = 2**64 - 1  # msgpack's integer range
_I64_MIN = -(2**63)

# These sets mirror swarm.core.guidance.Mode and swarm.core.camera.FACES (a test asserts they agree): the
# codec stays importable without scipy/numba/OpenCV (0.13 s instead of 0.54 s), for thin sensor drivers.
DOCKING_MODES: tuple[str, ...] = (
    "HOLD",
    "APPROACH",
    "REORIENT",
    "ALIGN",
    "DOCK",
    "DOCKED",
    "ABORT",
    "STATION",
)
"""Docking guidance modes (paper section V; ``STATION`` is the station-keeping target)."""
LANDING_MODES: tuple[str, ...] = ("CRUISE", "DEVIATE", "DESCEND", "FINAL", "CLIMB", "LANDED", "ABORT")
"""Landing guidance modes (paper section VI-B, ``swarm.core.landing``)."""
MODES: tuple[str, ...] = DOCKING_MODES + tuple(m for m in LANDING_MODES if m not in DOCKING_MODES)
"""Every guidance mode a ``Guidance`` or ``Command`` may carry."""
FACES: tuple[str, ...] = ("+x", "-x", "+y", "-y", "+z", "-z")
"""Faces of the target cube, named by the outward normal in the target body frame."""
VISION_KINDS: tuple[str, ...] = ("features", "pixels", "pose")
POSE_LEN = 43
"""Length of a ``"pose"`` row: ``t_cam_m`` (3), ``q_cam_target`` (4), ``cov_cam`` (6 x 6)
(``swarm.core.camera.POSE_N``)."""
CLOCK_STATES: tuple[str, ...] = ("running", "paused", "stopped")
RUN_COMMANDS: tuple[str, ...] = ("pause", "resume", "reset", "new_seed")
NEW_RUN_COMMANDS: tuple[str, ...] = ("reset", "new_seed")
"""The run controls that end the run for the next one (the world's ``run_end`` ``reason``)."""


def next_run_seed(end: dict, seed: int) -> int:
    """The seed of the run after the one ``end`` (a world's ``run_end`` data) ended, whose seed was ``seed``:
    the ``next_seed`` a ``reset`` or ``new_seed`` asked for, else the same seed for a ``reset`` and the next
    one otherwise (``new_seed``, ``swarm launch --repeat``)."""
    nxt = end.get("next_seed")
    if nxt is not None:
        return int(nxt)
    return seed if end.get("reason") == "reset" else seed + 1


EVENT_KINDS: tuple[str, ...] = (
    "mode",
    "docked",
    "contact",
    "collision",
    "abort",
    "estimator_reset",
    "lost",
    "restarted",
    "keepout_violation",
    "summary",
    "run_start",
    "run_end",
    "agent_missing",
    "fault",
    "fault_refused",
    "takeoff",
    "landing",
)
"""Event kinds in use; the set is open (any ``[a-z][a-z0-9_]*`` name is accepted)."""

_WIRE_DTYPE = re.compile(r"[<>](?:f[248]|[iu][1248])|\|[iu]1")
_EVENT_KIND = re.compile(r"[a-z][a-z0-9_]*")
_DECISION_PROBABILITIES = frozenset({"A11", "A22", "A23", "A32", "A33", "pi1", "pi2"})
_PROBABILITY_SLACK = 1e-9  # clipped probabilities; stationary ones come from a linear solve


# ------------------------------------------------------------------------------------- field checks


def _show(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _is_int(x: object) -> bool:
    return isinstance(x, int | np.integer) and not isinstance(x, bool | np.bool_)


def _is_real(x: object) -> bool:
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(x, bool | np.bool_)


def _bool(value: object, name: str) -> bool:
    if not isinstance(value, bool | np.bool_):
        raise MessageError(f"{name}: expected true or false, got {_show(value)}")
    return bool(value)


def _int(value: object, name: str, lo: int = 0, hi: int = _U64_MAX) -> int:
    if not _is_int(value):
        raise MessageError(f"{name}: expected an integer, got {_show(value)}")
    v = int(value)
    if v < lo:
        raise MessageError(f"{name}: must be >= {lo}, got {v}")
    if v > hi:
        raise MessageError(f"{name}: must be <= {hi}, got {v}")
    return v


def _float(
    value: object, name: str, *, lo: float | None = None, positive: bool = False, nullable: bool = False
) -> Any:
    if value is None and nullable:
        return None
    if not _is_real(value):
        raise MessageError(f"{name}: expected a number{' or nil' if nullable else ''}, got {_show(value)}")
    try:
        v = float(value)
    except OverflowError:
        v = math.inf
    if not math.isfinite(v):
        raise MessageError(f"{name}: not finite ({v})")
    if positive and not v > 0.0:
        raise MessageError(f"{name}: must be > 0, got {v}")
    if lo is not None and v < lo:
        raise MessageError(f"{name}: must be >= {lo:g}, got {v}")
    return v


def _str(
    value: object,
    name: str,
    *,
    choices: tuple[str, ...] | None = None,
    pattern: re.Pattern | None = None,
    max_len: int = _MAX_NAME,
) -> str:
    if not isinstance(value, str):
        raise MessageError(f"{name}: expected a string, got {_show(value)}")
    value = str(value)  # a StrEnum member becomes its plain value
    if choices is not None and value not in choices:
        raise MessageError(f"{name}: expected one of {choices}, got {_show(value)}")
    if len(value) > max_len:
        raise MessageError(f"{name}: {len(value)} characters, more than the {max_len} allowed")
    if pattern is not None and not pattern.fullmatch(value):
        raise MessageError(f"{name}: must match {pattern.pattern}, got {_show(value)}")
    return value


def _unpack_array(d: dict, name: str) -> np.ndarray:
    """The ``{"dtype", "shape", "data"}`` wire form of an array, as a read-only view of ``data``."""
    for k in ("dtype", "shape", "data"):
        if k not in d:
            raise MessageError(f"{name}: an array map needs 'dtype', 'shape' and 'data'; {k!r} is missing")
    code, shape, data = d["dtype"], d["shape"], d["data"]
    if not isinstance(code, str) or not _WIRE_DTYPE.fullmatch(code):
        raise MessageError(
            f"{name}.dtype: expected an int/float code with byte order like '<f8', got {_show(code)}"
        )
    if not (
        isinstance(shape, list | tuple)
        and len(shape) <= 2
        and all(_is_int(s) and 0 <= s <= MAX_PAYLOAD_BYTES for s in shape)
    ):
        raise MessageError(
            f"{name}.shape: expected a list of at most 2 sizes in [0, 65536], got {_show(shape)}"
        )
    if not isinstance(data, bytes | bytearray | memoryview):
        raise MessageError(f"{name}.data: expected bin (raw bytes), got {_show(data)}")
    dtype = np.dtype(code)
    need = math.prod(int(s) for s in shape) * dtype.itemsize
    if len(data) != need:
        raise MessageError(f"{name}.data: {len(data)} bytes, shape {list(shape)} of {code} needs {need}")
    return np.frombuffer(data, dtype=dtype).reshape([int(s) for s in shape])


def _nested_numbers(value: list | tuple, name: str, ndim: int) -> np.ndarray:
    """Plain nested arrays of numbers (``ndim`` levels) as an array; bools and strings refused."""

    def walk(x: object, depth: int) -> None:
        if isinstance(x, list | tuple):
            if depth == ndim:
                raise MessageError(f"{name}: nested deeper than {ndim} level(s)")
            for item in x:
                walk(item, depth + 1)
        elif depth != ndim or not _is_real(x):
            raise MessageError(f"{name}: expected {ndim}-level nested arrays of numbers, got {_show(x)}")

    walk(value, 0)
    try:
        return np.array(value, dtype=np.float64)
    except (ValueError, OverflowError) as exc:
        raise MessageError(f"{name}: ragged or out-of-range nested arrays ({exc})") from None


def _array(
    value: object, name: str, shape: tuple[int | None, ...], nullable: bool = False, max_rows: int = MAX_ITEMS
) -> Any:
    """A finite float64 array of ``shape`` (``None``: any length up to ``max_rows``, :data:`MAX_ITEMS`
    unless given), a writable copy. Accepts an ndarray, nested lists/tuples or the wire map; ``None`` too
    when ``nullable``."""
    if value is None and nullable:
        return None
    if type(value) is np.ndarray and value.dtype == np.float64 and value.shape == shape:
        out = value.copy()  # the common case of an array of the right shape, checked in one step
        if not np.isfinite(out).all():
            raise MessageError(f"{name}: not finite")
        return out
    if isinstance(value, np.ndarray):
        arr = value
        if arr.dtype.kind not in "iuf":
            raise MessageError(f"{name}: expected numbers, got dtype {arr.dtype}")
    elif isinstance(value, dict):
        arr = _unpack_array(value, name)
    elif isinstance(value, list | tuple):
        if len(value) == 0 and len(shape) > 1 and shape[0] is None and None not in shape[1:]:
            arr = np.zeros((0, *shape[1:]))  # "no rows" as an empty list, its row shape implied
        else:
            arr = _nested_numbers(value, name, len(shape))
    else:
        raise MessageError(
            f"{name}: expected an array (nested lists or a dtype/shape/data map), got {_show(value)}"
        )
    ok = arr.ndim == len(shape) and all(e is None or a == e for a, e in zip(arr.shape, shape, strict=False))
    if not ok:
        spec = ", ".join("N" if e is None else str(e) for e in shape) + ("," if len(shape) == 1 else "")
        raise MessageError(f"{name}: expected shape ({spec}), got {tuple(arr.shape)}")
    for a, e in zip(arr.shape, shape, strict=True):
        if e is None and a > max_rows:
            raise MessageError(f"{name}: {a} rows, more than the {max_rows} allowed")
    out = np.array(arr, dtype=np.float64)  # a copy: writable, and never a view of the payload
    if not np.isfinite(out).all():
        raise MessageError(f"{name}: not finite")
    return out


def _quat(value: object, name: str, nullable: bool = False) -> Any:
    if value is None and nullable:
        return None
    return _unit(_array(value, name, (4,)), name)


def _unit(q: np.ndarray, name: str) -> np.ndarray:
    if _clearly_unit(q):  # finite here: the common case, in a fraction of np.linalg.norm's time
        return q
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUAT_NORM_TOL:
        raise MessageError(
            f"{name}: norm {norm:.6g} is not within {QUAT_NORM_TOL:g} of 1 (unit quaternion x, y, z, w)"
        )
    return q


def _cov(value: object, name: str, n: int) -> np.ndarray:
    return _covariance(_array(value, name, (n, n)), name)


def _covariance(p: np.ndarray, name: str) -> np.ndarray:
    asym = float(np.max(np.abs(p - p.T)))
    if asym > COV_SYMMETRY_RTOL * float(np.max(np.abs(p))):
        raise MessageError(f"{name}: not symmetric (max |P - P^T| = {asym:.3g})")
    diag = np.diag(p)
    if np.any(diag < 0.0):
        i = int(np.argmin(diag))
        raise MessageError(f"{name}: negative diagonal entry {diag[i]:.3g} at index {i}")
    return p


def _ids(value: object, name: str, min_len: int = 1) -> tuple[int, ...]:
    if not isinstance(value, list | tuple):
        raise MessageError(f"{name}: expected an array of integers, got {_show(value)}")
    if not min_len <= len(value) <= MAX_ITEMS:
        raise MessageError(f"{name}: {len(value)} entries, expected {min_len} to {MAX_ITEMS}")
    ids = tuple(_int(v, f"{name}[{i}]", 0, _MAX_ID) for i, v in enumerate(value))
    if len(set(ids)) != len(ids):
        raise MessageError(f"{name}: duplicate ids in {_show(ids)}")
    return ids


def _plain(value: object, name: str, depth: int = 0) -> Any:
    """A copy of free-form data made of nil, bool, int, finite float, str, arrays and string-keyed maps."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if _is_int(value):
        return _int(value, name, _I64_MIN, _U64_MAX)
    if _is_real(value):
        return _float(value, name)
    if depth >= _MAX_DEPTH:
        raise MessageError(f"{name}: nested deeper than {_MAX_DEPTH} levels")
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, list | tuple):
        return [_plain(v, f"{name}[{i}]", depth + 1) for i, v in enumerate(value)]
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise MessageError(f"{name}: map keys must be strings, got {_show(k)}")
            out[k] = _plain(v, f"{name}.{k[:32]}", depth + 1)
        return out
    raise MessageError(f"{name}: unsupported value {_show(value)} (nil, bool, int, float, str, array, map)")


def _counts(value: object, name: str) -> dict[str, int]:
    if not isinstance(value, dict):
        raise MessageError(f"{name}: expected a map of name -> count, got {_show(value)}")
    if len(value) > MAX_ITEMS:
        raise MessageError(f"{name}: {len(value)} entries, more than the {MAX_ITEMS} allowed")
    out = {}
    for k, v in value.items():
        key = _str(k, f"{name} key", pattern=ID_PATTERN)
        out[key] = _int(v, f"{name}.{key}")
    return out


def _decision(value: object, name: str) -> dict[str, float | None] | None:
    if value is None:
        return None
    if not isinstance(value, dict):
        raise MessageError(f"{name}: expected a map or nil, got {_show(value)}")
    out = {}
    for k in DECISION_KEYS:
        if k not in value:
            raise MessageError(f"{name}.{k}: missing")
        prob = k in _DECISION_PROBABILITIES
        v = _float(value[k], f"{name}.{k}", lo=0.0, nullable=prob)
        if prob and v is not None and v > 1.0 + _PROBABILITY_SLACK:
            raise MessageError(f"{name}.{k}: a probability must be in [0, 1], got {v}")
        out[k] = v
    return out


def _frame(kind: str, data: np.ndarray, ids: tuple[int, ...]) -> None:
    """The checks of a :class:`Vision` frame across its fields (rows against ids, a pose's covariance)."""
    if kind == "pose":
        if data.shape[0] > 1:
            raise MessageError(f"data: a pose frame holds at most one pose, got {data.shape[0]} rows")
        if (len(ids) > 0) != (data.shape[0] == 1):
            raise MessageError(f"marker_ids: {len(ids)} ids for {data.shape[0]} poses")
        if data.shape[0] == 1:
            cov = data[0, 7:].reshape(6, 6)
            what = "data: a pose's covariance (columns 7-42)"
            if not np.array_equal(cov, cov.T) or not (np.diag(cov) > 0.0).all():
                diag = np.diag(cov).tolist()
                raise MessageError(f"{what} must be symmetric with a positive diagonal, got {diag}")
            try:
                np.linalg.cholesky(cov)
            except np.linalg.LinAlgError:
                raise MessageError(f"{what} is not positive definite") from None
    elif len(ids) != data.shape[0]:
        raise MessageError(f"marker_ids: {len(ids)} ids for {data.shape[0]} rows of data")


def _set(msg: object, **values: object) -> None:
    for k, v in values.items():
        object.__setattr__(msg, k, v)


def _checked(cls: type[M], values: dict[str, Any]) -> M:
    """A ``cls`` message of field ``values`` checked already (by the fast decoding, a sender's fast path or
    a batch's checks): the frozen dataclass's ``__post_init__`` would only check them again."""
    msg = object.__new__(cls)
    msg.__dict__.update(values)
    return msg


# ------------------------------------------------------------------------------------------ messages


class Message:
    """Base of every wire message: equality compares arrays by value (shape and entries)."""

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        for f in fields(self):  # type: ignore[arg-type]
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and np.array_equal(a, b)):
                    return False
            elif a != b:
                return False
        return True

    __hash__ = None  # type: ignore[assignment]  # holds arrays


# ---- sender fast paths: encode_imu, encode_uwb, encode_estimate, encode_command, encode_truth give the
# bytes of encode(Message(...)) without building the message, for the messages sent every tick. Each checks
# the common case in a few operations (plain Python numbers, float64 arrays of the right shapes, a finite
# sum, a quaternion clearly of unit norm) and leaves anything else to the message's own checks, which raise
# the MessageError naming the field (tests/transport/test_messages.py compares both, bytes and errors).

_F64 = np.dtype(np.float64)


def _is_f64(a: object, shape: tuple[int, ...]) -> bool:
    return type(a) is np.ndarray and a.dtype == _F64 and a.shape == shape  # type: ignore[union-attr]


def _clearly_unit(q: np.ndarray) -> bool:
    """``q`` (finite) passes the messages' unit-norm test with a margin that no rounding of the norm can
    cross (at the margin's edge the message's own check decides)."""
    return abs(math.hypot(*q.tolist()) - 1.0) <= 0.5 * QUAT_NORM_TOL


def _total(a: np.ndarray) -> float:
    """The sum of a small float64 array, in Python (a numpy reduction costs more than the sum on a few
    entries): finite only if every entry is, unless the entries are too large for their sum to hold (the
    message's own checks then decide)."""
    return sum(a.ravel().tolist())


def _is_time(t: object) -> bool:
    return type(t) is float and t >= 0.0  # finite: with the sum of the arrays


def _is_tick(k: object) -> bool:
    return type(k) is int and 0 <= k <= _U64_MAX  # type: ignore[operator]


def _pack(type_name: str, values: dict[str, Any]) -> bytes:
    out: dict[str, object] = {"v": SCHEMA_VERSION, "type": type_name}
    out.update((name, _wire(value)) for name, value in values.items())
    payload = msgpack.packb(out, use_bin_type=True)
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise MessageError(f"payload: {len(payload)} bytes, more than the {MAX_PAYLOAD_BYTES} allowed")
    return payload


@dataclass(frozen=True, eq=False)
class Imu(Message):
    """One gyro sample of one vehicle (and its AHRS attitude when there is one): ``<ns>/agent/<id>/imu``."""

    tick: int
    """Tick ``k`` of the swarm clock (>= 0); in simulation the sample time is ``k * dt``."""
    t_s: float
    """Sample time [s] on the swarm clock (>= 0)."""
    dt_s: float
    """Integration interval [s] (> 0) ending at ``t_s``, over which the estimator propagates this rate."""
    gyro_body: np.ndarray
    """Measured angular rate (3,) [rad/s], body frame, with the sensor's bias and noise."""
    q_ahrs_nav_body: np.ndarray | None = None
    """AHRS attitude (4,), unit quaternion (x, y, z, w) mapping body into nav; ``None`` when the vehicle has
    no AHRS or on ticks without an AHRS output (it runs at 10 Hz of the 100 Hz)."""
    acc_body: np.ndarray | None = None
    """Measured specific force (3,) [m/s^2], body frame, from a 6-axis IMU (what an accelerometer reads:
    about +9.81 up at rest); ``None`` for a gyro-only sensor (the simulated CubeSats)."""

    def __post_init__(self) -> None:
        _set(
            self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
            dt_s=_float(self.dt_s, "dt_s", positive=True),
            gyro_body=_array(self.gyro_body, "gyro_body", (3,)),
            q_ahrs_nav_body=_quat(self.q_ahrs_nav_body, "q_ahrs_nav_body", nullable=True),
            acc_body=_array(self.acc_body, "acc_body", (3,), nullable=True),
        )  # fmt: skip


def encode_imu(tick: int, t_s: float, dt_s: float, gyro_body, q_ahrs_nav_body=None, acc_body=None) -> bytes:
    """``encode(Imu(...))``, the same bytes, without building the message (the sender fast paths above)."""
    q, acc = q_ahrs_nav_body, acc_body
    plain = (
        _is_tick(tick) and _is_time(t_s) and type(dt_s) is float and dt_s > 0.0 and _is_f64(gyro_body, (3,))
        and (q is None or _is_f64(q, (4,))) and (acc is None or _is_f64(acc, (3,)))
    )  # fmt: skip
    if plain:
        total = t_s + dt_s + _total(gyro_body)
        total += 0.0 if q is None else _total(q)
        total += 0.0 if acc is None else _total(acc)
        plain = math.isfinite(total) and (q is None or _clearly_unit(q))
    if not plain:
        return encode(Imu(tick, t_s, dt_s, gyro_body, q, acc))
    wire = {"tick": tick, "t_s": t_s, "dt_s": dt_s, "gyro_body": gyro_body, "q_ahrs_nav_body": q,
            "acc_body": acc}  # fmt: skip
    return _pack("Imu", wire)


_UNIT_LO, _UNIT_HI = (1.0 - QUAT_NORM_TOL) ** 2, (1.0 + QUAT_NORM_TOL) ** 2


def _units(q: np.ndarray, name: str) -> np.ndarray:
    """Rows of ``q`` (finite, ``(M, 4)``), each a unit quaternion within :data:`QUAT_NORM_TOL`."""
    n2 = (q * q).sum(axis=1)
    if ((n2 >= _UNIT_LO) & (n2 <= _UNIT_HI)).all():
        return q
    norms = np.sqrt(n2)
    i = int(np.flatnonzero(np.abs(norms - 1.0) > QUAT_NORM_TOL)[0])
    raise MessageError(
        f"{name}[{i}]: norm {norms[i]:.6g} is not within {QUAT_NORM_TOL:g} of 1 (unit quaternion x, y, z, w)"
    )


_KNOWN_IDS: dict[tuple, None] = {}  # id lists already checked (a swarm's batches repeat one or a few)


def _vehicle_ids(value: object, name: str, min_len: int) -> tuple[str, ...]:
    """Distinct vehicle ids (:data:`~swarm.transport.keys.ID_PATTERN`), ``min_len`` to :data:`MAX_BATCH`."""
    if not isinstance(value, list | tuple):
        raise MessageError(f"{name}: expected an array of vehicle ids, got {_show(value)}")
    ids = tuple(value)
    if not min_len <= len(ids) <= MAX_BATCH:
        raise MessageError(f"{name}: {len(ids)} entries, expected {min_len} to {MAX_BATCH}")
    if all(type(v) is str for v in ids) and ids in _KNOWN_IDS:
        return ids
    ids = tuple(_str(v, f"{name}[{i}]", pattern=ID_PATTERN) for i, v in enumerate(ids))
    if len(set(ids)) != len(ids):
        raise MessageError(f"{name}: duplicate ids in {_show(ids)}")
    if len(_KNOWN_IDS) >= 64:
        _KNOWN_IDS.clear()
    _KNOWN_IDS[ids] = None
    return ids


class _Batch(Message):
    """Base of the batches (:class:`ImuBatch`, :class:`UwbBatch`, :class:`VisionBatch`,
    :class:`TruthBatch`): the samples of many vehicles in one message, row ``i`` vehicle ``ids[i]``'s;
    ``sample(vid)`` is one vehicle's message."""

    ids: tuple[str, ...]

    def index(self) -> dict[str, int]:
        """Each vehicle's row."""
        return {vid: i for i, vid in enumerate(self.ids)}

    def _row(self, vid: str, row: int | None) -> int | None:
        if row is not None:
            return row
        return self.ids.index(vid) if vid in self.ids else None


@dataclass(frozen=True, eq=False)
class ImuBatch(_Batch):
    """The :class:`Imu` samples of many vehicles at one tick, in one message: ``<ns>/world/imu``, sent by a
    simulated world that serves agent hosts instead of one ``agent/<id>/imu`` per vehicle (docs/protocol.md,
    "Rates": one message per tick where there were N, for the world, the router and a host alike).
    Row ``i`` of the arrays is vehicle ``ids[i]``'s; :meth:`sample` gives one vehicle's :class:`Imu`."""

    tick: int
    """Tick ``k`` of the swarm clock (>= 0), every row's."""
    t_s: float
    """Sample time [s] (>= 0), every row's."""
    dt_s: float
    """Integration interval [s] (> 0), every row's."""
    ids: tuple[str, ...]
    """The vehicles, distinct, 1 to :data:`MAX_BATCH`: row ``i`` of ``gyro_body`` (and ``acc_body``)."""
    gyro_body: np.ndarray
    """Measured angular rates (N, 3) [rad/s], each vehicle's body frame (:attr:`Imu.gyro_body`)."""
    ahrs_ids: tuple[str, ...] = ()
    """The vehicles among ``ids`` with an AHRS output this tick, distinct: row ``j`` of
    ``q_ahrs_nav_body``."""
    q_ahrs_nav_body: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    """AHRS attitudes (M, 4), unit quaternions (x, y, z, w), of ``ahrs_ids`` (:attr:`Imu.q_ahrs_nav_body`)."""
    acc_body: np.ndarray | None = None
    """Measured specific forces (N, 3) [m/s^2] of every row, or ``None`` (gyro-only sensors)."""

    def __post_init__(self) -> None:
        ids = _vehicle_ids(self.ids, "ids", 1)
        ahrs = _vehicle_ids(self.ahrs_ids, "ahrs_ids", 0)
        gyro = _array(self.gyro_body, "gyro_body", (None, 3), max_rows=MAX_BATCH)
        q = _units(_array(self.q_ahrs_nav_body, "q_ahrs_nav_body", (None, 4), max_rows=MAX_BATCH),
                   "q_ahrs_nav_body")  # fmt: skip
        acc = _array(self.acc_body, "acc_body", (None, 3), nullable=True, max_rows=MAX_BATCH)
        _batch_rows(ids, ahrs, gyro, q, acc)
        _set(self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
             dt_s=_float(self.dt_s, "dt_s", positive=True), ids=ids, gyro_body=gyro, ahrs_ids=ahrs,
             q_ahrs_nav_body=q, acc_body=acc)  # fmt: skip

    def sample(self, vid: str, row: int | None = None) -> Imu | None:
        """Vehicle ``vid``'s :class:`Imu` (``row`` its row when known, :meth:`index`), ``None`` when the
        batch has none. Its arrays are copies of the batch's checked rows (not checked again)."""
        row = self._row(vid, row)
        if row is None:
            return None
        q = None
        if vid in self.ahrs_ids:
            q = self.q_ahrs_nav_body[self.ahrs_ids.index(vid)].copy()
        return _checked(Imu, {
            "tick": self.tick, "t_s": self.t_s, "dt_s": self.dt_s, "gyro_body": self.gyro_body[row].copy(),
            "q_ahrs_nav_body": q, "acc_body": None if self.acc_body is None else self.acc_body[row].copy(),
        })  # fmt: skip


def _batch_rows(ids: tuple, ahrs: tuple, gyro: np.ndarray, q: np.ndarray, acc: np.ndarray | None) -> None:
    """The checks of an :class:`ImuBatch` across its fields (rows against ids)."""
    if gyro.shape[0] != len(ids):
        raise MessageError(f"gyro_body: {gyro.shape[0]} rows for {len(ids)} ids")
    if acc is not None and acc.shape[0] != len(ids):
        raise MessageError(f"acc_body: {acc.shape[0]} rows for {len(ids)} ids")
    if q.shape[0] != len(ahrs):
        raise MessageError(f"q_ahrs_nav_body: {q.shape[0]} rows for {len(ahrs)} ahrs_ids")
    if ahrs and not set(ahrs) <= set(ids):
        stray = sorted(set(ahrs) - set(ids))
        raise MessageError(f"ahrs_ids: {_show(stray)} not among ids")


@dataclass(frozen=True, eq=False)
class Uwb(Message):
    """One two-way ranging exchange between a vehicle's tag and one anchor: ``<ns>/agent/<id>/uwb``."""

    tick: int
    """Tick ``k`` of the exchange (>= 0)."""
    t_s: float
    """Time of the exchange [s] (>= 0)."""
    anchor_id: int
    """Anchor ranged to (>= 0), an id of the :class:`Anchors` message."""
    range_m: float | None = None
    """Measured tag-anchor distance [m] (>= 0); ``None`` if the exchange happened but the reply was lost
    (one message per UWB slot either way, so a lockstep agent knows not to wait)."""

    def __post_init__(self) -> None:
        _set(
            self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
            anchor_id=_int(self.anchor_id, "anchor_id", 0, _MAX_ID),
            range_m=_float(self.range_m, "range_m", lo=0.0, nullable=True),
        )  # fmt: skip


def encode_uwb(tick: int, t_s: float, anchor_id: int, range_m: float | None) -> bytes:
    """``encode(Uwb(...))``, the same bytes, without building the message (the sender fast paths above)."""
    plain = (
        _is_tick(tick) and _is_time(t_s) and math.isfinite(t_s) and type(anchor_id) is int
        and 0 <= anchor_id <= _MAX_ID
        and (range_m is None or (type(range_m) is float and math.isfinite(range_m) and range_m >= 0.0))
    )  # fmt: skip
    if not plain:
        return encode(Uwb(tick, t_s, anchor_id, range_m))
    return _pack("Uwb", {"tick": tick, "t_s": t_s, "anchor_id": anchor_id, "range_m": range_m})


@dataclass(frozen=True, eq=False)
class UwbBatch(_Batch):
    """The :class:`Uwb` exchanges of many vehicles in one UWB slot, in one message: ``<ns>/mothership/uwb``,
    sent by a simulated radio network that serves agent hosts instead of one ``agent/<id>/uwb`` per vehicle
    (docs/protocol.md, "Rates"). Entry ``i`` of each list is vehicle ``ids[i]``'s; :meth:`sample` gives one
    vehicle's :class:`Uwb`."""

    tick: int
    """Tick ``k`` of the slot (>= 0), every exchange's."""
    t_s: float
    """Time of the slot [s] (>= 0), every exchange's."""
    ids: tuple[str, ...]
    """The vehicles, distinct, 1 to :data:`MAX_BATCH`."""
    anchor_ids: tuple[int, ...]
    """The anchor each vehicle ranged to (:attr:`Uwb.anchor_id`), one per id."""
    range_m: tuple[float | None, ...]
    """Each vehicle's measured distance [m] (>= 0), ``None`` where the reply was lost (``Uwb.range_m``)."""

    def __post_init__(self) -> None:
        ids = _vehicle_ids(self.ids, "ids", 1)
        anchors, ranges = _per_id(self.anchor_ids, "anchor_ids", ids), _per_id(self.range_m, "range_m", ids)
        _set(self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0), ids=ids,
             anchor_ids=tuple(_int(a, f"anchor_ids[{i}]", 0, _MAX_ID) for i, a in enumerate(anchors)),
             range_m=tuple(_float(r, f"range_m[{i}]", lo=0.0, nullable=True) for i, r in enumerate(ranges)),
             )  # fmt: skip

    def sample(self, vid: str, row: int | None = None) -> Uwb | None:
        """Vehicle ``vid``'s :class:`Uwb` (``row`` its entry when known, :meth:`index`), ``None`` when the
        batch has none (its values are the batch's checked ones, not checked again)."""
        row = self._row(vid, row)
        if row is None:
            return None
        values = {"tick": self.tick, "t_s": self.t_s, "anchor_id": self.anchor_ids[row],
                  "range_m": self.range_m[row]}  # fmt: skip
        return _checked(Uwb, values)


MAX_TDOA_ROWS = 1024
"""Most distance differences in one :class:`Tdoa` (a tag hears at most ~400 packets a second, the Loco
Positioning system's cap, so a UWB slot of 10 Hz or faster carries ~40)."""


def _anchor_list(value: object, name: str) -> tuple[int, ...]:
    """Anchor ids (0 to 2**31 - 1, repeats allowed), at most :data:`MAX_TDOA_ROWS`."""
    if not isinstance(value, list | tuple):
        raise MessageError(f"{name}: expected an array of anchor ids, got {_show(value)}")
    if len(value) > MAX_TDOA_ROWS:
        raise MessageError(f"{name}: {len(value)} entries, more than the {MAX_TDOA_ROWS} allowed")
    if all(type(v) is int and 0 <= v <= _MAX_ID for v in value):
        return tuple(value)
    return tuple(_int(v, f"{name}[{i}]", 0, _MAX_ID) for i, v in enumerate(value))


@dataclass(frozen=True, eq=False)
class Tdoa(Message):
    """The TDoA distance differences one vehicle's tag heard since the previous UWB slot (``uwb.mode``
    tdoa2/tdoa3: anchors transmit, the tag only listens): ``<ns>/agent/<id>/tdoa``. Row ``i`` is the
    difference ``ddist_m[i] = d(tag, anchor_b[i]) - d(tag, anchor_a[i])`` (the Crazyflie's
    ``distanceDiff``, in the order heard). One message per UWB slot, with no rows when the tag heard none,
    so a lockstep agent knows not to wait (as :class:`Uwb` with ``range_m`` nil)."""

    tick: int
    """Tick ``k`` of the UWB slot (>= 0)."""
    t_s: float
    """Time of the slot [s] (>= 0): the rows are those heard up to it."""
    anchor_a: tuple[int, ...] = ()
    """Each row's first anchor, an id of the :class:`Anchors` message (0 to 2**31 - 1)."""
    anchor_b: tuple[int, ...] = ()
    """Each row's second anchor, never the row's ``anchor_a``."""
    ddist_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Each row's distance difference (N,) [m], finite, any sign; the three fields have one entry per row,
    0 to :data:`MAX_TDOA_ROWS`."""

    def __post_init__(self) -> None:
        a, b = _anchor_list(self.anchor_a, "anchor_a"), _anchor_list(self.anchor_b, "anchor_b")
        dd = _array(self.ddist_m, "ddist_m", (None,), max_rows=MAX_TDOA_ROWS)
        if len(b) != len(a):
            raise MessageError(f"anchor_b: {len(b)} entries for {len(a)} in anchor_a")
        if dd.shape[0] != len(a):
            raise MessageError(f"ddist_m: {dd.shape[0]} entries for {len(a)} in anchor_a")
        for i, (ia, ib) in enumerate(zip(a, b, strict=True)):
            if ia == ib:
                raise MessageError(f"anchor_b[{i}]: the same anchor as anchor_a[{i}] ({ia})")
        _set(self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0), anchor_a=a, anchor_b=b,
             ddist_m=dd)  # fmt: skip

    def rows(self) -> np.ndarray:
        """The differences as the agent step takes them (:attr:`swarm.step.agent.AgentInputs.tdoa`): (N, 3)
        float64, anchor ``A``, anchor ``B``, ``ddist_m``."""
        out = np.empty((len(self.anchor_a), 3))
        out[:, 0], out[:, 1], out[:, 2] = self.anchor_a, self.anchor_b, self.ddist_m
        return out


def encode_tdoa(tick: int, t_s: float, rows: np.ndarray) -> bytes:
    """``encode(Tdoa(...))`` of ``rows`` (N, 3) (anchor ``A``, anchor ``B``, ``ddist_m``: the radio step's
    :class:`swarm.step.radio.TdoaSample` rows, whose anchor columns hold whole numbers)."""
    r = np.asarray(rows, dtype=np.float64).reshape(-1, 3)
    a = tuple(int(x) for x in r[:, 0].tolist()) if np.all(r[:, 0] == np.round(r[:, 0])) else r[:, 0].tolist()
    b = tuple(int(x) for x in r[:, 1].tolist()) if np.all(r[:, 1] == np.round(r[:, 1])) else r[:, 1].tolist()
    return encode(Tdoa(tick, t_s, a, b, np.ascontiguousarray(r[:, 2])))


@dataclass(frozen=True, eq=False)
class TdoaBatch(_Batch):
    """The :class:`Tdoa` messages of many vehicles in one UWB slot, in one message: ``<ns>/mothership/tdoa``,
    sent by a simulated radio network that serves agent hosts instead of one ``agent/<id>/tdoa`` per
    vehicle (docs/protocol.md, "Rates"). A tag's count of rows varies, so each entry is the message as its
    own key would carry it (the msgpack bytes of a :class:`Tdoa`), as in a :class:`VisionBatch`."""

    tick: int
    """Tick ``k`` of the slot (>= 0), every entry's."""
    t_s: float
    """Time of the slot [s] (>= 0), every entry's."""
    ids: tuple[str, ...]
    """The vehicles, distinct, 1 to :data:`MAX_BATCH`: entry ``i`` of ``differences`` is ``ids[i]``'s."""
    differences: tuple[bytes, ...]
    """Each vehicle's encoded :class:`Tdoa` (msgpack bin), one per id; the whole message stays within
    :data:`MAX_PAYLOAD_BYTES`."""

    def __post_init__(self) -> None:
        ids = _vehicle_ids(self.ids, "ids", 1)
        blobs = _blobs(_per_id(self.differences, "differences", ids), "differences", "Tdoa")
        _set(self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0), ids=ids,
             differences=blobs)  # fmt: skip

    def sample(self, vid: str, row: int | None = None) -> Tdoa | None:
        """Vehicle ``vid``'s :class:`Tdoa`, decoded and checked as its own key's would be, ``None`` when the
        batch has none; MessageError naming the entry (``differences[3]: ...``) for one that does not
        decode, or whose tick or time is not the batch's."""
        row = self._row(vid, row)
        if row is None:
            return None
        msg = _entry(self.differences, "differences", row, Tdoa)
        if msg.tick != self.tick or msg.t_s != self.t_s:
            raise MessageError(f"differences[{row}]: tick {msg.tick} at {msg.t_s} s in the batch of tick "
                               f"{self.tick} at {self.t_s} s")  # fmt: skip
        return msg


def _per_id(value: object, name: str, ids: tuple) -> list | tuple:
    if not isinstance(value, list | tuple):
        raise MessageError(f"{name}: expected an array, got {_show(value)}")
    if len(value) != len(ids):
        raise MessageError(f"{name}: {len(value)} entries for {len(ids)} ids")
    return value


@dataclass(frozen=True, eq=False)
class Gnss(Message):
    """A satellite receiver's position fix of one vehicle: ``<ns>/agent/<id>/gnss`` (the landing's UAVs)."""

    tick: int
    """Tick ``k`` of the fix (>= 0)."""
    t_s: float
    """Time of the fix [s] (>= 0)."""
    p_nav: np.ndarray
    """Antenna position (3,) [m], frame nav."""
    cov: np.ndarray
    """Its covariance (3, 3) [m^2]: symmetric, non-negative diagonal."""

    def __post_init__(self) -> None:
        _set(
            self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
            p_nav=_array(self.p_nav, "p_nav", (3,)), cov=_cov(self.cov, "cov", 3),
        )  # fmt: skip


@dataclass(frozen=True, eq=False)
class Rangefinder(Message):
    """A downward distance sensor's reading of one vehicle: ``<ns>/agent/<id>/rangefinder`` (the landing's
    UAVs; PX4's ``distance_sensor``): the distance along the body's ``-z`` axis to the ground."""

    tick: int
    """Tick ``k`` of the reading (>= 0)."""
    t_s: float
    """Time of the reading [s] (>= 0)."""
    range_m: float | None
    """The distance [m] (>= 0); ``None`` when the sensor has no reading (the ground out of its reach, or the
    vehicle too tilted): one message per rangefinder tick either way, so a lockstep agent knows not to
    wait."""
    sigma_m: float
    """The reading's standard deviation [m] (> 0), the sensor's claim."""

    def __post_init__(self) -> None:
        _set(
            self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
            range_m=_float(self.range_m, "range_m", lo=0.0, nullable=True),
            sigma_m=_float(self.sigma_m, "sigma_m", positive=True),
        )  # fmt: skip


@dataclass(frozen=True, eq=False)
class Barometer(Message):
    """A barometric altimeter's reading of one vehicle: ``<ns>/agent/<id>/barometer`` (a log's ``baro.csv``;
    PX4's ``vehicle_air_data.baro_alt_meter``, a Crazyflie's ``baro.asl``): the altitude, up, on the
    sensor's own datum, so with any constant offset from the nav frame's height (a receiver estimates it)."""

    tick: int
    """Tick ``k`` of the reading (>= 0)."""
    t_s: float
    """Time of the reading [s] (>= 0)."""
    height_m: float | None
    """Barometric altitude, up, with any constant offset [m] (finite, any sign); ``None`` when the sensor
    has no reading, so a lockstep agent knows not to wait."""
    sigma_m: float
    """The reading's standard deviation [m] (> 0), the sensor's claim."""

    def __post_init__(self) -> None:
        _set(
            self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
            height_m=_float(self.height_m, "height_m", nullable=True),
            sigma_m=_float(self.sigma_m, "sigma_m", positive=True),
        )  # fmt: skip


@dataclass(frozen=True, eq=False)
class Vision(Message):
    """One camera frame's observations of the target's markers: ``<ns>/agent/<id>/vision``."""

    tick: int
    """Tick ``k`` of the frame (>= 0)."""
    t_s: float
    """Exposure time [s] (>= 0)."""
    target_id: str
    """Agent id of the vehicle whose markers were seen."""
    face: str
    """Face of the target the markers belong to, one of :data:`FACES`."""
    kind: str
    """``"features"``: marker positions in the camera frame [m] (the paper's feature model);
    ``"pixels"``: marker image coordinates [px] (the agent runs PnP); ``"pose"``: the target's pose in the
    camera frame from a camera that runs PnP itself, with its covariance."""
    data: np.ndarray
    """(N, 3) [m] in the OpenCV camera frame (+z optical axis, +x right, +y down) for ``features``;
    (N, 2) [px] image coordinates (u right, v down, as ``cv2.projectPoints`` gives them) for ``pixels``.
    Row i is marker ``marker_ids[i]``; 0 <= N <= :data:`MAX_ITEMS`. For ``pose``, (N, 43) with N <= 1:
    the target origin in the camera frame ``t_cam_m`` (3) [m], the attitude ``q_cam_target`` (4,
    scalar-last) and the covariance (6 x 6, row-major) of ``(dt_cam [m], dphi_cam [rad])``
    (``swarm.core.camera``). N = 0 is a frame in which no marker was detected: a camera reports every
    frame, so a lockstep agent knows the frame of its camera tick is complete (``docs/protocol.md``,
    "Clocks and lockstep")."""
    marker_ids: tuple[int, ...]
    """Index of each row's marker in the face's pattern (>= 0, distinct), N entries; for ``pose``, the
    markers the pose was computed from (empty when N = 0)."""

    @property
    def seen(self) -> bool:
        """Whether any marker was detected in this frame."""
        return len(self.marker_ids) > 0

    def __post_init__(self) -> None:
        kind = _str(self.kind, "kind", choices=VISION_KINDS)
        width = {"features": 3, "pixels": 2, "pose": POSE_LEN}[kind]
        data = _array(self.data, "data", (None, width))
        ids = _ids(self.marker_ids, "marker_ids", min_len=0)
        _frame(kind, data, ids)
        _set(
            self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
            target_id=_str(self.target_id, "target_id", pattern=ID_PATTERN),
            face=_str(self.face, "face", choices=FACES), kind=kind, data=data, marker_ids=ids,
        )  # fmt: skip


_VISION_WIDTH = {"features": 3, "pixels": 2}  # the kinds with a row per marker (a pose: the message decides)


def encode_vision(tick: int, t_s: float, target_id: str, face: str, kind: str, data, marker_ids) -> bytes:
    """``encode(Vision(...))``, the same bytes, without building the message: the world's camera frames,
    64 per camera tick at 128 vehicles (the sender fast paths above). The common case, marker features or
    pixels as a finite float64 array of a row per id, ids distinct plain ints, is checked here in a few
    operations; anything else (a pose, whose covariance the message checks) goes through the message."""
    width = _VISION_WIDTH.get(kind) if type(kind) is str else None
    plain = (
        width is not None and _is_tick(tick) and _is_time(t_s) and type(data) is np.ndarray
        and data.dtype == _F64 and data.ndim == 2 and data.shape[1] == width and data.shape[0] <= MAX_ITEMS
        and type(marker_ids) is tuple and len(marker_ids) == data.shape[0] and type(face) is str
        and face in FACES and type(target_id) is str and len(target_id) <= _MAX_NAME
        and ID_PATTERN.fullmatch(target_id) is not None
        and all(type(i) is int and 0 <= i <= _MAX_ID for i in marker_ids)
        and len(set(marker_ids)) == len(marker_ids) and math.isfinite(t_s + _total(data))
    )  # fmt: skip
    if not plain:
        return encode(Vision(tick, t_s, target_id, face, kind, data, marker_ids))
    wire = {"tick": tick, "t_s": t_s, "target_id": target_id, "face": face, "kind": kind, "data": data,
            "marker_ids": marker_ids}  # fmt: skip
    return _pack("Vision", wire)


@dataclass(frozen=True, eq=False)
class VisionBatch(_Batch):
    """The camera frames of many vehicles at one tick, in one message: ``<ns>/world/vision``, sent by a
    simulated world that serves agent hosts instead of one ``agent/<id>/vision`` per chaser (docs/protocol.md,
    "Rates"). A frame's size depends on its kind and on what its camera saw, so each entry is the frame
    as its own key would carry it: the msgpack bytes of a :class:`Vision` (a map, the same fields and checks),
    and a receiver decodes only the entries of its vehicles (:meth:`sample`)."""

    tick: int
    """Tick ``k`` of the camera slot (>= 0), every frame's."""
    t_s: float
    """Exposure time [s] (>= 0), every frame's."""
    ids: tuple[str, ...]
    """The vehicles, distinct, 1 to :data:`MAX_BATCH`: entry ``i`` of ``frames`` is ``ids[i]``'s."""
    frames: tuple[bytes, ...]
    """Each vehicle's frame, an encoded :class:`Vision` (msgpack bin), one per id; the whole message stays
    within :data:`MAX_PAYLOAD_BYTES`."""

    def __post_init__(self) -> None:
        ids = _vehicle_ids(self.ids, "ids", 1)
        frames = _blobs(_per_id(self.frames, "frames", ids), "frames", "Vision")
        _set(self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0), ids=ids, frames=frames)

    def sample(self, vid: str, row: int | None = None) -> Vision | None:
        """Vehicle ``vid``'s :class:`Vision` (``row`` its entry when known, :meth:`index`), decoded and
        checked as its own key's would be, ``None`` when the batch has none. MessageError naming the entry
        (``frames[3]: ...``) for a frame that does not decode, or whose tick or time is not the batch's."""
        row = self._row(vid, row)
        if row is None:
            return None
        frame = _entry(self.frames, "frames", row, Vision)
        if frame.tick != self.tick or frame.t_s != self.t_s:
            raise MessageError(f"frames[{row}]: tick {frame.tick} at {frame.t_s} s in the batch of tick "
                               f"{self.tick} at {self.t_s} s")  # fmt: skip
        return frame


def batch_rows(
    batch: _Batch, key: str, drops: DropCounter, ids: Container[str] | None = None
) -> list[tuple[str, Message]]:
    """Each vehicle's message of ``batch`` (of the vehicles in ``ids``; ``None``: every one), as ``(vehicle,
    message)`` in the batch's order: an entry that does not decode (a :class:`VisionBatch`'s or
    :class:`CommandBatch`'s, whose entries are decoded here) is dropped and counted in ``drops`` under
    ``key``, naming the vehicle and the entry, and the others are kept: one vehicle's bad entry loses no
    other vehicle's."""
    out = []
    for row, vid in enumerate(batch.ids):
        if ids is not None and vid not in ids:
            continue
        try:
            out.append((vid, batch.sample(vid, row)))
        except MessageError as exc:
            drops.drop(key, f"{vid}: {exc}")
    return out


_BATCH_ENVELOPE = 96
"""A :class:`VisionBatch`'s or :class:`CommandBatch`'s bytes besides its entries, at most: the map's keys,
the type's name, a tick and a time, the two lists' headers (~60) [bytes]."""


def _spans(entries: Sequence[tuple], distinct: bool) -> list[tuple[int, int]]:
    """``(label, encoded message, ...)`` entries, in order, cut into as few runs ``entries[a:b]`` as keep
    each message of them within :data:`MAX_PAYLOAD_BYTES` and :data:`MAX_BATCH` entries (``distinct``: a
    label at most once per run). The packing of :func:`pack_entries` and :func:`pack_bundle`."""
    spans: list[tuple[int, int]] = []
    start, size, labels = 0, _BATCH_ENVELOPE, set()
    for i, (label, payload, *_) in enumerate(entries):
        row = len(payload) + len(label) + 8  # the bin and str headers of the entry and its label
        if i > start and (size + row > MAX_PAYLOAD_BYTES or i - start == MAX_BATCH or label in labels):
            spans.append((start, i))
            start, size, labels = i, _BATCH_ENVELOPE, set()
        size += row
        if distinct:
            labels.add(label)
    if start < len(entries):
        spans.append((start, len(entries)))
    return spans


def pack_entries(entries: list[tuple[str, bytes]], make: Callable[[tuple, tuple], Message]) -> list[bytes]:
    """``(vehicle, encoded message)`` entries, in order, in as few batch messages (``make(ids, payloads)``:
    a :class:`VisionBatch` or :class:`CommandBatch`) as keep each within :data:`MAX_PAYLOAD_BYTES` and
    :data:`MAX_BATCH` vehicles, a vehicle at most once per message (a host that caught up on two of its
    ticks in one round sends the second command in the next message, after the first)."""
    out = []
    for a, b in _spans(entries, distinct=True):
        ids, blobs = zip(*entries[a:b], strict=True)
        out.append(encode(make(ids, blobs)))
    return out


def _blobs(entries: list | tuple, name: str, what: str) -> tuple[bytes, ...]:
    """A batch's entries ``name``: the bytes of a ``what`` message each (decoded by :func:`_entry`)."""
    for i, f in enumerate(entries):
        if type(f) is not bytes:
            raise MessageError(f"{name}[{i}]: expected the bytes of a {what} message, got {_show(f)}")
    return tuple(entries)


def _entry(blobs: tuple[bytes, ...], name: str, row: int, cls: type[M]) -> M:
    """Entry ``row`` of a batch's ``name``, decoded and checked as a ``cls`` message of its own key;
    MessageError naming the entry (``frames[3]: ...``)."""
    try:
        return decode(blobs[row], cls)
    except MessageError as exc:
        raise MessageError(f"{name}[{row}]: {exc}") from None


@dataclass(frozen=True, eq=False)
class CommandBatch(_Batch):
    """The commands an agent host's vehicles decided in one of its rounds, in one message:
    ``<ns>/agent/<id>/commands`` (``<id>`` the host's first vehicle), what a free-running host of several
    vehicles sends the world instead of one ``agent/<id>/command`` each (docs/protocol.md, "Rates"). Entry
    ``i`` is vehicle ``ids[i]``'s command as its own key would carry it, the msgpack bytes of a
    :class:`Command` (a vehicle's kind fixes its actuators' count, and the entries of one round may be of
    different ticks)."""

    ids: tuple[str, ...]
    """The vehicles, distinct, 1 to :data:`MAX_BATCH`: entry ``i`` of ``commands`` is ``ids[i]``'s."""
    commands: tuple[bytes, ...]
    """Each vehicle's command, an encoded :class:`Command` (msgpack bin), one per id."""

    def __post_init__(self) -> None:
        ids = _vehicle_ids(self.ids, "ids", 1)
        commands = _blobs(_per_id(self.commands, "commands", ids), "commands", "Command")
        _set(self, ids=ids, commands=commands)

    def sample(self, vid: str, row: int | None = None) -> Command | None:
        """Vehicle ``vid``'s :class:`Command`, decoded and checked as its own key's would be, ``None`` when
        the batch has none; MessageError naming the entry (``commands[3]: ...``) if it does not decode."""
        row = self._row(vid, row)
        return None if row is None else _entry(self.commands, "commands", row, Command)


BUNDLE_TYPES: tuple[str, ...] = ("Imu", "Uwb", "Vision", "TruthBatch", "Tdoa")
"""The messages a :class:`Bundle` may carry: a lockstep tick's samples (docs/protocol.md, "Bundles")."""


@dataclass(frozen=True, eq=False)
class Bundle(Message):
    """The samples of several consecutive lockstep ticks for one receiver, in one message: what a lockstep
    world sends on ``<ns>/agent/<id>/bundle`` (that vehicle's ``imu`` and ``vision``) and
    ``<ns>/world/bundle`` (the ``world/truth`` batches, for the mothership), and the mothership on
    ``<ns>/agent/<id>/bundle`` (that vehicle's ``uwb``), instead of one message per sample (docs/protocol.md,
    "Bundles"). Entry ``i`` is the message its own key would have carried, type ``types[i]``: its msgpack
    bytes, decoded and checked by the receiver (:func:`bundle_messages`), in the order they would have been
    published."""

    tick: int
    """The newest tick of any entry (>= 0)."""
    types: tuple[str, ...]
    """Each entry's message type, one of :data:`BUNDLE_TYPES`."""
    entries: tuple[bytes, ...]
    """The entries, 1 to :data:`MAX_BATCH`, one per type: each an encoded message (msgpack bin); the whole
    message stays within :data:`MAX_PAYLOAD_BYTES`."""

    def __post_init__(self) -> None:
        types = _bundle_types(self.types)
        if not isinstance(self.entries, list | tuple) or len(self.entries) != len(types):
            raise MessageError(f"entries: expected one per type ({len(types)}), got {_show(self.entries)}")
        entries = _blobs(self.entries, "entries", "wire")
        _set(self, tick=_int(self.tick, "tick"), types=types, entries=entries)


def _bundle_types(value: object) -> tuple[str, ...]:
    if not isinstance(value, list | tuple) or not 1 <= len(value) <= MAX_BATCH:
        raise MessageError(f"types: expected 1 to {MAX_BATCH} message types, got {_show(value)}")
    for i, t in enumerate(value):
        if t not in BUNDLE_TYPES:
            raise MessageError(f"types[{i}]: expected one of {', '.join(BUNDLE_TYPES)}, got {_show(t)}")
    return tuple(value)


def bundle_messages(
    bundle: Bundle, key: str, drops: DropCounter, accept: Container[str] = BUNDLE_TYPES
) -> list[Message]:
    """The entries of ``bundle`` whose type is in ``accept``, each decoded and checked as its own key's
    would be, in the bundle's order. An entry that does not decode, or whose tick is later than the
    bundle's, is dropped and counted in ``drops`` under ``key`` naming the entry (``entries[3]: ...``), and
    the others are kept: one bad entry loses no other sample. An entry of another type is skipped (a viewer
    that draws frames only takes the ``Vision`` entries)."""
    out: list[Message] = []
    for i, (name, blob) in enumerate(zip(bundle.types, bundle.entries, strict=True)):
        if name not in accept:
            continue
        try:
            msg = decode(blob, MESSAGE_TYPES[name])
        except MessageError as exc:
            drops.drop(key, f"entries[{i}]: {exc}")
            continue
        if msg.tick > bundle.tick:  # type: ignore[attr-defined]
            drops.drop(key, f"entries[{i}]: tick {msg.tick} after the bundle's {bundle.tick}")  # type: ignore[attr-defined]
            continue
        out.append(msg)
    return out


def pack_bundle(entries: list[tuple[str, bytes, int]]) -> list[bytes]:
    """``(type, encoded message, tick)`` entries, in order, in as few :class:`Bundle` messages as keep each
    within :data:`MAX_PAYLOAD_BYTES` and :data:`MAX_BATCH` entries (each message's ``tick`` its newest)."""
    out = []
    for a, b in _spans(entries, distinct=False):
        types, blobs, ticks = zip(*entries[a:b], strict=True)
        out.append(encode(Bundle(max(ticks), types, blobs)))
    return out


@dataclass(frozen=True, eq=False)
class Estimate(Message):
    """The pose estimate of one vehicle after tick ``k``'s measurements: ``<ns>/agent/<id>/estimate``."""

    tick: int
    """Tick ``k`` of the last measurement processed (>= 0)."""
    t_s: float
    """Time of the estimate [s] (>= 0)."""
    p_nav: np.ndarray
    """Centre-of-mass position (3,) [m], frame nav."""
    v_nav: np.ndarray
    """Centre-of-mass velocity (3,) [m/s], frame nav."""
    q_nav_body: np.ndarray
    """Attitude (4,), unit quaternion (x, y, z, w) mapping body into nav."""
    cov: np.ndarray
    """Error-state covariance (9, 9) of ``(d_p [m], d_v [m/s], d_theta [rad])``, ``d_theta`` a body-frame
    rotation vector (``q = q_est (x) exp(d_theta)``); symmetric, non-negative diagonal. The tandem
    filter's cross terms between translation and attitude are zero. While a chaser navigates relative to
    its target (vision), the position block includes the target's estimate covariance: its position in nav
    is known only as well as the target's (``swarm.step.agent.absolute_cov_pos``)."""
    sigma_pos_max_m: float
    """Largest position standard deviation [m] (>= 0), Algorithm 1's ``max(sigma_pos)``."""
    mahalanobis_d: float
    """Mahalanobis distance of the latest innovation (>= 0, dimensionless), Algorithm 1's ``d``."""
    rejection_fraction: float
    """Fraction of measurements rejected by the gate over the health window, in [0, 1]."""
    counts: dict[str, int]
    """Cumulative update counters (>= 0) named ``<kind>_<outcome>``, e.g. ``range_accepted``,
    ``range_rejected``, ``features_refused``; at most :data:`MAX_ITEMS` entries."""

    def __post_init__(self) -> None:
        rf = _float(self.rejection_fraction, "rejection_fraction", lo=0.0)
        if rf > 1.0:
            raise MessageError(f"rejection_fraction: must be in [0, 1], got {rf}")
        _set(
            self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
            p_nav=_array(self.p_nav, "p_nav", (3,)), v_nav=_array(self.v_nav, "v_nav", (3,)),
            q_nav_body=_quat(self.q_nav_body, "q_nav_body"), cov=_cov(self.cov, "cov", 9),
            sigma_pos_max_m=_float(self.sigma_pos_max_m, "sigma_pos_max_m", lo=0.0),
            mahalanobis_d=_float(self.mahalanobis_d, "mahalanobis_d", lo=0.0),
            rejection_fraction=rf, counts=_counts(self.counts, "counts"),
        )  # fmt: skip


def estimate_message(*args) -> Estimate:
    """``Estimate(*args)``, or, when its covariance (``args[5]``) is off symmetry by rounding only, the same
    with the covariance's symmetric part: what a filter publishes after an update."""
    try:
        return Estimate(*args)
    except MessageError:
        cov = np.asarray(args[5])
        return Estimate(*args[:5], 0.5 * (cov + cov.T), *args[6:])


_ESTIMATE_SHAPES = ((3,), (3,), (4,), (9, 9))


def _estimate_arrays(p, v, q, cov) -> int:
    """:func:`swarm.transport._codec_nb.estimate_arrays`' verdict, loaded on first use (numba)."""
    global _ESTIMATE_ARRAYS
    if _ESTIMATE_ARRAYS is None:
        from swarm.transport._codec_nb import estimate_arrays

        _ESTIMATE_ARRAYS = estimate_arrays
    return _ESTIMATE_ARRAYS(p, v, q, cov, COV_SYMMETRY_RTOL, QUAT_NORM_TOL)


_ESTIMATE_ARRAYS = None
_PLAIN, _SYMMETRIZE = 0, 1  # _codec_nb's verdicts (its module is not imported until the first estimate)


def _estimate_verdict(tick, t_s, p, v, q, cov, sigma, d, rf, counts) -> int | None:
    """:func:`encode_estimate`'s common case: ``_PLAIN``, ``_SYMMETRIZE`` (the covariance is off symmetry by
    rounding only: send its symmetric part, as :func:`estimate_message` does), or ``None`` (the reference
    path decides)."""
    if not all(_is_f64(a, shape) for a, shape in zip((p, v, q, cov), _ESTIMATE_SHAPES, strict=True)):
        return None
    if not (_is_int(tick) and tick >= 0 and len(counts) <= MAX_ITEMS and _is_real(rf) and rf <= 1.0):
        return None
    if not all(_is_real(x) and math.isfinite(x) and x >= 0.0 for x in (t_s, sigma, d, rf)):
        return None
    if not all(type(c) is int and c >= 0 and type(n) is str and ID_PATTERN.fullmatch(n)
               for n, c in counts.items()):  # fmt: skip
        return None
    verdict = _estimate_arrays(p, v, q, cov)
    return verdict if verdict in (_PLAIN, _SYMMETRIZE) else None


def _plain_estimate(args: tuple) -> dict[str, Any] | None:
    """The fields of the estimate ``args`` (:func:`encode_estimate`'s) in the common case, checked in a few
    operations, with the covariance's symmetric part where it is off symmetry by rounding; else ``None``."""
    verdict = _estimate_verdict(*args)
    if verdict is None:
        return None
    tick, t_s, p_nav, v_nav, q_nav_body, cov, sigma, d, rf, counts = args
    if verdict == _SYMMETRIZE:
        cov = 0.5 * (cov + cov.T)  # off symmetry by rounding only: its symmetric part (estimate_message)
    return {
        "tick": int(tick), "t_s": float(t_s), "p_nav": p_nav, "v_nav": v_nav, "q_nav_body": q_nav_body,
        "cov": cov, "sigma_pos_max_m": float(sigma), "mahalanobis_d": float(d),
        "rejection_fraction": float(rf), "counts": dict(counts),
    }  # fmt: skip


def encode_estimate(
    tick: int, t_s: float, p_nav, v_nav, q_nav_body, cov, sigma_pos_max_m: float, mahalanobis_d: float,
    rejection_fraction: float, counts: dict[str, int],
) -> bytes:  # fmt: skip
    """``encode(estimate_message(...))``, the same bytes, without building the message: what an agent sends
    every tick (its estimate, 1 kB, was a third of an agent host's CPU). The common case, float64 arrays of
    the right shapes with finite entries, a unit quaternion, a covariance symmetric to rounding with a
    non-negative diagonal, in-range numbers and plain counters, is checked here in a few array operations;
    anything else goes through :func:`estimate_message`, which raises the MessageError naming the field."""
    args = (tick, t_s, p_nav, v_nav, q_nav_body, cov, sigma_pos_max_m, mahalanobis_d, rejection_fraction,
            counts)  # fmt: skip
    f = _plain_estimate(args)
    return encode(estimate_message(*args)) if f is None else _pack("Estimate", f)


def estimate_and_payload(
    tick: int, t_s: float, p_nav, v_nav, q_nav_body, cov, sigma_pos_max_m: float, mahalanobis_d: float,
    rejection_fraction: float, counts: dict[str, int], *, payload: bool = True,
) -> tuple[Estimate, bytes | None]:  # fmt: skip
    """:func:`encode_estimate`'s bytes and the message a receiver decodes from them (its arrays copies), for
    a receiver in the same process: an agent host hands a target's estimate to its chaser without the
    decoding (``agents.host``), which was ~20 us of the chaser's tick. ``payload=False``: the message
    alone (``None`` for the bytes), when no one else subscribes."""
    args = (tick, t_s, p_nav, v_nav, q_nav_body, cov, sigma_pos_max_m, mahalanobis_d, rejection_fraction,
            counts)  # fmt: skip
    f = _plain_estimate(args)
    if f is None:
        msg = estimate_message(*args)
        return msg, encode(msg) if payload else None
    data = _pack("Estimate", f) if payload else None
    for name in ("p_nav", "v_nav", "q_nav_body", "cov"):
        f[name] = np.array(f[name], dtype=np.float64)  # a copy, as decoding makes: the sender's move on
    return _checked(Estimate, f), data  # checked above, as the fast decoding leaves it


@dataclass(frozen=True, eq=False)
class Guidance(Message):
    """Guidance state of one vehicle after tick ``k``: ``<ns>/agent/<id>/guidance``."""

    tick: int
    """Tick ``k`` (>= 0)."""
    t_s: float
    """Time [s] (>= 0)."""
    mode: str
    """Current guidance mode, one of :data:`MODES`."""
    range_m: float | None = None
    """Estimated range to the target [m] (>= 0); ``None`` without a target (the station keeper)."""
    r1_m: float | None = None
    """REORIENT -> ALIGN switch radius [m] (>= 0); ``None`` for a vehicle without a switcher."""
    r2_m: float | None = None
    """APPROACH -> REORIENT switch radius [m] (>= 0); ``None`` for a vehicle without a switcher."""
    r_t_m: float | None = None
    """Radius below which Algorithm 1 runs [m] (>= 0); ``None`` for a vehicle without a switcher."""
    decision: dict[str, float | None] | None = None
    """Latest Algorithm 1 pass: exactly the 17 keys of swarm/core/decision_keys.py
    (``swarm.core.decision_keys.DECISION_KEYS``), numbers >= 0, ``A11 A22 A23 A32 A33 pi1 pi2``
    probabilities in [0, 1] or ``None`` where the branch did not compute them; other keys are dropped.
    ``None`` when no pass happened yet (or the fixed policy)."""
    reason: str = ""
    """Human-readable account of the latest mode decision (at most 1024 characters)."""

    def __post_init__(self) -> None:
        _set(
            self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
            mode=_str(self.mode, "mode", choices=MODES),
            range_m=_float(self.range_m, "range_m", lo=0.0, nullable=True),
            r1_m=_float(self.r1_m, "r1_m", lo=0.0, nullable=True),
            r2_m=_float(self.r2_m, "r2_m", lo=0.0, nullable=True),
            r_t_m=_float(self.r_t_m, "r_t_m", lo=0.0, nullable=True),
            decision=_decision(self.decision, "decision"),
            reason=_str(self.reason, "reason", max_len=_MAX_TEXT),
        )  # fmt: skip


@dataclass(frozen=True, eq=False)
class Command(Message):
    """Actuator command of one vehicle for tick ``k``, held until the next: ``<ns>/agent/<id>/command``."""

    tick: int
    """Tick ``k`` this command answers (>= 0): in lockstep the world steps to ``k + 1`` once it has it."""
    t_s: float
    """Time [s] (>= 0)."""
    actuators: np.ndarray
    """The vehicle kind's actuator command (N,), 0 <= N <= :data:`MAX_ITEMS`, finite, in the kind's order
    and units: a ``cubesat``'s ten nozzle thrusts [N] (>= 0), a ``ground`` module's four wheel speeds
    [rad/s] (front-left, front-right, rear-right, rear-left). The world holds it until the next command and
    brings it into the actuators' range (a nozzle cannot pull, a wheel cannot pass its top speed); a
    command of the wrong length for the vehicle's kind is dropped and counted."""
    mode: str
    """Guidance mode that produced it, one of :data:`MODES`."""
    force_body_n: np.ndarray | None = None
    """Net force the command produces (3,) [N], body frame, where the kind has one (the nozzles)."""
    torque_body_nm: np.ndarray | None = None
    """Net torque about the centre of mass (3,) [N m], body frame, where the kind has one."""

    def __post_init__(self) -> None:
        _set(
            self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
            actuators=_array(self.actuators, "actuators", (None,)),
            mode=_str(self.mode, "mode", choices=MODES),
            force_body_n=_array(self.force_body_n, "force_body_n", (3,), nullable=True),
            torque_body_nm=_array(self.torque_body_nm, "torque_body_nm", (3,), nullable=True),
        )  # fmt: skip


def _command_is_plain(tick, t_s, actuators, mode, force, torque) -> bool:
    """Whether :func:`encode_command`'s arguments are the common case it checks in a few operations."""
    if not (_is_tick(tick) and _is_time(t_s)):
        return False
    if not (type(mode) is str and mode in MODES):
        return False
    a = actuators
    if not (type(a) is np.ndarray and a.dtype == _F64 and a.ndim == 1 and a.shape[0] <= MAX_ITEMS):
        return False
    total = t_s + _total(a)
    for v in (force, torque):
        if v is not None:
            if not _is_f64(v, (3,)):
                return False
            total += _total(v)
    # a sum is finite only if every entry is (a NaN or an infinity carries through; a finite sum too large
    # to hold goes the reference way, which decides exactly)
    return math.isfinite(total)


def encode_command(
    tick: int, t_s: float, actuators, mode: str, force_body_n=None, torque_body_nm=None
) -> bytes:
    """``encode(Command(...))``, the same bytes, without building the message: what an agent sends every
    tick. The common case (a plain int tick, a float time, float64 arrays of the right shapes with finite
    entries, a known mode) is checked here in a few operations; anything else goes through
    :class:`Command`, which raises the MessageError naming the field."""
    if not _command_is_plain(tick, t_s, actuators, mode, force_body_n, torque_body_nm):
        return encode(Command(tick, t_s, actuators, mode, force_body_n, torque_body_nm))
    wire = {"tick": tick, "t_s": t_s, "actuators": actuators, "mode": mode, "force_body_n": force_body_n,
            "torque_body_nm": torque_body_nm}  # fmt: skip
    return _pack("Command", wire)


@dataclass(frozen=True, eq=False)
class Truth(Message):
    """True state of one vehicle at tick ``k`` (agents never subscribe): ``<ns>/agent/<id>/truth``."""

    tick: int
    """Tick ``k`` (>= 0)."""
    t_s: float
    """Time [s] (>= 0)."""
    p_nav: np.ndarray
    """Centre-of-mass position (3,) [m], frame nav."""
    v_nav: np.ndarray
    """Centre-of-mass velocity (3,) [m/s], frame nav."""
    q_nav_body: np.ndarray
    """Attitude (4,), unit quaternion (x, y, z, w) mapping body into nav."""
    w_body: np.ndarray
    """Angular rate (3,) [rad/s], body frame."""
    effort: float = 0.0
    """The vehicle's effort since the run began (>= 0), in its kind's measure: a ``cubesat``'s total impulse
    ``sum |f| dt`` [N s], a ``ground`` module's wheel travel ``sum |omega| dt`` [rad]."""
    uwb_lost: bool = False
    """The radio environment of the vehicle's UWB tag at tick ``k``: every reply lost (a dropout window of
    the world's fault schedule). The mothership's simulated radios apply it to the exchange of this tick."""
    nlos_probability: float = 0.0
    """... and the NLOS outlier probability of an exchange inside a burst window, in [0, 1] (0: none; the
    radio's own ``uwb.nlos_probability`` applies anyway)."""

    def __post_init__(self) -> None:
        p = _float(self.nlos_probability, "nlos_probability", lo=0.0)
        if p > 1.0:
            raise MessageError(f"nlos_probability: must be in [0, 1], got {p}")
        _set(
            self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
            p_nav=_array(self.p_nav, "p_nav", (3,)), v_nav=_array(self.v_nav, "v_nav", (3,)),
            q_nav_body=_quat(self.q_nav_body, "q_nav_body"), w_body=_array(self.w_body, "w_body", (3,)),
            effort=_float(self.effort, "effort", lo=0.0), uwb_lost=_bool(self.uwb_lost, "uwb_lost"),
            nlos_probability=p,
        )  # fmt: skip


_TRUTH_FIELDS = ("tick", "t_s", "p_nav", "v_nav", "q_nav_body", "w_body", "effort", "uwb_lost",
                 "nlos_probability")  # fmt: skip


def encode_truth(
    tick: int, t_s: float, p_nav, v_nav, q_nav_body, w_body, effort: float = 0.0, uwb_lost: bool = False,
    nlos_probability: float = 0.0,
) -> bytes:  # fmt: skip
    """``encode(Truth(...))``, the same bytes, without building the message (the sender fast paths above)."""
    args = (tick, t_s, p_nav, v_nav, q_nav_body, w_body, effort, uwb_lost, nlos_probability)
    plain = (
        _is_tick(tick) and _is_time(t_s) and _is_f64(p_nav, (3,)) and _is_f64(v_nav, (3,))
        and _is_f64(q_nav_body, (4,)) and _is_f64(w_body, (3,)) and type(effort) is float and effort >= 0.0
        and type(uwb_lost) is bool and type(nlos_probability) is float and 0.0 <= nlos_probability <= 1.0
    )  # fmt: skip
    if plain:
        total = t_s + effort + _total(p_nav) + _total(v_nav) + _total(q_nav_body)
        plain = math.isfinite(total + _total(w_body)) and _clearly_unit(q_nav_body)
    if not plain:
        return encode(Truth(*args))
    return _pack("Truth", dict(zip(_TRUTH_FIELDS, args, strict=True)))


@dataclass(frozen=True, eq=False)
class TruthBatch(_Batch):
    """The :class:`Truth` of many vehicles at one tick, in one message: ``<ns>/world/truth``, what a world
    serving agent hosts sends its mothership instead of one ``agent/<id>/truth`` each (docs/protocol.md,
    "Rates"; the per-vehicle truths then go to a viewer only, while one subscribes). Row ``i`` of every
    array is vehicle ``ids[i]``'s; :meth:`sample` gives one vehicle's :class:`Truth`."""

    tick: int
    """Tick ``k`` (>= 0), every row's."""
    t_s: float
    """Time [s] (>= 0), every row's."""
    ids: tuple[str, ...]
    """The vehicles, distinct, 1 to :data:`MAX_BATCH`."""
    p_nav: np.ndarray
    """Positions (N, 3) [m], frame nav (:attr:`Truth.p_nav`)."""
    v_nav: np.ndarray
    """Velocities (N, 3) [m/s], frame nav."""
    q_nav_body: np.ndarray
    """Attitudes (N, 4), unit quaternions (x, y, z, w), body into nav."""
    w_body: np.ndarray
    """Angular rates (N, 3) [rad/s], body frames."""
    effort: np.ndarray
    """Efforts (N,) since the run began (>= 0), each in its kind's measure (:attr:`Truth.effort`)."""
    uwb_lost: tuple[bool, ...]
    """Each tag's radio environment: every reply lost (:attr:`Truth.uwb_lost`)."""
    nlos_probability: np.ndarray
    """Each tag's NLOS outlier probability in a burst window (N,), in [0, 1]."""

    def __post_init__(self) -> None:
        ids = _vehicle_ids(self.ids, "ids", 1)
        n, rows = len(ids), MAX_BATCH
        p, v = _array(self.p_nav, "p_nav", (n, 3)), _array(self.v_nav, "v_nav", (n, 3))
        q = _units(_array(self.q_nav_body, "q_nav_body", (n, 4)), "q_nav_body")
        w, effort = _array(self.w_body, "w_body", (n, 3)), _array(self.effort, "effort", (n,), max_rows=rows)
        nlos = _array(self.nlos_probability, "nlos_probability", (n,), max_rows=rows)
        lost = _per_id(self.uwb_lost, "uwb_lost", ids)
        _truth_rows(effort, nlos)
        _set(self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0), ids=ids, p_nav=p,
             v_nav=v, q_nav_body=q, w_body=w, effort=effort, nlos_probability=nlos,
             uwb_lost=tuple(_bool(x, f"uwb_lost[{i}]") for i, x in enumerate(lost)))  # fmt: skip

    def sample(self, vid: str, row: int | None = None) -> Truth | None:
        """Vehicle ``vid``'s :class:`Truth` (``row`` its row when known, :meth:`index`), ``None`` when the
        batch has none. Its arrays are copies of the batch's checked rows (not checked again)."""
        row = self._row(vid, row)
        if row is None:
            return None
        return _checked(Truth, {
            "tick": self.tick, "t_s": self.t_s, "p_nav": self.p_nav[row].copy(),
            "v_nav": self.v_nav[row].copy(), "q_nav_body": self.q_nav_body[row].copy(),
            "w_body": self.w_body[row].copy(),
            "effort": float(self.effort[row]), "uwb_lost": self.uwb_lost[row],
            "nlos_probability": float(self.nlos_probability[row]),
        })  # fmt: skip


_TRUTH_BATCH_FIELDS = ("tick", "t_s", "ids", "p_nav", "v_nav", "q_nav_body", "w_body", "effort", "uwb_lost",
                       "nlos_probability")  # fmt: skip


def encode_truth_batch(
    tick: int, t_s: float, ids: tuple[str, ...], X: np.ndarray, effort: np.ndarray, uwb_lost: bool,
    nlos_probability: float,
) -> bytes:  # fmt: skip
    """``encode(TruthBatch(...))`` of the rows of ``X`` (N, 13: position, velocity, attitude, rate, the
    world's truth layout), every tag in the same radio environment, the same bytes without building the
    message (the sender fast paths above; a world sends one every UWB slot tick)."""
    n = len(ids)
    x = np.ascontiguousarray(X, dtype=np.float64)
    p, v, q, w = x[:, 0:3], x[:, 3:6], x[:, 6:10], x[:, 10:13]
    effort = np.ascontiguousarray(effort, dtype=np.float64)
    nlos = np.full(n, nlos_probability)
    plain = (
        _is_tick(tick) and _is_time(t_s) and type(ids) is tuple and ids in _KNOWN_IDS and x.shape == (n, 13)
        and effort.shape == (n,) and type(uwb_lost) is bool and type(nlos_probability) is float
        and 0.0 <= nlos_probability <= 1.0
    )  # fmt: skip
    if plain:
        n2 = (q * q).sum(axis=1)
        plain = (
            math.isfinite(t_s + float(x.sum()) + float(effort.sum())) and bool((effort >= 0.0).all())
            and bool(((n2 >= _UNIT_LO) & (n2 <= _UNIT_HI)).all())
        )  # fmt: skip
    if not plain:
        return encode(TruthBatch(tick, t_s, ids, p, v, q, w, effort, (uwb_lost,) * n, nlos))
    values = (tick, t_s, ids, p, v, q, w, effort, (uwb_lost,) * n, nlos)
    return _pack("TruthBatch", dict(zip(_TRUTH_BATCH_FIELDS, values, strict=True)))


def _truth_rows(effort: np.ndarray, nlos: np.ndarray) -> None:
    """The ranges of a :class:`TruthBatch`'s per-row numbers."""
    if (effort < 0.0).any():
        i = int(np.flatnonzero(effort < 0.0)[0])
        raise MessageError(f"effort[{i}]: must be >= 0, got {effort[i]}")
    bad = (nlos < 0.0) | (nlos > 1.0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise MessageError(f"nlos_probability[{i}]: must be in [0, 1], got {nlos[i]}")


@dataclass(frozen=True, eq=False)
class Event(Message):
    """Something that happened to one vehicle, ``<ns>/agent/<id>/event`` (published by its agent, and by the
    world for what only the truth shows: ``contact``, ``collision``, ``keepout_violation``), or to the
    run, ``<ns>/world/event`` (the world: ``run_start``, ``run_end``, ``agent_missing``, ``fault`` and
    ``fault_refused`` for a run-time fault, UWB faults included: the world's schedule drives the radios)."""

    t_s: float
    """Time [s] (>= 0)."""
    kind: str
    """What happened, ``[a-z][a-z0-9_]*`` (at most 64 characters); :data:`EVENT_KINDS` lists those in use."""
    data: dict[str, Any] = field(default_factory=dict)
    """Details, free form: nil, bool, int, finite float, str, arrays and string-keyed maps, nested at most
    8 deep; e.g. ``{"from": "APPROACH", "to": "REORIENT", "range_m": 0.62, "reason": "..."}`` for ``mode``."""

    def __post_init__(self) -> None:
        if not isinstance(self.data, dict):
            raise MessageError(f"data: expected a map, got {_show(self.data)}")
        _set(
            self, t_s=_float(self.t_s, "t_s", lo=0.0), kind=_str(self.kind, "kind", pattern=_EVENT_KIND),
            data=_plain(self.data, "data"),
        )  # fmt: skip


CLOCK_EVERY = 10
"""A world's ``world/clock`` goes out every this many ticks by default (``--clock-every``), and at every
state change: the agents take their ticks from their samples, the clock is for viewers, joiners and the
launcher's stall watch (docs/protocol.md, "Rates")."""


@dataclass(frozen=True, eq=False)
class Clock(Message):
    """The world's clock and run state, every :data:`CLOCK_EVERY` ticks and at every state change:
    ``<ns>/world/clock``."""

    tick: int
    """Current tick ``k`` (>= 0)."""
    t_s: float
    """Current time [s] (>= 0), ``k * dt``."""
    state: str
    """``"running"``, ``"paused"`` or ``"stopped"``."""
    seed: int
    """Seed of the current run (0 <= seed < 2**64): every random stream derives from it."""

    def __post_init__(self) -> None:
        _set(
            self, tick=_int(self.tick, "tick"), t_s=_float(self.t_s, "t_s", lo=0.0),
            state=_str(self.state, "state", choices=CLOCK_STATES), seed=_int(self.seed, "seed"),
        )  # fmt: skip


@dataclass(frozen=True, eq=False)
class Anchors(Message):
    """The mothership's UWB anchors: ``<ns>/mothership/anchors`` (published and answered to queries)."""

    anchor_ids: tuple[int, ...]
    """Id of each anchor (>= 0, distinct), N entries, 1 <= N <= :data:`MAX_ITEMS`."""
    positions_nav: np.ndarray
    """Antenna position of each anchor (N, 3) [m], frame nav; row i is ``anchor_ids[i]``."""

    def __post_init__(self) -> None:
        ids = _ids(self.anchor_ids, "anchor_ids")
        pos = _array(self.positions_nav, "positions_nav", (None, 3))
        if pos.shape[0] != len(ids):
            raise MessageError(f"positions_nav: {pos.shape[0]} rows for {len(ids)} anchor ids")
        _set(self, anchor_ids=ids, positions_nav=pos)


@dataclass(frozen=True, eq=False)
class RunControl(Message):
    """A request to the world from the dashboard or the launcher: ``<ns>/control/run``."""

    command: str
    """``"pause"``, ``"resume"``, ``"reset"`` (restart the run) or ``"new_seed"`` (restart, new seed)."""
    seed: int | None = None
    """Seed for ``reset``/``new_seed`` (0 <= seed < 2**64); ``None``: ``reset`` keeps the current seed and
    ``new_seed`` lets the world draw one. Ignored by ``pause`` and ``resume``."""

    def __post_init__(self) -> None:
        seed = None if self.seed is None else _int(self.seed, "seed")
        _set(self, command=_str(self.command, "command", choices=RUN_COMMANDS), seed=seed)


FAULT_KINDS: tuple[str, ...] = ("uwb_dropout", "nlos_burst", "camera_loss", "gyro_bias_step", "sensor_delay")
"""Faults that can be injected at run time (:mod:`swarm.core.faults` has their models)."""


@dataclass(frozen=True, eq=False)
class Fault(Message):
    """A fault to inject at run time: ``<ns>/control/fault`` (``swarm fault``; the world applies camera and
    gyro faults, the mothership UWB ones). Every window opens no earlier than the receiver's next tick."""

    kind: str
    """One of :data:`FAULT_KINDS`."""
    duration_s: float | None = None
    """Length of the window [s] (> 0); required for every kind but ``gyro_bias_step`` (which lasts)."""
    start_s: float | None = None
    """Simulated time the window opens [s] (>= 0); ``None``: at once (the receiver's next tick)."""
    vehicle: str | None = None
    """The vehicle (``camera_loss``: a chaser; ``gyro_bias_step``: any); ``None``: every chaser."""
    probability: float | None = None
    """``nlos_burst``: probability that an exchange is an NLOS outlier inside the window, in (0, 1]."""
    rate_rad_s: np.ndarray | None = None
    """``gyro_bias_step``: the constant rate (3,) [rad/s], body frame, added to the gyro from ``start_s``."""
    delay_s: float | None = None
    """``sensor_delay``: each imu/vision sample of the vehicle(s) inside the window leaves the world late by
    a uniform random delay in ``[0, delay_s]`` [s of simulated time] (> 0), so samples also arrive out of
    order. Free-running clocks only: a lockstep world refuses it (it would wait on its own late samples)."""

    def __post_init__(self) -> None:
        kind = _str(self.kind, "kind", choices=FAULT_KINDS)
        dur = _float(self.duration_s, "duration_s", positive=True, nullable=True)
        if dur is None and kind != "gyro_bias_step":
            raise MessageError(f"duration_s: required for a {kind} fault")
        prob = _float(self.probability, "probability", lo=0.0, nullable=True)
        if kind == "nlos_burst" and (prob is None or not 0.0 < prob <= 1.0):
            raise MessageError(f"probability: an nlos_burst needs one in (0, 1], got {prob}")
        rate = None if self.rate_rad_s is None else _array(self.rate_rad_s, "rate_rad_s", (3,))
        if kind == "gyro_bias_step" and rate is None:
            raise MessageError("rate_rad_s: required for a gyro_bias_step fault")
        vehicle = None if self.vehicle is None else _str(self.vehicle, "vehicle", pattern=ID_PATTERN)
        delay = _float(self.delay_s, "delay_s", positive=True, nullable=True)
        if kind == "sensor_delay" and delay is None:
            raise MessageError("delay_s: required for a sensor_delay fault")
        _set(
            self, kind=kind, duration_s=dur, start_s=_float(self.start_s, "start_s", lo=0.0, nullable=True),
            vehicle=vehicle, probability=prob, rate_rad_s=rate, delay_s=delay,
        )  # fmt: skip


MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.__name__: cls
    for cls in (
        Imu,
        ImuBatch,
        Uwb,
        UwbBatch,
        Tdoa,
        TdoaBatch,
        Vision,
        VisionBatch,
        Gnss,
        Rangefinder,
        Barometer,
        Estimate,
        Guidance,
        Command,
        CommandBatch,
        Truth,
        TruthBatch,
        Bundle,
        Event,
        Clock,
        Anchors,
        RunControl,
        Fault,
    )
}
"""Every message class by its wire ``"type"``."""

MESSAGE_FOR_KIND: dict[str, type[Message]] = {
    "imu": Imu, "uwb": Uwb, "tdoa": Tdoa, "vision": Vision, "gnss": Gnss, "rangefinder": Rangefinder,
    "barometer": Barometer, "estimate": Estimate,
    "guidance": Guidance,
    "command": Command,
    "commands": CommandBatch,
    "truth": Truth, "event": Event, "world_clock": Clock, "world_event": Event, "world_imu": ImuBatch,
    "world_vision": VisionBatch, "anchors": Anchors, "mothership_uwb": UwbBatch, "world_truth": TruthBatch,
    "mothership_tdoa": TdoaBatch,
    "run_control": RunControl, "fault": Fault, "bundle": Bundle, "world_bundle": Bundle,
}  # fmt: skip
"""The message carried by each key kind of :meth:`swarm.transport.keys.Keys.parse`."""


# ---------------------------------------------------------------------------------------------- codec

M = TypeVar("M", bound=Message)


def _wire(value: object) -> object:
    if isinstance(value, np.ndarray):
        return {"dtype": "<f8", "shape": list(value.shape), "data": value.astype("<f8", copy=False).tobytes()}
    if isinstance(value, tuple):
        return list(value)
    return value


def encode(msg: Message) -> bytes:
    """The msgpack bytes of ``msg`` (module docstring); MessageError above :data:`MAX_PAYLOAD_BYTES`."""
    if type(msg).__name__ not in MESSAGE_TYPES or not isinstance(msg, Message):
        raise TypeError(f"not a wire message: {type(msg).__name__}")
    out: dict[str, object] = {"v": SCHEMA_VERSION, "type": type(msg).__name__}
    for f in fields(msg):  # type: ignore[arg-type]
        out[f.name] = _wire(getattr(msg, f.name))
    payload = msgpack.packb(out, use_bin_type=True)
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise MessageError(f"payload: {len(payload)} bytes, more than the {MAX_PAYLOAD_BYTES} allowed")
    return payload


def _as_bytes(payload: object) -> bytes | bytearray | memoryview:
    if isinstance(payload, bytes | bytearray):
        return payload
    if isinstance(payload, memoryview):
        if payload.nbytes > MAX_PAYLOAD_BYTES:
            raise MessageError(f"payload: {payload.nbytes} bytes, more than the {MAX_PAYLOAD_BYTES} allowed")
        return payload.tobytes()
    if hasattr(payload, "__bytes__"):  # zenoh.ZBytes, without importing zenoh
        return bytes(payload)  # type: ignore[call-overload]
    raise MessageError(f"payload: expected bytes, got {type(payload).__name__}")


def decode(payload: object, expected: type[M]) -> M:
    """The message of type ``expected`` in ``payload`` (bytes, bytearray, memoryview or ``zenoh.ZBytes``).

    Raises MessageError naming the field and the problem: ``"payload: not valid msgpack (...)"``,
    ``"payload: not a msgpack map"``, ``"v: unsupported schema version 7 ..."``, ``"type: expected 'Imu',
    got 'Uwb'"``, ``"<field>: missing"``, or any field check of the message class.
    """
    data = _as_bytes(payload)
    if len(data) > MAX_PAYLOAD_BYTES:
        raise MessageError(f"payload: {len(data)} bytes, more than the {MAX_PAYLOAD_BYTES} allowed")
    msg = _decode_fast(data, expected)
    return msg if msg is not None else _decode_reference(data, expected)


def _decode_reference(data: bytes | bytearray, expected: type[M]) -> M:
    """:func:`decode` by the message's own checks: every form the protocol allows, and the error messages."""
    try:
        obj = msgpack.unpackb(data, raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises ValueError, ExtraData, FormatError, StackError, UnicodeError...
        raise MessageError(f"payload: not valid msgpack ({type(exc).__name__}: {exc})"[:200]) from None
    if not isinstance(obj, dict):
        raise MessageError(f"payload: not a msgpack map (got {type(obj).__name__})")
    if "v" not in obj:
        raise MessageError("v: missing (the schema version)")
    version = obj["v"]
    if not _is_int(version) or version != SCHEMA_VERSION:
        raise MessageError(
            f"v: unsupported schema version {_show(version)} (this codec speaks {SCHEMA_VERSION})"
        )
    name = expected.__name__
    if obj.get("type") != name:
        raise MessageError(f"type: expected {name!r}, got {_show(obj.get('type'))}")
    kwargs = {}
    for f in fields(expected):  # type: ignore[arg-type]
        if f.name in obj:
            kwargs[f.name] = obj[f.name]
        elif f.default is MISSING and f.default_factory is MISSING:
            raise MessageError(f"{f.name}: missing")
    return expected(**kwargs)


# ------------------------------------------------------------------------------------------ fast path
#
# The messages of every tick (imu, uwb, vision, estimate, guidance, command, truth, clock) are decoded by
# msgspec into typed Structs first: types, integer and float ranges, string choices and patterns, the
# array maps' layout and the counters are checked in C, then the arrays' shapes, finiteness, a quaternion's
# norm and a covariance by the same helpers as the reference path. Whatever the fast path does not take as
# it is (a plain nested list, another dtype, any failed check) goes to the reference path, which accepts
# the other forms the protocol allows and names the field of an error: the fast path only ever accepts a
# subset, to the same message (tests/transport/test_messages.py checks both on the fuzzed payloads).


class _Defer(Exception):
    """The fast path leaves this payload to the reference path."""


_Nat = Annotated[int, msgspec.Meta(ge=0)]
_Time = Annotated[float, msgspec.Meta(ge=0.0)]
_NonNeg = Annotated[float, msgspec.Meta(ge=0.0)]
_Share = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
_Name = Annotated[str, msgspec.Meta(pattern=rf"\A(?:{ID_PATTERN.pattern})\Z", max_length=_MAX_NAME)]


class _Array(msgspec.Struct):
    """The wire map of a float64 array as this codec writes it."""

    dtype: Literal["<f8"]
    shape: list[int]
    data: bytes


class _Wire(msgspec.Struct):
    v: int
    type: str


class _ImuWire(_Wire):
    tick: _Nat
    t_s: _Time
    dt_s: Annotated[float, msgspec.Meta(gt=0.0)]
    gyro_body: _Array
    q_ahrs_nav_body: _Array | None = None
    acc_body: _Array | None = None


class _ImuBatchWire(_Wire):
    tick: _Nat
    t_s: _Time
    dt_s: Annotated[float, msgspec.Meta(gt=0.0)]
    ids: list[str]  # checked by _vehicle_ids, which remembers the lists it passed (a pattern each: ~30 us)
    gyro_body: _Array
    ahrs_ids: list[str] = []
    q_ahrs_nav_body: _Array | None = None
    acc_body: _Array | None = None


class _UwbWire(_Wire):
    tick: _Nat
    t_s: _Time
    anchor_id: Annotated[int, msgspec.Meta(ge=0, le=_MAX_ID)]
    range_m: _NonNeg | None = None


class _UwbBatchWire(_Wire):
    tick: _Nat
    t_s: _Time
    ids: list[str]  # checked by _vehicle_ids (see _ImuBatchWire)
    anchor_ids: list[Annotated[int, msgspec.Meta(ge=0, le=_MAX_ID)]]
    range_m: list[_NonNeg | None]


class _VisionWire(_Wire):
    tick: _Nat
    t_s: _Time
    target_id: _Name
    face: Literal[FACES]  # type: ignore[valid-type]
    kind: Literal[VISION_KINDS]  # type: ignore[valid-type]
    data: _Array
    marker_ids: list[Any]


class _VisionBatchWire(_Wire):
    tick: _Nat
    t_s: _Time
    ids: list[str]  # checked by _vehicle_ids (see _ImuBatchWire)
    frames: list[bytes]


class _EstimateWire(_Wire):
    tick: _Nat
    t_s: _Time
    p_nav: _Array
    v_nav: _Array
    q_nav_body: _Array
    cov: _Array
    sigma_pos_max_m: _NonNeg
    mahalanobis_d: _NonNeg
    rejection_fraction: _Share
    counts: Annotated[dict[_Name, _Nat], msgspec.Meta(max_length=MAX_ITEMS)]


class _GuidanceWire(_Wire):
    tick: _Nat
    t_s: _Time
    mode: Literal[MODES]  # type: ignore[valid-type]
    range_m: _NonNeg | None = None
    r1_m: _NonNeg | None = None
    r2_m: _NonNeg | None = None
    r_t_m: _NonNeg | None = None
    decision: Any = None
    reason: Annotated[str, msgspec.Meta(max_length=_MAX_TEXT)] = ""


class _CommandWire(_Wire):
    tick: _Nat
    t_s: _Time
    actuators: _Array
    mode: Literal[MODES]  # type: ignore[valid-type]
    force_body_n: _Array | None = None
    torque_body_nm: _Array | None = None


class _CommandBatchWire(_Wire):
    ids: list[str]  # checked by _vehicle_ids (see _ImuBatchWire)
    commands: list[bytes]


class _BundleWire(_Wire):
    tick: _Nat
    types: list[str]  # checked by _bundle_types
    entries: list[bytes]


class _TruthWire(_Wire):
    tick: _Nat
    t_s: _Time
    p_nav: _Array
    v_nav: _Array
    q_nav_body: _Array
    w_body: _Array
    effort: _NonNeg = 0.0
    uwb_lost: bool = False
    nlos_probability: _Share = 0.0


class _TruthBatchWire(_Wire):
    tick: _Nat
    t_s: _Time
    ids: list[str]  # checked by _vehicle_ids (see _ImuBatchWire)
    p_nav: _Array
    v_nav: _Array
    q_nav_body: _Array
    w_body: _Array
    effort: _Array
    uwb_lost: list[bool]
    nlos_probability: _Array


class _ClockWire(_Wire):
    tick: _Nat
    t_s: _Time
    state: Literal[CLOCK_STATES]  # type: ignore[valid-type]
    seed: _Nat


def _fin(x: float | None) -> float | None:
    if x is not None and not math.isfinite(x):
        raise _Defer
    return x


def _arr(a: _Array | None, shape: tuple[int | None, ...]) -> Any:
    out = _arr_shaped(a, shape)
    # finite: a small array's sum in Python (a NaN or an infinity carries through; a finite sum too large
    # to hold defers to the reference, which decides exactly), a larger one's entries in numpy
    if out is not None and not (math.isfinite(_total(out)) if out.size <= 16 else np.isfinite(out).all()):
        raise _Defer
    return out


def _arr_shaped(a: _Array | None, shape: tuple[int | None, ...]) -> Any:
    """:func:`_arr` without its finiteness check (the caller's)."""
    if a is None:
        return None
    if len(a.shape) != len(shape):
        raise _Defer
    n = 1
    for got, want in zip(a.shape, shape, strict=True):
        if got != want and (want is not None or not 0 <= got <= MAX_ITEMS):
            raise _Defer
        n *= got
    if len(a.data) != 8 * n:
        raise _Defer
    return np.frombuffer(a.data, "<f8").reshape(a.shape).astype(np.float64)  # a writable copy


def _q(a: _Array | None, name: str) -> Any:
    return None if a is None else _unit(_arr(a, (4,)), name)


def _imu(w: _ImuWire) -> dict[str, Any]:
    return {
        "tick": w.tick, "t_s": _fin(w.t_s), "dt_s": _fin(w.dt_s), "gyro_body": _arr(w.gyro_body, (3,)),
        "q_ahrs_nav_body": _q(w.q_ahrs_nav_body, "q_ahrs_nav_body"), "acc_body": _arr(w.acc_body, (3,)),
    }  # fmt: skip


def _imu_batch(w: _ImuBatchWire) -> dict[str, Any]:
    if w.q_ahrs_nav_body is None:
        raise _Defer
    ids, ahrs = _vehicle_ids(w.ids, "ids", 1), _vehicle_ids(w.ahrs_ids, "ahrs_ids", 0)
    gyro, acc = _arr(w.gyro_body, (len(ids), 3)), _arr(w.acc_body, (len(ids), 3))
    q = _units(_arr(w.q_ahrs_nav_body, (len(ahrs), 4)), "q_ahrs_nav_body")
    _batch_rows(ids, ahrs, gyro, q, acc)
    return {
        "tick": w.tick, "t_s": _fin(w.t_s), "dt_s": _fin(w.dt_s), "ids": ids, "gyro_body": gyro,
        "ahrs_ids": ahrs, "q_ahrs_nav_body": q, "acc_body": acc,
    }  # fmt: skip


def _uwb(w: _UwbWire) -> dict[str, Any]:
    return {"tick": w.tick, "t_s": _fin(w.t_s), "anchor_id": w.anchor_id, "range_m": _fin(w.range_m)}


def _uwb_batch(w: _UwbBatchWire) -> dict[str, Any]:
    ids = _vehicle_ids(w.ids, "ids", 1)
    if len(w.anchor_ids) != len(ids) or len(w.range_m) != len(ids):
        raise _Defer
    ranges = tuple(w.range_m)
    if not math.isfinite(sum(r for r in ranges if r is not None)):
        raise _Defer
    return {
        "tick": w.tick,
        "t_s": _fin(w.t_s),
        "ids": ids,
        "anchor_ids": tuple(w.anchor_ids),
        "range_m": ranges,
    }


def _vision(w: _VisionWire) -> dict[str, Any]:
    data = _arr(w.data, (None, {"features": 3, "pixels": 2, "pose": POSE_LEN}[w.kind]))
    ids = _ids(w.marker_ids, "marker_ids", min_len=0)
    _frame(w.kind, data, ids)
    return {
        "tick": w.tick, "t_s": _fin(w.t_s), "target_id": w.target_id, "face": w.face, "kind": w.kind,
        "data": data, "marker_ids": ids,
    }  # fmt: skip


def _vision_batch(w: _VisionBatchWire) -> dict[str, Any]:
    ids, frames = _entries(w.ids, w.frames)
    return {"tick": w.tick, "t_s": _fin(w.t_s), "ids": ids, "frames": frames}


def _entries(ids: list[str], blobs: list[bytes]) -> tuple[tuple[str, ...], tuple[bytes, ...]]:
    """A batch of encoded entries' ids, checked, and its entries, one per id (else the reference decides)."""
    checked = _vehicle_ids(ids, "ids", 1)
    if len(blobs) != len(checked):
        raise _Defer
    return checked, tuple(blobs)


def _estimate(w: _EstimateWire) -> dict[str, Any]:
    p, v, q, cov = _estimate_wire_arrays(w)
    return {
        "tick": w.tick, "t_s": _fin(w.t_s), "p_nav": p, "v_nav": v, "q_nav_body": q, "cov": cov,
        "sigma_pos_max_m": _fin(w.sigma_pos_max_m), "mahalanobis_d": _fin(w.mahalanobis_d),
        "rejection_fraction": w.rejection_fraction, "counts": w.counts,
    }  # fmt: skip


def _estimate_wire_arrays(w: _EstimateWire) -> list[Any]:
    """An estimate's four arrays, checked. A process that encodes estimates has the compiled checks loaded:
    one call checks all four where numpy took some ten (on a chaser's imu path, its target's estimate:
    BENCHMARKS.md, "The truths last, an estimate's compiled checks ..."); anything but their plain verdict,
    and any process without them (a viewer), takes numpy's checks, which decide exactly."""
    if _ESTIMATE_ARRAYS is not None and w.q_nav_body is not None:
        arrays = [_arr_shaped(a, shape) for a, shape in zip((w.p_nav, w.v_nav, w.q_nav_body, w.cov),
                                                            _ESTIMATE_SHAPES, strict=True)]  # fmt: skip
        if _estimate_arrays(*arrays) == _PLAIN:
            return arrays
    return [_arr(w.p_nav, (3,)), _arr(w.v_nav, (3,)), _q(w.q_nav_body, "q_nav_body"),
            _covariance(_arr(w.cov, (9, 9)), "cov")]  # fmt: skip


def _guidance(w: _GuidanceWire) -> dict[str, Any]:
    return {
        "tick": w.tick, "t_s": _fin(w.t_s), "mode": w.mode, "range_m": _fin(w.range_m), "r1_m": _fin(w.r1_m),
        "r2_m": _fin(w.r2_m), "r_t_m": _fin(w.r_t_m), "decision": _decision(w.decision, "decision"),
        "reason": w.reason,
    }  # fmt: skip


def _command(w: _CommandWire) -> dict[str, Any]:
    return {
        "tick": w.tick, "t_s": _fin(w.t_s), "actuators": _arr(w.actuators, (None,)), "mode": w.mode,
        "force_body_n": _arr(w.force_body_n, (3,)), "torque_body_nm": _arr(w.torque_body_nm, (3,)),
    }  # fmt: skip


def _command_batch(w: _CommandBatchWire) -> dict[str, Any]:
    ids, commands = _entries(w.ids, w.commands)
    return {"ids": ids, "commands": commands}


def _truth(w: _TruthWire) -> dict[str, Any]:
    return {
        "tick": w.tick, "t_s": _fin(w.t_s), "p_nav": _arr(w.p_nav, (3,)), "v_nav": _arr(w.v_nav, (3,)),
        "q_nav_body": _q(w.q_nav_body, "q_nav_body"), "w_body": _arr(w.w_body, (3,)),
        "effort": _fin(w.effort), "uwb_lost": w.uwb_lost, "nlos_probability": w.nlos_probability,
    }  # fmt: skip


def _truth_batch(w: _TruthBatchWire) -> dict[str, Any]:
    ids = _vehicle_ids(w.ids, "ids", 1)
    n = len(ids)
    if len(w.uwb_lost) != n:
        raise _Defer
    effort, nlos = _arr(w.effort, (n,)), _arr(w.nlos_probability, (n,))
    _truth_rows(effort, nlos)
    return {
        "tick": w.tick, "t_s": _fin(w.t_s), "ids": ids, "p_nav": _arr(w.p_nav, (n, 3)),
        "v_nav": _arr(w.v_nav, (n, 3)), "q_nav_body": _units(_arr(w.q_nav_body, (n, 4)), "q_nav_body"),
        "w_body": _arr(w.w_body, (n, 3)), "effort": effort, "uwb_lost": tuple(w.uwb_lost),
        "nlos_probability": nlos,
    }  # fmt: skip


def _bundle(w: _BundleWire) -> dict[str, Any]:
    types = _bundle_types(w.types)
    if len(w.entries) != len(types):
        raise _Defer
    return {"tick": w.tick, "types": types, "entries": tuple(w.entries)}


def _clock(w: _ClockWire) -> dict[str, Any]:
    return {"tick": w.tick, "t_s": _fin(w.t_s), "state": w.state, "seed": w.seed}


_FAST: dict[type[Message], tuple[msgspec.msgpack.Decoder, Callable[[Any], dict[str, Any]]]] = {
    cls: (msgspec.msgpack.Decoder(wire), convert)
    for cls, wire, convert in (
        (Imu, _ImuWire, _imu),
        (ImuBatch, _ImuBatchWire, _imu_batch),
        (Uwb, _UwbWire, _uwb),
        (UwbBatch, _UwbBatchWire, _uwb_batch),
        (Vision, _VisionWire, _vision),
        (VisionBatch, _VisionBatchWire, _vision_batch),
        (Estimate, _EstimateWire, _estimate),
        (Guidance, _GuidanceWire, _guidance),
        (Command, _CommandWire, _command),
        (CommandBatch, _CommandBatchWire, _command_batch),
        (Truth, _TruthWire, _truth),
        (TruthBatch, _TruthBatchWire, _truth_batch),
        (Bundle, _BundleWire, _bundle),
        (Clock, _ClockWire, _clock),
    )
}


def _decode_fast(data: bytes | bytearray, expected: type[M]) -> M | None:
    """The message in ``data`` if the fast path takes it as it is, else ``None`` (the reference decides)."""
    fast = _FAST.get(expected)
    if fast is None:
        return None
    decoder, convert = fast
    try:
        wire = decoder.decode(data)
        if wire.v != SCHEMA_VERSION or wire.type != expected.__name__:
            return None
        values = convert(wire)
    except (msgspec.MsgspecError, MessageError, _Defer):
        return None
    return _checked(expected, values)


# --------------------------------------------------------------------------------------- bad messages


class _KeyDrops:
    __slots__ = ("last_log_s", "last_reason", "pending", "total")

    def __init__(self) -> None:
        self.total = 0
        self.pending = 0
        self.last_reason = ""
        self.last_log_s: float | None = None


class DropCounter:
    """Thread-safe count of dropped (invalid) messages per key, with a rate-limited warning per key.

    The first drop on a key is logged at once; later ones at most once per ``log_interval_s`` per key,
    saying how many were dropped since the previous line and the last reason. :meth:`flush` logs what is
    pending (call it at shutdown). At most ``max_keys`` keys are tracked one by one; drops on further keys
    are counted under ``"<other keys>"`` so a flood of invented keys cannot grow memory.
    """

    OTHER = "<other keys>"

    def __init__(
        self,
        log_interval_s: float = 10.0,
        logger: logging.Logger | None = None,
        clock: Callable[[], float] = time.monotonic,
        max_keys: int = 1024,
    ) -> None:
        if not (
            isinstance(log_interval_s, int | float) and log_interval_s > 0 and math.isfinite(log_interval_s)
        ):
            raise ConfigError(f"transport.log_interval_s must be a finite number > 0, got {log_interval_s!r}")
        if not (isinstance(max_keys, int) and max_keys >= 1):
            raise ConfigError(f"transport.max_keys must be an integer >= 1, got {max_keys!r}")
        self.log_interval_s = float(log_interval_s)
        self._log = logger if logger is not None else _LOG
        self._clock = clock
        self._max_keys = max_keys
        self._lock = threading.Lock()
        self._keys: dict[str, _KeyDrops] = {}

    def drop(self, key: str, reason: str) -> None:
        """Count one dropped message on ``key`` for ``reason``, and log if this key's interval has passed."""
        key, reason = str(key), str(reason)[:300]
        now = self._clock()
        with self._lock:
            if key not in self._keys and len(self._keys) >= self._max_keys:
                key = self.OTHER
            st = self._keys.setdefault(key, _KeyDrops())
            st.total += 1
            st.pending += 1
            st.last_reason = reason
            if st.last_log_s is not None and now - st.last_log_s < self.log_interval_s:
                return
            pending, total = st.pending, st.total
            st.pending, st.last_log_s = 0, now
        self._emit(key, pending, total, reason)

    def _emit(self, key: str, pending: int, total: int, reason: str) -> None:
        self._log.warning(
            "dropped %d invalid message%s on %s (total %d); last: %s",
            pending, "" if pending == 1 else "s", key, total, reason,
        )  # fmt: skip

    def flush(self) -> None:
        """Log every key's drops not yet reported."""
        with self._lock:
            todo = [(k, s.pending, s.total, s.last_reason) for k, s in self._keys.items() if s.pending]
            for k, *_ in todo:
                self._keys[k].pending = 0
        for item in todo:
            self._emit(*item)

    def count(self, key: str) -> int:
        """Messages dropped on ``key`` so far."""
        with self._lock:
            st = self._keys.get(str(key))
            return 0 if st is None else st.total

    def counts(self) -> dict[str, int]:
        """A snapshot of the drops per key."""
        with self._lock:
            return {k: s.total for k, s in self._keys.items()}

    @property
    def total(self) -> int:
        """Messages dropped on all keys."""
        with self._lock:
            return sum(s.total for s in self._keys.values())


def safe_decode(payload: object, expected: type[M], key: object, counter: DropCounter) -> M | None:
    """:func:`decode` for a Zenoh callback: the message, or ``None`` after counting and (rate-limited)
    logging the drop under ``key``. Never raises."""
    try:
        return decode(payload, expected)
    except MessageError as exc:
        reason = str(exc)
    except Exception as exc:  # a codec bug must not kill the callback either; it is counted like bad input
        reason = f"{type(exc).__name__}: {exc}"
    try:
        counter.drop(str(key), reason)
    except Exception:
        _LOG.exception("could not count a dropped message on %s", key)
    return None
