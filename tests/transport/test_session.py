"""Tests for swarm.transport.session: flags, Zenoh configuration, sessions and decoded subscriptions.

Oracles: Zenoh itself (the configuration read back with ``Config.get_json``; real sessions on loopback,
free ports chosen at run time, multicast scouting off) and hand-written expectations. Every session is
opened with ``with`` so that it is closed even when a test fails (a callback subscriber in an unclosed
session hangs the interpreter at exit, measured here).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import queue
import subprocess
import sys
import time
import uuid

import pytest
import zenoh

from swarm.errors import ConfigError, SwarmError
from swarm.transport.keys import Keys
from swarm.transport.messages import DropCounter, Imu, Uwb, encode
from swarm.transport.session import (
    LEAN_RUNTIME,
    QueuedSubscriber,
    ZenohArgs,
    add_zenoh_arguments,
    attached_imu_ns,
    declare_liveliness,
    imu_stamp_attachment,
    listen_endpoints,
    make_config,
    open_session,
    subscribe_decoded,
    watch_liveliness,
    zenoh_args_from,
)
from tests.transport.procs import free_port, loopback, wait_until

TIMEOUT_S = 5.0  # for anything that happens in milliseconds on loopback


def _get(config: zenoh.Config, key: str) -> object:
    return json.loads(config.get_json(key))


def _imu(tick: int) -> Imu:
    return Imu(tick=tick, t_s=0.01 * tick, dt_s=0.01, gyro_body=[0.01, -0.02, 0.03 * tick])


@pytest.fixture
def keys() -> Keys:
    return Keys(f"test-{uuid.uuid4().hex[:8]}")


@pytest.fixture
def peers():
    """Two peer sessions in this process: ``a`` listens on a free loopback port, ``b`` connects to it."""
    endpoint = loopback(free_port())
    with (
        open_session(ZenohArgs(mode="peer", listen=(endpoint,))) as a,
        open_session(ZenohArgs(mode="peer", connect=(endpoint,))) as b,
    ):
        yield a, b


def _publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """A reliable, blocking publisher, returned once a subscriber matches it."""
    pub = session.declare_publisher(
        key, reliability=zenoh.Reliability.RELIABLE, congestion_control=zenoh.CongestionControl.BLOCK
    )
    wait_until(lambda: pub.matching_status.matching, TIMEOUT_S, f"a subscriber on {key}")
    return pub


# ------------------------------------------------------------------------------------------ make_config


def test_make_config_sets_mode_endpoints_and_turns_multicast_scouting_off() -> None:
    args = ZenohArgs(mode="client", connect=("tcp/127.0.0.1:7447", "tcp/10.0.0.2:7447"), listen=())
    config = make_config(args)
    assert _get(config, "mode") == "client"
    assert _get(config, "connect/endpoints") == ["tcp/127.0.0.1:7447", "tcp/10.0.0.2:7447"]
    assert _get(config, "scouting/multicast/enabled") is False
    assert _get(config, "scouting/delay") == 0


def test_make_config_sets_listen_endpoints_and_lease() -> None:
    config = make_config(ZenohArgs(mode="router", listen=("tcp/127.0.0.1:0",), lease_ms=2000))
    assert _get(config, "mode") == "router"
    assert _get(config, "listen/endpoints") == ["tcp/127.0.0.1:0"]
    assert _get(config, "transport/link/tx/lease") == 2000


def test_make_config_enables_multicast_scouting_only_when_asked() -> None:
    config = make_config(ZenohArgs(multicast_scouting=True))
    assert _get(config, "scouting/multicast/enabled") is True
    assert _get(config, "scouting/delay") is None  # Zenoh's default delay is kept for real scouting


def test_make_config_leaves_unset_fields_to_zenoh() -> None:
    config = make_config(ZenohArgs())
    assert _get(config, "mode") is None
    assert _get(config, "connect/endpoints") == []
    assert _get(config, "transport/link/tx/lease") == 10000


def test_config_file_is_the_base_and_flags_override_it(tmp_path) -> None:
    path = tmp_path / "zenoh.json5"
    path.write_text(
        "{ // Zenoh's own format: comments and unquoted keys\n"
        '  mode: "client", connect: { endpoints: ["tcp/10.0.0.1:7447"] },\n'
        "  scouting: { multicast: { enabled: true }, delay: 250 },\n"
        "  transport: { link: { tx: { lease: 3000 } } },\n"
        "}\n"
    )
    kept = make_config(ZenohArgs(config_file=str(path)))
    assert _get(kept, "mode") == "client"
    assert _get(kept, "connect/endpoints") == ["tcp/10.0.0.1:7447"]
    assert _get(kept, "scouting/multicast/enabled") is True  # the file wins over the default "off"
    assert _get(kept, "scouting/delay") == 250
    assert _get(kept, "transport/link/tx/lease") == 3000
    overridden = make_config(
        ZenohArgs(mode="peer", connect=("tcp/127.0.0.1:7000",), config_file=str(path), lease_ms=2000)
    )
    assert _get(overridden, "mode") == "peer"
    assert _get(overridden, "connect/endpoints") == ["tcp/127.0.0.1:7000"]
    assert _get(overridden, "transport/link/tx/lease") == 2000


def test_shared_memory_is_off_unless_the_config_file_configures_it(tmp_path) -> None:
    """Zenoh's shared memory (on by default) set up its pool in a run's first ticks and made a 32-vehicle
    world late (make_config): off for every session, unless a ``--zenoh-config`` file says otherwise."""
    assert json.loads(zenoh.Config().get_json("transport/shared_memory/enabled")) is True  # Zenoh's default
    assert _get(make_config(ZenohArgs()), "transport/shared_memory/enabled") is False
    other = tmp_path / "other.json5"
    other.write_text("{ transport: { link: { tx: { lease: 3000 } } } }")
    assert _get(make_config(ZenohArgs(config_file=str(other))), "transport/shared_memory/enabled") is False
    on = tmp_path / "on.json5"
    on.write_text('{ transport: { shared_memory: { enabled: true, mode: "init" } } }')
    kept = make_config(ZenohArgs(config_file=str(on), mode="peer"))
    assert _get(kept, "transport/shared_memory/enabled") is True
    assert _get(kept, "transport/shared_memory/mode") == "init"


def test_listen_endpoints_are_the_configured_ones_or_zenohs_default_for_the_mode() -> None:
    assert listen_endpoints(make_config(ZenohArgs(mode="router", listen=("tcp/127.0.0.1:0",)))) == (
        "tcp/127.0.0.1:0",
    )
    assert listen_endpoints(make_config(ZenohArgs(mode="router"))) == ("tcp/[::]:7447",)
    assert listen_endpoints(make_config(ZenohArgs(mode="peer"))) == ("tcp/[::]:0",)


@pytest.mark.parametrize(
    ("field", "value", "flag"),
    [
        ("connect", ("nonsense",), "--connect"),
        ("connect", ("tcp/127.0.0.1",), "--connect"),  # no port
        ("connect", ("tcp/127.0.0.1:0",), "--connect"),  # port 0 only means something to listen on
        ("connect", ("tcp/ 127.0.0.1:7447",), "--connect"),
        ("listen", ("tcp/127.0.0.1:99999",), "--listen"),
        ("listen", ("/127.0.0.1:7447",), "--listen"),
    ],
)
def test_bad_endpoint_gives_config_error_naming_flag_and_value(field, value, flag) -> None:
    with pytest.raises(ConfigError) as info:
        ZenohArgs(**{field: value})
    assert flag in str(info.value)
    assert repr(value[0]) in str(info.value)


def test_endpoints_given_as_one_string_are_refused() -> None:
    with pytest.raises(ConfigError, match="--connect must be a sequence of endpoints"):
        ZenohArgs(connect="tcp/127.0.0.1:7447")  # type: ignore[arg-type]


def test_good_endpoints_are_accepted() -> None:
    args = ZenohArgs(
        connect=("tcp/[::1]:7447", "tls/router.example.org:7447", "udp/10.0.0.1:7447#iface=eth0"),
        listen=("tcp/0.0.0.0:0", "unixsock-stream//tmp/zenoh.sock"),
    )
    assert args.connect[0] == "tcp/[::1]:7447"
    assert len(args.listen) == 2


def test_bad_mode_gives_config_error() -> None:
    with pytest.raises(ConfigError, match=r"--mode must be one of peer, client, router, got 'server'"):
        ZenohArgs(mode="server")


def test_missing_config_file_gives_config_error_naming_it(tmp_path) -> None:
    path = tmp_path / "absent.json5"
    with pytest.raises(ConfigError, match=rf"--zenoh-config: no such file '{path}'"):
        make_config(ZenohArgs(config_file=str(path)))


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("broken.json5", "{ mode: "),  # not JSON5
        ("badmode.json5", '{ mode: "server" }'),  # JSON5, but not a Zenoh configuration
        ("zenoh.txt", '{ mode: "peer" }'),  # a file type Zenoh does not read
    ],
)
def test_unloadable_config_file_gives_config_error_naming_it(tmp_path, name, text) -> None:
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        make_config(ZenohArgs(config_file=str(path)))
    assert f"--zenoh-config: cannot load '{path}'" in str(info.value)
    assert ".cargo" not in str(info.value)  # Zenoh's Rust source location is cut off


def test_command_line_flags_round_trip() -> None:
    parser = argparse.ArgumentParser()
    add_zenoh_arguments(parser)
    argv = "--mode client --connect tcp/127.0.0.1:7447 --connect tcp/127.0.0.1:7448 --listen tcp/127.0.0.1:0"
    ns = parser.parse_args([*argv.split(), "--zenoh-config", "z.json5", "--multicast-scouting"])
    assert zenoh_args_from(ns) == ZenohArgs(
        mode="client",
        connect=("tcp/127.0.0.1:7447", "tcp/127.0.0.1:7448"),
        listen=("tcp/127.0.0.1:0",),
        config_file="z.json5",
        multicast_scouting=True,
    )
    assert zenoh_args_from(parser.parse_args([])) == ZenohArgs()


def test_command_without_mode_flag_fixes_the_mode() -> None:
    parser = argparse.ArgumentParser()
    add_zenoh_arguments(parser, mode=False)
    with pytest.raises(SystemExit):
        parser.parse_args(["--mode", "peer"])
    assert zenoh_args_from(parser.parse_args([]), mode="router").mode == "router"


def test_bad_endpoint_on_the_command_line_gives_config_error() -> None:
    parser = argparse.ArgumentParser()
    add_zenoh_arguments(parser)
    with pytest.raises(ConfigError, match=r"--listen endpoint .* got 'localhost:7447'"):
        zenoh_args_from(parser.parse_args(["--listen", "localhost:7447"]))


# ------------------------------------------------------------------------------------------ sessions


def test_session_is_closed_when_the_with_block_ends() -> None:
    with open_session(ZenohArgs(mode="peer", listen=(loopback(free_port()),))) as session:
        assert not session.is_closed()
    assert session.is_closed()


def test_client_without_router_gives_swarm_error_naming_the_endpoint() -> None:
    endpoint = loopback(free_port())  # nothing listens there
    with pytest.raises(SwarmError, match=rf"cannot open a Zenoh client session \(connect \['{endpoint}'\]"):
        open_session(ZenohArgs(mode="client", connect=(endpoint,)))


def test_router_session_opens_without_the_scouting_delay() -> None:
    # Zenoh's default scouting/delay makes a router's open take 0.5 s (measured 0.50 s); with the delay
    # at 0 it takes ~2 ms. 0.3 s leaves room for a slow machine and still fails on the 0.5 s wait.
    t0 = time.perf_counter()
    with open_session(ZenohArgs(mode="router", listen=(loopback(free_port()),))):
        elapsed = time.perf_counter() - t0
    assert elapsed < 0.3, f"router open took {elapsed:.3f} s"


_THREADS_OF_A_SESSION = """
import collections, json, os, sys, time
from swarm.errors import ConfigError
from swarm.transport.session import ZenohArgs, open_session
first, endpoint, lean = sys.argv[1], sys.argv[2], {"lean": True, "-": None}[sys.argv[3]]
second = "client" if first == "router" else "peer"
try:
    with open_session(ZenohArgs(mode=first, listen=(endpoint,)), lean=lean), open_session(
        ZenohArgs(mode=second, connect=(endpoint,))
    ):
        tasks = f"/proc/{os.getpid()}/task"
        deadline = time.monotonic() + 2.0  # Zenoh's runtimes start their threads as their first task comes
        while True:
            names = [open(f"{tasks}/{t}/comm").read().strip().rstrip("0123456789-")
                     for t in os.listdir(tasks)]
            if "acc" in names or "rx" in names or time.monotonic() > deadline:
                break
            time.sleep(0.05)
        print(json.dumps({"env": os.environ.get("ZENOH_RUNTIME"), "threads": collections.Counter(names)}))
