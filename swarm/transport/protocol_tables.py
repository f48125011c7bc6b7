"""The field tables of ``docs/protocol.md``, generated from the message declarations.

Each message's table (field, type, default, checks, meaning) is written between the markers
``<!-- fields:<Type> -->`` and ``<!-- /fields:<Type> -->`` of the page: the type, the default and the checks
come from the field's annotation (:mod:`swarm.transport.declared`), the meaning from its docstring in
:mod:`swarm.transport.messages`. ``tests/transport/test_protocol_tables.py`` fails when the committed page
and the declarations differ.

Usage: ``python -m swarm.transport.protocol_tables`` rewrites the tables of ``docs/protocol.md``;
``--check`` only says whether they are up to date (exit status 1 when not).
"""

from __future__ import annotations

import argparse
import ast
import inspect
import re
import sys
import typing
from pathlib import Path
from typing import Any, Literal

import msgspec

from swarm.transport import messages
from swarm.transport.declared import _F64_MAX, MAX_BATCH, U64_MAX, Arr, Check, WireArray, field_parts

DOC = Path(__file__).resolve().parents[2] / "docs" / "protocol.md"
"""The page whose tables this module writes."""
_BLOCK = re.compile(r"(<!-- fields:(\w+) -->\n)(.*?)(<!-- /fields:\2 -->)", re.S)


def field_docs(cls: type) -> dict[str, str]:
    """Each field's docstring (the string literal after its annotation) in the class's source."""
    tree = ast.parse(inspect.getsource(messages))
    node = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls.__name__)
    out: dict[str, str] = {}
    for prev, item in zip(node.body, node.body[1:], strict=False):
        if isinstance(prev, ast.AnnAssign) and isinstance(prev.target, ast.Name):
            if isinstance(item, ast.Expr) and isinstance(item.value, ast.Constant):
                out[prev.target.id] = str(item.value.value)
    return out


def _markdown(text: str) -> str:
    """A docstring as one line of a markdown table cell: rST roles and literals as code, pipes escaped."""
    text = " ".join(text.split())
    text = re.sub(r":(?:class|data|attr|func|meth|mod):`~?([^`]+)`", r"`\1`", text)
    text = text.replace("``", "`")
    return text.replace("|", "\\|")


def _bound(x: float) -> str:
    return {U64_MAX: "2^64-1", 2**31 - 1: "2^31-1"}.get(x, f"{x:g}") if isinstance(x, int) else f"{x:g}"


def _meta(metas: list) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for m in metas:
        if isinstance(m, msgspec.Meta):
            out.update({k: getattr(m, k) for k in ("ge", "gt", "le", "pattern", "max_length", "min_length")
                        if getattr(m, k) is not None})  # fmt: skip
    return out


def _scalar(tp: Any, metas: list) -> tuple[str, str]:
    """A scalar type's name and checks."""
    b = _meta(metas)
    if typing.get_origin(tp) is Literal:
        return "str", "one of " + ", ".join(f"`{c}`" for c in typing.get_args(tp))
    if tp is bool:
        return "bool", ""
    if tp is int:
        lo, hi = b.get("ge", 0), b.get("le", U64_MAX)
        return "int", f"{_bound(lo)} .. {_bound(hi)}"
    if tp is float:
        lo = b.get("ge", b.get("gt"))
        hi = b.get("le")
        parts = ["finite"]
        if lo is not None and lo > -_F64_MAX and hi is not None and hi < _F64_MAX:
            parts.append(f"in [{lo:g}, {hi:g}]")
        elif lo is not None and lo > -_F64_MAX:
            parts.append(f"{'>' if 'gt' in b else '>='} {lo:g}")
        return "float", ", ".join(parts)
    if tp is str:
        checks = []
        if "pattern" in b:
            pattern = re.sub(r"^\\A\(\?:(.*)\)\\Z$", r"\1", b["pattern"])
            checks.append(f"`{pattern}`")
        checks.append(f"at most {b.get('max_length', 64)} characters")
        return "str", ", ".join(checks)
    if tp is bytes:
        return "bin", ""
    if typing.get_origin(tp) is dict:
        value = typing.get_args(tp)[1]
        return ("map" if value is Any else f"map str -> {_scalar(*field_parts(value)[:2])[0]}"), ""
    raise TypeError(f"no protocol type for {tp!r}")


