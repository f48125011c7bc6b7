"""Declared wire messages: a message is one msgspec Struct whose field types say its wire form and its checks.

A message class (:mod:`swarm.transport.messages`) declares each field once, with an annotation that is at
the same time

- what msgspec decodes and checks in C on a receiver (``Annotated[int, Meta(ge=0)]``, ``Literal[...]``,
  ``tuple[str, ...]``, :class:`WireArray` for an array's ``{"dtype", "shape", "data"}`` map),
- what the constructor checks on a sender (the same constraints, compiled by :func:`declare` into small
  Python checks whose :class:`~swarm.errors.MessageError` names the field and the value), and
- the row of ``docs/protocol.md``'s table of the message (:mod:`swarm.transport.protocol_tables`: the type,
  the default, the checks and the field's docstring).

What msgspec cannot say is said by markers in the same annotation: :class:`Arr` (an array's shape, finite
entries, a unit quaternion, a covariance), :class:`Check` (a check function, e.g. distinct ids), and a
message's ``_validate`` method for what spans fields (rows against ids, a pose's covariance).

The checks run in ``__post_init__`` in one of four modes (a thread's own): ``BUILD`` (a message built in
Python: every check, arrays copied), ``SEND`` (the sender fast paths ``encode_imu`` ...: every check, arrays
not copied, the message is encoded and dropped), ``DECODE`` (msgspec decoded it and checked what it can:
the arrays and the :class:`Check` fields that ask for it, then ``_validate``) and ``TRUSTED`` (a batch's
rows, checked already).
"""

from __future__ import annotations

import math
import re
import sys
import threading
import types
import typing
from collections.abc import Callable
from typing import Annotated, Any, Literal, TypeVar

import msgpack
import msgspec
import numpy as np

from swarm.errors import MessageError

SCHEMA_VERSION = 2
"""Value of the ``"v"`` key of every message; a receiver drops any other version."""
MAX_PAYLOAD_BYTES = 65536
"""Largest accepted payload [bytes]; larger ones are refused before unpacking."""
MAX_ITEMS = 64
"""Largest number of markers, nozzles, anchors, counters per message."""
MAX_BATCH = 256
"""Most vehicles in one batch message (``ImuBatch``); a larger swarm's world sends several."""
QUAT_NORM_TOL = 1e-3
"""A quaternion's norm must be within this of 1."""
COV_SYMMETRY_RTOL = 1e-9
"""``max |P - P^T| <= COV_SYMMETRY_RTOL * max |P|`` for a covariance."""
MAX_TEXT = 1024  # reasons and free text [characters]
MAX_NAME = 64  # modes, kinds, counter names [characters]
MAX_ID = 2**31 - 1  # marker and anchor ids fit an int32 in any language
U64_MAX = 2**64 - 1  # msgpack's integer range
_F64_MAX = sys.float_info.max  # a bound that excludes only the infinities (and NaN fails every bound)
_MAX_DEPTH = 8  # nesting of event data
_I64_MIN = -(2**63)

Nat = Annotated[int, msgspec.Meta(ge=0)]
"""An integer 0 .. 2^64-1 (ticks, seeds, counters; msgpack holds no larger one)."""
TimeS = Annotated[float, msgspec.Meta(ge=0.0, le=_F64_MAX)]
"""A time [s], finite, >= 0."""
NonNeg = Annotated[float, msgspec.Meta(ge=0.0, le=_F64_MAX)]
"""A finite number >= 0."""
Positive = Annotated[float, msgspec.Meta(gt=0.0, le=_F64_MAX)]
"""A finite number > 0."""
Finite = Annotated[float, msgspec.Meta(ge=-_F64_MAX, le=_F64_MAX)]
"""A finite number of any sign."""
Share = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
"""A fraction or a probability, in [0, 1]."""
MarkerId = Annotated[int, msgspec.Meta(ge=0, le=MAX_ID)]
"""A marker's or an anchor's id, 0 .. 2^31-1."""


# ------------------------------------------------------------------------------------- field checks


