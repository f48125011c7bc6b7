"""Tests for swarm.config: typed scenario loading, validation messages, overrides and the TOML writer.

Oracles: hand-written TOML documents with known expected objects; tomllib (the standard library's reader) for
everything dump_toml writes, and json for to_mapping; self-consistency (dump then load gives back the object)
as a hypothesis property over generated toy scenarios.
"""

from __future__ import annotations

import enum
import json
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarm.config import apply_overrides, dump_toml, from_mapping, load_toml, parse_override, to_mapping
from swarm.errors import ConfigError
from tests.budget import examples

# ------------------------------------------------------------------------------------- toy scenario


class Mode(enum.StrEnum):
    FAST = "fast"
    SLOW = "slow"


class Level(enum.IntEnum):
    LOW = 1
    HIGH = 2


@dataclass(frozen=True)
class Dynamics:
    mass_kg: float = 1.0
    """Mass [kg]."""
    inertia_kg_m2: tuple[float, float, float] = (0.1, 0.1, 0.1)
    """Principal moments of inertia [kg m^2]."""

    def __post_init__(self) -> None:
        if not self.mass_kg > 0:  # the project's convention: "<section>.<field> must ..."
            raise ConfigError(f"dynamics.mass_kg must be positive, got {self.mass_kg!r}")


@dataclass(frozen=True)
class Vehicle:
    name: str = "vehicle"
    """Display name."""
    dynamics: Dynamics = Dynamics()
    """Rigid-body parameters."""
    p0_nav: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Initial position [m], frame nav."""


@dataclass(frozen=True)
class Agent:
    gain: float = 1.0
    """Controller gain."""
    level: Level = Level.LOW
    """Autonomy level."""
    markers_nav: tuple[tuple[float, float, float], ...] = ()
    """Marker positions [m], frame nav."""

    def __post_init__(self) -> None:
        if self.gain < 0:  # a message that does not follow the convention: the loader prefixes the path
            raise ConfigError(f"gain must be non-negative, got {self.gain!r}")


@dataclass(frozen=True)
class Toy:
    seed: int = 0
    """Run seed."""
    duration_s: float = 10.0
    """Simulated time [s]."""
    verbose: bool = False
    """Chatty output."""
    mode: Mode = Mode.FAST
    """Guidance mode."""
    face: Literal["+x", "-x", "+z", "-z"] = "-z"
    """Docking face."""
    weights: tuple[float, ...] = (1.0, 2.0)
    """Any number of weights."""
    timeout_s: float | None = None
    """Optional timeout [s]."""
    chaser: Vehicle = Vehicle(name="chaser", dynamics=Dynamics(mass_kg=3.0))
    """The chaser; its default differs from Vehicle's defaults on purpose."""
    target: Vehicle | None = None
    """Optional target."""
    agents: dict[str, Agent] = field(default_factory=dict)
    """Named agents."""


@dataclass(frozen=True)
class Required:
    label: str
    """No default."""


@dataclass(frozen=True)
class NonNoneOptional:
    limit: float | None = 1.0
    """None is allowed but not the default."""


@dataclass(frozen=True)
class Gains:
    gains: dict[str, float] = field(default_factory=lambda: {"kp": 1.0})
    """Named scalar gains; the default is not empty."""


@dataclass(frozen=True)
class Crew:
    members: dict[str, Required] = field(default_factory=dict)
    """Named entries whose field has no default."""
    squad: tuple[Dynamics, ...] = ()
    """An array of tables (``[[squad]]``)."""


@dataclass(frozen=True)
class Unsupported:
    items: list[float] = field(default_factory=list)
    """Lists are not supported (tuples are)."""


FULL_TOML = """
seed = 7
duration_s = 20          # a TOML integer for a float field
verbose = true
mode = "slow"
face = "+x"
weights = [0.5, 1, 2.5]
timeout_s = 30.0

[chaser]
name = "c1"
p0_nav = [1.0, 2.0, 1.0]

[chaser.dynamics]
mass_kg = 4.5
inertia_kg_m2 = [0.2, 0.3, 0.4]

[target.dynamics]
mass_kg = 2.0

[agents.a1]
gain = 0.5
level = 2
markers_nav = [[0.0, 0.0, 0.1], [0.1, 0.0, 0.0]]

[agents."agent two"]
"""


# --------------------------------------------------------------------------------------------- loading