def row(info: msgspec.structs.FieldInfo, doc: str) -> str:
    """The table row of one field."""
    tp, metas, nullable = field_parts(info.type)
    checks: list[str] = []
    arr = next((m for m in metas if isinstance(m, Arr)), None)
    custom = next((m for m in metas if isinstance(m, Check)), None)
    if arr is not None:
        dims = ", ".join("N" if d is None else str(d) for d in arr.shape) + (
            "," if len(arr.shape) == 1 else ""
        )
        name, checks = f"ndarray ({dims})", [arr.describe()]
    elif tp is WireArray:
        raise TypeError(f"{info.name}: an array field needs its Arr")
    elif typing.get_origin(tp) is tuple:
        item, item_metas, item_nullable = field_parts(typing.get_args(tp)[0])
        item_name, item_checks = _scalar(item, item_metas)
        name = f"array of {item_name}{' or nil' if item_nullable else ''}"
        if item_checks and custom is None:
            checks.append(f"each {item_checks}")
        b = _meta(metas)
        if ("max_length" in b and b["max_length"] != MAX_BATCH) or "min_length" in b:
            checks.append(f"{b.get('min_length', 0)} to {b.get('max_length', MAX_BATCH)} entries")
    else:
        name, check = _scalar(tp, metas)
        checks += [check] if check else []
    if custom is not None:
        checks.append(custom.says)
    if nullable:
        name += " or nil"
    default = "required"
    if not info.required:
        value = info.default if info.default is not msgspec.NODEFAULT else info.default_factory()
        default = _default(value)
    said = "; ".join(c for c in checks if c) or "-"
    return f"| `{info.name}` | {name} | {default} | {said} | {_markdown(doc)} |"


def _default(value: Any) -> str:
    if value is None:
        return "nil"
    if isinstance(value, bool):
        return "false" if not value else "true"
    if isinstance(value, tuple | list | dict) and not value:
        return "`[]`" if not isinstance(value, dict) else "`{}`"
    if hasattr(value, "shape"):
        return "no rows"
    return f"`{value!r}`" if isinstance(value, str) else repr(value)


def table(cls: type) -> str:
    """The markdown table of the message class ``cls``."""
    docs = field_docs(cls)
    lines = ["| field | type | default | checks | meaning |", "|---|---|---|---|---|"]
    lines += [row(info, docs.get(info.name, "")) for info in msgspec.structs.fields(cls)]
    return "\n".join(lines) + "\n"


def render(text: str) -> str:
    """``text`` (the page) with every marked table rewritten from the declarations; KeyError names a marker
    of an unknown message."""
    return _BLOCK.sub(lambda m: m.group(1) + table(messages.MESSAGE_TYPES[m.group(2)]) + m.group(4), text)


def marked(text: str) -> set[str]:
    """The messages whose table the page marks."""
    return {m.group(2) for m in _BLOCK.finditer(text)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m swarm.transport.protocol_tables", description=__doc__)
    parser.add_argument("--check", action="store_true", help="exit 1 if the page's tables are out of date")
    parser.add_argument("path", nargs="?", type=Path, default=DOC, help="the page (default docs/protocol.md)")
    args = parser.parse_args(argv)
    text = args.path.read_text()
    new = render(text)
    missing = set(messages.MESSAGE_TYPES) - marked(text)
    if missing:
        print(f"{args.path}: no table marked for {', '.join(sorted(missing))}", file=sys.stderr)
        return 1
    if args.check:
        if new != text:
            print(f"{args.path}: the message tables differ from the declarations; run "
                  "python -m swarm.transport.protocol_tables", file=sys.stderr)  # fmt: skip
            return 1
        return 0
    args.path.write_text(new)
    return 0


if __name__ == "__main__":
    sys.exit(main())