def show(value: object) -> str:
    """``value`` for an error message, at most 60 characters."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def is_int(x: object) -> bool:
    return isinstance(x, int | np.integer) and not isinstance(x, bool | np.bool_)


def is_real(x: object) -> bool:
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(x, bool | np.bool_)


def check_bool(value: object, name: str) -> bool:
    if not isinstance(value, bool | np.bool_):
        raise MessageError(f"{name}: expected true or false, got {show(value)}")
    return bool(value)


def check_int(value: object, name: str, lo: int = 0, hi: int = U64_MAX) -> int:
    if not is_int(value):
        raise MessageError(f"{name}: expected an integer, got {show(value)}")
    v = int(value)  # type: ignore[call-overload]
    if v < lo:
        raise MessageError(f"{name}: must be >= {lo}, got {v}")
    if v > hi:
        raise MessageError(f"{name}: must be <= {hi}, got {v}")
    return v


def check_float(
    value: object, name: str, *, lo: float | None = None, hi: float | None = None, positive: bool = False,
    nullable: bool = False,
) -> Any:  # fmt: skip
    """A finite float (a Python one, from any real number), within the bounds given."""
    if value is None and nullable:
        return None
    if not is_real(value):
        raise MessageError(f"{name}: expected a number{' or nil' if nullable else ''}, got {show(value)}")
    try:
        v = float(value)  # type: ignore[arg-type]
    except OverflowError:
        v = math.inf
    if not math.isfinite(v):
        raise MessageError(f"{name}: not finite ({v})")
    if positive and not v > 0.0:
        raise MessageError(f"{name}: must be > 0, got {v}")
    if lo is not None and v < lo:
        raise MessageError(f"{name}: must be >= {lo:g}, got {v}")
    if hi is not None and v > hi:
        within = f"in [{lo:g}, {hi:g}]" if lo is not None else f"<= {hi:g}"
        raise MessageError(f"{name}: must be {within}, got {v}")
    return v


def check_str(
    value: object, name: str, *, choices: tuple[str, ...] | None = None, pattern: re.Pattern | None = None,
    max_len: int = MAX_NAME,
) -> str:  # fmt: skip
    if not isinstance(value, str):
        raise MessageError(f"{name}: expected a string, got {show(value)}")
    value = str(value)  # a StrEnum member becomes its plain value
    if choices is not None and value not in choices:
        raise MessageError(f"{name}: expected one of {choices}, got {show(value)}")
    if len(value) > max_len:
        raise MessageError(f"{name}: {len(value)} characters, more than the {max_len} allowed")
    if pattern is not None and not pattern.fullmatch(value):
        raise MessageError(f"{name}: must match {pattern.pattern}, got {show(value)}")
    return value


_WIRE_DTYPE = re.compile(r"[<>](?:f[248]|[iu][1248])|\|[iu]1")


def _unpack_array(d: dict, name: str) -> np.ndarray:
    """The ``{"dtype", "shape", "data"}`` wire form of an array, as a read-only view of ``data``."""
    for k in ("dtype", "shape", "data"):
        if k not in d:
            raise MessageError(f"{name}: an array map needs 'dtype', 'shape' and 'data'; {k!r} is missing")
    code, shape, data = d["dtype"], d["shape"], d["data"]
    if not isinstance(code, str) or not _WIRE_DTYPE.fullmatch(code):
        raise MessageError(
            f"{name}.dtype: expected an int/float code with byte order like '<f8', got {show(code)}"
        )
    if not (
        isinstance(shape, list | tuple)
        and len(shape) <= 2
        and all(is_int(s) and 0 <= s <= MAX_PAYLOAD_BYTES for s in shape)
    ):
        raise MessageError(
            f"{name}.shape: expected a list of at most 2 sizes in [0, 65536], got {show(shape)}"
        )
    if not isinstance(data, bytes | bytearray | memoryview):
        raise MessageError(f"{name}.data: expected bin (raw bytes), got {show(data)}")
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
        elif depth != ndim or not is_real(x):
            raise MessageError(f"{name}: expected {ndim}-level nested arrays of numbers, got {show(x)}")

    walk(value, 0)
    try:
        return np.array(value, dtype=np.float64)
    except (ValueError, OverflowError) as exc:
        raise MessageError(f"{name}: ragged or out-of-range nested arrays ({exc})") from None


_F64 = np.dtype(np.float64)
_NATIVE_F8 = np.dtype("<f8") == _F64  # a little-endian machine: float64 bytes are the wire's as they are


def _finite(a: np.ndarray) -> bool:
    """Whether every entry of ``a`` is finite: a small array's sum in Python (a NaN or an infinity carries
    through; a finite sum too large to hold is decided by numpy), a larger one's entries in numpy."""
    if a.size <= 16 and math.isfinite(sum(a.ravel().tolist())):
        return True
    return bool(np.isfinite(a).all())