def test_every_supported_type_loads() -> None:
    toy = from_mapping(Toy, tomllib.loads(FULL_TOML))
    assert toy == Toy(
        seed=7,
        duration_s=20.0,
        verbose=True,
        mode=Mode.SLOW,
        face="+x",
        weights=(0.5, 1.0, 2.5),
        timeout_s=30.0,
        chaser=Vehicle(name="c1", dynamics=Dynamics(4.5, (0.2, 0.3, 0.4)), p0_nav=(1.0, 2.0, 1.0)),
        target=Vehicle(dynamics=Dynamics(mass_kg=2.0)),
        agents={
            "a1": Agent(gain=0.5, level=Level.HIGH, markers_nav=((0.0, 0.0, 0.1), (0.1, 0.0, 0.0))),
            "agent two": Agent(),
        },
    )


def test_loaded_values_have_the_declared_python_types() -> None:
    toy = from_mapping(Toy, tomllib.loads(FULL_TOML))
    assert type(toy.duration_s) is float and type(toy.weights[1]) is float
    assert type(toy.mode) is Mode and type(toy.agents["a1"].level) is Level
    assert type(toy.chaser.p0_nav) is tuple and type(toy.agents["a1"].markers_nav[0]) is tuple


def test_empty_mapping_gives_the_defaults() -> None:
    assert from_mapping(Toy, {}) == Toy()


def test_missing_keys_keep_the_enclosing_default_instance() -> None:
    # Toy.chaser defaults to Vehicle(name="chaser", mass 3.0), unlike Vehicle() (name "vehicle", mass 1.0).
    toy = from_mapping(Toy, {"chaser": {"p0_nav": [1, 2, 3], "dynamics": {"inertia_kg_m2": [1, 1, 1]}}})
    assert toy.chaser.name == "chaser"
    assert toy.chaser.dynamics.mass_kg == 3.0


def test_integral_float_is_accepted_for_an_int_field() -> None:
    assert from_mapping(Toy, {"seed": 3.0}).seed == 3


def test_instances_are_accepted_in_place_of_tables() -> None:
    chaser = Vehicle(name="x")
    assert from_mapping(Toy, {"chaser": chaser, "mode": Mode.SLOW}).chaser is chaser


def test_section_prefixes_the_error_path() -> None:
    with pytest.raises(ConfigError, match=r"^chaser\.dynamics\.mass_kg: expected a number, got 'heavy'$"):
        from_mapping(Dynamics, {"mass_kg": "heavy"}, section="chaser.dynamics")


BAD_INPUTS = [
    # (TOML document, substrings the single error message must contain)
    ('[chaser.dynamics]\nmass_kg = "heavy"', ["chaser.dynamics.mass_kg: expected a number, got 'heavy'"]),
    ("duration_s = true", ["duration_s: expected a number, got True"]),
    ("seed = true", ["seed: expected an integer, got True"]),
    ("seed = 1.5", ["seed: expected an integer, got 1.5"]),
    ("duration_s = nan", ["duration_s: expected a finite number, got nan"]),
    ("weights = [1.0, -inf]", ["weights[1]: expected a finite number, got -inf"]),
    ("verbose = 1", ["verbose: expected true or false, got 1"]),
    ("[chaser]\nname = 5", ["chaser.name: expected a string, got 5"]),
    ("[chaser]\np0_nav = [1.0, 2.0]", ["chaser.p0_nav: expected an array of 3 items, got 2: [1.0, 2.0]"]),
    ("[chaser]\np0_nav = 1.0", ["chaser.p0_nav: expected an array, got 1.0"]),
    ("[agents.a1]\nmarkers_nav = [[0, 0, 1], [0, 1]]", ["agents.a1.markers_nav[1]: expected an array of 3"]),
    ('mode = "medium"', ["mode: expected one of 'fast', 'slow', got 'medium'"]),
    ("[agents.a1]\nlevel = 3", ["agents.a1.level: expected one of 1, 2, got 3"]),
    ("[agents.a1]\nlevel = true", ["agents.a1.level: expected one of 1, 2, got True"]),
    ('face = "+y"', ["face: expected one of '+x', '-x', '+z', '-z', got '+y'"]),
    ("chaser = 3", ["chaser: expected a table, got 3"]),
    ("agents = [1]", ["agents: expected a table, got [1]"]),
    (
        "[chaser.dynamics]\nmas_kg = 2.0",
        ["chaser.dynamics.mas_kg: unknown key", "did you mean 'mass_kg'", "inertia"],
    ),
    ("sed = 1\nfoo = 2", ["sed: unknown key", "at the top level", "duration_s", "also unknown: foo"]),
    ("[chaser.dynamics]\nmass_kg = -1", ["chaser.dynamics.mass_kg must be positive, got -1.0"]),
    ("[target.dynamics]\nmass_kg = 0", ["target.dynamics.mass_kg must be positive, got 0.0"]),
    ("[agents.a1]\ngain = -2", ["agents.a1: gain must be non-negative, got -2.0"]),
    # strings are not numbers nor booleans (msgspec's lax mode would read these; the loader stays strict)
    ('duration_s = "2.5"', ["duration_s: expected a number, got '2.5'"]),
    ('seed = "3"', ["seed: expected an integer, got '3'"]),
    ('verbose = "true"', ["verbose: expected true or false, got 'true'"]),
    ("timeout_s = [1.0]", ["timeout_s: expected a number, got [1.0]"]),
    ("target = 3", ["target: expected a table, got 3"]),
]


