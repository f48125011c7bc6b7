"""Every wire message of the swarm, each declared once, and the codec that turns them into bytes and back.

Wire format (``docs/protocol.md`` is the reference for drivers and other languages; its tables are generated
from the declarations below by :mod:`swarm.transport.protocol_tables`): one msgpack map per Zenoh sample,
``{"v": SCHEMA_VERSION, "type": "<class name>", "<field>": <value>, ...}`` with the fields in the order
declared. Floats may arrive as msgpack ints; integers must be ints; tuples are arrays; a numpy array is the
map ``{"dtype": "<f8", "shape": [...], "data": <bin>}`` of its raw C-order bytes, and plain nested arrays of
numbers are accepted too, so a client in any language can send lists. A field with a default may be left
out (its default applies); unknown keys are ignored, so a newer sender can add fields without breaking an
older receiver. A change that breaks old readers bumps :data:`SCHEMA_VERSION`.

Each message is one msgspec Struct (:mod:`swarm.transport.declared`): its annotations are its wire form and
its checks (msgspec checks them in C on a receiver; the constructor checks them on a sender), its field
docstrings are its documentation, and ``_validate`` holds what a type cannot say (rows against ids, a pose's
covariance). A message that exists is valid, whether it was built in Python or decoded from the wire; every
field is checked for type, shape, finiteness (no NaN or Inf anywhere), obvious ranges and size caps, and
:class:`~swarm.errors.MessageError` names the field (``"gyro_body: expected shape (3,), got (4,)"``). Arrays
are stored as writable float64 copies. :func:`safe_decode` is what a Zenoh callback calls: it never raises;
a bad message is dropped, counted per key in a :class:`DropCounter` and logged at a limited rate.

Conventions (notes/conventions.md): frames ``nav`` (mothership, inertial) and ``body``; quaternions
scalar-last ``(x, y, z, w)``, ``q_nav_body`` maps body vectors into ``nav``; SI units.
"""

from __future__ import annotations

import logging
import math
import sys
import threading
import time
from collections.abc import Callable, Container, Sequence
from typing import Annotated, Any, Literal

import msgspec
import numpy as np

from swarm.core.decision_keys import DECISION_KEYS
from swarm.errors import ConfigError, MessageError
from swarm.transport import declared
from swarm.transport.declared import (
    MAX_BATCH,
    MAX_ID,
    MAX_ITEMS,
    MAX_NAME,
    MAX_PAYLOAD_BYTES,
    MAX_TEXT,
    QUAT_NORM_TOL,
    SCHEMA_VERSION,
    U64_MAX,
    Check,
    Finite,
    M,
    MarkerId,
    Message,
    Nat,
    NonNeg,
    Positive,
    Share,
    TimeS,
    array,
    check_float,
    check_int,
    check_plain,
    check_str,
    decode,
    encode,
    send,
    show,
    trusted,
)
from swarm.transport.declared import declare as _declare
from swarm.transport.keys import ID_PATTERN

_decode_fast = declared.decode_fast  # (the two decodings, for the tests and swarm bench codec)
_decode_reference = declared.decode_reference

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
FAULT_KINDS: tuple[str, ...] = ("uwb_dropout", "nlos_burst", "camera_loss", "gyro_bias_step", "sensor_delay")
"""Faults that can be injected at run time (:mod:`swarm.core.faults` has their models)."""
BUNDLE_TYPES: tuple[str, ...] = ("Imu", "Uwb", "Vision", "TruthBatch", "Tdoa")
"""The messages a :class:`Bundle` may carry: a lockstep tick's samples (docs/protocol.md, "Bundles")."""
MAX_TDOA_ROWS = 1024
"""Most distance differences in one :class:`Tdoa` (a tag hears at most ~400 packets a second, the Loco
Positioning system's cap, so a UWB slot of 10 Hz or faster carries ~40)."""
CLOCK_EVERY = 10
"""A world's ``world/clock`` goes out every this many ticks by default (``--clock-every``), and at every
state change: the agents take their ticks from their samples, the clock is for viewers, joiners and the
launcher's stall watch (docs/protocol.md, "Rates")."""


def next_run_seed(end: dict, seed: int) -> int:
    """The seed of the run after the one ``end`` (a world's ``run_end`` data) ended, whose seed was ``seed``:
    the ``next_seed`` a ``reset`` or ``new_seed`` asked for, else the same seed for a ``reset`` and the next
    one otherwise (``new_seed``, ``swarm launch --repeat``)."""
    nxt = end.get("next_seed")
    if nxt is not None:
        return int(nxt)
    return seed if end.get("reason") == "reset" else seed + 1


EVENT_KINDS: tuple[str, ...] = (
    "mode", "docked", "contact", "collision", "abort", "estimator_reset", "lost", "restarted",
    "keepout_violation", "summary", "run_start", "run_end", "agent_missing", "fault", "fault_refused",
    "takeoff", "landing",
)  # fmt: skip
"""Event kinds in use; the set is open (any ``[a-z][a-z0-9_]*`` name is accepted)."""

_ID = rf"\A(?:{ID_PATTERN.pattern})\Z"
Name = Annotated[str, msgspec.Meta(pattern=_ID, max_length=MAX_NAME)]
"""A vehicle's or a counter's id, ``[A-Za-z0-9_-]{1,64}``."""
_DECISION_PROBABILITIES = frozenset({"A11", "A22", "A23", "A32", "A33", "pi1", "pi2"})
_PROBABILITY_SLACK = 1e-9  # clipped probabilities; stationary ones come from a linear solve
_F64_MAX = sys.float_info.max


# ------------------------------------------------------------------------- checks types cannot say


def _marker_ids(value: object, name: str, min_len: int = 0) -> tuple[int, ...]:
    if (
        type(value) is tuple and min_len <= len(value) <= MAX_ITEMS
        and all(type(v) is int and 0 <= v <= MAX_ID for v in value) and len(set(value)) == len(value)
    ):  # fmt: skip
        return value
    if not isinstance(value, list | tuple):
        raise MessageError(f"{name}: expected an array of integers, got {show(value)}")
    if not min_len <= len(value) <= MAX_ITEMS:
        raise MessageError(f"{name}: {len(value)} entries, expected {min_len} to {MAX_ITEMS}")
    ids = tuple(check_int(v, f"{name}[{i}]", 0, MAX_ID) for i, v in enumerate(value))
    if len(set(ids)) != len(ids):
        raise MessageError(f"{name}: duplicate ids in {show(ids)}")
    return ids


_KNOWN_IDS: dict[tuple, None] = {}  # id lists already checked (a swarm's batches repeat one or a few)