def check_array(
    value: object, name: str, shape: tuple[int | None, ...], max_rows: int = MAX_ITEMS, copy: bool = True
) -> np.ndarray:
    """A finite float64 array of ``shape`` (``None``: any length up to ``max_rows``), a writable copy unless
    ``copy`` is false and it is a float64 array already. Accepts an ndarray, nested lists/tuples or the
    wire map."""
    if type(value) is np.ndarray and value.dtype == _F64 and value.shape == shape:
        out = value.copy() if copy else value  # the common case, checked in one step
        if not _finite(out):
            raise MessageError(f"{name}: not finite")
        return out
    if isinstance(value, np.ndarray):
        arr = value
        if arr.dtype.kind not in "iuf":
            raise MessageError(f"{name}: expected numbers, got dtype {arr.dtype}")
    elif isinstance(value, dict):
        arr = _unpack_array(value, name)
    elif isinstance(value, list | tuple):
        if len(value) == 0 and len(shape) > 1 and shape[0] is None:
            arr = np.zeros((0, *(0 if s is None else s for s in shape[1:])))  # "no rows", as an empty list
        else:
            arr = _nested_numbers(value, name, len(shape))
    else:
        raise MessageError(
            f"{name}: expected an array (nested lists or a dtype/shape/data map), got {show(value)}"
        )
    if not (
        arr.ndim == len(shape) and all(e is None or a == e for a, e in zip(arr.shape, shape, strict=False))
    ):
        raise MessageError(f"{name}: expected shape {shape_text(shape)}, got {tuple(arr.shape)}")
    for a, e in zip(arr.shape, shape, strict=True):
        if e is None and a > max_rows:
            raise MessageError(f"{name}: {a} rows, more than the {max_rows} allowed")
    out = np.array(arr, dtype=np.float64) if copy or arr.dtype != _F64 else arr  # never a view of the payload
    if not _finite(out):
        raise MessageError(f"{name}: not finite")
    return out


def shape_text(shape: tuple) -> str:
    """``(N, 3)`` for ``(None, 3)``, ``(3,)`` for ``(3,)``."""
    return (
        "(" + ", ".join("N" if e is None else str(e) for e in shape) + ("," if len(shape) == 1 else "") + ")"
    )


class Defer(Exception):
    """The msgspec decoding leaves this payload to the reference decoding (whose errors name the field)."""


class WireArray(msgspec.Struct, gc=False):
    """The wire map of a float64 array as this codec writes it: what msgspec decodes in C."""

    dtype: Literal["<f8"]
    shape: list[int]
    data: bytes


def from_wire(a: WireArray, shape: tuple[int | None, ...], max_rows: int) -> np.ndarray:
    """A decoded array map as a writable float64 array of ``shape``; :class:`Defer` otherwise."""
    if len(a.shape) != len(shape):
        raise Defer
    n = 1
    for got, want in zip(a.shape, shape, strict=True):
        if got != want and (want is not None or not 0 <= got <= max_rows):
            raise Defer
        n *= got
    if len(a.data) != 8 * n:
        raise Defer
    return np.frombuffer(a.data, "<f8").reshape(a.shape).astype(np.float64)  # a writable copy


def clearly_unit(q: np.ndarray) -> bool:
    """``q`` (finite) passes the unit-norm test with a margin that no rounding of the norm can cross (at the
    margin's edge the exact test decides)."""
    return abs(math.hypot(*q.tolist()) - 1.0) <= 0.5 * QUAT_NORM_TOL


def check_unit(q: np.ndarray, name: str) -> np.ndarray:
    if clearly_unit(q):
        return q
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUAT_NORM_TOL:
        raise MessageError(
            f"{name}: norm {norm:.6g} is not within {QUAT_NORM_TOL:g} of 1 (unit quaternion x, y, z, w)"
        )
    return q


