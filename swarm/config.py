"""Typed scenario files: build frozen params dataclasses from TOML, validate every field, write them back.

A scenario is a frozen dataclass composed of the modules' params dataclasses (``EstimatorParams`` ...); the
TOML file mirrors it, one table per nested dataclass::

    seed = 7

    [estimator]
    structure = "tandem"
    sigma_range_m = 0.02

    [chaser.dynamics]
    mass_kg = 3.0

The field types decide how a TOML value is read (:func:`from_mapping`) and written (:func:`to_mapping`,
:func:`dump_toml`):

======================================  ============================================================
field type                              TOML value
======================================  ============================================================
``float``                               integer or float, finite (``nan`` and ``inf`` are rejected)
``int``                                 integer (an integral float such as ``3.0`` is accepted)
``bool``                                ``true`` or ``false``
``str``                                 string
``Literal["a", "b"]``                   one of the listed values
``enum.Enum`` subclass (``StrEnum``)    a member's value, e.g. ``"tandem"``
dataclass                               table
``tuple[X, Y, Z]`` / ``tuple[X, ...]``  array of exactly that length / of any length
``X | None``                            ``X``, or the key left out for a None default (TOML has no null;
                                        :func:`to_mapping` output for JSON keeps None and reads back)
``dict[str, X]``                        table of named entries, e.g. ``[agents.a1]``, ``[agents.a2]``
======================================  ============================================================

A key missing from a table keeps its default: the value in the enclosing field's default instance when
there is one (``chaser: Vehicle = Vehicle(mass_kg=3.0)`` keeps 3.0 when ``[chaser]`` sets only other
keys), else the dataclass's own default. Unknown keys are errors; a key a rename retired (a dataclass's
``RENAMED = {old: (new, factor)}``, factor from the old unit to the new) is refused with the key and value
to write instead. Every error is a
:class:`swarm.errors.ConfigError` whose message names the dotted path of the field (``chaser.dynamics.
mass_kg``, ``markers_nav[2][0]``) and quotes the bad value. A dataclass's own ``__post_init__`` error
(``estimator.sigma_range_m must be ...``, by the project's convention) is re-rooted at the field's real
path (``agents.a1.sigma_range_m must be ...``), or prefixed with the path if it does not follow it.

``msgspec.convert`` (strict) checks the types and builds the dataclasses, calling their ``__post_init__``.
What it does not do is a short walk over the tables before it (:func:`_prepare`): unknown keys (msgspec
refuses them on its Structs only, a dataclass drops them silently), defaults from the enclosing default
instance (msgspec knows the class defaults only), ``nan``/``inf`` (msgspec takes them) and ``3.0`` for an
int (strict mode refuses it; lax mode would also take ``"3"`` and ``1`` for ``true``). Its errors name the
path (``Expected `float`, got `str` - at `$.chaser.dynamics.mass_kg```) but not the bad value nor a
dict's key (``$.agents[...]``): :func:`_explain` finds both and words them as above.
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import functools
import math
import numbers
import os
import re
import reprlib
import tomllib
import types
import typing
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin

import msgspec

from swarm.errors import ConfigError

__all__ = ["apply_overrides", "dump_toml", "from_mapping", "load_toml", "parse_override", "to_mapping"]

T = TypeVar("T")

_NONE_TYPE = type(None)
_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")
_KEY_PART = r'(?:[A-Za-z0-9_-]+|"(?:[^"\\\n]|\\.)*")'
_DOTTED_KEY = re.compile(rf"\s*{_KEY_PART}(?:\s*\.\s*{_KEY_PART})*\s*")
# An override value that is not TOML but looks like a word is taken as a string, so that
# ``--set estimator.structure=compounded`` works without shell-quoting the TOML quotes.
_BARE_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*")
_TOML_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}

_repr = reprlib.Repr()
_repr.maxstring = 80
_repr.maxother = 80
_repr.maxlist = _repr.maxtuple = 8
_repr.maxdict = 4
_repr.maxlevel = 3


# ------------------------------------------------------------------------------------------- public API


def from_mapping(cls: type[T], data: Mapping[str, Any], section: str = "") -> T:
    """An instance of the dataclass ``cls`` built from ``data`` (e.g. ``tomllib.load`` output), recursively.

    ``section`` is the dotted path of ``data`` inside the scenario (``"chaser.dynamics"``), used only to
    name fields in error messages. Raises ConfigError naming the field for any bad, unknown or missing
    key; TypeError if ``cls`` is not a dataclass or has a field type this module does not support.
    """
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise TypeError(f"from_mapping needs a dataclass type, got {cls!r}")
    _schema(cls)  # every field type is one of the table's (msgspec would also take lists, sets, unions)
    data = _prepare(cls, data, section, None)
    try:
        return msgspec.convert(data, cls, strict=True)
    except msgspec.ValidationError as exc:
        raise _explain(exc, cls, data, section) from exc


def to_mapping(obj: Any) -> dict[str, Any]:
    """The inverse of :func:`from_mapping`: nested dicts of plain values (enums as their values, tuples as
    lists, None kept), ready for ``json.dump``; ``from_mapping(type(obj), to_mapping(obj)) == obj``."""
    _require_instance(obj)
    return _plain(obj, "", None, toml=False)


def dump_toml(obj: Any) -> str:
    """``obj`` as a TOML document that :func:`from_mapping` reads back to an equal object.

    Every field is written, None fields are omitted. Raises ConfigError naming the field when a value
    cannot round-trip: None where the default is not None (TOML has no null) or a non-finite float.
    """
    _require_instance(obj)
    lines: list[str] = []
    _emit_table(_plain(obj, "", None, toml=True), [], lines)
    return "\n".join(lines) + "\n" if lines else ""


def load_toml(
    cls: type[T],
    path: str | os.PathLike[str],
    overrides: Mapping[str, object] | None = None,
    migrate: Callable[[dict[str, Any], str], dict[str, Any]] | None = None,
    migrate_key: Callable[[str], str] | None = None,
) -> T:
    """Read the TOML file at ``path`` into the dataclass ``cls``.

    ``overrides`` maps dotted keys to values (``{"estimator.sigma_range_m": 0.03}``, e.g. from
    :func:`parse_override`) applied on top of the file (:func:`apply_overrides`) before validation.
    ``migrate(data, name)`` and ``migrate_key(key)``, if given, rewrite the file's parsed mapping and each
    override's key from an older format (before the overrides are applied).
    A missing or unreadable file, a TOML syntax error (with its line and column) and every invalid field
    raise ConfigError naming the file; an invalid overridden value is reported as coming from the override.
    """
    name = os.fspath(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{name}: invalid TOML: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{name}: not UTF-8 text: {exc}") from exc
    except OSError as exc:
        raise ConfigError(f"{name}: cannot read the scenario file: {exc.strerror or exc}") from exc
    if migrate is not None:
        data = migrate(data, name)
    keys: list[str] = []
    if overrides:
        if migrate_key is not None:
            overrides = {migrate_key(k): v for k, v in overrides.items()}
        data = apply_overrides(data, overrides)
        keys = [_join_parts(_split_key(k)) for k in overrides]
    try:
        return from_mapping(cls, data)
    except ConfigError as exc:
        msg = str(exc)
        for key in keys:
            if msg.startswith(key) and msg[len(key) : len(key) + 1] in ("", ":", ".", "[", " "):
                raise ConfigError(f"{msg} (value set by override {key})") from exc
        at = _locate(path, msg)
        raise ConfigError(
            f"{name}: {msg}" + ("" if at is None else f" (at line {at[0]}, column {at[1]})")
        ) from exc


_KEY_PATH = re.compile(r"[A-Za-z0-9_\-]+(?:\[\d+\])*(?:\.[A-Za-z0-9_\-]+(?:\[\d+\])*)*")
_HEADER = re.compile(r"\s*\[\[?\s*([^\]\[]+?)\s*\]\]?\s*(?:#.*)?$")
_ASSIGN = re.compile(r"(\s*)([A-Za-z0-9_\-\.\s\"']+?)\s*=")


def _toml_parts(dotted: str) -> list[str]:
    return [p.strip().strip("\"'") for p in dotted.split(".")]


def _locate(path: str | os.PathLike[str], msg: str) -> tuple[int, int] | None:
    """Best effort: the line and column (1-based) in the TOML file at ``path`` of the key a validation
    message ``msg`` begins with (``sim.max_duration_s: ...``, ``anchors_m[2] ...``): the line that sets it
    (``[table]`` headers and dotted keys followed) or, for a table set by dotted keys, its first line; else
    the deepest table or key on its path that the file has (a key the file lacks: its table's header).
    ``None`` when nothing matches (tomllib keeps no positions, so the text is scanned; a key inside an
    inline table is found at its outer key's line)."""
    m = _KEY_PATH.match(msg)
    if m is None:
        return None
    want = [re.sub(r"\[\d+\]", "", p) for p in m.group(0).split(".")]
    field = re.match(r": ([A-Za-z0-9_]+) must ", msg[m.end() :])  # a table's check of a field: "t: f must"
    if field is not None:
        want.append(field.group(1))
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    table: list[str] = []
    best: tuple[int, int, int] | None = None  # (parts matched, line, column)
    depth = 0  # brackets and braces left open by a value over several lines (its rows are no headers)
    for n, line in enumerate(text.splitlines(), 1):
        code = line.split("#", 1)[0]
        if depth > 0:
            depth += code.count("[") + code.count("{") - code.count("]") - code.count("}")
            continue
        h = _HEADER.match(line)
        if h is not None:
            table = _toml_parts(h.group(1))
            found, col = table, line.index("[") + 1
        else:
            a = _ASSIGN.match(line)
            if a is None:
                continue
            found, col = table + _toml_parts(a.group(2)), len(a.group(1)) + 1
            value = code[a.end() :]
            depth = max(0, value.count("[") + value.count("{") - value.count("]") - value.count("}"))
        # the key itself, a table or key on its path, or the first line under it (a table set by dotted keys)
        score = len(found) if found == want[: len(found)] else len(want) if found[: len(want)] == want else 0
        if score and (best is None or score > best[0]):
            best = (score, n, col)
    return None if best is None else best[1:]


def parse_override(text: str) -> tuple[str, object]:
    """Split a ``--set`` argument ``"key=value"`` into the dotted key and the value parsed as TOML
    (``1.5``, ``true``, ``"text"``, ``[1, 2, 3]``, ``{a = 1}``); a bare word (``compounded``) that is not
    TOML is taken as a string. Raises ConfigError on a malformed key or value."""
    key, sep, raw = text.partition("=")
    key, raw = key.strip(), raw.strip()
    if not sep or not key:
        raise ConfigError(f"override {text!r}: expected key=value, e.g. estimator.sigma_range_m=0.03")
    _split_key(key)
    if not raw:
        raise ConfigError(f"override {text!r}: missing value after '='")
    try:
        doc = tomllib.loads(f"v = {raw}")
    except tomllib.TOMLDecodeError as exc:
        if _BARE_WORD.fullmatch(raw):
            return key, raw
        raise ConfigError(
            f"{key}: cannot parse the override value {raw!r} as TOML ({exc}); quote strings: {key}='\"text\"'"
        ) from exc
    if set(doc) != {"v"}:
        raise ConfigError(f"{key}: the override value {raw!r} is not a single TOML value")
    return key, doc["v"]


def apply_overrides(data: Mapping[str, Any], overrides: Mapping[str, object]) -> dict[str, Any]:
    """A copy of the parsed mapping ``data`` with each dotted key of ``overrides`` set (intermediate tables
    are created; a table value is merged into an existing table). Values are validated later, by
    :func:`from_mapping`; a key that runs through a non-table value raises ConfigError."""
    out = _copy_tree(data)
    for key, value in overrides.items():
        parts = _split_key(key)
        node = out
        for i, part in enumerate(parts[:-1]):
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                where = _join_parts(parts[: i + 1])
                raise ConfigError(
                    f"{_join_parts(parts)}: cannot set it, {where} is {_show(child)}, not a table"
                )
            node = child
        last = parts[-1]
        if isinstance(value, Mapping) and isinstance(node.get(last), dict):
            _merge(node[last], value)
        else:
            node[last] = _copy_tree(value)
    return out


# ----------------------------------------------------------------------------------------------- schema

_SCHEMAS: dict[type, dict[str, tuple[dataclasses.Field, Any]]] = {}
_WORDS = {float: "a number", int: "an integer", bool: "true or false", str: "a string"}
_AS_IS = frozenset({int, bool, str, _NONE_TYPE})  # what _prepare hands to msgspec as it is
_MS_AT = re.compile(r" - at `\$([^`]*)`$")  # the path at the end of a msgspec.ValidationError
_MS_STEP = re.compile(r"\.(\w+)|\[(\d+)\]|\[\.\.\.\]")


def _schema(cls: type) -> dict[str, tuple[dataclasses.Field, Any]]:
    """The init fields of the dataclass ``cls`` with their resolved types, every type checked as supported."""
    cached = _SCHEMAS.get(cls)
    if cached is not None:
        return cached
    try:
        hints = typing.get_type_hints(cls)
    except (NameError, TypeError, AttributeError) as exc:
        raise TypeError(f"cannot resolve the type hints of {cls.__qualname__}: {exc}") from exc
    schema = {f.name: (f, hints[f.name]) for f in dataclasses.fields(cls) if f.init}
    _SCHEMAS[cls] = schema  # before checking, so that a self-referencing dataclass terminates
    try:
        for name, (_, tp) in schema.items():
            _check_type(tp, f"{cls.__qualname__}.{name}")
    except TypeError:
        del _SCHEMAS[cls]
        raise
    return schema


@functools.cache
def _shape(tp: Any) -> tuple[Any, Any, tuple]:
    """``tp`` without ``| None`` (``X`` for ``X | None``), its origin (``dict``, ``tuple``, ``Literal`` or
    None) and its arguments."""
    args = get_args(tp)
    if get_origin(tp) in (typing.Union, types.UnionType) and len(args) == 2 and _NONE_TYPE in args:
        tp = args[0] if args[1] is _NONE_TYPE else args[1]
    return tp, get_origin(tp), get_args(tp)


def _check_type(tp: Any, where: str) -> None:
    tp, origin, args = _shape(tp)
    if tp in _WORDS or (isinstance(tp, type) and issubclass(tp, enum.Enum)):
        return
    if origin is Literal and args and all(isinstance(a, str | int | enum.Enum) for a in args):
        return
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        _schema(tp)
        return
    if origin is tuple and ((len(args) == 2 and args[1] is Ellipsis) or Ellipsis not in args):
        for a in args[:1] if Ellipsis in args else args:
            _check_type(a, where)
        return
    if origin is dict and len(args) == 2 and args[0] is str:
        return _check_type(args[1], where)
    raise TypeError(f"{where}: unsupported field type {tp!r} (see the table in swarm.config)")


# ------------------------------------------------------------------ before and after msgspec.convert


def _prepare(tp: Any, value: Any, path: str, base: Any) -> Any:
    """``value`` of field type ``tp`` at ``path`` made ready for ``msgspec.convert``: a table's unknown
    keys refused, its missing keys filled from ``base`` (the field's default instance, if any), floats
    checked finite, an integral float for an int made an int, numpy scalars and enum members made plain
    (strict msgspec takes exact builtin types). Copies; ``value`` is not changed."""
    if type(value) in _AS_IS:
        return value
    tp, origin, args = _shape(tp)
    if not isinstance(value, float | dict | list | tuple):
        if isinstance(value, str):
            return str.__str__(value)
        if isinstance(value, numbers.Real):
            value = int(value) if isinstance(value, numbers.Integral) else float(value)
    if isinstance(value, float):
        if tp is float and not math.isfinite(value):
            raise _bad(path, "a finite number", value)
        if tp is not bool and isinstance(tp, type) and issubclass(tp, int) and value.is_integer():
            return int(value)
        return float(value)  # a numpy float64 is a float that strict msgspec refuses
    if isinstance(value, Mapping):
        if dataclasses.is_dataclass(tp):
            return _prepare_table(tp, value, path, base if isinstance(base, tp) else None)
        if origin is dict:
            return {k: _prepare(args[1], v, _join(path, str(k)), None) for k, v in value.items()}
    elif isinstance(value, list | tuple) and origin is tuple:
        item_types = [args[0]] * len(value) if Ellipsis in args else args
        if len(item_types) == len(value):  # else msgspec tells the length
            pairs = enumerate(zip(item_types, value, strict=True))
            return [_prepare(t, v, f"{path}[{i}]", None) for i, (t, v) in pairs]
    return value


def _prepare_table(cls: type, data: Mapping[str, Any], path: str, base: Any) -> dict[str, Any]:
    schema = _schema(cls)
    unknown = [k for k in data if k not in schema]
    if unknown:
        renamed = getattr(cls, "RENAMED", {})
        for k in unknown:
            if k in renamed:
                raise _renamed_key(path, str(k), renamed[k], data[k])
        raise _unknown_keys(path, unknown, list(schema))
    out = {}
    for name, (f, tp) in schema.items():
        where = f"{path}.{name}" if path else name  # a field's name is a bare key
        if name in data:
            value = data[name]
            sub_base = None
            if isinstance(value, Mapping):  # only a table can be built on top of a default instance
                sub_base = getattr(base, name) if base is not None else _default(f)
            out[name] = _prepare(tp, value, where, sub_base)
        elif base is not None:
            out[name] = _prepare(tp, getattr(base, name), where, None)
    return out


def _explain(exc: msgspec.ValidationError, tp: Any, data: Any, path: str) -> ConfigError:
    """msgspec's error on the prepared ``data`` of type ``tp`` worded as the other errors here: the dotted
    path (a dict's key, which msgspec writes ``[...]``, is the first entry that fails alone), the bad
    value, and a dataclass's own ``__post_init__`` message re-rooted at its path (:func:`_with_path`)."""
    msg = str(exc)
    at = _MS_AT.search(msg)
    value = data
    for step in _MS_STEP.finditer(at.group(1) if at else ""):
        tp, _, args = _shape(tp)
        name, index = step.groups()
        if name is not None:
            tp, value, path = _schema(tp)[name][1], value[name], _join(path, name)
        elif index is not None:
            i = int(index)
            tp, value, path = args[0 if Ellipsis in args else i], value[i], f"{path}[{i}]"
        else:
            tp = args[1]
            key = next((k for k, v in value.items() if not _converts(v, tp)), None)
            if key is None:
                path += "[...]"
                break
            value, path = value[key], _join(path, str(key))
    tp = _shape(tp)[0]
    if isinstance(exc.__cause__, ValueError | TypeError):  # msgspec wraps what __post_init__ raised
        fields = _schema(tp) if dataclasses.is_dataclass(tp) else {}
        return ConfigError(_with_path(path, str(exc.__cause__), fields))
    head = msg[: at.start()] if at else msg
    if head.startswith("Object missing required field `"):
        return ConfigError(f"{_join(path, head.split('`')[1])}: missing (the field has no default)")
    length = re.match(r"Expected `array` of length (\d+), got (\d+)", head)
    if length:
        return ConfigError(f"{path}: expected an array of {length[1]} items, got {length[2]}: {_show(value)}")
    return _bad(path, _expected(tp), value)


def _converts(value: Any, tp: Any) -> bool:
    """Whether ``value`` converts to ``tp`` (strict, as :func:`from_mapping` converts)."""
    try:
        msgspec.convert(value, tp, strict=True)
    except msgspec.ValidationError:
        return False
    return True


def _expected(tp: Any) -> str:
    """What a value of the (not optional) field type ``tp`` must be, in words."""
    if tp in _WORDS:
        return _WORDS[tp]
    _, origin, args = _shape(tp)
    if origin is Literal:
        choices = [c.value if isinstance(c, enum.Enum) else c for c in args]
    elif isinstance(tp, type) and issubclass(tp, enum.Enum):
        choices = [m.value for m in tp]
    else:
        return "an array" if origin is tuple else "a table"
    return f"one of {', '.join(_show(c) for c in choices)}"


def _plain(value: Any, path: str, base: Any, toml: bool) -> Any:
    """``value`` (a dataclass instance or a field's value at ``path``) as plain data: tables as dicts,
    enums as their values, tuples as lists. For TOML (``toml``), None fields are left out (refused where
    the default, ``base``'s value if given, is not None) and non-finite floats refused."""
    if dataclasses.is_dataclass(value):
        out: dict[str, Any] = {}
        for name, (f, _) in _schema(type(value)).items():
            v, where = getattr(value, name), _join(path, name)
            default = getattr(base, name) if base is not None else _default(f)
            if v is None and toml:
                if default is None:
                    continue
                shown = "no default" if default is dataclasses.MISSING else f"the default {_show(default)}"
                raise ConfigError(
                    f"{where}: None cannot be written to TOML (no null; omitting the key would load {shown})"
                )
            out[name] = _plain(v, where, default if type(default) is type(v) else None, toml)
        return out
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, Mapping):
        return {k: _plain(v, _join(path, k), None, toml) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v, f"{path}[{i}]", None, toml) for i, v in enumerate(value)]
    if isinstance(value, float):
        if toml and not math.isfinite(value):
            raise _bad(path, "a finite number", value)
        return float(value)
    return value


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