def _vehicle_ids(value: object, name: str, min_len: int = 1) -> tuple[str, ...]:
    """Distinct vehicle ids (:data:`~swarm.transport.keys.ID_PATTERN`), ``min_len`` to :data:`MAX_BATCH`."""
    if not isinstance(value, list | tuple):
        raise MessageError(f"{name}: expected an array of vehicle ids, got {show(value)}")
    ids = tuple(value)
    if not min_len <= len(ids) <= MAX_BATCH:
        raise MessageError(f"{name}: {len(ids)} entries, expected {min_len} to {MAX_BATCH}")
    try:
        if ids in _KNOWN_IDS:  # equal to a list that passed (only a str equals a str)
            return ids
    except TypeError:  # an unhashable entry: refused below
        pass
    ids = tuple(check_str(v, f"{name}[{i}]", pattern=ID_PATTERN) for i, v in enumerate(ids))
    if len(set(ids)) != len(ids):
        raise MessageError(f"{name}: duplicate ids in {show(ids)}")
    if len(_KNOWN_IDS) >= 64:
        _KNOWN_IDS.clear()
    _KNOWN_IDS[ids] = None
    return ids


_VEHICLES = "distinct, 1 to 256, each an id `[A-Za-z0-9_-]{1,64}`"
Vehicles = Annotated[tuple[str, ...], Check(_vehicle_ids, _VEHICLES)]
"""The vehicles of a batch."""
MarkerIds = Annotated[
    tuple[MarkerId, ...], msgspec.Meta(max_length=MAX_ITEMS), Check(_marker_ids, "distinct")
]
AnchorIds = Annotated[
    tuple[MarkerId, ...], msgspec.Meta(min_length=1, max_length=MAX_ITEMS),
    Check(lambda v, name: _marker_ids(v, name, 1), "distinct"),
]  # fmt: skip
AhrsIds = Annotated[tuple[str, ...], Check(lambda v, name: _vehicle_ids(v, name, 0), "distinct, among `ids`")]


def blobs(what: str) -> Any:
    """The annotation of a batch's entries: the bytes of a ``what`` message each, one per id."""

    def check(entries: object, name: str) -> tuple[bytes, ...]:
        if not isinstance(entries, list | tuple):
            raise MessageError(f"{name}: expected an array, got {show(entries)}")
        for i, f in enumerate(entries):
            if type(f) is not bytes:
                raise MessageError(f"{name}[{i}]: expected the bytes of a {what} message, got {show(f)}")
        return tuple(entries)

    says = "each the bytes of a message of its type" if what == "wire" else f"each the bytes of a `{what}`"
    return Annotated[tuple[bytes, ...], Check(check, says, on_decode=False)]


def _counts(value: object, name: str) -> dict[str, int]:
    if not isinstance(value, dict):
        raise MessageError(f"{name}: expected a map of name -> count, got {show(value)}")
    if len(value) > MAX_ITEMS:
        raise MessageError(f"{name}: {len(value)} entries, more than the {MAX_ITEMS} allowed")
    if all(type(v) is int and 0 <= v <= U64_MAX and type(k) is str and ID_PATTERN.fullmatch(k)
           for k, v in value.items()):  # fmt: skip
        return dict(value)
    out = {}
    for k, v in value.items():
        key = check_str(k, f"{name} key", pattern=ID_PATTERN)
        out[key] = check_int(v, f"{name}.{key}")
    return out


def _decision(value: object, name: str) -> dict[str, float | None] | None:
    if value is None:
        return None
    if not isinstance(value, dict):
        raise MessageError(f"{name}: expected a map or nil, got {show(value)}")
    out = {}
    for k in DECISION_KEYS:  # the common case: plain floats in range (nil for a probability), no call each
        v = value.get(k)
        prob = k in _DECISION_PROBABILITIES
        if type(v) is float and 0.0 <= v <= (1.0 + _PROBABILITY_SLACK if prob else _F64_MAX):
            out[k] = v
        elif v is None and prob and k in value:
            out[k] = None
        else:
            break
    else:
        return out
    out = {}
    for k in DECISION_KEYS:
        if k not in value:
            raise MessageError(f"{name}.{k}: missing")
        prob = k in _DECISION_PROBABILITIES
        v = check_float(value[k], f"{name}.{k}", lo=0.0, nullable=prob)
        if prob and v is not None and v > 1.0 + _PROBABILITY_SLACK:
            raise MessageError(f"{name}.{k}: a probability must be in [0, 1], got {v}")
        out[k] = v
    return out