UNIT_LO, UNIT_HI = (1.0 - QUAT_NORM_TOL) ** 2, (1.0 + QUAT_NORM_TOL) ** 2


def check_units(q: np.ndarray, name: str) -> np.ndarray:
    """Rows of ``q`` (finite, ``(M, 4)``), each a unit quaternion within :data:`QUAT_NORM_TOL`."""
    n2 = (q * q).sum(axis=1)
    if n2.size == 0 or (n2.min() >= UNIT_LO and n2.max() <= UNIT_HI):
        return q
    norms = np.sqrt(n2)
    i = int(np.flatnonzero(np.abs(norms - 1.0) > QUAT_NORM_TOL)[0])
    raise MessageError(
        f"{name}[{i}]: norm {norms[i]:.6g} is not within {QUAT_NORM_TOL:g} of 1 (unit quaternion x, y, z, w)"
    )


_COV_KERNEL: Callable | None = None
"""The compiled covariance check (:func:`swarm.transport._codec_nb.covariance`), loaded on the first
covariance a sender fast path checks (an agent's estimate), so that a process that only decodes (a viewer,
a recorder) never imports numba; numpy's checks otherwise, which decide exactly anyway."""


def load_compiled() -> None:
    """Load the compiled covariance check (numba)."""
    global _COV_KERNEL
    from swarm.transport._codec_nb import covariance

    _COV_KERNEL = covariance


def check_covariance(p: np.ndarray, name: str) -> np.ndarray:
    asym = float(np.max(np.abs(p - p.T)))
    if asym > COV_SYMMETRY_RTOL * float(np.max(np.abs(p))):
        raise MessageError(f"{name}: not symmetric (max |P - P^T| = {asym:.3g})")
    diag = np.diag(p)
    if np.any(diag < 0.0):
        i = int(np.argmin(diag))
        raise MessageError(f"{name}: negative diagonal entry {diag[i]:.3g} at index {i}")
    return p