except ConfigError as exc:
    print(json.dumps({"error": str(exc)}))
"""


def _session_in_a_fresh_process(first_mode: str, zenoh_runtime: str | None, lean: bool = False) -> dict:
    """What :data:`_THREADS_OF_A_SESSION` prints (a ``first_mode`` session listening on loopback, opened
    with ``lean=True`` if ``lean``, a second one connected to it), run by a new interpreter (Zenoh reads
    ``ZENOH_RUNTIME`` once per process, at its first session) with ``ZENOH_RUNTIME`` set to
    ``zenoh_runtime`` or unset."""
    env = {k: v for k, v in os.environ.items() if k != "ZENOH_RUNTIME"}
    env["RUST_BACKTRACE"] = "0"
    if zenoh_runtime is not None:
        env["ZENOH_RUNTIME"] = zenoh_runtime
    flag = "lean" if lean else "-"
    out = subprocess.run(
        [sys.executable, "-c", _THREADS_OF_A_SESSION, first_mode, loopback(free_port()), flag],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _lean(threads: dict) -> bool:
    """Whether a process with a listening session and a link runs the lean runtime: Zenoh's receiving
    ("rx") and accepting ("acc") tasks handed to the application runtime leave no thread of either; with
    Zenoh's defaults the listener has an "acc" thread ("rx" threads start only with some links, so they tell
    nothing; nor does the number of "app" threads: tokio gives its blocking pool's threads that name)."""
    return "rx" not in threads and "acc" not in threads