def _event_data(value: object, name: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise MessageError(f"{name}: expected a map, got {show(value)}")
    return check_plain(value, name)


def _per_id(self: Message, ids: tuple, *names: str) -> None:
    """Each of the fields ``names`` of ``self`` has one entry per id."""
    for name in names:
        n = len(getattr(self, name))
        if n != len(ids):
            raise MessageError(f"{name}: {n} entries for {len(ids)} ids")


def _rows(self: Message, n: int, what: str, *names: str) -> None:
    """Each array field of ``names`` has ``n`` rows (one per ``what``)."""
    for name in names:
        a = getattr(self, name)
        if a is not None and a.shape[0] != n:
            raise MessageError(f"{name}: {a.shape[0]} rows for {n} {what}")


# ------------------------------------------------------------------------------------------ messages


class _Batch(Message):
    """Base of the batches: the samples of many vehicles in one message, row ``i`` vehicle ``ids[i]``'s;
    ``sample(vid)`` is one vehicle's message."""

    def index(self) -> dict[str, int]:
        """Each vehicle's row."""
        return {vid: i for i, vid in enumerate(self.ids)}  # type: ignore[attr-defined]

    def _row(self, vid: str, row: int | None) -> int | None:
        if row is not None:
            return row
        return self.ids.index(vid) if vid in self.ids else None  # type: ignore[attr-defined]

    def _entry(self, name: str, row: int, cls: type[M]) -> M:
        """Entry ``row`` of the field ``name`` (encoded messages), decoded and checked as a ``cls`` of its
        own key, of this batch's tick and time where it has them; MessageError naming the entry."""
        try:
            msg = decode(getattr(self, name)[row], cls)
        except MessageError as exc:
            raise MessageError(f"{name}[{row}]: {exc}") from None
        tick, t_s = getattr(self, "tick", None), getattr(self, "t_s", None)
        if t_s is not None and (msg.tick != tick or msg.t_s != t_s):  # type: ignore[attr-defined]
            raise MessageError(f"{name}[{row}]: tick {msg.tick} at {msg.t_s} s in the batch of tick "  # type: ignore[attr-defined]
                               f"{tick} at {t_s} s")  # fmt: skip
        return msg


@_declare
class Imu(Message):
    """One gyro sample of one vehicle (and its AHRS attitude when there is one): ``<ns>/agent/<id>/imu``."""

    tick: Nat
    """Tick ``k`` of the swarm clock; in simulation the sample time is ``k * dt``."""
    t_s: TimeS
    """Sample time [s] on the swarm clock."""
    dt_s: Positive
    """Integration interval [s] ending at ``t_s``, over which the estimator propagates this rate."""
    gyro_body: array((3,))
    """Measured angular rate (3,) [rad/s], body frame, with the sensor's bias and noise."""
    q_ahrs_nav_body: array((4,), unit=True) | None = None
    """AHRS attitude (4,), mapping body into nav; nil when the vehicle has no AHRS or on ticks without an
    AHRS output (it runs at 10 Hz of the 100 Hz)."""
    acc_body: array((3,)) | None = None
    """Measured specific force (3,) [m/s^2], body frame, from a 6-axis IMU (what an accelerometer reads:
    about +9.81 up at rest); nil for a gyro-only sensor (the simulated CubeSats). Added in schema 2 without
    a version bump: an older receiver ignores it."""


@_declare
class ImuBatch(_Batch):
    """The :class:`Imu` samples of many vehicles at one tick, in one message: ``<ns>/world/imu``, sent by a
    simulated world that serves agent hosts instead of one ``agent/<id>/imu`` per vehicle (docs/protocol.md,
    "Rates"). Row ``i`` of the arrays is vehicle ``ids[i]``'s; :meth:`sample` gives one vehicle's
    :class:`Imu`."""

    tick: Nat
    """Tick ``k`` of the swarm clock, every row's."""
    t_s: TimeS
    """Sample time [s], every row's."""
    dt_s: Positive
    """Integration interval [s], every row's."""
    ids: Vehicles
    """The vehicles: row ``i`` of ``gyro_body`` (and ``acc_body``)."""
    gyro_body: array((None, 3), max_rows=MAX_BATCH)
    """Measured angular rates (N, 3) [rad/s], each vehicle's body frame, one row per id."""
    ahrs_ids: AhrsIds = ()
    """The vehicles among ``ids`` with an AHRS output this tick: row ``j`` of ``q_ahrs_nav_body``."""
    q_ahrs_nav_body: array((None, 4), unit="rows", max_rows=MAX_BATCH) = msgspec.field(
        default_factory=lambda: np.zeros((0, 4))
    )
    """AHRS attitudes (M, 4) of ``ahrs_ids``, body into nav."""
    acc_body: array((None, 3), max_rows=MAX_BATCH) | None = None
    """Measured specific forces (N, 3) [m/s^2] of every row, or nil (gyro-only sensors)."""

    def _validate(self) -> None:
        _rows(self, len(self.ids), "ids", "gyro_body", "acc_body")
        _rows(self, len(self.ahrs_ids), "ahrs_ids", "q_ahrs_nav_body")
        if self.ahrs_ids and self.ahrs_ids != self.ids and not set(self.ahrs_ids) <= set(self.ids):
            raise MessageError(f"ahrs_ids: {show(sorted(set(self.ahrs_ids) - set(self.ids)))} not among ids")

    def sample(self, vid: str, row: int | None = None) -> Imu | None:
        """Vehicle ``vid``'s :class:`Imu` (``row`` its row when known, :meth:`index`), ``None`` when the
        batch has none. Its arrays are copies of the batch's checked rows (not checked again)."""
        row = self._row(vid, row)
        if row is None:
            return None
        q = None
        if vid in self.ahrs_ids:
            q = self.q_ahrs_nav_body[self.ahrs_ids.index(vid)].copy()
        return trusted(Imu, {
            "tick": self.tick, "t_s": self.t_s, "dt_s": self.dt_s, "gyro_body": self.gyro_body[row].copy(),
            "q_ahrs_nav_body": q, "acc_body": None if self.acc_body is None else self.acc_body[row].copy(),
        })  # fmt: skip


@_declare
class Uwb(Message):
    """One two-way ranging exchange between a vehicle's tag and one anchor: ``<ns>/agent/<id>/uwb``."""

    tick: Nat
    """Tick ``k`` of the exchange."""
    t_s: TimeS
    """Time of the exchange [s]."""
    anchor_id: MarkerId
    """The anchor ranged to, an id of the :class:`Anchors` message."""
    range_m: NonNeg | None = None
    """Measured tag-anchor distance [m]; nil if the exchange happened but the reply was lost (one message
    per UWB slot either way, so a lockstep agent knows not to wait)."""


@_declare
class UwbBatch(_Batch):
    """The :class:`Uwb` exchanges of many vehicles in one UWB slot, in one message: ``<ns>/mothership/uwb``,
    sent by a simulated radio network that serves agent hosts instead of one ``agent/<id>/uwb`` per vehicle
    (docs/protocol.md, "Rates"). Entry ``i`` of each list is vehicle ``ids[i]``'s; :meth:`sample` gives one
    vehicle's :class:`Uwb`."""

    tick: Nat
    """Tick ``k`` of the slot, every exchange's."""
    t_s: TimeS
    """Time of the slot [s], every exchange's."""
    ids: Vehicles
    """The vehicles."""
    anchor_ids: tuple[MarkerId, ...]
    """The anchor each vehicle ranged to (``Uwb.anchor_id``), one per id."""
    range_m: tuple[NonNeg | None, ...]
    """Each vehicle's measured distance [m], nil where the reply was lost (``Uwb.range_m``), one per id."""

    def _validate(self) -> None:
        _per_id(self, self.ids, "anchor_ids", "range_m")

    def sample(self, vid: str, row: int | None = None) -> Uwb | None:
        """Vehicle ``vid``'s :class:`Uwb` (``row`` its entry when known, :meth:`index`), ``None`` when the
        batch has none (its values are the batch's checked ones, not checked again)."""
        row = self._row(vid, row)
        if row is None:
            return None
        values = {"tick": self.tick, "t_s": self.t_s, "anchor_id": self.anchor_ids[row],
                  "range_m": self.range_m[row]}  # fmt: skip
        return trusted(Uwb, values)


AnchorList = Annotated[tuple[MarkerId, ...], msgspec.Meta(max_length=MAX_TDOA_ROWS)]


@_declare
class Tdoa(Message):
    """The TDoA distance differences one vehicle's tag heard since the previous UWB slot (``uwb.mode``
    tdoa2/tdoa3: anchors transmit, the tag only listens): ``<ns>/agent/<id>/tdoa``. Row ``i`` is the
    difference ``ddist_m[i] = d(tag, anchor_b[i]) - d(tag, anchor_a[i])`` (the Crazyflie's
    ``distanceDiff``, in the order heard). One message per UWB slot, with no rows when the tag heard none,
    so a lockstep agent knows not to wait (as :class:`Uwb` with ``range_m`` nil)."""

    tick: Nat
    """Tick ``k`` of the UWB slot."""
    t_s: TimeS
    """Time of the slot [s]: the rows are those heard up to it."""
    anchor_a: AnchorList = ()
    """Each row's first anchor, an id of the :class:`Anchors` message."""
    anchor_b: AnchorList = ()
    """Each row's second anchor, never the row's ``anchor_a``."""
    ddist_m: array((None,), max_rows=MAX_TDOA_ROWS) = msgspec.field(default_factory=lambda: np.zeros(0))
    """Each row's distance difference (N,) [m], any sign; the three fields have one entry per row."""

    def _validate(self) -> None:
        a, b, n = self.anchor_a, self.anchor_b, len(self.anchor_a)
        if len(b) != n:
            raise MessageError(f"anchor_b: {len(b)} entries for {n} in anchor_a")
        if self.ddist_m.shape[0] != n:
            raise MessageError(f"ddist_m: {self.ddist_m.shape[0]} entries for {n} in anchor_a")
        for i, (ia, ib) in enumerate(zip(a, b, strict=True)):
            if ia == ib:
                raise MessageError(f"anchor_b[{i}]: the same anchor as anchor_a[{i}] ({ia})")

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


@_declare
class TdoaBatch(_Batch):
    """The :class:`Tdoa` messages of many vehicles in one UWB slot, in one message: ``<ns>/mothership/tdoa``,
    sent by a simulated radio network that serves agent hosts instead of one ``agent/<id>/tdoa`` per
    vehicle (docs/protocol.md, "Rates"). A tag's count of rows varies, so each entry is the message as its
    own key would carry it (the msgpack bytes of a :class:`Tdoa`), as in a :class:`VisionBatch`."""

    tick: Nat
    """Tick ``k`` of the slot, every entry's."""
    t_s: TimeS
    """Time of the slot [s], every entry's."""
    ids: Vehicles
    """The vehicles: entry ``i`` of ``differences`` is ``ids[i]``'s."""
    differences: blobs("Tdoa")
    """Each vehicle's encoded :class:`Tdoa` (msgpack bin) of the batch's tick and time, one per id."""

    def _validate(self) -> None:
        _per_id(self, self.ids, "differences")

    def sample(self, vid: str, row: int | None = None) -> Tdoa | None:
        """Vehicle ``vid``'s :class:`Tdoa`, decoded and checked as its own key's would be, ``None`` when the
        batch has none; MessageError naming the entry (``differences[3]: ...``) for one that does not
        decode, or whose tick or time is not the batch's."""
        row = self._row(vid, row)
        return None if row is None else self._entry("differences", row, Tdoa)


@_declare
class Gnss(Message):
    """A satellite receiver's position fix of one vehicle: ``<ns>/agent/<id>/gnss`` (the landing's UAVs)."""

    tick: Nat
    """Tick ``k`` of the fix."""
    t_s: TimeS
    """Time of the fix [s]."""
    p_nav: array((3,))
    """Antenna position (3,) [m], frame nav."""
    cov: array((3, 3), cov=True)
    """Its covariance (3, 3) [m^2]."""


@_declare
class Rangefinder(Message):
    """A downward distance sensor's reading of one vehicle: ``<ns>/agent/<id>/rangefinder`` (the landing's
    UAVs; PX4's ``distance_sensor``): the distance along the body's ``-z`` axis to the ground."""

    tick: Nat
    """Tick ``k`` of the reading."""
    t_s: TimeS
    """Time of the reading [s]."""
    range_m: NonNeg | None
    """The distance [m]; nil when the sensor has no reading (the ground out of its reach, or the vehicle
    too tilted): one message per rangefinder tick either way, so a lockstep agent knows not to wait."""
    sigma_m: Positive
    """The reading's standard deviation [m], the sensor's claim."""


@_declare
class Barometer(Message):
    """A barometric altimeter's reading of one vehicle: ``<ns>/agent/<id>/barometer`` (a log's ``baro.csv``;
    PX4's ``vehicle_air_data.baro_alt_meter``, a Crazyflie's ``baro.asl``): the altitude, up, on the
    sensor's own datum, so with any constant offset from the nav frame's height (a receiver estimates it)."""

    tick: Nat
    """Tick ``k`` of the reading."""
    t_s: TimeS
    """Time of the reading [s]."""
    height_m: Finite | None
    """Barometric altitude, up, with any constant offset [m], any sign; nil when the sensor has no
    reading, so a lockstep agent knows not to wait."""
    sigma_m: Positive
    """The reading's standard deviation [m], the sensor's claim."""


_VISION_WIDTH = {"features": 3, "pixels": 2, "pose": POSE_LEN}


@_declare
class Vision(Message):
    """One camera frame's observations of the target's markers: ``<ns>/agent/<id>/vision``."""

    tick: Nat
    """Tick ``k`` of the frame."""
    t_s: TimeS
    """Exposure time [s]."""
    target_id: Name
    """Agent id of the vehicle whose markers were seen."""
    face: Literal[FACES]  # type: ignore[valid-type]
    """Face of the target the markers belong to (the outward normal in the target's body frame)."""
    kind: Literal[VISION_KINDS]  # type: ignore[valid-type]
    """``features``: marker positions in the camera frame [m] (the paper's feature model); ``pixels``:
    marker image coordinates [px] (the agent runs PnP); ``pose``: the target's pose in the camera frame
    from a camera that runs PnP itself, with its covariance."""
    data: array((None, None))
    """(N, 3) [m] in the OpenCV camera frame (+z optical axis, +x right, +y down) for ``features``; (N, 2)
    [px] image coordinates (u right, v down, as ``cv2.projectPoints`` gives them) for ``pixels``; row i is
    marker ``marker_ids[i]``. For ``pose``, (N, 43) with N <= 1: the target origin in the camera frame
    ``t_cam_m`` (3) [m], the attitude ``q_cam_target`` (4, scalar-last, ``X_cam = R(q) X_target + t``) and
    the covariance (6 x 6, row-major, symmetric, positive definite) of ``(dt_cam [m], dphi_cam [rad])``
    (``swarm.core.camera``). N = 0 is a frame in which no marker was detected: a camera reports every
    frame, so a lockstep agent knows its camera tick is complete (``docs/protocol.md``, "Clocks and
    lockstep")."""
    marker_ids: MarkerIds
    """Index of each row's marker in the face's pattern, N entries; for ``pose``, the markers the pose was
    computed from (empty when N = 0)."""

    @property
    def seen(self) -> bool:
        """Whether any marker was detected in this frame."""
        return len(self.marker_ids) > 0

    def _validate(self) -> None:
        data, ids, width = self.data, self.marker_ids, _VISION_WIDTH[self.kind]
        if data.shape == (0, 0):
            data = np.zeros((0, width))  # "no rows" as an empty list
            self._set(data=data)
        if data.shape[1] != width:
            raise MessageError(f"data: expected shape (N, {width}), got {data.shape}")
        if self.kind != "pose":
            if len(ids) != data.shape[0]:
                raise MessageError(f"marker_ids: {len(ids)} ids for {data.shape[0]} rows of data")
            return
        if data.shape[0] > 1:
            raise MessageError(f"data: a pose frame holds at most one pose, got {data.shape[0]} rows")
        if (len(ids) > 0) != (data.shape[0] == 1):
            raise MessageError(f"marker_ids: {len(ids)} ids for {data.shape[0]} poses")
        if data.shape[0] == 1:
            cov = data[0, 7:].reshape(6, 6)
            what = "data: a pose's covariance (columns 7-42)"
            if not np.array_equal(cov, cov.T) or not (np.diag(cov) > 0.0).all():
                raise MessageError(
                    f"{what} must be symmetric with a positive diagonal, got {np.diag(cov).tolist()}"
                )
            try:
                np.linalg.cholesky(cov)
            except np.linalg.LinAlgError:
                raise MessageError(f"{what} is not positive definite") from None


def encode_vision(tick: int, t_s: float, target_id: str, face: str, kind: str, data, marker_ids) -> bytes:
    """``encode(Vision(...))``, the same bytes, its arrays not copied: the world's camera frames."""
    return send(Vision, tick, t_s, target_id, face, kind, data, marker_ids)


@_declare
class VisionBatch(_Batch):
    """The camera frames of many vehicles at one tick, in one message: ``<ns>/world/vision``, sent by a
    simulated world that serves agent hosts instead of one ``agent/<id>/vision`` per chaser (docs/protocol.md,
    "Rates"). A frame's size depends on its kind and on what its camera saw, so each entry is the frame
    as its own key would carry it: the msgpack bytes of a :class:`Vision` (a map, the same fields and checks),
    and a receiver decodes only the entries of its vehicles (:meth:`sample`)."""

    tick: Nat
    """Tick ``k`` of the camera slot, every frame's."""
    t_s: TimeS
    """Exposure time [s], every frame's."""
    ids: Vehicles
    """The vehicles: entry ``i`` of ``frames`` is ``ids[i]``'s."""
    frames: blobs("Vision")
    """Each vehicle's frame, an encoded :class:`Vision` (msgpack bin) of the batch's tick and time, one per
    id; the whole message stays within 64 KiB."""

    def _validate(self) -> None:
        _per_id(self, self.ids, "frames")

    def sample(self, vid: str, row: int | None = None) -> Vision | None:
        """Vehicle ``vid``'s :class:`Vision` (``row`` its entry when known, :meth:`index`), decoded and
        checked as its own key's would be, ``None`` when the batch has none. MessageError naming the entry
        (``frames[3]: ...``) for a frame that does not decode, or whose tick or time is not the batch's."""
        row = self._row(vid, row)
        return None if row is None else self._entry("frames", row, Vision)


@_declare
class CommandBatch(_Batch):
    """The commands an agent host's vehicles decided in one of its rounds, in one message:
    ``<ns>/agent/<id>/commands`` (``<id>`` the host's first vehicle), what a free-running host of several
    vehicles sends the world instead of one ``agent/<id>/command`` each (docs/protocol.md, "Rates"). Entry
    ``i`` is vehicle ``ids[i]``'s command as its own key would carry it, the msgpack bytes of a
    :class:`Command` (a vehicle's kind fixes its actuators' count, and the entries of one round may be of
    different ticks)."""

    ids: Vehicles
    """The vehicles: entry ``i`` of ``commands`` is ``ids[i]``'s."""
    commands: blobs("Command")
    """Each vehicle's command, an encoded :class:`Command` (msgpack bin), one per id."""

    def _validate(self) -> None:
        _per_id(self, self.ids, "commands")

    def sample(self, vid: str, row: int | None = None) -> Command | None:
        """Vehicle ``vid``'s :class:`Command`, decoded and checked as its own key's would be, ``None`` when
        the batch has none; MessageError naming the entry (``commands[3]: ...``) if it does not decode."""
        row = self._row(vid, row)
        return None if row is None else self._entry("commands", row, Command)


def _bundle_types(value: object, name: str) -> tuple[str, ...]:
    if not isinstance(value, list | tuple) or not 1 <= len(value) <= MAX_BATCH:
        raise MessageError(f"{name}: expected 1 to {MAX_BATCH} message types, got {show(value)}")
    for i, t in enumerate(value):
        if t not in BUNDLE_TYPES:
            raise MessageError(f"{name}[{i}]: expected one of {', '.join(BUNDLE_TYPES)}, got {show(t)}")
    return tuple(value)


@_declare
class Bundle(Message):
    """The samples of several consecutive lockstep ticks for one receiver, in one message: what a lockstep
    world sends on ``<ns>/agent/<id>/bundle`` (that vehicle's ``imu`` and ``vision``) and
    ``<ns>/world/bundle`` (the ``world/truth`` batches, for the mothership), and the mothership on
    ``<ns>/agent/<id>/bundle`` (that vehicle's ``uwb``), instead of one message per sample (docs/protocol.md,
    "Bundles"). Entry ``i`` is the message its own key would have carried, type ``types[i]``: its msgpack
    bytes, decoded and checked by the receiver (:func:`bundle_messages`), in the order they would have been
    published."""

    tick: Nat
    """The newest tick of any entry."""
    types: Annotated[
        tuple[Literal[BUNDLE_TYPES], ...],  # type: ignore[valid-type]
        msgspec.Meta(min_length=1, max_length=MAX_BATCH),
        Check(_bundle_types, "each `Imu`, `Uwb`, `Vision`, `TruthBatch` or `Tdoa`", on_decode=False),
    ]
    """Each entry's message type."""
    entries: blobs("wire")
    """The entries, one per type: each an encoded message (msgpack bin); the whole message stays within
    64 KiB."""

    def _validate(self) -> None:
        if len(self.entries) != len(self.types):
            raise MessageError(
                f"entries: expected one per type ({len(self.types)}), got {show(self.entries)}"
            )


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
        types, blobs_, ticks = zip(*entries[a:b], strict=True)
        out.append(encode(Bundle(max(ticks), types, blobs_)))
    return out


@_declare
class Estimate(Message):
    """The pose estimate of one vehicle after tick ``k``'s measurements: ``<ns>/agent/<id>/estimate``."""

    tick: Nat
    """Tick ``k`` of the last measurement processed."""
    t_s: TimeS
    """Time of the estimate [s]."""
    p_nav: array((3,))
    """Centre-of-mass position (3,) [m], frame nav."""
    v_nav: array((3,))
    """Centre-of-mass velocity (3,) [m/s], frame nav."""
    q_nav_body: array((4,), unit=True)
    """Attitude (4,), mapping body into nav."""
    cov: array((9, 9), cov=True)
    """Error-state covariance (9, 9) of ``(d_p [m], d_v [m/s], d_theta [rad])``, ``d_theta`` a body-frame
    rotation vector (``q = q_est (x) exp(d_theta)``). The tandem filter's cross terms between translation
    and attitude are zero. While a chaser navigates relative to its target (vision), the position block
    includes the target's estimate covariance: its position in nav is known only as well as the target's
    (``swarm.step.agent.absolute_cov_pos``)."""
    sigma_pos_max_m: NonNeg
    """Largest position standard deviation [m], Algorithm 1's ``max(sigma_pos)``."""
    mahalanobis_d: NonNeg
    """Mahalanobis distance of the latest innovation (dimensionless), Algorithm 1's ``d``."""
    rejection_fraction: Share
    """Fraction of measurements rejected by the gate over the health window."""
    counts: Annotated[
        dict[Name, Nat], msgspec.Meta(max_length=MAX_ITEMS),
        Check(_counts, "names `[A-Za-z0-9_-]{1,64}`, counts >= 0, at most 64", on_decode=False),
    ]  # fmt: skip
    """Cumulative update counters named ``<kind>_<outcome>``, e.g. ``range_accepted``, ``range_rejected``,
    ``features_refused``."""


def estimate_message(*args) -> Estimate:
    """``Estimate(*args)``, or, when its covariance (``args[5]``) is off symmetry by rounding only, the same
    with the covariance's symmetric part: what a filter publishes after an update."""
    try:
        return Estimate(*args)
    except MessageError:
        cov = np.asarray(args[5])
        return Estimate(*args[:5], 0.5 * (cov + cov.T), *args[6:])


def encode_estimate(
    tick: int, t_s: float, p_nav, v_nav, q_nav_body, cov, sigma_pos_max_m: float, mahalanobis_d: float,
    rejection_fraction: float, counts: dict[str, int],
) -> bytes:  # fmt: skip
    """``encode(estimate_message(...))``, the same bytes, its arrays not copied: what an agent sends every
    tick."""
    args = (tick, t_s, p_nav, v_nav, q_nav_body, cov, sigma_pos_max_m, mahalanobis_d, rejection_fraction,
            counts)  # fmt: skip
    try:
        return send(Estimate, *args)
    except MessageError:
        c = np.asarray(cov)
        return send(Estimate, *args[:5], 0.5 * (c + c.T), *args[6:])


def estimate_and_payload(
    tick: int, t_s: float, p_nav, v_nav, q_nav_body, cov, sigma_pos_max_m: float, mahalanobis_d: float,
    rejection_fraction: float, counts: dict[str, int], *, payload: bool = True,
) -> tuple[Estimate, bytes | None]:  # fmt: skip
    """:func:`encode_estimate`'s bytes and the message a receiver decodes from them (its arrays copies), for
    a receiver in the same process: an agent host hands a target's estimate to its chaser without the
    decoding (``agents.host``). ``payload=False``: the message alone (``None`` for the bytes), when no one
    else subscribes."""
    msg = estimate_message(tick, t_s, p_nav, v_nav, q_nav_body, cov, sigma_pos_max_m, mahalanobis_d,
                           rejection_fraction, counts)  # fmt: skip
    return msg, encode(msg) if payload else None


@_declare
class Guidance(Message):
    """Guidance state of one vehicle after tick ``k``: ``<ns>/agent/<id>/guidance``."""

    tick: Nat
    """Tick ``k``."""
    t_s: TimeS
    """Time [s]."""
    mode: Literal[MODES]  # type: ignore[valid-type]
    """Current guidance mode: a docking mode (``STATION``: the station-keeping target) or a landing mode
    (``swarm/core/landing.py``)."""
    range_m: NonNeg | None = None
    """Estimated range to the target [m]; nil without a target (the station keeper)."""
    r1_m: NonNeg | None = None
    """REORIENT -> ALIGN switch radius [m]; nil for a vehicle without a switcher."""
    r2_m: NonNeg | None = None
    """APPROACH -> REORIENT switch radius [m]; nil for a vehicle without a switcher."""
    r_t_m: NonNeg | None = None
    """Radius below which Algorithm 1 runs [m]; nil for a vehicle without a switcher."""
    decision: Annotated[
        dict[str, float | None] | None,
        Check(
            _decision,
            "exactly the keys of `swarm/core/decision_keys.py`, numbers >= 0, probabilities in [0, 1]",
        ),
    ] = None
    """The latest pass of Algorithm 1 (below): ``A11 A22 A23 A32 A33 pi1 pi2`` are probabilities or nil where
    the branch did not compute them; other keys are dropped. Nil before the first pass or with the fixed
    policy."""
    reason: Annotated[str, msgspec.Meta(max_length=MAX_TEXT)] = ""
    """Human-readable account of the latest mode decision."""


@_declare
class Command(Message):
    """Actuator command of one vehicle for tick ``k``, held until the next: ``<ns>/agent/<id>/command``."""

    tick: Nat
    """Tick ``k`` this command answers: in lockstep the world steps to ``k + 1`` once it has it."""
    t_s: TimeS
    """Time [s]."""
    actuators: array((None,))
    """The vehicle kind's actuator command (N,), in the kind's order and units: a ``cubesat``'s ten nozzle
    thrusts [N] (>= 0), a ``ground`` module's four wheel speeds [rad/s] (front-left, front-right,
    rear-right, rear-left). The world holds it until the next command and brings it into the actuators'
    range (a nozzle cannot pull, a wheel cannot pass its top speed); a command of the wrong length for the
    vehicle's kind is dropped and counted."""
    mode: Literal[MODES]  # type: ignore[valid-type]
    """Guidance mode that produced it (as ``Guidance.mode``)."""
    force_body_n: array((3,)) | None = None
    """Net force the command produces (3,) [N], body frame, where the kind has one (the nozzles)."""
    torque_body_nm: array((3,)) | None = None
    """Net torque about the centre of mass (3,) [N m], body frame, where the kind has one."""


def encode_command(
    tick: int, t_s: float, actuators, mode: str, force_body_n=None, torque_body_nm=None
) -> bytes:
    """``encode(Command(...))``, the same bytes, its arrays not copied: what an agent sends every tick."""
    return send(Command, tick, t_s, actuators, mode, force_body_n, torque_body_nm)


@_declare
class Truth(Message):
    """True state of one vehicle at tick ``k`` (agents never subscribe): ``<ns>/agent/<id>/truth``."""

    tick: Nat
    """Tick ``k``."""
    t_s: TimeS
    """Time [s]."""
    p_nav: array((3,))
    """Centre-of-mass position (3,) [m], frame nav."""
    v_nav: array((3,))
    """Centre-of-mass velocity (3,) [m/s], frame nav."""
    q_nav_body: array((4,), unit=True)
    """Attitude (4,), mapping body into nav."""
    w_body: array((3,))
    """Angular rate (3,) [rad/s], body frame."""
    effort: NonNeg = 0.0
    """The vehicle's effort since the run began, in its kind's measure: a ``cubesat``'s total impulse
    ``sum |f| dt`` [N s], a ``ground`` module's wheel travel ``sum |omega| dt`` [rad]."""
    uwb_lost: bool = False
    """The radio environment of the vehicle's UWB tag at tick ``k``: every reply lost (a dropout window of
    the world's fault schedule). The mothership's simulated radios apply it to the exchange of this tick."""
    nlos_probability: Share = 0.0
    """... and the NLOS outlier probability of an exchange inside a burst window (0: none; the radio's own
    ``uwb.nlos_probability`` applies anyway)."""


def encode_imu(tick: int, t_s: float, dt_s: float, gyro_body, q_ahrs_nav_body=None, acc_body=None) -> bytes:
    """``encode(Imu(...))``, the same bytes, its arrays not copied: what a world sends every tick."""
    return send(Imu, tick, t_s, dt_s, gyro_body, q_ahrs_nav_body, acc_body)


def encode_uwb(tick: int, t_s: float, anchor_id: int, range_m: float | None) -> bytes:
    """``encode(Uwb(...))``, the same bytes: what a mothership sends every slot."""
    return send(Uwb, tick, t_s, anchor_id, range_m)


def encode_truth(
    tick: int, t_s: float, p_nav, v_nav, q_nav_body, w_body, effort: float = 0.0, uwb_lost: bool = False,
    nlos_probability: float = 0.0,
) -> bytes:  # fmt: skip
    """``encode(Truth(...))``, the same bytes, its arrays not copied."""
    return send(Truth, tick, t_s, p_nav, v_nav, q_nav_body, w_body, effort, uwb_lost, nlos_probability)


@_declare
class TruthBatch(_Batch):
    """The :class:`Truth` of many vehicles at one tick, in one message: ``<ns>/world/truth``, what a world
    serving agent hosts sends its mothership instead of one ``agent/<id>/truth`` each (docs/protocol.md,
    "Rates"; the per-vehicle truths then go to a viewer only, while one subscribes). Row ``i`` of every
    array is vehicle ``ids[i]``'s; :meth:`sample` gives one vehicle's :class:`Truth`."""

    tick: Nat
    """Tick ``k``, every row's."""
    t_s: TimeS
    """Time [s], every row's."""
    ids: Vehicles
    """The vehicles."""
    p_nav: array((None, 3), max_rows=MAX_BATCH)
    """Positions (N, 3) [m], frame nav (``Truth.p_nav``)."""
    v_nav: array((None, 3), max_rows=MAX_BATCH)
    """Velocities (N, 3) [m/s], frame nav."""
    q_nav_body: array((None, 4), unit="rows", max_rows=MAX_BATCH)
    """Attitudes (N, 4), body into nav."""
    w_body: array((None, 3), max_rows=MAX_BATCH)
    """Angular rates (N, 3) [rad/s], body frames."""
    effort: array((None,), max_rows=MAX_BATCH)
    """Efforts (N,) since the run began (>= 0), each in its kind's measure (``Truth.effort``)."""
    uwb_lost: tuple[bool, ...]
    """Each tag's radio environment: every reply lost (``Truth.uwb_lost``)."""
    nlos_probability: array((None,), max_rows=MAX_BATCH)
    """Each tag's NLOS outlier probability in a burst window (N,), in [0, 1]."""

    def _validate(self) -> None:
        n = len(self.ids)
        for name in ("p_nav", "v_nav", "q_nav_body", "w_body", "effort", "nlos_probability"):
            a = getattr(self, name)
            if a.shape[0] != n:
                raise MessageError(f"{name}: expected shape {(n, *a.shape[1:])}, got {a.shape}")
        _per_id(self, self.ids, "uwb_lost")
        effort, nlos = self.effort, self.nlos_probability
        if effort.min() < 0.0:
            i = int(np.flatnonzero(effort < 0.0)[0])
            raise MessageError(f"effort[{i}]: must be >= 0, got {effort[i]}")
        if nlos.min() < 0.0 or nlos.max() > 1.0:
            i = int(np.flatnonzero((nlos < 0.0) | (nlos > 1.0))[0])
            raise MessageError(f"nlos_probability[{i}]: must be in [0, 1], got {nlos[i]}")

    def sample(self, vid: str, row: int | None = None) -> Truth | None:
        """Vehicle ``vid``'s :class:`Truth` (``row`` its row when known, :meth:`index`), ``None`` when the
        batch has none. Its arrays are copies of the batch's checked rows (not checked again)."""
        row = self._row(vid, row)
        if row is None:
            return None
        return trusted(Truth, {
            "tick": self.tick, "t_s": self.t_s, "p_nav": self.p_nav[row].copy(),
            "v_nav": self.v_nav[row].copy(), "q_nav_body": self.q_nav_body[row].copy(),
            "w_body": self.w_body[row].copy(), "effort": float(self.effort[row]),
            "uwb_lost": self.uwb_lost[row], "nlos_probability": float(self.nlos_probability[row]),
        })  # fmt: skip


def encode_truth_batch(
    tick: int, t_s: float, ids: tuple[str, ...], X: np.ndarray, effort: np.ndarray, uwb_lost: bool,
    nlos_probability: float,
) -> bytes:  # fmt: skip
    """``encode(TruthBatch(...))`` of the rows of ``X`` (N, 13: position, velocity, attitude, rate, the
    world's truth layout), every tag in the same radio environment, its arrays not copied (a world sends
    one every UWB slot tick)."""
    n = len(ids)
    x = np.asarray(X, dtype=np.float64)
    effort = np.asarray(effort, dtype=np.float64)
    return send(TruthBatch, tick, t_s, ids, x[:, 0:3], x[:, 3:6], x[:, 6:10], x[:, 10:13], effort,
                (uwb_lost,) * n, np.full(n, nlos_probability))  # fmt: skip


_EVENT_KIND = r"\A(?:[a-z][a-z0-9_]*)\Z"


@_declare
class Event(Message):
    """Something that happened to one vehicle, ``<ns>/agent/<id>/event`` (published by its agent, and by the
    world for what only the truth shows: ``contact``, ``collision``, ``keepout_violation``), or to the
    run, ``<ns>/world/event`` (the world: ``run_start``, ``run_end``, ``agent_missing``, ``fault`` and
    ``fault_refused`` for a run-time fault, UWB faults included: the world's schedule drives the radios)."""

    t_s: TimeS
    """Time [s]."""
    kind: Annotated[str, msgspec.Meta(pattern=_EVENT_KIND, max_length=MAX_NAME)]
    """What happened; :data:`EVENT_KINDS` lists those in use."""
    data: Annotated[
        dict[str, Any],
        Check(
            _event_data, "nil, bool, int, finite float, str, arrays and str-keyed maps, nested at most 8 deep"
        ),
    ] = msgspec.field(default_factory=dict)
    """Details, free form; e.g. ``{"from": "APPROACH", "to": "REORIENT", "range_m": 0.62, "reason": "..."}``
    for ``mode``."""


@_declare
class Clock(Message):
    """The world's clock and run state, every :data:`CLOCK_EVERY` ticks and at every state change:
    ``<ns>/world/clock``."""

    tick: Nat
    """Current tick ``k``."""
    t_s: TimeS
    """Current time [s], ``k * dt``."""
    state: Literal[CLOCK_STATES]  # type: ignore[valid-type]
    """The run's state."""
    seed: Nat
    """Seed of the current run: every random stream of the run derives from it."""


@_declare
class Anchors(Message):
    """The mothership's UWB anchors: ``<ns>/mothership/anchors`` (published and answered to queries)."""

    anchor_ids: AnchorIds
    """Id of each anchor, N entries."""
    positions_nav: array((None, 3))
    """Antenna position of each anchor (N, 3) [m], frame nav; row i is ``anchor_ids[i]``."""

    def _validate(self) -> None:
        if self.positions_nav.shape[0] != len(self.anchor_ids):
            raise MessageError(
                f"positions_nav: {self.positions_nav.shape[0]} rows for {len(self.anchor_ids)} anchor ids"
            )


@_declare
class RunControl(Message):
    """A request to the world from the dashboard or the launcher: ``<ns>/control/run``."""

    command: Literal[RUN_COMMANDS]  # type: ignore[valid-type]
    """``pause``, ``resume``, ``reset`` (restart the run) or ``new_seed`` (restart, new seed)."""
    seed: Nat | None = None
    """Seed for ``reset``/``new_seed``; nil: ``reset`` keeps the current seed and ``new_seed`` lets the
    world draw one. Ignored by ``pause`` and ``resume``."""


@_declare
class Fault(Message):
    """A fault to inject at run time: ``<ns>/control/fault`` (``swarm fault``; the world applies camera and
    gyro faults, the mothership UWB ones). Every window opens no earlier than the receiver's next tick."""

    kind: Literal[FAULT_KINDS]  # type: ignore[valid-type]
    """The fault (``sensor_delay``: free-running clocks only, a lockstep world refuses it)."""
    duration_s: Positive | None = None
    """Length of the window [s]; required for every kind but ``gyro_bias_step`` (which lasts)."""
    start_s: TimeS | None = None
    """Simulated time the window opens [s]; nil: at once (the receiver's next tick)."""
    vehicle: Name | None = None
    """The vehicle (``camera_loss``: a chaser; ``gyro_bias_step``: any); nil: every chaser."""
    probability: NonNeg | None = None
    """``nlos_burst``: probability that an exchange is an NLOS outlier inside the window, in (0, 1]
    (required)."""
    rate_rad_s: array((3,)) | None = None
    """``gyro_bias_step``: the constant rate (3,) [rad/s], body frame, added to the gyro from ``start_s``
    (required)."""
    delay_s: Positive | None = None
    """``sensor_delay``: each imu/vision sample of the vehicle(s) inside the window leaves the world late by
    a uniform random delay in ``[0, delay_s]`` [s of simulated time], so samples also arrive out of order
    (required)."""

    def _validate(self) -> None:
        kind = self.kind
        if self.duration_s is None and kind != "gyro_bias_step":
            raise MessageError(f"duration_s: required for a {kind} fault")
        prob = self.probability
        if kind == "nlos_burst" and (prob is None or not 0.0 < prob <= 1.0):
            raise MessageError(f"probability: an nlos_burst needs one in (0, 1], got {prob}")
        if kind == "gyro_bias_step" and self.rate_rad_s is None:
            raise MessageError("rate_rad_s: required for a gyro_bias_step fault")
        if kind == "sensor_delay" and self.delay_s is None:
            raise MessageError("delay_s: required for a sensor_delay fault")


MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.__name__: cls
    for cls in (
        Imu, ImuBatch, Uwb, UwbBatch, Tdoa, TdoaBatch, Vision, VisionBatch, Gnss, Rangefinder, Barometer,
        Estimate, Guidance, Command, CommandBatch, Truth, TruthBatch, Bundle, Event, Clock, Anchors,
        RunControl, Fault,
    )
}  # fmt: skip
"""Every message class by its wire ``"type"``, in the order of ``docs/protocol.md``."""