def check_plain(value: object, name: str, depth: int = 0) -> Any:
    """A copy of free-form data made of nil, bool, int, finite float, str, arrays and string-keyed maps."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if is_int(value):
        return check_int(value, name, _I64_MIN, U64_MAX)
    if is_real(value):
        return check_float(value, name)
    if depth >= _MAX_DEPTH:
        raise MessageError(f"{name}: nested deeper than {_MAX_DEPTH} levels")
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, list | tuple):
        return [check_plain(v, f"{name}[{i}]", depth + 1) for i, v in enumerate(value)]
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise MessageError(f"{name}: map keys must be strings, got {show(k)}")
            out[k] = check_plain(v, f"{name}.{k[:32]}", depth + 1)
        return out
    raise MessageError(f"{name}: unsupported value {show(value)} (nil, bool, int, float, str, array, map)")


# ---------------------------------------------------------------------------------- field markers


class Arr:
    """An array field: ``Annotated[WireArray, Arr((3,))]``. ``shape`` (``None``: any length up to
    ``max_rows``); ``unit``: a unit quaternion (x, y, z, w) (``"rows"``: each row one); ``cov``: a covariance
    (symmetric within :data:`COV_SYMMETRY_RTOL`, diagonal >= 0)."""

    def __init__(
        self, shape: tuple[int | None, ...], *, unit: bool | str = False, cov: bool = False,
        max_rows: int = MAX_ITEMS,
    ) -> None:  # fmt: skip
        self.shape, self.unit, self.cov, self.max_rows = shape, unit, cov, max_rows

    def more(self, a: np.ndarray, name: str) -> np.ndarray:
        """The checks besides shape and finiteness (exact; their errors name the field)."""
        if self.unit == "rows":
            return check_units(a, name)
        if self.unit:
            return check_unit(a, name)
        if self.cov:
            return check_covariance(a, name)
        return a

    def checker(self) -> Callable[[Any, str, int], np.ndarray]:
        """The field's check ``(value, name, mode)``: a float64 array of the shape (a copy, but in ``SEND``
        mode), finite, and what :meth:`more` says. The common cases (an array of the right shape, a decoded
        array map) are checked in a few operations; anything else by :func:`check_array` and :meth:`more`."""
        shape, max_rows, unit, cov, more = self.shape, self.max_rows, self.unit, self.cov, self.more
        fixed = None not in shape
        rows = not fixed and shape[0] is None and None not in shape[1:]  # (N, 3), (N,): rows of a fixed shape
        tail, flat, plain, ndim = shape[1:], len(shape) == 1, not unit and not cov, len(shape)
        free = all(e is None for e in shape)  # (N, M): any sizes up to max_rows
        want, nbytes = list(shape), 8 * math.prod(shape) if fixed else 0  # type: ignore[arg-type]

        def check(v: Any, name: str, mode: int) -> np.ndarray:
            if type(v) is WireArray and mode == DECODE:
                if fixed and v.shape == want and len(v.data) == nbytes and _NATIVE_F8:
                    a = np.frombuffer(v.data, _F64)  # a writable copy next, never a view of the payload
                    a = a.copy() if flat else a.reshape(shape).copy()
                else:
                    a = from_wire(v, shape, max_rows)
            elif type(v) is np.ndarray and v.dtype == _F64 and (
                v.shape == shape if fixed else v.ndim == ndim and (
                    max(v.shape) <= max_rows if free
                    else rows and v.shape[1:] == tail and v.shape[0] <= max_rows
                )
            ):  # fmt: skip
                a = v if mode == SEND else v.copy()
            else:
                return more(check_array(v, name, shape, max_rows, copy=mode != SEND), name)
            if a.size <= 64:
                values = a.tolist() if flat else a.ravel().tolist()
                if math.isfinite(sum(values)):  # a NaN or an infinity carries through the sum
                    if plain:
                        return a
                    if unit is True and abs(math.hypot(*values) - 1.0) <= 0.5 * QUAT_NORM_TOL:
                        return a  # clearly a unit quaternion: no rounding of the norm crosses the margin
                    if not cov:
                        return more(a, name)
            if cov and (_COV_KERNEL is not None or mode == SEND):
                if _COV_KERNEL is None:
                    load_compiled()
                if _COV_KERNEL(a, COV_SYMMETRY_RTOL) == 0:  # type: ignore[misc]
                    return a  # finite, symmetric, diagonal >= 0: the compiled check's verdict
            if not np.isfinite(a).all():
                if mode == DECODE:
                    raise Defer
                raise MessageError(f"{name}: not finite")
            return a if plain else more(a, name)

        return check

    def describe(self) -> str:
        text = "finite"
        if self.unit:
            text = f"unit quaternion{'s' if self.unit == 'rows' else ''} (x, y, z, w), norm within 1e-3 of 1"
        if self.cov:
            text = "finite, symmetric (max abs(P - P^T) <= 1e-9 max abs(P)), diagonal >= 0"
        if None in self.shape:
            text += f"; N <= {self.max_rows}"
        return text


def array(shape: tuple[int | None, ...], **kwargs: Any) -> Any:
    """The annotation of an array field of ``shape`` (:class:`Arr`'s keywords)."""
    return Annotated[WireArray, Arr(shape, **kwargs)]


class Check:
    """A field checked by ``fn(value, name) -> value`` (e.g. distinct ids); ``on_decode``: after msgspec's
    decoding too (what its types cannot say). ``says``: the check, for the protocol's table."""

    def __init__(self, fn: Callable[[Any, str], Any], says: str, on_decode: bool = True) -> None:
        self.fn, self.says, self.on_decode = fn, says, on_decode


# ------------------------------------------------------------------------------------------ modes

BUILD, SEND, DECODE, TRUSTED = 0, 1, 2, 3


class _Mode(threading.local):
    mode = BUILD


MODE = _Mode()


def make(mode: int, cls: type[M], *args: Any, **kwargs: Any) -> M:
    """``cls(*args, **kwargs)`` with its checks in ``mode`` (module docstring)."""
    MODE.mode = mode
    try:
        return cls(*args, **kwargs)
    finally:
        MODE.mode = BUILD


def trusted(cls: type[M], values: dict[str, Any]) -> M:
    """A ``cls`` message of field ``values`` checked already (a batch's rows): no check runs again."""
    return make(TRUSTED, cls, **values)


_force = msgspec.structs.force_setattr


class Message(msgspec.Struct, frozen=True, eq=False, gc=False):
    """Base of every wire message: its checks run at construction (module docstring); equality compares
    arrays by value (shape and entries)."""

    _prefix: typing.ClassVar[bytes] = b""
    _decoder: typing.ClassVar[Any] = None
    _fields: typing.ClassVar[tuple[tuple[str, bool], ...]] = ()
    _envelope: typing.ClassVar[bytes] = b""

    def __post_init__(self) -> None:
        self._check()  # the checks :func:`declare` generated for the class

    def _check(self) -> None:
        raise TypeError(f"{type(self).__name__} is not declared (swarm.transport.declared.declare)")

    def _validate(self) -> None:
        """The checks across fields (a message's own); none here."""

    def _set(self, **values: Any) -> None:
        for k, v in values.items():
            _force(self, k, v)

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        for name in self.__struct_fields__:
            a, b = getattr(self, name), getattr(other, name)
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and np.array_equal(a, b)):
                    return False
            elif a != b:
                return False
        return True

    __hash__ = None  # type: ignore[assignment]  # holds arrays