@pytest.mark.parametrize(("text", "expected"), BAD_INPUTS, ids=[t for t, _ in BAD_INPUTS])
def test_bad_input_raises_config_error_naming_the_field_and_value(text: str, expected: list[str]) -> None:
    with pytest.raises(ConfigError) as info:
        from_mapping(Toy, tomllib.loads(text))
    for part in expected:
        assert part in str(info.value)


def test_missing_required_field_is_named() -> None:
    with pytest.raises(ConfigError, match=r"^label: missing"):
        from_mapping(Required, {})


def test_non_dataclass_type_is_a_type_error() -> None:
    with pytest.raises(TypeError, match="dataclass"):
        from_mapping(dict, {})


def test_unsupported_field_type_is_a_type_error_naming_the_field() -> None:
    with pytest.raises(TypeError, match=r"Unsupported\.items: unsupported field type"):
        from_mapping(Unsupported, {})


# ------------------------------------------------------------------------------------------- files


def test_load_toml_reads_a_file(tmp_path: Path) -> None:
    path = tmp_path / "scenario.toml"
    path.write_text(FULL_TOML, encoding="utf-8")
    assert load_toml(Toy, path) == from_mapping(Toy, tomllib.loads(FULL_TOML))


def test_missing_file_is_a_config_error_naming_the_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match=r"nope\.toml: cannot read the scenario file"):
        load_toml(Toy, path)


def test_toml_syntax_error_names_file_line_and_column(tmp_path: Path) -> None:
    path = tmp_path / "broken.toml"
    path.write_text('seed = 1\nmode = "fast\n', encoding="utf-8")
    with pytest.raises(ConfigError, match=r"broken\.toml: invalid TOML: .*line 2, column"):
        load_toml(Toy, path)


def test_non_utf8_file_is_a_config_error(tmp_path: Path) -> None:
    path = tmp_path / "latin1.toml"
    path.write_bytes('[chaser]\nname = "caf\xe9"\n'.encode("latin-1"))
    with pytest.raises(ConfigError, match=r"latin1\.toml: not UTF-8"):
        load_toml(Toy, path)


def test_invalid_field_in_a_file_names_file_and_field(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[chaser.dynamics]\nmass_kg = 'heavy'\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"bad\.toml: chaser\.dynamics\.mass_kg: expected a number"):
        load_toml(Toy, path)


