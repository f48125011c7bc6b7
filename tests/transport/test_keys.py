"""Tests for swarm.transport.keys: every key expression, its inverse, and namespace / id validation.

Oracle: the key table of docs/protocol.md, written out by hand below.
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from swarm.errors import ConfigError
from swarm.transport.keys import AGENT_KINDS, ID_PATTERN, Keys, check_id

EXPECTED_AGENT_KINDS = (
    "imu", "uwb", "tdoa", "vision", "gnss", "rangefinder", "barometer", "estimate", "guidance", "command",
    "commands", "truth", "event", "bundle",
)  # fmt: skip


@pytest.mark.parametrize("ns", ["tpods", "lab/swarm-2"])
def test_every_key_string_matches_the_protocol_table(ns):
    k = Keys(ns)
    assert k.imu("chaser") == f"{ns}/agent/chaser/imu"
    assert k.uwb("chaser") == f"{ns}/agent/chaser/uwb"
    assert k.vision("chaser") == f"{ns}/agent/chaser/vision"
    assert k.estimate("target") == f"{ns}/agent/target/estimate"
    assert k.guidance("c_1") == f"{ns}/agent/c_1/guidance"
    assert k.command("c-2") == f"{ns}/agent/c-2/command"
    assert k.truth("A9") == f"{ns}/agent/A9/truth"
    assert k.gnss("A9") == f"{ns}/agent/A9/gnss"
    assert k.rangefinder("A9") == f"{ns}/agent/A9/rangefinder"
    assert k.barometer("A9") == f"{ns}/agent/A9/barometer"
    assert k.event("chaser") == f"{ns}/agent/chaser/event"
    assert k.world_clock() == f"{ns}/world/clock"
    assert k.world_imu() == f"{ns}/world/imu"
    assert k.world_vision() == f"{ns}/world/vision"
    assert k.mothership_uwb() == f"{ns}/mothership/uwb"
    assert k.tdoa("chaser") == f"{ns}/agent/chaser/tdoa"
    assert k.mothership_tdoa() == f"{ns}/mothership/tdoa"
    assert k.world_truth() == f"{ns}/world/truth"
    assert k.bundle("c_1") == f"{ns}/agent/c_1/bundle"
    assert k.world_bundle() == f"{ns}/world/bundle"
    assert k.anchors() == f"{ns}/mothership/anchors"
    assert k.run_control() == f"{ns}/control/run"
    assert k.alive("agent", "chaser") == f"{ns}/alive/agent/chaser"
    assert k.alive_all() == f"{ns}/alive/**"
    assert k.agent_all("estimate") == f"{ns}/agent/*/estimate"
    assert k.agent_topics("chaser") == f"{ns}/agent/chaser/*"
    assert k.everything() == f"{ns}/**"


def test_default_namespace_is_tpods():
    assert Keys().namespace == "tpods"
    assert Keys().imu("a") == "tpods/agent/a/imu"


def test_agent_kinds_are_the_twelve_per_vehicle_topics():
    assert AGENT_KINDS == EXPECTED_AGENT_KINDS


@pytest.mark.parametrize("ns", ["tpods", "lab/swarm-2"])
@pytest.mark.parametrize("kind", EXPECTED_AGENT_KINDS)
def test_parse_inverts_every_per_vehicle_key(ns, kind):
    k = Keys(ns)
    assert k.parse(getattr(k, kind)("chaser_1")) == (kind, "chaser_1")


@pytest.mark.parametrize(
    "method",
    [
        "world_clock",
        "world_event",
        "world_imu",
        "world_vision",
        "world_truth",
        "world_bundle",
        "anchors",
        "mothership_uwb",
        "run_control",
        "fault",
    ],
)
def test_parse_names_swarm_wide_keys_by_their_builder(method):
    k = Keys("lab/swarm-2")
    assert k.parse(getattr(k, method)()) == (method, None)


def test_parse_of_a_liveliness_key_gives_the_process_id_and_parse_alive_the_role():
    k = Keys()
    key = k.alive("dashboard", "dash-1")
    assert k.parse(key) == ("alive", "dash-1")
    assert k.parse_alive(key) == ("dashboard", "dash-1")
    assert k.parse_alive(k.imu("a")) is None


@pytest.mark.parametrize(
    "key",
    [
        "other/agent/a/imu",
        "tpodsx/agent/a/imu",  # a prefix of the chunk, not the namespace
        "tpods",
        "tpods/",
        "tpods/agent/a/unknown",
        "tpods/agent/*/imu",  # wildcards are not keys of one agent
        "tpods/agent/a/imu/extra",
        "tpods/agent//imu",
        "tpods/world/clockwork",
        "tpods/alive/agent",
        "tpods/alive/**",
        "",
    ],
)
def test_parse_returns_none_outside_the_protocol(key):
    assert Keys().parse(key) is None


def test_parse_does_not_match_a_sibling_namespace():
    assert Keys("lab/s1").parse("lab/agent/a/imu") is None
    assert Keys("lab/s1").parse("lab/s2/agent/a/imu") is None


def test_parse_accepts_objects_whose_str_is_the_key():
    class FakeKeyExpr:  # like zenoh.KeyExpr
        def __str__(self) -> str:
            return "tpods/agent/a/uwb"

    assert Keys().parse(FakeKeyExpr()) == ("uwb", "a")


@given(st.from_regex(ID_PATTERN, fullmatch=True), st.sampled_from(EXPECTED_AGENT_KINDS))
def test_any_valid_id_round_trips_through_parse(agent_id, kind):
    k = Keys()
    assert k.parse(getattr(k, kind)(agent_id)) == (kind, agent_id)


@pytest.mark.parametrize(
    "ns", ["", "/tpods", "tpods/", "a//b", "tp*ds", "a/**", "a/$b", "a?b", "a#b", 5, None]
)
def test_invalid_namespace_is_a_config_error_naming_it(ns):
    with pytest.raises(ConfigError, match=r"transport\.namespace") as exc:
        Keys(ns)
    assert repr(ns) in str(exc.value)


@pytest.mark.parametrize("ns", ["tpods", "lab/swarm-1", "a.b/c_d"])
def test_valid_namespaces_are_accepted(ns):
    assert Keys(ns).namespace == ns


@pytest.mark.parametrize("bad", ["", "a/b", "*", "**", "a b", "a" * 65, "ü", "a$", 3, None])
def test_invalid_agent_id_is_a_config_error_naming_it(bad):
    with pytest.raises(ConfigError, match="agent id") as exc:
        Keys().imu(bad)
    assert repr(bad) in str(exc.value)


@pytest.mark.parametrize("role, pid, what", [("a/b", "x", "role"), ("agent", "x*", "process id")])
def test_invalid_role_or_process_id_is_a_config_error_naming_it(role, pid, what):
    with pytest.raises(ConfigError, match=what):
        Keys().alive(role, pid)


def test_agent_all_refuses_an_unknown_kind():
    with pytest.raises(ConfigError, match="kind"):
        Keys().agent_all("imus")


def test_check_id_returns_a_valid_id_and_config_error_is_a_value_error():
    assert check_id("chaser-1") == "chaser-1"
    with pytest.raises(ValueError):
        check_id("chaser/1")