M = TypeVar("M", bound=Message)


# ---------------------------------------------------------------------------------- declarations


def field_parts(tp: Any) -> tuple[Any, list, bool]:
    """A field annotation's base type, its ``Annotated`` metadata and whether it may be nil."""
    nullable, metas = False, []
    while True:
        if typing.get_origin(tp) is Annotated:
            tp, *extra = typing.get_args(tp)
            metas = [*extra, *metas]
        elif typing.get_origin(tp) in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(tp) if a is not type(None)]
            nullable, tp = nullable or len(args) < len(typing.get_args(tp)), args[0]
        else:
            return tp, metas, nullable


def _bounds(metas: list) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for m in metas:
        if isinstance(m, msgspec.Meta):
            for k in ("ge", "gt", "le", "lt", "pattern", "max_length", "min_length"):
                if getattr(m, k) is not None:
                    out[k] = getattr(m, k)
    return out


def _unanchored(pattern: str) -> re.Pattern:
    """A msgspec pattern ``\\A(?:...)\\Z`` as the regex a message's check matches whole."""
    m = re.fullmatch(r"\\A\(\?:(.*)\)\\Z", pattern)
    return re.compile(m.group(1) if m else pattern)


def _scalar_check(tp: Any, metas: list, nullable: bool) -> tuple[Callable[[Any, str], Any], str | None, dict]:
    """The sender's check of a scalar field from its msgspec annotation: ``(check(value, name), guard,
    names)``, ``guard`` an expression in ``v`` true of a value that passes as it is (inlined by
    :func:`declare`; ``@x`` stands for ``names[x]``)."""
    b = _bounds(metas)
    guard: str | None = None
    extra: dict[str, Any] = {}
    if typing.get_origin(tp) is Literal:
        choices = typing.get_args(tp)
        fn: Callable = lambda v, name: check_str(v, name, choices=choices)  # noqa: E731
        guard = f"type(v) is str and v in {frozenset(choices)!r}"
    elif tp is bool:
        fn, guard = check_bool, "type(v) is bool"
    elif tp is int:
        lo, hi = b.get("ge", 0), b.get("le", U64_MAX)
        fn = lambda v, name: check_int(v, name, lo, hi)  # noqa: E731
        guard = f"type(v) is int and {lo} <= v <= {hi}"
    elif tp is float:
        lo = b.get("ge", b.get("gt"))
        lo = None if lo is None or lo <= -_F64_MAX else lo
        hi = b.get("le")
        hi = None if hi is None or hi >= _F64_MAX else hi
        positive = "gt" in b
        fn = lambda v, name: check_float(v, name, lo=None if positive else lo, hi=hi, positive=positive)  # noqa: E731
        flo, fhi = -_F64_MAX if lo is None else lo, _F64_MAX if hi is None else hi
        guard = f"type(v) is float and {flo!r} {'<' if positive else '<='} v <= {fhi!r}"
    elif tp is str:
        pattern = _unanchored(b["pattern"]) if "pattern" in b else None
        max_len = b.get("max_length", MAX_NAME)
        known: dict[str, None] = {}  # the strings passed already (a swarm's ids repeat: a match is ~0.5 us)

        def fn(v: Any, name: str) -> Any:
            out = check_str(v, name, pattern=pattern, max_len=max_len)
            if len(known) >= 4096:
                known.clear()
            known[out] = None
            return out

        guard = "type(v) is str and v in @known"
        extra = {"known": known}
    else:
        raise TypeError(f"no check for a field of type {tp!r}: declare one with Check")
    if nullable:
        inner = fn

        def fn(v: Any, name: str) -> Any:
            if v is None:
                return None
            try:
                return inner(v, name)
            except MessageError as exc:
                if str(exc).startswith(f"{name}: expected a number, got"):
                    raise MessageError(f"{name}: expected a number or nil, got {show(v)}") from None
                raise

        guard = None if guard is None else f"v is None or ({guard})"
    return fn, guard, extra


