"""Every ``swarm`` command that docs/usage.md and BENCHMARKS.md tell a user to type still parses: each line
of their fenced code blocks that starts with ``swarm`` (or ``.venv/bin/swarm``), and each command in a cell
of a table, through the CLI's own parser (``swarm.cli.main.build_parser``). Parsing only: nothing runs.
A flag renamed or removed, a choice dropped or a value the flag now refuses makes the documented command
fail here, with its file and line, instead of on a user's machine."""

from __future__ import annotations

import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

from swarm.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[2]
DOCUMENTS = ("docs/usage.md", "BENCHMARKS.md")  # README.md is a tour: its commands are make targets
_COMMAND = r"(?:\.venv/bin/)?swarm [a-z][a-z-]*"  # ``swarm`` and a subcommand's name
_TABLE_COMMAND = re.compile(rf"`({_COMMAND} [^`]+)`")  # with arguments: not a command named in a sentence


def documented_commands(text: str) -> list[tuple[int, str]]:
    """``(line number, command)`` for every ``swarm`` command line of ``text``'s fenced code blocks (a
    trailing ``# comment`` dropped) and every backquoted ``swarm`` command with arguments in a table row
    (``| ... |``; a bare `` `swarm sim` `` there names the command, as in prose)."""
    out, fenced = [], False
    for n, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        stripped = line.strip()
        if fenced:
            if re.match(rf"{_COMMAND}(\s|$)", stripped):
                out.append((n, stripped.split(" #", 1)[0].strip()))
        elif stripped.startswith("|"):
            out += [(n, m.group(1)) for m in _TABLE_COMMAND.finditer(stripped)]
    return out


def test_the_extraction_takes_code_and_table_commands_and_leaves_prose():
    text = (
        "Run `swarm sim docking` in prose: not taken.\n"
        "```\n"
        "swarm sim docking --seed 3   # a comment\n"
        ".venv/bin/swarm bench sim\n"
        "python -m agents --id x\n"
        "```\n"
        "| goal | `swarm launch docking --agents 2` | equal to `swarm sim` |\n"
        "```\n"
        "   swarm navigate), synthetic.py (swarm synth-log)\n"
        "```\n"
    )
    assert documented_commands(text) == [
        (3, "swarm sim docking --seed 3"),
        (4, ".venv/bin/swarm bench sim"),
        (7, "swarm launch docking --agents 2"),
    ]


def _parse(command: str) -> str | None:
    """None if ``command`` parses, else the parser's last error line."""
    argv = shlex.split(re.sub(r"^\.venv/bin/", "", command))[1:]
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            build_parser().parse_args(argv)
    except SystemExit as exc:
        if exc.code:
            return (err.getvalue().strip().splitlines() or [f"exit {exc.code}"])[-1]
    except Exception as exc:  # a type= validator that raised something else: as bad for a user
        return f"{type(exc).__name__}: {exc}"
    return None


@pytest.mark.parametrize("document", DOCUMENTS)
def test_every_documented_command_parses(document):
    commands = documented_commands((ROOT / document).read_text())
    assert len(commands) >= 20, commands  # the documents' command blocks were found at all
    failed = [f"{document}:{n}: {c}\n    {why}" for n, c in commands if (why := _parse(c)) is not None]
    assert not failed, "\n".join(failed)


def test_a_command_the_parser_refuses_is_reported_with_its_error():
    assert _parse("swarm sim docking --seed 3") is None
    assert "unrecognized arguments: --no-such-flag" in _parse("swarm sim docking --no-such-flag")
    assert "invalid choice: 'orbit'" in _parse("swarm sim docking --policy orbit")