# ------------------------------------------------------------------------------------------ messages


def _show(value: Any) -> str:
    return _repr.repr(value)


def _bad(path: str, expected: str, value: Any) -> ConfigError:
    return ConfigError(f"{path or '(top level)'}: expected {expected}, got {_show(value)}")


def _unknown_keys(path: str, unknown: list, valid: list[str]) -> ConfigError:
    first = str(unknown[0])
    close = difflib.get_close_matches(first, valid, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    where = f"in {path}" if path else "at the top level"
    others = ", ".join(_join(path, str(k)) for k in unknown[1:])
    more = f"; also unknown: {others}" if others else ""
    return ConfigError(
        f"{_join(path, first)}: unknown key{hint}; valid keys {where}: {', '.join(valid) or '(none)'}{more}"
    )


def _renamed_key(path: str, old: str, new: tuple[str, float], value: Any) -> ConfigError:
    """An old file's key that a rename retired: the key to write instead and, when the unit changed with
    the name, the value converted (``new`` is the new name and the factor from the old unit to the new)."""
    name, factor = new
    write = f"{_join(path, name)} = {value!r}"
    if factor != 1.0 and isinstance(value, int | float) and not isinstance(value, bool):
        write = f"{_join(path, name)} = {value * factor!r} (the value in the new unit)"
    return ConfigError(f"{_join(path, old)}: renamed; write {write} instead")


def _with_path(path: str, msg: str, fields: Mapping[str, Any]) -> str:
    """``msg`` from the dataclass at ``path`` made to name the full path: kept if it does; a leading
    ``<section>.<field>`` (the convention, e.g. ``estimator.sigma_range_m must ...``) or ``<section>``
    re-rooted at ``path``; else prefixed with ``path:``."""
    if not path or re.search(rf"(?<![\w.\"]){re.escape(path)}(?![\w\"])", msg):
        return msg
    lead = re.match(r"([A-Za-z_][\w.]*)\.(\w+)\b", msg)
    if lead and lead.group(2) in fields:
        return path + msg[lead.end(1) :]
    last = path.rsplit(".", 1)[-1]
    if msg.startswith(last) and msg[len(last) : len(last) + 1] in (".", ":", " "):
        return path + msg[len(last) :]
    return f"{path}: {msg}"


# ---------------------------------------------------------------------------------------------- keys


def _join(path: str, key: str) -> str:
    part = key if _BARE_KEY.fullmatch(key) else _toml_str(key)
    return f"{path}.{part}" if path else part


def _join_parts(parts: tuple[str, ...]) -> str:
    path = ""
    for p in parts:
        path = _join(path, p)
    return path


def _split_key(key: str) -> tuple[str, ...]:
    """The parts of a dotted TOML key (``a.b``, ``agents."a 1".gain``)."""
    if not isinstance(key, str) or not _DOTTED_KEY.fullmatch(key):
        raise ConfigError(f"invalid override key {key!r}: expected a dotted key like estimator.sigma_range_m")
    try:
        node: Any = tomllib.loads(f"{key} = 0")
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid override key {key!r}: {exc}") from exc
    parts = []
    while isinstance(node, dict):
        ((part, node),) = node.items()
        parts.append(part)
    return tuple(parts)


def _copy_tree(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {k: _copy_tree(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_copy_tree(v) for v in value]
    return value


def _merge(dst: dict[str, Any], src: Mapping[str, Any]) -> None:
    for k, v in src.items():
        if isinstance(v, Mapping) and isinstance(dst.get(k), dict):
            _merge(dst[k], v)
        else:
            dst[k] = _copy_tree(v)


# -------------------------------------------------------------------------------------- TOML writer


def _emit_table(table: dict[str, Any], prefix: list[str], lines: list[str]) -> None:
    """Key/value lines of ``table`` under a ``[prefix]`` header, then its sub-tables. The header is left
    out when the table has only sub-tables (TOML creates it implicitly) but kept for an empty table."""
    scalars = [(k, v) for k, v in table.items() if not isinstance(v, dict)]
    tables = [(k, v) for k, v in table.items() if isinstance(v, dict)]
    if prefix and (scalars or not tables):
        if lines:
            lines.append("")
        lines.append("[" + ".".join(_toml_key(p) for p in prefix) + "]")
    lines.extend(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in scalars)
    for k, v in tables:
        _emit_table(v, [*prefix, k], lines)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)  # shortest repr that round-trips exactly; always TOML float syntax when finite
    if isinstance(v, str):
        return _toml_str(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise ConfigError(f"cannot write {_show(v)} (of type {type(v).__name__}) to TOML")


def _toml_key(k: str) -> str:
    return k if _BARE_KEY.fullmatch(k) else _toml_str(k)


def _toml_str(s: str) -> str:
    """A TOML basic string: quotes, backslashes and control characters escaped (TOML 1.0, "String")."""
    out = ['"']
    for ch in s:
        code = ord(ch)
        if ch in _TOML_ESCAPES:
            out.append(_TOML_ESCAPES[ch])
        elif code < 0x20 or code == 0x7F:
            out.append(f"\\u{code:04X}")
        elif 0xD800 <= code <= 0xDFFF:
            raise ConfigError(f"cannot write the lone surrogate U+{code:04X} in {_show(s)} to TOML")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _require_instance(obj: Any) -> None:
    if isinstance(obj, type) or not dataclasses.is_dataclass(obj):
        raise TypeError(f"expected a dataclass instance, got {obj!r}")