@pytest.mark.parametrize(
    ("text", "match", "line", "column"),
    [
        # the key's own line, in its table (not the same name in another table before it)
        ("seed = 1\n[chaser.dynamics]\nmass_kg = 2.0\n[target.dynamics]\n  mass_kg = 'heavy'\n",
         r"target\.dynamics\.mass_kg: expected a number", 5, 3),
        # a dotted key; a multi-line array before it whose last row is no table header
        ("agents.a.markers_nav = [\n  [0.0, 0.0, 0.0],\n  [1.0, 0.0, 0.0]\n]\nagents.a.gain = -1.0\n",
         r"agents\.a: gain must be non-negative", 5, 1),
        # an unknown table set by dotted keys: its first line
        ("seed = 1\nagent.gain = 1.0\nagent.level = 2\n",
         r"agent: unknown key \(did you mean 'agents'\?\)", 2, 1),
        # an unknown key: where it is
        ("[chaser]\nname = 'c'\n\n[chaser.dynamics]\nmas_kg = 1.0\n",
         r"chaser\.dynamics\.mas_kg: unknown key", 5, 1),
        # an array element: its array's line
        ("seed = 1\nweights = [1.0, 'two']\n", r"weights\[1\]: expected a number", 2, 1),
        # a table's own check of its field
        ("seed = 1\n[chaser.dynamics]\nmass_kg = -1.0\n",
         r"chaser\.dynamics\.mass_kg must be positive", 3, 1),
        # a table given only by its header before its sub-table
        ("seed = 1\n[chaser]\nname = 'c'\n[target]\n[target.dynamics]\nmass_kg = 'x'\n",
         r"target\.dynamics\.mass_kg: expected a number", 6, 1),
    ],
)  # fmt: skip
def test_an_invalid_value_in_a_file_gives_its_line_and_column(tmp_path, text, match, line, column) -> None:
    """tomllib keeps no positions: the loader finds the key's line in the text, as the syntax errors have."""
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=rf"bad\.toml: {match}.* \(at line {line}, column {column}\)$"):
        load_toml(Toy, path)


# ------------------------------------------------------- errors found by msgspec.convert keep the path


def test_a_wrong_type_deep_in_a_named_entry_names_its_path_file_line_and_column(tmp_path: Path) -> None:
    """msgspec writes a dict's key as ``[...]``; the message names the entry (the second one here)."""
    path = tmp_path / "deep.toml"
    path.write_text(
        "[agents.a1]\ngain = 0.5\n\n[agents.a2]\ngain = 1.0\n"
        "  markers_nav = [[0.0, 0.0, 0.1], [0.0, 'x', 0.0]]\n",
        encoding="utf-8",
    )
    want = rf"^{re.escape(str(path))}: agents\.a2\.markers_nav\[1\]\[1\]: expected a number, got 'x'"
    with pytest.raises(ConfigError, match=want + r" \(at line 6, column 3\)$"):
        load_toml(Toy, path)


def test_a_check_of_a_later_named_entry_is_rerooted_at_it(tmp_path: Path) -> None:
    path = tmp_path / "deep.toml"
    path.write_text("[agents.a1]\ngain = 0.5\n\n[agents.a2]\ngain = -1.0\n", encoding="utf-8")
    with pytest.raises(
        ConfigError, match=r": agents\.a2: gain must be non-negative, got -1\.0 \(at line 5, column 1\)$"
    ):
        load_toml(Toy, path)


def test_a_missing_field_of_a_named_entry_is_named() -> None:
    with pytest.raises(ConfigError, match=r"^members\.y\.label: missing \(the field has no default\)$"):
        from_mapping(Crew, {"members": {"x": {"label": "a"}, "y": {}}})


