"""docs/protocol.md's message tables are the ones the declarations generate (issue 44, item 4).

Oracle: :func:`swarm.transport.protocol_tables.render` of the committed page; a declaration changed without
regenerating the page (``python -m swarm.transport.protocol_tables``) fails here, naming the message.
"""

from __future__ import annotations

import msgspec
import pytest

from swarm.transport import protocol_tables
from swarm.transport.messages import MESSAGE_TYPES, Uwb

PAGE = protocol_tables.DOC.read_text()


def test_every_message_has_a_table_on_the_page():
    assert protocol_tables.marked(PAGE) == set(MESSAGE_TYPES)


@pytest.mark.parametrize("name", list(MESSAGE_TYPES))
def test_the_committed_table_is_the_generated_one(name):
    start = PAGE.index(f"<!-- fields:{name} -->\n") + len(f"<!-- fields:{name} -->\n")
    end = PAGE.index(f"<!-- /fields:{name} -->")
    assert PAGE[start:end] == protocol_tables.table(MESSAGE_TYPES[name]), (
        f"docs/protocol.md's {name} table is out of date: run python -m swarm.transport.protocol_tables"
    )


def test_every_field_is_documented():
    for cls in MESSAGE_TYPES.values():
        docs = protocol_tables.field_docs(cls)
        assert set(docs) == set(cls.__struct_fields__), cls.__name__


def test_a_row_says_the_type_default_and_checks_of_the_declaration():
    row = protocol_tables.row(msgspec.structs.fields(Uwb)[3], "Measured distance.")
    assert row == "| `range_m` | float or nil | nil | finite, >= 0 | Measured distance. |"


def test_the_check_mode_fails_on_a_stale_page(tmp_path, capsys):
    stale = tmp_path / "protocol.md"
    stale.write_text(
        PAGE.replace("| `tick` | int | required | 0 .. 2^64-1 |", "| `tick` | int | required | - |", 1)
    )
    assert protocol_tables.main(["--check", str(stale)]) == 1
    assert "differ from the declarations" in capsys.readouterr().err
    assert protocol_tables.main([str(stale)]) == 0  # rewritten
    assert protocol_tables.main(["--check", str(stale)]) == 0 and stale.read_text() == PAGE