def test_a_first_session_that_is_no_router_runs_zenoh_lean_and_leaves_children_their_choice() -> None:
    got = _session_in_a_fresh_process("peer", None)
    assert _lean(got["threads"]), got
    assert got["env"] is None, got  # not left in the environment: a child process chooses by its own mode


def test_a_router_keeps_zenohs_default_runtime_unless_it_asks_for_lean() -> None:
    got = _session_in_a_fresh_process("router", None)
    assert not _lean(got["threads"]), got
    assert got["env"] is None, got
    got = _session_in_a_fresh_process("router", None, lean=True)  # the launcher's router
    assert _lean(got["threads"]), got
    assert got["env"] is None, got


@pytest.mark.parametrize(("first", "value", "lean"), [("peer", "()", False), ("router", LEAN_RUNTIME, True)])
def test_zenoh_runtime_set_in_the_environment_wins(first, value, lean) -> None:
    got = _session_in_a_fresh_process(first, value)
    assert _lean(got["threads"]) is lean, got
    assert got["env"] == value, got


@pytest.mark.parametrize("bad", ["(bogus: 1)", "(app: (worker_threads: 0))", "(rx: "])
def test_a_bad_zenoh_runtime_gives_config_error_naming_it(bad) -> None:
    got = _session_in_a_fresh_process("peer", bad)
    assert got.get("error", "").startswith(f"Zenoh cannot open a session with ZENOH_RUNTIME={bad!r}: "), got