def _sequence_check(tp: Any, metas: list) -> Callable[[Any, str], Any]:
    """The sender's check of a ``tuple[X, ...]`` field: an array of X, each checked, at most max_length."""
    item, guard, names = _scalar_check(*field_parts(typing.get_args(tp)[0]))
    ok = eval(f"lambda v: {(guard or 'False').replace('@', '')}", names)  # (a declared type's guard)
    b = _bounds(metas)
    lo, hi = b.get("min_length", 0), b.get("max_length", MAX_BATCH)

    def sequence(v: Any, name: str) -> tuple:
        if not isinstance(v, list | tuple):
            raise MessageError(f"{name}: expected an array, got {show(v)}")
        if not lo <= len(v) <= hi:
            within = f"more than the {hi} allowed" if lo == 0 else f"expected {lo} to {hi}"
            raise MessageError(f"{name}: {len(v)} entries, {within}")
        if all(map(ok, v)):
            return tuple(v)
        return tuple(item(x, f"{name}[{i}]") for i, x in enumerate(v))

    return sequence


def _field_code(info: msgspec.structs.FieldInfo) -> tuple[str, str | None, Callable, dict]:
    """A field's check for :func:`declare`: ``(when, guard, check)``. ``when``: ``"always"`` (after msgspec's
    decoding too) or ``"build"``; ``guard`` (or ``None``): an expression in ``v`` true of a value that passes
    as it is; ``check(v, name, mode)``: the value, normalised, or MessageError naming the field."""
    tp, metas, nullable = field_parts(info.type)
    for m in metas:
        if isinstance(m, Arr):
            return "always", "v is None" if nullable else None, m.checker(), {}
        if isinstance(m, Check):
            return (
                ("always" if m.on_decode else "build"),
                "v is None" if nullable else None,
                (lambda v, name, mode, fn=m.fn: fn(v, name)),
                {},
            )
    if typing.get_origin(tp) is tuple:
        seq = _sequence_check(tp, metas)
        return "build", None, lambda v, name, mode: seq(v, name), {}
    scalar, guard, names = _scalar_check(tp, metas, nullable)
    return "build", guard, lambda v, name, mode: scalar(v, name), names


def declare(cls: type[M]) -> type[M]:
    """Compile the checks, the envelope and the decoder of the message class ``cls`` (its fields' order is
    the wire's). Its ``__post_init__`` is generated, as ``dataclasses`` does: each field's guard inlined, its
    check called only for a value the guard does not pass."""
    ns: dict[str, Any] = {"MODE": MODE, "_force": _force}
    lines = ["def _check(self):", "    mode = MODE.mode", f"    if mode == {TRUSTED}:", "        return"]
    for i, info in enumerate(msgspec.structs.fields(cls)):
        when, guard, check, names = _field_code(info)
        ns[f"c{i}"] = check
        ns.update({f"{k}{i}": v for k, v in names.items()})
        for k in names:
            guard = guard.replace(f"@{k}", f"{k}{i}")  # type: ignore[union-attr]
        pad = "    "
        lines.append(f"    v = self.{info.name}")
        if when == "build":
            lines.append(f"    if mode != {DECODE}:")
            pad += "    "
        if guard is None:
            lines += [f"{pad}w = c{i}(v, {info.name!r}, mode)", f"{pad}if w is not v:",
                      f"{pad}    _force(self, {info.name!r}, w)"]  # fmt: skip
        else:
            lines += [
                f"{pad}if not ({guard}):",
                f"{pad}    _force(self, {info.name!r}, c{i}(v, {info.name!r}, mode))",
            ]
    lines.append("    self._validate()")
    exec("\n".join(lines), ns)  # the declared fields' code, as dataclasses writes __init__
    cls._check = ns["_check"]  # type: ignore[method-assign]
    n = len(cls.__struct_fields__) + 2
    if n > 15:
        raise TypeError(f"{cls.__name__}: {n} keys, more than a msgpack fixmap holds")
    cls._prefix = bytes([0x80 | n]) + msgpack.packb("v") + msgpack.packb(SCHEMA_VERSION) + msgpack.packb(
        "type"
    ) + msgpack.packb(cls.__name__, use_bin_type=True)  # fmt: skip
    cls._envelope = cls._prefix[1:]  # the "v" and "type" entries, after the map's header
    cls._decoder = msgspec.msgpack.Decoder(cls)
    cls._fields = tuple(
        (f.name, f.required) for f in msgspec.structs.fields(cls)
    )  # (fields() evaluates hints)
    return cls