MESSAGE_FOR_KIND: dict[str, type[Message]] = {
    "imu": Imu, "uwb": Uwb, "tdoa": Tdoa, "vision": Vision, "gnss": Gnss, "rangefinder": Rangefinder,
    "barometer": Barometer, "estimate": Estimate, "guidance": Guidance, "command": Command,
    "commands": CommandBatch, "truth": Truth, "event": Event, "world_clock": Clock, "world_event": Event,
    "world_imu": ImuBatch, "world_vision": VisionBatch, "anchors": Anchors, "mothership_uwb": UwbBatch,
    "world_truth": TruthBatch, "mothership_tdoa": TdoaBatch, "run_control": RunControl, "fault": Fault,
    "bundle": Bundle, "world_bundle": Bundle,
}  # fmt: skip
"""The message carried by each key kind of :meth:`swarm.transport.keys.Keys.parse`."""


# ------------------------------------------------------------------------------------ batch packing


def batch_rows(
    batch: _Batch, key: str, drops: DropCounter, ids: Container[str] | None = None
) -> list[tuple[str, Message]]:
    """Each vehicle's message of ``batch`` (of the vehicles in ``ids``; ``None``: every one), as ``(vehicle,
    message)`` in the batch's order: an entry that does not decode (a :class:`VisionBatch`'s or
    :class:`CommandBatch`'s, whose entries are decoded here) is dropped and counted in ``drops`` under
    ``key``, naming the vehicle and the entry, and the others are kept: one vehicle's bad entry loses no
    other vehicle's."""
    out = []
    for row, vid in enumerate(batch.ids):  # type: ignore[attr-defined]
        if ids is not None and vid not in ids:
            continue
        try:
            out.append((vid, batch.sample(vid, row)))  # type: ignore[attr-defined]
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


def pack_entries(
    entries: list[tuple[str, bytes]], make_batch: Callable[[tuple, tuple], Message]
) -> list[bytes]:
    """``(vehicle, encoded message)`` entries, in order, in as few batch messages (``make_batch(ids,
    payloads)``: a :class:`VisionBatch` or :class:`CommandBatch`) as keep each within
    :data:`MAX_PAYLOAD_BYTES` and :data:`MAX_BATCH` vehicles, a vehicle at most once per message (a host
    that caught up on two of its ticks in one round sends the second command in the next message, after
    the first)."""
    out = []
    for a, b in _spans(entries, distinct=True):
        ids, payloads = zip(*entries[a:b], strict=True)
        out.append(encode(make_batch(ids, payloads)))
    return out


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