# ------------------------------------------------------------------------------------------ subscribe_decoded


def test_two_peers_exchange_an_imu_through_subscribe_decoded(peers, keys) -> None:
    a, b = peers
    inbox: queue.Queue = queue.Queue()
    drops = DropCounter()
    subscribe_decoded(a, keys.imu("chaser"), Imu, lambda key, msg: inbox.put((key, msg)), drops)
    pub = _publisher(b, keys.imu("chaser"))
    sent = _imu(7)
    pub.put(encode(sent))
    key, got = inbox.get(timeout=TIMEOUT_S)
    assert key == keys.imu("chaser")
    assert isinstance(got, Imu)
    assert got.tick == 7
    assert got.gyro_body.tolist() == sent.gyro_body.tolist()
    assert drops.total == 0


def test_garbage_reaches_the_counter_not_the_handler(peers, keys) -> None:
    a, b = peers
    inbox: queue.Queue = queue.Queue()
    drops = DropCounter()
    key = keys.imu("chaser")
    subscribe_decoded(a, key, Imu, lambda k, msg: inbox.put(msg), drops)
    pub = _publisher(b, key)
    for garbage in (b"\xc1\xff not msgpack", b"", encode(Uwb(tick=1, t_s=0.01, anchor_id=3, range_m=1.0))):
        pub.put(garbage)
    pub.put(encode(_imu(1)))  # delivered after the garbage: one publisher's samples arrive in order
    assert inbox.get(timeout=TIMEOUT_S).tick == 1
    assert drops.count(key) == 3
    assert inbox.empty()