@pytest.mark.parametrize(
    ("second", "message"),
    [
        ("mass_kg = 'x'", r"^squad\[1\]\.mass_kg: expected a number, got 'x'$"),
        ("mass_kg = -1.0", r"^squad\[1\]\.mass_kg must be positive, got -1\.0$"),
        ("inertia_kg_m2 = [1.0, 1.0]",
         r"^squad\[1\]\.inertia_kg_m2: expected an array of 3 items, got 2: \[1\.0, 1\.0\]$"),
    ],
)  # fmt: skip
def test_an_error_in_an_array_of_tables_names_the_item(second: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        from_mapping(Crew, tomllib.loads(f"[[squad]]\nmass_kg = 2.0\n\n[[squad]]\n{second}\n"))


def test_an_override_deep_in_a_named_entry_is_named_with_the_override(scenario_file: Path) -> None:
    with pytest.raises(ConfigError) as info:
        load_toml(Toy, scenario_file, {"agents.a1.markers_nav": [[0.0, "x", 0.0]]})
    msg = str(info.value)
    assert msg.startswith("agents.a1.markers_nav[0][1]: expected a number, got 'x'")
    assert msg.endswith("(value set by override agents.a1.markers_nav)")


def test_numpy_scalars_and_enum_members_from_python_callers_load_as_plain_values() -> None:
    """Strict msgspec takes exact builtin types only; a caller's numpy value loaded before and still does."""
    face = enum.StrEnum("Face", {"PX": "+x"})
    toy = from_mapping(
        Toy,
        {"duration_s": np.float64(2.5), "seed": np.int64(4), "face": face.PX, "chaser": {"name": Mode.SLOW}},
    )
    assert (toy.duration_s, toy.seed, toy.face, toy.chaser.name) == (2.5, 4, "+x", "slow")
    assert type(toy.duration_s) is float and type(toy.seed) is int
    assert type(toy.face) is str and type(toy.chaser.name) is str


# --------------------------------------------------------------------------------------- overrides


@pytest.fixture
def scenario_file(tmp_path: Path) -> Path:
    path = tmp_path / "scenario.toml"
    path.write_text(FULL_TOML, encoding="utf-8")
    return path


def test_overrides_apply_on_top_of_the_file(scenario_file: Path) -> None:
    toy = load_toml(Toy, scenario_file, {"chaser.dynamics.mass_kg": 9, "mode": "fast", "agents.a3.gain": 2.0})
    assert toy.chaser.dynamics.mass_kg == 9.0
    assert toy.chaser.dynamics.inertia_kg_m2 == (0.2, 0.3, 0.4)  # from the file
    assert toy.mode is Mode.FAST
    assert toy.agents["a3"] == Agent(gain=2.0)


def test_invalid_override_value_names_the_field_and_the_override(scenario_file: Path) -> None:
    with pytest.raises(ConfigError) as info:
        load_toml(Toy, scenario_file, {"chaser.dynamics.mass_kg": "heavy"})
    msg = str(info.value)
    assert msg.startswith("chaser.dynamics.mass_kg: expected a number, got 'heavy'")
    assert msg.endswith("(value set by override chaser.dynamics.mass_kg)")


def test_unknown_override_key_is_rejected(scenario_file: Path) -> None:
    with pytest.raises(ConfigError, match=r"chaser\.dynamics\.mas_kg: unknown key"):
        load_toml(Toy, scenario_file, {"chaser.dynamics.mas_kg": 2.0})


def test_override_through_a_scalar_is_rejected() -> None:
    with pytest.raises(ConfigError, match=r"seed\.x: cannot set it, seed is 7, not a table"):
        apply_overrides({"seed": 7}, {"seed.x": 1})


def test_table_override_merges_into_the_existing_table() -> None:
    merged = apply_overrides({"chaser": {"name": "c", "p0_nav": [1, 2, 3]}}, {"chaser": {"name": "d"}})
    assert merged == {"chaser": {"name": "d", "p0_nav": [1, 2, 3]}}


def test_apply_overrides_leaves_the_input_unchanged() -> None:
    data = {"chaser": {"name": "c"}}
    apply_overrides(data, {"chaser.name": "d", "chaser.dynamics.mass_kg": 1.0})
    assert data == {"chaser": {"name": "c"}}


@pytest.mark.parametrize(
    ("text", "key", "value"),
    [
        ("a.b=1.5", "a.b", 1.5),
        (" verbose = true ", "verbose", True),
        ('chaser.name="c 1"', "chaser.name", "c 1"),
        ("weights=[1, 2, 3]", "weights", [1, 2, 3]),
        ("mode=slow", "mode", "slow"),  # a bare word is a string
        ('agents."a 1".gain=2', 'agents."a 1".gain', 2),
        ("chaser.dynamics={mass_kg = 2.0}", "chaser.dynamics", {"mass_kg": 2.0}),
    ],
)
def test_parse_override_reads_toml_values(text: str, key: str, value: object) -> None:
    assert parse_override(text) == (key, value)


@pytest.mark.parametrize(
    "text",
    ["a.b", "=1", "a..b=1", "a.b=", "a.b=[1, 2", "a b=1", "a.b=1.5x", 'a.b="open', "a.b=1\nc=2", "a.b=x=y"],
)
def test_parse_override_rejects_bad_syntax(text: str) -> None:
    with pytest.raises(ConfigError):
        parse_override(text)


def test_parsed_override_applies_through_the_loader(scenario_file: Path) -> None:
    toy = load_toml(Toy, scenario_file, dict([parse_override('agents."agent two".level=2')]))
    assert toy.agents["agent two"].level is Level.HIGH


# -------------------------------------------------------------------------------------- writing


def test_dump_toml_writes_tables_and_escapes(tmp_path: Path) -> None:
    toy = Toy(chaser=Vehicle(name='say "hi"\n\t\\ \x7f é'), agents={"a b": Agent(), "": Agent(gain=2.0)})
    text = dump_toml(toy)
    assert '[agents."a b"]' in text and '[agents.""]' in text
    assert from_mapping(Toy, tomllib.loads(text)) == toy


def test_dump_toml_keeps_an_empty_table_whose_default_is_not_empty() -> None:
    text = dump_toml(Gains(gains={}))
    assert "[gains]" in text
    assert from_mapping(Gains, tomllib.loads(text)) == Gains(gains={})


def test_dict_of_scalars_loads_and_validates_each_entry() -> None:
    assert from_mapping(Gains, {"gains": {"kp": 2, "kd": 0.5}}).gains == {"kp": 2.0, "kd": 0.5}
    with pytest.raises(ConfigError, match=r"^gains\.kd: expected a number, got 'x'$"):
        from_mapping(Gains, {"gains": {"kp": 2, "kd": "x"}})


def test_dump_toml_omits_none_with_a_none_default() -> None:
    data = tomllib.loads(dump_toml(Toy()))
    assert "timeout_s" not in data and "target" not in data


def test_dump_toml_refuses_none_when_the_default_is_not_none() -> None:
    with pytest.raises(ConfigError, match=r"^limit: None cannot be written to TOML.*default 1\.0"):
        dump_toml(NonNoneOptional(limit=None))


def test_dump_toml_refuses_non_finite_floats() -> None:
    with pytest.raises(ConfigError, match=r"^chaser\.p0_nav\[2\]: expected a finite number, got nan"):
        dump_toml(Toy(chaser=Vehicle(p0_nav=(0.0, 0.0, math.nan))))


def test_to_mapping_gives_plain_json_data() -> None:
    toy = from_mapping(Toy, tomllib.loads(FULL_TOML))
    data = to_mapping(toy)
    assert data["mode"] == "slow" and type(data["mode"]) is str
    assert data["agents"]["a1"]["level"] == 2 and type(data["agents"]["a1"]["level"]) is int
    assert data["chaser"]["p0_nav"] == [1.0, 2.0, 1.0]
    assert from_mapping(Toy, json.loads(json.dumps(data))) == toy


def test_to_mapping_keeps_none_for_json() -> None:
    assert to_mapping(NonNoneOptional(limit=None)) == {"limit": None}
    assert from_mapping(NonNoneOptional, {"limit": None}) == NonNoneOptional(limit=None)


# ------------------------------------------------------------------------------ round-trip property

_finite = st.floats(allow_nan=False, allow_infinity=False)
_vec3 = st.tuples(_finite, _finite, _finite)
_text = st.text(st.characters(exclude_categories=("Cs",)), max_size=12)  # TOML cannot hold lone surrogates
_positive = st.floats(min_value=0.0, exclude_min=True, allow_infinity=False)
_dynamics = st.builds(Dynamics, mass_kg=_positive, inertia_kg_m2=_vec3)
_vehicle = st.builds(Vehicle, name=_text, dynamics=_dynamics, p0_nav=_vec3)
_agent = st.builds(
    Agent,
    gain=st.floats(min_value=0.0, allow_infinity=False),
    level=st.sampled_from(Level),
    markers_nav=st.lists(_vec3, max_size=3).map(tuple),
)
_toys = st.builds(
    Toy,
    seed=st.integers(-(2**63), 2**63 - 1),
    duration_s=_finite,
    verbose=st.booleans(),
    mode=st.sampled_from(Mode),
    face=st.sampled_from(["+x", "-x", "+z", "-z"]),
    weights=st.lists(_finite, max_size=4).map(tuple),
    timeout_s=st.none() | _finite,
    chaser=_vehicle,
    target=st.none() | _vehicle,
    agents=st.dictionaries(_text, _agent, max_size=3),
)


@settings(max_examples=examples(200), deadline=None)
@given(_toys)
def test_dump_toml_then_load_gives_back_the_object(toy: Toy) -> None:
    assert from_mapping(Toy, tomllib.loads(dump_toml(toy))) == toy


@settings(max_examples=examples(100), deadline=None)
@given(_toys)
def test_to_mapping_then_from_mapping_gives_back_the_object(toy: Toy) -> None:
    assert from_mapping(Toy, json.loads(json.dumps(to_mapping(toy)))) == toy