# ------------------------------------------------------------------------------------------ codec


def _enc_hook(value: object) -> object:
    if type(value) is np.ndarray:
        data = value.tobytes() if _NATIVE_F8 and value.dtype == _F64 else value.astype("<f8").tobytes()
        return {"dtype": "<f8", "shape": list(value.shape), "data": data}
    raise NotImplementedError(f"not a wire value: {type(value).__name__}")


_ENCODER = msgspec.msgpack.Encoder(enc_hook=_enc_hook)


def encode(msg: Message) -> bytes:
    """The msgpack bytes of ``msg``: ``{"v", "type", <fields in order>}``; MessageError above
    :data:`MAX_PAYLOAD_BYTES`."""
    prefix = getattr(type(msg), "_prefix", b"")
    if not prefix or not isinstance(msg, Message):
        raise TypeError(f"not a wire message: {type(msg).__name__}")
    body = _ENCODER.encode(msg)
    payload = prefix + memoryview(body)[1:]
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise MessageError(f"payload: {len(payload)} bytes, more than the {MAX_PAYLOAD_BYTES} allowed")
    return payload


def send(cls: type[Message], *args: Any) -> bytes:
    """``encode(cls(*args))``, its arrays checked but not copied (the message is dropped at once)."""
    return encode(make(SEND, cls, *args))


def as_bytes(payload: object) -> bytes | bytearray | memoryview:
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
    data = as_bytes(payload)
    if len(data) > MAX_PAYLOAD_BYTES:
        raise MessageError(f"payload: {len(data)} bytes, more than the {MAX_PAYLOAD_BYTES} allowed")
    msg = decode_fast(data, expected)
    return msg if msg is not None else decode_reference(data, expected)


def decode_fast(data: bytes | bytearray, expected: type[M]) -> M | None:
    """The message in ``data`` if msgspec takes it as it is, else ``None`` (the reference decides). It takes
    the envelope as this codec writes it (``v`` then ``type`` first) and the arrays as float64 maps; any
    other form the protocol allows, and any failed check, is left to :func:`decode_reference`."""
    envelope = expected._envelope
    if data[1 : len(envelope) + 1] != envelope or not 0x80 <= data[0] <= 0x8F:
        return None
    MODE.mode = DECODE
    try:
        return expected._decoder.decode(data)
    except (msgspec.MsgspecError, MessageError, Defer):
        return None
    finally:
        MODE.mode = BUILD


def decode_reference(data: bytes | bytearray, expected: type[M]) -> M:
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
    if not is_int(version) or version != SCHEMA_VERSION:
        raise MessageError(
            f"v: unsupported schema version {show(version)} (this codec speaks {SCHEMA_VERSION})"
        )
    name = expected.__name__
    if obj.get("type") != name:
        raise MessageError(f"type: expected {name!r}, got {show(obj.get('type'))}")
    kwargs = {}
    for name, required in expected._fields:
        if name in obj:
            kwargs[name] = obj[name]
        elif required:
            raise MessageError(f"{name}: missing")
    return expected(**kwargs)