def test_raising_handler_does_not_break_later_deliveries(peers, keys, caplog) -> None:
    a, b = peers
    got: queue.Queue = queue.Queue()

    def handler(key: str, msg: Imu) -> None:
        got.put(msg.tick)
        if msg.tick < 3:
            raise RuntimeError(f"handler bug at tick {msg.tick}")

    caplog.set_level(logging.ERROR, logger="swarm.transport.session")
    subscribe_decoded(a, keys.imu("chaser"), Imu, handler, DropCounter())
    pub = _publisher(b, keys.imu("chaser"))
    for tick in range(5):
        pub.put(encode(_imu(tick)))
    assert [got.get(timeout=TIMEOUT_S) for _ in range(5)] == [0, 1, 2, 3, 4]
    # Rate-limited: the first exception is logged at once, with its traceback; the next two fall within
    # the 10 s interval and are only counted.
    records = [r for r in caplog.records if "handler bug" in r.getMessage()]
    assert len(records) == 1
    assert records[0].exc_info is not None
    assert "RuntimeError: handler bug at tick 0" in records[0].getMessage()


def test_keys_as_message_type_dispatches_on_the_key(peers, keys) -> None:
    a, b = peers
    inbox: queue.Queue = queue.Queue()
    drops = DropCounter()
    subscribe_decoded(a, keys.agent_topics("chaser"), keys, lambda k, msg: inbox.put((k, msg)), drops)
    imu_pub = _publisher(b, keys.imu("chaser"))
    uwb_pub = _publisher(b, keys.uwb("chaser"))
    uwb = Uwb(tick=2, t_s=0.02, anchor_id=4, range_m=1.5)
    imu_pub.put(encode(uwb))  # the wrong type for this key: dropped
    imu_pub.put(encode(_imu(2)))
    uwb_pub.put(encode(uwb))
    received = {k: msg for k, msg in (inbox.get(timeout=TIMEOUT_S) for _ in range(2))}
    assert isinstance(received[keys.imu("chaser")], Imu)
    assert isinstance(received[keys.uwb("chaser")], Uwb)
    assert drops.count(keys.imu("chaser")) == 1


def test_remote_only_ignores_this_sessions_own_publications(peers, keys) -> None:
    a, b = peers
    inbox: queue.Queue = queue.Queue()
    key = keys.imu("chaser")
    subscribe_decoded(a, key, Imu, lambda k, msg: inbox.put(msg.tick), DropCounter(), remote_only=True)
    a.put(key, encode(_imu(1)))  # own publication: not delivered
    _publisher(b, key).put(encode(_imu(2)))
    assert inbox.get(timeout=TIMEOUT_S) == 2
    time.sleep(0.05)  # a local delivery would be synchronous; give it a margin anyway
    assert inbox.empty()


def test_subscribe_decoded_refuses_a_non_message_type(peers, keys) -> None:
    with pytest.raises(TypeError, match="msg_type must be a Message class or a Keys"):
        subscribe_decoded(peers[0], keys.imu("x"), dict, lambda k, m: None, DropCounter())  # type: ignore[arg-type]


def test_a_queued_subscriber_wakes_nobody_and_hands_over_what_waits_when_drained(peers, keys) -> None:
    """Samples wait in Zenoh's queue, not on a thread: the handler sees nothing until drain(), then every
    valid message in order, on the caller's thread; garbage is counted as a callback subscriber counts it;
    past the capacity the oldest go (a ring, never blocking Zenoh's receiving thread)."""
    import threading

    a, b = peers
    key = keys.uwb("chaser")
    got: list[tuple[str, int, int]] = []
    drops = DropCounter()
    handler = lambda k, msg: got.append((k, msg.tick, threading.get_ident()))  # noqa: E731
    sub = QueuedSubscriber(a, key, Uwb, handler, drops, capacity=4)
    pub = _publisher(b, key)
    pub.put(encode(Uwb(tick=1, t_s=0.01, anchor_id=3, range_m=1.0)))
    pub.put(b"\xc1 not msgpack")
    pub.put(encode(_imu(2)))  # the wrong type for this key
    pub.put(encode(Uwb(tick=2, t_s=0.02, anchor_id=4, range_m=1.5)))
    wait_until(lambda: sub.drain() > 0 or bool(got), TIMEOUT_S, "the samples queued")
    wait_until(lambda: (sub.drain(), len(got) + drops.total)[1] == 4, TIMEOUT_S, "all four drained")
    assert [(k, t) for k, t, _ in got] == [(key, 1), (key, 2)]
    assert {thread for _, _, thread in got} == {threading.get_ident()}  # the drainer's own thread
    assert drops.count(key) == 2
    assert sub.drain() == 0  # nothing left
    # nothing is handed over between drains, however long one waits
    pub.put(encode(Uwb(tick=3, t_s=0.03, anchor_id=0, range_m=2.0)))
    time.sleep(0.2)
    assert len(got) == 2
    # a ring of 4: ten more samples, only the newest four are there when drained
    for tick in range(4, 14):
        pub.put(encode(Uwb(tick=tick, t_s=0.01 * tick, anchor_id=0, range_m=2.0)))
    time.sleep(0.3)
    sub.drain()
    assert [t for _, t, _ in got[2:]] == [10, 11, 12, 13]
    sub.undeclare()
    assert sub.drain() == 0  # undeclared: nothing, and no exception
    with pytest.raises(ConfigError, match="capacity must be an integer >= 1, got 0"):
        QueuedSubscriber(a, key, Uwb, handler, drops, capacity=0)


# ------------------------------------------------------------------------------------------ liveliness


def test_liveliness_token_is_seen_and_its_loss_when_the_session_closes(keys) -> None:
    endpoint = loopback(free_port())
    events: queue.Queue = queue.Queue()
    with open_session(ZenohArgs(mode="peer", listen=(endpoint,))) as watcher:
        watch_liveliness(watcher, keys, lambda role, pid, alive: events.put((role, pid, alive)))
        with open_session(ZenohArgs(mode="peer", connect=(endpoint,))) as agent:
            token = declare_liveliness(agent, keys, "agent", "chaser")
            assert events.get(timeout=TIMEOUT_S) == ("agent", "chaser", True)
        assert events.get(timeout=TIMEOUT_S) == ("agent", "chaser", False)
        del token


def test_liveliness_watcher_sees_tokens_declared_before_it(peers, keys) -> None:
    a, b = peers
    events: queue.Queue = queue.Queue()
    token = declare_liveliness(b, keys, "world", "world")
    # The token must have reached a's side before the watcher is declared, or history proves nothing.
    wait_until(
        lambda: any(r.ok is not None for r in a.liveliness().get(keys.alive_all(), timeout=1.0)),
        TIMEOUT_S,
        "the token to reach the other session",
    )
    watch_liveliness(a, keys, lambda role, pid, alive: events.put((role, pid, alive)))
    assert events.get(timeout=TIMEOUT_S) == ("world", "world", True)
    del token


def _alive_seen_by(session: zenoh.Session, keys: Keys) -> set[str]:
    return {str(r.ok.key_expr) for r in session.liveliness().get(keys.alive_all(), timeout=1.0) if r.ok}


def test_liveliness_token_that_is_not_kept_is_undeclared(peers, keys) -> None:
    # Zenoh undeclares a token as soon as Python drops it (unlike a callback subscriber, which lives
    # until the session closes): declare_liveliness's docstring tells callers to keep it.
    a, b = peers
    declare_liveliness(b, keys, "agent", "forgotten")
    kept = declare_liveliness(b, keys, "agent", "kept")
    # b's declarations reach a in order: once "kept" is there, "forgotten" has come and gone.
    wait_until(lambda: keys.alive("agent", "kept") in _alive_seen_by(a, keys), TIMEOUT_S, "the kept token")
    assert _alive_seen_by(a, keys) == {keys.alive("agent", "kept")}
    del kept


def test_liveliness_watcher_ignores_keys_outside_the_protocol_and_survives_its_handler(peers, keys) -> None:
    a, b = peers
    events: queue.Queue = queue.Queue()

    def on_change(role: str, pid: str, alive: bool) -> None:
        events.put((role, pid, alive))
        raise RuntimeError("watcher bug")

    watch_liveliness(a, keys, on_change)
    stray = b.liveliness().declare_token(f"{keys.namespace}/alive/too/many/chunks")
    first = declare_liveliness(b, keys, "agent", "first")
    second = declare_liveliness(b, keys, "agent", "second")
    # Tokens already known when the watcher's history is collected may come in any order: compare sets.
    got = {events.get(timeout=TIMEOUT_S) for _ in range(2)}
    assert got == {("agent", "first", True), ("agent", "second", True)}
    time.sleep(0.05)  # the stray token, had it been passed on, would be here by now
    assert events.empty()
    del stray, first, second


def test_declare_liveliness_refuses_an_id_that_is_not_one_key_chunk(peers, keys) -> None:
    with pytest.raises(ConfigError, match="process id"):
        declare_liveliness(peers[0], keys, "agent", "a/b")


# ------------------------------------------------------------------------------------------ stamps


@pytest.mark.parametrize("stamping", [True, False])
def test_a_stamped_subscriber_hands_over_the_publishers_stamp_queued_or_not(tmp_path, keys, stamping) -> None:
    """``stamped``: the handler gets the sample's publication stamp, the publisher's clock at its ``put``
    (Zenoh's timestamping on, for the publisher only) or ``None`` (off), with a callback and from a queue."""
    conf = tmp_path / "stamps.json5"
    conf.write_text("{ timestamping: { enabled: { peer: true } } }" if stamping else "{}")
    endpoint = loopback(free_port())
    with (
        open_session(ZenohArgs(mode="peer", listen=(endpoint,))) as a,
        open_session(ZenohArgs(mode="peer", connect=(endpoint,), config_file=str(conf))) as b,
    ):
        inbox: queue.Queue = queue.Queue()
        drops = DropCounter()
        subscribe_decoded(a, keys.imu("chaser"), Imu, lambda *args: inbox.put(args), drops, stamped=True)
        got: list = []
        sub = QueuedSubscriber(
            a, keys.imu("chaser"), Imu, lambda *args: got.append(args), drops, stamped=True
        )
        pub = _publisher(b, keys.imu("chaser"))
        before = time.time_ns()
        pub.put(encode(_imu(7)))
        after = time.time_ns()
        key, msg, ns = inbox.get(timeout=TIMEOUT_S)
        wait_until(lambda: sub.drain() or got, TIMEOUT_S, "the queued imu")
        assert (key, msg.tick) == (keys.imu("chaser"), 7) and [(k, m.tick, n) for k, m, n in got] == [
            (key, 7, ns)
        ]
        if stamping:  # (an HLC stamp: the real-time clock, to within its logical counter's few ns)
            assert before - 1000 <= ns <= after + 1000
        else:
            assert ns is None
        assert drops.total == 0


def test_an_estimates_attachment_carries_its_imus_stamp_and_refuses_anybody_elses(peers, keys) -> None:
    """``imu_stamp_attachment`` puts ``{"imu_published_ns": ns}`` in msgpack, any msgpack library reads it,
    and ``attached_imu_ns`` reads it back off a received sample; none, or one of anybody else's making, is
    ``None``, never an exception."""
    import msgpack

    ns = 1_764_400_000_123_456_789
    assert msgpack.unpackb(imu_stamp_attachment(ns)) == {"imu_published_ns": ns}
    a, b = peers
    inbox: queue.Queue = queue.Queue()
    a.declare_subscriber(keys.estimate("chaser"), inbox.put)
    pub = _publisher(b, keys.estimate("chaser"))
    field = "imu_published_ns"
    bad = [None, b"", b"\xc1", msgpack.packb([ns]), msgpack.packb({"x": ns}), msgpack.packb({field: -1}),
           msgpack.packb({field: 1.5}), msgpack.packb({field: True}),
           msgpack.packb({field: str(ns)})]  # fmt: skip
    for attachment in [imu_stamp_attachment(ns), imu_stamp_attachment(0), *bad]:
        pub.put(b"payload", attachment=attachment)
    got = [attached_imu_ns(inbox.get(timeout=TIMEOUT_S)) for _ in range(2 + len(bad))]
    assert got == [ns, 0] + [None] * len(bad)
